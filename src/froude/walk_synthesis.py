"""The walking machine's path in the world and the walking time warp (issue 17).

The walking counterpart of ``pipeline.machine_path``: the (scaled) walking machine's periodic walk
(``WalkingMachine.path``) placed in the reference's heading frame, with the reference stride phase ψ of
every output time. The time warp is piecewise linear with knots at the walking events in their order
(A lands, B lifts, B lands, A lifts: ``synthesis.EVENT_ORDERS["walking"]``), so the reference's double
supports are played over the machine's double supports and its single supports over the machine's;
both feet are on the ground, and held by the IK, in every double support.

The foot anchors are the reference's contact points (``Stance.contact_point``, the foot's mean loaded
position): each contact is placed as far ahead of (or behind) the machine's COM at mid-stance as the
reference's is of its COM (× L), so the time-warped reference pose reaches its feet.
"""
from __future__ import annotations

import math

import numpy as np

from .constants import UP_AXIS
from .synthesis import FootEvent, sample_cycle

__all__ = ["prepare_walk", "walking_events", "contact_from_com", "walk_machine_path", "walking_report"]


def walking_events(gait, frame_time: float, n_frames: int) -> list[FootEvent]:
    """Touchdowns and liftoffs of a walk at the gait's sub-frame times (the walking fit's events), in time
    order; edges of stances cut by the clip omitted. frame_time [s] is unused but kept for symmetry."""
    ev = []
    for s in gait.stances:
        if s.start > 0:
            ev.append(FootEvent(float(s.t_on) if math.isfinite(s.t_on) else float(s.start), s.foot, "td"))
        if s.stop < n_frames:
            ev.append(FootEvent(float(s.t_off) if math.isfinite(s.t_off) else float(s.stop), s.foot, "lo"))
    return sorted(ev, key=lambda e: e.frame)


def contact_from_com(gait, com: np.ndarray, heading: np.ndarray, frame_time: float) -> np.ndarray:
    """(2,) mean forward distance [m] of each foot's contact point (``Stance.contact_point``) ahead of the
    COM at mid-stance, over the clip's complete stances (left, right; a foot never seen takes the other's).
    com: (F, 3) [m]; heading: (3,) forward unit vector."""
    F = com.shape[0]
    x = com @ heading
    d = [[], []]
    for st in gait.full_stances:
        a = st.t_on if math.isfinite(st.t_on) else float(st.start)
        b = st.t_off if math.isfinite(st.t_off) else float(st.stop - 1)
        d[st.foot].append(float(st.contact_point @ heading) - float(np.interp(0.5 * (a + b), np.arange(F), x)))
    out = np.array([np.mean(v) if v else np.nan for v in d])
    return np.where(np.isnan(out), out[::-1], out)


def prepare_walk(motion, body, com, markers, gait, summary, source: str, mass: float, notes):
    """``pipeline.prepare`` for a walk: the walking machine's fit and the walking stride cycle."""
    from pathlib import Path

    from .machine.walk_fit import fit_walking_detailed
    from .pipeline import Prepared, modelled_part
    from .synthesis import extract_cycle

    fit = fit_walking_detailed(motion, body, mass=mass, source=Path(source).name)
    events = walking_events(gait, motion.frame_time, motion.n_frames)
    cycle = extract_cycle(motion, body, gait, com, markers, events=events, order="walking")
    modelled, note = modelled_part(motion, summary, com, gait)
    return Prepared(motion, body, com, markers, gait, summary, fit.machine, cycle, source, fit,
                    modelled=modelled, notes=tuple(notes) + ((note,) if note else ()))


def _knots(n_steps: int, t_step: float, t_double: float, pe: np.ndarray, A_first: bool = True):
    """Time warp knots (times [s], phases ψ) at every touchdown and the other foot's liftoff, one step
    before and one after the output as well. Step i (foot A for even i) lands at i·t_step."""
    times, psis = [], []
    for i in range(-2, n_steps + 2):
        k = i // 2
        if i % 2 == 0:   # A lands, then B lifts
            td, lo = k + 0.0, k + pe[3]
        else:            # B lands, then A lifts
            td, lo = k + pe[2], k + pe[1]
        times += [i * t_step, i * t_step + t_double]
        psis += [td, lo]
    return np.array(times), np.array(psis)


