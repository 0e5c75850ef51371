"""BVH reading and writing.

Reading accepts any channel order per joint, 3- or 6-channel (or any subset) joints, End Sites, tabs or
spaces, CRLF, scientific notation and large files. Units are converted to metres and the up axis to +Y at
this boundary: ``length_scale`` is given, or detected from the motion and reported; the rest of the rig's
conventions (folded bind pose, translation channels) are read from the motion too (``froude.body.conventions``):
``read_bvh`` here reads the file's numbers as they are, ``froude.body.load.load_bvh`` makes them SI and +Y up.
Writing keeps the input's conventions (unit, up axis, names, channel orders) unless told otherwise. Cleaning (the
synthetic T-pose first frame of the CMU conversions, invalid leading or trailing rows) is reported in
``motion.meta["cleaning"]``, never silent. Every problem raises ``BvhError`` naming file and line.

Position channels replace a joint's rest offset (the convention of most exporters); rotation channels
compose intrinsically in file order.
"""
from __future__ import annotations

import os
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core import quat
from ..core.motion import Motion
from ..core.rig import Z_UP_TO_Y_UP, change_basis
from ..core.skeleton import POSITION_CHANNELS, ROTATION_CHANNELS, Skeleton
from ..errors import BvhError
from .atomic import atomic_write_text

_VALID_CHANNELS = set(POSITION_CHANNELS) | set(ROTATION_CHANNELS)

#: Header values froude supports (checked while parsing, with the line): frame times [s] (10-1000 Hz) and
#: OFFSET components [file units] (a 2 m body in micrometres is 2e6; beyond that a value is corrupt).
FRAME_TIME_RANGE_S = (1e-3, 0.1)
MAX_HEADER_OFFSET = 1e7


@dataclass(frozen=True)
class _Token:
    text: str
    line: int


def _split_lines(text: str) -> list[str]:
    """Lines as editors count them: split on LF, CRLF or CR only.

    (``str.splitlines`` also splits on form feeds, U+0085 … which would shift every reported line number.)
    """
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    return text.split("\n")


def _show(word: str, limit: int = 40) -> str:
    """A token as it may appear in a one-line message: control characters escaped, long tokens cut."""
    shown = word if word.isprintable() else repr(word)[1:-1]
    return shown if len(shown) <= limit else shown[: limit - 3] + "..."


