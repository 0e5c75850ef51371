"""Re-express a real clip in another rig convention, as other tools would have written it.

Independent of froude: the clip is read by the tests' oracle reader (``conftest.read_bvh_oracle``),
joint transforms are SciPy ``Rotation``s, and the file is written here. Every variant shows the same
motion in the world (to rounding), only the file's conventions change:

- ``units``: lengths in another unit (centimetres, metres, inches ...);
- ``z_up``: Z-up axes (Blender's): (x, y, z) -> (x, -z, y), every local rotation conjugated;
- ``folded``: every joint given a bind orientation (bones along local axes, the Maya habit), so the
  zero-rotation pose is folded while the animated world pose is unchanged;
- ``renamed``: Mixamo, Unreal, Character Creator, SMPL, Blender or Bandai joint names;
- ``extra_root``: a static reference root at the origin above the old root;
- ``six_channels``: position channels (equal to the OFFSET) on every joint;
- ``every``: every n-th frame (120 Hz -> 30 or 60 Hz);
- ``resampled``: the rate divided by n through an anti-alias low-pass (SciPy's polyphase resampler);
- ``upsampled``: the rate multiplied by n by spline interpolation (a 30 Hz clip at 60 or 120 Hz);
- ``shifted_end_site``: one end site moved (another performer's toe marker).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.signal import resample_poly
from scipy.spatial.transform import Rotation

from conftest import OracleBvh

# Canonical parts of the two real rigs; joints not listed get neutral names ("bone_07").
CMU_PARTS = {
    "Hips": "pelvis", "LeftUpLeg": "hip_L", "LeftLeg": "knee_L", "LeftFoot": "ankle_L", "LeftToeBase": "toe_L",
    "RightUpLeg": "hip_R", "RightLeg": "knee_R", "RightFoot": "ankle_R", "RightToeBase": "toe_R",
    "LowerBack": "spine1", "Spine": "spine2", "Spine1": "spine3", "Neck": "neck", "Head": "head",
    "LeftShoulder": "clav_L", "LeftArm": "shoulder_L", "LeftForeArm": "elbow_L", "LeftHand": "wrist_L",
    "RightShoulder": "clav_R", "RightArm": "shoulder_R", "RightForeArm": "elbow_R", "RightHand": "wrist_R",
}
BANDAI_PARTS = {
    "Hips": "pelvis", "Spine": "spine1", "Chest": "spine2", "Neck": "neck", "Head": "head",
    "Shoulder_L": "clav_L", "UpperArm_L": "shoulder_L", "LowerArm_L": "elbow_L", "Hand_L": "wrist_L",
    "Shoulder_R": "clav_R", "UpperArm_R": "shoulder_R", "LowerArm_R": "elbow_R", "Hand_R": "wrist_R",
    "UpperLeg_L": "hip_L", "LowerLeg_L": "knee_L", "Foot_L": "ankle_L", "Toes_L": "toe_L",
    "UpperLeg_R": "hip_R", "LowerLeg_R": "knee_R", "Foot_R": "ankle_R", "Toes_R": "toe_R",
}
_LIMBS = {  # family -> part -> name pattern ({S}: L/R side as the family writes it)
    "mixamo": {"pelvis": "mixamorig:Hips", "hip": "mixamorig:{Side}UpLeg", "knee": "mixamorig:{Side}Leg",
               "ankle": "mixamorig:{Side}Foot", "toe": "mixamorig:{Side}ToeBase",
               "clav": "mixamorig:{Side}Shoulder", "shoulder": "mixamorig:{Side}Arm",
               "elbow": "mixamorig:{Side}ForeArm", "wrist": "mixamorig:{Side}Hand", "spine1": "mixamorig:Spine",
               "spine2": "mixamorig:Spine1", "spine3": "mixamorig:Spine2", "neck": "mixamorig:Neck",
               "head": "mixamorig:Head"},
    "unreal": {"pelvis": "pelvis", "hip": "thigh_{s}", "knee": "calf_{s}", "ankle": "foot_{s}", "toe": "ball_{s}",
               "clav": "clavicle_{s}", "shoulder": "upperarm_{s}", "elbow": "lowerarm_{s}", "wrist": "hand_{s}",
               "spine1": "spine_01", "spine2": "spine_02", "spine3": "spine_03", "neck": "neck_01", "head": "head"},
    "cc": {"pelvis": "CC_Base_Pelvis", "hip": "CC_Base_{S}_Thigh", "knee": "CC_Base_{S}_Calf",
           "ankle": "CC_Base_{S}_Foot", "toe": "CC_Base_{S}_ToeBase", "clav": "CC_Base_{S}_Clavicle",
           "shoulder": "CC_Base_{S}_Upperarm", "elbow": "CC_Base_{S}_Forearm", "wrist": "CC_Base_{S}_Hand",
           "spine1": "CC_Base_Waist", "spine2": "CC_Base_Spine01", "spine3": "CC_Base_Spine02",
           "neck": "CC_Base_NeckTwist01", "head": "CC_Base_Head"},
    "smpl": {"pelvis": "Pelvis", "hip": "{S}_Hip", "knee": "{S}_Knee", "ankle": "{S}_Ankle", "toe": "{S}_Foot",
             "clav": "{S}_Collar", "shoulder": "{S}_Shoulder", "elbow": "{S}_Elbow", "wrist": "{S}_Wrist",
             "spine1": "Spine1", "spine2": "Spine2", "spine3": "Spine3", "neck": "Neck", "head": "Head"},
    "blender": {"pelvis": "hips", "hip": "thigh.{S}", "knee": "shin.{S}", "ankle": "foot.{S}", "toe": "toe.{S}",
                "clav": "shoulder.{S}", "shoulder": "upper_arm.{S}", "elbow": "forearm.{S}", "wrist": "hand.{S}",
                "spine1": "spine", "spine2": "spine.001", "spine3": "chest", "neck": "neck", "head": "head"},
    "bandai": {"pelvis": "Hips", "hip": "UpperLeg_{S}", "knee": "LowerLeg_{S}", "ankle": "Foot_{S}",
               "toe": "Toes_{S}", "clav": "Shoulder_{S}", "shoulder": "UpperArm_{S}", "elbow": "LowerArm_{S}",
               "wrist": "Hand_{S}", "spine1": "Spine", "spine2": "Chest", "spine3": "Chest2", "neck": "Neck",
               "head": "Head"},
}
FAMILIES = tuple(_LIMBS)
# Metres per unit.
UNITS = {"metres": 1.0, "centimetres": 0.01, "inches": 0.0254, "CMU units": 0.056444}
# Y-up -> Z-up axes: (x, y, z) -> (x, -z, y)
Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


# ---- decomposing and composing the channel values -----------------------------------------------------
def _decompose(b: OracleBvh):
    """(local translations (F, J, 3) in file units, local rotations [Rotation (F,)] per joint)."""
    F, J = len(b.values), len(b.names)
    trans = np.broadcast_to(np.asarray(b.offsets, float), (F, J, 3)).copy()
    rots = []
    col = 0
    for j in range(J):
        order, angles = "", []
        for c in b.channels[j]:
            if c.endswith("position"):
                trans[:, j, "XYZ".index(c[0])] = b.values[:, col]
            else:
                order += c[0].upper()
                angles.append(b.values[:, col])
            col += 1
        rots.append(Rotation.from_euler(order, np.stack(angles, axis=1), degrees=True) if order
                    else Rotation.identity(F))
    return trans, rots


def _compose(b: OracleBvh, trans, rots) -> np.ndarray:
    """(F, C) channel values of joints with b's channels from local translations and rotations."""
    cols = []
    for j, chans in enumerate(b.channels):
        order = "".join(c[0].upper() for c in chans if c.endswith("rotation"))
        euler = rots[j].as_euler(order, degrees=True) if order else None
        k = 0
        for c in chans:
            if c.endswith("position"):
                cols.append(trans[:, j, "XYZ".index(c[0])])
            else:
                cols.append(euler[:, k])
                k += 1
    return np.stack(cols, axis=1)


