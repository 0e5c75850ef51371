"""froude batch: plan parsing, done-markers, and the issue-8 acceptance runs on a local Dask cluster.

The Dask runs (marked slow) use the real clips: the 132-task batch of the acceptance criteria, a SIGKILL
of the driver's process group followed by a resume, and a corrupted BVH among good clips.
"""
from __future__ import annotations

import csv
import json
import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import MOCAP, RUNNING, WALKING, clip
from froude import batch, load_bvh, pipeline
from froude.batch import BatchError

pytest.importorskip("distributed")

REPO = Path(__file__).resolve().parents[1]


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def read_index(outdir) -> list[dict]:
    with open(Path(outdir) / "index.csv", newline="") as f:
        return list(csv.DictReader(f))


# ---- plans ---------------------------------------------------------------------------------------------
def test_example_plan_parses_and_expands(tmp_path):
    (tmp_path / "chars").mkdir()
    write(tmp_path / "chars" / "elf.yaml", "name: elf\nheight: 1.5\nproportions: {legs: 1.1}\n")
    plan = batch.load_plan(write(tmp_path / "plan.yaml", batch.EXAMPLE_PLAN))
    # characters: child, elf, tall, 7 heights, 3 troll leg scales = 13; each x (4 speeds x 1 strides + 2 accelerations)
    assert len(plan.variations) == 13 * 6
    ids = [v.id for v in plan.variations]
    assert len(set(ids)) == len(ids)
    heights = sorted({dict(v.numbers)["height"] for v in plan.variations if v.character is None and v.character_label.startswith("h")})
    assert heights == pytest.approx([1.0, 1.2, 1.4, 1.6, 1.8, 2.0, 2.2])
    elf = next(v for v in plan.variations if v.character_label == "elf")
    assert elf.character == str(tmp_path / "chars" / "elf.yaml")  # found next to the plan
    v = next(v for v in plan.variations if v.id == "child_v3.5ms_4str")
    assert dict(v.args) == {"target_speed": 3.5, "strides": 4} and v.kind == "scale"
    a = next(v for v in plan.variations if v.id == "tall_to2.5ms_20steps_l2_h4")
    assert a.kind == "accelerate" and dict(a.args)["to_speed"] == 2.5 and dict(a.numbers) == {"height": 1.95, "mass": 85}
    assert plan.reference_mass == 70 and plan.length_scale is None


@pytest.mark.parametrize("text, words", [
    ("characters: [child\n  speeds: 3\n", "plan.yaml:2: YAML syntax error"),
    ("- child\n", "a plan is a YAML mapping"),
    ("charactres: [child]\n", "charactres: unknown key"),
    ("characters: [kid]\n", "characters[0]: unknown character 'kid'"),
    ("characters: [missing.yaml]\n", "missing.yaml: no such character file"),
    ("characters: [{height: {from: 1.0, to: 2.2}}]\n", "characters[0].height: a range is"),
    ("characters: [{height: -1}]\n", "characters[0].height: a number > 0"),
    ("characters: [{height: 1.5, wings: 2}]\n", "characters[0].wings: unknown key"),
    ("characters: [child]\nspeeds: [fast]\n", "speeds[0]: a factor"),
    ("characters: [child]\nstrides: 0\n", "strides[0]: a whole number >= 1"),
    ("characters: [child]\naccelerations: [{to_factor: 1.2}]\n", "give exactly one length"),
    ("characters: [child]\naccelerations: [{steps: 8}]\n", "give exactly one goal"),
    ("characters: [child, child]\n", "listed twice"),
    ("characters: [child]\nspeeds: []\n", "no variations"),
])
def test_bad_plans_are_one_line_errors_with_exit_2(tmp_path, run_cli, text, words):
    plan = write(tmp_path / "plan.yaml", text)
    with pytest.raises(BatchError, match=None) as e:
        batch.load_plan(plan)
    assert words in str(e.value) and "\n" not in str(e.value)
    code, out, err = run_cli("batch", clip("09_01"), "--plan", plan, "-o", tmp_path / "out", "--dry-run")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and words in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_bad_inputs_exit_2(tmp_path, run_cli):
    plan = write(tmp_path / "plan.yaml", "characters: [child]\n")
    for bad in (tmp_path / "nope.bvh", tmp_path / "*.nothing", tmp_path):
        code, _, err = run_cli("batch", bad, "--plan", plan, "-o", tmp_path / "out", "--dry-run")
        assert code == 2 and len(err.strip().splitlines()) == 1, err


