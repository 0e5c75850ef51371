"""The live studio in the browser (viser): the reference and the result running side by side, the simple
machine drawn over them, controls that recompute through the pipeline, numbers, plots and downloads.

Threads: viser calls the GUI handlers on its pool; they only post the latest parameters to the worker
thread, which computes the IK result and pushes it, then its physics report (a newer request makes it skip
the stale one). When the result would be slow (long outputs) it first pushes a cheap preview (machine +
time-warped reference, no IK). The player thread draws one frame at the display rate by indexing arrays
precomputed once per result (until a new result's bones are done, one frame's FK); it holds its frames
while a quick change is computed, so that the change reaches the page sooner.
"""
from __future__ import annotations

import contextlib
import io
import sys
import threading
import time
import traceback
from dataclasses import dataclass

import numpy as np

from ..constants import UP_AXIS
from ..errors import FroudeError
from .session import LIMITS, MODES, Params, Session, Solved, with_character, with_report
from .tracks import Track

#: Frames drawn per second (the motion itself is indexed at its own rate, 120 Hz for the sample).
DISPLAY_HZ = 30.0
#: Sideways distance [m] between the reference and the result when side by side.
SIDE_BY_SIDE_M = 1.2
#: A change whose IK result is expected to take longer than this [s] (the last result of its mode, per
#: stride) first shows a preview — the machine's motion on the new body, no IK — and waits DEBOUNCE_S of
#: quiet before solving (a slider drag sends many changes). Quicker ones go straight to the result: during
#: a drag the worker then solves the newest value back to back (the latest request wins).
SLOW_RESULT_S = 0.1
DEBOUNCE_S = 0.08
#: Pause [s] after pushing a result, so the websocket thread sends it before the report is computed.
YIELD_S = 0.003

COLOR_RESULT = (20, 80, 200)
COLOR_PREVIEW = (120, 130, 145)
COLOR_REFERENCE = (225, 120, 20)
COLOR_COM = (220, 30, 60)
COLOR_LEG = (20, 150, 80)
COLOR_FEET = np.array([[30, 120, 230], [230, 60, 60]], np.uint8)  # left, right contacts


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


class _Runner:
    """The scene nodes of one runner (body lines, COM ball, spring legs, contacts, trail)."""

    def __init__(self, scene, root: str, track: Track, color):
        self.root = scene.add_frame(root, show_axes=False)
        self.body = scene.add_line_segments(f"{root}/body", track.segments_at(0), _colors(track, color),
                                            thickness=0.04)
        self.com = scene.add_icosphere(f"{root}/com", radius=0.06, color=COLOR_COM, position=track.com[0],
                                       subdivisions=2, cast_shadow=False, receive_shadow=False)
        self.legs = scene.add_line_segments(f"{root}/legs", track.legs[0], COLOR_LEG, thickness=0.02)
        self.contacts = scene.add_point_cloud(f"{root}/contacts", *_contact_points(track), point_size=0.05,
                                              point_shape="circle")
        self.trail = scene.add_line_segments(f"{root}/trail", track.trail, COLOR_COM, thickness=0.008)
        self.track = track
        self._colored = (color, track.n_bones)

    def set_track(self, track: Track, color) -> None:
        """New precomputed arrays (one message per static node; per-frame nodes follow in draw)."""
        self.track = track
        if (color, track.n_bones) != self._colored:  # each message costs the push a little: only changes
            self.body.colors = _colors(track, color)
            self._colored = (color, track.n_bones)
        pts, cols = _contact_points(track)
        self.contacts.points, self.contacts.colors = pts, cols
        self.trail.points = track.trail

    def draw(self, t: float, offset: np.ndarray, machine: bool) -> None:
        i, shift = self.track.frame_at(t)
        self.root.position = offset + shift
        self.body.points = self.track.segments_at(i)
        self.com.position = self.track.com[i]
        self.legs.points = self.track.legs[i]
        for node in (self.com, self.legs, self.contacts, self.trail):
            node.visible = machine

    def set_visible(self, visible: bool) -> None:
        self.root.visible = visible


def _colors(track: Track, color) -> np.ndarray:
    return np.broadcast_to(np.asarray(color, np.uint8), (track.n_bones, 2, 3)).copy()


def _contact_points(track: Track) -> tuple[np.ndarray, np.ndarray]:
    pts = track.contacts.astype(np.float32)
    if len(pts) == 0:  # viser wants at least one point: a hidden one under the start
        return track.com[:1].astype(np.float32) * np.array([1, 0, 1], np.float32), COLOR_FEET[:1]
    return pts, COLOR_FEET[track.contact_foot]


