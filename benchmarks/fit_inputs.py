"""Which of the §4 fit's measured inputs carry the 30 Hz thinning's error (issue 12 acceptance 1: K within 3 %,
θ0 within 0.5° of the 120 Hz fit), and whether the COM's displacement, not its force, fixes the spring better.

    python benchmarks/fit_inputs.py                  # the cycle search's inputs, swapped for the 120 Hz ones (~10 s)
    python benchmarks/fit_inputs.py --displacement   # each stance's spring fitted to the COM's displacement (~15 s)
    python benchmarks/fit_inputs.py --machine        # the whole machine fitted to the COM's displacement (~1 min)

The periodic cycle search (``fit._cycle_search``) sees two kinds of measured input: priors z0 = (U, H, θ0, K, a,
b, c) (apex speed and height, the mean touchdown angle, the pooled eq. 2 fit of the stances) and targets (stance
time, flight time, mean speed; T_c is the stance time). The default mode records them for the 120 Hz clip and
its four thinned 30 Hz takes (frames 0, 1, 2, 3 mod 4: ``fit_rates._take``), then re-runs the search on the 30
Hz take's inputs with one group replaced by the 120 Hz value: the misses left say how much of the error that
group carries. It also re-runs both rates with the search changed (K's scale; fixed a, b, c priors; a soft
stance time: least squares with the step time, speed and periodicity held and the stance time weighted by 1/σ),
to see whether a search that leans less on the noisy input agrees better; the 120 Hz fit's own move with it.

``--displacement``: each full stance's spring fitted to the COM's raw displacement at the clip's own frames
(not its twice-differentiated force): eq. 2's basis (compression, 1, τ, τ² along the leg, from the smoothed
COM's geometry) integrated twice over the stance and ``W_S`` seconds of the flights on each side, plus free
initial position and speed, by linear least squares, spring first like ``fit.fit_stance_control``; its
per-stance K at 30 Hz against the same stance at 120 Hz, next to the force-based fit's.

``--machine``: the whole machine fitted to the COM's displacement through the simulator
(``machine_displacement_fit``), at both rates, free stance time or held within 1 %; the 120 Hz fit's move too.
"""
from __future__ import annotations

import math
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from fit_rates import CMU_RUNS, _take  # noqa: E402

#: Flight kept on each side of a stance in the displacement fit [s].
W_S = 0.05


@contextmanager
def _recording():
    """Record the inputs of every ``fit._cycle_search`` call: yields a list of dicts (z0, T_c, targets, n)."""
    import froude.machine.fit as fit

    calls: list[dict] = []
    real = fit._cycle_search

    def spy(z0, T_c, targets, n_per_stance, **kw):
        calls.append({"z0": np.array(z0, float), "T_c": T_c, "targets": np.array(targets, float),
                      "n": n_per_stance})
        return real(z0, T_c, targets, n_per_stance, **kw)

    fit._cycle_search = spy
    try:
        yield calls
    finally:
        fit._cycle_search = real


def _takes(name, tmp):
    """(120 Hz motion, [the four thinned 30 Hz motions]) of a CMU run."""
    from bars_matrix import clip_path

    from froude.body.load import load_bvh

    import rig_variants as rv
    from conftest import read_bvh_oracle

    b = read_bvh_oracle(clip_path(name))
    out = []
    for phase in range(4):
        path = Path(tmp, f"{name}.thinned{phase}.bvh")
        path.write_text(rv.bvh_text(_take(b, "thinned", phase)))
        out.append(load_bvh(path))
    return load_bvh(clip_path(name)), out


def _inputs(names):
    """{name: (120 Hz inputs, [the four thinned takes' inputs])} as recorded by ``_recording``."""
    from froude.machine.fit import fit_machine

    got = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            ref, thinned = _takes(name, tmp)
            with _recording() as calls:
                for m in (ref, *thinned):
                    fit_machine(m)
            got[name] = (calls[0], calls[1:])
    return got


def _soft_search(inp, sigma_t, k_scale):
    """The cycle (7,) by least squares: periodicity, step time and mean speed held (weight 1e4), the stance time
    within relative σ = sigma_t, z near the priors in CYCLE_SCALES (K's scaled by k_scale, relative)."""
    from scipy.optimize import least_squares

    from froude.machine.dynamics import Control, step
    from froude.machine.fit import _VARS, CYCLE_SCALES, _cycle_search

    z0, Tc, tg = inp["z0"], inp["T_c"], inp["targets"]
    s = np.array([CYCLE_SCALES[v] for v in _VARS])
    s[3] = k_scale * abs(z0[3])
    period = tg[0] + tg[1]

    def residual(z):
        r = step(z[0], z[1], z[2], Control(K=z[3], a=z[4], b=z[5], c=z[6], T_c=Tc), n_per_stance=inp["n"])
        if not bool(r.valid):
            return np.full(12, 1e3)
        t_step = float(r.t_fall + r.t_stance + r.t_rise)
        held = [float(r.U_next) - z[0], float(r.H_next) - z[1], t_step / period - 1,
                float(r.apex_dx) / t_step / tg[2] - 1]
        return np.concatenate([1e4 * np.array(held), [(float(r.t_stance) / tg[0] - 1) / sigma_t], (z - z0) / s])

    start = _cycle_search(z0, Tc, tg, inp["n"])[0]
    return least_squares(residual, start, x_scale=s, diff_step=1e-7).x