def walk_machine_path(prep, retarget, *, n_steps: int, fps: float, machine=None, speed: float = 1.0):
    """The scaled walking machine for n_steps steps in the world (a ``pipeline.MachinePath``).

    prep: a prepared walk (``pipeline.prepare``); retarget: the character (L, M); fps: output frame rate
    [Hz]; machine: the (unscaled) WalkingMachine to walk (default: the fitted one); speed must be 1 (a
    walk changes speed by re-solving its cycle, ``machine.walk_speed``, never by stretching).
    """
    from .pipeline import MachinePath

    if speed != 1.0:
        raise ValueError("a walking path is never stretched: re-solve the cycle at the new speed instead")
    m = (prep.machine if machine is None else machine).scaled(retarget.L, retarget.M)
    cyc = prep.cycle
    T = m.time_unit
    t_step, t_double, t_stance = m.t_step * T, m.t_double * T, m.t_stance * T
    n_frames = int(math.floor(n_steps * t_step * fps + 1e-9)) + 1
    t = np.arange(n_frames) / fps
    mp = m.path(t)
    A = cyc.first_foot
    feet = np.where(np.arange(n_steps) % 2 == 0, A, 1 - A)
    t_td = np.arange(n_steps) * t_step
    t_lo = t_td + t_stance
    kt, kp = _knots(n_steps, t_step, t_double, cyc.phase_events)
    psi = np.interp(t, kt, kp)
    pe = cyc.phase_events
    # each step's foot: its touchdown and liftoff phases, then its marker contact (a little wider)
    psi_td = np.interp(t_td, kt, kp)
    td_ph = np.where(feet == A, 0.0, pe[2])
    lo_ph = np.where(feet == A, pe[1], pe[3])
    stance_ph = np.mod(lo_ph - td_ph, 1.0)
    ext_before = np.array([(0.0 if f == A else pe[2]) - cyc.contact_phase[f, 0] for f in feet])
    ext_after = np.array([cyc.contact_phase[f, 1] - cyc.contact_phase[f, 0] for f in feet]) - ext_before - stance_ph
    contact_on = np.interp(psi_td - ext_before, kp, kt)
    contact_off = np.interp(psi_td + stance_ph + ext_after, kp, kt)

    fwd, up, lat = cyc.frame
    L = retarget.L
    l0 = m.l0
    phi = np.mod(psi, 1.0)
    _, data = sample_cycle(cyc, phi, rotations=False)
    origin = prep.com[0].copy()
    origin[UP_AXIS] = 0.0
    p = mp["p_com"]
    com = origin + np.outer(p[:, 0], fwd) + np.outer(p[:, 1], up) + np.outer(L * data["com_lateral"], lat)
    # Each foot stands where the reference's stands relative to the COM at mid-stance (× L): the pose and
    # the foot then agree. The machine's own touchdown point (l_td sin θ0 ahead of the COM, the centre of
    # pressure's heel end) differs from it by the fit's geometry error; the IK follows the reference's.
    t_mid = 0.5 * (t_td + t_lo)
    x_mid = m.path(t_mid)["p_com"][:, 0]
    ahead = contact_from_com(prep.gait, prep.com, fwd, prep.motion.frame_time)
    contacts = origin + np.outer(x_mid + L * ahead[feet], fwd) + np.outer(L * cyc.contact_lateral[feet], lat)
    force = np.outer(mp["force"][:, 0], fwd) + np.outer(mp["force"][:, 1], up)
    # the machine's feet (0 leads the even steps) are the reference's A and B
    stance = mp["contact"][:, [0, 1] if A == 0 else [1, 0]]
    contact = np.zeros((n_frames, 2), bool)
    for i, f in enumerate(feet):
        contact[(t >= contact_on[i]) & (t < contact_off[i]), f] = True
    v = m.mean_speed * m.speed_unit
    return MachinePath(
        times=t, com=com, force=force, psi=psi, stance=stance, contact=contact, foot_of_step=feet,
        t_touchdown=t_td, t_liftoff=t_lo, contact_on=contact_on, contact_off=contact_off, contacts=contacts,
        apex_speed=np.full(n_steps + 1, v), U=np.full(n_steps + 1, m.mean_speed), frame=cyc.frame, l0=l0,
        mass=m.mass,
    )


def _double_support_fraction(gait, n_frames: int) -> float:
    """Mean double support / mean step time over the complete steps (a touchdown, the other foot's
    liftoff, the next touchdown) at the gait's sub-frame events: the machine's t_double / t_step. The
    share of frames with both feet down when the motion has no complete step."""
    ev = walking_events(gait, gait.frame_time, n_frames)
    ds, steps = [], []
    for i, e in enumerate(ev):
        if e.kind != "td":
            continue
        lo = next((x for x in ev[i + 1:] if x.kind == "lo"), None)
        nxt = next((x for x in ev[i + 1:] if x.kind == "td"), None)
        if lo is None or nxt is None or lo.foot == e.foot or nxt.foot == e.foot or lo.frame > nxt.frame:
            continue
        ds.append(lo.frame - e.frame)
        steps.append(nxt.frame - e.frame)
    return float(np.mean(ds) / np.mean(steps)) if steps else float(gait.double_support_fraction)


