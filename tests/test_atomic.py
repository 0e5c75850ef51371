"""io.atomic: the output guard and all-or-none groups of writes (issue 18: one output guard)."""
import os

import pytest

from froude.io.atomic import OutputError, atomic_group, atomic_write_text, check_outputs, is_temporary


def test_group_lands_together_or_not_at_all(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    with pytest.raises(RuntimeError):
        with atomic_group():
            atomic_write_text(a, "A")
            assert not a.exists()  # inside a group nothing lands before the end
            raise RuntimeError("stop")
    assert sorted(os.listdir(tmp_path)) == []  # temporaries removed too
    with atomic_group():
        atomic_write_text(a, "A")
        with atomic_group():  # nested groups join the outer one
            atomic_write_text(b, "B")
        assert not b.exists()
    assert a.read_text() == "A" and b.read_text() == "B"


def test_interrupt_inside_a_group_leaves_nothing(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        with atomic_group():
            atomic_write_text(tmp_path / "a.txt", "A")
            raise KeyboardInterrupt
    assert os.listdir(tmp_path) == []


def test_guard(tmp_path):
    clip = tmp_path / "in.bvh"
    clip.write_text("x")
    os.symlink(clip, tmp_path / "link.bvh")
    (tmp_path / "d").mkdir()
    with pytest.raises(OutputError, match="would overwrite the input"):
        check_outputs([tmp_path / "link.bvh"], [clip])
    with pytest.raises(OutputError, match="given twice"):
        check_outputs([tmp_path / "o.bvh", tmp_path / "d" / ".." / "o.bvh"])
    with pytest.raises(OutputError, match="is a folder"):
        check_outputs([tmp_path / "d"])
    with pytest.raises(OutputError, match="is a file, not a folder"):
        check_outputs([clip / "o.bvh"])
    with pytest.raises(OutputError, match="does not exist"):
        check_outputs([tmp_path / "no" / "o.bvh"])
    with pytest.raises(OutputError, match="not a regular file"):
        check_outputs(["/dev/null"])
    check_outputs([tmp_path / "d" / "new" / "o.bvh"], folders=[tmp_path / "d" / "new"])  # a folder to be made
    assert not (tmp_path / "d" / "new").exists()
    assert sorted(os.listdir(tmp_path)) == ["d", "in.bvh", "link.bvh"]  # the probe left nothing


def test_temporary_names():
    assert is_temporary(".o.abcd1234.bvh") and is_temporary(".o.report.abcd1234.json")
    assert not is_temporary("o.bvh") and not is_temporary(".hidden.bvh")
