"""Bending a straight output back onto the clip's path (issue 28): the machines run along a straightened
take (``body.path.straighten``), and their output's targets are rolled back onto the path, scaled.

A point of the straight output at distance a along its travel direction and offset r (sideways and up)
goes to C(a) + Rot(Δψ(a)) r, where the centreline C turns as the clip's travel line does (its COM's track
without the sway the machines put back, ``TakePath.travel_line``): Δψ(a) is the heading it has gained where
the clip's path has arc length a / L (the path scaled by L about the start; a speed change keeps
it in metres), and C is the integral of the turned travel direction. A foot's markers go rigidly with one
place (``foot_places``: on the ground its contact point's), so a planted foot stays planted and whole and
the IK in the world frame plants the feet where the map puts them; the COM's offset from the
path (its sway, its lean into the turn) is turned with the path, so the lateral dynamics are the clip's.
Before the start and past the clip's end the centreline runs straight on.
"""
from __future__ import annotations

from dataclasses import dataclass
from dataclasses import replace as _replace

import numpy as np

__all__ = ["Centreline", "bend", "bend_points", "foot_places", "lean_shift"]

from ..body.model import BodyModel
from ..body.path import TakePath, turn_about_up, yaw_carrier, yaw_quat
from ..core import quat
from ..core.constants import GRAVITY, UP, UP_AXIS
from .targets import Targets, within_reach
from .timewarp import MachinePath


