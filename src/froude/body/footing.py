"""Where feet stand: the floor of a motion found from its feet, the window about each stance in which a foot
marker is watched, and how high each marker rests in stance. One definition for the clip and its outputs:
the synthesis places an output's feet where the clip's rest (``synthesis.feet``, ``synthesis.targets``), and
the physics report measures the output by the same definition (``report.metrics``), on the output motion.
"""
from __future__ import annotations

import numpy as np

from ..core.constants import UP_AXIS
from .gait import Gait

#: Skate is measured on these foot markers (index into the body's (ankle, toe, toe end)): the ball and
#: the tip of the foot, the points a runner stands and pushes off on.
SKATE_MARKERS = (1, 2)
#: A marker is on or just above the floor while within this fraction of the leg length of its lowest
#: height around the stance (2 % of L: 18 mm for an adult).
SKATE_BAND_L = 0.02
#: ... and only if that lowest height is within this fraction of L of the floor (a joint centre rests a
#: sole's thickness above it; a "contact" cut by the clip's edge may be a foot in the air).
SKATE_REACH_L = 0.04
#: The stance window is widened by this much on each side [s] so that touchdown and lift-off are in it.
SKATE_MARGIN_S = 0.1
#: The file's own y = 0 is the floor when the feet's lowest points rest within these fractions of L above it
#: (a joint centre rests a sole's thickness above the floor: CMU's toe end sites 10-20 mm, a folded Bandai
#: rig's estimated toe tip 20 mm); otherwise the floor is where they rest (``floor_height``). Not below it:
#: nothing rests under the floor, so feet resting below y = 0 (Bandai dataset-2_walk_exhausted_001's 10 mm,
#: dataset-1_walk_normal_001's 13 mm) stand on a floor that low; taken as y = 0, an output copying the
#: clip's height above it was lowered into its floor (penetration 10-13 mm on a troll or a giant).
FLOOR_NEAR_L = (0.0, 0.06)


def floor_height(markers: np.ndarray, gait: Gait, leg_length: float) -> tuple[float, str]:
    """The floor of a motion [m] found from its feet alone, and a sentence saying how.

    markers: (F, 2, 3, 3) [m]. Each foot rests at the median over its whole stances of its lowest point in
    the stance; the floor is the file's y = 0 when the lower foot's rest is within FLOOR_NEAR_L × L of it,
    else that rest (the feet's lowest points then taken to stand on the floor). NaN without a stance.
    """
    rest = []
    for foot in (0, 1):
        st = [s for s in gait.stances if s.foot == foot and not s.partial] or \
             [s for s in gait.stances if s.foot == foot]
        if st:
            rest.append(float(np.median([markers[s.start:s.stop, foot, :, UP_AXIS].min() for s in st])))
    if not rest:
        return float("nan"), "no foot contact"
    low = min(rest)
    lo, hi = FLOOR_NEAR_L
    if lo * leg_length <= low <= hi * leg_length:
        return 0.0, f"the file's y = 0 (the feet's lowest points rest {1000 * low:.1f} mm above it)"
    return low, f"where the feet's lowest points rest ({1000 * low:.1f} mm from the file's y = 0)"


def stance_rest_heights(markers: np.ndarray, gait: Gait, floor: float) -> tuple[np.ndarray, list]:
    """How high each foot marker rests in stance above the floor [m].

    markers: (F, 2, 3, 3) [m]; floor [m]. Returns rest (2, 3) [m]: per foot and marker (ankle, ball, tip) the
    median over the foot's whole stances of the marker's lowest height about the stance (NaN for a foot
    without a whole stance: a contact cut by the clip's edge may not reach its lowest point), and per whole
    stance (foot, start, stop, (3,) lowest heights [m]). About the stance: widened as the skate measure's
    (skate_windows: SKATE_MARGIN_S, not past the middle of the swings), because a toe tip comes lowest as
    the heel rises at push-off, where the contact test may already have let the foot go (a frame earlier in
    one motion than in another would change the figure by the tip's drop in that frame). A point below the
    floor rests on it (0): how deep it goes is the penetration's bar (a folded rig's estimated toe tip rests
    5 mm under the floor of dataset-1_run_tired_001, which its troll, copying it, took 8 mm deep).
    """
    per = [(foot, s.start, s.stop, np.maximum(markers[a:b, foot, :, UP_AXIS].min(axis=0) - floor, 0.0))
           for foot, s, a, b in skate_windows(gait, markers.shape[0]) if not s.partial]
    per.sort(key=lambda x: x[1])
    rest = np.full((2, 3), np.nan)
    for foot in (0, 1):
        h = [x[3] for x in per if x[0] == foot]
        if h:
            rest[foot] = np.median(np.array(h), axis=0)
    return rest, per


def skate_windows(gait: Gait, n_frames: int):
    """(foot, stance, a, b) for every stance: the frames [a, b) foot_skate_floor_mm watches about it (the
    stance widened by SKATE_MARGIN_S on each side, not past the middle of the swings around it)."""
    margin = int(round(SKATE_MARGIN_S / gait.frame_time))
    for foot in (0, 1):
        st = sorted((s for s in gait.stances if s.foot == foot), key=lambda s: s.start)
        for i, s in enumerate(st):
            lo_lim = (st[i - 1].stop + s.start) // 2 if i > 0 else 0
            hi_lim = (s.stop + st[i + 1].start + 1) // 2 if i + 1 < len(st) else n_frames
            yield foot, s, max(lo_lim, s.start - margin), min(hi_lim, s.stop + margin)
