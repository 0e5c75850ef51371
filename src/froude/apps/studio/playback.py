"""The studio's scene and playback: the runners' meshes (capsules, COM, onion skin, spring leg, contacts),
drawing a frame, framing the camera, and the play / step / rate / time / view controls."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ...core.constants import UP_AXIS
from ...viz.rig import LEFT, RIGHT
from .tracks import Track, capsule_instances

if TYPE_CHECKING:  # a part of Tab: its methods use the attributes Tab.__init__ sets
    _TabPart = Any
else:
    _TabPart = object

#: Frames drawn per second (the motion itself is indexed at its own rate, 120 Hz for the sample).
DISPLAY_HZ = 30.0

#: The paper's Figure 3 spacing of snapshots [s]: the onion skin's ghosts are this far apart in time.
ONION_SPACING_S = 0.066
ONION_GHOSTS = 4

#: Width [px] of the control panel over the canvas (auto-framing centres the runners in the rest).
PANEL_PX = 400

#: Cameras: side is the paper's Figure 3 view, a long lens far away, so that runners at the same depth
#: keep their true relative size (a near-orthographic projection); fields of view [deg].
CAMERAS = ("side", "front", "three-quarter")
_CAMERA_FOV_DEG = {"side": 8.0, "front": 8.0, "three-quarter": 30.0}

COLOR_RESULT = (40, 90, 210)
COLOR_PREVIEW = (140, 150, 165)
COLOR_REFERENCE = (230, 130, 30)
COLOR_NAIVE = (150, 60, 190)
COLOR_COM = (220, 30, 60)
COLOR_LEG = (20, 150, 80)
COLOR_FEET = np.array([[30, 120, 230], [230, 60, 60]], np.uint8)  # left, right contacts


# ---- meshes ------------------------------------------------------------------------------------------
def _unit_cylinder(n: int = 14) -> tuple[np.ndarray, np.ndarray]:
    """Open cylinder of radius 1 along z from -0.5 to 0.5: vertices (2n, 3), faces (2n, 3)."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a)], axis=1)
    v = np.concatenate([np.c_[ring, np.full(n, -0.5)], np.c_[ring, np.full(n, 0.5)]])
    i = np.arange(n)
    j = (i + 1) % n
    f = np.concatenate([np.stack([i, j, n + j], 1), np.stack([i, n + j, n + i], 1)])
    return v.astype(np.float32), f.astype(np.uint32)

def _unit_sphere(n_lat: int = 7, n_lon: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """UV sphere of radius 1: vertices, faces."""
    th = np.linspace(0, np.pi, n_lat + 1)
    ph = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    v = np.array([[np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)] for t in th for p in ph])
    f = []
    for a in range(n_lat):
        for b in range(n_lon):
            p0, p1 = a * n_lon + b, a * n_lon + (b + 1) % n_lon
            q0, q1 = p0 + n_lon, p1 + n_lon
            f += [(p0, q0, q1), (p0, q1, p1)]
    return v.astype(np.float32), np.array(f, np.uint32)

CYLINDER = _unit_cylinder()
SPHERE = _unit_sphere()

def _shades(track: Track, color) -> np.ndarray:
    """(B+1, 3) uint8 capsule colours: the left side darker, the right lighter (render's convention)."""
    base = np.asarray(color, float)
    side = np.append(np.asarray(track.rig.bone_side), -1)
    k = np.where(side == LEFT, 0.7, np.where(side == RIGHT, 1.15, 1.0))[:, None]
    return np.clip(base * k, 0, 255).astype(np.uint8)

