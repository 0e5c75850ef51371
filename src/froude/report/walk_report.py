"""The physics report's walking figures (issue 17): double support, the vertical force's two peaks and
trough, the cadence against dynamic similarity and against the naive retarget; and their rows in the CLI's
result table. Measured on the motion like the rest of the report (``metrics``).
"""
from __future__ import annotations

import math

import numpy as np

from ..body.gait import detect_gait
from ..machine.walk_fit import PROFILE_SAMPLES, force_landmarks
from ..synthesis.walking import walking_events
from .metrics import _with_ground, vertical_force_bw

__all__ = ["walking_extras", "walking_report", "walking_rows"]


def _double_support_fraction(gait, n_frames: int) -> float:
    """Mean double support / mean step time over the complete steps (a touchdown, the other foot's
    liftoff, the next touchdown) at the gait's sub-frame events: the machine's t_double / t_step. The
    share of frames with both feet down when the motion has no complete step.

    As the walking fit takes them (``machine.walk_fit``), a step whose other foot has stood since the first
    frame (its touchdown outside the motion) is no complete step: CMU 07_01 starts from standing, and its
    first double support (0.139 s, against 0.073 and 0.081 s) put the clip's share at 17.6 % where its
    walking steps, which the machine models, have 14.5 %."""
    ev = walking_events(gait, gait.frame_time, n_frames)
    ds, steps = [], []
    for i, e in enumerate(ev):
        if e.kind != "td":
            continue
        lo = next((x for x in ev[i + 1:] if x.kind == "lo"), None)
        nxt = next((x for x in ev[i + 1:] if x.kind == "td"), None)
        if lo is None or nxt is None or lo.foot == e.foot or nxt.foot == e.foot or lo.frame > nxt.frame:
            continue
        if not any(x.kind == "td" and x.foot == lo.foot for x in ev[:i]):
            continue  # the other foot down since the motion began
        ds.append(lo.frame - e.frame)
        steps.append(nxt.frame - e.frame)
    return float(np.mean(ds) / np.mean(steps)) if steps else float(gait.double_support_fraction)


def walking_report(com: np.ndarray, gait, frame_time: float) -> dict:
    """The walking figures of a motion's report (issue 17): double-support fraction, the vertical force's
    two peaks and trough over a stance [BW] and their stance phases, from the COM (eq. 1, the project's
    one differentiation) averaged over the complete stances. com: (F, 3) [m]. NaN when not measurable."""
    F = com.shape[0]
    out = {"double_support_fraction": _double_support_fraction(gait, F)}
    full = [s for s in gait.full_stances]
    nan = {k: float("nan") for k in ("peak1_bw", "trough_bw", "peak2_bw", "tau_peak1", "tau_trough", "tau_peak2")}
    if not full or F < 9:
        out.update(nan)
        return out
    fz = vertical_force_bw(com, frame_time)
    frames = np.arange(F, dtype=float)
    tau = np.linspace(0.0, 1.0, PROFILE_SAMPLES)
    prof, durs = [], []
    for s in full:
        a = s.t_on if math.isfinite(s.t_on) else float(s.start)
        b = s.t_off if math.isfinite(s.t_off) else float(s.stop - 1)
        if a < 3 or b > F - 4:  # the filter's edges are least trustworthy
            continue
        prof.append(np.interp(a + tau * (b - a), frames, fz))
        durs.append((b - a) * frame_time)
    if not prof:
        out.update(nan)
        return out
    ds = out["double_support_fraction"]  # t_double / t_step; a stance lasts t_step + t_double
    lm = force_landmarks(tau, np.mean(prof, axis=0), ds / (1.0 + ds))
    out.update({"peak1_bw": lm["peak1"], "trough_bw": lm["trough"], "peak2_bw": lm["peak2"],
                "tau_peak1": lm["tau_peak1"], "tau_trough": lm["tau_trough"], "tau_peak2": lm["tau_peak2"]})
    return out



