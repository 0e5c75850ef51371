"""Which speeds a prepared clip reaches for a character with every physics bar met (the planner's refusals in
the user's terms are ``speed_change.plan_refusal``'s)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import BeyondHumanRange, FitError
from .pipeline import plan_scale
from .prepared import Prepared


@dataclass(frozen=True)
class SpeedRange:
    """The speeds a prepared clip reaches for one character with every physics bar met.

    lo, hi: speed factors on the character's dynamically scaled speed [-]; lo_m_s, hi_m_s: the same in
    m/s; base_m_s: the character's speed at factor 1 [m/s] (the clip's mean speed for its own body).
    probes: ((factor, met: bool, reason), ...) every output tried, in order. human_top: the fastest factor
    inside the human range for the character's size (``Prepared.human_top``; None: not limited, a walk or
    ``unlimited``), the end of the search when it is below SPEED_SEARCH_RANGE's.
    """

    lo: float
    hi: float
    lo_m_s: float
    hi_m_s: float
    base_m_s: float
    probes: tuple = ()
    empty: bool = False  # True when not even x1 meets every bar
    human_top: float | None = None

    def describe(self) -> str:
        if self.empty:
            return f"none (x1 = {self.base_m_s:.2f} m/s already misses a bar)"
        return (f"x{self.lo:.2f}-{self.hi:.2f} ({self.lo_m_s:.2f}-{self.hi_m_s:.2f} m/s; "
                f"x1 = {self.base_m_s:.2f} m/s)")

    def sentence(self) -> str:
        """The range as refusals and bar misses say it (scale and accelerate alike)."""
        # "steady": the range is probed with ``scale`` outputs; walks and runs alike
        human = "" if self.human_top is None else " and inside the human range for its size"
        return f"with every physics bar met{human} this character's steady speeds are {self.describe()}"


class SearchStopped(Exception):
    """reachable_speed_range was asked to stop (its ``stop()`` said so) before it was done; the outputs it
    had checked are kept on ``prep.memo`` and its next run for the same character starts from them."""


#: The factors reachable_speed_range searches between, and how finely [-].
SPEED_SEARCH_RANGE = (0.3, 3.0)
SPEED_SEARCH_TOL = 0.03


def _speed_ok(prep: Prepared, character, s: float, numbers: dict, unlimited: bool) -> tuple[bool, str]:
    """Whether a 4-stride output (scale's default) at speed factor s meets every physics bar (and is inside
    the human range unless ``unlimited``), and why not."""
    try:
        rep = plan_scale(prep, character, speed=s, strides=4, unlimited=unlimited, **numbers).finish().report
    except (FitError, BeyondHumanRange) as e:
        return False, str(e)
    assert rep is not None  # finish() computes the report by default
    fails = rep.check_bars()
    return not fails, "; ".join(fails)


#: After the bisection, every factor this far apart between x1 and each end is produced and checked too.
SPEED_GRID = 0.1


def _walk_in(ok, direction: float, end: float) -> float:
    """The end of the interval of factors around 1 whose outputs meet the bars, walking out from 1 in steps
    of SPEED_GRID up to ``end`` (the bisection's end): a grid factor that misses ends the interval there
    (refined by bisection to SPEED_SEARCH_TOL). The bisection alone assumes one interval; a loop unrolled
    from one stride can miss at x1.8 and meet the bars again at x2.1."""
    good = 1.0
    for g in np.arange(1.0 + direction * SPEED_GRID, end, direction * SPEED_GRID):
        if ok(float(g)):
            good = float(g)
            continue
        return _bisect(ok, good, float(g))
    return end


def _bisect(ok, good: float, bad: float) -> float:
    """The factor between ``good`` (meets the bars) and ``bad`` (misses) where ok flips, to SPEED_SEARCH_TOL;
    the value returned is one that was checked and met them."""
    while abs(bad - good) > SPEED_SEARCH_TOL:
        mid = 0.5 * (good + bad)
        if ok(mid):
            good = mid
        else:
            bad = mid
    return good


def reachable_speed_range(prep: Prepared, character=None, *, stop=None, unlimited: bool = False,
                          **character_numbers) -> SpeedRange:
    """The range of ``scale`` speed factors whose outputs meet every physics bar, for one character, inside
    the human range for its size (a run: ``Prepared.human_top`` ends the search; ``unlimited`` lifts it).

    Bisection on real outputs (4 strides each, the same synthesis and IK as ``scale``) between 1 and the
    ends of SPEED_SEARCH_RANGE, to SPEED_SEARCH_TOL; the ends returned were themselves produced and
    checked; then every SPEED_GRID step between x1 and each end is checked too (_walk_in), so that the
    range is one interval of factors that were all seen to meet the bars (at that spacing). About thirty
    short outputs (a few seconds on a quiet machine, minutes on a loaded one); remembered per character
    on ``prep``. For the studio's speed slider and for ``scale``'s refusals.

    stop: () -> bool, asked before each output (None: never stop); when it says True the search raises
    SearchStopped, so that a caller with something more urgent (the studio's next change) waits for one
    output at most, not the whole search. Each checked output is remembered on ``prep``, so the next run
    resumes where this one stopped (the probes are the same: the search is deterministic).
    """
    key = ("speed_range", character if isinstance(character, (str, type(None))) else id(character),
           tuple(sorted((k, v) for k, v in character_numbers.items() if v is not None)), bool(unlimited))
    hit = prep.memo.speed_ranges.get(key)
    if hit is not None:
        return hit
    rt = prep.retarget(character, **character_numbers)
    m = prep.machine.scaled(rt.L, rt.M)
    base = m.mean_speed_m_s
    top = None if unlimited else prep.kind.human_top(prep, rt)
    human_top = None if top is None else top.factor
    search = (SPEED_SEARCH_RANGE[0],
              SPEED_SEARCH_RANGE[1] if human_top is None else max(1.0, min(SPEED_SEARCH_RANGE[1], human_top)))
    probes = []
    seen = prep.memo.speed_probes.setdefault(key, {})

    def ok(s):
        s = float(s)
        if s not in seen:
            if stop is not None and stop():
                raise SearchStopped(f"speed range search for {character!r} stopped after {len(seen)} outputs")
            seen[s] = _speed_ok(prep, character, s, character_numbers, unlimited)
        good, why = seen[s]
        probes.append((s, good, why))
        return good

    if not ok(1.0):
        lo = hi = 1.0  # not even the clip's own speed meets the bars: nothing is reachable (empty range)
    else:
        ends = []
        for far in search:
            ends.append(far if ok(far) else _bisect(ok, 1.0, far))
        lo, hi = (_walk_in(ok, far, end) for far, end in zip((-1.0, 1.0), ends))
    out = SpeedRange(lo=lo, hi=hi, lo_m_s=lo * base, hi_m_s=hi * base, base_m_s=base, probes=tuple(probes),
                     empty=not probes[0][1], human_top=human_top)
    prep.memo.speed_ranges[key] = out
    prep.memo.speed_probes.pop(key, None)  # the range itself is remembered now
    return out
