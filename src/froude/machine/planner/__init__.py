"""§5.3: plan acceleration and deceleration of the simple machine, step by step (dimensionless).

A *step* is one stance and the flight after it, apex → apex; a stride is two steps. The state at
each apex is (U, H) (speed [√(g l0)], height [l0]); per step the planner chooses the touchdown angle
θ0 — the paper's control input (eq. 5) — and, only where θ0 alone cannot do the job, a small change
δb of the control's linear leg-extension coefficient b ("push harder / softer"). K, a, c and T_c
always stay the fitted ones.

Why b and not a. At a running cycle the step map nearly conserves the apex energy E = ½U² + H
whatever θ0 is (measured on a K = 17 cycle: ΔE' ≈ 0.005 for 8° of θ0): a steeper or flatter leg
only trades speed for height. Halving U = 1.2 with θ0 alone would lift the apex by
½(1.2² − 0.6²) = 0.54 l0, a bound rather than a run, and U × 1.3 would need an apex below the
touchdown height. Energy must be added or removed in stance. Of the control's coefficients, a
(length offset) acts like θ0 (measured ∂U'/∂a ≈ −2.2, ∂E'/∂a ≈ 0.1-0.3), while b (desired length
growing by b l0 over the stance) changes the actuator work ∫ f dl_d almost alone (∂E'/∂b ≈ 2.5,
∂U'/∂b ≈ 0.08). δb is the runner extending the leg more (accelerating) or less (braking) during
the push; the planner keeps |δb| ≤ ``Comfort.b_band`` (0.08 l0; the real clips use ≤ 0.05).

Policy (:func:`plan_speed_change`):

* target: a periodic orbit of the machine at U_t (:func:`target_cycle`), the one nearest the start
  cycle in fall time, b and apex height (scales 0.05, 0.01, 0.02; minimum-norm Newton of the one orbit
  solver, ``machine.orbit.solve_orbit``, inside the comfort band), found by continuation;
* reference speeds: U_ref(k) = U0 + (U_t − U0) s(k/n) for the n change steps, s = ``"ease"``
  (smoothstep 3x² − 2x³: gentle start and end, peak change 1.5× the mean) or ``"even"`` (equal ΔU);
  monotone, so apex speeds never overshoot;
* ``energy="b"``: θ0 and b per step; every apex speed equals U_ref exactly and the last apex is
  the target orbit's fixed point; among the solutions the planner takes the one whose inputs
  stay closest to the start → target interpolation (least squares, scaled);
* ``energy="theta"`` (the paper's): θ0 only; the last apex speed is U_t exactly and the change
  ends on a periodic orbit of the fitted control (whichever it reaches: θ0 only barely moves the
  energy), the intermediate speeds follow U_ref in the least-squares sense and monotonically;
* ``energy="auto"`` (default): θ0 only when that works within the comfort bounds, else θ0 + δb;
* lead steps (before) and hold steps (after) track the start and target fixed points exactly (Newton
  per step on the same solver).

Numerics. The change steps are solved together by constrained Gauss–Newton with *multiple
shooting* (inputs and apex states are unknowns tied by continuity constraints; the per-step maps
are unstable, |λ| up to ≈ 2, so single shooting compounds sensitivities) on the exact simulator
:func:`~froude.machine.dynamics.step`, with finite-difference rows batched into one call. Inside,
the touchdown is parametrised by the apex → touchdown fall time τ (cos θ0 = H − τ²/2): every τ ≥ 0
is a reachable touchdown, so iterations cannot fall off the "apex below touchdown" cliff the fitted
cycles sit next to (their apex is only ≈ 0.01-0.05 l0 above touchdown height). With a transition
table, θ0-only plans start from a table rollout (``theta_for_speed`` + ``lookup``, the paper's
use) and lead/hold steps take their first θ0 from it; the answer never comes from the
interpolant: the final plan is re-simulated step by step with the simulator's scalar path (the
one :func:`~froude.machine.dynamics.simulate` uses), so it is exact against direct simulation.
``pipeline.accelerate`` passes no table: on the 9 CMU running clips θ0 alone reaches neither 0.9× nor
1.1× in 8 steps, so every plan there is θ0 + δb, which the table (of the fitted control) does not
cover; given a table, the 18 plans of 0.5×/1.3× are identical to the bit and no faster
(``benchmarks/bench_plan_table.py``).

Everything is dimensionless (l0 = g = m = 1); nothing depends on a character's size or mass, so one
plan serves every dynamically similar character. SI appears only in :meth:`SpeedPlan.to_si`.
"""
from __future__ import annotations

from froude.machine.planner.policy import (
    ENERGY_MODES,
    POLICIES,
    SpeedPlan,
    plan_speed_change,
    plan_speed_profile,
    speed_fraction_at,
)
from froude.machine.planner.shooting import Comfort, one_step_range, sustainable_range, target_cycle

__all__ = ["Comfort", "SpeedPlan", "plan_speed_change", "plan_speed_profile", "target_cycle",
           "one_step_range", "sustainable_range", "speed_fraction_at", "POLICIES", "ENERGY_MODES"]