def test_dry_run_lists_tasks_and_help_shows_the_example(tmp_path, run_cli):
    plan = write(tmp_path / "plan.yaml", "characters: [child, {height: {from: 1.0, to: 2.2, steps: 7}}]\n"
                 "speeds: [0.8, 1.2]\nstrides: 2\n")
    code, out, err = run_cli("batch", MOCAP / "09_0[12].bvh" if MOCAP else clip("09_01"), MOCAP / "02_03.bvh",
                             "--plan", plan, "-o", tmp_path / "out", "--dry-run")
    assert code == 0, err
    lines = out.strip().splitlines()
    assert len(lines) == 1 + 3 * 8 * 2
    assert "02_03\th1.4_x0.8_2str\tscale\theight=1.4 speed=0.8 strides=2\t02_03/h1.4_x0.8_2str.bvh\tto do" in lines
    assert "48 tasks" in err and not (tmp_path / "out").exists()
    code, out, _ = run_cli("batch", "--help")
    assert code == 0 and "characters:" in out and "{from: 1.0, to: 2.2, steps: 7}" in out


# ---- the work of one task, without Dask ---------------------------------------------------------------------
def test_prepared_pickles_and_done_marker_guards_reruns(tmp_path):
    plan = batch.parse_plan({"characters": ["child"], "speeds": [1.0], "strides": 1})
    c = batch.find_clips([clip("09_02")])[0]
    prepped = batch.prepare_clip(c.path, 70.0, "male", None)
    assert prepped.error == ""
    # Dask ships the fitted clip to the variation tasks: it must survive pickling and give the same result
    again = pickle.loads(pickle.dumps(prepped))
    task = batch.make_tasks([c], plan)[0]
    row = batch.run_task(again, task, plan, str(tmp_path))
    assert row["status"] == "ok", row
    direct = pipeline.scale(prepped.prep, "child", speed=1.0, strides=1)
    assert row["n_frames"] == direct.motion.n_frames
    assert row["froude_U"] == pytest.approx(direct.report.froude_U, rel=1e-9)
    out = tmp_path / task.output
    assert load_bvh(out).n_frames == row["n_frames"]
    assert json.loads(pipeline.report_path(out).read_text())["froude_U"] == pytest.approx(row["froude_U"])
    done = batch.read_done(tmp_path, task, plan)
    assert done is not None and done["variation"] == task.variation.id
    # another plan giving the same id different parameters is not "done"
    other = batch.parse_plan({"characters": ["child"], "speeds": [1.0], "strides": 1, "reference": {"mass": 80}})
    assert batch.read_done(tmp_path, batch.make_tasks([c], other)[0], other) is None
    # a damaged output is not done
    out.write_text(out.read_text()[:-10])
    assert batch.read_done(tmp_path, task, plan) is None
    # a failing clip fails its task with the reason, one line
    bad = batch.prepare_clip(str(clip("02_01")), 70.0, "male", None)
    row = batch.run_task(bad, batch.Task(batch.Clip("02_01", str(clip("02_01"))), task.variation), plan, str(tmp_path))
    assert row["status"] == "failed" and "walking" in row["reason"] and "\n" not in row["reason"]


# ---- acceptance runs on a local Dask cluster -----------------------------------------------------------------
def _bars_failures(rows) -> str:
    bad = [f"{r['clip']}/{r['variation']}: {r['bars_failed']}" for r in rows if r["bars_met"] != "yes"]
    return f"{len(bad)} of {len(rows)} outputs miss physics bars:\n" + "\n".join(bad)


