"""The Blender add-on: a panel in the 3D view's sidebar (tab "froude") for the active armature and its action.

    Analyse     what ``froude info`` says of the action (units, kind of motion, speed, Froude number,
                cadence), the foot contacts as timeline markers ("froude L" / "froude R")
    Scale       ``froude.scale``: a character (preset, height, mass) and a speed factor
    Accelerate  ``froude.accelerate``: to a factor of the start speed over some steps

Scale and Accelerate write a *new* action on the same armature and make it the active one; the original
action is kept (with a fake user, so saving the file keeps it) and never changed. Every failure is one line
in the panel and in Blender's report, and leaves the scene as it was. Progress shows in the status bar.

Only this module imports ``bpy``; the armature <-> Motion arithmetic is ``adapter.py``'s. Blender 4.2 and
later (layered actions of 4.4+ and the flat F-curves of older versions alike).
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import bpy
import numpy as np

import froude

from ...body.model import load_joint_map
from ...body.presets import list_presets
from ...core import quat
from ...errors import FroudeError
from .adapter import (
    EULER_MODES,
    Armature,
    armature_basis,
    armature_motion,
    basis_matrices,
    decompose_basis,
    euler_quaternions,
    pose_from_basis,
)

#: Timeline markers the Analyse button puts at each foot's touchdown start with this.
MARKER_PREFIX = "froude "
#: A connected bone's keyed location that varies by more than this fraction of its length is motion.
CONNECTED_LOCATION_TOLERANCE = 1e-3
#: Keys spaced within this (relative) of whole scene frames are taken at the scene's rate.
RATE_ROUNDING = 1e-5
#: Text of the "no character change" choice.
SAME_BODY = "SAME"


# ---- reading the armature ------------------------------------------------------------------------------------
def _bone_order(obj) -> list[Any]:
    """The armature's bones, parents first (depth first from the one root)."""
    roots = [b for b in obj.data.bones if b.parent is None]
    if len(roots) != 1:
        raise FroudeError(f"armature '{obj.name}' has {len(roots)} root bones; froude needs one skeleton root")
    out: list[Any] = []
    stack = [roots[0]]
    while stack:
        b = stack.pop()
        out.append(b)
        stack.extend(reversed(list(b.children)))
    return out


def active_armature(context):
    """(the active armature object, its action); FroudeError saying what is missing."""
    obj = context.active_object
    if obj is None or obj.type != "ARMATURE":
        what = "nothing is active" if obj is None else f"the active object '{obj.name}' is a {obj.type.lower()}"
        raise FroudeError(f"select an armature with an action ({what})")
    action = obj.animation_data.action if obj.animation_data else None
    if action is None:
        raise FroudeError(f"armature '{obj.name}' has no action to read")
    return obj, action


def action_fcurves(action) -> list[Any]:
    """Every F-curve of an action (Blender 4.4+ keeps them in layered channelbags)."""
    if hasattr(action, "layers") and len(action.layers):
        return [fc for layer in action.layers for strip in layer.strips for bag in strip.channelbags
                for fc in bag.fcurves]
    return list(getattr(action, "fcurves", ()))


def action_frames(action) -> np.ndarray:
    """(F,) scene frames to sample an action at: its keys where every F-curve is keyed at the same evenly
    spaced frames (a baked action: BVH and FBX imports; an FBX at a frame rate Blender rounds puts them a
    little off whole frames), else every whole frame of its range."""
    keys = None
    for fc in action_fcurves(action):
        co = np.empty(2 * len(fc.keyframe_points))
        fc.keyframe_points.foreach_get("co", co)
        t = co[0::2]
        if keys is None:
            keys = t
        elif len(t) != len(keys) or np.abs(t - keys).max() > 1e-4:
            keys = None
            break
    if keys is not None and len(keys) > 2:
        step = np.diff(keys)
        if np.abs(step - step.mean()).max() <= 1e-4 * step.mean():
            return keys
    lo, hi = action.frame_range
    return np.arange(int(round(lo)), int(round(hi)) + 1).astype(float)


