"""Property test: mutated real BVH files give a Motion or a BvhError, never anything else.

Mutations: byte flips, truncation, token swaps, line deletions and duplications, token replacement by
junk, and combinations. A bounded example count keeps the test well under 30 s on this machine.
"""
from __future__ import annotations

import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from froude import BvhError, Motion, load_bvh

from conftest import ALL_CLIPS, FIXTURES, MOCAP

SOURCES = {f"{name}.bvh": (MOCAP / f"{name}.bvh").read_bytes() for name in ALL_CLIPS[:6]} if MOCAP else {}
SOURCES["orders_crlf_tabs_sci.bvh"] = (FIXTURES / "orders_crlf_tabs_sci.bvh").read_bytes()
SOURCES["three_joint.bvh"] = (FIXTURES / "three_joint.bvh").read_bytes()
_TMP = tempfile.TemporaryDirectory(prefix="froude-prop-")

JUNK = [b"", b"nan", b"inf", b"-inf", b"1e999", b"-1e308", b"0", b"x", b"{", b"}", b"JOINT", b"End", b"Site",
        b"ROOT", b"MOTION", b"Frames:", b"Frame", b"Time:", b"CHANNELS", b"OFFSET", b"7", b"-3", b"0.0",
        b"Xposition", b"Qrotation", b"\x00", b"\xff\xfe", b"1_0", b"1,5", b"\t", b"\r", b"\r\n", b"\x0c", b"\xc2\x85"]


def _flip(data: bytes, pos: int, byte: int) -> bytes:
    pos %= max(len(data), 1)
    return data[:pos] + bytes([byte]) + data[pos + 1 :]


@st.composite
def mutated(draw):
    name = draw(st.sampled_from(sorted(SOURCES)))
    data = SOURCES[name]
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["flip", "truncate", "swap", "delete_line", "dup_line", "junk", "cut_range"]))
        if kind == "flip":
            data = _flip(data, draw(st.integers(0, len(data))), draw(st.integers(0, 255)))
        elif kind == "truncate":
            data = data[: draw(st.integers(0, len(data)))]
        elif kind == "cut_range":
            a = draw(st.integers(0, len(data)))
            data = data[:a] + data[a + draw(st.integers(0, 200)) :]
        else:
            lines = data.split(b"\n")
            if kind in ("delete_line", "dup_line"):
                i = draw(st.integers(0, len(lines) - 1))
                lines = lines[:i] + lines[i + 1 :] if kind == "delete_line" else lines[: i + 1] + lines[i:]
            else:
                # token-level edits on one or two lines (the header or the frame rows)
                i = draw(st.integers(0, len(lines) - 1))
                words = lines[i].split(b" ")
                k = draw(st.integers(0, max(len(words) - 1, 0)))
                if kind == "swap":
                    j = draw(st.integers(0, len(lines) - 1))
                    other = lines[j].split(b" ")
                    m = draw(st.integers(0, max(len(other) - 1, 0)))
                    if words and other:
                        words[k], other[m] = other[m], words[k]
                        if i == j:
                            other = words
                        lines[j] = b" ".join(other)
                elif words:
                    words[k] = draw(st.sampled_from(JUNK))
                lines[i] = b" ".join(words)
            data = b"\n".join(lines)
    return name, data


@settings(max_examples=250, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(case=mutated(), clean=st.booleans())
def test_mutated_files_raise_only_bvh_error(case, clean):
    name, data = case
    path = Path(_TMP.name) / name
    path.write_bytes(data)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a numerical warning would mean garbage reached the arithmetic
        try:
            motion = load_bvh(path, clean=clean)
        except BvhError as e:
            msg = str(e)
            assert msg and "\n" not in msg and "\r" not in msg
            assert e.line is None or e.line >= 1
            return
    assert isinstance(motion, Motion) and motion.n_frames >= 1
    assert np.all(np.isfinite(motion.root_positions)) and np.all(np.isfinite(motion.rotations))
    assert np.allclose(np.linalg.norm(motion.rotations, axis=-1), 1.0)


@pytest.mark.parametrize("name", sorted(SOURCES))
def test_unmutated_sources_load(name):
    path = Path(_TMP.name) / f"ok_{name}"
    path.write_bytes(SOURCES[name])
    load_bvh(path, clean=False)