@pytest.mark.slow
def test_acceptance_132_tasks(tmp_path, run_cli):
    """11 clips (9 running, 2 walking) x 4 characters x 3 speeds = 132 rows; the walking 24 fail with the reason."""
    if MOCAP is None:
        pytest.skip("real clips not found")
    plan = write(tmp_path / "plan.yaml", "characters: [child, troll, giant, small]\nspeeds: [0.8, 1.0, 1.2]\nstrides: 2\n")
    inputs = [MOCAP / f"{n}.bvh" for n in RUNNING + WALKING]
    out = tmp_path / "out"
    t0 = time.perf_counter()
    code, stdout, err = run_cli("batch", *inputs, "--plan", plan, "-o", out, "--workers", 2)
    elapsed = time.perf_counter() - t0
    assert code == 1, err  # some tasks (the walking clips) failed
    rows = read_index(out)
    assert len(rows) == 132
    assert {(r["clip"], r["variation"]) for r in rows} == {
        (c, f"{ch}_x{s}_2str") for c in RUNNING + WALKING for ch in ("child", "troll", "giant", "small") for s in ("0.8", "1", "1.2")}
    walking = [r for r in rows if r["clip"] in WALKING]
    running = [r for r in rows if r["clip"] in RUNNING]
    assert len(walking) == 24 and all(r["status"] == "failed" for r in walking)
    assert all("walking, not running" in r["reason"] for r in walking)
    assert [f"{r['clip']}/{r['variation']}: {r['reason']}" for r in running if r["status"] != "ok"] == []
    assert "132 tasks: 108 succeeded, 24 failed, 0 skipped" in stdout
    # the index agrees with the files: every output loads, its report holds the index's figures
    for r in running[::9]:
        m = load_bvh(out / r["output"])
        assert m.n_frames == int(r["n_frames"])
        rep = json.loads(pipeline.report_path(out / r["output"]).read_text())
        assert rep["froude_U"] == pytest.approx(float(r["froude_U"]), rel=1e-5)
    assert not list(out.rglob("*.tmp"))
    print(f"132-task batch on 2 local workers: {elapsed:.1f} s")
    # last: the physics bars (depend on the pipeline, not on the batch)
    assert all(r["bars_met"] == "yes" for r in running), _bars_failures(running)


def _done_files(outdir) -> dict:
    """{path: (inode, mtime_ns)} of every finished task's three files."""
    out = {}
    for m in Path(outdir).rglob("*.done.json"):
        bvh = m.with_name(m.name.replace(".done.json", ".bvh"))
        for p in (bvh, pipeline.report_path(bvh), m):
            st = p.stat()
            out[str(p)] = (st.st_ino, st.st_mtime_ns)
    return out


@pytest.mark.slow
def test_sigkill_midway_then_resume(tmp_path, run_cli):
    """SIGKILL of the driver's process group mid-batch: no partial file; a re-run finishes and redoes nothing done."""
    if MOCAP is None:
        pytest.skip("real clips not found")
    plan = write(tmp_path / "plan.yaml", "characters: [child, small]\nspeeds: [0.9, 1.0, 1.1]\nstrides: 2\n")
    inputs = [str(MOCAP / f"{n}.bvh") for n in ("09_02", "09_03", "09_04")]
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "froude.cli", "batch", *inputs, "--plan", str(plan), "-o", str(out), "-q"]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while len(list(out.rglob("*.done.json"))) < 3:
            assert proc.poll() is None, f"batch ended before it could be killed: {proc.stderr.read().decode()}"
            assert time.monotonic() < deadline, "no outputs after 120 s"
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the driver, the scheduler and every worker process
        proc.wait()
    _wait_group_gone(proc.pid)
    n_done = len(list(out.rglob("*.done.json")))
    assert 3 <= n_done < 18, "kill came too late to test a resume"
    for p in out.rglob("*.bvh"):  # no partial output: every BVH is complete
        load_bvh(p)
    before = _done_files(out)
    code, stdout, err = run_cli("batch", *inputs, "--plan", plan, "-o", out, "--workers", 2, "-q")
    assert code == 0, err
    rows = read_index(out)
    assert len(rows) == 18 and all(r["status"] in ("ok", "skipped") for r in rows)
    assert sum(r["status"] == "skipped" for r in rows) == n_done
    after = _done_files(out)
    assert len(after) == 3 * 18
    assert {p: after[p] for p in before} == before  # nothing finished was redone
    for p in out.rglob("*.bvh"):
        load_bvh(p)
    assert not list(out.rglob("*.tmp"))


def _wait_group_gone(pgid: int, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.1)
    raise AssertionError(f"processes of group {pgid} still alive {timeout} s after SIGKILL")


