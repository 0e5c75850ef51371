"""What the studio draws, precomputed once per motion: pure NumPy, no viser.

A ``Track`` holds everything the playback loop needs for one runner at every frame, so that a frame
update is only array indexing: bone segments from one batched FK (worked out after the first frame is on
screen), the simple machine's COM, the spring legs (COM → contact point while a foot is in stance), the
contact points and the COM trail.
"""
from __future__ import annotations

import functools
import hashlib
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ...body.path import unstraighten, unstraighten_points
from ...core.constants import GRAVITY, UP_AXIS
from ...core.kinematics import fk, fk_soa, to_soa
from ...core.motion import Motion
from ...report.metrics import vertical_force_bw
from ...viz.rig import build_rig

if TYPE_CHECKING:
    from ...body.model import BodyModel

#: Every n-th frame of the COM path goes into the drawn trail (a trail needs no 120 Hz detail).
TRAIL_STRIDE = 3
#: ... at most this far apart in time [s] (a 30 Hz clip keeps every frame: its trail stays smooth).
TRAIL_STEP_S = 0.025


def _trail_stride(frame_time: float) -> int:
    return max(1, min(TRAIL_STRIDE, int(TRAIL_STEP_S / frame_time)))


@dataclass(frozen=True, eq=False)
class Track:
    """One runner ready to play.

    frame_time [s]; motion: the runner's poses, whose bone segments ``segments`` (F, B, 2, 3) float32 [m]
    (joint→child, joint→end site) are worked out by one batched FK when first needed (``segments_at``
    gives one frame before that: a new result is drawn without waiting for all its frames);
    com: (F, 3) simple-machine (or body) COM [m]; legs: (F, 2, 2, 3) float32 spring-leg segment per foot,
    zero length at the COM when that foot is not in stance; contacts: (n, 3) contact points [m] with
    contact_foot (n,) 0/1; trail: (K, 2, 3) float32 COM path segments [m];
    force_t: (T,) [s], force_bw: (T,) machine vertical leg force [body weights] (empty if none);
    body_com: (F, 3) the body's whole-body COM [m], whose implied vertical force ``body_force_bw`` (F,)
    [body weights] is worked out when first asked for (the plot is drawn after the runner);
    loop_shift: (3,) horizontal displacement over one pass, added per loop so a short clip keeps running.
    """

    frame_time: float
    motion: Motion
    com: np.ndarray
    legs: np.ndarray
    contacts: np.ndarray
    contact_foot: np.ndarray
    trail: np.ndarray
    force_t: np.ndarray
    force_bw: np.ndarray
    body_com: np.ndarray
    loop_shift: np.ndarray
    body: BodyModel | None = None  # the runner's body model (its capsules); None: lines only

    @property
    def stature(self) -> float:
        """The runner's stature [m] (its body model's; every runner the studio places has one)."""
        assert self.body is not None, "a track without a body model has no stature"
        return float(self.body.stature)

    @functools.cached_property
    def rig(self):
        """The capsules of this skeleton (``froude render``'s): the same widths, head and sides."""
        assert self.body is not None, "a track without a body model is drawn as lines"
        return build_rig(self.body)

    def borrow_rig(self, other: Track) -> bool:
        """Draw with ``other``'s capsules scaled to this body's stature until this body's own rig is built
        (``exact_rig``): a new result reaches the page without the ~8 ms rig build. False when the
        skeletons differ in topology (then the rig is built now)."""
        a, b = self.motion.skeleton, other.motion.skeleton
        same = a.n_joints == b.n_joints and np.array_equal(a.parents, b.parents)
        if other.body is None or self.body is None or not same:
            return False
        from dataclasses import replace as _replace

        k = float(self.body.stature) / float(other.body.stature)
        r = other.rig
        self.__dict__["rig"] = _replace(r, point_local=r.point_local * k, bone_width=r.bone_width * k,
                                        head_radius=r.head_radius * k, stature=r.stature * k)
        self.__dict__.pop("capsules", None)
        return True

    def exact_rig(self) -> None:
        """Replace a borrowed rig by this body's own (and redo the capsules)."""
        assert self.body is not None, "a track without a body draws lines only"
        self.__dict__["rig"] = build_rig(self.body)
        self.__dict__.pop("capsules", None)
        _ = self.capsules

    @functools.cached_property
    def capsules(self) -> np.ndarray:
        """(F, B+1, 2, 3) float32 capsule end points [m] of every frame (the last one: the head)."""
        return capsule_ends(self.motion, self.rig)

    def capsules_at(self, i: int) -> np.ndarray:
        """(B+1, 2, 3) capsule ends of frame i (one frame's FK until all frames are done)."""
        done = self.__dict__.get("capsules")
        return done[i] if done is not None else capsule_ends(self.motion[i:i + 1], self.rig)[0]

    @property
    def capsule_radii(self) -> np.ndarray:
        """(B+1,) capsule radius [m] (the last: the head)."""
        r = self.rig
        return np.append(0.5 * np.asarray(r.bone_width, float), r.head_radius).astype(np.float32)

    @functools.cached_property
    def phases(self) -> np.ndarray:
        """(F,) int8 0 flight, 1 left stance, 2 right stance, 3 both (from the drawn spring legs)."""
        stance = np.linalg.norm(self.legs[:, :, 1] - self.legs[:, :, 0], axis=-1) > 1e-6  # (F, 2)
        return (stance[:, 0] * 1 + stance[:, 1] * 2).astype(np.int8)

    @functools.cached_property
    def speed_m_s(self) -> np.ndarray:
        """(F,) horizontal COM speed [m/s] (central differences of the drawn COM path)."""
        com = np.asarray(self.com, float).copy()
        com[:, UP_AXIS] = 0.0
        if len(com) < 2:
            return np.zeros(len(com))
        v = np.gradient(com, self.frame_time, axis=0)
        return np.linalg.norm(v, axis=1)

    @functools.cached_property
    def body_force_bw(self) -> np.ndarray:
        return body_force_bw(self.body_com, self.frame_time)

    @functools.cached_property
    def segments(self) -> np.ndarray:
        return bone_segments(self.motion)[0]

    def segments_at(self, i: int) -> np.ndarray:
        """(B, 2, 3) float32 bone segments of frame i [m] (one frame's FK until all frames are done)."""
        done = self.__dict__.get("segments")
        return done[i] if done is not None else bone_segments(self.motion[i:i + 1])[0][0]

    @property
    def n_bones(self) -> int:
        sk = self.motion.skeleton
        return int(np.count_nonzero(sk.parents >= 0)) + len(sk.end_sites)

    @property
    def n_frames(self) -> int:
        return int(self.motion.n_frames)

    @property
    def duration(self) -> float:
        return self.n_frames * self.frame_time

    def frame_at(self, t: float) -> tuple[int, np.ndarray]:
        """Frame index at time t [s] (looping) and the position shift (3,) [m] of that loop."""
        k = math.floor(t / self.duration) if self.duration > 0 else 0
        i = int((t - k * self.duration) / self.frame_time) if self.frame_time > 0 else 0
        return min(max(i, 0), self.n_frames - 1), k * self.loop_shift


