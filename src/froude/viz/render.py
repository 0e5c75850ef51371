"""Renders of motions: capsule figures in filmstrips (the paper's Fig. 3), stills, GIF and MP4 videos.

A figure is drawn as thick round-capped lines along the skeleton's bones ("capsules"), a disc for the
head, a soft shadow on the ground and a ground line (side camera) or ground grid (three-quarter, front).
Limbs are shaded by side: the side away from the camera darker, the near side lighter, so left and
right read at a glance. Projection is orthographic: a point p [m] appears at (p·right, p·up) on screen,
with the camera basis built from the runner's mean heading, so every runner travels left to right. A take
that turns (``body.path``) is drawn unrolled along its path (``body.path.straighten``): the camera follows
the curve, and the speed shown is the speed along the path.

Everything is drawn at one common scale [px/m] across rows and panels, so a child looks small next to
a giant. matplotlib (and imageio + imageio-ffmpeg for GIF/MP4) are optional extras imported lazily;
a missing one raises FroudeError with the pip command that installs it.

Public API: ``filmstrip_image`` (the RGB array plus the drawn geometry), ``render_filmstrip`` (PNG),
``render_video`` (GIF/MP4), ``render_frame`` (a still PNG of the video layout), ``build_rig``,
``camera_basis``.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..body.gait import detect_gait, summarize
from ..body.model import BodyModel
from ..body.path import is_straight, straighten, take_path
from ..constants import UP, UP_AXIS
from ..core.kinematics import ancestor_mask, points_world
from ..core.motion import Motion
from ..errors import FroudeError

INSTALL_HINT = "pip install 'froude[render]'"
CAMERAS = ("side", "three-quarter", "front")
VIDEO_EXTENSIONS = (".gif", ".mp4")
STILL_EXTENSIONS = (".png",)
#: Camera azimuth from the runner's right side towards its front, and elevation [deg].
_CAMERA_ANGLES_DEG = {"side": (0.0, 0.0), "three-quarter": (40.0, 14.0), "front": (90.0, 6.0)}

# Capsule diameters as fractions of stature (an adult of 1.75 m: thigh 13 cm, upper arm 8 cm ...).
_WIDTH = {
    "torso": 0.13, "neck": 0.05, "hip": 0.07, "thigh": 0.075, "shank": 0.055, "foot": 0.036,
    "clavicle": 0.04, "upper_arm": 0.046, "forearm": 0.038, "hand": 0.03,
}
_HEAD_RADIUS = 0.058  # head disc radius / stature
LEFT, RIGHT, CENTRE = 0, 1, 2

# Colours: grey-blue silhouettes like the paper's figure; far side dark, near side light.
_BG = "#ffffff"
_FAR = "#4a5361"
_MID = "#6f7a88"
_NEAR = "#a9b3bf"
_GROUND = "#8c8c8c"
_GROUND_FILL = "#f1f1ef"
_SHADOW = "#000000"
_TEXT = "#222222"
_DPI = 100.0


def _imports():
    """matplotlib's object API on the Agg canvas (no pyplot, no global state)."""
    try:
        import matplotlib
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.collections import LineCollection
        from matplotlib.figure import Figure
        from matplotlib.patches import Circle, Polygon
    except ImportError:
        raise FroudeError(f"rendering needs matplotlib: {INSTALL_HINT}") from None
    del matplotlib
    return Figure, FigureCanvasAgg, LineCollection, Circle, Polygon


def _imageio():
    try:
        import imageio.v2 as iio2
        import imageio.v3 as iio3
    except ImportError:
        raise FroudeError(f"GIF/MP4 output needs imageio: {INSTALL_HINT}") from None
    return iio2, iio3


# ---- the rig: which points and capsules to draw ------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Rig:
    """What to draw of a skeleton.

    point_joint: (P,) joint each drawn point is fixed to; point_local: (P, 3) point in that joint's frame [m]
    (points 0..J-1 are the joints themselves; extra points are toe tips, hand ends, the head centre).
    bone_a, bone_b: (B,) point indices of each capsule's ends; bone_width: (B,) capsule diameter [m];
    bone_side: (B,) LEFT, RIGHT or CENTRE; head: point index of the head centre; head_radius [m];
    stature [m]; pelvis: point index of the pelvis.
    """

    point_joint: np.ndarray
    point_local: np.ndarray
    bone_a: np.ndarray
    bone_b: np.ndarray
    bone_width: np.ndarray
    bone_side: np.ndarray
    head: int
    head_radius: float
    stature: float
    pelvis: int

    def points(self, p_world_joint: np.ndarray, R_world_joint: np.ndarray) -> np.ndarray:
        """(F, P, 3) world positions [m] of the drawn points."""
        return points_world(p_world_joint, R_world_joint, self.point_joint, self.point_local)