def _check_connected_locations(obj, action) -> None:
    """FroudeError when the action moves connected bones: Blender ignores a connected bone's location, so
    what the scene shows is not what was keyed (Blender's FBX importer connects every bone whose head sits
    on its parent's tail, a hips bone that travels below a static root too). A location that stays within
    CONNECTED_LOCATION_TOLERANCE of the bone's length is rounding, not motion."""
    connected = {b.name for b in obj.data.bones if b.use_connect}
    moved = []
    for fc in action_fcurves(action):
        path = fc.data_path
        if not (path.startswith('pose.bones["') and path.endswith('"].location')):
            continue
        bone = path[len('pose.bones["'):-len('"].location')].replace('\\"', '"')
        if bone not in connected or bone in moved or len(fc.keyframe_points) < 2:
            continue
        co = np.empty(2 * len(fc.keyframe_points))
        fc.keyframe_points.foreach_get("co", co)
        if np.ptp(co[1::2]) > CONNECTED_LOCATION_TOLERANCE * obj.data.bones[bone].length:
            moved.append(bone)
    if moved:
        names = ", ".join(f"'{b}'" for b in moved)
        raise FroudeError(f"bone(s) {names} are connected to their parent, so Blender ignores their keyed location "
                          "(importers connect bones whose head sits on the parent's tail): disconnect them (Edit "
                          "Mode, Alt+P > Disconnect Bone) to play the action as keyed")


def frame_set(scene, frame: float) -> None:
    """Evaluate the scene at a (possibly fractional) frame."""
    whole = int(np.floor(frame + 1e-9))
    scene.frame_set(whole, subframe=float(frame - whole))


def scene_frame_time(scene) -> float:
    """Seconds per scene frame [s] (fps / fps_base)."""
    return scene.render.fps_base / scene.render.fps


def sample_armature(context) -> tuple[Armature, np.ndarray, np.ndarray]:
    """(Armature, pose_world (F, B, 4, 4) [BU], frames (F,)) of the active armature's action, sampled at
    every scene frame of the action's range; the scene's current frame is restored."""
    from mathutils import Matrix

    obj, action = active_armature(context)
    scene = context.scene
    bones = _bone_order(obj)
    names = tuple(b.name for b in bones)
    index = {n: k for k, n in enumerate(names)}
    _check_connected_locations(obj, action)
    frames = action_frames(action)
    if len(frames) < 3:
        raise FroudeError(f"action '{action.name}' has {len(frames)} frame(s); froude needs a motion")
    current, sub = scene.frame_current, scene.frame_subframe
    pose = np.empty((len(frames), len(bones), 4, 4))
    pbones = [obj.pose.bones[n] for n in names]
    # the action alone on the rest pose: a channel the action does not key would otherwise keep whatever
    # another action (froude's, with its bone scales) left there; the pose is put back afterwards
    saved = [pb.matrix_basis.copy() for pb in pbones]
    try:
        for pb in pbones:
            pb.matrix_basis = Matrix.Identity(4)  # (assigning writes location, rotation and scale)
        frame_set(scene, frames[0])
        object_world = np.array(obj.matrix_world)
        rest = np.array([object_world @ np.array(b.matrix_local) for b in bones])
        tails = np.array([(object_world @ np.append(np.array(b.tail_local), 1.0))[:3] for b in bones])
        loc = np.empty((len(frames), len(bones), 3))
        rot = np.empty((len(frames), len(bones), 4))
        scale = np.empty((len(frames), len(bones), 3))
        world = np.empty((len(frames), 4, 4))
        for k, f in enumerate(frames):
            frame_set(scene, f)
            world[k] = np.array(obj.matrix_world)
            pose[k] = np.array([np.array(pb.matrix) for pb in pbones])
            for b, pb in enumerate(pbones):
                loc[k, b], scale[k, b] = pb.location, pb.scale
                rot[k, b] = _rotation(pb)
    finally:
        for pb, m in zip(pbones, saved):
            pb.matrix_basis = m
        scene.frame_set(current, subframe=sub)
    if np.abs(world - world[0]).max() > 1e-6 * max(float(np.abs(world[0, :3, :3]).max()), 1.0):
        raise FroudeError(f"the armature object '{obj.name}' itself moves during the action; froude reads the "
                          "bones' motion: move the object's animation onto the root bone first")
    arm = Armature(names, np.array([-1 if b.parent is None else index[b.parent.name] for b in bones]),
                   rest, tails, np.array([b.use_connect for b in bones]), object_world)
    # Blender's pose matrices are float32; composed again in float64 from the keyed values where that is
    # what Blender computes (no constraints, drivers or other inheritance: checked against its own)
    exact = pose_from_basis(arm, basis_matrices(loc, rot, scale))
    size = max(float(np.ptp(rest[:, :3, 3], axis=0).max()), 1e-9)
    if np.abs(exact - pose).max() <= 1e-4 * max(size, 1.0):
        pose = exact
    return arm, world[:, None] @ pose, frames