class _Runner:
    """The scene nodes of one runner: solid limbs (capsules: cylinders + joint spheres), COM ball, spring
    legs, contacts, COM trail, and (optionally) the onion skin's ghosts."""

    def __init__(self, scene, root: str, track: Track, color, ghosts: bool = False):
        self.scene, self.name, self.ghosts_on = scene, root, ghosts
        self.root = scene.add_frame(root, show_axes=False)
        self.track, self.color = track, color
        self._build_body(track, color)
        self.com = scene.add_icosphere(f"{root}/com", radius=0.05, color=COLOR_COM, position=track.com[0],
                                       subdivisions=2, cast_shadow=False, receive_shadow=False)
        self.legs = scene.add_line_segments(f"{root}/legs", track.legs[0], COLOR_LEG, thickness=0.02)
        self.contacts = scene.add_point_cloud(f"{root}/contacts", *_contact_points(track), point_size=0.05,
                                              point_shape="circle")
        self.trail = scene.add_line_segments(f"{root}/trail", track.trail, COLOR_COM, thickness=0.008)

    def _build_body(self, track: Track, color) -> None:
        sc, root = self.scene, self.name
        n = len(track.capsule_radii)
        pos, q, s = capsule_instances(track.capsules_at(0), track.capsule_radii)
        self.limbs = sc.add_batched_meshes_simple(
            f"{root}/limbs", *CYLINDER, q, pos, batched_scales=s, batched_colors=_shades(track, color), lod="off",
            cast_shadow=False, receive_shadow=False)
        ends = track.capsules_at(0).reshape(-1, 3)
        self.joints = sc.add_batched_meshes_simple(
            f"{root}/joints", *SPHERE, np.tile([1.0, 0, 0, 0], (2 * n, 1)), ends,
            batched_scales=np.repeat(track.capsule_radii, 2), batched_colors=np.repeat(_shades(track, color), 2, 0),
            lod="off", cast_shadow=False, receive_shadow=False)
        self.ghosts = None
        if self.ghosts_on:
            k = ONION_GHOSTS
            self.ghosts = sc.add_batched_meshes_simple(
                f"{root}/ghosts", *CYLINDER, np.tile(q, (k, 1)), np.tile(pos, (k, 1)),
                batched_scales=np.tile(s, (k, 1)), batched_colors=np.tile(_shades(track, color), (k, 1)),
                batched_opacities=np.repeat(np.linspace(0.45, 0.15, k), n).astype(np.float32), lod="off",
                cast_shadow=False, receive_shadow=False, visible=False)
        self._body_key = (n, tuple(color))

    def set_track(self, track: Track, color) -> None:
        """New precomputed arrays (one message per static node; per-frame nodes follow in draw)."""
        key = (len(track.capsule_radii), tuple(color))
        if key != self._body_key:  # another skeleton or colour: new meshes
            for node in (self.limbs, self.joints, self.ghosts):
                if node is not None:
                    node.remove()
            self.track = track
            self._build_body(track, color)
        elif not np.array_equal(track.capsule_radii, self.track.capsule_radii):
            self.joints.batched_scales = np.repeat(track.capsule_radii, 2)
        self.track, self.color = track, color
        pts, cols = _contact_points(track)
        self.contacts.points, self.contacts.colors = pts, cols
        self.trail.points = track.trail

    def draw(self, t: float, slot: np.ndarray, machine: bool, onion: bool) -> None:
        """Frame at time t, drawn in place: the runner's horizontal COM at ``slot`` [m]."""
        tr = self.track
        i, _ = tr.frame_at(t)
        here = np.asarray(tr.com[i], float).copy()
        here[UP_AXIS] = 0.0
        self.root.position = slot - here
        ends = tr.capsules_at(i)
        pos, q, s = capsule_instances(ends, tr.capsule_radii)
        self.limbs.batched_positions, self.limbs.batched_wxyzs, self.limbs.batched_scales = pos, q, s
        self.joints.batched_positions = ends.reshape(-1, 3)
        self.com.position = tr.com[i]
        self.legs.points = tr.legs[i]
        for node in (self.com, self.legs, self.contacts, self.trail):
            node.visible = machine
        if self.ghosts is not None:
            self.ghosts.visible = onion
            if onion:
                step = max(1, int(round(ONION_SPACING_S / tr.frame_time)))
                idx = [max(i - (k + 1) * step, 0) for k in range(ONION_GHOSTS)]
                inst = [capsule_instances(tr.capsules_at(j), tr.capsule_radii) for j in idx]
                self.ghosts.batched_positions = np.concatenate([p for p, _, _ in inst])
                self.ghosts.batched_wxyzs = np.concatenate([w for _, w, _ in inst])
                self.ghosts.batched_scales = np.concatenate([g for _, _, g in inst])

    def set_visible(self, visible: bool) -> None:
        self.root.visible = visible

    def vertical_extent(self, t: float) -> float:
        """Height [m] of what is drawn at time t: lowest capsule surface to the highest (head top)."""
        tr = self.track
        ends = tr.capsules_at(tr.frame_at(t)[0])
        r = tr.capsule_radii[:, None]
        y = ends[:, :, UP_AXIS]
        return float((y + r).max() - (y - r).min())