# Long because capsule sides, ends and radii come from one walk over the bones with shared lookups.
def build_rig(body: BodyModel) -> Rig:
    """The capsules of a skeleton: bones parent→child, minus fingers and zero-length bones.

    Sides come from the roles: a joint is left when it lies in the subtree of left_hip or left_shoulder,
    or on the chain leading to one of them that carries neither the head nor the other side (CMU's
    LHipJoint, LeftShoulder clavicle).
    """
    sk = body.skeleton
    roles = body.roles
    J = sk.n_joints
    anc = ancestor_mask(sk)  # anc[b, k]: k is b or an ancestor of b
    stature = body.stature
    rest, R_ref = sk.reference_world()  # the upright reference pose (the rest pose unless it is folded)
    ends: dict[int, np.ndarray] = {}
    for j, off in sk.end_sites:
        if np.linalg.norm(off) > 0:  # zero-length end sites ("OFFSET 0 0 0") mark nothing
            ends.setdefault(int(j), np.asarray(off, dtype=float))

    def subtree(j):
        return anc[:, j]  # (J,) joints at or below j

    side = np.full(J, CENTRE)
    for s, code in (("left", LEFT), ("right", RIGHT)):
        other = "right" if s == "left" else "left"
        mine = subtree(roles[f"{s}_hip"]) | subtree(roles[f"{s}_shoulder"])
        for limb in ("hip", "shoulder"):
            chain = anc[roles[f"{s}_{limb}"]]  # ancestors of this limb's root
            shared = anc[roles["head"]] | anc[roles[f"{other}_hip"]] | anc[roles[f"{other}_shoulder"]]
            mine |= chain & ~shared
        side[mine] = code
    fingers = np.zeros(J, dtype=bool)
    for s in ("left", "right"):
        fingers |= subtree(roles[f"{s}_wrist"])
        fingers[roles[f"{s}_wrist"]] = False
    fingers |= subtree(roles["head"])
    fingers[roles["head"]] = False

    point_joint = list(range(J))
    point_local = [np.zeros(3) for _ in range(J)]

    def add_point(joint, local):
        point_joint.append(int(joint))
        point_local.append(np.asarray(local, dtype=float))
        return len(point_joint) - 1

    bones = []  # (a, b, kind, side)

    def kind_of(child: int) -> str:
        for s in ("left", "right"):
            r = {k: roles[f"{s}_{k}"] for k in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist")}
            if child == r["knee"]:
                return "thigh"
            if child == r["ankle"]:
                return "shank"
            if subtree(r["ankle"])[child]:
                return "foot"
            if subtree(r["hip"])[child] or (side[child] == (LEFT if s == "left" else RIGHT) and anc[r["hip"], child]):
                return "hip"
            if child == r["elbow"]:
                return "upper_arm"
            if child == r["wrist"]:
                return "forearm"
            if side[child] == (LEFT if s == "left" else RIGHT) and anc[r["shoulder"], child]:
                return "clavicle"
        neck = roles.get("neck", roles["head"])
        return "torso" if anc[neck, child] else "neck"

    min_len = 1e-3 * stature
    body_joints = subtree(roles["pelvis"])  # a static or ground-level reference root above it is not drawn
    for j in range(1, J):
        if fingers[j] or np.linalg.norm(sk.offsets[j]) < min_len or j == roles["pelvis"] or not body_joints[j]:
            continue
        bones.append((int(sk.parents[j]), j, kind_of(j), side[j]))
    for s in ("left", "right"):
        code = LEFT if s == "left" else RIGHT
        toe, wrist = roles[f"{s}_toe"], roles[f"{s}_wrist"]
        if f"{s}_toe_end" in roles:
            bones.append((toe, roles[f"{s}_toe_end"], "foot", code))
        elif toe in ends:
            bones.append((toe, add_point(toe, ends[toe]), "foot", code))
        # the hand: wrist -> hand end (a finger joint or an end site); fingers themselves are not drawn
        b: int | None
        if f"{s}_hand_end" in roles:
            b = roles[f"{s}_hand_end"]  # a finger joint: follows the fingers' rotation
        elif wrist in ends:
            b = add_point(wrist, ends[wrist])
        else:
            kids = [k for k in sk.children(wrist) if np.linalg.norm(sk.offsets[k]) >= min_len]
            b = add_point(wrist, sk.offsets[kids[0]]) if kids else None
        if b is not None:
            bones.append((wrist, b, "hand", code))
    head = roles["head"]
    if "head_end" in roles:
        vertex_local = R_ref[head].T @ (rest[roles["head_end"]] - rest[head])
    elif head in ends:
        vertex_local = ends[head]
    else:
        vertex_local = R_ref[head].T @ (np.asarray(UP, dtype=float) * 0.12 * stature)
    # the head disc touches the vertex: its centre sits one radius below it along the head's axis
    radius = _HEAD_RADIUS * stature
    vlen = np.linalg.norm(vertex_local)
    centre_local = vertex_local * max(vlen - radius, 0.35 * vlen) / max(vlen, 1e-12)
    head_pt = add_point(head, centre_local)
    bone_a, bone_b, kinds, sides = zip(*bones)
    return Rig(
        np.array(point_joint), np.array(point_local), np.array(bone_a), np.array(bone_b),
        np.array([_WIDTH[k] * stature for k in kinds]), np.array(sides), head_pt, radius, stature,
        roles["pelvis"],
    )


# ---- camera ----------------------------------------------------------------------------------------
def camera_basis(camera: str, heading: np.ndarray) -> np.ndarray:
    """(3, 3) rows: screen right, screen up, towards the viewer (unit world vectors).

    heading: (3,) the runner's travel direction; the side camera stands at the runner's right so travel
    reads left to right; "three-quarter" turns 40° towards the front and looks 14° down; "front" faces
    the runner.
    """
    if camera not in _CAMERA_ANGLES_DEG:
        raise FroudeError(f"unknown camera '{camera}'; choose one of: {', '.join(CAMERAS)}")
    up = np.asarray(UP, dtype=float)
    f = np.asarray(heading, dtype=float) - np.dot(heading, up) * up
    n = np.linalg.norm(f)
    f = f / n if n > 1e-9 else np.roll(up, 1)  # no travel: look along +Z for +Y up
    runner_right = np.cross(f, up)
    az, el = np.radians(_CAMERA_ANGLES_DEG[camera])
    toward = np.cos(el) * (np.cos(az) * runner_right + np.sin(az) * f) + np.sin(el) * up
    right = np.cross(up, toward)
    right /= np.linalg.norm(right)
    screen_up = np.cross(toward, right)
    return np.stack([right, screen_up, toward])


# ---- per-motion scene data ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Actor:
    """One motion prepared for drawing: rig, camera, ground, speed and label."""

    motion: Motion
    body: BodyModel
    rig: Rig
    basis: np.ndarray  # (3, 3)
    heading: np.ndarray  # (3,)
    ground: float  # [m] world height of the ground
    speed: float  # [m/s]
    contact: np.ndarray  # (F, 2) bool
    label: str
    far_side: int  # LEFT or RIGHT

    @property
    def sole(self) -> float:
        """World height [m] of the drawn ground: the ground lowered by the foot capsule's radius, so the
        capsule's rim (not its axis) touches it."""
        return self.ground - 0.5 * _WIDTH["foot"] * self.rig.stature


def _label_for(motion: Motion, i: int) -> str:
    src = motion.meta.get("source") if motion.meta else None
    return Path(src).stem if src else f"motion {i + 1}"


def _actors(motions: Sequence[Motion], labels: Sequence[str] | None, camera: str) -> list[_Actor]:
    motions = list(motions)
    if not motions:
        raise FroudeError("nothing to render: give at least one motion")
    if labels is not None and len(labels) != len(motions):
        raise FroudeError(f"{len(labels)} labels for {len(motions)} motions")
    out = []
    for i, m in enumerate(motions):
        if m.n_frames < 1:
            raise FroudeError(f"{_label_for(m, i)}: motion has no frames")
        body = BodyModel.from_skeleton(m.skeleton)
        com, markers = body.com_and_markers(m)
        gait = detect_gait(m, body, markers)
        path = take_path(m, body, com, gait)
        if not is_straight(path):  # the camera follows a turn: the take is drawn unrolled along its path
            m = straighten(m, path)
            com, markers = body.com_and_markers(m)
            gait = detect_gait(m, body, markers)
        summary = summarize(m, body, com, gait)
        speed = float(summary.mean_speed) if np.isfinite(summary.mean_speed) else 0.0
        heading = np.asarray(summary.heading, dtype=float)
        if not np.all(np.isfinite(heading)) or np.linalg.norm(heading) < 0.5:
            heading = np.roll(np.asarray(UP, dtype=float), 1)
        basis = camera_basis(camera, heading)
        rig = build_rig(body)
        # far side: the hip further from the camera on average
        p, _ = body.world(m[:: max(1, m.n_frames // 20)])
        depth = p[:, [body.roles["left_hip"], body.roles["right_hip"]]] @ basis[2]
        far = LEFT if depth[:, 0].mean() < depth[:, 1].mean() else RIGHT
        label = labels[i] if labels is not None else _label_for(m, i)
        out.append(_Actor(m, body, rig, basis, heading, gait.ground, speed, gait.contact, label, far))
    return out


def _colours(actor: _Actor) -> tuple[list[str], list[float]]:
    """Colour and z-order offset of each bone: far side, centre, near side."""
    look = {CENTRE: (_MID, 0.2), actor.far_side: (_FAR, 0.1)}
    pairs = [look.get(s, (_NEAR, 0.3)) for s in actor.rig.bone_side]
    return [c for c, _ in pairs], [z for _, z in pairs]


def _shadow_outline(actor: _Actor, centre: np.ndarray, n: int = 28) -> np.ndarray:
    """(..., n, 2) screen outline [m] of the shadow: a flat ellipse on the ground under ``centre`` (..., 3).

    Drawn in the ground plane (long axis along the heading); a camera that looks almost level would
    flatten it to a line, so it is seen from at least 12° above.
    """
    up = np.asarray(UP, dtype=float)
    f = actor.heading - np.dot(actor.heading, up) * up
    f = f / max(np.linalg.norm(f), 1e-12)
    lat = np.cross(f, up)
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    a, b = 0.22 * actor.rig.stature, 0.09 * actor.rig.stature
    c = np.array(centre, dtype=float)
    c[..., UP_AXIS] = actor.sole
    ring = a * np.cos(th)[:, None] * f + b * np.sin(th)[:, None] * lat  # (n, 3)
    right, sup, toward = actor.basis
    xy = np.stack([(c[..., None, :] + ring) @ right, c[..., None, :] @ sup + ring @ sup], axis=-1)
    el = np.arcsin(np.clip(np.dot(toward, up), -1, 1))
    if abs(el) < np.radians(12):
        xy[..., 1] += (ring @ toward) * (np.sin(np.radians(12)) - np.sin(el))
    return xy


# ---- drawing one figure (a snapshot or a video panel) --------------------------------------------
class _FigureArtists:
    """Artists of one capsule figure on an axes, updated in place with ``set`` (no re-creation).

    All capsules are one LineCollection drawn in order far side → centre → near side; each capsule is
    preceded by a slightly wider background-coloured copy, a rim that separates overlapping limbs (and
    overlapping snapshots). One collection draws in one call: ~20x faster than a Line2D per bone.
    """

    def __init__(self, ax, actor: _Actor, px_per_m: float, z0: float):
        _, _, LineCollection, Circle, Polygon = _imports()
        self.actor = actor
        rig = actor.rig
        pt_per_m = px_per_m * 72.0 / _DPI
        cols, zs = _colours(actor)
        rim = max(1.0, 0.006 * rig.stature * pt_per_m)
        back = [k for k in np.argsort(zs, kind="stable") if zs[k] < 0.3]
        front = [k for k in np.argsort(zs, kind="stable") if zs[k] >= 0.3]
        self.order = {}
        for name, picked, dz in (("back", back, 0.2), ("front", front, 0.3)):
            ks = np.array(picked, dtype=int)
            widths = np.ravel(np.stack([rig.bone_width[ks] * pt_per_m + 2 * rim, rig.bone_width[ks] * pt_per_m], 1))
            colours = [c for k in ks for c in (_BG, cols[k])]
            lc = LineCollection(np.zeros((2 * len(ks), 2, 2)), colors=colours, linewidths=widths,
                                capstyle="round", zorder=z0 + dz)
            ax.add_collection(lc)
            self.order[name] = (ks, lc)
        # the head sits between the far/centre capsules and the near-side limbs
        self.head = Circle((0, 0), rig.head_radius, facecolor=_MID, edgecolor=_BG, zorder=z0 + 0.25, lw=rim)
        ax.add_patch(self.head)
        # a soft shadow: nested ellipses, darkest in the middle
        self.shadows = []
        for scale, a in ((1.0, 0.07), (0.75, 0.09), (0.5, 0.12)):
            poly = Polygon(np.zeros((3, 2)), closed=True, color=_SHADOW, alpha=a, lw=0, zorder=z0 - 0.5)
            ax.add_patch(poly)
            self.shadows.append((poly, scale))

    def set(self, xy: np.ndarray, shadow_xy: np.ndarray) -> None:
        """xy: (P, 2) screen positions [m] of the rig's points; shadow_xy: (n, 2) shadow outline [m]."""
        rig = self.actor.rig
        seg = np.stack([xy[rig.bone_a], xy[rig.bone_b]], axis=1)  # (B, 2, 2)
        for ks, lc in self.order.values():
            lc.set_segments(np.repeat(seg[ks], 2, axis=0))  # rim, fill, rim, fill ...
        self.head.center = (xy[rig.head, 0], xy[rig.head, 1])
        c = shadow_xy.mean(axis=0)
        for poly, scale in self.shadows:
            poly.set_xy(c + scale * (shadow_xy - c))


def _screen(points: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """(..., 2) orthographic screen coordinates [m] of world points (..., 3)."""
    return points @ basis[:2].T


def _lowest_drawn(actor: _Actor, xy: np.ndarray) -> np.ndarray:
    """(...,) lowest screen height [m] reached by any capsule rim or the head disc; xy: (..., P, 2)."""
    rig = actor.rig
    r = 0.5 * rig.bone_width
    ends = np.minimum(xy[..., rig.bone_a, 1] - r, xy[..., rig.bone_b, 1] - r)
    return np.minimum(ends.min(axis=-1), xy[..., rig.head, 1] - rig.head_radius)


def _ground_artists(ax, actor: _Actor, x_range: tuple[float, float], ticks: bool, z: float = -2.0) -> None:
    """Ground under an actor: a line and a pale band (side camera, optional ticks every 0.5 m),
    or a grid of 0.5 m squares on the ground plane (cameras that look down)."""
    _, _, LineCollection, _, _ = _imports()
    right, sup, toward = actor.basis
    up = np.asarray(UP, dtype=float)
    level = abs(np.dot(toward, up)) < 1e-6
    x0, x1 = x_range
    if level:
        y = actor.sole * sup[UP_AXIS]
        ax.axhspan(y - 1e3, y, color=_GROUND_FILL, zorder=z - 1, lw=0)
        ax.axhline(y, color=_GROUND, lw=1.2, zorder=z)
        if ticks:
            xs = np.arange(np.floor(x0 / 0.5) * 0.5, x1 + 0.5, 0.5)
            seg = np.stack([np.stack([xs, np.full_like(xs, y)], -1),
                            np.stack([xs - 0.12, np.full_like(xs, y - 0.12)], -1)], axis=1)
            ax.add_collection(LineCollection(seg, colors=_GROUND, linewidths=0.8, zorder=z))
        return
    # world grid over the region the camera can see: span the screen range along the heading and 1.5 m
    # to each side of the path
    f = actor.heading - np.dot(actor.heading, up) * up
    f /= max(np.linalg.norm(f), 1e-12)
    lat = np.cross(f, up)
    root = actor.motion.root_positions
    o = root.mean(axis=0)
    o[UP_AXIS] = actor.sole
    along = (root - o) @ f
    half = 3.0 * actor.rig.stature
    s = np.arange(np.floor((along.min() - half) / 0.5) * 0.5, along.max() + half + 0.5, 0.5)
    t = np.arange(-1.5, 1.5 + 1e-9, 0.5)
    lines = [np.stack([o + si * f + t[0] * lat, o + si * f + t[-1] * lat]) for si in s]
    lines += [np.stack([o + s[0] * f + ti * lat, o + s[-1] * f + ti * lat]) for ti in t]
    segs = _screen(np.array(lines), actor.basis)
    ax.add_collection(LineCollection(segs, colors="#c9c9c9", linewidths=0.8, zorder=z))


def _new_figure(width_px: int, height_px: int):
    Figure, FigureCanvasAgg, _, _, _ = _imports()
    fig = Figure(figsize=(width_px / _DPI, height_px / _DPI), dpi=_DPI, facecolor=_BG)
    canvas = FigureCanvasAgg(fig)
    return fig, canvas


def _blank_axes(fig, rect):
    ax = fig.add_axes(rect)
    ax.set_axis_off()
    ax.set_facecolor(_BG)
    ax.set_autoscale_on(False)
    return ax


def _rgb(canvas) -> np.ndarray:
    canvas.draw()
    return np.ascontiguousarray(np.asarray(canvas.buffer_rgba())[..., :3])  # one copy, RGB


def _even(n: float) -> int:
    return max(2, int(round(n / 2.0)) * 2)


# ---- filmstrip -------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Filmstrip:
    """A rendered filmstrip and the geometry it drew.

    image: (H, W, 3) uint8 RGB. px_per_m: common scale. Per row (one per motion): labels, speeds [m/s],
    n_snapshots, times [s] (n,), row_px ((top, bottom) pixel rows of each row band), ground_px (pixel row
    of the drawn ground line, or None for a camera that looks down), lowest_px ((n,) pixel row of the
    lowest drawn point of each snapshot), contact ((n,) bool: a foot is on the ground at that time),
    spacing [m] (extra offset between snapshots along the heading).
    """

    image: np.ndarray
    px_per_m: float
    labels: tuple[str, ...]
    speeds: tuple[float, ...]
    n_snapshots: tuple[int, ...]
    times: tuple[np.ndarray, ...]
    row_px: tuple[tuple[int, int], ...]
    ground_px: tuple[float | None, ...]
    lowest_px: tuple[np.ndarray, ...]
    contact: tuple[np.ndarray, ...]
    spacing: float


def snapshot_times(duration: float, interval: float) -> np.ndarray:
    """(n,) snapshot times [s]: 0, interval, ... up to the clip's end; n = floor(duration / interval) + 1."""
    if not interval > 0:
        raise FroudeError(f"snapshot interval must be > 0 s, got {interval}")
    n = int(np.floor(duration / interval + 1e-9)) + 1
    return np.arange(n) * interval


# Long because the rows share one scale, spacing and figure layout computed across all motions first.
def filmstrip_image(
    motions: Sequence[Motion],
    labels: Sequence[str] | None = None,
    interval: float = 0.066,
    camera: str = "side",
    width: int = 2400,
    spacing: float | None = None,
) -> Filmstrip:
    """Snapshots every ``interval`` seconds side by side, one row per motion, at one common scale.

    Each snapshot stands at its true world position moved ``i * spacing`` metres further along the
    heading (snapshot i), so the figures do not pile up; spacing=0 gives a true chronophotograph.
    spacing=None picks one spacing for all rows: consecutive snapshots of the slowest row at least
    0.4 x the tallest stature apart. width: image width [px]. Rows are labelled "label  u m/s".
    """
    actors = _actors(motions, labels, camera)
    rows = []
    for act in actors:
        t = snapshot_times(act.motion.duration, interval)
        snap = act.motion.sample(t)
        p, R = act.body.world(snap)
        pts = act.rig.points(p, R)  # (n, P, 3)
        rows.append((act, t, pts))
    tallest = max(a.rig.stature for a in actors)
    if spacing is None:
        step = min(a.speed * interval for a in actors)
        spacing = max(0.0, 0.4 * tallest - step)
    if spacing < 0:
        raise FroudeError(f"spacing must be >= 0 m, got {spacing}")
    geo = []
    for act, t, pts in rows:
        offset = (np.arange(len(t)) * spacing)[:, None, None] * act.heading
        pts = pts + offset
        xy = _screen(pts, act.basis)  # (n, P, 2)
        shadow = _shadow_outline(act, pts[:, act.rig.pelvis])  # (n, k, 2)
        r = act.rig.bone_width.max() / 2 + act.rig.head_radius
        lo = np.minimum(xy.min(axis=(0, 1)) - r, shadow.min(axis=(0, 1)))
        hi = xy.max(axis=(0, 1)) + r
        geo.append((act, t, xy, shadow, lo, hi))
    margin = 0.12 * tallest
    label_band = 0.2 * tallest
    span_x = max(g[5][0] - g[4][0] for g in geo) + 2 * margin
    width = _even(width)
    px_per_m = width / span_x
    # one scale for all rows; each row as tall as its own figures need (a child's row is lower)
    row_h = [_even((g[5][1] - g[4][1] + margin + label_band) * px_per_m) for g in geo]
    H = int(sum(row_h))
    tops = np.concatenate([[0], np.cumsum(row_h)])
    fig, canvas = _new_figure(width, H)
    axes = []
    title = max(9.0, 0.075 * tallest * px_per_m * 72 / _DPI)
    for i, (act, t, xy, shadow, lo, _hi) in enumerate(geo):
        ax = _blank_axes(fig, (0, 1 - tops[i + 1] / H, 1, row_h[i] / H))
        x0 = lo[0] - margin
        y0 = lo[1] - 0.5 * margin
        ax.set_xlim(x0, x0 + span_x)
        ax.set_ylim(y0, y0 + row_h[i] / px_per_m)
        _ground_artists(ax, act, (x0, x0 + span_x), ticks=False)
        for k in range(len(t)):
            # later snapshots on top, each figure above the previous one's shadow
            _FigureArtists(ax, act, px_per_m, z0=10 + 2 * k).set(xy[k], shadow[k])
        ax.annotate(act.label, (0, 1), xycoords="axes fraction", xytext=(0.4 * title, -0.4 * title),
                    textcoords="offset points", ha="left", va="top", fontsize=title, color=_TEXT, weight="bold")
        ax.annotate(f"{act.speed:.2f} m/s", (0, 1), xycoords="axes fraction", xytext=(0.4 * title, -1.75 * title),
                    textcoords="offset points", ha="left", va="top", fontsize=0.8 * title, color="#555555")
        axes.append(ax)
    image = _rgb(canvas)
    # geometry in pixel rows (top = 0), through the same transforms that drew the picture
    ground_px, lowest_px, row_px, contact = [], [], [], []
    for i, ((act, t, xy, _shadow, _lo, _hi), ax) in enumerate(zip(geo, axes)):
        to_px = ax.transData.transform
        low = _lowest_drawn(act, xy)
        lowest_px.append(H - to_px(np.stack([np.zeros_like(low), low], -1))[:, 1])
        level = abs(act.basis[2] @ np.asarray(UP, dtype=float)) < 1e-6
        ground_px.append(float(H - to_px([[0.0, act.sole * act.basis[1][UP_AXIS]]])[0, 1]) if level else None)
        row_px.append((int(tops[i]), int(tops[i + 1])))
        frames = np.clip(np.round(t / act.motion.frame_time).astype(int), 0, act.motion.n_frames - 1)
        contact.append(act.contact[frames].any(axis=1))
    return Filmstrip(
        image, px_per_m, tuple(a.label for a in actors), tuple(a.speed for a in actors),
        tuple(len(g[1]) for g in geo), tuple(g[1] for g in geo), tuple(row_px), tuple(ground_px),
        tuple(lowest_px), tuple(contact), float(spacing),
    )


# ---- video -----------------------------------------------------------------------------------------
class _VideoScene:
    """One figure with a panel per motion; ``frame(t)`` updates the artists and returns the RGB image."""

    def __init__(self, actors: list[_Actor], width: int, height: int | None):
        from scipy.ndimage import gaussian_filter1d

        n = len(actors)
        self.actors = actors
        self.width = _even(width)
        panel_w = self.width / n
        self.height = _even(height if height else max(200.0, 0.75 * panel_w))
        tallest = max(a.rig.stature for a in actors)
        span_y = 1.55 * tallest
        self.px_per_m = self.height / span_y
        self.span_x = panel_w / self.px_per_m
        self.span_y = span_y
        self.fig, self.canvas = _new_figure(self.width, self.height)
        self.panels = []
        font = max(8.0, min(14.0, 0.06 * self.height * 72 / _DPI))
        for i, act in enumerate(actors):
            ax = _blank_axes(self.fig, (i / n, 0, 1 / n, 1))
            m = act.motion
            # the camera follows a smoothed pelvis (σ = 0.25 s) so the stride's sway does not shake it
            p, R = act.body.world(m)
            pelvis = p[:, act.body.roles["pelvis"]].copy()
            pelvis[:, UP_AXIS] = act.sole
            sigma = max(1e-6, 0.25 / m.frame_time)
            follow = gaussian_filter1d(pelvis, sigma, axis=0, mode="nearest") if m.n_frames > 1 else pelvis
            self_follow = _screen(follow, act.basis)  # (F, 2)
            xr = (self_follow[:, 0].min() - self.span_x, self_follow[:, 0].max() + self.span_x)
            _ground_artists(ax, act, xr, ticks=True)
            fa = _FigureArtists(ax, act, self.px_per_m, z0=10)
            ax.text(0.03, 0.96, act.label, transform=ax.transAxes, ha="left", va="top", fontsize=font,
                    color=_TEXT, weight="bold", zorder=50)
            ax.text(0.03, 0.96 - 1.5 * font * _DPI / 72 / self.height, f"{act.speed:.2f} m/s",
                    transform=ax.transAxes, ha="left", va="top", fontsize=0.85 * font, color="#555555", zorder=50)
            clock = ax.text(0.97, 0.96, "", transform=ax.transAxes, ha="right", va="top", fontsize=0.85 * font,
                            color="#777777", zorder=50, family="monospace")
            if i > 0:  # a thin divider between panels
                ax.plot([0, 0], [0, 1], transform=ax.transAxes, color="#cccccc", lw=1.0, zorder=60)
            self.panels.append((ax, act, fa, self_follow, clock))

    def prepare(self, times: np.ndarray) -> None:
        """Sample every motion at the output times (T,) [s] and project, all frames at once."""
        self.times = np.asarray(times, dtype=float)
        self.tracks = []
        for _ax, act, _fa, follow, _clock in self.panels:
            m = act.motion
            snap = m.sample(self.times)
            p, R = act.body.world(snap)
            pts = act.rig.points(p, R)  # (T, P, 3)
            u = np.clip(self.times / m.frame_time, 0.0, m.n_frames - 1)
            i0 = np.minimum(np.floor(u).astype(int), max(m.n_frames - 2, 0))
            i1 = np.minimum(i0 + 1, m.n_frames - 1)
            w = (u - i0)[:, None]
            centre = follow[i0] * (1 - w) + follow[i1] * w  # (T, 2) camera target
            self.tracks.append((_screen(pts, act.basis), _shadow_outline(act, pts[:, act.rig.pelvis]), centre,
                                np.minimum(self.times, m.duration)))

    def frame(self, k: int) -> np.ndarray:
        """(H, W, 3) uint8 image of output frame k (each motion clamped to its own end)."""
        for (ax, _act, fa, _follow, clock), (xy, shadow, centre, clock_t) in zip(self.panels, self.tracks):
            fa.set(xy[k], shadow[k])
            c = centre[k]
            ax.set_xlim(c[0] - 0.5 * self.span_x, c[0] + 0.5 * self.span_x)
            ax.set_ylim(c[1] - 0.14 * self.span_y, c[1] + 0.86 * self.span_y)
            clock.set_text(f"{clock_t[k]:.2f} s")
        return _rgb(self.canvas)


def video_times(motions: Sequence[Motion], fps: float) -> np.ndarray:
    """(n,) output frame times [s] covering the longest motion: n = floor(max duration * fps) + 1."""
    if not fps > 0:
        raise FroudeError(f"fps must be > 0, got {fps}")
    duration = max(m.duration for m in motions)
    return np.arange(int(np.floor(duration * fps + 1e-9)) + 1) / fps


# ---- output files ----------------------------------------------------------------------------------
def _check_path(path, allowed: tuple[str, ...]) -> Path:
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in allowed:
        raise FroudeError(f"{path}: unknown output extension '{path.suffix}'; use {', '.join(allowed)}")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise FroudeError(f"{path}: folder '{folder}' does not exist")
    return path


def _atomic(path: Path, write: Callable[[str], None]) -> None:
    """Run write(temp_path) on a temp file beside ``path`` (same extension), then move it into place."""
    from ..io.atomic import atomic_write

    atomic_write(path, write)


def _write_png(path: Path, image: np.ndarray) -> None:
    from PIL import Image  # a dependency of matplotlib

    _atomic(path, lambda tmp: Image.fromarray(np.ascontiguousarray(image)).save(tmp, format="PNG"))


def render_filmstrip(
    motions: Sequence[Motion],
    path,
    labels: Sequence[str] | None = None,
    interval: float = 0.066,
    camera: str = "side",
    width: int = 2400,
    spacing: float | None = None,
) -> Filmstrip:
    """Write the filmstrip of ``filmstrip_image`` as a PNG (atomically) and return it."""
    path = _check_path(path, STILL_EXTENSIONS)
    strip = filmstrip_image(motions, labels, interval, camera, width, spacing)
    _write_png(path, strip.image)
    return strip


def render_frame(
    motions: Sequence[Motion],
    path,
    labels: Sequence[str] | None = None,
    time: float = 0.0,
    camera: str = "side",
    width: int = 960,
    height: int | None = None,
) -> np.ndarray:
    """Write one frame of the video layout (a panel per motion) at ``time`` [s] as a PNG; return it (H, W, 3)."""
    path = _check_path(path, STILL_EXTENSIONS)
    scene = _VideoScene(_actors(motions, labels, camera), width, height)
    scene.prepare(np.array([float(time)]))
    image = scene.frame(0)
    _write_png(path, image)
    return image


#: x264 constant rate factor of the MP4s (what imageio's quality 7 meant: visually clean, small files).
MP4_CRF = 15


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """Linux: have the kernel send SIGKILL to this child when its parent dies (even by SIGKILL)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, 9)  # PR_SET_PDEATHSIG, SIGKILL
    except Exception:
        pass


def _ffmpeg_exe() -> str:
    """Path of the ffmpeg binary imageio-ffmpeg ships (FroudeError with the install hint if missing)."""
    try:
        from imageio_ffmpeg import get_ffmpeg_exe
    except ImportError:
        raise FroudeError(f"MP4 output needs imageio-ffmpeg: {INSTALL_HINT}") from None
    return get_ffmpeg_exe()


def _encode_mp4(ffmpeg: str, tmp: str, frames, fps: float, width: int, height: int) -> None:
    """Pipe RGB frames (height, width, 3) uint8 into an ffmpeg child that writes H.264 to ``tmp``.

    The child ends with froude: in its own session (a Ctrl-C in the terminal reaches froude, which stops
    it), killed and reaped on any interrupt or error here, and (Linux) killed by the kernel if froude
    itself is killed. A failed encode is a FroudeError with ffmpeg's last message.
    """
    import subprocess
    import sys

    cmd = [ffmpeg, "-y", "-loglevel", "error", "-f", "rawvideo", "-vcodec", "rawvideo",
           "-s", f"{width}x{height}", "-pix_fmt", "rgb24", "-r", f"{fps:.6g}", "-i", "-", "-an",
           "-vcodec", "libx264", "-pix_fmt", "yuv420p", "-crf", str(MP4_CRF),
           "-preset", "veryfast",  # encoding shares 2 cores with drawing
           "-f", "mp4", tmp]
    linux = sys.platform.startswith("linux")
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True, preexec_fn=_die_with_parent if linux else None)
    assert proc.stdin is not None and proc.stderr is not None  # both are pipes
    try:
        try:
            for im in frames:
                proc.stdin.write(np.ascontiguousarray(im, dtype=np.uint8).tobytes())
        except BrokenPipeError:
            pass  # ffmpeg stopped: its message is read below
        proc.stdin.close()
        err = proc.stderr.read().decode(errors="replace").strip()
        code = proc.wait()
    except BaseException:
        proc.kill()
        proc.wait()
        raise
    finally:
        proc.stderr.close()
    if code != 0:
        last = err.splitlines()[-1] if err else f"exit status {code}"
        raise FroudeError(f"ffmpeg could not encode the video: {last}")


def render_video(
    motions: Sequence[Motion],
    path,
    labels: Sequence[str] | None = None,
    fps: float = 30.0,
    camera: str = "side",
    width: int = 960,
    height: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[int, int, int]:
    """Render motions side by side (one panel each, common scale, camera following each runner) at real
    time to a GIF or MP4 (by extension), written atomically. Shorter motions hold their last pose.

    width, height: frame size [px] (rounded to even numbers; height defaults to 0.75 x panel width).
    progress(done, total) is called after every frame. Returns (frames, height, width).
    """
    path = _check_path(path, VIDEO_EXTENSIONS)
    mp4 = path.suffix.lower() == ".mp4"
    ffmpeg = _ffmpeg_exe() if mp4 else None  # a missing extra is said before any drawing
    iio3 = None if mp4 else _imageio()[1]
    actors = _actors(motions, labels, camera)
    times = video_times([a.motion for a in actors], fps)
    scene = _VideoScene(actors, width, height)
    scene.prepare(times)

    def frames():
        for k in range(len(times)):
            yield scene.frame(k)
            if progress:
                progress(k + 1, len(times))

    def write(tmp: str) -> None:
        if ffmpeg is not None:
            _encode_mp4(ffmpeg, tmp, frames(), fps, scene.width, scene.height)
        else:
            assert iio3 is not None
            # GIF delays are whole centiseconds; Pillow merges identical consecutive frames, so
            # frames are nudged apart only by their content (the clock text changes every frame)
            with iio3.imopen(tmp, "w", plugin="pillow", extension=".gif") as f:
                f.write(np.stack(list(frames())), duration=1000.0 / fps, loop=0)

    _atomic(path, write)
    return len(times), scene.height, scene.width