def walking_extras(prep, res, report) -> dict:
    """The walking part of an output's report (``Report.extras``): the walking figures of the output and
    of the clip, and the cadence the naive retarget would have next to the physical one.

    "cadence": clip [Hz] (measured over its complete steps), output [Hz] (measured), expected (dynamic
    similarity and the walking speed law, ``_expected_and_naive_cadence``), naive (engines keep the clip's
    timing, played faster with the speed) and its error against the expected one.
    """
    body = res.retarget.body
    com, markers = body.com_and_markers(res.motion)
    gait = _with_ground(detect_gait(res.motion, body, markers), 0.0)
    out = walking_report(com, gait, res.motion.frame_time)
    clip = walking_report(prep.com, prep.gait, prep.motion.frame_time)
    L, s = float(res.retarget.L), float(res.speed_factor)
    # the clip's cadence over its complete steps (what the machine models; the gait summary's counts the
    # take's first and last touchdowns too, 2 % slower on CMU 07_01, which starts and stops)
    f_clip = 1.0 / float(prep.machine.reference["step_time_s"])
    f_out = float(report.step_frequency_hz)
    expected, naive = _expected_and_naive_cadence(prep, res, f_clip, L, s)
    return {"walking": {**out, "clip": clip},
            "cadence": {"clip_step_frequency_hz": f_clip, "step_frequency_hz": f_out,
                        "expected_step_frequency_hz": expected, "naive_step_frequency_hz": naive,
                        "naive_error": naive / expected - 1.0, "clip_froude_U": float(prep.summary.froude)}}


def _expected_and_naive_cadence(prep, res, f_clip: float, L: float, s: float) -> tuple[float, float]:
    """(expected, naive) step frequency [Hz] of an output walked at speed factor s by a character L × the clip.

    A scaled output: expected = clip × L^-1/2 × the speed law's factor (above the clip's speed the step time
    of the cycle actually walked, ``machine.walk_speed``'s faster-cadence law where the first finds no cycle;
    the same solve as the output's, remembered on prep; below it §5.2's horizontal stretch keeps the clip's
    timing); naive = clip × s. An accelerated output (a walking plan in ``res.extras``) walks a cycle
    per step: expected = steps / their total time (each step's cycle, L included), naive = clip × the
    time-weighted mean speed factor (an engine plays the clip faster as the speed rises).
    """
    plan = res.extras.get("plan") or {}
    if "step_time_s" in plan:
        t = np.asarray(plan["step_time_s"], float)
        factors = np.asarray(plan["apex_speed_m_s"], float) / float(plan["start_speed_m_s"])
        return 1.0 / float(np.mean(t)), f_clip * float(np.sum(factors * t) / np.sum(t))
    law = prep.machine.t_step / prep.machine_at_speed(s).t_step if s > 1.0 else 1.0
    return f_clip * L ** -0.5 * law, f_clip * s


def walking_rows(report) -> list[tuple[str, str]]:
    """Rows of the CLI's result table for a walking output (empty for other reports)."""
    w, c = report.extras.get("walking"), report.extras.get("cadence")
    if not w or not c:
        return []
    return [
        ("double support", f"{100 * w['double_support_fraction']:.1f} % of the cycle "
                           f"(clip {100 * w['clip']['double_support_fraction']:.1f} %)"),
        ("vertical force", f"peaks {w['peak1_bw']:.2f} / {w['peak2_bw']:.2f} BW, trough {w['trough_bw']:.2f} BW "
                           f"(clip {w['clip']['peak1_bw']:.2f} / {w['clip']['peak2_bw']:.2f}, "
                           f"{w['clip']['trough_bw']:.2f})"),
        ("cadence", f"{c['step_frequency_hz']:.3f} Hz (expected {c['expected_step_frequency_hz']:.3f}); the naive "
                    f"retarget steps at {c['naive_step_frequency_hz']:.3f} Hz ({100 * c['naive_error']:+.0f} %)"),
    ]