def _rotation(pb) -> np.ndarray:
    """A pose bone's rotation as a (w, x, y, z) quaternion from its own channels (float64)."""
    mode = pb.rotation_mode
    if mode == "QUATERNION":
        return np.asarray(pb.rotation_quaternion, float)
    if mode == "AXIS_ANGLE":
        angle, *axis = pb.rotation_axis_angle
        n = np.linalg.norm(axis)
        return quat.from_axis_angle(np.asarray(axis) / n, angle) if n > 0 else quat.identity()
    return euler_quaternions(np.asarray(pb.rotation_euler, float), mode)


def read_motion(context):
    """(Armature, Motion, frames) of the active armature's action with the panel's settings."""
    st = context.scene.froude
    arm, pose, frames = sample_armature(context)
    obj, action = active_armature(context)
    joint_map = None
    if st.joint_map.strip():
        joint_map = load_joint_map(bpy.path.abspath(st.joint_map))
    unit = context.scene.unit_settings.scale_length if st.length_unit == "SCENE" else None
    spacing = float(np.diff(frames).mean())  # scene frames per sample
    if abs(spacing / round(spacing) - 1.0) < RATE_ROUNDING:
        # keys a few ppm off whole frames are an importer's rounding of the rate (Blender keeps fps_base in
        # float32, FBX converts times in its own ticks): the scene's rate is the clip's
        spacing = float(round(spacing))
    motion = armature_motion(arm, pose, spacing * scene_frame_time(context.scene), metres_per_unit=unit,
                             joint_map=joint_map, source=f"{obj.name} / {action.name}")
    return arm, motion, frames


# ---- writing a new action ------------------------------------------------------------------------------------
def _channel_values(q: np.ndarray, mode: str) -> tuple[str, np.ndarray]:
    """(pose-bone rotation property, (F, n) values) for (F, 4) quaternions in the bone's rotation mode."""
    from mathutils import Quaternion

    if mode == "QUATERNION":
        return "rotation_quaternion", q
    if mode == "AXIS_ANGLE":
        out = np.empty((len(q), 4))
        for f, qf in enumerate(q):
            axis, angle = Quaternion(qf).to_axis_angle()
            out[f] = (angle, *axis)
        return "rotation_axis_angle", out
    if mode not in EULER_MODES:
        raise FroudeError(f"unknown rotation mode '{mode}'")
    out = np.empty((len(q), 3))
    prev = None
    for f, qf in enumerate(q):  # each Euler triple compatible with the previous one: no 360° flips
        e = Quaternion(qf).to_euler(mode) if prev is None else Quaternion(qf).to_euler(mode, prev)
        out[f] = e
        prev = e
    return "rotation_euler", out


