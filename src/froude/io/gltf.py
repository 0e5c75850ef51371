"""glTF 2.0 / GLB: a Motion as a skinned, animated skeleton (and back), with an optional mannequin mesh.

Conventions match froude's and glTF's alike: metres, +Y up, right-handed. Each joint is a node whose
translation is its rest offset [m] (the root's and any joint with position channels are animated) and
whose rotation is animated from the local quaternions; a joint's world transform is then
parent · T(offset) · R(local), exactly the BVH forward kinematics (``kinematics.fk``). The skin lists every
joint with the inverse of its rest-pose world matrix (every rotation identity, the root at its offset:
``Skeleton.rest_positions`` shifted by the root offset), the pose the mannequin is modelled in.

The mannequin is one octahedral "bone" per parent→child segment (and per end site), each skinned rigidly
to the parent joint, so the file shows a body in any viewer. BVH channel orders and the frame rate are kept
in the scene's ``extras`` so that reading a froude file gives back the same BVH layout.

pygltflib (the optional extra ``froude[gltf]``) is imported inside the functions.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..core import quat
from ..core.kinematics import fk
from ..core.motion import Motion
from ..core.rig import is_end_bone, placeholder_end
from ..core.skeleton import Skeleton
from ..errors import FroudeError
from .atomic import atomic_write
from .bvh import synthetic_pose_frame

#: glTF component types and accessor types used here.
_FLOAT, _USHORT, _UINT, _UBYTE = 5126, 5123, 5125, 5121
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
#: Thickness of the mannequin's bones as a fraction of their length (and at least this many metres).
BONE_WIDTH_FRACTION = 0.12
BONE_MIN_WIDTH_M = 0.01
EXTRAS_KEY = "froude"


def _require_pygltflib():
    try:
        import pygltflib
    except ImportError:
        raise FroudeError("glTF/GLB files need pygltflib: pip install 'froude[gltf]'") from None
    return pygltflib


class _Blob:
    """One binary buffer built view by view (each view 4-byte aligned, as glTF requires)."""

    def __init__(self, gl, pyg):
        self.gl = gl
        self._pyg = pyg  # the pygltflib module (imported by the caller, inside the function)
        self.data = bytearray()

    def add(self, array: np.ndarray, component: int, kind: str, target=None, minmax: bool = False) -> int:
        """Append array as a bufferView + accessor; returns the accessor index."""
        gl = self.gl
        arr = np.ascontiguousarray(array)
        while len(self.data) % 4:
            self.data.append(0)
        offset = len(self.data)
        self.data += arr.tobytes()
        gl.bufferViews.append(self._pyg.BufferView(buffer=0, byteOffset=offset, byteLength=arr.nbytes, target=target))
        count = arr.shape[0]
        acc = self._pyg.Accessor(bufferView=len(gl.bufferViews) - 1, componentType=component, count=count, type=kind)
        if minmax:
            flat = arr.reshape(count, -1)
            acc.min = [float(x) for x in flat.min(axis=0)]
            acc.max = [float(x) for x in flat.max(axis=0)]
        gl.accessors.append(acc)
        return len(gl.accessors) - 1


def _rest_world(skeleton: Skeleton) -> np.ndarray:
    """(J, 4, 4) rest-pose world matrices: identity rotations, root at its offset (as the nodes' rest)."""
    p = skeleton.rest_positions() + skeleton.offsets[0]
    m = np.tile(np.eye(4), (skeleton.n_joints, 1, 1))
    m[:, :3, 3] = p
    return m


def mannequin(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A simple body for the rest pose: one octahedron per bone (parent→child and joint→end site).

    Returns vertices (V, 3) [m] in the rest pose (root at its offset), triangles (T, 3) int and the joint
    each vertex follows (V,) int (rigid skinning to the bone's parent joint).
    """
    rest = skeleton.rest_positions() + skeleton.offsets[0]
    segs = [(int(skeleton.parents[j]), rest[skeleton.parents[j]], rest[j]) for j in range(1, skeleton.n_joints)]
    segs += [(j, rest[j], rest[j] + np.asarray(off)) for j, off in skeleton.end_sites]
    verts: list[np.ndarray] = []
    tris: list[tuple[int, int, int]] = []
    joints: list[int] = []
    for joint, a, b in segs:
        d = b - a
        length = float(np.linalg.norm(d))
        if length < 1e-6:
            continue
        u = d / length
        # two directions across the bone
        helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
        s = np.cross(u, helper)
        s /= np.linalg.norm(s)
        t = np.cross(u, s)
        w = max(BONE_WIDTH_FRACTION * length, BONE_MIN_WIDTH_M) / 2.0
        mid = a + 0.2 * d
        base = len(verts)
        verts += [a, mid + w * s, mid + w * t, mid - w * s, mid - w * t, b]
        joints += [joint] * 6
        ring = [1, 2, 3, 4]
        for k in range(4):
            r0, r1 = ring[k], ring[(k + 1) % 4]
            tris += [(base, base + r1, base + r0), (base + 5, base + r0, base + r1)]
    return np.array(verts, float).reshape(-1, 3), np.array(tris, np.int64).reshape(-1, 3), np.array(joints, np.int64)


def gltf_document(motion: Motion, *, mesh: bool = True):
    """The pygltflib.GLTF2 document of a motion (binary data set as its blob)."""
    pyg = _require_pygltflib()
    sk = motion.skeleton
    J, F = sk.n_joints, motion.n_frames
    for name, arr in (("root positions", motion.root_positions), ("rotations", motion.rotations)):
        if not np.all(np.isfinite(arr)):
            raise FroudeError(f"the motion's {name} hold non-finite values: nothing written")
    gl = pyg.GLTF2(asset=pyg.Asset(version="2.0", generator="froude"))
    blob = _Blob(gl, pyg)
    gl.buffers.append(pyg.Buffer(byteLength=0))

    # joint nodes (node j = joint j), the hierarchy
    rot_xyzw = np.roll(motion.continuous().rotations, -1, axis=-1)  # glTF quaternions are (x, y, z, w)
    rot_xyzw /= np.linalg.norm(rot_xyzw, axis=-1, keepdims=True)
    for j in range(J):
        t = motion.root_positions[0] if j == 0 else (
            motion.translations[0, j] if motion.translations is not None else sk.offsets[j])
        node = pyg.Node(name=sk.names[j], translation=[float(x) for x in t],
                        rotation=[float(x) for x in rot_xyzw[0, j]])
        node.children = sk.children(j)
        gl.nodes.append(node)
    scene_nodes = [0]

    # animation: root translation, every joint's rotation, translations of joints with position channels
    times = (np.arange(F) * motion.frame_time).astype(np.float32)
    anim = pyg.Animation(name=Path(str(motion.meta.get("source") or "motion")).stem or "motion")
    t_acc = blob.add(times, _FLOAT, "SCALAR", minmax=True)

    def channel(node: int, path: str, values: np.ndarray, kind: str):
        out = blob.add(values.astype(np.float32), _FLOAT, kind)
        anim.samplers.append(pyg.AnimationSampler(input=t_acc, output=out, interpolation="LINEAR"))
        anim.channels.append(pyg.AnimationChannel(sampler=len(anim.samplers) - 1,
                                                  target=pyg.AnimationChannelTarget(node=node, path=path)))

    channel(0, "translation", motion.root_positions, "VEC3")
    for j in range(J):
        channel(j, "rotation", rot_xyzw[:, j], "VEC4")
    if motion.translations is not None:
        for j in range(1, J):
            if sk.has_translation_channels(j):
                channel(j, "translation", motion.translations[:, j], "VEC3")
    gl.animations.append(anim)

    # skin: every joint, inverse bind matrices of the rest pose (column-major, as glTF stores matrices)
    ibm = np.linalg.inv(_rest_world(sk)).transpose(0, 2, 1).astype(np.float32)
    skin = pyg.Skin(name="skeleton", joints=list(range(J)), skeleton=0,
                    inverseBindMatrices=blob.add(ibm.reshape(J, 16), _FLOAT, "MAT4"))
    gl.skins.append(skin)

    if mesh:
        verts, tris, vjoint = mannequin(sk)
        pos = blob.add(verts.astype(np.float32), _FLOAT, "VEC3", _ARRAY_BUFFER, minmax=True)
        jt = np.zeros((len(verts), 4), np.uint16 if J > 255 else np.uint8)
        jt[:, 0] = vjoint
        wt = np.zeros((len(verts), 4), np.float32)
        wt[:, 0] = 1.0
        j_acc = blob.add(jt, _USHORT if J > 255 else _UBYTE, "VEC4", _ARRAY_BUFFER)
        w_acc = blob.add(wt, _FLOAT, "VEC4", _ARRAY_BUFFER)
        idx_dtype, idx_type = (np.uint16, _USHORT) if len(verts) < 65535 else (np.uint32, _UINT)
        i_acc = blob.add(tris.astype(idx_dtype).reshape(-1), idx_type, "SCALAR", _ELEMENT_ARRAY_BUFFER)
        prim = pyg.Primitive(attributes=pyg.Attributes(POSITION=pos, JOINTS_0=j_acc, WEIGHTS_0=w_acc), indices=i_acc)
        gl.meshes.append(pyg.Mesh(name="mannequin", primitives=[prim]))
        gl.nodes.append(pyg.Node(name="mannequin", mesh=0, skin=0))
        scene_nodes.append(len(gl.nodes) - 1)

    gl.scenes.append(pyg.Scene(name="froude", nodes=scene_nodes, extras={EXTRAS_KEY: {
        "channels": [list(c) for c in sk.channels],
        "end_sites": [[int(j), [float(x) for x in off]] for j, off in sk.end_sites],
        "frame_time_s": float(motion.frame_time),
        "units": "m, +Y up",
    }}))
    gl.scene = 0
    while len(blob.data) % 4:
        blob.data.append(0)
    gl.buffers[0].byteLength = len(blob.data)
    gl.set_binary_blob(bytes(blob.data))
    return gl


def save_gltf(motion: Motion, path: str | os.PathLike, *, mesh: bool = True) -> Path:
    """Write ``motion`` as ``.glb`` (binary) or ``.gltf`` (JSON, data embedded) atomically; returns the path.

    mesh: include the mannequin (False: skeleton and animation only).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".glb", ".gltf"):
        raise FroudeError(f"{path}: a glTF output ends in .glb or .gltf")
    gl = gltf_document(motion, mesh=mesh)

    def write(tmp: str) -> None:
        if suffix == ".glb":
            gl.save_binary(tmp)
        else:
            pyg = _require_pygltflib()
            gl.convert_buffers(pyg.BufferFormat.DATAURI)
            gl.save_json(tmp)

    return atomic_write(path, write)


# ---- reading ------------------------------------------------------------------------------------------
def _accessor_array(gl, index: int) -> np.ndarray:
    """An accessor's data as a float array (count, n)."""
    acc = gl.accessors[index]
    view = gl.bufferViews[acc.bufferView]
    n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc.type]
    dtype = {_FLOAT: np.float32, _USHORT: np.uint16, _UINT: np.uint32, _UBYTE: np.uint8, 5120: np.int8,
             5122: np.int16}[acc.componentType]
    data = gl.get_data_from_buffer_uri(gl.buffers[view.buffer].uri) if gl.buffers[view.buffer].uri else gl.binary_blob()
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    stride = view.byteStride or n * np.dtype(dtype).itemsize
    raw = np.frombuffer(data, np.uint8, count=stride * (acc.count - 1) + n * np.dtype(dtype).itemsize, offset=start)
    rows = np.lib.stride_tricks.as_strided(raw, shape=(acc.count, n * np.dtype(dtype).itemsize), strides=(stride, 1))
    return np.ascontiguousarray(rows).view(dtype).reshape(acc.count, n).astype(float)


#: Node and animated scales within this of 1 are rounding (Blender writes 0.99999994); others are refused.
SCALE_TOLERANCE = 1e-4


def _node_matrix(node) -> np.ndarray:
    """(4, 4) a glTF node's local transform T · R · S (or its matrix)."""
    if node.matrix:
        return np.array(node.matrix, float).reshape(4, 4).T  # column-major in the file

    m = np.eye(4)
    x, y, z, w = node.rotation or [0.0, 0.0, 0.0, 1.0]
    m[:3, :3] = quat.to_matrix(quat.normalize(np.array([w, x, y, z], float))) * np.array(node.scale or [1, 1, 1])
    m[:3, 3] = node.translation or [0.0, 0.0, 0.0]
    return m


def _above_root(gl, root_node: int) -> np.ndarray:
    """(4, 4) the world transform of the nodes above the skeleton's root (an exporter's armature node)."""
    parent = {c: i for i, n in enumerate(gl.nodes) for c in (n.children or [])}
    m = np.eye(4)
    k = parent.get(root_node)
    while k is not None:
        m = _node_matrix(gl.nodes[k]) @ m
        k = parent.get(k)
    return m


def _frame_time(tracks: dict, extras: dict, fps: float | None) -> tuple[float, str]:
    """(seconds per frame, how it was chosen): the caller's fps, a froude file's own, else the animation's
    key spacing when every track is sampled at the same even times (exporters bake every frame), else 30 Hz."""
    if fps:
        return 1.0 / fps, "given"
    if "frame_time_s" in extras:
        return float(extras["frame_time_s"]), "the file's"
    times = [t for t, _, _ in tracks.values() if len(t) > 2]
    if times:
        t = max(times, key=len)
        step = np.diff(t)
        if step.min() > 0 and np.abs(step - np.median(step)).max() <= 1e-3 * np.median(step):
            return float(np.median(step)), "the animation's key spacing"
    return 1.0 / 30.0, "30 Hz (default: the keys are not evenly spaced)"


def _end_node_sites(motion: Motion, gl, joints: list, end_nodes: set, parents: np.ndarray, new: dict,
                    scale: float) -> tuple[tuple[int, np.ndarray], ...]:
    """End sites (joint index, offset [m] in its frame) from an exporter's chain-end nodes, leaving out the
    placeholders an importer invented (``core.rig.placeholder_end``).
    scale: the uniform scale of the nodes above the skeleton."""
    # judged in the rest pose (the nodes' own rotations), where an importer's copy lies along its parent bone
    kept = sorted(new, key=lambda k: new[k])
    rest_rot = np.array([gl.nodes[joints[k]].rotation or [0.0, 0.0, 0.0, 1.0] for k in kept])
    rest = motion[:1].with_(rotations=quat.normalize(np.roll(rest_rot, 1, axis=-1))[None], translations=None)
    p, R = fk(rest)
    size = float(np.ptp(p[0], axis=0).max())
    out = {}
    for k in sorted(end_nodes, key=lambda k: new[parents[k]]):
        j = new[parents[k]]
        off = scale * np.array(gl.nodes[joints[k]].translation or [0.0, 0.0, 0.0], float)
        pj = motion.skeleton.parents[j]
        bone = p[0, j] - p[0, pj] if pj >= 0 else np.zeros(3)
        if j not in out and not placeholder_end(R[0, j] @ off, bone, size):
            out[j] = off
    return tuple(out.items())


def _read_document(path: Path):
    """The parsed glTF document of path (pygltflib's GLTF2) with at least one skin; FroudeError otherwise."""
    pyg = _require_pygltflib()
    import warnings

    try:
        with warnings.catch_warnings():  # pygltflib warns, then fails or returns None, on a foreign file
            warnings.simplefilter("ignore")
            gl = pyg.GLTF2().load(str(path))
    except Exception as e:  # noqa: BLE001 - pygltflib raises many kinds on a bad file
        first = (str(e).splitlines() or [""])[0]
        raise FroudeError(f"{path}: not a readable glTF file ({type(e).__name__}: {first})") from None
    if gl is None or not gl.skins:
        raise FroudeError(f"{path}: no skin (skeleton) in this glTF file")
    return gl


def _skin_tree(gl, path: Path):
    """The first skin's joint tree: (joints: node of each skin joint k, index: node -> k, parents (K,) skin
    index of each joint's parent or -1, end_nodes: the chain-end leaves read as end sites, order: the kept
    joints depth-first with parents first (froude's Skeleton needs parents[j] < j), new: k -> froude index).
    FroudeError unless the joints form one tree."""
    joints = list(gl.skins[0].joints)
    index = {node: k for k, node in enumerate(joints)}
    parents = np.full(len(joints), -1)
    for k, node in enumerate(joints):
        for c in gl.nodes[node].children or []:
            if c in index:
                parents[index[c]] = k
    # an exporter's chain-end leaves (Blender's "_leaf", "_end") are end sites, not joints
    has_child = np.zeros(len(joints), bool)
    has_child[parents[parents >= 0]] = True
    end_nodes = {k for k in range(len(joints))
                 if parents[k] >= 0 and not has_child[k] and is_end_bone(gl.nodes[joints[k]].name or "")}
    roots = [k for k in range(len(joints)) if parents[k] < 0]
    if len(roots) != 1:
        raise FroudeError(f"{path}: the skin's joints form {len(roots)} trees; froude needs one skeleton root")
    order = []

    def visit(k):
        order.append(k)
        for c in gl.nodes[joints[k]].children or []:
            if c in index and index[c] not in end_nodes:
                visit(index[c])

    visit(roots[0])
    new = {k: i for i, k in enumerate(order)}
    return joints, index, parents, end_nodes, order, new


def _rest_pose(nodes, path: Path):
    """(offsets (J, 3) [m], rest rotations (J, 4) glTF (x, y, z, w)) of the joints' nodes; FroudeError for
    joints with scale or matrix transforms."""
    offsets = np.array([n.translation or [0.0, 0.0, 0.0] for n in nodes], float)
    rest_rot = np.array([n.rotation or [0.0, 0.0, 0.0, 1.0] for n in nodes], float)
    if any(n.matrix for n in nodes) or any(
            n.scale and np.abs(np.array(n.scale, float) - 1.0).max() > SCALE_TOLERANCE for n in nodes):
        raise FroudeError(f"{path}: joints with scale or matrix transforms are not supported")
    return offsets, rest_rot


def _animation_tracks(gl, index: dict, new: dict, path: Path):
    """(tracks: (froude joint, "rotation" | "translation") -> (key times (k,) [s], values (k, 3 or 4),
    interpolation), first key time [s], last key time [s]) of the first animation's channels on skin joints.
    FroudeError without an animation, or for an animated joint scale."""
    if not gl.animations:
        raise FroudeError(f"{path}: no animation in this glTF file")
    anim = gl.animations[0]
    tracks = {}
    t_end, t_start = 0.0, np.inf
    for ch in anim.channels:
        node = ch.target.node
        if node not in index:
            continue
        if ch.target.path not in ("rotation", "translation", "scale"):
            continue
        s = anim.samplers[ch.sampler]
        t = _accessor_array(gl, s.input)[:, 0]
        v = _accessor_array(gl, s.output)
        if s.interpolation == "CUBICSPLINE":
            v = v.reshape(len(t), 3, -1)[:, 1]
        if ch.target.path == "scale":
            if np.abs(v - 1.0).max() > SCALE_TOLERANCE:
                raise FroudeError(f"{path}: animated joint scale is not supported (node '{gl.nodes[node].name}')")
            continue
        tracks[(new[index[node]], ch.target.path)] = (t, v, s.interpolation or "LINEAR")
        t_end, t_start = max(t_end, float(t[-1])), min(t_start, float(t[0]))
    return tracks, t_start, t_end


def _sample_track(tracks: dict, key, default, times):
    """(n, c) values of track key at times (n,) [s] (STEP held, else linear); default (c,) where the joint has
    no such track."""
    n = len(times)
    if key not in tracks:
        return np.broadcast_to(default, (n, len(default))).copy()
    t, v, interp = tracks[key]
    if interp == "STEP":
        return v[np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 1)]
    return np.stack([np.interp(times, t, v[:, c]) for c in range(v.shape[1])], axis=1)