@pytest.mark.slow
def test_corrupted_bvh_fails_alone(tmp_path, run_cli):
    src = clip("09_01").read_text().splitlines(keepends=True)
    clips = tmp_path / "clips"
    clips.mkdir()
    write(clips / "good.bvh", clip("09_02").read_text())
    bad_line = next(i for i, l in enumerate(src) if "OFFSET" in l and i > 10)
    src[bad_line] = src[bad_line].replace("OFFSET", "OFFSET oops")
    write(clips / "broken.bvh", "".join(src))
    plan = write(tmp_path / "plan.yaml", "characters: [child, {height: [1.6, 1.9]}]\nspeeds: [1.0]\nstrides: 1\n")
    out = tmp_path / "out"
    code, stdout, err = run_cli("batch", clips, "--plan", plan, "-o", out, "--workers", 1, "-q")
    assert code == 1, err
    rows = {(r["clip"], r["variation"]): r for r in read_index(out)}
    assert len(rows) == 6
    for v in ("child_x1_1str", "h1.6_x1_1str", "h1.9_x1_1str"):
        assert rows[("good", v)]["status"] == "ok", rows[("good", v)]
        assert load_bvh(out / "good" / f"{v}.bvh").n_frames == int(rows[("good", v)]["n_frames"])
        bad = rows[("broken", v)]
        assert bad["status"] == "failed"
        assert f"broken.bvh:{bad_line + 1}" in bad["reason"], bad["reason"]
        assert not (out / "broken" / f"{v}.bvh").exists()
    assert float(rows[("good", "h1.9_x1_1str")]["char_height_m"]) == pytest.approx(1.9, rel=1e-6)
    assert "3 succeeded, 3 failed" in stdout and "broken.bvh" in stdout


@pytest.mark.slow
def test_ctrl_c_stops_cleanly(tmp_path):
    """SIGINT to the whole process group (what Ctrl-C does): exit 130, one line, an index that matches OUTDIR."""
    if MOCAP is None:
        pytest.skip("real clips not found")
    plan = write(tmp_path / "plan.yaml", "characters: [child, small]\nspeeds: [0.9, 1.0, 1.1]\nstrides: 2\n")
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "froude.cli", "batch", *(str(MOCAP / f"{n}.bvh") for n in ("09_02", "09_03", "09_04")),
           "--plan", str(plan), "-o", str(out), "-q"]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while len(list(out.rglob("*.done.json"))) < 2:
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130
    assert stderr.strip() == "froude batch: interrupted" and stdout == ""
    _wait_group_gone(proc.pid)
    rows = read_index(out)
    assert len(rows) == 18 and {r["status"] for r in rows} <= {"ok", "pending"}
    done = {str(m.relative_to(out)).replace(".done.json", ".bvh") for m in out.rglob("*.done.json")}
    assert {r["output"] for r in rows if r["status"] == "ok"} == done
    bvhs = {str(p.relative_to(out)) for p in out.rglob("*.bvh")}
    assert done <= bvhs
    for p in bvhs:  # complete, even one whose worker stopped before its marker
        load_bvh(out / p)
    assert not list(out.rglob("*.tmp"))


@pytest.mark.slow
def test_existing_scheduler(tmp_path, run_cli):
    """--scheduler ADDRESS: the tasks run on a cluster the batch did not start (and leaves running)."""
    from distributed import Client, LocalCluster

    plan = write(tmp_path / "plan.yaml", "characters: [small]\nspeeds: [1.0]\nstrides: 1\n"
                 "accelerations: [{to_factor: 1.1, steps: 40}]\n")
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        code, stdout, err = run_cli("batch", clip("09_03"), "--plan", plan, "-o", tmp_path / "out",
                                    "--scheduler", cluster.scheduler_address, "-q")
        with Client(cluster) as c:
            assert len(c.nthreads()) == 1  # still up
    rows = {r["variation"]: r for r in read_index(tmp_path / "out")}
    assert set(rows) == {"small_x1_1str", "small_to1.1x_40steps"}
    assert rows["small_x1_1str"]["status"] == "ok", rows
    acc = rows["small_to1.1x_40steps"]
    assert acc["kind"] == "accelerate" and acc["to_factor"] == "1.1"
    assert acc["status"] == "ok", acc  # a gentle change (+10 % over 40 steps) the planner can make
    assert code == 0, err
    assert "2 succeeded" in stdout


def test_parquet_index_when_pyarrow_is_installed(tmp_path):
    pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    plan = batch.parse_plan({"characters": ["child", "giant"], "speeds": [1.0]})
    rows = [batch.base_row(t) for t in batch.make_tasks([batch.Clip("a", "a.bvh")], plan)]
    path = batch.write_parquet(tmp_path, rows)
    table = pq.read_table(path)
    assert table.num_rows == 2 and table.column_names == list(batch.INDEX_COLUMNS)
