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

The tab's parts: the control panel and its text in ``studio.layout``, the scene and playback in
``studio.playback``, the downloads in ``studio.export`` (mixins of :class:`Tab`); here the session wiring
(controls → parameters → the worker → results on the page) and the server.
"""
from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ...errors import FroudeError
from ...flow import pipeline
from ...flow.speed_range import SearchStopped, reachable_speed_range
from ..signals import interrupt_on_signals, restore_signals
from . import guard
from .export import _Export
from .guard import reachable_addresses
from .layout import MAX_CLIP_BYTES, _Layout, _page_script
from .playback import COLOR_NAIVE, COLOR_PREVIEW, COLOR_REFERENCE, COLOR_RESULT, DISPLAY_HZ, _Playback, _Runner
from .session import LIMITS, Params, Session, Solved, with_character, with_report
from .tracks import motion_hash, naive_track

#: A change whose IK result is expected to take longer than this [s] (the last result of its mode, per
#: stride) first shows a preview — the machine's motion on the new body, no IK — and waits DEBOUNCE_S of
#: quiet before solving (a slider drag sends many changes). Quicker ones go straight to the result.
SLOW_RESULT_S = 0.1
DEBOUNCE_S = 0.08
#: Pause [s] after pushing a result, so the websocket thread sends it before the report is computed.
YIELD_S = 0.003


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


# ---- one browser tab ---------------------------------------------------------------------------------
class Tab(_Layout, _Playback, _Export):
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

    def _wire_gui(self) -> None:
        """Each control's handler (called by ``_build_gui`` once the controls exist)."""
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
        self.gui_state.content = self._state_md()  # its speed_reach= changes with the range
        self._flush()

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


# ---- the server --------------------------------------------------------------------------------------
class Studio:
    """The viser server: one ``Tab`` per browser tab (each its own session), the handshake guard, the
    player thread. ``start()`` runs the player; ``stop()``."""

    def __init__(self, prep, *, host: str = "127.0.0.1", port: int = 8080, params: Params | None = None,
                 clip_name: str | None = None):
        import viser  # optional extra froude[studio]

        self.session = Session(prep)
        self.clip_name = clip_name or (Path(prep.source).name if prep.source else "clip")
        if params is None:  # a turning take's output makes its whole turn (pipeline.default_strides)
            params = Params(strides=min(pipeline.default_strides(prep), int(LIMITS["strides"].hi)))
        params = params.check(self.session.presets)
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
