"""A clip's foot events and the stride phase they give: touchdowns and liftoffs (from the markers' contacts,
the load, or the fit's force-refined times), the order of the four events in a running or a walking stride,
and the mean durations between them. ``synthesis.cycle`` phases every frame of the clip by them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..body.com_force import vertical_force_bw
from ..body.gait import Gait
from ..core.motion import Motion
from ..errors import FitError
from ..machine.forces import _crossing


@dataclass(frozen=True)
class FootEvent:
    """A foot event in reference frames (fractional allowed): kind 'td' (touchdown) or 'lo' (liftoff)."""

    frame: float
    foot: int
    kind: str


def events_from_gait(gait: Gait) -> list[FootEvent]:
    """Touchdowns and liftoffs of a gait, in time order (edges of partial stances omitted)."""
    F = len(gait.contact)
    ev = []
    for s in gait.stances:
        if s.start > 0:
            ev.append(FootEvent(float(s.start), s.foot, "td"))
        if s.stop < F:
            ev.append(FootEvent(float(s.stop), s.foot, "lo"))
    return sorted(ev, key=lambda e: e.frame)


#: The order of the four foot events in one stride, as (foot, kind) with foot 0 = A (the first to touch
#: down), 1 = B. Running: A lands, A lifts, B lands, B lifts (a flight between the stances). Walking: A
#: lands, B lifts, B lands, A lifts (two double supports, each foot's stance overlapping the other's).
EVENT_ORDERS = {
    "running": ((0, "td"), (0, "lo"), (1, "td"), (1, "lo")),
    "walking": ((0, "td"), (1, "lo"), (1, "td"), (0, "lo")),
}


def _order_of(order: str):
    if order not in EVENT_ORDERS:
        raise FitError(f"unknown event order {order!r} (running or walking)")
    return EVENT_ORDERS[order]


def event_phases(order: str, fractions: np.ndarray) -> np.ndarray:
    """(4,) stride phases of [touchdown A, liftoff A, touchdown B, liftoff B] from the phases (3,) of the
    second, third and fourth events of the stride in ``order`` (the first, A's touchdown, is 0)."""
    out = np.zeros(4)
    slot = {(0, "td"): 0, (0, "lo"): 1, (1, "td"): 2, (1, "lo"): 3}
    for (foot, kind), ph in zip(_order_of(order)[1:], fractions):
        out[slot[(foot, kind)]] = ph
    return out


def phase_of_events(events: list[FootEvent], first_foot: int, fractions: np.ndarray,
                     order: str = "running") -> np.ndarray:
    """Unwrapped stride phase ψ of each event (ψ increases by 1 per stride; first A touchdown = 0)."""
    pe = event_phases(order, fractions)
    base = {(first_foot, "td"): 0.0, (first_foot, "lo"): pe[1],
            (1 - first_foot, "td"): pe[2], (1 - first_foot, "lo"): pe[3]}
    values: list[float] = []
    for e in events:
        p = base[(e.foot, e.kind)]
        if values:
            prev = values[-1]
            p = p + np.ceil(prev - p + 1e-9)  # smallest value ≡ p (mod 1) after prev
        values.append(p)
    psi = np.array(values)
    first_a_td = next(i for i, e in enumerate(events) if e.foot == first_foot and e.kind == "td")
    return psi - np.floor(psi[first_a_td] + 1e-9)


def stride_durations(events: list[FootEvent], first_foot: int, frame_time: float, order: str = "running") -> np.ndarray:
    """Mean reference durations [s] between consecutive events of the stride in ``order`` (running: stance
    A, flight after A, stance B, flight after B; walking: double support after A lands, single support on
    A, double support after B lands, single support on B)."""
    seq = [((first_foot if f == 0 else 1 - first_foot), k) for f, k in _order_of(order)]
    sums: dict[int, list[float]] = {k: [] for k in range(4)}
    for e0, e1 in zip(events[:-1], events[1:]):
        dt = (e1.frame - e0.frame) * frame_time
        i = seq.index((e0.foot, e0.kind))
        if seq[(i + 1) % 4] == (e1.foot, e1.kind):
            sums[i].append(dt)
    out = np.full(4, np.nan)
    for k, v in sums.items():
        if v:
            out[k] = np.mean(v)
    # a phase seen only for one foot stands in for the other foot's
    for k, twin in ((0, 2), (1, 3), (2, 0), (3, 1)):
        if np.isnan(out[k]):
            out[k] = out[twin]
    if np.any(np.isnan(out)) or np.any(out <= 0):
        raise FitError(f"cannot find the four phases of a {order} stride to build a stride cycle from")
    return out


def fit_events(machine, motion: Motion):
    """The fit's force-refined touchdown/liftoff times as foot events (None: they do not alternate)."""
    ev = []
    for s in getattr(machine, "stances", ()):
        foot = 0 if s.get("foot") in (0, "left") else 1
        for key, kind in (("t_touchdown_s", "td"), ("t_liftoff_s", "lo")):
            t = s.get(key)
            if t is not None and np.isfinite(t) and 0 < t < motion.duration:
                ev.append(FootEvent(t / motion.frame_time, foot, kind))
    return _alternating(ev)


def _alternating(ev: list[FootEvent]) -> list[FootEvent] | None:
    """The events sorted in time if touchdowns and liftoffs alternate (a running order), else None."""
    ev = sorted(ev, key=lambda e: e.frame)
    for a, b in zip(ev[:-1], ev[1:]):
        if a.kind == b.kind:
            return None
    return ev or None


#: How far outside a foot's marker contact its load may cross the fit's event threshold [s] (loaded_events).
LOADED_EVENT_SEARCH_S = 0.15


def loaded_events(gait: Gait, com: np.ndarray, frame_time: float) -> list[FootEvent] | None:
    """Foot events where each contact's load crosses the fit's EVENT_THRESHOLD_BW (0.5 body weights): the
    rising crossing nearest the marker touchdown and the falling one nearest the marker lift-off, searched
    within the contact and up to LOADED_EVENT_SEARCH_S outside it (None: they do not alternate).

    For a clip whose feet rest on the floor, barely loaded, long before the load rises and after it falls
    (the tired Bandai jog: loaded 0.23-0.30 s of 0.33-0.50 s contacts, the load falling 0.25 s before the
    toe leaves), the fit's events keep some marker events and do not alternate. The cycle must still be
    phased by the load: the machine's stance is the loaded one, so the clip's loaded poses must fall in it
    and its unloaded ones (nearly ballistic, as in the machine's flight) in the flight, where the marker
    contact (contact_phase) still holds the feet down. Phased by the marker contacts instead, the machine's
    0.17 s flight played the clip's 0.03-0.08 s flights and its grounded poses fell in the air: knee flips
    of 47-90° against the clip's 25°. gait: the clip's marker contacts; com: (F, 3) [m]; frame_time [s].
    """
    fy_bw = vertical_force_bw(com, frame_time)
    w = int(round(LOADED_EVENT_SEARCH_S / frame_time))
    ev = []
    for s in gait.stances:
        td = None if s.start == 0 else _crossing(fy_bw, s.start - w, s.stop, True, s.start - 0.5)
        lo = None if s.stop >= len(fy_bw) else _crossing(fy_bw, s.start, s.stop + w, False, s.stop - 0.5)
        ev += [FootEvent(x, s.foot, kind) for x, kind in ((td, "td"), (lo, "lo")) if x is not None]
    return _alternating(ev)