class _Parser:
    """Header parser. Tokens are produced lazily, line by line, so that only the HIERARCHY and the
    MOTION header are ever tokenized; the frame rows are parsed in bulk by ``_read_rows``."""

    def __init__(self, path: str, text: str):
        self.path = path
        self.lines = _split_lines(text)
        self._next_line = 0  # index of the next line to tokenize
        self._buf: deque[_Token] = deque()
        self._last_line = 1  # line of the last token handed out

    def _fill(self) -> bool:
        while not self._buf and self._next_line < len(self.lines):
            self._next_line += 1
            self._buf.extend(_Token(w, self._next_line) for w in self.lines[self._next_line - 1].split())
        return bool(self._buf)

    def _last_content_line(self) -> int:
        for i in range(len(self.lines) - 1, -1, -1):
            if self.lines[i].strip():
                return i + 1
        return 1

    def error(self, msg: str, line: int | None = None) -> BvhError:
        if line is None:
            tok = self.peek()
            line = tok.line if tok is not None else self._last_line
        return BvhError(msg, self.path, line)

    def peek(self) -> _Token | None:
        return self._buf[0] if self._fill() else None

    def next(self, what: str) -> _Token:
        tok = self.peek()
        if tok is None:
            raise BvhError(f"file ends early: expected {what}", self.path, self._last_content_line())
        self._buf.popleft()
        self._last_line = tok.line
        return tok

    def expect(self, word: str) -> _Token:
        tok = self.next(f"'{word}'")
        if tok.text.upper() != word.upper():
            raise self.error(f"expected '{word}', found '{_show(tok.text)}'", tok.line)
        return tok

    def number(self, what: str) -> float:
        tok = self.next(what)
        try:
            value = float(tok.text)
            if "_" in tok.text:  # Python reads "1_0" as 10; no BVH writer writes it (frame rows refuse it too)
                raise ValueError
        except ValueError:
            raise self.error(f"expected a number for {what}, found '{_show(tok.text)}'", tok.line) from None
        if not np.isfinite(value):
            raise self.error(f"{what} is not finite ('{_show(tok.text)}')", tok.line)
        if abs(value) > MAX_HEADER_OFFSET:
            raise self.error(f"{what} {_show(tok.text)} is beyond the supported ±{MAX_HEADER_OFFSET:g} file units",
                             tok.line)
        return value

    def parse_hierarchy(self):
        names: list[str] = []
        parents: list[int] = []
        offsets: list = []
        channels: list = []
        end_sites: list = []
        tok = self.peek()
        if tok is None:
            raise BvhError("empty file: no HIERARCHY section", self.path, 1)
        self.expect("HIERARCHY")
        tok = self.next("ROOT")
        self.root_line = tok.line
        if tok.text.upper() != "ROOT":
            raise self.error(f"expected 'ROOT', found '{_show(tok.text)}'", tok.line)
        try:
            self._parse_joint(-1, names, parents, offsets, channels, end_sites)
        except RecursionError:
            raise self.error("joints nested too deeply") from None
        tok = self.peek()
        if tok is not None and tok.text.upper() == "ROOT":
            raise self.error("more than one ROOT: only single-rooted skeletons are supported", tok.line)
        return names, parents, offsets, channels, end_sites

    def _parse_joint(self, parent, names, parents, offsets, channels, end_sites):
        name_tok = self.next("a joint name")
        name = name_tok.text
        # Names may contain spaces in some exporters: join words up to the brace on the same line.
        while (nxt := self.peek()) is not None and nxt.text != "{" and nxt.line == name_tok.line:
            name += " " + self.next("joint name").text
        shown = _show(name)
        if name in names:
            raise self.error(f"duplicate joint name '{shown}'", name_tok.line)
        index = len(names)
        names.append(name)
        parents.append(parent)
        self.expect("{")
        self.expect("OFFSET")
        offsets.append([self.number(f"OFFSET of joint '{shown}'") for _ in range(3)])
        ch_tok = self.expect("CHANNELS")
        n_tok = self.next("channel count")
        try:
            n = int(n_tok.text)
        except ValueError:
            raise self.error(f"expected a channel count for joint '{shown}', found '{_show(n_tok.text)}'",
                             n_tok.line) from None
        if not 0 <= n <= 6:
            raise self.error(f"joint '{shown}' declares {n} channels (0-6 allowed)", n_tok.line)
        chans = []
        for _ in range(n):
            c = self.next(f"a channel name of joint '{shown}'")
            canonical = c.text[0].upper() + c.text[1:].lower() if c.text else c.text
            if canonical not in _VALID_CHANNELS:
                raise self.error(f"unknown channel '{_show(c.text)}' in joint '{_show(name)}'", c.line)
            if canonical in chans:
                raise self.error(f"channel '{_show(c.text)}' repeated in joint '{shown}'", c.line)
            chans.append(canonical)
        if sum(c in ROTATION_CHANNELS for c in chans) not in (0, 3):
            raise self.error(f"joint '{shown}' must have 0 or 3 rotation channels", ch_tok.line)
        channels.append(tuple(chans))
        while True:
            tok = self.next(f"'}}' closing joint '{shown}'")
            word = tok.text.upper()
            if word == "}":
                return
            if word == "JOINT":
                self._parse_joint(index, names, parents, offsets, channels, end_sites)
            elif word == "END":
                self.expect("Site")
                self.expect("{")
                self.expect("OFFSET")
                off = [self.number(f"End Site OFFSET of joint '{shown}'") for _ in range(3)]
                self.expect("}")
                end_sites.append((index, off))
            else:
                raise self.error(f"unexpected '{_show(tok.text)}' inside joint '{_show(name)}'", tok.line)

    def parse_motion_header(self):
        tok = self.peek()
        if tok is None:
            raise BvhError("missing MOTION section", self.path, self._last_content_line())
        if tok.text.upper() != "MOTION":
            raise self.error(f"expected 'MOTION', found '{_show(tok.text)}'", tok.line)
        self.next("'MOTION'")
        t = self.next("'Frames:'")
        if t.text.rstrip(":").upper() != "FRAMES":
            raise self.error(f"expected 'Frames:', found '{_show(t.text)}'", t.line)
        if not t.text.endswith(":"):
            self.expect(":")
        n_tok = self.next("frame count")
        try:
            n_frames = int(n_tok.text)
        except ValueError:
            raise self.error(f"expected an integer frame count, found '{_show(n_tok.text)}'", n_tok.line) from None
        if n_frames <= 0:
            raise self.error(f"the file declares {n_frames} frames: nothing to read", n_tok.line)
        t = self.next("'Frame Time:'")
        if t.text.upper() != "FRAME":
            raise self.error(f"expected 'Frame Time:', found '{_show(t.text)}'", t.line)
        t = self.next("'Time:'")
        if t.text.rstrip(":").upper() != "TIME":
            raise self.error(f"expected 'Time:', found '{_show(t.text)}'", t.line)
        if not t.text.endswith(":"):
            self.expect(":")
        ft_tok = self.next("frame time")
        try:
            frame_time = float(ft_tok.text)
            if "_" in ft_tok.text:
                raise ValueError
        except ValueError:
            raise self.error(f"expected a number for the frame time, found '{_show(ft_tok.text)}'",
                             ft_tok.line) from None
        lo, hi = FRAME_TIME_RANGE_S
        if not (np.isfinite(frame_time) and frame_time > 0):
            raise self.error(f"frame time must be > 0 s, found '{_show(ft_tok.text)}'", ft_tok.line)
        if not lo * (1 - 1e-9) <= frame_time <= hi * (1 + 1e-9):
            raise self.error(f"frame time {_show(ft_tok.text)} s is outside the supported {lo:g}-{hi:g} s "
                             f"({1 / hi:g}-{1 / lo:g} Hz)", ft_tok.line)
        return n_frames, frame_time, ft_tok.line


