"""Stance events from the whole COM trajectory instead of the eq. 1 force's 0.5 BW crossings (issue 12
acceptance 1, a measurement: the fit does not use it).

Each full stance with at least EDGE_S of the clip on either side: the raw COM height at the clip's own
samples, from the previous contact's liftoff to the next one's touchdown (marker contacts), is fitted by least
squares with a ballistic flight (g known), a stance under a half-sine vertical force A m g sin(π u / Tc), and
a ballistic flight after, joined with continuous position and velocity: 5 parameters (height and vertical
speed at touchdown, touchdown time, Tc, A) from ~20 samples at 30 Hz, ~90 at 120 Hz.

    python benchmarks/trajectory_events.py            # per stance: 30 Hz thinned takes against 120 Hz [ms]
    python benchmarks/trajectory_events.py --fit      # K, θ0 of the fit with these events, 30 against 120 Hz
    python benchmarks/trajectory_events.py --fit --bw 0.5   # events where the pulse crosses 0.5 BW
    python benchmarks/trajectory_events.py --fit --no-short --edge 0.06   # see SHORT_STANCE_S, EDGE_S

``--fit`` replaces the fit's force-refined events (``forces.refine_events``) by the trajectory's and measures a
stance without them (too near the clip's edge) like a stance cut by the edge. Measured 2026-11-26 on the nine
runs, four thinning phases each (figures in the comment above ``_RATE_SHORT`` in tests/test_conventions.py).
"""
from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

#: Least flight [s] a stance needs inside the clip on either side for its trajectory fit (3 samples at 30 Hz).
EDGE_S = 0.1
#: ``--no-short``: 1e-9 turns off the fit's short-stance rule (fit.SHORT_STANCE_S; a 60 ms contact sliver at a
#: 30 Hz take's start can pull the contacts' median below it on a CMU run); None keeps it.
SHORT_STANCE_S: float | None = None


def com_height(t, y_td, v_td, td, Tc, A, g):
    """COM height (N,) [m] at times t (N,) [s]: ballistic until td [s], half-sine force A m g over Tc [s],
    ballistic after; y_td [m], v_td [m/s] at touchdown; g [m/s²]."""
    w = math.pi / Tc

    def stance(u):  # height and vertical speed u [s] after touchdown
        return (y_td + v_td * u - 0.5 * g * u * u + g * A / w * (u - np.sin(w * u) / w),
                v_td - g * u + g * A / w * (1 - np.cos(w * u)))

    s = t - td
    y, _ = stance(np.clip(s, 0.0, Tc))
    y_lo, v_lo = stance(Tc)
    y = np.where(s < 0, y_td + v_td * s - 0.5 * g * s * s, y)
    s2 = s - Tc
    return np.where(s2 > 0, y_lo + v_lo * s2 - 0.5 * g * s2 * s2, y)


def fit_events(t, y, td0, lo0, bw=0.0):
    """(touchdown, liftoff) [s] of the stance in samples t (N,) [s], y (N,) COM height [m], from the guess
    td0, lo0 [s]; bw > 0: where the fitted pulse crosses bw body weights instead of its ends."""
    from scipy.optimize import least_squares

    from froude.core.constants import GRAVITY

    before = t < td0
    v_td, y_td = (np.polyfit(t[before] - td0, y[before] + 0.5 * GRAVITY * (t[before] - td0) ** 2, 1)
                  if before.sum() >= 2 else (-0.5, float(np.interp(td0, t, y))))
    r = least_squares(lambda x: com_height(t, *x, GRAVITY) - y, [y_td, v_td, td0, lo0 - td0, 2.0],
                      x_scale=[0.01, 0.1, 0.01, 0.01, 0.5])
    _, _, td, Tc, A = r.x
    d = Tc / math.pi * math.asin(min(bw / A, 1.0)) if bw > 0 else 0.0
    return td + d, td + Tc - d


def trajectory_events(motion, bw=0.0):
    """[(touchdown, liftoff)] [s] of the full stances of a motion with EDGE_S of clip on either side."""
    from froude.body.gait import detect_gait
    from froude.body.model import BodyModel
    from froude.core.constants import UP_AXIS

    body = BodyModel.from_skeleton(motion.skeleton)
    com, markers = body.com_and_markers(motion)
    sts = detect_gait(motion, body, markers).stances
    dt = motion.frame_time
    t = np.arange(motion.n_frames) * dt
    out = []
    for i, st in enumerate(sts):
        a = sts[i - 1].t_off * dt if i > 0 else 0.0
        b = sts[i + 1].t_on * dt if i + 1 < len(sts) else t[-1]
        if st.partial or st.t_on * dt - a < EDGE_S or b - st.t_off * dt < EDGE_S:
            continue
        sel = (t >= a) & (t <= b)
        out.append(fit_events(t[sel], com[sel, UP_AXIS], st.t_on * dt, st.t_off * dt, bw))
    return out


