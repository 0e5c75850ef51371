"""The studio's page layout: the control panel (folders, sliders, dropdowns, buttons, plots), the legend,
the page script (title, keys, drop), and the text it shows (state, status, facts, comparison table)."""
from __future__ import annotations

import html
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from ...io.jsonable import dumps
from .export import BVH_RATES, BVH_ROOT, BVH_UNITS
from .playback import (
    CAMERAS,
    COLOR_COM,
    COLOR_FEET,
    COLOR_LEG,
    COLOR_NAIVE,
    COLOR_PREVIEW,
    COLOR_REFERENCE,
    COLOR_RESULT,
)
from .session import LIMITS, MODES
from .tracks import Track

#: Largest clip the page accepts [bytes] (a 10-minute 120 Hz BVH of 30 joints is about 20 MB).
MAX_CLIP_BYTES = 32 * 1024 * 1024

if TYPE_CHECKING:  # a part of Tab: its methods use the attributes Tab.__init__ sets
    _TabPart = Any
else:
    _TabPart = object


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
    return dumps(s).replace("<", "\\u003c")


class _Layout(_TabPart):
    """The layout part of :class:`~froude.apps.studio.app.Tab` (a mixin: the tab's state lives in Tab)."""

    # ---- GUI
    # The page's controls, one statement per widget, in page order; their handlers: Tab._wire_gui.
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

        self._wire_gui()  # the session wiring: the handlers (Tab, studio.app)
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
        # the speed factors this character reaches with every bar met, once worked out (the slider's bounds)
        rng = self.session.speed_ranges.get(p.character)
        reach = "pending" if rng is None else ("none" if rng.empty else f"{rng.lo:.2f}-{rng.hi:.2f}")
        return (f"`state: clip={self.clip_name.replace(' ', '_')} character={p.character} mode={p.mode} "
                f"speed_factor={p.speed:g} to_factor={p.to_factor:g} steps={p.steps} strides={p.strides} "
                f"n_frames={s.n_frames} frame={frame} h_ref_m={h_ref:.4f} h_res_m={h_res:.4f} "
                f"speed_m_s={speed} naive_frames={naive} speed_reach={reach} hash={s.hash} status={status}`")

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