def _score(label, got, search):
    """Print misses and RMS of (K, θ0) of the thinned takes against 120 Hz, each fitted by search(inp, ref)."""
    err, moved = [], []
    for ref, takes in got.values():
        z120 = search(ref, ref)
        z_now = _plain(ref)
        moved.append(f"{100 * (z120[3] / z_now[3] - 1):+.1f} %/{math.degrees(z120[2] - z_now[2]):+.2f}°")
        for inp in takes:
            z = search(inp, ref)
            err.append((100 * (z[3] / z120[3] - 1), math.degrees(z[2] - z120[2])))
    e = np.array(err)
    miss = int(np.sum(~((np.abs(e[:, 0]) <= 3.0) & (np.abs(e[:, 1]) <= 0.5))))
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    print(f"{label:44s} {miss:2d} of {len(e)} miss; RMS ΔK {rms[0]:.2f} %, Δθ0 {rms[1]:.3f}°; "
          f"120 Hz fit moves K/θ0 {' '.join(moved)}", flush=True)


def _plain(inp):
    from froude.machine.fit import _cycle_search

    return _cycle_search(inp["z0"], inp["T_c"], inp["targets"], inp["n"])[0]


def _rescaled(inp, k_scale):
    """The plain search with K's scale in CYCLE_SCALES set to k_scale (relative)."""
    from froude.machine import fit

    saved = fit.CYCLE_SCALES["K"]
    fit.CYCLE_SCALES["K"] = k_scale
    try:
        return _plain(inp)
    finally:
        fit.CYCLE_SCALES["K"] = saved


def _swapped(prior_idx=(), targets=False):
    """A search on the 30 Hz inputs with the priors prior_idx (and the targets and T_c) taken from 120 Hz."""
    def search(inp, ref):
        z0 = inp["z0"].copy()
        z0[list(prior_idx)] = ref["z0"][list(prior_idx)]
        src = ref if targets else inp
        return _plain({**inp, "z0": z0, "T_c": src["T_c"], "targets": src["targets"]})
    return search


def inputs(names: list[str]) -> int:
    """The table of the default mode (see the module doc)."""
    got = _inputs(names)
    _score("as fitted", got, _swapped())
    swaps = (("120 Hz stance/flight time and speed", (), True), ("120 Hz prior K", (3,), False),
             ("120 Hz priors a, b, c", (4, 5, 6), False), ("120 Hz priors K, a, b, c", (3, 4, 5, 6), False),
             ("120 Hz priors U, H, θ0", (0, 1, 2), False), ("120 Hz priors (all seven)", range(7), False))
    for label, idx, tgt in swaps:
        _score(label, got, _swapped(idx, tgt))
    for k_scale in (0.3, 1.0, 3.0):
        _score(f"K scale {k_scale} (targets held)", got, lambda inp, ref, k=k_scale: _rescaled(inp, k))
    abc = np.mean([ref["z0"][4:7] for ref, _ in got.values()], axis=0)
    _score("priors a, b, c: the runs' mean (both rates)", got,
           lambda inp, ref: _plain({**inp, "z0": np.concatenate([inp["z0"][:4], abc])}))
    for sigma_t in (0.003, 0.01, 0.02, 0.05):
        for k_scale in (0.1, 0.3):
            _score(f"soft stance time σ {100 * sigma_t:.1f} %, K scale {k_scale}", got,
                   lambda inp, ref, s=sigma_t, k=k_scale: _soft_search(inp, s, k))
    return 0


def _double_integral(t, f):
    """∫∫ f from t[0] on the grid t (N,) [s], f (N, ...) → (N, ...) (trapezoids)."""
    from scipy.integrate import cumulative_trapezoid

    return cumulative_trapezoid(cumulative_trapezoid(f, t, axis=0, initial=0), t, axis=0, initial=0)