def _contact_points(track: Track) -> tuple[np.ndarray, np.ndarray]:
    pts = track.contacts.astype(np.float32)
    if len(pts) == 0:  # viser wants at least one point: a hidden one under the start
        return track.com[:1].astype(np.float32) * np.array([1, 0, 1], np.float32), COLOR_FEET[:1]
    return pts, COLOR_FEET[track.contact_foot]


class _Playback(_TabPart):
    """The playback part of :class:`~froude.apps.studio.app.Tab` (a mixin: the tab's state lives in Tab)."""

    # the playhead, owned here (Tab.__init__ sets them)
    _t: float  # [s] into the result
    _playing: bool
    _rate: float  # playback speed (1 = real time)
    _last_slider: float  # the tick time of the last scrubber update [s]

    # ---- scene
    def _build_scene(self) -> None:
        sc = self.target.scene
        R = self.root_name
        self._world = sc.add_frame(R, show_axes=False)
        self._grid = sc.add_grid(f"{R}/grid", width=200.0, height=200.0, plane="xz", cell_size=0.5,
                                 section_size=2.0, shadow_opacity=0.0)
        self.result = _Runner(sc, f"{R}/result", self.good.track, COLOR_RESULT, ghosts=True)
        self.reference = _Runner(sc, f"{R}/reference", self.session.reference, COLOR_REFERENCE)
        self.naive_runner: _Runner | None = None
        frame = self.session.prep.cycle.frame  # rows: forward, up, lateral (heading frame)
        self._forward = np.asarray(frame[0], float)
        self._lateral = np.asarray(frame[2], float)

    def _runners(self) -> list[tuple[_Runner, bool]]:
        """(runner, visible) in slot order: reference, physical result, naive."""
        out = [(self.reference, bool(self.gui_show_ref.value)), (self.result, True)]
        if self.naive_runner is not None:
            out.append((self.naive_runner, bool(self.gui_show_naive.value) and self.naive is not None))
        return out

    def _slots(self) -> dict[int, np.ndarray]:
        """Where each visible runner stands [m] (by id): in a row across the view, at one depth from the
        camera (so the side camera shows true relative sizes), or all at one place when overlaid."""
        vis = [r for r, v in self._runners() if v]
        if self.gui_overlay.value or len(vis) < 2:
            return {id(r): np.zeros(3) for r in vis}
        across = self._lateral if self.gui_camera.value == "front" else self._forward
        gap = 0.9 * max(r.track.stature for r in vis) + 0.4
        n = len(vis)
        return {id(r): (k - (n - 1) / 2) * gap * across for k, r in enumerate(vis)}

    def _draw(self) -> None:
        """One frame: index the precomputed tracks at the current time and send the node updates."""
        with self._draw_lock, self._atomic():
            t = self._t
            machine, onion = bool(self.gui_machine.value), bool(self.gui_onion.value)
            # the ground moves under the physical result, which runs in place at its slot
            i, _ = self.result.track.frame_at(t)
            here = np.asarray(self.result.track.com[i], float).copy()
            here[UP_AXIS] = 0.0
            self._grid.position = -np.mod(here, 2.0)
            slots = self._slots()
            for runner, visible in self._runners():
                runner.set_visible(visible)
                if visible:
                    runner.draw(t, slots[id(runner)], machine, onion and runner is self.result)
            if self._camera_dirty:
                self._frame_camera(slots)

    def _frame_camera(self, slots=None) -> None:
        """Point the tab's camera (side, front, three-quarter) so that every visible runner is whole."""
        self._camera_dirty = False
        if self.client is None:
            return
        slots = self._slots() if slots is None else slots
        vis = [r for r, v in self._runners() if v]
        H = max(r.track.stature for r in vis)
        pts = np.array([slots[id(r)] for r in vis])
        centre = pts.mean(axis=0)
        up = np.eye(3)[UP_AXIS]
        width = float(np.ptp(pts @ (self._lateral if self.gui_camera.value == "front" else self._forward))) + 1.3 * H
        height = 1.35 * H
        cam = self.gui_camera.value
        fov = np.radians(_CAMERA_FOV_DEG[cam])
        cs = self.client.camera
        w_px, h_px = (cs.image_width, cs.image_height) if getattr(cs, "image_height", 0) else (1280, 800)
        free_px = max(w_px - PANEL_PX, 0.5 * w_px)  # the control panel covers the right of the canvas
        dist = max(height / h_px, width / free_px) * h_px / (2 * np.tan(fov / 2))
        side = self._lateral  # the runner goes left to right on screen (screen right = forward)
        if cam == "side":
            view = side
        elif cam == "front":
            view = self._forward
        else:
            az, el = np.radians(40.0), np.radians(14.0)
            view = np.cos(el) * (np.cos(az) * side + np.sin(az) * self._forward) + np.sin(el) * up
        right = np.cross(-view, up)  # screen right
        right /= max(np.linalg.norm(right), 1e-9)
        m_per_px = 2 * dist * np.tan(fov / 2) / h_px
        look = centre + 0.5 * H * up + right * (0.5 * (w_px - free_px) * m_per_px)  # centred in the free part
        with self.client.atomic():
            cs.fov = fov
            cs.up_direction = up
            cs.position = look + dist * view
            cs.look_at = look

    # handlers (viser's pool); programmatic value changes come with event.client None and are ignored
    def _on_play(self, event) -> None:
        self._playing = not self._playing
        self.gui_play.label = "Pause" if self._playing else "Play"

    def _step(self, frames: int) -> None:
        """Pause and move one frame of the result."""
        if self._playing:
            self._on_play(None)
        tr = self.result.track
        i, _ = tr.frame_at(self._t)
        i = (i + frames) % tr.n_frames
        self._t = (i + 0.5) * tr.frame_time
        self.gui_time.value = round(min(self._t, self.gui_time.max), 2)
        self._draw()
        self._update_playheads()
        self.gui_state.content = self._state_md()

    def _on_rate(self, event) -> None:
        v = float(self.gui_rate.value)
        if not (math.isfinite(v) and 0.1 <= v <= 2.0):  # a crafted value: the slider's own range only
            self._show_error(f"Playback speed {v:g}× is outside 0.1× to 2×")
            self.gui_rate.value = self._rate
            return
        self._rate = v

    def _on_time(self, event) -> None:
        if event.client is None:
            return
        t = float(self.gui_time.value)
        if not (math.isfinite(t) and 0.0 <= t <= self.result.track.duration + 0.01):
            self._show_error(f"Time {t:g} s is outside 0 to {self.result.track.duration:.2f} s")
            self.gui_time.value = round(min(self._t, self.gui_time.max), 2)
            return
        self._t = t
        self._draw()
        self._update_playheads()
        self.gui_state.content = self._state_md()

    def _on_view(self, event) -> None:
        if getattr(event, "client", 1) is None:
            return
        if self.gui_camera.value not in CAMERAS:  # a crafted value: the dropdown's own options only
            self._show_error(f"Camera must be one of {', '.join(CAMERAS)}")
            self.gui_camera.value = "side"
        self._camera_dirty = True
        self._draw()

    def _update_playheads(self) -> None:
        tr = self.shown.track
        if self.shown.preview:
            return
        i, _ = tr.frame_at(self._t)
        self.gui_plot.data = self._force_series(tr, i)
        self.gui_speed_plot.data = self._speed_series(tr, i)

    def tick(self, dt: float, now: float) -> None:
        """The player's call, every display frame: advance the clock and draw (unless a quick change of
        this tab is being computed: then the clock runs on but frames are not sent, see Studio)."""
        if self._playing:
            self._t = (self._t + dt * self._rate) % self.result.track.duration
        if self._busy.is_set():
            return
        if self._playing:
            self._draw()
        if now - self._last_slider > 0.25:  # the scrubber and playheads follow, a few times a second
            self._last_slider = now
            if self._playing:
                self.gui_time.value = round(min(self._t, self.gui_time.max), 2)
                self._update_playheads()
            if self._work_since is not None:  # progress of a long job
                self.gui_status.content = self._status_md()