#: Swing marker weight reached at touchdown and left at liftoff by ``soften_swing_weights`` [1/m²], and the
#: share of the step time over which it ramps (geometrically, from the swing weight).
SWING_GUIDE_WEIGHT = 0.5
SWING_GUIDE_SHARE = 0.35


def soften_swing_weights(path, weight: np.ndarray, swing_weight: float) -> np.ndarray:
    """(T, 2, 3) foot marker weights with the swinging foot guided more firmly near its contacts.

    A walking foot lands and leaves with an almost straight knee; the swing weight lets the foot drift
    centimetres from its target (the posture pull wins), and the stance ramp then pulls it back within a
    frame or two, a knee jump of 10-15 degrees. Here the weight rises geometrically (min-jerk in log
    weight) from swing_weight to SWING_GUIDE_WEIGHT over SWING_GUIDE_SHARE of a step before each contact
    and falls the same way after it, so the foot is brought to its target over a tenth of a second.
    weight: (T, 2, 3) [1/m²] before the per-size factor; path: the walking MachinePath.
    """
    from .synthesis import min_jerk

    t = path.times
    step = float(np.median(np.diff(path.t_touchdown))) if len(path.t_touchdown) > 1 else 0.5
    Tw = SWING_GUIDE_SHARE * step
    ratio = math.log(SWING_GUIDE_WEIGHT / swing_weight)
    out = weight.copy()
    for i, f in enumerate(path.foot_of_step):
        a, b = path.contact_on[i], path.contact_off[i]
        u = np.where((t >= a) & (t <= b), 1.0, np.minimum(np.clip((t - (a - Tw)) / Tw, 0, 1),
                                                            np.clip(((b + Tw) - t) / Tw, 0, 1)))
        g = swing_weight * np.exp(ratio * min_jerk(u))
        out[:, f] = np.maximum(out[:, f], g[:, None])
    return out


def walking_report(com: np.ndarray, gait, frame_time: float) -> dict:
    """The walking figures of a motion's report (issue 17): double-support fraction, the vertical force's
    two peaks and trough over a stance [BW] and their stance phases, from the COM (eq. 1, the project's
    one differentiation) averaged over the complete stances. com: (F, 3) [m]. NaN when not measurable."""
    from .machine.walk_fit import PROFILE_SAMPLES, force_landmarks
    from .metrics import vertical_force_bw

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

    "cadence": clip [Hz] (measured), output [Hz] (measured), expected = clip × L^-1/2 × s^1/2 (dynamic
    similarity and the walking speed law, ``machine.walk_speed``), naive = clip × s (engines keep the
    clip's timing, played s times faster) and its error against the expected one.
    """
    from .gait import detect_gait
    from .machine.walk_speed import STEP_TIME_EXPONENT
    from .metrics import _with_ground

    body = res.retarget.body
    com, markers = body.com_and_markers(res.motion)
    gait = _with_ground(detect_gait(res.motion, body, markers), 0.0)
    out = walking_report(com, gait, res.motion.frame_time)
    clip = walking_report(prep.com, prep.gait, prep.motion.frame_time)
    L, s = float(res.retarget.L), float(res.speed_factor)
    f_clip = float(prep.summary.step_frequency)
    f_out = float(report.step_frequency_hz)
    expected = f_clip * L ** -0.5 * s ** (-STEP_TIME_EXPONENT)
    naive = f_clip * s
    return {"machine": "walking", "walking": {**out, "clip": clip},
            "cadence": {"clip_step_frequency_hz": f_clip, "step_frequency_hz": f_out,
                        "expected_step_frequency_hz": expected, "naive_step_frequency_hz": naive,
                        "naive_error": naive / expected - 1.0, "clip_froude_U": float(prep.summary.froude)}}


def walking_rows(report) -> list[tuple[str, str]]:
    """Rows of the CLI's result table for a walking output (empty for other reports)."""
    w, c = report.extras.get("walking"), report.extras.get("cadence")
    if not w or not c:
        return []
    return [
        ("double support", f"{100 * w['double_support_fraction']:.1f} % of the cycle "
                           f"(clip {100 * w['clip']['double_support_fraction']:.1f} %)"),
        ("vertical force", f"peaks {w['peak1_bw']:.2f} / {w['peak2_bw']:.2f} BW, trough {w['trough_bw']:.2f} BW "
                           f"(clip {w['clip']['peak1_bw']:.2f} / {w['clip']['peak2_bw']:.2f}, {w['clip']['trough_bw']:.2f})"),
        ("cadence", f"{c['step_frequency_hz']:.3f} Hz (expected {c['expected_step_frequency_hz']:.3f}); the naive "
                    f"retarget steps at {c['naive_step_frequency_hz']:.3f} Hz ({100 * c['naive_error']:+.0f} %)"),
    ]
