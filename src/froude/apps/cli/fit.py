"""``froude fit CLIP.bvh -o MACHINE.json [--plot FIT.png] [--mass KG]``: §4, the simple machine of a clip."""
from __future__ import annotations

import math
from pathlib import Path

from .common import (
    add_load_options,
    add_mass,
    add_quiet,
    add_range_option,
    check_inputs,
    guard_outputs,
    load_clip,
    say,
    say_loaded,
)

#: The one-line summary ``froude --help`` lists.
HELP = "fit the simple machine (running: one spring leg; walking: two) to a running or walking clip"


def register(sub) -> None:
    p = sub.add_parser(
        "fit", help=HELP,
        description="Fit Pollard's simple running machine (1999, section 4) to a running clip: ground force from "
        "the COM (eq. 1), per-stance leg geometry and control fits (eq. 2), and a periodic running cycle that "
        "matches the measured stance time, flight time and speed. A walk gets the walking machine instead (two "
        "spring legs with double support, docs/walking.md): a periodic cycle with the measured stance time, "
        "double-support time and speed, fitted to the clip's vertical force and COM height. Prints a table; "
        "writes the machine as JSON.",
    )
    p.add_argument("clip", help="BVH (or glTF/GLB) file of a running or walking motion")
    p.add_argument("-o", "--output", required=True, metavar="OUT.json",
                   help="machine JSON to write (schema froude.machine/1, froude.walking/1 for a walk); "
                   "its folder must exist")
    p.add_argument("--plot", default=None, metavar="PNG", help="also write Figure 2 of the paper for this clip (.png)")
    add_mass(p, "body mass [kg]")
    add_quiet(p)
    add_load_options(p)
    add_range_option(p)
    p.set_defaults(func=run)


def fit_table(res) -> str:
    """The per-stance and cycle table printed by ``froude fit``."""
    m = res.machine
    T = m.time_unit
    lines = ["stance  foot   t_td [s]  dur [s]  l0 [m]  θtd [°]  θlo [°]  drop [cm]  Fz pk [BW]      K       a       b"
             "       c     r²"]
    for i, (sg, ft) in enumerate(zip(res.stances, res.stance_fits)):
        if ft is not None:
            fit = f" {ft.K:6.1f} {ft.a:+7.3f} {ft.b:+7.3f} {ft.c:+7.3f} {ft.r2:6.3f}"
        elif sg.partial:
            fit = "      (partial: not fitted)"
        else:
            fit = "      (not a spring: left out of the fit)"
        lines.append(f"{i:>6}  {('left', 'right')[sg.foot]:<5} {sg.t_touchdown:9.3f} {sg.duration:8.3f} {sg.l0:7.3f} "
                     f"{math.degrees(sg.theta_touchdown):8.1f} {math.degrees(sg.theta_liftoff):8.1f} "
                     f"{100 * sg.com_drop:10.1f} {sg.peak_vertical_force / (m.mass * m.g):11.2f}{fit}")
    ref, q = m.reference, m.quality
    lines += [
        "",
        f"cycle   U = {m.U:.4f}  H = {m.H:.4f}  θ0 = {math.degrees(m.theta0):.2f}°  K = {m.K:.2f}  "
        f"a = {m.a:+.4f}  b = {m.b:+.4f}  c = {m.c:+.4f}  T_c = {m.T_c:.4f}   (l0 = {m.l0:.3f} m, m = {m.mass:g} kg)",
        f"        k = {m.k / 1000:.2f} kN/m, periodic to {m.periodicity:.1e} ({m.iterations} simulator calls), "
        f"peak leg force {m.peak_force:.2f} BW",
        f"        stance {m.t_stance * T:.3f} s (measured {ref['stance_time_s']:.3f}, "
        f"{100 * q['stance_time_error']:+.1f}%)  flight {m.t_flight * T:.3f} s (measured {ref['flight_time_s']:.3f}, "
        f"{100 * q['flight_time_error']:+.1f}%)",
        f"        mean speed {m.mean_speed_m_s:.3f} m/s (measured {ref['mean_speed_m_s']:.3f}, "
        f"{100 * q['mean_speed_error']:+.1f}%)  COM height RMS vs reference over a stride "
        f"{100 * q['com_rms_m']:.2f} cm",
        f"forces  flight residual {ref['flight_residual_bw']:.3f} BW RMS; share of stance force captured: "
        f"along the leg {100 * ref['shares']['leg']:.0f}%, vertical only {100 * ref['shares']['vertical']:.0f}%",
    ]
    return "\n".join(lines)