def _fcurve(action, obj, data_path: str, index: int, group: str):
    """A new F-curve on the action for obj's property, grouped under the bone where Blender can."""
    if hasattr(action, "fcurve_ensure_for_datablock"):  # Blender 4.4+: layered actions with slots
        params = action.bl_rna.functions["fcurve_ensure_for_datablock"].parameters
        if "group_name" in params:  # 5.0; 4.4-4.5 have no group here (the curves are then ungrouped)
            return action.fcurve_ensure_for_datablock(obj, data_path, index=index, group_name=group)
        return action.fcurve_ensure_for_datablock(obj, data_path, index=index)
    return action.fcurves.new(data_path, index=index, action_group=group)


def _key(action, obj, data_path: str, frames: np.ndarray, values: np.ndarray, group: str) -> None:
    """Key (F, n) values at scene frames (F,) on the n channels of a property, linear between keys."""
    n = len(frames)
    for i in range(values.shape[1]):
        fc = _fcurve(action, obj, data_path, i, group)
        fc.keyframe_points.add(n)
        fc.keyframe_points.foreach_set("co", np.column_stack([frames, values[:, i]]).astype(np.float32).ravel())
        fc.keyframe_points.foreach_set("interpolation", [1] * n)  # LINEAR: froude's own samples in between
        fc.update()


def write_action(obj, arm: Armature, basis: np.ndarray, frames: np.ndarray, name: str):
    """A new action on ``obj`` keying every bone's basis (F, B, 4, 4) at scene frames (F,), made the active
    one; the previous action keeps a fake user and is not changed. On failure nothing is left behind."""
    loc, q, s = decompose_basis(basis)
    ad = obj.animation_data or obj.animation_data_create()
    old = ad.action
    old_slot = getattr(ad, "action_slot", None)
    action = bpy.data.actions.new(name)
    try:
        ad.action = action
        for b, bone in enumerate(arm.names):
            pb = obj.pose.bones[bone]
            path = f'pose.bones["{bpy.utils.escape_identifier(bone)}"]'
            prop, rot = _channel_values(q[:, b], pb.rotation_mode)
            _key(action, obj, f"{path}.location", frames, loc[:, b], bone)
            _key(action, obj, f"{path}.{prop}", frames, rot, bone)
            _key(action, obj, f"{path}.scale", frames, np.repeat(s[:, b, None], 3, axis=1), bone)
    except BaseException:
        ad.action = old
        if old_slot is not None and old is not None:
            ad.action_slot = old_slot
        bpy.data.actions.remove(action)
        raise
    if old is not None:
        old.use_fake_user = True  # the original stays in the file even with no user
    return action


# ---- the operators -------------------------------------------------------------------------------------------
#: The end of froude's refusal of a speed beyond the human range, in the command line's and the API's terms,
#: and the same in the panel's.
_UNLIMITED_CLI = "; --unlimited (unlimited=True) lifts it"
_UNLIMITED_PANEL = "; tick Unlimited to lift it"


def _one_line(e: BaseException) -> str:
    text = (" ".join(str(e).split()) or type(e).__name__).replace(_UNLIMITED_CLI, _UNLIMITED_PANEL)
    return text if isinstance(e, (FroudeError, OSError, ValueError)) else f"internal error (a bug): {text}"


class _Progress:
    """Blender's progress indicator and a status-bar line while froude works."""

    def __init__(self, context, what: str):
        self.wm, self.ws, self.what = context.window_manager, getattr(context, "workspace", None), what
        self.wm.progress_begin(0, 100)

    def step(self, percent: int, doing: str) -> None:
        self.wm.progress_update(percent)
        if self.ws is not None:
            self.ws.status_text_set(f"froude {self.what}: {doing}")

    def end(self) -> None:
        self.wm.progress_end()
        if self.ws is not None:
            self.ws.status_text_set(None)


def typed(value: float) -> float:
    """The number the user typed into a float property: Blender keeps float32 (1.2 is 1.2000000477), so the
    shortest decimal that is the same float32 (froude's answers to 1.2 and to 1.2000000477 differ)."""
    return float(np.format_float_positional(np.float32(value), unique=True, trim="0"))