def bone_segments(motion: Motion) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bone segments of every frame from one batched FK.

    Returns segments (F, B, 2, 3) float32 [m] (B = bones to children + bones to end sites), and the
    component-major FK outputs P (J, 3, F) [m], R (J, 9, F) for reuse (e.g. the body COM).
    """
    sk = motion.skeleton
    rp, rot, tr = to_soa(motion.root_positions, motion.rotations, motion.translations)
    P, R = fk_soa(sk.parents, sk.offsets, rp, rot, tr)
    child = np.flatnonzero(sk.parents >= 0)
    a = P[sk.parents[child]]  # (Bc, 3, F)
    b = P[child]
    if sk.end_sites:
        ej = np.array([j for j, _ in sk.end_sites])
        eo = np.array([np.asarray(o, float) for _, o in sk.end_sites])  # (E, 3) local offsets [m]
        Rm = R[ej].reshape(len(ej), 3, 3, -1)  # row-major entries -> (E, 3, 3, F)
        tip = P[ej] + np.einsum("erkf,ek->erf", Rm, eo)
        a = np.concatenate([a, P[ej]])
        b = np.concatenate([b, tip])
    seg = np.stack([a, b], axis=1)  # (B, 2, 3, F)
    return np.ascontiguousarray(seg.transpose(3, 0, 1, 2), dtype=np.float32), P, R


def capsule_ends(motion: Motion, rig) -> np.ndarray:
    """(F, B+1, 2, 3) float32 end points [m] of a rig's capsules per frame; the head is the last, a
    zero-length capsule at the head centre."""
    p, R = fk(motion)
    pts = rig.points(p, R)  # (F, P, 3)
    ends = np.stack([pts[:, rig.bone_a], pts[:, rig.bone_b]], axis=2)  # (F, B, 2, 3)
    head = np.repeat(pts[:, rig.head][:, None, None, :], 2, axis=2)
    return np.concatenate([ends, head], axis=1).astype(np.float32)


def capsule_instances(ends: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cylinder instances for capsule end points (N, 2, 3) [m] and radii (N,) [m]: positions (N, 3) (mid
    points), wxyz (N, 4) (turning +z onto the bone) and per-axis scales (N, 3) (radius, radius, length) of
    a unit cylinder along z centred at the origin. Zero-length capsules get length 0."""
    a, b = ends[:, 0].astype(np.float64), ends[:, 1].astype(np.float64)
    d = b - a
    length = np.linalg.norm(d, axis=1)
    u = d / np.maximum(length, 1e-9)[:, None]
    u[length < 1e-9] = (0.0, 0.0, 1.0)
    # the shortest rotation z -> u: q = (1 + u_z, -u_y, u_x, 0) normalised; u = -z is a half turn about x
    w = 1.0 + u[:, 2]
    q = np.stack([w, -u[:, 1], u[:, 0], np.zeros(len(u))], axis=1)
    flip = w < 1e-9
    q[flip] = (0.0, 1.0, 0.0, 0.0)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    scales = np.stack([radii, radii, length], axis=1)
    return (0.5 * (a + b)).astype(np.float32), q.astype(np.float32), scales.astype(np.float32)