def _sampled_pose(tracks: dict, times, offsets, rest_rot):
    """(rotations (n, J, 4) froude (w, x, y, z), root position (n, 3) [m], joints with animated translation,
    their translations (n, J, 3) [m] or None) of the tracks at times (n,) [s]."""
    n, J = len(times), len(offsets)
    rot = np.empty((n, J, 4))
    for j in range(J):
        q = _sample_track(tracks, (j, "rotation"), rest_rot[j], times)  # (x, y, z, w), linear then normalised
        rot[:, j] = quat.normalize(np.roll(q, 1, axis=-1))
    root = _sample_track(tracks, (0, "translation"), offsets[0], times)
    moving = [j for j in range(1, J) if (j, "translation") in tracks]
    translations = None
    if moving:
        translations = np.broadcast_to(offsets, (n, J, 3)).copy()
        for j in moving:
            translations[:, j] = _sample_track(tracks, (j, "translation"), offsets[j], times)
    return rot, root, moving, translations


def _apply_above_root(above, root, rot, offsets, translations, path: Path):
    """The pose with the transform (4, 4) of the nodes above the skeleton's root applied to its root (an
    exporter's armature node: rotation and uniform scale): (root (n, 3) [m], rot (n, J, 4), offsets (J, 3)
    [m], translations, that scale). FroudeError for a sheared or unevenly scaled transform."""
    if np.allclose(above, np.eye(4), atol=1e-9):
        return root, rot, offsets, translations, 1.0
    lin = above[:3, :3]
    scale = float(np.cbrt(np.linalg.det(lin)))
    R = lin / scale
    if scale <= 0 or np.abs(R @ R.T - np.eye(3)).max() > SCALE_TOLERANCE:
        raise FroudeError(f"{path}: the skeleton's parent node is sheared or scaled unevenly")
    root = root @ lin.T + above[:3, 3]
    rot[:, 0] = quat.mul(quat.from_matrix(R), rot[:, 0])
    offsets = offsets * scale
    offsets[0] = root[0]
    if translations is not None:
        translations = translations * scale
    return root, rot, offsets, translations, scale