def _read_rows(path: str, lines: list[str], first_line: int, n_frames: int, n_channels: int,
               channel_names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Parse the frame rows. Returns values (F, C) (NaN/inf kept for cleaning) and their line numbers (F,)."""
    body = lines[first_line:]
    row_lines = [i for i, l in enumerate(body) if l.strip()]
    if len(row_lines) < n_frames:
        last = first_line + (row_lines[-1] + 1 if row_lines else 0)
        raise BvhError(
            f"file ends early: {len(row_lines)} of {n_frames} declared frames present", path, max(last, first_line)
        )
    if len(row_lines) > n_frames:
        extra = first_line + row_lines[n_frames] + 1
        raise BvhError(f"more frame rows than the {n_frames} declared", path, extra)
    text_rows = [body[i] for i in row_lines]
    linenos = np.array(row_lines, dtype=np.int64) + first_line + 1
    # NumPy's C parser checks that every row has the same number of values and converts without
    # creating a Python float per value (a 1-hour 120 Hz clip has 40 million of them).
    try:
        values = np.loadtxt(text_rows, dtype=float, comments=None, ndmin=2)
        if values.shape == (n_frames, n_channels):
            return values, linenos
    except ValueError:
        pass  # locate the bad row below, with a message naming its line
    for k, row in enumerate(text_rows):
        words = row.split()
        if len(words) != n_channels:
            raise BvhError(f"frame row has {len(words)} values, expected {n_channels}", path, int(linenos[k]))
        for c, w in enumerate(words):
            try:
                float(w)
                ok = "_" not in w  # Python accepts "1_000"; no BVH writer does
            except ValueError:
                ok = False
            if not ok:
                raise BvhError(
                    f"non-numeric value '{_show(w)}' for channel {channel_names[c]}", path, int(linenos[k])
                )
        try:
            np.loadtxt([row], dtype=float, comments=None, ndmin=2)
        except ValueError:
            raise BvhError("unreadable frame row", path, int(linenos[k])) from None
    raise BvhError("could not parse frame rows", path, first_line)  # pragma: no cover


def _pose_jump_deg(rot: np.ndarray) -> np.ndarray:
    """(F-1,) median over joints of the rotation change [deg] between consecutive frames (F, J, 4).

    The median, not the maximum: noisy hand channels make single-joint jumps common in real captures,
    while a synthetic pose frame moves most joints at once.
    """
    # one joint at a time: no (F, J, 4) temporaries on long clips
    jumps = np.empty((rot.shape[0] - 1, rot.shape[1]))
    for j in range(rot.shape[1]):
        jumps[:, j] = quat.step_angles(rot[:, j])
    # joints that never turn (helper, twist or reference bones) would hide the pose frame in the median
    moving = jumps.max(axis=0) > 1e-9
    return np.degrees(np.median(jumps[:, moving] if moving.any() else jumps, axis=1))


def synthetic_pose_frame(rotations: np.ndarray) -> str | None:
    """Why the first frame of (F, J, 4) local rotations is a synthetic pose (the CMU conversions add a
    T-pose as frame 0), or None: it shows up as a jump in joint rotations far larger than any other
    frame-to-frame change. Needs F > 2."""
    jumps = _pose_jump_deg(rotations)
    typical = np.percentile(jumps[1:], 99)
    if jumps[0] > 5.0 and jumps[0] > 3.0 * typical:
        return (f"synthetic pose frame (T-pose), its joints turn by {jumps[0]:.0f} deg (median) to the next "
                f"frame (99th percentile elsewhere {typical:.1f} deg)")
    return None


def read_bvh(path: str | os.PathLike, *, clean: bool = True) -> tuple[Motion, int]:
    """A BVH file's motion as written: lengths in file units, the file's axes, translation channels kept;
    and the line of its ROOT (where a problem of the rig as a whole, such as its unit, is reported).

    ``froude.body.load.load_bvh`` reads it in SI units, +Y up (the conventions read from the motion).
    clean: drop (and report in meta["cleaning"]) a synthetic rest/T-pose first frame and invalid
        leading/trailing rows (all-zero, NaN or inf). With clean=False every row is kept and any
        non-finite value is an error.
    meta: source (the path), cleaning (sentences), first_line (the file line of the first frame kept).
    Raises BvhError (file and line in the message) on anything malformed.
    """
    path = str(path)
    try:
        raw = Path(path).read_bytes()
    except OSError as e:
        raise BvhError(f"cannot read file: {e.strerror}", path) from None
    if b"\x00" in raw[:65536]:
        raise BvhError("not a BVH text file (binary content)", path, 1)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    del raw  # large files: keep one copy of the text at a time (see benchmarks/bench_core.py)
    if not text or text.isspace():
        raise BvhError("empty file", path, 1)

    parser = _Parser(path, text)
    del text
    names, parents, offsets, channels, end_sites = parser.parse_hierarchy()
    n_frames, frame_time, ft_line = parser.parse_motion_header()
    n_channels = sum(len(c) for c in channels)
    channel_names = [f"{names[j]}.{c}" for j in range(len(names)) for c in channels[j]]
    values, linenos = _read_rows(path, parser.lines, ft_line, n_frames, n_channels, channel_names)
    root_line = parser.root_line
    del parser  # the text lines

    # Cleaning is about rotations and rows: done in file units; the conventions are read from the motion
    # afterwards (froude.body.conventions): units, up axis, the rest pose, translation channels.
    skel_file = Skeleton(tuple(names), np.array(parents), np.array(offsets, dtype=float), tuple(channels),
                         tuple((j, np.array(o, float)) for j, o in end_sites))
    finite = np.isfinite(values).all(axis=1)
    if not clean:
        bad = np.flatnonzero(~finite)
        if bad.size:
            raise _non_finite_error(path, values, linenos, channel_names, int(bad[0]), "")
        root_positions, rotations, translations = _channels_to_pose(skel_file, values, 1.0)
        notes: list[str] = []
    else:
        root_positions, rotations, translations, linenos, notes = _clean(
            path, skel_file, values, linenos, finite, channel_names, 1.0
        )
    del values
    meta = {"source": path, "cleaning": tuple(notes), "first_line": int(linenos[0])}
    return Motion(skel_file, root_positions, rotations, frame_time, translations).with_(meta=meta), root_line


def _non_finite_error(path, values, linenos, channel_names, k: int, where: str) -> BvhError:
    c = int(np.flatnonzero(~np.isfinite(values[k]))[0])
    return BvhError(f"non-finite value for channel {_show(channel_names[c])}{where}", path, int(linenos[k]))


def _describe_rows(linenos: np.ndarray, values: np.ndarray, what: str) -> str:
    """'2 invalid leading row(s) (all-zero; lines 188-189)' for the rows given."""
    n_bad = int((~np.isfinite(values).all(axis=1)).sum())
    kinds = ", ".join(k for k, n in (("all-zero", len(values) - n_bad), ("NaN/inf", n_bad)) if n)
    lines = f"line {linenos[0]}" if len(linenos) == 1 else f"lines {linenos[0]}-{linenos[-1]}"
    return f"dropped {len(values)} invalid {what} row(s) ({kinds}; {lines})"


def _clean(path, skeleton, values, linenos, finite, channel_names, length_scale):
    """Drop a synthetic pose first frame and invalid (all-zero or non-finite) rows before and after the
    motion; returns (root_positions, rotations, translations, linenos, notes). A non-finite value inside
    the motion is an error.

    The synthetic pose frame is judged against the next *valid* row, so invalid rows between the pose
    frame and the motion (a recording that starts late) are dropped with it.
    """
    valid = finite & np.any(values != 0.0, axis=1)
    vidx = np.flatnonzero(valid)
    if not vidx.size:
        raise BvhError("no valid frame: every row is all-zero or non-finite", path, int(linenos[0]))
    rp, rot, tr = _channels_to_pose(skeleton, values if len(vidx) == len(values) else values[vidx], length_scale)
    notes = []
    start, stop = int(vidx[0]), int(vidx[-1]) + 1
    if start > 0:
        notes.append(_describe_rows(linenos[:start], values[:start], "leading"))
    first_valid = 0  # index into vidx of the motion's first frame
    if len(vidx) > 2:
        why = synthetic_pose_frame(rot)
        if why:
            notes.append(f"dropped frame {start} (line {linenos[start]}): {why}")
            first_valid = 1
            gap = slice(start + 1, int(vidx[1]))
            if gap.stop > gap.start:
                notes.append(_describe_rows(linenos[gap], values[gap], "leading") + " after the pose frame")
            start = int(vidx[1])
    if stop < len(values):
        notes.append(_describe_rows(linenos[stop:], values[stop:], "trailing"))
    inner_bad = np.flatnonzero(~finite[start:stop])
    if inner_bad.size:
        k = start + int(inner_bad[0])
        raise _non_finite_error(path, values, linenos, channel_names, k, f" inside the motion (frame {k})")
    if stop - start == len(vidx) - first_valid:  # no all-zero rows inside the motion: reuse the conversion
        sl = slice(first_valid, None)
        rp, rot, tr = rp[sl], rot[sl], None if tr is None else tr[sl]
    else:
        rp, rot, tr = _channels_to_pose(skeleton, values[start:stop], length_scale)
    return rp, rot, tr, linenos[start:stop], notes


def _channels_to_pose(skeleton: Skeleton, values: np.ndarray, length_scale: float):
    F = values.shape[0]
    J = skeleton.n_joints
    rotations = np.empty((F, J, 4))
    translations = None
    if any(skeleton.has_translation_channels(j) for j in range(1, J)):
        translations = np.broadcast_to(skeleton.offsets, (F, J, 3)).copy()
    root_positions = np.broadcast_to(skeleton.offsets[0], (F, 3)).copy()
    columns = np.ascontiguousarray(values.T)  # (C, F): each channel contiguous, not a 768-byte stride
    col = 0
    for j in range(J):
        chans = skeleton.channels[j]
        rot_cols, rot_order = [], ""
        for c in chans:
            if c in POSITION_CHANNELS:
                axis = POSITION_CHANNELS.index(c)
                if j == 0:
                    root_positions[:, axis] = columns[col] * length_scale
                else:
                    assert translations is not None  # made above: a joint below the root has position channels
                    translations[:, j, axis] = columns[col] * length_scale
            else:
                rot_cols.append(col)
                rot_order += c[0].lower()
            col += 1
        if rot_cols:
            # continuous signs joint by joint: no (F, J, 4) temporaries on long clips
            rotations[:, j] = quat.make_continuous(quat.from_euler(np.radians(columns[rot_cols].T), rot_order))
        else:
            rotations[:, j] = quat.identity()
    return root_positions, rotations, translations


def motion_to_channels(motion: Motion, length_scale: float = 1.0) -> np.ndarray:
    """(F, C) BVH channel values (file units, degrees) of a motion, in the skeleton's channel layout."""
    skel = motion.skeleton
    F = motion.n_frames
    out = np.empty((F, skel.n_channels))
    trans = motion.local_translations()
    col = 0
    for j in range(skel.n_joints):
        chans = skel.channels[j]
        order = skel.rotation_order(j)
        euler = np.degrees(quat.to_euler(motion.rotations[:, j], order)) if order else None
        k = 0
        for c in chans:
            if c in POSITION_CHANNELS:
                out[:, col] = trans[:, j, POSITION_CHANNELS.index(c)] / length_scale
            else:
                assert euler is not None  # a rotation channel means the joint has a rotation order
                out[:, col] = euler[:, k]
                k += 1
            col += 1
    return out


def _format_block(values: np.ndarray) -> str:
    # Fixed 6 decimals keeps every number within 5e-7 of the value (the round-trip bar is 1e-4) and
    # is what DCC tools expect; "-0.000000" is normalised to "0.000000".
    values = np.where(np.abs(values) < 5e-7, 0.0, values)
    lines = [" ".join(f"{v:.6f}" for v in row) for row in values]
    return "\n".join(lines) + "\n"


def file_convention(motion: Motion, *, length_scale: float | None = None, up: str | None = None,
                    rotations_only: bool = False) -> tuple[Motion, float]:
    """The motion as it will be written, and the length scale (metres per file unit).

    By default the output keeps the input's conventions: its unit (meta["length_scale"]), its up axis
    (``skeleton.file_up``: a Z-up file is written Z-up again), its joint names and channel orders.
    rotations_only drops the position channels of every joint but the root (some readers mishandle
    them); refused when such a joint moves.
    """
    if length_scale is None:
        length_scale = float(motion.meta.get("length_scale", 1.0))
    if not (np.isfinite(length_scale) and length_scale > 0):
        raise BvhError(f"length scale must be > 0 m per file unit, got {length_scale}")
    skel = motion.skeleton
    if rotations_only:
        if motion.translations is not None and np.ptp(motion.translations[:, 1:], axis=0).max() > 1e-9:
            moving = int(np.argmax(np.ptp(motion.translations[:, 1:], axis=0).max(axis=1))) + 1
            raise BvhError(f"cannot write rotations only: joint '{skel.names[moving]}' moves along its position "
                           "channels")
        channels = tuple(c if j == 0 else tuple(x for x in c if x in ROTATION_CHANNELS)
                         for j, c in enumerate(skel.channels))
        motion = motion.with_(skeleton=skel.with_(channels=channels), translations=None)
    up = (up or motion.skeleton.file_up).upper()
    if up == "Z":
        motion = change_basis(motion, Z_UP_TO_Y_UP.T)
    elif up != "Y":
        raise BvhError(f"up axis must be Y or Z, got '{up}'")
    return motion, float(length_scale)


def bvh_text(motion: Motion, length_scale: float | None = None, *, up: str | None = None,
             rotations_only: bool = False) -> str:
    """The BVH file text of a motion, in the input's conventions unless told otherwise
    (``file_convention``). length_scale: metres per file unit (default: the source's, else 1)."""
    motion, length_scale = file_convention(motion, length_scale=length_scale, up=up, rotations_only=rotations_only)
    skel = motion.skeleton
    children: list[list[int]] = [[] for _ in range(skel.n_joints)]
    for j in range(1, skel.n_joints):
        children[skel.parents[j]].append(j)
    ends: list[list[np.ndarray]] = [[] for _ in range(skel.n_joints)]
    for j, off in skel.end_sites:
        ends[j].append(np.asarray(off) / length_scale)

    out = ["HIERARCHY"]

    def fmt(v):
        return " ".join(f"{x:.6f}" for x in np.where(np.abs(v) < 5e-7, 0.0, v))

    def write(j, depth):
        ind = "\t" * depth
        out.append(f"{ind}{'ROOT' if j == 0 else 'JOINT'} {skel.names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}\tOFFSET {fmt(skel.offsets[j] / length_scale)}")
        out.append(f"{ind}\tCHANNELS {len(skel.channels[j])}" + "".join(" " + c for c in skel.channels[j]))
        for c in children[j]:
            write(c, depth + 1)
        for off in ends[j]:
            out.append(f"{ind}\tEnd Site")
            out.append(f"{ind}\t{{")
            out.append(f"{ind}\t\tOFFSET {fmt(off)}")
            out.append(f"{ind}\t}}")
        out.append(f"{ind}}}")

    write(0, 0)
    out.append("MOTION")
    out.append(f"Frames: {motion.n_frames}")
    # ten significant digits: 1/120 s reads back as 120.000 Hz (seven decimals gave 120.0005)
    out.append(f"Frame Time: {motion.frame_time:.10g}")
    header = "\n".join(out) + "\n"
    return header + _format_block(motion_to_channels(motion, length_scale))


def save_bvh(motion: Motion, path: str | os.PathLike, *, length_scale: float | None = None, up: str | None = None,
             rotations_only: bool = False) -> None:
    """Write a motion as BVH, atomically, in the input's conventions unless told otherwise
    (``file_convention``: length_scale in metres per file unit, up "Y"/"Z", rotations_only)."""
    if not np.all(np.isfinite(motion.root_positions)) or not np.all(np.isfinite(motion.rotations)):
        raise BvhError("refusing to write a motion with non-finite values", str(path))
    atomic_write_text(path, bvh_text(motion, length_scale, up=up, rotations_only=rotations_only))