def spring_legs(com: np.ndarray, stance_contact: np.ndarray) -> np.ndarray:
    """(F, 2, 2, 3) float32 leg segments: COM → contact point where stance_contact (F, 2, 3) is finite."""
    F = com.shape[0]
    legs = np.empty((F, 2, 2, 3), np.float32)
    legs[:, :, 0] = com[:, None, :]
    ok = np.isfinite(stance_contact).all(axis=2)
    legs[:, :, 1] = np.where(ok[:, :, None], stance_contact, com[:, None, :])
    return legs


def trail_segments(com: np.ndarray, stride: int = TRAIL_STRIDE) -> np.ndarray:
    """(K, 2, 3) float32 polyline segments along a COM path (F, 3) [m], every ``stride`` frames."""
    pts = com[::stride]
    if len(com) and (len(com) - 1) % stride:
        pts = np.concatenate([pts, com[-1:]])
    if len(pts) < 2:
        pts = np.repeat(com[:1], 2, axis=0) if len(com) else np.zeros((2, 3))
    return np.stack([pts[:-1], pts[1:]], axis=1).astype(np.float32)


def path_stance_contacts(path, n_frames: int) -> np.ndarray:
    """(F, 2, 3) contact point of each foot at each output frame of a MachinePath (NaN: not in stance)."""
    t = path.times[:n_frames]
    out = np.full((len(t), 2, 3), np.nan)
    for i, foot in enumerate(path.foot_of_step):  # loop over steps, not frames
        m = (t >= path.t_touchdown[i]) & (t < path.t_liftoff[i])
        out[m, int(foot)] = path.contacts[i]
    return out


def body_force_bw(com: np.ndarray, frame_time: float) -> np.ndarray:
    """(F,) vertical ground force [body weights] implied by a COM path; NaN when it is too short."""
    try:
        return vertical_force_bw(com, frame_time)
    except Exception:  # a too-short or degenerate path: no curve rather than no studio
        return np.full(len(com), np.nan)