def _channels(saved_channels, J: int, moving: list) -> tuple:
    """The BVH channel names of each of the J joints: froude's saved ones, or ZYX rotations (and positions on
    the root and the joints with animated translation)."""
    if saved_channels and len(saved_channels) == J:
        return tuple(tuple(c) for c in saved_channels)
    pos = ("Xposition", "Yposition", "Zposition")
    rotc = ("Zrotation", "Yrotation", "Xrotation")
    return tuple(pos + rotc if j == 0 or j in moving else rotc for j in range(J))


def _cleaned(raw: Motion, clean: bool) -> tuple[Motion, tuple[str, ...]]:
    """raw with a synthetic pose first frame dropped (with clean) as ``read_bvh`` drops it, and the sentences
    saying so."""
    why = synthetic_pose_frame(raw.rotations) if clean and raw.n_frames > 2 else None
    if not why:
        return raw, ()
    return raw.cut(1), (f"dropped frame 0: {why}",)


def read_gltf(path: str | os.PathLike, *, fps: float | None = None, clean: bool = True) -> Motion:
    """The first skin's skeleton and the first animation of a .glb/.gltf file as a Motion in the file's
    units (glTF's: metres) and axes (glTF's: +Y up); ``froude.body.load.load_gltf`` reads it as ``froude.load``
    reads a BVH file (the conventions of ``body.conventions.understand``).

    The skeleton's offsets are the joints' rest translations (glTF's units); animated rotations (and the
    root's translation) become the motion; the transform of the nodes above the skeleton's root (an
    exporter's armature node: Blender's, with its object's rotation and scale) is applied to the root.
    fps: sampling rate (default: the file's own for froude files, else the animation's key spacing when it
    is even, else 30 Hz); channel orders come from froude's extras or default to ZYX rotations. A
    synthetic pose first frame is dropped as ``read_bvh`` does unless clean=False. Joints' rest rotations
    (bind orientations) are kept.
    meta: source (the path), conventions (a sentence saying how the frame rate was found), cleaning.
    Raises FroudeError (one line) for files froude cannot read as a skeletal animation.
    """
    path = Path(path)
    gl = _read_document(path)
    joints, index, parents, end_nodes, order, new = _skin_tree(gl, path)
    nodes = [gl.nodes[joints[k]] for k in order]
    J = len(order)
    par = np.array([-1 if parents[k] < 0 else new[parents[k]] for k in order])
    offsets, rest_rot = _rest_pose(nodes, path)
    extras = (gl.scenes[gl.scene or 0].extras or {}).get(EXTRAS_KEY, {}) if gl.scenes else {}
    saved_channels = extras.get("channels")
    tracks, t_start, t_end = _animation_tracks(gl, index, new, path)
    frame_time, rate_how = _frame_time(tracks, extras, fps)
    # from the first key (Blender's exporter puts scene frame 1 at 1/fps), not from zero
    t_start = min(t_start, t_end)
    n = int(round((t_end - t_start) / frame_time)) + 1
    times = t_start + np.arange(n) * frame_time
    rot, root, moving, translations = _sampled_pose(tracks, times, offsets, rest_rot)
    root, rot, offsets, translations, above_scale = _apply_above_root(
        _above_root(gl, joints[order[0]]), root, rot, offsets, translations, path)
    channels = _channels(saved_channels, J, moving)
    ends = tuple((int(j), np.asarray(off, float)) for j, off in extras.get("end_sites", ())) if saved_channels else ()
    names = tuple(n.name or f"joint{k}" for k, n in enumerate(nodes))
    skel = Skeleton(names, par, offsets, channels, ends)
    raw = Motion(skel, root, rot, frame_time, translations)
    if end_nodes and not ends:
        raw = raw.with_(skeleton=skel.with_(end_sites=_end_node_sites(raw, gl, joints, end_nodes, parents, new,
                                                                     above_scale)))
    rate_note = f"frame rate {1 / frame_time:.6g} Hz ({rate_how})"
    raw, cleaning = _cleaned(raw, clean)
    return raw.with_(meta={"source": str(path), "conventions": (rate_note,), "cleaning": cleaning})