def _character_kwargs(st) -> dict:
    """froude.scale/accelerate's character arguments (and ``unlimited``) from the panel (0 = not given)."""
    kw: dict[str, Any] = {"character": None if st.character == SAME_BODY else st.character,
                          "unlimited": st.unlimited}
    if st.height_m > 0:
        kw["height"] = typed(st.height_m)
    if st.character_mass_kg > 0:
        kw["character_mass"] = typed(st.character_mass_kg)
    return kw


def _report_rows(res, action_name: str) -> list[list[str]]:
    r = res.report
    fails = r.check_bars()

    def f(v, spec, unit=""):
        return "n/a" if v is None or not math.isfinite(v) else f"{format(v, spec)}{unit}"

    return [["new action", action_name],
            ["frames", f"{r.n_frames} at {r.frame_rate_hz:.1f} Hz"],
            ["speed", f(r.mean_speed_m_s, ".2f", " m/s") + f"  (U = {f(r.froude_U, '.3f')})"],
            ["cadence", f(r.step_frequency_hz, ".2f", " steps/s")],
            ["COM tracking", f(r.com_tracking_rms_mm, ".1f", " mm RMS")],
            ["foot skate", f(r.foot_skate_floor_mm, ".1f", " mm")],
            ["physics bars", "all met" if not fails else "NOT met: " + "; ".join(fails)]]


class _FroudeOperator(bpy.types.Operator):
    """Shared run: read the armature, call froude, write the new action; one-line errors, scene untouched."""

    bl_options = {"REGISTER", "UNDO"}
    what = ""

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "ARMATURE"

    def compute(self, context, motion):  # -> api.Result
        raise NotImplementedError

    def label(self, st) -> str:
        raise NotImplementedError

    def execute(self, context):
        st = context.scene.froude
        st.error = st.report_json = ""
        progress = _Progress(context, self.what)
        try:
            progress.step(5, "reading the action")
            arm, motion, frames = read_motion(context)
            progress.step(30, "fitting and synthesising")
            res = self.compute(context, motion)
            fails = res.report.check_bars()
            if fails and not st.keep:
                raise FroudeError(f"the output misses physics bars ({'; '.join(fails)}); tick Keep to write it "
                                  "anyway")
            progress.step(80, "writing the new action")
            obj, action = active_armature(context)
            basis = armature_basis(arm, motion, res.motion)
            step = res.motion.frame_time / scene_frame_time(context.scene)
            first = frames[int(motion.meta.get("first_frame", 0))]
            keys = first + step * np.arange(res.motion.n_frames)
            new = write_action(obj, arm, basis, keys, f"{action.name} froude {self.label(st)}")
            st.report_json = json.dumps(_report_rows(res, new.name))
        except Exception as e:  # noqa: BLE001 - every failure is one line in the panel, never a traceback
            st.error = _one_line(e)
            self.report({"ERROR"}, st.error)
            return {"CANCELLED"}
        finally:
            progress.end()
        self.report({"INFO"}, f"froude: wrote action '{new.name}'")
        return {"FINISHED"}


class FROUDE_OT_scale(_FroudeOperator):
    """Rescale the active action to another character and speed (froude.scale) as a new action"""

    bl_idname = "froude.scale"
    bl_label = "Scale"
    what = "scale"

    def compute(self, context, motion):
        st = context.scene.froude
        return froude.scale(motion, speed=typed(st.speed_factor), strides=st.strides, reference_mass=typed(st.mass_kg),
                            **_character_kwargs(st))

    def label(self, st) -> str:
        who = "same body" if st.character == SAME_BODY else st.character
        return f"{who} x{st.speed_factor:.2f}"