def run(args) -> int:
    from ...io.atomic import require_suffix  # lazy: start-up (froude --help imports every verb module and no NumPy)

    out = require_suffix(args.output, (".json",))
    plot = require_suffix(args.plot, (".png",), "plot") if args.plot else None
    check_inputs(args.clip)
    guard_outputs([out, plot], [args.clip])

    from ...body.model import BodyModel  # lazy: start-up (froude --help imports every verb module and no NumPy)

    # the load's notes are said once the fit succeeded: a clip that cannot be fitted is one error line
    motion = load_clip(args.clip, args.length_scale, args.keep_all_frames, True, args.joint_map, args.up)
    if args.range:
        from ...body.take import select_range  # lazy: start-up (froude --help imports every verb module and no NumPy)

        motion = select_range(motion, args.range, Path(args.clip).name)
    body = BodyModel.from_skeleton(motion.skeleton, mass=args.mass)
    from ...body.gait import summarize  # lazy: start-up (froude --help imports every verb module and no NumPy)
    from ...body.take import analysed_take, said_on_turn  # lazy: start-up (as above)
    from ...flow.kinds import choose_kind  # lazy: start-up (froude --help imports every verb module and no NumPy)

    # the take as ``prepare`` analyses it (a loop unrolled, an in-place take given its travel, a turning take
    # straightened along its path) and the one decision of body.gait about what it is: the same as ``info``
    # says and ``scale`` models (in place or unknown is refused in info's words, before a fit)
    take = analysed_take(motion, body)
    motion = take.motion
    kind = choose_kind(summarize(motion, body, take.com, take.gait), Path(args.clip).name)
    with said_on_turn(args.clip, take.turn):
        res = kind.fit_detailed(motion, body, mass=args.mass, source=Path(args.clip).name)
    for note in take.notes:
        say(f"note: {note}", args.quiet)
    table, plot_fn = FIT_OUTPUTS[kind.name]
    return _write_fit(args, motion, res, out, plot, plot_fn, table(res))


def _write_fit(args, motion, res, out, plot, plot_fn, table: str) -> int:
    """The machine file (and plot) of a fit, written together; then the table and what was written.
    plot_fn: loads the plot function (called only when a plot is asked for)."""
    from ...io.atomic import atomic_group  # lazy: start-up (froude --help imports every verb module and no NumPy)

    with atomic_group():
        if plot:
            plot_fn()(res, plot, title=Path(args.clip).name)
        res.machine.save(out)
    say_loaded(motion, args.clip, args.quiet)
    print(table)
    if plot:
        say(f"wrote {plot}", args.quiet)
    say(f"wrote {out}", args.quiet)
    return 0


def walk_table(res) -> str:
    """The table printed by ``froude fit`` for a walk: the cycle, then clip vs machine."""
    m = res.machine
    T, ref, q = m.time_unit, m.reference, m.quality
    fr, fm = ref["force_bw"], q["force_bw"]
    st = m.t_stance * T

    def pct(x):
        return f"{100 * x:+.1f}%"

    lines = [
        f"walking machine  u = {m.u:.4f}  v = {m.v:+.4f}  d = {m.d:.4f}  s = {m.s:.4f}  "
        f"θ0 = {math.degrees(m.theta0):.2f}°  l_td = {m.l_td:.4f}  roll = {m.roll:.4f}",
        f"        control  K = {m.K:.2f}  a = {m.a:+.4f}  b = {m.b:+.4f}  c = {m.c:+.4f}  e = {m.e:+.4f}  "
        f"T_c = {m.T_c:.4f}"
        f"   (l0 = {m.l0:.3f} m, m = {m.mass:g} kg; periodic to {m.periodicity:.1e})",
        *([f"         pulses  push-off p = {m.p:+.4f} at τ {m.tau_p:.3f} ± {m.w_p:.3f}   weight acceptance "
           f"q = {m.q:+.4f} at τ {m.tau_q:.3f} ± {m.w_q:.3f}"] if (m.p or m.q) else []),
        "",
        "                       clip    machine",
        f"stance [s]           {ref['stance_time_s']:6.3f}     {st:6.3f}  {pct(q['stance_time_error'])}",
        f"double support [s]   {ref['double_support_s']:6.3f}     {m.t_double * T:6.3f}  "
        f"{pct(q['double_support_error'])}",
        f"speed [m/s]          {ref['mean_speed_m_s']:6.3f}     {m.mean_speed_m_s:6.3f}  "
        f"{pct(q['mean_speed_error'])}",
        f"step time [s]        {ref['step_time_s']:6.3f}     {m.t_step * T:6.3f}",
    ]
    for key, name in (("peak1", "weight-acceptance peak"), ("trough", "trough"), ("peak2", "push-off peak")):
        lines.append(f"{name:<22} {fr[key]:5.2f} BW at {1e3 * fr['tau_' + key] * ref['stance_time_s']:4.0f} ms   "
                     f"{fm[key]:5.2f} BW at {1e3 * fm['tau_' + key] * st:4.0f} ms   "
                     f"({q[key + '_error_bw']:+.2f} BW, {pct(q[key + '_timing_error_step'])} of a step)")
    lines.append(f"COM height RMS over {ref['n_steps']} complete steps: {100 * q['com_rms_m']:.2f} cm; force over a "
                 f"stance RMS {q['force_profile_rms_bw']:.3f} BW (machine through the clip's "
                 f"{ref['filter']['cutoff_hz']:g} Hz filter)")
    return "\n".join(lines)


def _plot_run_fit():
    from ...viz.fit_plot import plot_fit  # lazy: start-up (froude --help imports every verb module and no NumPy)

    return plot_fit


def _plot_walk_fit():
    from ...viz.walk_plot import plot_walk_fit  # lazy: start-up (froude --help imports every verb module and no NumPy)

    return plot_walk_fit


#: What ``froude fit`` prints and plots for each kind of motion (``kinds.MotionKind.name``): the table of
#: the fit result and the plot function's loader (matplotlib is imported only when a plot is written).
FIT_OUTPUTS = {"running": (fit_table, _plot_run_fit), "walking": (walk_table, _plot_walk_fit)}