class Studio:
    """The viser server with the studio's scene and controls. ``start()`` runs the threads; ``stop()``."""

    def __init__(self, prep, *, host: str = "127.0.0.1", port: int = 8080, params: Params | None = None):
        import viser  # optional extra froude[studio]

        self.session = Session(prep)
        self.params = params or Params()
        self._stop = threading.Event()
        self._busy = threading.Event()  # set while a change is computed: the player then skips its frames
        self._wake = threading.Condition()
        self._pending: tuple[Params, float] | None = None
        self._draw_lock = threading.RLock()
        self._t = 0.0
        self._playing = True
        self._rate = 1.0
        self.timing = Timing()
        self.message = ""
        first = self.session.solve(self.params, report=False)  # raises on a bad start
        self._result_s = {first.params.mode: (first.seconds, first.params.strides)}  # last compute, strides
        self.good = with_report(prep, first)  # the last good result
        self.shown = self.good
        frame = prep.cycle.frame  # rows: forward, up, lateral (heading frame)
        self._lateral = np.asarray(frame[2], float)
        self._forward = np.asarray(frame[0], float)
        self._defaults = self.session.character_defaults(self.params.character)

        with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: we print our own address line
            self.server = viser.ViserServer(host=host, port=port, label="froude studio", verbose=False)
        from . import guard

        self.refused = guard.install(self.server, self.server.get_port, host, on_refused=self._say_refused)
        self.server.scene.set_up_direction("+y")
        # no shadows: they cost more than they show for stick figures (software WebGL renders 2-5x faster)
        self.server.scene.configure_default_lights(enabled=True, cast_shadow=False)
        self._build_scene()
        self._build_gui()
        self._publish(self.good)
        self._threads = [threading.Thread(target=self._work_loop, name="froude-studio-worker", daemon=True),
                         threading.Thread(target=self._play_loop, name="froude-studio-player", daemon=True)]

    @staticmethod
    def _say_refused(why: str) -> None:
        print(f"froude studio: refused a connection: {why}", file=sys.stderr, flush=True)

    # ---- lifecycle -----------------------------------------------------------------------------------
    @property
    def url(self) -> str:
        return self.urls[0]

    @property
    def urls(self) -> list[str]:
        """Every address a browser can open (bound to all interfaces: this machine's network addresses)."""
        from .guard import reachable_addresses

        port = self.server.get_port()
        return [f"http://{f'[{a}]' if ':' in a else a}:{port}" for a in reachable_addresses(self.server.get_host())]

    def start(self) -> "Studio":
        for th in self._threads:
            th.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        with self._wake:
            self._wake.notify_all()
        for th in self._threads:
            if th.is_alive():
                th.join(timeout=5.0)
        with contextlib.redirect_stdout(io.StringIO()):
            self.server.stop()

    # ---- scene ----------------------------------------------------------------------------------------
    def _build_scene(self) -> None:
        sc = self.server.scene
        up = np.eye(3)[UP_AXIS]
        start = self.good.track.com[0].copy()
        start[UP_AXIS] = 0.0
        self._world = sc.add_frame("/world", show_axes=False, position=-start)
        # the ground moves with the world, so following the runner shows it running over the floor
        self._grid = sc.add_grid("/world/grid", width=400.0, height=400.0, plane="xz", cell_size=0.5,
                                 section_size=2.0, position=start, shadow_opacity=0.0)
        self.result = _Runner(sc, "/world/result", self.good.track, COLOR_RESULT)
        self.reference = _Runner(sc, "/world/reference", self.session.reference, COLOR_REFERENCE)
        # a side view from the result's side, a little ahead and above; the world moves, the camera stays
        self._cam_position = 3.6 * self._lateral + 1.5 * up + 1.2 * self._forward
        self._cam_look_at = 0.9 * up
        cam = self.server.initial_camera
        cam.position, cam.look_at, cam.up = self._cam_position, self._cam_look_at, up
        cam.fov = np.radians(55.0)

        @self.server.on_client_connect
        def _(client) -> None:
            client.camera.up_direction = up
            client.camera.position = self._cam_position
            client.camera.look_at = self._cam_look_at

    def _offset_reference(self) -> np.ndarray:
        return np.zeros(3) if self.gui_overlay.value else -SIDE_BY_SIDE_M * self._lateral  # beyond the result

    def _draw(self) -> None:
        """One frame: index the precomputed tracks at the current time and send the node updates."""
        with self._draw_lock, self.server.atomic():
            t = self._t
            machine = self.gui_machine.value
            res = self.result.track
            i, _ = res.frame_at(t)
            if self.gui_follow.value:
                focus = res.com[i].copy()
            else:
                focus = res.com[0].copy()
            focus[UP_AXIS] = 0.0
            show_ref = self.gui_show_ref.value
            centre = 0.5 * self._offset_reference() if show_ref else np.zeros(3)
            self._world.position = -(focus + centre)
            self.result.draw(t, np.zeros(3), machine)
            self.reference.set_visible(show_ref)
            if show_ref:
                self.reference.draw(t, self._offset_reference(), machine)

    # ---- GUI ------------------------------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.configure_theme(control_width="large", show_logo=False)
        p = self.params
        h, m, legs = self._defaults
        self.gui_state = gui.add_markdown(self._state_md(), order=0)
        with gui.add_folder("Playback", order=1):
            self.gui_play = gui.add_button("Pause", icon=None)
            self.gui_time = gui.add_slider("Time [s]", min=0.0, max=round(self.good.track.duration, 2), step=0.01,
                                           initial_value=0.0)
            self.gui_rate = gui.add_slider("Playback speed", min=0.1, max=2.0, step=0.05, initial_value=1.0)
            self.gui_overlay = gui.add_checkbox("Overlay (else side by side)", initial_value=False)
            self.gui_show_ref = gui.add_checkbox("Show reference", initial_value=True)
            self.gui_machine = gui.add_checkbox("Show simple machine", initial_value=True)
            self.gui_follow = gui.add_checkbox("Camera follows runner", initial_value=True)
        with gui.add_folder("Change", order=2):
            self.gui_mode = gui.add_dropdown("Mode", options=MODES, initial_value=p.mode)
            self.gui_char = gui.add_dropdown("Character", options=tuple(self.session.presets),
                                             initial_value=p.character)
            L = LIMITS
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
        with gui.add_folder("Numbers", order=3):
            self.gui_status = gui.add_markdown("")
            self.gui_numbers = gui.add_markdown("")
            t, fm, fb = self._force_series(self.good.track)
            self.gui_plot = gui.add_uplot(
                data=(t, fm, fb),
                series=({"label": "t [s]"}, {"label": "machine", "stroke": "#dc1e3c", "width": 2},
                        {"label": "body", "stroke": "#286edc", "width": 1}),
                title="vertical leg force [body weights]", aspect=1.6,
                scales={"x": {"time": False}, "y": {"auto": True}},
            )
        with gui.add_folder("Export", order=4):
            self.gui_dl_bvh = gui.add_button("Download BVH")
            self.gui_dl_report = gui.add_button("Download report")

        self.gui_play.on_click(self._on_play)
        self.gui_time.on_update(self._on_time)
        self.gui_rate.on_update(lambda e: setattr(self, "_rate", float(self.gui_rate.value)))
        for g in (self.gui_overlay, self.gui_show_ref, self.gui_machine, self.gui_follow):
            g.on_update(lambda e: self._draw())
        self.gui_char.on_update(self._on_character)
        for g in (self.gui_mode, self.gui_height, self.gui_mass, self.gui_legs, self.gui_speed, self.gui_strides,
                  self.gui_to, self.gui_steps):
            g.on_update(self._on_change)
        self.gui_dl_bvh.on_click(self._on_download_bvh)
        self.gui_dl_report.on_click(self._on_download_report)
        self._sync_mode_controls()

    @staticmethod
    def _force_series(track: Track):
        """(t, machine force, body force) on the result's frames [s], [body weights] (NaN gaps allowed)."""
        F = track.n_frames
        t = np.arange(F) * track.frame_time
        fm = np.interp(t, track.force_t, track.force_bw) if len(track.force_t) else np.full(F, np.nan)
        return t, fm, np.asarray(track.body_force_bw, float)

    def _sync_mode_controls(self) -> None:
        scale = self.gui_mode.value == "scale"
        for g in (self.gui_speed, self.gui_strides):
            g.disabled = not scale
        for g in (self.gui_to, self.gui_steps):
            g.disabled = scale

    def params_from_gui(self) -> Params:
        """The parameters the controls show; numbers equal to the character's own are not overrides."""
        h0, m0, l0 = self._defaults

        def override(v, v0, tol):
            v = float(v)
            return None if abs(v - v0) <= tol else v

        return Params(  # checked against the controls' own options and limits (values can be crafted)
            mode=str(self.gui_mode.value), character=str(self.gui_char.value),
            height=override(self.gui_height.value, h0, 6e-3), mass=override(self.gui_mass.value, m0, 0.06),
            leg_scale=override(self.gui_legs.value, l0, 6e-3), speed=float(self.gui_speed.value),
            strides=self.gui_strides.value, to_factor=float(self.gui_to.value), steps=self.gui_steps.value,
        ).check(self.session.presets)

    # handlers (viser's pool); programmatic value changes come with event.client None and are ignored
    def _on_play(self, event) -> None:
        self._playing = not self._playing
        self.gui_play.label = "Pause" if self._playing else "Play"

    def _on_time(self, event) -> None:
        if event.client is None:
            return
        self._t = float(self.gui_time.value)
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
        """A control value outside its options or limits: say so, put the controls back to the last good
        result's values, and compute nothing."""
        self._show_error(err)
        self._set_controls(self.good.params)

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

    def _on_download_bvh(self, event) -> None:
        from ..io.bvh import bvh_text

        res = self.good.result
        event.client.send_file_download(self._file_stem() + ".bvh", bvh_text(res.motion).encode(),
                                        save_immediately=True)

    def _on_download_report(self, event) -> None:
        res = self.good.result
        event.client.send_file_download(self._file_stem() + ".report.json", res.report.to_json().encode(),
                                        save_immediately=True)

    def _file_stem(self) -> str:
        p = self.good.params
        tag = f"x{p.speed:g}" if p.mode == "scale" else f"to{p.to_factor:g}x{p.steps}"
        return f"froude_{p.character}_{p.mode}_{tag}"

    # ---- recompute ------------------------------------------------------------------------------------
    def request(self, params: Params) -> None:
        """Ask for a recompute (the latest request wins). What every control calls."""
        with self._wake:
            self._pending = (params, time.perf_counter())
            self._wake.notify_all()

    def _take(self, timeout: float | None = None) -> tuple[Params, float] | None:
        with self._wake:
            if self._pending is None and not self._stop.is_set():
                self._wake.wait(timeout)
            got, self._pending = self._pending, None
            return got

    def _newer_pending(self) -> bool:
        with self._wake:
            return self._pending is not None

    def apply(self, params: Params, *, debounce: float = 0.0) -> Timing:
        """Preview → push → (debounce) → result → push, for one change; returns its timing. Never raises
        a FroudeError: a bad change shows its message and the last good result stays."""
        timing = Timing(started_at=time.perf_counter())
        slow = self.expected_seconds(params) > SLOW_RESULT_S
        if not slow:
            self._busy.set()  # a quick change: the player holds its frames until it is on screen
        try:
            if slow:
                t0 = time.perf_counter()
                pre = self.session.preview(params)
                if pre is not None:
                    timing.preview_compute = time.perf_counter() - t0
                    t1 = time.perf_counter()
                    self._publish(pre, status=f"preview ({pre.seconds * 1e3:.0f} ms); solving IK ...")
                    timing.preview_push = time.perf_counter() - t1
                if debounce > 0 and self._stop.wait(debounce):
                    return timing
                if self._newer_pending():
                    return timing  # superseded: go straight to the newer change
            t0 = time.perf_counter()
            res = self.session.solve(params, report=False)  # the corrected motion first ...
            timing.result_compute = time.perf_counter() - t0
            self._result_s[params.mode] = (timing.result_compute, params.strides)
            if self._newer_pending():
                return timing
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
            res.track.segments  # noqa: B018 -- all frames' bones, so the player only indexes from here on
            res = with_report(self.session.prep, res)  # ... then its numbers
            timing.report_compute = time.perf_counter() - t2
            if self._newer_pending():
                return timing
            self.good = res
            self._publish(res)
        except FroudeError as e:
            self._show_error(e)
        except Exception as e:  # never let a bug in one change kill the studio; say it and carry on
            traceback.print_exc(file=sys.stderr)
            self._show_error(f"internal error: {type(e).__name__}: {e}")
        finally:
            self._busy.clear()
        self.timing = timing
        return timing

    def expected_seconds(self, params: Params) -> float:
        """What the IK result of ``params`` should take to compute [s]: the last result of its mode (per
        stride when scaling), or forever (a preview first) when there was none yet."""
        last = self._result_s.get(params.mode)
        if last is None:
            return float("inf")
        seconds, strides = last
        return seconds * (params.strides / max(strides, 1) if params.mode == "scale" else 1.0)

    def _work_loop(self) -> None:
        while not self._stop.is_set():
            job = self._take(timeout=0.5)
            if job is not None:
                self.apply(job[0], debounce=DEBOUNCE_S)

    def _publish(self, solved: Solved, status: str | None = None) -> None:
        """Swap in a new track (preview or result), refresh numbers and plot, and draw the frame now."""
        with self._draw_lock:
            self.shown = solved
            self.message = "" if status is None else status
            color = COLOR_PREVIEW if solved.preview else COLOR_RESULT
            self.result.set_track(solved.track, color)
            dur = solved.track.duration
            if self._t >= dur:
                self._t = self._t % dur
            self.gui_time.max = round(dur, 2)
            if not solved.preview and solved.result.report is not None:  # numbers and plot follow the runner
                self.gui_plot.data = self._force_series(solved.track)
                self.gui_numbers.content = self._numbers_md(solved)
            self.gui_status.content = self._status_md()
            self.gui_state.content = self._state_md()
            self._draw()
        self.server.flush()

    def _show_error(self, err) -> None:
        """Say what went wrong and put the last good result back on screen."""
        msg = str(err).splitlines()[0] if str(err) else type(err).__name__
        if self.shown is not self.good:
            self._publish(self.good)
        self.message = f"error: {msg}"
        self.gui_status.content = self._status_md()
        self.gui_state.content = self._state_md()
        for client in self.server.get_clients().values():
            client.add_notification("froude: change not applied", msg, color="red", auto_close_seconds=6.0)
        self.server.flush()

    # ---- text ----------------------------------------------------------------------------------------
    def _state_md(self) -> str:
        """One line the tests (and users) can read: what is on screen right now."""
        s = getattr(self, "shown", None) or self.good
        p = s.params
        complete = s.result is not None and s.result.report is not None
        speed = f"{s.result.report.mean_speed_m_s:.3f}" if complete else "n/a"
        status = "error" if self.message.startswith("error") else (
            "preview" if s.preview else ("ok" if complete else "report"))
        return (f"`state: character={p.character} mode={p.mode} speed_factor={p.speed:g} to_factor={p.to_factor:g} "
                f"steps={p.steps} strides={p.strides} n_frames={s.n_frames} speed_m_s={speed} hash={s.hash} "
                f"status={status}`")

    def _status_md(self) -> str:
        if self.message.startswith("error"):
            return f"**:warning: {self.message}**  \n(showing the last good result: {self.good.params.label()})"
        if self.message:
            return f"*{self.message}*"
        res = self.good.result
        notes = list(res.notes) + [f"bar: {b}" for b in res.report.check_bars()]
        head = f"**{self.good.params.label()}** — solved in {self.good.seconds * 1e3:.0f} ms"
        return head + ("".join(f"  \n- {n}" for n in notes) if notes else "  \nall physics bars pass")

    @staticmethod
    def _numbers_md(solved: Solved) -> str:
        res = solved.result
        rows = res.summary_rows()
        rows.insert(3, ("frames", f"{res.motion.n_frames} at {res.motion.fps:.0f} Hz"))
        return "| | |\n|---|---|\n" + "\n".join(f"| {k} | {v} |" for k, v in rows)

    # ---- playback -------------------------------------------------------------------------------------
    def _play_loop(self) -> None:
        period = 1.0 / DISPLAY_HZ
        last = time.perf_counter()
        last_slider = 0.0
        while not self._stop.wait(period):
            now = time.perf_counter()
            try:
                if self._playing:
                    dur = self.result.track.duration
                    self._t = (self._t + (now - last) * self._rate) % dur
                    # While a quick change is computed the clock runs on but frames are not sent: drawing
                    # and sending them takes the GIL and a core from the solve (measured: +10-15 ms on a
                    # 40 ms change); the new result is drawn at the current time the moment it is ready.
                    if not self._busy.is_set():
                        self._draw()
                        if now - last_slider > 0.25:  # the scrubber follows, a few times a second
                            self.gui_time.value = round(min(self._t, self.gui_time.max), 2)
                            last_slider = now
            except Exception:  # a drawing hiccup (e.g. a client leaving) must not stop playback
                traceback.print_exc(file=sys.stderr)
            last = now


def serve(prep, *, host: str = "127.0.0.1", port: int = 8080, params: Params | None = None,
          open_browser: bool = False, announce=print) -> int:
    """Run the studio until Ctrl-C (or SIGTERM); returns 0 after a clean shutdown."""
    import signal

    def _interrupt(signum, frame):
        raise KeyboardInterrupt

    # Ctrl-C and SIGTERM both stop cleanly, even when started from a shell that ignores SIGINT in
    # background jobs (signal handlers can only be set from the main thread)
    old = {}
    if threading.current_thread() is threading.main_thread():
        old = {sig: signal.signal(sig, _interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
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
        for sig, handler in old.items():
            signal.signal(sig, handler)
    return 0