class FROUDE_OT_accelerate(_FroudeOperator):
    """Speed the active action up or slow it down over some steps (froude.accelerate) as a new action"""

    bl_idname = "froude.accelerate"
    bl_label = "Accelerate"
    what = "accelerate"

    def compute(self, context, motion):
        st = context.scene.froude
        return froude.accelerate(motion, to_factor=typed(st.to_factor), steps=st.steps,
                                 reference_mass=typed(st.mass_kg),
                                 **_character_kwargs(st))

    def label(self, st) -> str:
        return f"to x{st.to_factor:.2f} in {st.steps} steps"


class FROUDE_OT_info(bpy.types.Operator):
    """What froude sees in the active action (froude info); foot contacts as timeline markers"""

    bl_idname = "froude.info"
    bl_label = "Analyse"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return _FroudeOperator.poll(context)

    def execute(self, context):
        st = context.scene.froude
        st.error = ""
        progress = _Progress(context, "info")
        try:
            progress.step(10, "reading the action")
            _, motion, frames = read_motion(context)
            progress.step(50, "analysing")
            d = froude.info(motion, mass=typed(st.mass_kg))
        except Exception as e:  # noqa: BLE001 - one line in the panel
            st.error = _one_line(e)
            self.report({"ERROR"}, st.error)
            return {"CANCELLED"}
        finally:
            progress.end()
        st.info_json = json.dumps(d)
        markers = context.scene.timeline_markers
        for m in [m for m in markers if m.name.startswith(MARKER_PREFIX)]:
            markers.remove(m)
        if st.mark_contacts:
            first = frames[int(motion.meta.get("first_frame", 0))]
            step = motion.frame_time / scene_frame_time(context.scene)
            for c in d["contacts"]:
                markers.new(f"{MARKER_PREFIX}{c['foot'][0].upper()}",
                            frame=int(round(first + c["start_s"] / motion.frame_time * step)))
        self.report({"INFO"}, f"froude: {d['kind']}, {d['mean_speed_m_s']:.2f} m/s")
        return {"FINISHED"}


# ---- the panel ---------------------------------------------------------------------------------------------------
def info_rows(d: dict) -> list[tuple[str, str]]:
    """The panel's lines for a ``froude.info`` dict."""
    sk = d["skeleton"]

    def n(v, spec, unit=""):
        return "n/a" if v is None else f"{format(v, spec)}{unit}"

    rows = [("units", str(sk["units"])),
            ("height / leg", f"{n(sk['height_m'], '.3f')} / {n(sk['leg_length_m'], '.3f')} m"),
            ("motion", f"{d['kind']}: {d['verdict']}"),
            ("speed", f"{n(d['mean_speed_m_s'], '.2f', ' m/s')}  (U = {n(d['froude_U'], '.3f')})"),
            ("cadence", n(d["step_frequency_hz"], ".2f", " steps/s")),
            ("contacts", " ".join(c["foot"][0].upper() for c in d["contacts"]) or "none")]
    rows += [("cleaning", c) for c in d.get("cleaning", ())]
    return rows


class FROUDE_PT_panel(bpy.types.Panel):
    """froude in the 3D view's sidebar."""

    bl_label = "froude"
    bl_idname = "FROUDE_PT_panel"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "froude"

    def draw(self, context):
        layout = self.layout
        st = context.scene.froude
        obj = context.active_object
        if obj is None or obj.type != "ARMATURE":
            layout.label(text="Select an armature with an action", icon="INFO")
            return
        action = obj.animation_data.action if obj.animation_data else None
        layout.label(text=f"{obj.name}: {action.name if action else 'no action'}", icon="ARMATURE_DATA")
        col = layout.column(align=True)
        col.prop(st, "length_unit")
        col.prop(st, "joint_map")
        col.prop(st, "mass_kg")
        col.prop(st, "mark_contacts")
        layout.operator(FROUDE_OT_info.bl_idname, icon="VIEWZOOM")
        if st.info_json:
            box = layout.box()
            for k, v in info_rows(json.loads(st.info_json)):
                box.label(text=f"{k}: {v}")
        box = layout.box()
        box.label(text="Character")
        box.prop(st, "character")
        box.prop(st, "height_m")
        box.prop(st, "character_mass_kg")
        box.prop(st, "keep")
        box.prop(st, "unlimited")
        box = layout.box()
        box.prop(st, "speed_factor")
        box.prop(st, "strides")
        box.operator(FROUDE_OT_scale.bl_idname, icon="CON_SIZELIKE")
        box = layout.box()
        box.prop(st, "to_factor")
        box.prop(st, "steps")
        box.operator(FROUDE_OT_accelerate.bl_idname, icon="FF")
        if st.report_json:
            box = layout.box()
            for k, v in json.loads(st.report_json):
                box.label(text=f"{k}: {v}")
        if st.error:
            layout.label(text=st.error, icon="ERROR")