def fit_with(motion, bw=0.0):
    """fit_machine with each stance's events taken from trajectory_events where one lies within 40 ms of both
    force-refined events; a stance without them is measured like one cut by the clip's edge."""
    import froude.machine.fit as fm

    events = trajectory_events(motion, bw)
    force_events = fm.refine_events

    def refine(fy_bw, start, stop, dt, partial=False):
        td, lo, _, _ = force_events(fy_bw, start, stop, dt, partial)
        for t0, t1 in events:
            if abs(t0 - td * dt) < 0.04 and abs(t1 - lo * dt) < 0.04:
                return t0 / dt, t1 / dt, True, True
        return td, lo, False, False

    with mock.patch.object(fm, "refine_events", refine), \
            mock.patch.object(fm, "SHORT_STANCE_S", SHORT_STANCE_S or fm.SHORT_STANCE_S):
        return fm.fit_machine(motion)


def _takes(name):
    """(phase, thinned 30 Hz Motion) for the four phases of a run."""
    from bars_matrix import clip_path
    from fit_rates import _take

    from froude.body.load import load_bvh

    import rig_variants as rv
    from conftest import read_bvh_oracle

    b = read_bvh_oracle(clip_path(name))
    with tempfile.TemporaryDirectory() as tmp:
        for phase in range(4):
            path = Path(tmp, f"{name}.thinned{phase}.bvh")
            path.write_text(rv.bvh_text(_take(b, "thinned", phase)))
            yield phase, load_bvh(path)


def stances(names, bw):
    """Per stance: touchdown, liftoff and duration of each thinned take against 120 Hz [ms]; RMS over all."""
    from bars_matrix import clip_path

    from froude.body.load import load_bvh

    err = []
    for name in names:
        ref = trajectory_events(load_bvh(clip_path(name)), bw)
        for phase, m in _takes(name):
            for td, lo in trajectory_events(m, bw):
                td, lo = td + phase / 120, lo + phase / 120
                td0, lo0 = min(ref, key=lambda r: abs(r[0] - td))
                if abs(td0 - td) < 0.05:
                    err.append((1e3 * (td - td0), 1e3 * (lo - lo0), 1e3 * ((lo - td) - (lo0 - td0))))
        print(name, " ".join(f"{d:+.1f}" for *_, d in err[-8:]), flush=True)
    rms = np.sqrt(np.mean(np.array(err) ** 2, axis=0))
    print(f"{len(err)} stances: RMS touchdown {rms[0]:.2f} ms, liftoff {rms[1]:.2f} ms, duration {rms[2]:.2f} ms")
    return 0


def fits(names, bw):
    """K, θ0 of each thinned take's fit against the 120 Hz fit, both with trajectory events; the 120 Hz fit's
    change from the force events (K, θ0, COM height RMS)."""
    from bars_matrix import clip_path

    from froude.body.load import load_bvh
    from froude.errors import FroudeError
    from froude.machine.fit import fit_machine

    rows, miss, n = [], 0, 0
    for name in names:
        m0 = load_bvh(clip_path(name))
        old = fit_machine(m0)
        try:
            ref = fit_with(m0, bw)
        except FroudeError as exc:
            print(f"{name}: the 120 Hz fit with trajectory events fails ({exc})")
            miss, n = miss + 4, n + 4
            continue
        cells = []
        for _, m in _takes(name):
            n += 1
            try:
                fit = fit_with(m, bw)
            except FroudeError as exc:
                miss += 1
                cells.append(f"fails ({type(exc).__name__})")
                continue
            dk, dth = 100 * (fit.K / ref.K - 1), math.degrees(fit.theta0 - ref.theta0)
            bad = not (abs(dk) <= 3.0 and abs(dth) <= 0.5)
            miss += bad
            rows.append((dk, dth))
            cells.append(f"{dk:+5.1f} %/{dth:+.2f}°{'*' if bad else ' '}")
        print(f"{name} 120 Hz K {old.K:5.2f} -> {ref.K:5.2f}, θ0 {math.degrees(old.theta0):.2f} -> "
              f"{math.degrees(ref.theta0):.2f}°, COM RMS {1e3 * old.quality['com_rms_m']:.1f} -> "
              f"{1e3 * ref.quality['com_rms_m']:.1f} mm | " + "  ".join(cells), flush=True)
    rms = np.sqrt(np.mean(np.array(rows) ** 2, axis=0))
    print(f"{miss} of {n} takes miss K 3 % or θ0 0.5° (*, or no fit); RMS ΔK {rms[0]:.2f} %, Δθ0 {rms[1]:.3f}°")
    return 0


def main(argv: list[str]) -> int:
    from fit_rates import CMU_RUNS

    global EDGE_S, SHORT_STANCE_S
    bw = float(argv[argv.index("--bw") + 1]) if "--bw" in argv else 0.0
    EDGE_S = float(argv[argv.index("--edge") + 1]) if "--edge" in argv else EDGE_S
    SHORT_STANCE_S = 1e-9 if "--no-short" in argv else None
    names = [a for i, a in enumerate(argv)
             if not a.startswith("--") and (i == 0 or argv[i - 1] not in ("--bw", "--edge"))]
    return (fits if "--fit" in argv else stances)(names or list(CMU_RUNS), bw)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
