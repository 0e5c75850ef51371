"""The reference cycle's feet: how high each foot marker rests in the clip's stances, when each foot is on
the ground in the cycle, its anchor (the stance's contact point, or a minimum-jerk blend between contacts),
and the de-skating that holds a loaded marker still (a run's markers each; a walk's rolling foot one pivot
at a time) while the foot's bones keep their lengths.
"""
from __future__ import annotations

import math

import numpy as np

from ..body.footing import SKATE_REACH_L, floor_height, stance_rest_heights
from ..body.gait import Gait
from ..core.constants import UP_AXIS

#: A loaded foot marker of a run is held still while within this fraction of the leg length of its lowest
#: point: wider than the physics report's 0.02 L (SKATE_BAND_L) because the output's lowest point is not the
#: cycle's (frames fall between cycle samples, the stance is time-warped): at 0.022 L a giant's tip was let
#: go 0.0197 L above the output's lowest point and slid 6.8 mm within the report's band (02_03).
SLIDE_BAND_L = 0.026
#: The band of a walk's rolling pivot (remove_sliding_rolling), as tuned on the walks (the running hold's
#: band above was widened after).
ROLL_BAND_L = 0.022
#: The ball and tip of a run are held if they come within the report's reach plus this fraction of L
#: (extract_cycle).
HOLD_REACH_MARGIN_L = 0.01