def _character_items(self, context):
    return [(SAME_BODY, "Same body", "the action's own body")] + [(p, p, f"froude's '{p}' preset")
                                                                  for p in list_presets()]


def _settings_class():
    """The scene's froude settings (``scene.froude``), built here so the annotations stay Blender's own."""
    P = bpy.props
    annotations = {
        "length_unit": P.EnumProperty(
            name="Units", description="Metres per Blender unit",
            items=[("SCENE", "Scene", "the scene's unit scale (Scene > Units > Unit Scale)"),
                   ("DETECT", "Detect", "detected from the motion, as froude info does for a file")]),
        "joint_map": P.StringProperty(name="Joint map", subtype="FILE_PATH",
                                      description="YAML 'role: BoneName' for bone names froude does not know"),
        "mass_kg": P.FloatProperty(name="Performer mass [kg]", default=70.0, min=1.0, max=5000.0),
        "mark_contacts": P.BoolProperty(name="Contacts on the timeline", default=True,
                                        description="Analyse puts a marker at each foot's touchdown"),
        "character": P.EnumProperty(name="Preset", items=_character_items),
        "height_m": P.FloatProperty(name="Height [m] (0: preset's)", default=0.0, min=0.0, max=10.0),
        "character_mass_kg": P.FloatProperty(name="Mass [kg] (0: preset's)", default=0.0, min=0.0, max=5000.0),
        "keep": P.BoolProperty(name="Keep", default=False,
                               description="write the new action even when it misses a physics bar"),
        "unlimited": P.BoolProperty(name="Unlimited", default=False,
                                    description="allow speeds beyond what a human of the character's size runs"),
        "speed_factor": P.FloatProperty(name="Speed ×", default=1.0, min=0.05, max=10.0,
                                        description="factor on the character's dynamically scaled speed"),
        "strides": P.IntProperty(name="Strides", default=4, min=1, max=100),
        "to_factor": P.FloatProperty(name="To speed ×", default=1.3, min=0.05, max=10.0,
                                     description="the end speed as a factor of the start speed"),
        "steps": P.IntProperty(name="Steps", default=8, min=1, max=100),
        "info_json": P.StringProperty(options={"HIDDEN", "SKIP_SAVE"}),
        "report_json": P.StringProperty(options={"HIDDEN", "SKIP_SAVE"}),
        "error": P.StringProperty(options={"HIDDEN", "SKIP_SAVE"}),
    }
    return type("FroudeSettings", (bpy.types.PropertyGroup,), {"__annotations__": annotations})


_CLASSES: list[Any] = []


def register() -> None:
    """Register the settings, the operators and the panel (Blender calls this when the add-on is enabled)."""
    if _CLASSES:
        return
    _CLASSES[:] = [_settings_class(), FROUDE_OT_info, FROUDE_OT_scale, FROUDE_OT_accelerate, FROUDE_PT_panel]
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.froude = bpy.props.PointerProperty(type=_CLASSES[0])


def unregister() -> None:
    del bpy.types.Scene.froude
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
    _CLASSES.clear()


__all__ = ["FROUDE_OT_accelerate", "FROUDE_OT_info", "FROUDE_OT_scale", "FROUDE_PT_panel", "Path", "info_rows",
           "read_motion", "register", "sample_armature", "unregister", "write_action"]