def displacement_spring(motion, res, com_raw, sg) -> float:
    """K [-] of one stance sg (StanceGeometry of FitResult res) fitted to the raw COM (F, 3) [m] at the clip's
    frames over the stance and W_S on each side: x, y (heading, up) = x0 + v0 t + ∫∫ (f_leg/m u − g), f_leg = m g
    (K (1 − l/l0) + k1), u and l from the smoothed COM and the contact point (the spring-first fit's first step)."""
    from froude.core.constants import GRAVITY, UP_AXIS

    t_clip = np.arange(motion.n_frames) * motion.frame_time
    t0, t1 = sg.t_touchdown - W_S, sg.t_liftoff + W_S
    sel = (t_clip >= t0) & (t_clip <= t1)
    ts = t_clip[sel]
    tg = np.linspace(t0, t1, 2001)
    p = np.stack([np.interp(tg, res.times, res.p_world_com[:, k]) for k in range(3)], axis=1) - sg.p_world_contact
    rx, ry = p @ res.machine.heading, p[:, UP_AXIS]
    leg = np.hypot(rx, ry)
    on = (tg >= sg.t_touchdown) & (tg <= sg.t_liftoff)
    cols = []
    for basis in (np.maximum(0.0, 1.0 - leg / sg.l0), np.ones_like(tg)):
        acc = np.where(on, basis, 0.0) * GRAVITY  # [m/s²] per unit of the coefficient (body weights)
        cols.append(np.concatenate([np.interp(ts, tg, _double_integral(tg, acc * rx / leg)),
                                    np.interp(ts, tg, _double_integral(tg, acc * ry / leg))]))
    one, zero, dt = np.ones_like(ts), np.zeros_like(ts), ts - t0
    free = [np.concatenate(c) for c in ((one, zero), (dt, zero), (zero, one), (zero, dt))]
    data = np.concatenate([com_raw[sel] @ res.machine.heading, com_raw[sel, UP_AXIS] + 0.5 * GRAVITY * dt * dt])
    coef, *_ = np.linalg.lstsq(np.stack(cols + free, axis=1), data, rcond=None)
    return float(coef[0])


def displacement(names: list[str]) -> int:
    """The table of ``--displacement`` (see the module doc)."""
    from froude.body.model import BodyModel
    from froude.machine.fit import fit_machine_detailed

    def rows(motion):
        res = fit_machine_detailed(motion)
        com = BodyModel.from_skeleton(motion.skeleton).com(motion)
        return [(sg.t_touchdown, sg.t_liftoff, ft.K, displacement_spring(motion, res, com, sg))
                for sg, ft in zip(res.stances, res.stance_fits) if not sg.partial and ft is not None]

    err = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            ref, thinned = _takes(name, tmp)
            ref_rows = rows(ref)
            cells = []
            for phase, m in enumerate(thinned):
                for td, lo, k_force, k_disp in rows(m):
                    td, lo = td + phase / 120.0, lo + phase / 120.0
                    r = min(ref_rows, key=lambda q: abs(q[0] - td) + abs(q[1] - lo))
                    err.append((100 * (k_force / r[2] - 1), 100 * (k_disp / r[3] - 1)))
                    cells.append(f"{err[-1][0]:+5.1f}/{err[-1][1]:+5.1f}")
            print(f"{name}  120 Hz K force/displacement " + " ".join(f"{q[2]:.1f}/{q[3]:.1f}" for q in ref_rows)
                  + "  | 30 Hz ΔK % " + " ".join(cells), flush=True)
    e = np.array(err)
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    print(f"{len(e)} stances: per-stance K at 30 Hz against 120 Hz, RMS {rms[0]:.2f} % from the force, "
          f"{rms[1]:.2f} % from the displacement; |ΔK| > 5 % on {int(np.sum(abs(e[:, 0]) > 5))} / "
          f"{int(np.sum(abs(e[:, 1]) > 5))}")
    return 0


#: Scale of the COM samples' misfit in the machine displacement fit [m] (the capture's vibration is 0.5-0.75 mm).
SIGMA_COM_M = 0.5e-3


