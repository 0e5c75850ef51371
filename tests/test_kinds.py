"""Gait as one type (issue 27 acceptance 4): the pipeline, report, studio and batch ask a motion's kind
(``froude.flow.kinds``) and never which one it is; a third kind is added through the protocol alone."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from froude.flow import kinds, pipeline

from conftest import clip

SRC = Path(__file__).resolve().parents[1] / "src" / "froude"
#: The modules that must not branch on the gait: the orchestration, the report, the studio and batch.
ASKERS = ("flow/pipeline.py", "flow/prepared.py", "flow/speed_range.py", "flow/speed_change.py", "flow/speed_goal.py",
          "flow/result.py", "flow/naive.py", "report/metrics.py", "report/path_report.py", "api.py", "apps/studio",
          "apps/batch", "apps/cli")
#: A test of which gait a motion is: the machine's kind, a report's "machine" field or the walking helpers.
BRANCH = re.compile(r"is_walking\(|[=!]= *[\"']walking[\"']|[\"']walking[\"'] *[=!]=|\bwalks\(|\.order *[=!]=")


def _sources():
    for name in ASKERS:
        p = SRC / name
        yield from (sorted(p.rglob("*.py")) if p.is_dir() else [p])


def test_no_gait_branching_where_the_kind_is_asked():
    hits = [f"{p.relative_to(SRC)}:{i}: {line.strip()}" for p in _sources()
            for i, line in enumerate(p.read_text().splitlines(), 1)
            if BRANCH.search(line) and not line.lstrip().startswith("#")]
    assert not hits, "gait branching outside froude.flow.kinds:\n" + "\n".join(hits)


def test_the_branch_pattern_catches_what_it_is_for():
    for line in ('if is_walking(prep.machine):', 'if r.extras.get("machine") == "walking":',
                 'if cyc.order == "walking":', "if walks(summary) and not running_only:"):
        assert BRANCH.search(line), line


class Hopping:
    """A toy third kind: the running machine under another name, with its own report part and summary row
    and one IK repair pass more. Only the protocol is implemented: nothing else in froude knows it."""

    name = "hopping"
    has_flight = True
    repair_rounds = 2

    def __getattr__(self, attr):  # fit, machine_at_speed, scale_path, speed_change: the running machine's
        return getattr(kinds.RUNNING, attr)

    def takes(self, summary) -> bool:
        return summary.kind == "running"

    def report_extras(self, prep, res, report) -> dict:
        return {"hopping": {"hops": len(res.path.foot_of_step)}}

    def summary_rows(self, report) -> list[tuple[str, str]]:
        return [("hops", str(report.extras["hopping"]["hops"]))]

    def speed_refusal(self, character, factor, speed_m_s, err) -> str:
        return f"{character} cannot hop at x{factor:g}"


@pytest.fixture
def hopping():
    kinds.register(Hopping())
    try:
        yield
    finally:
        kinds.unregister("hopping")


def test_a_third_kind_through_the_protocol_alone(hopping):
    prep = pipeline.prepare(clip("09_01"))
    assert prep.kind.name == "hopping"
    res = pipeline.scale(prep, "child", strides=2)
    assert res.report is not None
    assert res.report.extras["machine"] == "hopping"
    assert res.report.extras["hopping"]["hops"] == len(res.path.foot_of_step) == 4
    assert ("hops", "4") in res.summary_rows()
    assert np.isfinite(res.motion.root_positions).all()
    # the kind's own flight bar applies (a run with flights): the child's output meets it
    assert not [f for f in res.report.check_bars() if "flight gravity" in f]


def test_kinds_are_chosen_by_the_one_decision_and_named_once():
    with pytest.raises(ValueError, match="registered already"):
        kinds.register(kinds.Walking())
    assert kinds.kind_named(None) is kinds.RUNNING and kinds.kind_named("walking") is kinds.WALKING
    with pytest.raises(KeyError):
        kinds.kind_named("swimming")
