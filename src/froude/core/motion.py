"""A motion: a skeleton plus root positions and local joint rotations for every frame, and pure operations.

Every operation returns a new ``Motion``; none mutates its input.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from . import quat
from .skeleton import Skeleton


@dataclass(frozen=True, eq=False)
class Motion:
    """A skeletal motion sampled at a fixed frame rate.

    skeleton: the joint hierarchy.
    root_positions: (F, 3) world position of the root joint [m].
    rotations: (F, J, 4) local joint rotations, unit quaternions (w, x, y, z), relative to the parent frame.
    frame_time: seconds per frame [s].
    translations: (F, J, 3) local joint translations [m] for skeletons whose non-root joints have
        position channels; None means every non-root joint sits at its rest offset.
    meta: free-form provenance (source file, length scale, cleaning notes ...).
    """

    skeleton: Skeleton
    root_positions: np.ndarray
    rotations: np.ndarray
    frame_time: float
    translations: np.ndarray | None = None
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        rp = np.asarray(self.root_positions, dtype=float)
        rot = np.asarray(self.rotations, dtype=float)
        object.__setattr__(self, "root_positions", rp)
        object.__setattr__(self, "rotations", rot)
        F = rp.shape[0]
        J = self.skeleton.n_joints
        if rp.shape != (F, 3) or rot.shape != (F, J, 4):
            raise ValueError(
                f"root_positions must be (F, 3) and rotations (F, {J}, 4); got {rp.shape} and {rot.shape}"
            )
        if self.translations is not None:
            tr = np.asarray(self.translations, dtype=float)
            if tr.shape != (F, J, 3):
                raise ValueError(f"translations must be (F, {J}, 3); got {tr.shape}")
            object.__setattr__(self, "translations", tr)
        if not self.frame_time > 0:
            raise ValueError("frame_time must be > 0")

    # ---- basic properties -------------------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        return self.root_positions.shape[0]

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    @property
    def duration(self) -> float:
        """Time from the first to the last frame [s]."""
        return max(self.n_frames - 1, 0) * self.frame_time

    @property
    def times(self) -> np.ndarray:
        """(F,) frame times [s] starting at 0."""
        return np.arange(self.n_frames) * self.frame_time

    def local_translations(self) -> np.ndarray:
        """(F, J, 3) local joint translations [m]: rest offsets, root position, position channels."""
        if self.translations is not None:
            t = self.translations.copy()
        else:
            t = np.broadcast_to(self.skeleton.offsets, (self.n_frames, self.skeleton.n_joints, 3)).copy()
        t[:, 0] = self.root_positions
        return t

    def with_(self, **changes) -> Motion:
        """A copy with fields replaced (dataclasses.replace)."""
        return replace(self, **changes)

    # ---- pure operations ---------------------------------------------------------------------------
    def cut(self, start: int, stop: int | None = None) -> Motion:
        """Frames [start, stop) as a new motion."""
        sl = slice(start, stop)
        return replace(
            self,
            root_positions=self.root_positions[sl],
            rotations=self.rotations[sl],
            translations=None if self.translations is None else self.translations[sl],
        )

    def sample(self, times_s: np.ndarray) -> Motion:
        """The motion evaluated at arbitrary source times (T,) [s]: linear positions, slerped rotations.

        The result has frame time ``self.frame_time`` unless it is replaced afterwards; use ``resample``
        or ``time_warp`` for the common cases. Times outside the clip are clamped to its ends.
        """
        t = np.clip(np.asarray(times_s, dtype=float) / self.frame_time, 0.0, self.n_frames - 1)
        # (i * dt) / dt is not always exactly i in floating point: snap times that hit a frame, so that
        # sampling at the frame times (an identity time-warp) reproduces the frames bit for bit.
        nearest = np.rint(t)
        t = np.where(np.abs(t - nearest) < 1e-9, nearest, t)
        i0 = np.minimum(np.floor(t).astype(np.int64), max(self.n_frames - 2, 0))
        i1 = np.minimum(i0 + 1, self.n_frames - 1)
        w = t - i0
        rp = self.root_positions[i0] * (1.0 - w)[:, None] + self.root_positions[i1] * w[:, None]
        rots = quat.make_continuous(self.rotations)
        r = quat.slerp(rots[i0], rots[i1], np.broadcast_to(w[:, None], (len(w), self.skeleton.n_joints)))
        # slerp renormalises, which can change the last bit of an exact frame: take those frames as they are
        r = np.where((w == 0.0)[:, None, None], rots[i0], np.where((w == 1.0)[:, None, None], rots[i1], r))
        tr = None
        if self.translations is not None:
            tr = self.translations[i0] * (1.0 - w)[:, None, None] + self.translations[i1] * w[:, None, None]
        return replace(self, root_positions=rp, rotations=r, translations=tr)

    def resample(self, fps: float) -> Motion:
        """The same motion at another frame rate [Hz], covering the same duration."""
        if not fps > 0:
            raise ValueError("fps must be > 0")
        n = int(np.floor(self.duration * fps + 1e-9)) + 1
        out = self.sample(np.arange(n) / fps)
        return replace(out, frame_time=1.0 / fps)

    def time_warp(self, source_times_s: np.ndarray, frame_time: float | None = None) -> Motion:
        """Retime by a monotone map: output frame i shows the source at ``source_times_s[i]`` [s]."""
        st = np.asarray(source_times_s, dtype=float)
        if st.ndim != 1 or (st.size > 1 and np.any(np.diff(st) < 0)):
            raise ValueError("source_times_s must be a non-decreasing 1-D array")
        out = self.sample(st)
        return replace(out, frame_time=self.frame_time if frame_time is None else frame_time)

    def continuous(self) -> Motion:
        """The same motion with quaternion signs made continuous over time."""
        return replace(self, rotations=quat.make_continuous(self.rotations))

    def __len__(self) -> int:
        return self.n_frames

    def __getitem__(self, item) -> Motion:
        """Frame slicing without copying semantics surprises: ``motion[10:50]``, ``motion[::2]``."""
        if isinstance(item, (int, np.integer)):
            item = slice(int(item), int(item) + 1 if item != -1 else None)
        if not isinstance(item, slice):
            raise TypeError("motions are sliced by frame: motion[start:stop:step]")
        step = item.step or 1
        return replace(
            self,
            root_positions=self.root_positions[item],
            rotations=self.rotations[item],
            translations=None if self.translations is None else self.translations[item],
            frame_time=self.frame_time * abs(step),
        )


def max_joint_jump_deg(motion: Motion) -> float:
    """Largest frame-to-frame rotation change of any joint [deg] (root orientation included)."""
    return float(np.degrees(quat.max_step_angle(motion.rotations)))