@dataclass(frozen=True)
class Centreline:
    """The output's path: a_m (K,) arc length [m]; dpsi_rad (K,) heading gained there [rad] (+ = left);
    p_world (K, 3) its points (height 0) from origin; fwd0 (3,) the straight output's travel direction."""

    a_m: np.ndarray
    dpsi_rad: np.ndarray
    p_world: np.ndarray
    fwd0: np.ndarray

    @staticmethod
    def of(clip: TakePath, L: float, origin: np.ndarray, fwd0: np.ndarray) -> Centreline:
        """The clip's path scaled by L, starting at origin (3,) [m] along fwd0 (3,) (the straight output's).

        The straight output's distance a is the clip's path arc length x L (the straightened take runs at the
        speed along the path); it goes to the clip's travel line (``TakePath.travel_line``: the track whose
        stride average is the path) at that place, so the output measured as the clip was (its COM averaged
        over a stride) has the clip's path, not the path averaged twice.
        """
        heading, track_m = clip.travel_line()
        s = np.maximum.accumulate(clip.arc_length_m)
        keep = np.concatenate([[True], np.diff(s) > 0])  # strictly increasing for the interpolation
        a = L * s[keep]
        # points and offsets follow the travel line (offsets turned by the path's own heading instead, tried with
        # a sharper travel line, lagged the body's turn behind its travel: two walk-turns' giants skated 16-28 mm)
        dpsi = (heading - clip.heading_rad[0])[keep]  # fwd0 is the path's first direction
        dirs = quat.rotate(yaw_quat(dpsi), np.broadcast_to(fwd0, (a.size, 3)))
        track = L * np.maximum.accumulate(track_m)[keep]
        steps = 0.5 * (dirs[1:] + dirs[:-1]) * np.diff(track)[:, None]  # trapezoid
        p = np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)]) + origin * (1 - UP)
        return Centreline(a, dpsi, p, fwd0)

    def at(self, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(point (..., 3) [m], heading gained (...,) [rad]) at arc lengths a (...) [m], straight beyond."""
        a = np.asarray(a, float)
        dpsi = np.interp(a, self.a_m, self.dpsi_rad)
        base = np.stack([np.interp(np.clip(a, self.a_m[0], self.a_m[-1]), self.a_m, self.p_world[:, k])
                         for k in range(3)], axis=-1)
        over = a - np.clip(a, self.a_m[0], self.a_m[-1])  # < 0 before the start, > 0 past the end
        d = quat.rotate(yaw_quat(dpsi), np.broadcast_to(self.fwd0, a.shape + (3,)))
        return base + over[..., None] * d, dpsi


def bend_points(x: np.ndarray, line: Centreline, origin: np.ndarray, a: np.ndarray | None = None) -> np.ndarray:
    """(..., 3) straight-output points [m] (NaN kept) moved onto the centreline (see the module); a (...): the
    place [m] each is moved with (default its own distance along the straight travel), its offset from
    there (along and across) turned with the line's heading there."""
    rel = x - origin * (1 - UP)
    a = rel @ line.fwd0 if a is None else np.broadcast_to(a, x.shape[:-1])
    r = rel - a[..., None] * line.fwd0
    r[..., UP_AXIS] = x[..., UP_AXIS]
    finite = np.isfinite(a)
    out = np.full_like(x, np.nan)
    c, dpsi = line.at(a[finite])
    out[finite] = c * (1 - UP) + quat.rotate(yaw_quat(dpsi), r[finite])
    return out


def _clip_step_figures(clip: TakePath) -> tuple[np.ndarray, ...]:
    """Per clip step: foot (n,), arc length at touchdown (n,) [m], lean (n,) [rad] and the turn's Froude
    number v^2 / (g r) (n,) [-] (signed like the turn; 0 on a straight step)."""
    frames = np.arange(clip.arc_length_m.size)
    foot = np.array([s.foot for s in clip.steps], int)
    s_td = np.interp([s.t0_s / clip.frame_time for s in clip.steps], frames, clip.arc_length_m)
    lean = np.array([s.lean_rad for s in clip.steps])
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.array([s.heading_change_rad / s.arc_length_m if s.arc_length_m > 0 else 0.0
                          for s in clip.steps])
    fr = np.array([s.speed_m_s for s in clip.steps]) ** 2 * kappa / GRAVITY
    return foot, s_td, lean, np.nan_to_num(fr)


#: The share of a swing at each end during which a foot keeps the sideways shift of the stance it leaves
#: or reaches (its toes are near the floor there).
SWING_HOLD = 0.25


def _smooth_blend(u: np.ndarray) -> np.ndarray:
    """Smoothstep 3u^2 - 2u^3 of u clipped to [0, 1]: a swing's sideways shift starts and ends at rest."""
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def lean_shift(com: np.ndarray, markers: np.ndarray, a_com: np.ndarray, path: MachinePath, clip: TakePath, L: float,
               left0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far to move each foot sideways in the straight output [m] so that it leans into the turn as the
    clip does (issue 28, acceptance 2): per frame (T, 2) and per machine step (n,), along UP x fwd0 (+ =
    left of the straight travel).

    The machines repeat one reference stride, whose COM sways over the stance foot as on a straight walk:
    the lean into the curve (the COM inside the stance foot, tan phi = v^2 / (g r) for the mean force of a
    steady turn) is not in it. The lean is dimensionless, so dynamic similarity keeps the clip's per step:
    each output step is asked for the lean of the clip's steps of the same foot at its place along the path
    (arc length a / L; more than a stride before the clip's first step of that foot or past its last,
    the machine's stride as it is), and a speed change turns it by arctan(v'^2 / (g r')) - arctan(v^2 / (g r)) with the
    output's speed along its straight travel and the clip's radius scaled by L. A planted foot is moved by
    one amount for its whole stance (no skate); a swing goes from one amount to the next smoothly. The COM
    (the path) stays: the feet go out of the curve, as the clip's do. The move is not
    bounded: the turns of the shared walks ask up to 0.11 leg lengths under pure scaling, a faster walk or an
    erratic step (the exhausted walks) up to 0.19; a bound of 0.05-0.09 (tried) cost the lean of steady turns
    more than it saved in skating. The lean each step would have without the move is measured on the output
    bent along the line, in the frontal plane of the clip's path there (the report's): the bend itself moves
    the COM against the stance foot where the line curves between them (the COM passes the foot while the
    line turns), by more the sharper the line (``TakePath.travel_line``).
    com: (T, 3), markers: (T, 2, 3, 3) the output's COM and foot marker targets bent along the line [m];
    a_com: (T,) the COM's distance along the straight travel [m]; left0: (3,) left of the straight travel.
    """
    n = len(path.foot_of_step)
    T = len(path.times)
    shift_step = np.zeros(n)
    out = np.zeros((T, 2))
    foot_c, s_c, lean_c, fr_c = _clip_step_figures(clip)
    if n == 0 or len(foot_c) < 2 or T < 2:
        return out, shift_step
    t = path.times
    # left of the clip's path where the COM is (the report measures the lean across the output's path)
    psi = np.interp(a_com / L, np.maximum.accumulate(clip.arc_length_m), clip.heading_rad) - clip.heading_rad[0]
    left = quat.rotate(yaw_quat(psi), np.broadcast_to(left0, (T, 3)))
    for k in range(n):
        f = int(path.foot_of_step[k])
        on = (t >= path.contact_on[k]) & (t < path.contact_off[k])
        same = foot_c == f
        if on.sum() < 2 or same.sum() < 1:
            continue
        # the stance foot's contact point as the report measures it (body.gait: the mean of the foot's
        # lowest marker over the stance), here of its targets: the machine's contact point lies elsewhere
        # on the foot (2-3 cm sideways on the Bandai walks)
        mk = markers[on, f]  # (n_on, 3, 3)
        low = mk[np.arange(mk.shape[0]), np.argmin(mk[:, :, UP_AXIS], axis=1)]
        if not np.isfinite(low).all():
            continue
        d = com[on] - low.mean(axis=0)
        h = float(np.mean(d[:, UP_AXIS]))
        if not h > 0:
            continue
        pred = float(np.mean(np.arctan2(np.einsum("ij,ij->i", d, left[on]), d[:, UP_AXIS])))
        s_k = float(np.interp(path.contact_on[k], t, a_com)) / L  # the clip's arc length here [m]
        # before the clip's first step of this foot or past its last by more than a stride: the machine's
        # stride as it is; within one stride, the end step's (the report may place a step a little differently)
        reach = float(np.median(np.diff(s_c[same]))) if same.sum() > 1 else 0.0
        if not s_c[same][0] - reach <= s_k <= s_c[same][-1] + reach:
            continue
        want = float(np.interp(s_k, s_c[same], lean_c[same]))
        # a speed change at the same (scaled) radius: the lean follows tan phi = v^2 / (g r)
        i_on = np.flatnonzero(on)
        dur = t[i_on[-1]] - t[i_on[0]]
        v_out = (a_com[i_on[-1]] - a_com[i_on[0]]) / dur if dur > 0 else 0.0
        fr = float(np.interp(s_k, s_c, fr_c))
        v_clip = float(np.interp(s_k, s_c, [s.speed_m_s for s in clip.steps]))
        if v_clip > 0 and v_out > 0:
            ratio = v_out**2 / (L * v_clip**2)
            want += float(np.arctan(fr * ratio) - np.arctan(fr))
        # the foot goes right (against left0) to put the COM further left of it
        shift_step[k] = -h * (np.tan(want) - np.tan(pred))
    return _per_frame(path, shift_step), shift_step


def foot_places(path: MachinePath, markers: np.ndarray, origin: np.ndarray, fwd0: np.ndarray) -> np.ndarray:
    """(T, 2) the place along the straight travel [m] with which each foot's markers are bent (``bend_points``).

    A foot is bent as one rigid piece. On the ground it goes with its contact point, one place for the whole
    contact: its markers that stay stay, and the heel rises about the toes as in the straight output. Bent
    marker by marker instead, a planted foot was stretched and turned where the line curves under it (heel and
    toes 0.25 L apart, up to 16 degrees of the line's turn between them in a sharp turn), the IK could not
    fit it, and the toes of planted feet slid 5-12 mm (the outputs of 4 of the shared walk-turns, at the
    line of ``TakePath.travel_line``). In the air it goes with its own centre (the mean of its markers'
    places), from and to its contact places over the first and last SWING_HOLD of the swing (smoothstep).
    markers: (T, 2, 3, 3) the straight output's foot marker targets [m]; origin, fwd0: (3,).
    """
    t = path.times
    a_centre = np.nanmean((markers - origin * (1 - UP)) @ fwd0, axis=2)  # (T, 2)
    a_contact = _per_frame(path, (path.contacts - origin * (1 - UP)) @ fwd0)  # (T, 2), one per contact
    on_ground = np.ones((len(t), 2))  # the contact's share of the place
    for f in (0, 1):
        ks = np.flatnonzero(path.foot_of_step == f)
        if ks.size == 0:
            on_ground[:, f] = 0.0
            continue
        for j in range(ks.size - 1):
            off, on = path.contact_off[ks[j]], path.contact_on[ks[j + 1]]
            sw = (t >= off) & (t < on)
            u = (t[sw] - off) / max(on - off, 1e-9)
            on_ground[sw, f] = 1.0 - _smooth_blend(np.minimum(u, 1.0 - u) / SWING_HOLD)
        on_ground[(t < path.contact_on[ks[0]]) | (t >= path.contact_off[ks[-1]]), f] = 0.0
    return on_ground * a_contact + (1.0 - on_ground) * a_centre


def _per_frame(path: MachinePath, shift_step: np.ndarray) -> np.ndarray:
    """(T, 2) each foot's sideways move [m] per frame from its steps' (n,): one amount over a stance, a
    smooth change over the middle of the swing to the next stance of that foot."""
    t = path.times
    out = np.zeros((len(t), 2))
    for f in (0, 1):
        ks = np.flatnonzero(path.foot_of_step == f)
        if ks.size == 0:
            continue
        on, off, dx = path.contact_on[ks], path.contact_off[ks], shift_step[ks]
        col = np.full(len(t), dx[0])
        for j in range(ks.size):
            col[t >= on[j]] = dx[j]
            if j + 1 < ks.size:  # the swing to the next stance of this foot
                # over the middle half of the swing: the heel and toes leave and reach the floor where they
                # are (a sideways move as the toes push off or touch down would skate them)
                sw = (t >= off[j]) & (t < on[j + 1])
                span = on[j + 1] - off[j]
                u = (t[sw] - off[j] - SWING_HOLD * span) / max((1.0 - 2.0 * SWING_HOLD) * span, 1e-9)
                col[sw] = dx[j] + (dx[j + 1] - dx[j]) * _smooth_blend(u)
        out[:, f] = col
    return out


def bend(targets: Targets, path: MachinePath, clip: TakePath | None, L: float,
         origin: np.ndarray, body: BodyModel, order: str) -> tuple[Targets, MachinePath]:
    """The straight output's IK targets and machine path rolled onto the clip's path scaled by L (as they are
    when clip is None: a straight take, modelled as it is).

    COM, foot markers, the machine's COM and contact points are moved point by point; the initial motion's
    pose (the IK's start and the pose it is pulled toward) is moved rigidly with its COM target, turned
    by the heading gained there; the foot targets are then kept within the legs' reach of the turned pose
    (``targets.within_reach``; body: the character's; order: the cycle's, a walk's reach rule for
    "walking"). origin: (3,) [m] where the straight output starts (``Prepared.origin``).
    """
    if clip is None:
        return targets, path
    fwd0 = path.frame[0]
    left0 = np.cross(UP, fwd0)
    line = Centreline.of(clip, L, origin, fwd0)
    a_com = (targets.com - origin * (1 - UP)) @ fwd0  # (T,) the COM's distance along the straight travel [m]
    com = bend_points(targets.com, line, origin)
    # each foot's markers moved rigidly, with the line at the foot's place (foot_places)
    a_feet = foot_places(path, targets.markers, origin, fwd0)[:, :, None]  # (T, 2, 1)
    markers = bend_points(targets.markers, line, origin, a_feet)
    shift, shift_step = lean_shift(com, markers, a_com, path, clip, L, left0)
    # a foot moved sideways in the straight output is moved so, turned with the line at the foot's place
    _, dpsi_feet = line.at(a_feet)
    markers = markers + shift[:, :, None, None] * quat.rotate(yaw_quat(dpsi_feet), left0)
    # the pose moved rigidly with its COM target: turned by the heading gained there, about it (a rig's root
    # may lie far from the body: Bandai's joint_Root, 2.4 m ahead of the COM in a straightened turn), at the
    # joint the straightening turned (``body.path.yaw_carrier``)
    init = targets.initial
    _, dpsi = line.at(a_com)
    q = yaw_quat(dpsi)
    initial = turn_about_up(init, q, com + quat.rotate(q, init.root_positions - targets.com), yaw_carrier(init))
    forward = quat.rotate(q, np.broadcast_to(fwd0, (len(dpsi), 3)))
    markers = within_reach(initial, markers, body, forward, walking=order == "walking")
    new_targets = _replace(targets, com=com, markers=markers, initial=initial)
    new_path = _replace(path, com=bend_points(path.com, line, origin),
                        contacts=bend_points(path.contacts + shift_step[:, None] * left0, line, origin))
    return new_targets, new_path