def _is_root(b, j):
    return b.parents[j] < 0


# ---- the variants ----------------------------------------------------------------------------------------
def units(b: OracleBvh, metres_per_unit_from: float, metres_per_unit_to: float) -> OracleBvh:
    """Every length in another unit."""
    f = metres_per_unit_from / metres_per_unit_to
    trans, rots = _decompose(b)
    out = replace(b, offsets=np.asarray(b.offsets) * f, end_sites=[(j, np.asarray(o) * f) for j, o in b.end_sites])
    return replace(out, values=_compose(out, trans * f, rots))


def z_up(b: OracleBvh) -> OracleBvh:
    """The same motion in Z-up axes (x, -z, y): offsets and translations turned, rotations conjugated."""
    C = Rotation.from_matrix(Y_TO_Z)
    trans, rots = _decompose(b)
    out = replace(b, offsets=np.asarray(b.offsets) @ Y_TO_Z.T,
                  end_sites=[(j, np.asarray(o) @ Y_TO_Z.T) for j, o in b.end_sites])
    return replace(out, values=_compose(out, trans @ Y_TO_Z.T, [C * r * C.inv() for r in rots]))


def folded(b: OracleBvh, seed: int = 0) -> OracleBvh:
    """Every joint given a rest (bind) orientation B_j; the world motion unchanged.

    World frames become W'_j = W_j B_j, so local rotations become B_p⁻¹ L_j B_j, offsets B_p⁻¹ o_j and end
    sites B_j⁻¹ o_e. The orientations are quarter turns about random axes: bones end up along local axes
    and the zero-rotation pose lies folded.
    """
    rng = np.random.default_rng(seed)
    J = len(b.names)
    B = [Rotation.from_rotvec(0.5 * np.pi * v / np.linalg.norm(v)) for v in rng.normal(size=(J, 3))]
    trans, rots = _decompose(b)
    new_rots, new_off = [], np.array(b.offsets, float)
    new_trans = trans.copy()
    for j in range(J):
        p = b.parents[j]
        Bp_inv = Rotation.identity() if p < 0 else B[p].inv()
        new_rots.append(Bp_inv * rots[j] * B[j])
        new_off[j] = Bp_inv.apply(b.offsets[j])
        new_trans[:, j] = Bp_inv.apply(trans[:, j])
    ends = [(j, B[j].inv().apply(o)) for j, o in b.end_sites]
    out = replace(b, offsets=new_off, end_sites=ends)
    return replace(out, values=_compose(out, new_trans, new_rots))


