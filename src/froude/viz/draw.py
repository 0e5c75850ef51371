"""Drawing motions with matplotlib's object API: the camera, the per-motion scene (rig, ground, shading by
side), one figure's artists, and the filmstrip image (the paper's Fig. 3) with the geometry it drew."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..body.gait import detect_gait, summarize
from ..body.model import BodyModel
from ..body.path import is_straight, straighten, take_path
from ..core.constants import UP, UP_AXIS
from ..core.motion import Motion
from ..errors import FroudeError
from .rig import _WIDTH, CENTRE, LEFT, RIGHT, Rig, build_rig

INSTALL_HINT = "pip install 'froude[render]'"
CAMERAS = ("side", "three-quarter", "front")
#: Camera azimuth from the runner's right side towards its front, and elevation [deg].
_CAMERA_ANGLES_DEG = {"side": (0.0, 0.0), "three-quarter": (40.0, 14.0), "front": (90.0, 6.0)}

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


def _snapshots(actor: _Actor, interval: float) -> tuple[np.ndarray, np.ndarray]:
    """A filmstrip row's snapshot times (n,) [s] and drawn points (n, P, 3) [m], every ``interval`` s."""
    t = snapshot_times(actor.motion.duration, interval)
    p, R = actor.body.world(actor.motion.sample(t))
    return t, actor.rig.points(p, R)


def _row_label(ax, actor: _Actor, title: float) -> None:
    """A filmstrip row's label and speed at its top left (title: font size [pt])."""
    ax.annotate(actor.label, (0, 1), xycoords="axes fraction", xytext=(0.4 * title, -0.4 * title),
                textcoords="offset points", ha="left", va="top", fontsize=title, color=_TEXT, weight="bold")
    ax.annotate(f"{actor.speed:.2f} m/s", (0, 1), xycoords="axes fraction", xytext=(0.4 * title, -1.75 * title),
                textcoords="offset points", ha="left", va="top", fontsize=0.8 * title, color="#555555")


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
    rows = [(act, *_snapshots(act, interval)) for act in actors]
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
        _row_label(ax, act, title)
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