def machine_displacement_fit(motion, res, stance_sigma=None):
    """(U, H, θ0, K, a, b, c) [-] of the machine whose simulated COM (heading, up; ``dynamics.simulate``) best
    matches the raw COM at the clip's frames over the fit's stride (events e0..e4 ± 0.06 s), by least squares:
    residuals [SIGMA_COM_M] of the height above the stances' ground and of the forward position (its mean
    removed), z near the fit's priors in CYCLE_SCALES, periodicity, step time and mean speed held (weight 1e4),
    the stance time within relative stance_sigma if given; one free time offset. Starts at the fitted machine."""
    from scipy.optimize import least_squares

    from froude.body.model import BodyModel
    from froude.core.constants import UP_AXIS
    from froude.errors import FroudeError
    from froude.machine.dynamics import Control, simulate
    from froude.machine.fit import _VARS, CYCLE_SCALES
    from froude.machine.units import speed_unit, time_unit

    m = res.machine
    com = BodyModel.from_skeleton(motion.skeleton).com(motion)
    t = np.arange(motion.n_frames) * motion.frame_time
    e = res.stride_events
    sel = (t >= e[0] - 0.06) & (t <= e[4] + 0.06)
    T, unit = time_unit(m.l0), SIGMA_COM_M / m.l0
    tk, xk = t[sel] / T, com[sel] @ m.heading / m.l0
    mid = [0.5 * (s.t_touchdown + s.t_liftoff) for s in res.stances]
    yk = (com[sel, UP_AXIS] - np.interp(t[sel], mid, [s.ground for s in res.stances])) / m.l0
    ref = m.reference
    period, speed, t_stance = ref["step_time_s"] / T, ref["mean_speed_m_s"] / speed_unit(m.l0), ref["stance_time_s"] / T
    z_fit = np.array([m.U, m.H, m.theta0, m.K, m.a, m.b, m.c])
    z0 = np.array([ref["pooled_fit"][k] if k in "Kabc" else v for k, v in zip(_VARS, z_fit)])
    s = np.array([CYCLE_SCALES[v] for v in _VARS])
    s[3] *= abs(z0[3])
    offset0 = e[0] / T - (m.t_fall if res.stride_kinds[0] == "TD" else m.t_fall + m.t_stance)
    bad = np.full(2 * tk.size + 12, 1e3)

    def residual(q):
        U, H, th, K, a, b, c, offset = q
        if not K > 0.5:
            return bad
        try:
            tr = simulate(U, H, th, Control(K=K, a=a, b=b, c=c, T_c=m.T_c), 0.01, n_steps=1)
        except (FroudeError, ValueError):
            return bad
        step_t, step_x = tr.t_apex[1], tr.x_apex[1]
        n = np.floor((tk - offset) / step_t)
        ph = tk - offset - n * step_t
        rx = xk - np.interp(ph, tr.t, tr.pos[:, 0]) - n * step_x
        held = [tr.U_apex[1] - U, tr.H_apex[1] - H, step_t / period - 1, step_x / step_t / speed - 1]
        soft = [] if stance_sigma is None else [((tr.t_liftoff[0] - tr.t_touchdown[0]) / t_stance - 1) / stance_sigma]
        return np.concatenate([(yk - np.interp(ph, tr.t, tr.pos[:, 1])) / unit, (rx - rx.mean()) / unit,
                               1e4 * np.array(held), soft, (q[:7] - z0) / s])

    sol = least_squares(residual, np.append(z_fit, offset0), x_scale=np.append(s, 0.01), diff_step=1e-6)
    com_rms_mm = 1e3 * SIGMA_COM_M * float(np.sqrt(np.mean(sol.fun[:2 * tk.size] ** 2)))
    return sol.x[:7], com_rms_mm


def machine(names: list[str], stance_sigma=None) -> int:
    """The table of ``--machine`` (see machine_displacement_fit)."""
    from froude.machine.fit import fit_machine_detailed

    err = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            ref, thinned = _takes(name, tmp)
            r120 = fit_machine_detailed(ref)
            z120, misfit = machine_displacement_fit(ref, r120, stance_sigma)
            cells = []
            for m in thinned:
                z, _ = machine_displacement_fit(m, fit_machine_detailed(m), stance_sigma)
                err.append((100 * (z[3] / z120[3] - 1), math.degrees(z[2] - z120[2])))
                cells.append(f"{err[-1][0]:+5.1f} %/{err[-1][1]:+.2f}°")
            th = math.degrees(r120.machine.theta0)
            print(f"{name}  120 Hz K {r120.machine.K:.2f} -> {z120[3]:.2f}, θ0 {th:.2f} -> "
                  f"{math.degrees(z120[2]):.2f}° (COM misfit {misfit:.1f} mm RMS)  | 30 Hz " + "  ".join(cells),
                  flush=True)
    e = np.array(err)
    miss = int(np.sum(~((np.abs(e[:, 0]) <= 3.0) & (np.abs(e[:, 1]) <= 0.5))))
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    print(f"machine displacement fit (stance time σ {stance_sigma}): {miss} of {len(e)} miss; RMS ΔK {rms[0]:.2f} %, "
          f"Δθ0 {rms[1]:.3f}°")
    return 0


def main(argv: list[str]) -> int:
    if argv[:1] == ["--machine"]:
        return machine(argv[1:] or list(CMU_RUNS)) + machine(argv[1:] or list(CMU_RUNS), stance_sigma=0.01)
    if argv[:1] == ["--displacement"]:
        return displacement(argv[1:] or list(CMU_RUNS))
    return inputs(argv or list(CMU_RUNS))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