def renamed(b: OracleBvh, family: str, parts: dict) -> OracleBvh:
    """Joint names of a naming family; joints without a canonical part get neutral names."""
    names = []
    for j, n in enumerate(b.names):
        part = parts.get(n)
        if part is None:
            names.append(f"bone_{j:02d}")
            continue
        base, _, side = part.partition("_")
        pattern = _LIMBS[family][base]
        names.append(pattern.format(S=side, s=side.lower(), Side={"L": "Left", "R": "Right"}.get(side, "")))
    return replace(b, names=names)


def extra_root(b: OracleBvh, name: str = "Reference") -> OracleBvh:
    """A static root at the origin (six channels, all zero) above the old root."""
    values = np.concatenate([np.zeros((len(b.values), 6)), b.values], axis=1)
    return replace(
        b, names=[name] + list(b.names), parents=[-1] + [p + 1 for p in b.parents],
        offsets=np.vstack([np.zeros(3), b.offsets]),
        channels=[["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"]] + list(b.channels),
        end_sites=[(j + 1, o) for j, o in b.end_sites], values=values,
    )


def six_channels(b: OracleBvh) -> OracleBvh:
    """Position channels equal to the OFFSET on every joint that lacks them."""
    trans, rots = _decompose(b)
    chans = [list(c) if any(x.endswith("position") for x in c)
             else ["Xposition", "Yposition", "Zposition"] + list(c) for c in b.channels]
    out = replace(b, channels=chans)
    return replace(out, values=_compose(out, trans, rots))


def every(b: OracleBvh, n: int, pose_frames: int = 0) -> OracleBvh:
    """Every n-th frame: the frame rate divided by n.

    pose_frames: leading rows that are not motion (the T-pose frame the CMU conversions put first): kept
    as they are, and the motion thinned from its own first frame, as a converter writing the take at the
    lower rate would; so the thinned take starts at the same instant as the original's motion.
    """
    return replace(b, values=np.concatenate([b.values[:pose_frames], b.values[pose_frames::n]]),
                   frame_time=b.frame_time * n)


def resampled(b: OracleBvh, n: int, pose_frames: int = 0) -> OracleBvh:
    """The rate divided by n as a resampler with an anti-alias filter writes it (``every`` thins without one).

    Every channel (rotations unwrapped, in degrees) goes through ``scipy.signal.resample_poly(x, 1, n)``: a
    polyphase FIR low-pass below the new Nyquist frequency, then every n-th sample; its ends are padded along
    a line. pose_frames as in ``every``.
    """
    v = np.array(b.values[pose_frames:], float)
    rot = np.array([c.endswith("rotation") for chans in b.channels for c in chans])
    v[:, rot] = np.unwrap(v[:, rot], period=360.0, axis=0)
    out = resample_poly(v, 1, n, axis=0, padtype="line")
    return replace(b, values=np.concatenate([b.values[:pose_frames], out]), frame_time=b.frame_time * n)


def upsampled(b: OracleBvh, n: int, pose_frames: int = 0) -> OracleBvh:
    """The rate multiplied by n as an exporter sampling the same take at a higher rate writes it: each
    joint's rotation through SciPy's ``RotationSpline`` and its translation through a ``CubicSpline`` (both
    twice differentiable, so the COM keeps its curvature; a channel-wise filter of Euler angles would ring
    across their wraps). pose_frames as in ``every``."""
    from scipy.interpolate import CubicSpline
    from scipy.spatial.transform import RotationSpline

    body = replace(b, values=np.asarray(b.values[pose_frames:], float))
    trans, rots = _decompose(body)
    F = len(body.values)
    t = np.arange(F, dtype=float)
    t_new = np.arange((F - 1) * n + 1, dtype=float) / n
    trans_new = CubicSpline(t, trans, axis=0)(t_new)
    rots_new = [RotationSpline(t, r)(t_new) for r in rots]
    out = _compose(body, trans_new, rots_new)
    return replace(b, values=np.concatenate([b.values[:pose_frames], out]), frame_time=b.frame_time / n)


