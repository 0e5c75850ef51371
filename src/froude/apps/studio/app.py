"""The live studio in the browser (viser): one session per browser tab — its own clip, controls, scene,
result and worker — with the reference, the physical result and the engine-style naive retarget drawn as
solid limbs, the simple machine over them, a timeline, a comparison table, plots and downloads.

Threads: viser calls the GUI handlers on its pool; they check the value against the control's own limits
and post the latest parameters to the tab's worker thread, which computes the IK result and pushes it,
then its physics report (a newer request makes it skip the stale one). When the result would be slow (long
outputs) it first pushes a cheap preview (machine + time-warped reference, no IK) and shows its progress.
One player thread draws every tab's frame at the display rate by indexing arrays precomputed once per
result; it holds a tab's frames while a quick change of that tab is computed, so the change reaches the
page sooner.
"""
from __future__ import annotations

import contextlib
import html
import io
import math
import os
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ...constants import UP_AXIS
from ...errors import FroudeError
from ...result import Result
from .session import LIMITS, MODES, Params, Session, Solved, with_character, with_report
from .tracks import Track, capsule_instances, naive_track

#: Frames drawn per second (the motion itself is indexed at its own rate, 120 Hz for the sample).
DISPLAY_HZ = 30.0
#: A change whose IK result is expected to take longer than this [s] (the last result of its mode, per
#: stride) first shows a preview — the machine's motion on the new body, no IK — and waits DEBOUNCE_S of
#: quiet before solving (a slider drag sends many changes). Quicker ones go straight to the result.
SLOW_RESULT_S = 0.1
DEBOUNCE_S = 0.08
#: Pause [s] after pushing a result, so the websocket thread sends it before the report is computed.
YIELD_S = 0.003
#: The paper's Figure 3 spacing of snapshots [s]: the onion skin's ghosts are this far apart in time.
ONION_SPACING_S = 0.066
ONION_GHOSTS = 4
#: Largest clip the page accepts [bytes] (a 10-minute 120 Hz BVH of 30 joints is about 20 MB).
MAX_CLIP_BYTES = 32 * 1024 * 1024
#: Cameras: side is the paper's Figure 3 view, a long lens far away, so that runners at the same depth
#: keep their true relative size (a near-orthographic projection); fields of view [deg].
CAMERAS = ("side", "front", "three-quarter")
#: Width [px] of the control panel over the canvas (auto-framing centres the runners in the rest).
PANEL_PX = 400
_CAMERA_FOV_DEG = {"side": 8.0, "front": 8.0, "three-quarter": 30.0}

#: Export choices for the BVH download.
BVH_UNITS = ("the clip's", "metres", "centimetres")
BVH_RATES = ("the clip's", "24 Hz", "30 Hz", "60 Hz", "120 Hz")
BVH_ROOT = ("root motion", "in place")

COLOR_RESULT = (40, 90, 210)
COLOR_PREVIEW = (140, 150, 165)
COLOR_REFERENCE = (230, 130, 30)
COLOR_NAIVE = (150, 60, 190)
COLOR_COM = (220, 30, 60)
COLOR_LEG = (20, 150, 80)
COLOR_FEET = np.array([[30, 120, 230], [230, 60, 60]], np.uint8)  # left, right contacts
LEGEND = (
    (COLOR_REFERENCE, "reference", "the clip as captured, on its own body"),
    (COLOR_RESULT, "physical result", "froude: the simple machine scaled by dynamic similarity, then IK"),
    (COLOR_NAIVE, "naive retarget", "what engines do: joint angles copied, root × L, timing unchanged"),
    (COLOR_PREVIEW, "preview", "the machine's motion on the new body before IK (shown while solving)"),
    (COLOR_COM, "centre of mass", "ball: the body's COM; line: its trail over the whole result"),
    (COLOR_LEG, "spring leg", "the simple machine's leg: COM to the contact point while a foot is down"),
    (tuple(COLOR_FEET[0]), "left contact", "where the left foot is planted (the machine's contact point)"),
    (tuple(COLOR_FEET[1]), "right contact", "where the right foot is planted"),
)


@dataclass
class Timing:
    """Latency of the last change [s]: compute and scene push of the preview and of the result."""

    preview_compute: float = float("nan")
    preview_push: float = float("nan")
    result_compute: float = float("nan")
    result_push: float = float("nan")
    report_compute: float = float("nan")
    started_at: float = float("nan")  # perf_counter when the worker took the change up [s]
    result_flushed_at: float = float("nan")  # perf_counter when the result was handed to the server [s]


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
    from ...viz.render import LEFT, RIGHT

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


def _swatch(color, text: str, hint: str) -> str:
    r, g, b = (int(c) for c in color)
    return (f'<div title="{html.escape(hint)}" style="display:flex;align-items:center;gap:6px;margin:1px 0;'
            f'cursor:help"><span style="display:inline-block;width:14px;height:14px;border-radius:3px;'
            f'background:rgb({r},{g},{b})"></span><span style="font-size:0.85em">{html.escape(text)}</span></div>')


def _page_script(title: str) -> str:
    """An invisible element whose error handler sets the tab's title and, once per page, installs the
    keys (Space play/pause, ←/→ a frame) and dropping a clip anywhere on the page (it goes to the
    page's own 'Open clip' file input, so it is checked like a picked file).

    The keys are taken on the window in the capture phase and stopped there: viser's camera controls
    listen on the document and turn the camera at 50°/s while an arrow key is held, so a frame step
    would also swing the view (more so on a busy machine, where a press lasts longer)."""
    js = (
        f"document.title={_js_str(title)};"
        "if(!window.__froude){window.__froude=1;"
        "const btn=(t)=>[...document.querySelectorAll('button')].find(b=>b.textContent.trim()===t);"
        "window.addEventListener('keydown',(e)=>{const a=document.activeElement;"
        "if(a&&(a.tagName==='INPUT'||a.tagName==='TEXTAREA'||a.isContentEditable))return;"
        "let b=null;if(e.code==='Space'){b=btn('Pause')||btn('Play');}"
        "else if(e.code==='ArrowRight'){b=btn('Next frame');}else if(e.code==='ArrowLeft'){b=btn('Previous frame');}"
        "if(b){e.preventDefault();e.stopPropagation();if(a&&a.blur)a.blur();b.click();}},true);"
        "window.addEventListener('dragover',(e)=>{e.preventDefault();});"
        "window.addEventListener('drop',(e)=>{e.preventDefault();const f=e.dataTransfer&&e.dataTransfer.files;"
        "if(!f||!f.length)return;const i=document.querySelector('input[type=file]');if(!i)return;"
        "const d=new DataTransfer();d.items.add(f[0]);i.files=d.files;"
        "i.dispatchEvent(new Event('change',{bubbles:true}));});}"
    )
    return f'<img src="/froude-no-image" alt="" style="display:none" onerror="{html.escape(js, quote=True)}">'