def min_jerk(u: np.ndarray) -> np.ndarray:
    """Minimum-jerk progress 10u³ − 15u⁴ + 6u⁵ on [0, 1] (zero velocity and acceleration at both ends)."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10.0 - 15.0 * u + 6.0 * u**2)


def rest_above(gait: Gait, markers: np.ndarray, leg_length: float, ground: float) -> tuple[float, np.ndarray]:
    """How far ``ground`` [m] is above the clip's floor, and how high each foot marker rests in the clip's
    stances above ``ground`` (2, 3) [m] (NaN without a whole stance of that foot).

    The floor and the rest heights are the clip's as the physics report defines them (``body.footing.floor_height``,
    ``body.footing.stance_rest_heights``: the definition of what an output must match, measured here on the clip
    only; the report measures the output by itself). markers: (F, 2, 3, 3) [m].
    """

    floor, _ = floor_height(markers, gait, leg_length)
    if not np.isfinite(floor):
        return 0.0, np.full((2, 3), np.nan)
    rest, _ = stance_rest_heights(markers, gait, floor)
    return float(ground - floor), rest - (ground - floor)


def contact_phases(marker_rel: np.ndarray, phase_events: np.ndarray, first_foot: int, contact_tol: float,
                    max_extension: float = 0.15) -> np.ndarray:
    """(2, 2) [on, off] stride phases of each foot's ground contact.

    The machine's force-based stance, extended before touchdown and after liftoff for as long as some
    marker of the foot stays within ``contact_tol`` of the ground in the cycle (the force crosses its
    threshold a little after the foot lands and before the toe leaves; the foot must stay pinned for all
    of that). marker_rel: (K, 2, 3, 3) cycle marker offsets (heading frame, heights above the ground).
    Extensions are capped at ``max_extension`` of a stride. Unwrapped: on < off.
    """
    K = marker_rel.shape[0]
    low = marker_rel[..., 1].min(axis=2) <= contact_tol  # (K, 2)
    td = {first_foot: 0.0, 1 - first_foot: phase_events[2]}
    # a walk's B stance wraps around φ = 0 (B lifts after A lands): unwrap it so that on < off
    lo_b = phase_events[3] if phase_events[3] > phase_events[2] else phase_events[3] + 1.0
    lo = {first_foot: phase_events[1], 1 - first_foot: lo_b}
    cap = int(max_extension * K)
    out = np.zeros((2, 2))
    for foot in range(2):
        i_on = int(np.floor(td[foot] * K))
        i_off = int(np.ceil(lo[foot] * K))
        n_before = 0
        while n_before < cap and low[(i_on - n_before - 1) % K, foot]:
            n_before += 1
        n_after = 0
        while n_after < cap and low[(i_off + n_after) % K, foot]:
            n_after += 1
        out[foot] = (td[foot] - n_before / K, lo[foot] + n_after / K)
    return out


def contact_mask(phi: np.ndarray, contact_phase: np.ndarray) -> np.ndarray:
    """(…, 2) bool marker contact of each foot at stride phases phi (…)."""
    p = np.mod(phi, 1.0)[..., None]
    on, off = contact_phase[:, 0], contact_phase[:, 1]
    return (np.mod(p - on, 1.0) < (off - on))


def swing_anchor(psi, psi_off, psi_on, c_off, c_on) -> tuple[np.ndarray, np.ndarray]:
    """The one foot-anchor rule of a swing (the reference cycle's and the output's IK targets): the anchor
    moves from the contact left (c_off, (3,) or (n, 3) [m]) to the next one (c_on) with min-jerk progress in
    stride phase, u = (ψ − ψ_off)/(ψ_on − ψ_off). psi (n,): the frames' phases; psi_off / psi_on: the
    phases of the liftoff and of the next touchdown (scalars or (n,)). Returns (anchor (n, 3) [m], u (n,)).
    """
    u = (psi - psi_off) / np.maximum(psi_on - psi_off, 1e-9)
    w = min_jerk(u)[:, None]
    return c_off * (1 - w) + c_on * w, u


def foot_anchors(gait: Gait, psi: np.ndarray, stride: np.ndarray, F: int, subframe: bool = False):
    """Anchor point of each foot per frame (F, 2, 3) [m] and whether it is known (F, 2).

    In stance the anchor is the stance's contact point (on its ground); in swing it moves from the
    previous contact to the next one with min-jerk progress in stride phase. A swing cut by the clip's
    edge gets a virtual contact one stride (``stride`` (3,) [m], horizontal) before the first or after
    the last contact of that foot, one stride phase earlier or later: the cycle is periodic.

    subframe: a swing runs from the stance's sub-frame liftoff to the next sub-frame touchdown
    (``Stance.t_off``, ``t_on``) rather than from its first frame off the ground to its first frame on it.
    An output's anchor swings between the machine's events, and a walking machine's events are the gait's
    sub-frame ones: a reference anchor that set off and arrived half a frame later on average left that
    half frame of anchor motion in the cycle's foot offsets, and the output's foot, its anchor already
    arrived, slowed to a stop 0.3 frames before its planned touchdown (walk_elderly_001 scaled to itself:
    stances 16 ms longer than the machine's, double support +3 points of the cycle).
    """
    anchors = np.zeros((F, 2, 3))
    ok = np.zeros((F, 2), bool)
    frames = np.arange(F)
    for foot in range(2):
        st = [s for s in gait.stances if s.foot == foot]
        if not st:
            continue
        pts, psi_on, psi_off = [], [], []
        for s in st:
            c = s.contact_point.copy()
            c[UP_AXIS] = s.ground
            pts.append(c)
            anchors[s.start : s.stop, foot] = c
            ok[s.start : s.stop, foot] = True
            a = s.t_on if subframe and s.start > 0 and np.isfinite(s.t_on) else s.start
            b = s.t_off if subframe and s.stop < F and np.isfinite(s.t_off) else min(s.stop, F - 1)
            psi_on.append(float(np.interp(a, frames, psi)))
            psi_off.append(float(np.interp(b, frames, psi)))
        # virtual neighbours (a stance cut at the edge has an unknown start or end: use its known end)
        pts = [pts[0] - stride] + pts + [pts[-1] + stride]
        psi_off = [psi_off[0] - 1.0] + psi_off + [psi_off[-1] + 1.0]
        psi_on = [psi_on[0] - 1.0] + psi_on + [psi_on[-1] + 1.0]
        bounds = [(-10**9, 0)] + [(s.start, s.stop) for s in st] + [(F + 10**9, F + 10**9)]
        for j in range(len(bounds) - 1):
            a, b = bounds[j][1], bounds[j + 1][0]
            sel = (frames >= max(a, 0)) & (frames < min(b, F))
            if not sel.any():
                continue
            anchors[sel, foot], _ = swing_anchor(psi[sel], psi_off[j], psi_on[j + 1], pts[j], pts[j + 1])
            ok[sel, foot] = True
    return anchors, ok


#: Per-sample relaxation of an unloaded marker's own de-skating correction toward the foot's common one.
RELAX = 0.2
#: Fraction of a tilt's rise a marker keeps from one cycle sample to the next once the tilt is over.
TILT_RELAX = 0.5


# Long because the per-sample correction δ runs forward through a stance, each sample's depending on the
# previous one's loaded markers, and then fades over the swing: one sequential pass per foot.
def remove_sliding(rel: np.ndarray, stance: np.ndarray, contact_tol: float | np.ndarray,
                    band: float) -> np.ndarray:
    """Remove the reference's foot sliding in stance by translating each foot rigidly.

    rel: (K, 2, 3, 3) marker offsets from the anchor (heading frame: forward, up, lateral).
    A marker that reaches within contact_tol (scalar or per marker (3,)) [m] of the ground in a stance is
    loaded while it is within ``band`` of its own lowest point of that stance (joint centres sit a sole's
    thickness above the floor). The three markers of a foot move together by one horizontal correction δ(φ)
    (so the foot keeps the reference's shape and orientation, which IK can then meet exactly): from one
    sample to the next δ cancels the mean motion of the markers loaded at both, so loaded points stay put
    and δ stays continuous. After the stance δ fades out over the swing (min-jerk), so the cycle still
    closes. Heights are clamped to ≥ 0.
    """
    out = rel.copy()
    K = rel.shape[0]
    firm = np.zeros(rel.shape[:3])  # (K, 2, 3) how firmly each marker is held (for the bones)
    in_place = np.zeros(rel.shape[:3], bool)  # (K, 2, 3) markers held in place (loaded in a stance)
    for foot in range(2):
        idx = _stance_in_time(stance[:, foot])  # the stance may wrap around φ = 0
        if idx.size == 0:
            continue
        idx = _with_approach(rel[:, foot], idx, stance[:, foot], contact_tol, band)
        h = rel[idx, foot][:, :, [0, 2]]  # (n, 3 markers, 2) horizontal offsets
        height = rel[idx, foot, :, 1]  # (n, 3) above the ground
        h_min = height.min(axis=0)
        # a marker bears load while near its own lowest point of the stance (joint centres sit a sole's
        # thickness above the floor) and only if it reaches the floor at all
        reaches = h_min <= contact_tol
        loaded = (height <= h_min + band) & reaches
        # a marker is held in place from its first to its last loaded sample, rises in between included: a tip
        # that lifts a little and comes down again may not have moved (the report sees it back on the floor;
        # 02_03, 09_06 at 1.3x)
        span = loaded.copy()
        for m in range(3):
            on = np.flatnonzero(loaded[:, m])
            if on.size:
                span[on[0] : on[-1] + 1, m] = True
        # δ changes by minus the (weighted) mean motion of the markers loaded at both neighbouring samples,
        # so the loaded points stay put and δ is continuous whatever markers load and unload (a
        # re-averaging of held positions would jump); markers pressed deeper (nearer their lowest point)
        # count more, so the point that carries the foot stays put and a lightly touching one gives way
        depth = np.clip(1.0 - (height - h_min) / band, 0.0, 1.0) ** 4
        firm[idx, foot] += depth * reaches
        in_place[idx, foot] = span
        wgt = (loaded[1:] & loaded[:-1]) * 0.5 * (depth[1:] + depth[:-1])  # (n-1, 3)
        step = h[1:] - h[:-1]  # (n-1, 3, 2)
        w_sum = wgt.sum(axis=1, keepdims=True)
        mean_step = np.where(w_sum > 0, (step * wgt[..., None]).sum(axis=1) / np.maximum(w_sum, 1e-12), 0.0)
        delta = np.concatenate([np.zeros((1, 2)), -np.cumsum(mean_step, axis=0)])  # common (rigid) part
        # Each marker then gets its own correction: while it is held it cancels its own motion exactly
        # (two loaded points that move relative to each other both stay put; IK bends the toe joint to
        # match); while unloaded it relaxes back to the common one, so the foot keeps its shape in the air.
        # A released marker relaxes only once it is clearly off the floor (above band, fully at 2 bands): a
        # tip that yawed with the foot and was held would otherwise swing back sideways while still within
        # the height at which the physics report watches it slide.
        # Each sample is given its bone lengths back (_rigid_foot's rule) before the next one holds its
        # points, so what is held is a pose the foot can take (_hold_stance).
        rate = RELAX * np.clip((height - h_min - band) / band, 0.0, 1.0)  # (n, 3)
        own, lift = _hold_stance(rel[idx, foot], step, span[1:], rate, delta, _bone_lengths(rel[:, foot]),
                                 firm[idx, foot], in_place[idx, foot])
        d = delta[-1]
        out[idx, foot, :, 0] += own[..., 0]
        out[idx, foot, :, 1] += lift
        out[idx, foot, :, 2] += own[..., 1]
        rest = own[-1] - d  # what remains of the markers' own corrections at the end of the stance
        covered = np.zeros(K, bool)
        covered[idx] = True
        swing = np.flatnonzero(~covered)
        if swing.size:
            start = (idx[-1] + 1) % K
            order = (np.arange(swing.size) + np.searchsorted(swing, start)) % swing.size
            sw = swing[order]
            fade = 1.0 - min_jerk(np.linspace(0, 1, sw.size))
            corr = (d[None, :] + rest)[None] * fade[:, None, None]  # (n_sw, 3, 2)
            out[sw, foot, :, 0] += corr[..., 0]
            out[sw, foot, :, 1] += lift[-1][None, :] * fade[:, None]  # a tilt's rise fades with them
            out[sw, foot, :, 2] += corr[..., 1]
    out[..., 1] = np.maximum(out[..., 1], 0.0)
    return _keep_feet_rigid(out, rel, firm, in_place)


def _stance_in_time(stance_foot: np.ndarray) -> np.ndarray:
    """The samples (K,) of one foot's stance in time order (a stance may wrap around φ = 0)."""
    idx = np.flatnonzero(stance_foot)
    if idx.size and stance_foot[0] and stance_foot[-1]:
        gap = np.flatnonzero(np.diff(idx) > 1)
        if gap.size:
            idx = np.concatenate([idx[gap[0] + 1 :], idx[: gap[0] + 1]])
    return idx


def remove_sliding_rolling(rel: np.ndarray, stance: np.ndarray, contact_tol: float,
                            band: float) -> np.ndarray:
    """Remove the reference's foot sliding from a walk's stances: the foot rolls over one pivot at a time.

    rel: (K, 2, 3, 3) marker offsets from the anchor (heading frame: forward, up, lateral); stance: (K, 2).
    A walking foot rolls from the heel over the ball onto the toe, and the reference's markers, held each
    on its own as remove_sliding does for a run, contradict each other while it rolls: a toe segment
    pitching up over its tip moves the ball forward, so a held ball and a held tip flattened the toes
    under a rising heel and let them spring back at lift-off (toe joint jumps of 35-54 deg on 07_01). Here
    the three markers of a foot move together, by one rigid motion per sample (``_rolling_correction``:
    the foot keeps the reference's shape, so the IK meets it with the reference's joint angles) that holds
    the current pivot still; after the stance the motion fades over the swing (min-jerk) so the cycle
    closes. Heights are clamped to ≥ 0.
    """
    bones = [_bone_lengths(rel[:, foot]) for foot in range(2)]
    rel = np.stack([_with_bone_lengths(rel[:, foot], bones[foot]) for foot in range(2)], axis=1)
    out = rel.copy()
    K = rel.shape[0]
    for foot in range(2):
        idx = _stance_in_time(stance[:, foot])
        if idx.size == 0:
            continue
        # the landing foot is held from when it is low; the lifting one until the stance ends (it is raised
        # clear by then)
        idx = _with_approach(rel[:, foot], idx, stance[:, foot], contact_tol, band, with_after=False)
        yaw, shift, lift, level = _rolling_correction(rel[idx, foot], contact_tol, band,
                                                      max(1, int(LIFT_OFF_SHARE * K)))
        out[idx, foot] = _moved(rel[idx, foot], yaw, shift, lift)
        covered = np.zeros(K, bool)
        covered[idx] = True
        swing = np.flatnonzero(~covered)
        if swing.size:
            start = (idx[-1] + 1) % K
            sw = swing[(np.arange(swing.size) + np.searchsorted(swing, start)) % swing.size]
            fade = 1.0 - min_jerk(np.linspace(0, 1, sw.size))
            out[sw, foot] = _moved(rel[sw, foot], yaw[-1] * fade, shift[-1] * fade[:, None],
                                   lift[-1] * fade + level * (1.0 - fade))
    out[..., 1] = np.maximum(out[..., 1], 0.0)
    return out


def _with_bone_lengths(foot: np.ndarray, length: np.ndarray) -> np.ndarray:
    """One foot's markers (N, 3, 3) [m] with the foot's bones (ankle-ball, ball-tip) at the lengths ``length``
    (3, 3) [m] along their own directions, about the ball (the averaged cycle's bones change length by a few
    millimetres: a foot held at one point would slide at the others)."""
    out = foot.copy()
    for k in (0, 2):
        v = foot[:, k] - foot[:, 1]
        out[:, k] = foot[:, 1] + v * (length[1, k] / np.maximum(np.linalg.norm(v, axis=-1), 1e-12))[:, None]
    return out


def _moved(seg: np.ndarray, yaw: np.ndarray, shift: np.ndarray, lift: np.ndarray) -> np.ndarray:
    """seg (n, m, 3) (heading frame: forward, up, lateral) turned by yaw (n,) [rad] about the up axis through
    the origin, then moved by shift (n, 2) [m] (forward, lateral) and lift (n,) [m] (up)."""
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    out = seg.copy()
    out[..., 0] = c * seg[..., 0] - s * seg[..., 2] + shift[:, None, 0]
    out[..., 2] = s * seg[..., 0] + c * seg[..., 2] + shift[:, None, 1]
    out[..., 1] = seg[..., 1] + lift[:, None]
    return out


#: The pivot of a rolling foot passes to a marker nearer the toes once that marker is this fraction of the
#: holding band nearer its own lowest point than the pivot is to its own (hysteresis against mocap noise).
ROLL_SWITCH_BAND = 0.1
#: Per-sample relaxation of a rolling foot's held yaw back to the reference's once only its pivot is down.
YAW_RELAX = 0.2
#: Share of the stride over which a walking foot's pivot is raised to the top of the floor band by the end
#: of its stance (_rolling_correction): 0.04 left the ball sliding 6-7 mm on 02_01's and 07_01's giants as
#: the toe pitched over its tip; raised earlier, the ball leaves the band before the toe has pitched far.
LIFT_OFF_SHARE = 0.08


# Long because the rigid motion of each sample depends on the previous one's (held pivot, held yaw): one
# sequential pass over the ~120 samples of a stance.
def _rolling_correction(seg: np.ndarray, contact_tol: float, band: float, n_rise: int):
    """The rigid motion per sample of a walking stance that holds the foot's pivot still.

    seg: (n, 3 markers, 3) one foot's marker offsets over the stance in time order (heading frame; markers
    from the heel end: ankle, ball, tip). A marker
    that reaches the floor (its lowest point within contact_tol) bears load while within ``band`` of its
    lowest point. The pivot is the loaded marker that has risen least since its own lowest point so far
    (by more than a tenth of the band: hysteresis), and it only moves toward the toes (a walking foot rolls
    heel → ball → toe). The pivot is held horizontally where it is. While another marker is within two bands
    of its lowest point, the foot's yaw is held (the reference's foot turns a few degrees about its toe while
    the ball is still low, and its toes yaw while they come down: either slid sideways within the report's
    band); otherwise the yaw relaxes back to the reference's. Vertically the first pivot (the landing one)
    comes down to its lowest height so far and stays there; a later pivot keeps its height (the CMU toe end
    site sinks 1-2 cm while the toes pitch up over it, a mocap end site, not a contact: following it down
    would slide the rising ball forward within the band). Over the last n_rise samples of the stance the
    pivot is raised (min-jerk) to ``band`` above its height then, or onto the reference's own path where
    that is higher, so the foot leaves the floor band when the reference's foot lifts (held until it was
    clear, the foot stayed down 40-50 ms longer than the clip's, whose toe scuffs forward at lift-off, and
    the double support grew by up to 9 points).
    The foot lands and leaves at its held stance's level (``_contact_level``, returned as level [m]).
    Returns yaw (n,) [rad], shift (n, 2) [m] (forward, lateral), lift (n,) [m] for ``_moved``, and level.
    """
    n = seg.shape[0]
    height = seg[:, :, 1]
    h_min = height.min(axis=0)
    rise = np.where(h_min <= contact_tol, height - h_min, np.inf)  # (n, 3) unloaded: never a pivot
    yaw, shift, lift = np.zeros(n), np.zeros((n, 2)), np.zeros(n)
    pivot, first = -1, -1
    lowest = np.inf  # the landing pivot: its reference's lowest height so far
    low_so_far = np.minimum.accumulate(height, axis=0)  # (n, 3) each marker's lowest height up to sample i
    for i in range(n):
        loaded = np.flatnonzero(rise[i] <= band)
        later = loaded[loaded > pivot] if pivot >= 0 else loaded
        if later.size:
            up = height[i] - low_so_far[i]  # (3,) risen since each marker's lowest so far
            k = int(later[np.argmin(up[later])])
            if pivot < 0 or up[k] + ROLL_SWITCH_BAND * band < up[pivot]:
                pivot = k
                first = k if first < 0 else first
        if pivot < 0 or i == 0:
            continue
        near = np.flatnonzero(rise[i] <= 2.0 * band)  # near the floor: its lowest in the output may be higher
        others = near[near != pivot]
        if others.size:  # the yaw of the line from the pivot to the farthest other low marker is held
            q = int(others[np.argmax(np.abs(others - pivot))])
            a, b = (seg[j, q, [0, 2]] - seg[j, pivot, [0, 2]] for j in (i - 1, i))
            yaw[i] = yaw[i - 1] - (np.arctan2(b[1], b[0]) - np.arctan2(a[1], a[0]) + np.pi) % (2 * np.pi) + np.pi
        else:
            yaw[i] = (1.0 - YAW_RELAX) * yaw[i - 1]
        # the pivot where it was: its previous position moved as then, less its new position turned as now
        was = _moved(seg[i - 1 : i, pivot : pivot + 1], yaw[i - 1 : i], shift[i - 1 : i], lift[i - 1 : i])[0, 0]
        now = _moved(seg[i : i + 1, pivot : pivot + 1], yaw[i : i + 1], np.zeros((1, 2)), np.zeros(1))[0, 0]
        shift[i] = was[[0, 2]] - now[[0, 2]]
        y = seg[i, pivot, 1]
        lift[i] = lift[i - 1]
        if pivot == first:  # the landing pivot comes down to its lowest height so far, then stays there
            lowest = min(lowest, y)
            lift[i] = lowest - y
        else:  # a later pivot stays at its height until the foot lifts
            lift[i] = lift[i - 1] - (y - seg[i - 1, pivot, 1])
    level = 0.0
    if pivot >= 0:
        level = _contact_level(seg, lift, rise, band, n_rise)
        # raised to the top of its floor band by the end of the stance (min-jerk) ...
        a = max(1, n - n_rise)
        u = min_jerk((np.arange(a, n) - a + 1) / (n - a))
        raw = seg[a:, pivot, 1]
        held = raw + lift[a:]
        # ... or onto the reference's own path (at the contact's level) where that is higher, which it then
        # leaves with the reference's height and speed (a step onto a plateau at the band's top held the
        # foot's lowest marker still just under the gait's 0.05 L contact test: a millimetre decided its
        # liftoff)
        top = np.maximum(seg[a - 1, pivot, 1] + lift[a - 1] + band, raw + level)
        lift[a:] = np.maximum(held, (1.0 - u) * held + u * top) - raw
    return yaw, shift, lift, level


def _contact_level(seg: np.ndarray, lift: np.ndarray, rise: np.ndarray, band: float, n_settle: int) -> float:
    """How much higher [m] the held foot's lowest point over the stance is than the reference's, and ``lift``
    (n,) [m] raised by it (in place) until the landing pivot is down, settling (min-jerk) over n_settle samples.

    seg: (n, 3, 3) the foot's markers over the stance (heading frame), lift: their held heights' change,
    rise: (n, 3) each marker's rise over its lowest point (inf if it never reaches the floor). The gait's
    contact test (and the double support the report measures with it) takes a foot as down while its
    lowest marker is within 0.05 L of the foot's lowest height over the stance. A later pivot keeps its
    height where the reference's sinks (the toe end site: 5.5 mm on one foot of CMU 02_01, 14.5 mm on one
    of 07_01), so the held foot's lowest height is that much above the reference's, and a foot coming down
    as the reference's crossed the test early (02_01 as a child: its targets' right foot 1.9 frames early
    at 120 Hz, the double support 3.3 points long). Landing and leaving at that level too (the foot raised
    by it outside the stance), it crosses the test when the reference's did.
    """
    raw_low = float(seg[:, :, 1].min())
    level = float((seg[:, :, 1] + lift[:, None]).min()) - raw_low
    landed = int(np.flatnonzero((rise <= band).any(axis=1))[0])
    i = np.arange(seg.shape[0])
    lift += level * (1.0 - min_jerk((i - landed) / max(n_settle, 1)))
    return level


def _hold_stance(pose: np.ndarray, step: np.ndarray, hold: np.ndarray, rate: np.ndarray, delta: np.ndarray,
                 length: np.ndarray, firm: np.ndarray, held: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The markers' own de-skating corrections through one stance of n samples, in time order.

    pose: (n, 3, 3) the foot's marker offsets (heading frame: forward, up, lateral) [m]; step: (n-1, 3, 2)
    their horizontal motion from one sample to the next [m]; hold: (n-1, 3) held in place at the later of
    the two samples (from its first to its last loaded sample of the stance); rate:
    (n, 3) relaxation toward the common correction delta (n, 2) [m]; length: (3, 3) bone lengths [m];
    firm, held: (n, 3) as _rigid_foot takes them. Returns own (n, 3, 2) [m], the horizontal corrections, and lift
    (n, 3) [m], the height changes of the bones' tilting.

    Sequential (each sample's correction starts from the previous one's rigid pose), so it runs in Python
    floats: ~50 samples of three markers, where NumPy's per-call cost would be most of the time.
    """
    n = pose.shape[0]
    bones = [float(length[i, j]) for i, j in FOOT_BONES]
    firm_l = (RIGID_MIN_FIRM + firm).tolist()
    held_l, pose_l, step_l = held.tolist(), pose.tolist(), step.tolist()
    hold_l, rate_l, delta_l = hold.tolist(), rate.tolist(), delta.tolist()
    own = [[[0.0, 0.0] for _ in range(3)] for _ in range(n)]
    lift = [[0.0, 0.0, 0.0] for _ in range(n)]
    for i in range(n):
        target = [list(p) for p in pose_l[i]]  # (3 markers, 3)
        if i > 0:
            for k in range(3):
                prev = own[i - 1][k]
                if hold_l[i - 1][k]:  # held: cancels its own motion
                    cur = [prev[c] - step_l[i - 1][k][c] for c in range(2)]
                else:  # relaxes toward the common correction
                    cur = [prev[c] + rate_l[i][k] * (delta_l[i][c] - prev[c]) for c in range(2)]
                target[k][0] += cur[0]
                target[k][2] += cur[1]
                # a marker a tilt raised comes back down over a few samples, not at once
                target[k][1] += TILT_RELAX * max(lift[i - 1][k], 0.0)
        rigid = _rigid_pose(target, bones, firm_l[i], held_l[i])
        for k in range(3):
            own[i][k] = [rigid[k][0] - pose_l[i][k][0], rigid[k][2] - pose_l[i][k][2]]
            lift[i][k] = rigid[k][1] - pose_l[i][k][1]
    return np.array(own).reshape(n, 3, 2), np.array(lift).reshape(n, 3)


#: At most this fraction of the cycle is added before and after a stance by _with_approach.
APPROACH_MAX = 0.08


def _with_approach(rel_foot: np.ndarray, idx: np.ndarray, stance_foot: np.ndarray,
                   contact_tol: float | np.ndarray, band: float, with_after: bool = True) -> np.ndarray:
    """A stance's samples idx (ordered in time, indices into K) with the samples just before and after it in
    which a marker that reaches the floor is already (still) within ``band`` of its lowest point.

    The reference's foot comes down still moving forward and leaves still moving: mocap feet land a few
    millimetres before the contact test calls them down. Holding them from the moment they are that low
    (as the physics report watches them) removes the landing sweep and the lift-off scuff as well.
    rel_foot: (K, 3, 3) marker offsets (heights above the ground); stance_foot: (K,) bool; with_after: False
    for none after the stance (a walking foot is raised clear by the stance's end instead).
    """
    K = rel_foot.shape[0]
    height = rel_foot[:, :, 1]  # (K, 3)
    h_min = height[idx].min(axis=0)
    reaches = h_min <= contact_tol
    if not reaches.any():
        return idx
    low = np.any((height <= h_min + band) & reaches, axis=1)  # (K,)
    most = int(APPROACH_MAX * K)
    before: list[int] = []
    after: list[int] = []
    k = (idx[0] - 1) % K
    while len(before) < most and low[k] and not stance_foot[k]:
        before.append(k)
        k = (k - 1) % K
    if with_after:
        # up to the farthest low sample within reach, a lift in between included: a marker that rises a
        # little and comes down again (a toe tip that dips at lift-off, 02_03) is still on the floor for the
        # report
        after = _to_farthest(low & ~stance_foot, idx[-1], 1, most, set(before))
    return np.concatenate([np.array(before[::-1], int), idx, np.array(after, int)])


def _to_farthest(ok: np.ndarray, start: int, step: int, most: int, taken: set) -> list[int]:
    """Cycle samples start + step, start + 2 step, ... (mod K = len(ok)) up to the farthest of the first
    ``most`` at which ``ok`` holds, none of them in ``taken``; empty if there is none."""
    K = ok.shape[0]
    ks = [(start + step * (j + 1)) % K for j in range(most)]
    hits = [j for j, k in enumerate(ks) if ok[k] and k not in taken]
    return [k for k in ks[: hits[-1] + 1] if k not in taken] if hits else []


#: Bones of the foot between its markers (ankle-ball: the foot; ball-tip: the toes): their lengths are fixed.
FOOT_BONES = ((1, 2), (0, 1))
#: Sweeps of the bone-length projection (each restores both bones; a few settle the chain to < 0.1 mm).
RIGID_SWEEPS = 4
#: Firmness of a marker off the floor (the bones' ends then share a correction equally), and of one held in
#: place horizontally (it does not give way to one that is not).
RIGID_MIN_FIRM = 1e-3
RIGID_HELD_FIRM = 1e6


def _bone_lengths(rel_foot: np.ndarray) -> np.ndarray:
    """(3, 3) distances between one foot's markers [m] (median over the cycle), from rel_foot (K, 3, 3)."""
    return np.median(np.linalg.norm(rel_foot[:, :, None, :] - rel_foot[:, None, :, :], axis=-1), axis=0)


def _keep_feet_rigid(out: np.ndarray, rel: np.ndarray, firm: np.ndarray, held: np.ndarray) -> np.ndarray:
    """_rigid_foot on every sample of both feet of a cycle's markers out (K, 2, 3, 3); rel: before de-skating."""
    out = out.copy()
    for foot in range(2):
        out[:, foot] = _rigid_foot(out[:, foot], _bone_lengths(rel[:, foot]), firm[:, foot], held[:, foot])
    out[..., 1] = np.maximum(out[..., 1], 0.0)
    return out


def _rigid_foot(pose: np.ndarray, length: np.ndarray, firm: np.ndarray, held: np.ndarray) -> np.ndarray:
    """One foot's markers (N, 3, 3) (heading frame: forward, up, lateral) with their bone lengths restored.

    Holding each loaded marker where it is while the reference foot rolls would keep a rising ball in its
    place instead of swinging it back round the tip: the ball-tip distance shrank by up to 14 % (09_08), and
    IK, unable to meet such targets, split the difference and slid the held tip 5-7 mm on a giant. So each
    bone (FOOT_BONES, lengths ``length`` (3, 3) [m]) gets its length back. A bone with both ends held in
    place (held: (N, 3) bool) keeps them where they are and tilts: its less firm end moves up or down (firm:
    (N, 3), how near each is to its lowest point of the stance), which is not sliding (the toes flex
    about the ball, or the ball rolls over the tip). Otherwise the bone slides along itself horizontally, a
    held end not at all and otherwise the firmer end less; heights stay (they decide what is on the ground).
    Sample by sample (``_rigid_pose``): remove_sliding calls it on one sample at a time, where NumPy's
    per-call cost would be most of the time.
    """
    bones = [float(length[i, j]) for i, j in FOOT_BONES]
    firm = RIGID_MIN_FIRM + np.asarray(firm, dtype=float)
    rows = zip(pose.tolist(), firm.tolist(), np.asarray(held, dtype=bool).tolist(), strict=True)
    return np.array([_rigid_pose(p, bones, f, h) for p, f, h in rows]).reshape(pose.shape)


def _rigid_pose(pose: list, bones: list, firm: list, held: list) -> list:
    """_rigid_foot on one sample, in Python floats: pose [[forward, up, lateral] × 3 markers] [m], bones:
    the FOOT_BONES' lengths [m], firm: 3 firmnesses (RIGID_MIN_FIRM included), held: 3 bools. Returns the
    pose with its bone lengths restored (RIGID_SWEEPS sweeps over the bones)."""
    x = [p[0] for p in pose]  # forward
    y = [p[1] for p in pose]  # up
    z = [p[2] for p in pose]  # lateral
    rules = []  # per bone: its ends, its length, both ends held, j the less firm end, j's share of a slide
    for (i, j), d in zip(FOOT_BONES, bones, strict=True):
        fi = RIGID_HELD_FIRM if held[i] else firm[i]
        fj = RIGID_HELD_FIRM if held[j] else firm[j]
        rules.append((i, j, d, held[i] and held[j], firm[j] <= firm[i], fi / (fi + fj)))
    for _ in range(RIGID_SWEEPS):
        for i, j, d, both_held, j_moves, share in rules:
            vx, vz = x[j] - x[i], z[j] - z[i]
            n = math.sqrt(vx * vx + vz * vz)
            if both_held and n <= d:  # tilt: the less firm end rises or sinks
                rise = math.sqrt(max(d * d - n * n, 0.0)) * (1.0 if y[j] >= y[i] else -1.0)
                if j_moves:
                    y[j] = y[i] + rise
                else:
                    y[i] = y[j] - rise
                continue
            # slide along the bone: j by share·change, i by -(1 - share)·change
            dy = y[j] - y[i]
            scale = math.sqrt(max(d * d - dy * dy, 0.0)) - n  # horizontal length wanted - now
            n_safe = max(n, 1e-12)
            cx, cz = scale * (vx / n_safe), scale * (vz / n_safe)
            x[j] += share * cx
            z[j] += share * cz
            x[i] -= (1.0 - share) * cx
            z[i] -= (1.0 - share) * cz
    return [[x[k], y[k], z[k]] for k in range(3)]


def held_feet(marker_rel: np.ndarray, stance_mask: np.ndarray, leg_length: float, order: str) -> np.ndarray:
    """The cycle's foot markers relative to their anchors (K, 2, 3, 3) [m] with the sliding of loaded
    markers removed: a walk's rolling foot (heel, ball, toe) one pivot at a time, a run's markers each.
    stance_mask: (K, 2) whether each foot is on the ground at each cycle sample; leg_length [m]."""
    # a marker is held if it comes as near the floor as the physics report's skate measure watches (its
    # SKATE_REACH_L, 0.04 L: a folded rig's ball joint rests 0.033 L up, above the 0.03 L contact test); in a
    # run the ball and the tip (the report's SKATE_MARKERS) even if HOLD_REACH_MARGIN_L higher: the IK may
    # bring an unheld ball that rests 0.047 L up under the report's reach at lift-off while it yaws with the
    # foot about the tip (10 mm, dash_feminine's troll). Not the ankle: holding 09_03's heel, 0.049 L up,
    # turned the foot at touchdown and slid its tip 13 mm (giant x1.5). The band (SLIDE_BAND_L) is wider
    # than the 0.02 L within which the physics report watches a marker slide, so a tip that lifts to just
    # under 0.02 L and comes down again is held all the while.
    if order == "walking":  # a walking foot rolls (heel, ball, toe): one pivot at a time holds it
        return remove_sliding_rolling(marker_rel, stance_mask, contact_tol=SKATE_REACH_L * leg_length,
                                      band=ROLL_BAND_L * leg_length)
    reach_tol = (SKATE_REACH_L + np.array([0.0, HOLD_REACH_MARGIN_L, HOLD_REACH_MARGIN_L])) * leg_length
    return remove_sliding(marker_rel, stance_mask, contact_tol=reach_tol, band=SLIDE_BAND_L * leg_length)