def _world_rotations(b: OracleBvh, joint: int) -> Rotation:
    """World rotations (F,) of one joint: its chain's local rotations composed from the root."""
    _, rots = _decompose(b)
    chain = []
    j = joint
    while j >= 0:
        chain.append(j)
        j = b.parents[j]
    R = rots[chain[-1]]
    for k in reversed(chain[:-1]):
        R = R * rots[k]
    return R


def shifted_end_site(b: OracleBvh, joint_name: str, metres_per_unit: float, shift_m=(0.0, 0.03, 0.0),
                     frame: int | None = None) -> OracleBvh:
    """Another performer's marker placement: the end site(s) of one joint (a foot's toe tip) moved by
    shift_m [m], a vector in the file's world axes at ``frame`` (default: where the joint is lowest on
    the file's Y axis), so the end site moves by the same amount in the joint's own axes at every frame.

    The joints and the motion are unchanged; only that end site (and so the foot's tip) is elsewhere."""
    j = b.names.index(joint_name)
    R = _world_rotations(b, j)
    if frame is None:
        from conftest import oracle_fk

        p, _ = oracle_fk(b, 1.0)
        frame = int(np.argmin(p[:, j, 1]))
    local = R[frame].inv().apply(np.asarray(shift_m, float)) / metres_per_unit
    ends = [(k, np.asarray(o, float) + local if k == j else o) for k, o in b.end_sites]
    return replace(b, end_sites=ends)


# ---- writing ---------------------------------------------------------------------------------------------
def bvh_text(b: OracleBvh) -> str:
    """The BVH text of an OracleBvh (joints in depth-first order)."""
    children = {j: [k for k, p in enumerate(b.parents) if p == j] for j in range(len(b.names))}
    ends = {}
    for j, o in b.end_sites:
        ends.setdefault(j, []).append(o)
    out = ["HIERARCHY"]

    def fmt(v):
        return " ".join(f"{x:.9g}" for x in v)

    def write(j, depth):
        ind = "  " * depth
        out.append(f"{ind}{'ROOT' if b.parents[j] < 0 else 'JOINT'} {b.names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}  OFFSET {fmt(b.offsets[j])}")
        out.append(f"{ind}  CHANNELS {len(b.channels[j])} {' '.join(b.channels[j])}")
        for k in children[j]:
            write(k, depth + 1)
        for o in ends.get(j, []):
            out.extend([f"{ind}  End Site", f"{ind}  {{", f"{ind}    OFFSET {fmt(o)}", f"{ind}  }}"])
        out.append(f"{ind}}}")

    write(0, 0)
    out += ["MOTION", f"Frames: {len(b.values)}", f"Frame Time: {b.frame_time:.10g}"]
    out += [" ".join(f"{x:.8g}" for x in row) for row in b.values]
    return "\n".join(out) + "\n"


def with_helpers(b: OracleBvh, parents_of_helpers: dict) -> OracleBvh:
    """Helper bones (twist, "share" bones) added as static children: {joint name: [helper names]}.

    Each helper sits halfway along its parent's first child bone, with three rotation channels at zero:
    it moves nothing, as in rigs where twist bones carry only skinning.
    """
    names, parents, offsets, channels = list(b.names), list(b.parents), [np.asarray(o) for o in b.offsets], \
        [list(c) for c in b.channels]
    values = b.values
    ends = list(b.end_sites)
    for parent_name, helpers in parents_of_helpers.items():
        for h in helpers:
            p = names.index(parent_name)
            kids = [k for k, q in enumerate(parents) if q == p]
            off = 0.5 * offsets[kids[0]] if kids else np.zeros(3)
            at = p + 1  # right after its parent: depth-first order still holds (it has no children)
            col = sum(len(c) for c in channels[:at])
            names.insert(at, h)
            parents = [q + (q >= at) for q in parents]
            parents.insert(at, p)
            offsets.insert(at, off)
            channels.insert(at, ["Zrotation", "Xrotation", "Yrotation"])
            values = np.concatenate([values[:, :col], np.zeros((len(values), 3)), values[:, col:]], axis=1)
            ends = [(j + (j >= at), o) for j, o in ends]
    return replace(b, names=names, parents=parents, offsets=np.array(offsets), channels=channels,
                   end_sites=ends, values=values)