def _js_str(s: str) -> str:
    from ...io.jsonable import dumps

    return dumps(s).replace("<", "\\u003c")


# ---- one browser tab ---------------------------------------------------------------------------------
class Tab:
    """One browser tab's session: its clip, parameters, results, controls, scene and worker thread.

    target: what to draw into and build the controls on (a viser ClientHandle for a browser tab, or the
    server itself for a tab without a browser, as in tests); client: the ClientHandle or None.
    """

    def __init__(self, studio: Studio, target, client=None, root: str = "/froude"):
        self.studio, self.target, self.client, self.root_name = studio, target, client, root
        self.session: Session = studio.session
        self.clip_name = studio.clip_name
        self.params = studio.first.params
        self.good: Solved = studio.first  # the last good result
        self.shown: Solved = self.good
        self.naive: Solved | None = None
        self.timing = Timing()
        self.message = ""
        self._stop = threading.Event()
        self._busy = threading.Event()  # set while a quick change is computed: the player skips its frames
        self._work_since: float | None = None  # perf_counter when the current long job began (progress)
        self._work_what = ""
        self._wake = threading.Condition()
        self._pending: tuple | None = None  # ("params", Params, t) | ("clip", name, bytes, t) | ("naive",)
        #: The newest change asked for by the controls and not yet finished (None: the controls show self.good)
        self._asked: Params | None = None
        self._draw_lock = threading.RLock()
        self._t = 0.0
        self._playing = True
        self._rate = 1.0
        self._last_slider = 0.0
        self._result_s = {self.good.params.mode: (self.good.seconds, self.good.params.strides)}
        self._defaults = self.session.character_defaults(self.params.character)
        self._camera_dirty = True
        self._range_note = ""
        self._build_scene()
        self._build_gui()
        self._publish(self.good)
        self._worker = threading.Thread(target=self._work_loop, name="froude-studio-tab", daemon=True)
        self._worker.start()
        # bound the speed slider to what this character can reach (a few seconds: ~24 short outputs, in the worker)
        self._post(("range",))

    # ---- lifecycle
    def close(self) -> None:
        self._stop.set()
        with self._wake:
            self._wake.notify_all()
        if self._worker.is_alive() and self._worker is not threading.current_thread():
            self._worker.join(timeout=5.0)

    def _flush(self) -> None:
        if self.client is not None:
            self.client.flush()
        else:
            self.studio.server.flush()

    def _atomic(self):
        return self.client.atomic() if self.client is not None else self.studio.server.atomic()

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

    # ---- GUI
    # Long because it is a flat list of the page's controls, one statement per widget, in page order.
    def _build_gui(self) -> None:
        gui = self.target.gui
        gui.configure_theme(control_width="large", show_logo=False)
        p = self.params
        h, m, legs = self._defaults
        L = LIMITS
        self.gui_page = gui.add_html(_page_script(self._title()), order=0)
        with gui.add_folder("Clip", order=1):
            self.gui_open = gui.add_upload_button("Open clip (.bvh)", icon=None, mime_type=".bvh",
                                                  hint=f"a running BVH clip up to {MAX_CLIP_BYTES >> 20} MB; "
                                                  "or drop the file anywhere on the page")
            self.gui_facts = gui.add_markdown("")
        with gui.add_folder("Change", order=2):
            self.gui_mode = gui.add_dropdown("Mode", options=MODES, initial_value=p.mode)
            self.gui_char = gui.add_dropdown("Character", options=tuple(self.session.presets),
                                             initial_value=p.character)
            self.gui_height = gui.add_number("Height [m]", initial_value=round(h, 3), min=L["height"].lo,
                                             max=L["height"].hi, step=L["height"].step)
            self.gui_mass = gui.add_number("Mass [kg]", initial_value=round(m, 1), min=L["mass"].lo, max=L["mass"].hi,
                                           step=L["mass"].step)
            self.gui_legs = gui.add_slider("Leg scale", min=L["leg_scale"].lo, max=L["leg_scale"].hi,
                                           step=L["leg_scale"].step, initial_value=round(legs, 2))
            self.gui_speed = gui.add_slider("Speed factor", min=L["speed"].lo, max=L["speed"].hi, step=L["speed"].step,
                                            initial_value=p.speed)
            self.gui_strides = gui.add_slider("Strides", min=L["strides"].lo, max=L["strides"].hi, step=1,
                                              initial_value=p.strides)
            self.gui_to = gui.add_number("Goal speed factor", initial_value=p.to_factor, min=L["to_factor"].lo,
                                         max=L["to_factor"].hi, step=L["to_factor"].step)
            self.gui_steps = gui.add_slider("Steps to change", min=L["steps"].lo, max=L["steps"].hi, step=1,
                                            initial_value=p.steps)
            self.gui_status = gui.add_markdown("")
        with gui.add_folder("Playback", order=3):
            self.gui_play = gui.add_button("Pause")
            self.gui_prev = gui.add_button("Previous frame", hint="← key")
            self.gui_next = gui.add_button("Next frame", hint="→ key")
            self.gui_bands = gui.add_html("")
            self.gui_time = gui.add_slider("Time [s]", min=0.0, max=round(self.good.track.duration, 2), step=0.01,
                                           initial_value=0.0)
            self.gui_rate = gui.add_slider("Playback speed", min=0.1, max=2.0, step=0.05, initial_value=1.0)
            self.gui_camera = gui.add_dropdown("Camera", options=CAMERAS, initial_value="side")
            self.gui_frame = gui.add_button("Frame all", hint="point the camera so every runner is whole")
            self.gui_onion = gui.add_checkbox("Onion skin (every 0.066 s)", initial_value=False)
        with gui.add_folder("Compare", order=4):
            self.gui_show_ref = gui.add_checkbox("Show reference", initial_value=True)
            self.gui_show_naive = gui.add_checkbox("Show naive retarget", initial_value=False)
            self.gui_overlay = gui.add_checkbox("Overlay (else side by side)", initial_value=False)
            self.gui_machine = gui.add_checkbox("Show simple machine", initial_value=True)
            self.gui_table = gui.add_markdown("")
        with gui.add_folder("Plots", order=5):
            t, fm, fb, now = self._force_series(self.good.track, 0)
            self.gui_plot = gui.add_uplot(
                data=(t, fm, fb, now),
                series=({"label": "t [s]"}, {"label": "machine", "stroke": "#dc1e3c", "width": 2},
                        {"label": "body", "stroke": "#286edc", "width": 1},
                        {"label": "now", "stroke": "#111111", "width": 0, "points": {"show": True, "size": 9}}),
                title="vertical leg force [body weights]", aspect=1.6,
                scales={"x": {"time": False}, "y": {"auto": True}},
            )
            t, v, now = self._speed_series(self.good.track, 0)
            self.gui_speed_plot = gui.add_uplot(
                data=(t, v, now),
                series=({"label": "t [s]"}, {"label": "speed [m/s]", "stroke": "#286edc", "width": 2},
                        {"label": "now", "stroke": "#111111", "width": 0, "points": {"show": True, "size": 9}}),
                title="running speed [m/s]", aspect=2.2, scales={"x": {"time": False}, "y": {"auto": True}},
            )
        with gui.add_folder("Legend", order=6):
            self.gui_legend = gui.add_html("".join(_swatch(c, t, h) for c, t, h in LEGEND))
        with gui.add_folder("Export", order=7):
            self.gui_bvh_units = gui.add_dropdown("BVH units", options=BVH_UNITS, initial_value=BVH_UNITS[0])
            self.gui_bvh_fps = gui.add_dropdown("BVH rate", options=BVH_RATES, initial_value=BVH_RATES[0])
            self.gui_bvh_root = gui.add_dropdown("BVH root", options=BVH_ROOT, initial_value=BVH_ROOT[0])
            self.gui_dl_bvh = gui.add_button("Download BVH", hint="the result, with the units, rate and root above")
            self.gui_dl_report = gui.add_button("Download report", hint="the physics report (JSON)")
            self.gui_dl_csv = gui.add_button("Download CSV", hint="per frame: time, COM, ground force, contacts")
            self.gui_dl_mp4 = gui.add_button("Download MP4", hint="a render of the reference and the result")
        with gui.add_folder("Details", order=8, expand_by_default=False):
            self.gui_state = gui.add_markdown(self._state_md())

        self.gui_play.on_click(self._on_play)
        self.gui_prev.on_click(lambda e: self._step(-1))
        self.gui_next.on_click(lambda e: self._step(+1))
        self.gui_time.on_update(self._on_time)
        self.gui_rate.on_update(self._on_rate)
        for g in (self.gui_overlay, self.gui_show_ref, self.gui_machine, self.gui_onion, self.gui_camera):
            g.on_update(self._on_view)
        self.gui_frame.on_click(self._on_view)
        self.gui_show_naive.on_update(self._on_naive)
        self.gui_char.on_update(self._on_character)
        for g in (self.gui_mode, self.gui_height, self.gui_mass, self.gui_legs, self.gui_speed, self.gui_strides,
                  self.gui_to, self.gui_steps):
            g.on_update(self._on_change)
        self.gui_open.on_upload(self._on_upload)
        self.gui_dl_bvh.on_click(self._on_download_bvh)
        self.gui_dl_report.on_click(self._on_download_report)
        self.gui_dl_csv.on_click(self._on_download_csv)
        self.gui_dl_mp4.on_click(self._on_download_mp4)
        self._sync_mode_controls()

    def _title(self) -> str:
        return f"{self.clip_name} · froude studio"

    @staticmethod
    def _force_series(track: Track, i: int):
        """(t, machine force, body force, playhead) on the result's frames [s], [body weights]."""
        F = track.n_frames
        t = np.arange(F) * track.frame_time
        fm = np.interp(t, track.force_t, track.force_bw) if len(track.force_t) else np.full(F, np.nan)
        fb = np.asarray(track.body_force_bw, float)
        now = np.full(F, np.nan)
        now[i] = fm[i] if np.isfinite(fm[i]) else fb[i]
        return t, fm, fb, now

    @staticmethod
    def _speed_series(track: Track, i: int):
        """(t, horizontal COM speed [m/s], playhead) on the result's frames."""
        t = np.arange(track.n_frames) * track.frame_time
        v = np.asarray(track.speed_m_s, float)
        now = np.full(track.n_frames, np.nan)
        now[i] = v[i]
        return t, v, now

    def _sync_mode_controls(self) -> None:
        scale = self.gui_mode.value == "scale"
        for g in (self.gui_speed, self.gui_strides):
            g.disabled = not scale
        for g in (self.gui_to, self.gui_steps):
            g.disabled = scale

    def params_from_gui(self) -> Params:
        """The parameters the controls show, checked against the controls' own options and limits (values
        can be crafted); numbers equal to the character's own are not overrides."""
        h0, m0, l0 = self._defaults

        def override(v, v0, tol):
            v = float(v)
            return None if abs(v - v0) <= tol else v

        p = Params(
            mode=str(self.gui_mode.value), character=str(self.gui_char.value),
            height=override(self.gui_height.value, h0, 6e-3), mass=override(self.gui_mass.value, m0, 0.06),
            leg_scale=override(self.gui_legs.value, l0, 6e-3), speed=float(self.gui_speed.value),
            strides=self.gui_strides.value, to_factor=float(self.gui_to.value), steps=self.gui_steps.value,
        ).check(self.session.presets)
        rng = self._known_speed_range(p.character)
        if p.mode == "scale" and rng is not None and not rng.empty and not (
                rng.lo - 1e-9 <= p.speed <= rng.hi + 1e-9):
            raise FroudeError(f"Speed ×{p.speed:g} is beyond what {p.character} can run on this clip with every "
                              f"physics bar met: pick ×{rng.lo:.2f} to ×{rng.hi:.2f} "
                              f"({rng.lo_m_s:.2f} to {rng.hi_m_s:.2f} m/s)")
        return p

    def _known_speed_range(self, character: str):
        """The reachable speed factors of a preset on this clip if already worked out (else None).

        Per preset, whatever its number overrides: speed factors are relative to the dynamically scaled
        speed, so a uniformly scaled body reaches the same factors."""
        return self.session.speed_ranges.get(character)

    def _bound_speed(self, character: str) -> None:
        """Work out (once per preset; about 24 short outputs: a few seconds, minutes on a loaded machine) the
        speed factors whose outputs meet every physics bar and bound the speed slider to them (within its
        own limits).

        The search gives way to the user: a change (or the tab closing) that comes in meanwhile stops it
        after the output being checked, and the change is computed next; the outputs already checked are
        kept, and the search resumes from them when this preset's result is next on screen (apply)."""
        from ...speed_range import SearchStopped, reachable_speed_range

        rng = self.session.speed_ranges.get(character)
        lim = LIMITS["speed"]
        if rng is None:
            # Until this character's search is done the slider spans its own limits (not the previous
            # character's range), and the status says the range is being worked out.
            self._set_speed_bounds(lim.lo, lim.hi, f"working out which speeds {character} reaches with every "
                                                   "physics bar met (the slider is not narrowed meanwhile)")
            try:
                rng = reachable_speed_range(self.session.prep, None if character == "same" else character,
                                            stop=lambda: self._stop.is_set() or self._newer_pending())
            except SearchStopped:
                return  # resumed when this character's result is next on screen
            self.session.speed_ranges[character] = rng
        if rng.empty:
            lo, hi = lim.lo, lim.hi
            note = (f"no speed factor meets every physics bar for {character} on this clip "
                    f"(×1 = {rng.base_m_s:.2f} m/s already misses one): the slider is not narrowed")
        else:
            lo, hi = max(lim.lo, rng.lo), min(lim.hi, rng.hi)
            note = (f"speed reachable with every bar met: ×{rng.lo:.2f} to ×{rng.hi:.2f} "
                    f"({rng.lo_m_s:.2f} to {rng.hi_m_s:.2f} m/s)")
        self._set_speed_bounds(lo, hi, note)

    def _set_speed_bounds(self, lo: float, hi: float, note: str) -> None:
        """Bound the speed slider to ×lo … ×hi and show why (the status's range note)."""
        self._range_note = note
        if (self.gui_speed.min, self.gui_speed.max) != (round(lo, 2), round(hi, 2)):
            self.gui_speed.min, self.gui_speed.max = round(lo, 2), round(hi, 2)
        self.gui_status.content = self._status_md()
        self._flush()

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

    def _on_naive(self, event) -> None:
        if event.client is None:
            return
        if self.gui_show_naive.value and self.naive is None:
            self._post(("naive",))
        self._camera_dirty = True
        self._draw()

    def _on_character(self, event) -> None:
        if event.client is None:
            return
        name = str(self.gui_char.value)
        try:
            defaults = self.session.character_defaults(name)  # refuses anything but a listed preset
        except FroudeError as e:
            self._refuse(e)
            return
        self._defaults = defaults
        h, m, legs = self._defaults
        self.gui_height.value, self.gui_mass.value, self.gui_legs.value = round(h, 3), round(m, 1), round(legs, 2)
        try:
            self.request(with_character(self.params_from_gui(), name))
        except FroudeError as e:
            self._refuse(e)

    def _on_change(self, event) -> None:
        if event.client is None:
            return
        try:
            params = self.params_from_gui()
        except FroudeError as e:
            self._refuse(e)
            return
        self._sync_mode_controls()
        self.request(params)

    def _refuse(self, err) -> None:
        """A control value outside its options or limits: say so, put the controls back to the change being
        computed (or, with none, to the last good result's values), and compute nothing."""
        self._show_error(err)
        asked = self._asked
        self._set_controls(asked if asked is not None else self.good.params)

    def _set_controls(self, p: Params) -> None:
        """The controls showing ``p`` (the character's own numbers where ``p`` does not override them)."""
        try:
            self._defaults = self.session.character_defaults(p.character)
        except FroudeError:
            pass
        h, m, legs = self._defaults
        self.gui_mode.value, self.gui_char.value = p.mode, p.character
        self.gui_height.value = round(p.height if p.height is not None else h, 3)
        self.gui_mass.value = round(p.mass if p.mass is not None else m, 1)
        self.gui_legs.value = round(p.leg_scale if p.leg_scale is not None else legs, 2)
        self.gui_speed.value, self.gui_strides.value = p.speed, p.strides
        self.gui_to.value, self.gui_steps.value = p.to_factor, p.steps
        self._sync_mode_controls()

    def _on_upload(self, event) -> None:
        f = self.gui_open.value
        name = Path(str(f.name)).name or "clip.bvh"
        data = f.content
        if not name.lower().endswith(".bvh"):
            self._show_error(f"{name}: not a .bvh file; open a BVH motion clip")
            return
        if len(data) > MAX_CLIP_BYTES:
            self._show_error(f"{name}: {len(data) / 2**20:.1f} MB is larger than the studio's "
                             f"{MAX_CLIP_BYTES >> 20} MB limit; trim the clip or use the command line")
            return
        self._post(("clip", name, bytes(data)))

    # ---- downloads
    def _send(self, event, name: str, data: bytes) -> None:
        client = event.client if event is not None and event.client is not None else self.client
        if client is not None:
            client.send_file_download(name, data, save_immediately=True)

    @property
    def _good_result(self) -> Result:
        """The last good result's output (a good result is a solved one, never an IK-free preview)."""
        assert self.good.result is not None
        return self.good.result

    def _on_download_bvh(self, event) -> None:
        """The result as BVH: in the clip's units or metres/centimetres, at the clip's rate or another, with
        its root motion or in place (the CLI's ``in_place_motion``: only the forward progression between
        touchdowns comes off the root, so the sway and the surge within each step stay)."""
        from ...io.bvh import bvh_text
        from ...result import in_place_motion

        units, rate, root = str(self.gui_bvh_units.value), str(self.gui_bvh_fps.value), str(self.gui_bvh_root.value)
        if units not in BVH_UNITS or rate not in BVH_RATES or root not in BVH_ROOT:  # crafted values
            self._show_error("BVH export options must be chosen from their lists")
            return
        # in place before resampling: the machine path's touchdowns are on the result's own frames
        motion = in_place_motion(self._good_result) if root == "in place" else self._good_result.motion
        if rate != BVH_RATES[0]:
            motion = motion.resample(float(rate.split()[0]))
        scale = {"metres": 1.0, "centimetres": 0.01}.get(units)
        self._send(event, self._file_stem() + ".bvh", bvh_text(motion, scale).encode())

    def _on_download_report(self, event) -> None:
        res = with_report(self.session.prep, self.good).result
        assert res is not None and res.report is not None  # with_report computes it
        self._send(event, self._file_stem() + ".report.json", res.report.to_json().encode())

    def _on_download_csv(self, event) -> None:
        """Per-frame data (COM, ground force, contacts, machine path) through ``froude.io.framedata``."""
        try:
            from ...io.framedata import frame_table, write_frame_data
        except ImportError:
            self._show_error("per-frame CSV needs froude.io.framedata, which this build does not have")
            return
        res = self._good_result
        path = res.path if res.path is not None and len(res.path.times) == res.motion.n_frames else None
        try:
            table = frame_table(res.motion, res.retarget.body, machine_path=path)
            with tempfile.TemporaryDirectory(prefix="froude-studio-") as d:
                data = write_frame_data(table, Path(d) / "frames.csv").read_bytes()
        except FroudeError as e:
            self._show_error(e)
            return
        self._send(event, self._file_stem() + ".csv", data)

    def _on_download_mp4(self, event) -> None:
        """Render the reference and the result (and the naive one when shown) with ``froude render``'s
        capsules and this camera, then send the file. Takes seconds: the status says so."""
        from ...viz.render import render_video

        motions = [self.session.prep.motion, self._good_result.motion]
        labels = ["reference", f"physical ({self.good.params.character})"]
        if self.gui_show_naive.value and self.naive is not None and self.naive.result is not None:
            motions.append(self.naive.result.motion)
            labels.append("naive")
        self._set_status(f"*rendering the MP4 ({len(motions)} runners) ...*")
        try:
            with tempfile.TemporaryDirectory(prefix="froude-studio-") as d:
                out = Path(d) / "render.mp4"
                render_video(motions, out, labels=labels, fps=30.0, camera=str(self.gui_camera.value), width=960)
                data = out.read_bytes()
        except FroudeError as e:
            self._show_error(e)
            return
        self._set_status(None)
        self._send(event, self._file_stem() + ".mp4", data)

    def _file_stem(self) -> str:
        p = self.good.params
        tag = f"x{p.speed:g}" if p.mode == "scale" else f"to{p.to_factor:g}x{p.steps}"
        return f"{Path(self.clip_name).stem}_{p.character}_{p.mode}_{tag}"

    # ---- recompute
    def request(self, params: Params) -> None:
        """Ask for a recompute (the latest request wins). What every control calls."""
        self._asked = params
        self._post(("params", params))

    def _post(self, job: tuple) -> None:
        with self._wake:
            if job[0] in ("naive", "range") and self._pending is not None:
                return  # a newer change computes its naive twin anyway
            self._pending = (*job, time.perf_counter())
            self._wake.notify_all()

    def _take(self, timeout: float | None = None):
        with self._wake:
            if self._pending is None and not self._stop.is_set():
                self._wake.wait(timeout)
            got, self._pending = self._pending, None
            return got

    def _newer_pending(self) -> bool:
        with self._wake:
            return self._pending is not None

    def _work_loop(self) -> None:
        while not self._stop.is_set():
            job = self._take(timeout=0.5)
            if job is None:
                continue
            try:
                if job[0] == "params":
                    self.apply(job[1], debounce=DEBOUNCE_S)
                elif job[0] == "clip":
                    self.open_clip(job[1], job[2])
                elif job[0] == "naive":
                    self._solve_naive()
                elif job[0] == "range" and self.good.params.mode == "scale":
                    self._bound_speed(self.good.params.character)
            except Exception as e:  # never let a bug in one job kill the tab; say it and carry on
                traceback.print_exc(file=sys.stderr)
                self._show_error(f"internal error: {type(e).__name__}: {e}")

    def apply(self, params: Params, *, debounce: float = 0.0) -> Timing:
        """Preview → push → (debounce) → result → push, for one change; returns its timing. Never raises
        a FroudeError: a bad change shows its message and the last good result stays."""
        timing = Timing(started_at=time.perf_counter())
        slow = self.expected_seconds(params) > SLOW_RESULT_S
        if not slow:
            self._busy.set()  # a quick change: the player holds its frames until it is on screen
        try:
            if slow:
                self._work_since, self._work_what = time.perf_counter(), params.label()
                t0 = time.perf_counter()
                pre = self.session.preview(params)
                if pre is not None:
                    timing.preview_compute = time.perf_counter() - t0
                    t1 = time.perf_counter()
                    self._publish(pre, status="preview (machine only)")
                    timing.preview_push = time.perf_counter() - t1
                if debounce > 0 and self._stop.wait(debounce):
                    return timing
                if self._newer_pending():
                    return timing  # superseded: go straight to the newer change
            t0 = time.perf_counter()
            res = self.session.solve(params, report=False)  # the corrected motion first ...
            timing.result_compute = time.perf_counter() - t0
            self._result_s[res.params.mode] = (timing.result_compute, res.params.strides)
            if self._newer_pending():
                return timing
            res.track.borrow_rig(self.result.track)  # its own rig is built after the push
            t1 = time.perf_counter()
            self._publish(res, status="computing the physics report ...")
            timing.result_flushed_at = time.perf_counter()
            timing.result_push = timing.result_flushed_at - t1
            # let the server's event loop thread take the GIL and send the new runner before the report's
            # arithmetic holds it (CPython hands the GIL over only every few milliseconds otherwise)
            time.sleep(YIELD_S)
            self._busy.clear()  # the runner is on the page: playback goes on while the rest is worked out
            if self._newer_pending():
                return timing  # the next change first; this one's report would be stale
            t2 = time.perf_counter()
            res.track.exact_rig()  # this body's own capsules, all frames: the player only indexes from here on
            res = with_report(self.session.prep, res)  # ... then its numbers
            timing.report_compute = time.perf_counter() - t2
            if self._newer_pending():
                return timing
            self.good = res
            self.naive = None
            self._work_since = None
            self._publish(res)
            if self.gui_show_naive.value:
                self._solve_naive()
            if res.params.mode == "scale" and not self._newer_pending():
                self._bound_speed(res.params.character)
        except FroudeError as e:
            self._show_error(e)
        finally:
            self._busy.clear()
            self._work_since = None
            if self._asked is params and not self._newer_pending():
                self._asked = None  # done (a result or its refusal): the controls are the good result's again
        self.timing = timing
        return timing

    def _solve_naive(self) -> None:
        """The engine-style naive retarget of the current result (scale only), drawn beside it."""
        from ... import pipeline

        p = self.good.params
        if p.mode != "scale":
            self.naive = None
            self._set_status("*the naive retarget has no acceleration: shown for scale only*")
            self._draw()
            return
        t0 = time.perf_counter()
        spec, nums = p.character_args()
        res = pipeline.scale(self.session.prep, spec, speed=p.speed, strides=p.strides, method="naive", **nums)
        track = naive_track(res, self.session.prep)
        track.capsules  # noqa: B018
        from .tracks import motion_hash

        self.naive = Solved(p, track, res, False, time.perf_counter() - t0, motion_hash(res.motion),
                            res.motion.n_frames)
        with self._draw_lock:
            if self.naive_runner is None:
                self.naive_runner = _Runner(self.target.scene, f"{self.root_name}/naive", track, COLOR_NAIVE)
            else:
                self.naive_runner.set_track(track, COLOR_NAIVE)
            self._camera_dirty = True
            self.gui_table.content = self._table_md()
            self.gui_state.content = self._state_md()
            self._draw()
        self._flush()

    def open_clip(self, name: str, data: bytes) -> bool:
        """Prepare an uploaded clip (checked, fitted) and make it this tab's reference. A bad clip says
        why in one line and the current clip stays."""
        from ... import pipeline

        self._work_since, self._work_what = time.perf_counter(), f"opening {name} (loading, checking, fitting)"
        self._set_status(None)  # the progress line says what is going on
        try:
            with tempfile.TemporaryDirectory(prefix="froude-studio-") as d:
                path = Path(d) / name
                path.write_bytes(data)
                try:
                    prep = pipeline.prepare(str(path))
                except FroudeError as e:
                    raise FroudeError(str(e).splitlines()[0].replace(str(path), name).replace(d + os.sep, "")) from None
            prep = replace(prep, source=name)
            session = Session(prep)
            params = replace(self.good.params, height=None, mass=None, leg_scale=None)
            first = with_report(prep, session.solve(params, report=False))
        except FroudeError as e:
            self._show_error(e)
            return False
        finally:
            self._work_since = None
        with self._draw_lock:
            self.session, self.clip_name = session, name
            frame = prep.cycle.frame
            self._forward, self._lateral = np.asarray(frame[0], float), np.asarray(frame[2], float)
            self._defaults = session.character_defaults(params.character)
            self.good, self.naive = first, None
            self._result_s = {params.mode: (first.seconds, params.strides)}
            self.reference.set_track(session.reference, COLOR_REFERENCE)
            self.gui_page.content = _page_script(self._title())
            self._set_controls(params)
            self._camera_dirty = True
            self._t = 0.0
            self._publish(first)
        if self.gui_show_naive.value:
            self._solve_naive()
        if params.mode == "scale":
            self._bound_speed(params.character)
        return True

    def expected_seconds(self, params: Params) -> float:
        """What the IK result of ``params`` should take to compute [s]: the last result of its mode (per
        stride when scaling), or forever (a preview first) when there was none yet."""
        last = self._result_s.get(params.mode)
        if last is None:
            return float("inf")
        seconds, strides = last
        return seconds * (params.strides / max(strides, 1) if params.mode == "scale" else 1.0)

    def _publish(self, solved: Solved, status: str | None = None) -> None:
        """Swap in a new track (preview or result), refresh numbers and plots, and draw the frame now."""
        with self._draw_lock:
            old = self.shown
            self.shown = solved
            self.message = "" if status is None else status
            color = COLOR_PREVIEW if solved.preview else COLOR_RESULT
            self.result.set_track(solved.track, color)
            dur = solved.track.duration
            if self._t >= dur:
                self._t = self._t % dur
            self.gui_time.max = round(dur, 2)
            if abs(old.track.stature - solved.track.stature) > 1e-6:
                self._camera_dirty = True
            done = solved.result is not None and solved.result.report is not None
            if not solved.preview and done:  # numbers and plots follow the runner
                i, _ = solved.track.frame_at(self._t)
                self._set_plot(self.gui_plot, self._force_series(solved.track, i))
                self._set_plot(self.gui_speed_plot, self._speed_series(solved.track, i))
                self.gui_bands.content = self._bands_html(solved.track)
                self.gui_table.content = self._table_md()
                self.gui_facts.content = self._facts_md()
            self.gui_status.content = self._status_md()
            self.gui_state.content = self._state_md()
            self._draw()
        self._flush()

    def _set_status(self, text: str | None) -> None:
        self.message = "" if text is None else text
        self.gui_status.content = self._status_md()
        self._flush()

    def _show_error(self, err) -> None:
        """Say what went wrong (one line) and put the last good result back on screen."""
        msg = str(err).splitlines()[0] if str(err) else type(err).__name__
        if self.shown is not self.good:
            self._publish(self.good)
        self.message = f"error: {msg}"
        self.gui_status.content = self._status_md()
        self.gui_state.content = self._state_md()
        if self.client is not None:
            self.client.add_notification("Change not applied", msg, color="red", auto_close_seconds=10.0)
        self._flush()

    def _update_playheads(self) -> None:
        tr = self.shown.track
        if self.shown.preview:
            return
        i, _ = tr.frame_at(self._t)
        self.gui_plot.data = self._force_series(tr, i)
        self.gui_speed_plot.data = self._speed_series(tr, i)

    @staticmethod
    def _set_plot(plot, data) -> None:
        """New data and a fixed y range from its finite values: the playhead series is NaN but for one
        point, and uPlot's automatic range does not skip NaN."""
        ys = np.concatenate([np.asarray(d, float) for d in data[1:]])
        ys = ys[np.isfinite(ys)]
        lo, hi = (float(ys.min()), float(ys.max())) if len(ys) else (0.0, 1.0)
        pad = 0.08 * max(hi - lo, 1e-3)
        plot.scales = {"x": {"time": False}, "y": {"range": (lo - pad, hi + pad)}}
        plot.data = data

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

    # ---- text
    def _state_md(self) -> str:
        """One line the tests (and the benchmark) read: what is on screen right now (in Details)."""
        s = self.shown
        p = s.params
        rep = s.result.report if s.result is not None else None
        complete = rep is not None
        speed = f"{rep.mean_speed_m_s:.3f}" if rep is not None else "n/a"
        status = "error" if self.message.startswith("error") else (
            "preview" if s.preview else ("ok" if complete else "report"))
        naive = self.naive.n_frames if self.naive is not None else 0
        frame, _ = s.track.frame_at(self._t)
        # drawn heights [m] of the reference and the result at this instant (true relative size checks)
        h_ref, h_res = self.reference.vertical_extent(self._t), self.result.vertical_extent(self._t)
        return (f"`state: clip={self.clip_name.replace(' ', '_')} character={p.character} mode={p.mode} "
                f"speed_factor={p.speed:g} to_factor={p.to_factor:g} steps={p.steps} strides={p.strides} "
                f"n_frames={s.n_frames} frame={frame} h_ref_m={h_ref:.4f} h_res_m={h_res:.4f} "
                f"speed_m_s={speed} naive_frames={naive} hash={s.hash} status={status}`")

    def _status_md(self) -> str:
        if self.message.startswith("error"):
            return (f"**⚠ {html.escape(self.message[7:])}**  \n(showing the last good result: "
                    f"{self.good.params.label()})")
        if self._work_since is not None:
            return f"*working: {self._work_what} … {time.perf_counter() - self._work_since:.1f} s*"
        if self.message:
            return self.message if self.message.startswith("*") else f"*{self.message}*"
        res = self._good_result
        assert res.report is not None  # a good result is shown with its report
        notes = list(res.notes) + [f"bar: {b}" for b in res.report.check_bars()]
        if self._range_note and self.good.params.mode == "scale":
            notes.append(self._range_note)
        head = f"**{self.good.params.label()}**: solved in {self.good.seconds:.2f} s"
        return head + ("".join(f"  \n- {n}" for n in notes) if notes else "  \nall physics bars pass")

    def _facts_md(self) -> str:
        prep = self.session.prep
        m, sm = prep.motion, prep.summary
        ls = float(m.meta.get("length_scale", 1.0))
        unit = {1.0: "m", 0.01: "cm", 0.001: "mm", 0.0254: "inches"}.get(round(ls, 6), f"{ls:.4g} m per unit")
        if "CMU" in str(m.meta.get("units", "")):
            unit += " (CMU)"
        return (f"**{html.escape(self.clip_name)}**  \n"
                f"units: {unit} · {m.fps:.0f} frames/s · {m.n_frames} frames ({m.n_frames * m.frame_time:.2f} s)  \n"
                f"speed {sm.mean_speed:.2f} m/s · Froude number {sm.froude:.2f} · leg {sm.leg_length:.2f} m · "
                f"height {prep.body.stature:.2f} m" + ("" if prep.turn is None else  # a turn: its facts
                f"  \nturns {np.degrees(prep.turn.heading_change_rad):+.0f}° over {prep.turn.length_m:.2f} m "
                "(+ = left; speeds along the path)"))

    def _table_md(self) -> str:
        """Reference, physical and naive side by side: the physics numbers that tell them apart."""
        sm = self.session.prep.summary
        phys = self._good_result.report
        nv = self.naive.result.report if self.naive is not None and self.naive.result is not None else None

        def mean(x):
            return float(np.mean(x)) if len(x) else float("nan")

        def f(v, spec):  # not measurable (no flight phase, ...) reads as a dash
            return format(v, spec) if np.isfinite(v) else "—"

        def col(r):
            if r is None:
                return ["—"] * 7
            return [f(r.mean_speed_m_s, ".2f"), f(r.froude_U, ".2f"), f(r.step_frequency_hz, ".2f"),
                    f"{f(mean(r.stance_times_s), '.3f')} / {f(mean(r.flight_times_s), '.3f')}",
                    f(r.flight_gravity_m_s2, ".1f"), f(r.foot_skate_mm, ".0f"), f(r.peak_vertical_force_bw, ".1f")]

        ref = [f(sm.mean_speed, ".2f"), f(sm.froude, ".2f"), f(sm.step_frequency, ".2f"),
               f"{f(mean(sm.stance_times), '.3f')} / {f(mean(sm.flight_times), '.3f')}", "—", "—", "—"]
        rows = ["speed [m/s]", "Froude number", "steps [1/s]", "stance / flight [s]", "flight gravity [m/s²]",
                "foot skate [mm]", "peak force [× weight]"]
        out = "| | reference | physical | naive |\n|---|---|---|---|\n"
        for k, a, b, c in zip(rows, ref, col(phys), col(nv)):
            out += f"| {k} | {a} | {b} | {c} |\n"
        return out

    @staticmethod
    def _bands_html(track: Track) -> str:
        """The result's stance (left, right) and flight phases as a coloured strip over the scrubber."""
        ph = track.phases
        if len(ph) == 0:
            return ""
        edges = np.flatnonzero(np.diff(ph)) + 1
        starts = np.r_[0, edges]
        stops = np.r_[edges, len(ph)]
        colors = {0: "#e9ecef", 1: "rgb(30,120,230)", 2: "rgb(230,60,60)", 3: "rgb(120,80,160)"}
        cells = "".join(f'<div style="flex:{b - a};background:{colors[int(ph[a])]}"></div>'
                        for a, b in zip(starts, stops))
        key = ('<div style="font-size:0.75em;color:#666">stance: <span style="color:rgb(30,120,230)">left</span> / '
               '<span style="color:rgb(230,60,60)">right</span>, grey: flight</div>')
        return f'<div style="display:flex;height:10px;border-radius:3px;overflow:hidden">{cells}</div>{key}'