def naive_track(res, prep) -> Track:
    """An engine-style naive result (no machine path): its body COM, no spring legs, no contacts."""
    motion, body = res.motion, res.retarget.body
    seg, P, R = bone_segments(motion)
    com = np.ascontiguousarray(body.com_soa(P, R).T)
    F = motion.n_frames
    track = Track(
        frame_time=float(motion.frame_time), motion=motion, com=com,
        legs=spring_legs(com, np.full((F, 2, 3), np.nan)), contacts=np.zeros((0, 3)),
        contact_foot=np.zeros(0, int), trail=trail_segments(com, _trail_stride(motion.frame_time)),
        force_t=np.zeros(0), force_bw=np.zeros(0),
        body_com=com, loop_shift=np.zeros(3), body=body,
    )
    track.__dict__["segments"] = seg
    return track


def machine_track(motion: Motion, body, path, body_com: np.ndarray | None = None) -> Track:
    """A result (or preview) on its target skeleton with its machine path drawn over it.

    body_com: (F, 3) the motion's whole-body COM [m] when known (an IK result's is the machine's, exactly);
    computed from the FK otherwise.
    """
    F = motion.n_frames
    com_path = np.asarray(path.com[:F], float)
    seg = None
    if body_com is None:  # one FK for the COM and the bones
        seg, P, R = bone_segments(motion)
        body_com = np.ascontiguousarray(body.com_soa(P, R).T)
    f_bw = path.force[:, UP_AXIS] / (path.mass * GRAVITY)
    track = Track(
        frame_time=float(motion.frame_time), motion=motion, com=com_path,
        legs=spring_legs(com_path, path_stance_contacts(path, F)),
        contacts=np.asarray(path.contacts, float), contact_foot=np.asarray(path.foot_of_step, int),
        trail=trail_segments(com_path, _trail_stride(motion.frame_time)),
        force_t=np.asarray(path.times, float), force_bw=f_bw,
        body_com=body_com, loop_shift=np.zeros(3), body=body,
    )
    if seg is not None:
        track.__dict__["segments"] = seg  # already computed: fill the cached property
    return track


def reference_track(prep) -> Track:
    """The reference clip with its own COM, detected contacts and legs; loops with its displacement.

    A turning take is drawn as it was taken, along its curve (the machines saw it straightened:
    ``body.path.straighten``; results are bent back onto the curve, so the reference is too)."""
    motion = prep.motion
    F = motion.n_frames
    com = np.asarray(prep.com, float)
    contact = np.full((F, 2, 3), np.nan)
    for s in prep.gait.stances:  # loop over contacts, not frames
        contact[s.start:s.stop, s.foot] = s.contact_point
    if prep.turn is not None:
        motion = unstraighten(motion, prep.turn)
        com = unstraighten_points(com, prep.turn)
        contact = unstraighten_points(contact, prep.turn)
    # per loop, move on by the clip's horizontal COM displacement (plus one frame of travel)
    shift = com[-1] - com[0]
    if F > 1:
        shift = shift + (com[-1] - com[-2])
    shift[UP_AXIS] = 0.0
    stances = prep.gait.stances
    track = Track(
        frame_time=float(motion.frame_time), motion=motion, com=com, legs=spring_legs(com, contact),
        contacts=np.array([contact[(s.start + s.stop - 1) // 2, s.foot] for s in stances]).reshape(-1, 3),
        contact_foot=np.array([s.foot for s in stances], int),
        trail=trail_segments(com, _trail_stride(motion.frame_time)),
        force_t=np.zeros(0), force_bw=np.zeros(0), body_com=com, loop_shift=shift, body=prep.body,
    )
    _ = track.capsules  # played from start to end for the whole session: all frames now
    return track


def motion_hash(motion: Motion) -> str:
    """12 hex digits identifying a motion's numbers (rounded to 1e-6, so float noise does not count)."""
    h = hashlib.sha1()
    for a in (motion.root_positions, motion.rotations, motion.skeleton.offsets):
        h.update((np.round(np.asarray(a, float), 6) + 0.0).tobytes())  # + 0.0: -0.0 and 0.0 hash alike
    h.update(f"{motion.frame_time:.9f}".encode())
    return h.hexdigest()[:12]