# ---- the server --------------------------------------------------------------------------------------
class Studio:
    """The viser server: one ``Tab`` per browser tab (each its own session), the handshake guard, the
    player thread. ``start()`` runs the player; ``stop()``."""

    def __init__(self, prep, *, host: str = "127.0.0.1", port: int = 8080, params: Params | None = None,
                 clip_name: str | None = None):
        import viser  # optional extra froude[studio]

        from . import guard

        self.session = Session(prep)
        self.clip_name = clip_name or (Path(prep.source).name if prep.source else "clip")
        params = (params or Params()).check(self.session.presets)
        self.first = with_report(prep, self.session.solve(params, report=False))  # raises on a bad start
        self.first.track.capsules  # noqa: B018 -- every tab starts from it
        self.tabs: dict[int, Tab] = {}
        self._tabs_lock = threading.Lock()
        self._stop = threading.Event()
        with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: we print our own address line
            self.server = viser.ViserServer(host=host, port=port, label="froude studio", verbose=False)
        self.refused = guard.install(self.server, self.server.get_port, host, on_refused=self._say_refused)
        self.server.scene.set_up_direction("+y")
        self.server.scene.configure_default_lights(enabled=True, cast_shadow=False)
        self.server.on_client_connect(self._on_connect)
        self.server.on_client_disconnect(self._on_disconnect)
        self._player = threading.Thread(target=self._play_loop, name="froude-studio-player", daemon=True)

    @staticmethod
    def _say_refused(why: str) -> None:
        print(f"froude studio: refused a connection: {why}", file=sys.stderr, flush=True)

    def _on_connect(self, client) -> None:
        if client.client_id in self.refused:
            return
        tab = Tab(self, client, client)
        with self._tabs_lock:
            self.tabs[client.client_id] = tab

    def _on_disconnect(self, client) -> None:
        with self._tabs_lock:
            tab = self.tabs.pop(client.client_id, None)
        if tab is not None:
            tab.close()

    def open_tab(self) -> Tab:
        """A tab without a browser, drawing into the server's shared scene (tests, scripts)."""
        with self._tabs_lock:
            key = -1 - sum(1 for k in self.tabs if k < 0)
        tab = Tab(self, self.server, None, root=f"/froude_headless{-key}")
        with self._tabs_lock:
            self.tabs[key] = tab
        return tab

    def wait_for_tabs(self, n: int, timeout: float = 30.0) -> list[Tab]:
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            with self._tabs_lock:
                tabs = list(self.tabs.values())
            if len(tabs) >= n:
                return tabs
            time.sleep(0.05)
        raise TimeoutError(f"{n} tab(s) never connected")

    # ---- lifecycle
    @property
    def url(self) -> str:
        return self.urls[0]

    @property
    def urls(self) -> list[str]:
        """Every address a browser can open (bound to all interfaces: this machine's network addresses)."""
        from .guard import reachable_addresses

        port = self.server.get_port()
        return [f"http://{f'[{a}]' if ':' in a else a}:{port}" for a in reachable_addresses(self.server.get_host())]

    def start(self) -> Studio:
        self._player.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        with self._tabs_lock:
            tabs = list(self.tabs.values())
            self.tabs.clear()
        for tab in tabs:
            tab.close()
        if self._player.is_alive():
            self._player.join(timeout=5.0)
        with contextlib.redirect_stdout(io.StringIO()):
            self.server.stop()

    def _play_loop(self) -> None:
        period = 1.0 / DISPLAY_HZ
        last = time.perf_counter()
        while not self._stop.wait(period):
            now = time.perf_counter()
            with self._tabs_lock:
                tabs = list(self.tabs.values())
            for tab in tabs:
                try:
                    tab.tick(now - last, now)
                except Exception:  # a drawing hiccup (e.g. a client leaving) must not stop playback
                    if not tab._stop.is_set():
                        traceback.print_exc(file=sys.stderr)
            last = now


def serve(prep, *, host: str = "127.0.0.1", port: int = 8080, params: Params | None = None,
          open_browser: bool = False, announce=print) -> int:
    """Run the studio until Ctrl-C (or SIGTERM); returns 0 after a clean shutdown."""
    from ..signals import interrupt_on_signals, restore_signals

    old = interrupt_on_signals()  # Ctrl-C and SIGTERM both stop cleanly (apps.signals)
    studio = None
    try:
        studio = Studio(prep, host=host, port=port, params=params).start()
        # the handlers are in place before the address is out: a Ctrl-C from then on is a clean stop
        announce(f"froude studio: {studio.url}  (Ctrl-C to stop)")
        for other in studio.urls[1:]:
            announce(f"froude studio: also {other}")
        if open_browser:
            import webbrowser

            webbrowser.open(studio.url)
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        if studio is not None:
            studio.stop()
        restore_signals(old)
    return 0
