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

from froude import load_bvh
from froude.apps import batch
from froude.apps.batch import BatchError
from froude.flow import pipeline

from conftest import MOCAP, RUNNING, WALKING, clip

pytest.importorskip("distributed")

REPO = Path(__file__).resolve().parents[1]


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def read_index(outdir) -> list[dict]:
    with open(Path(outdir) / "index.csv", newline="") as f:
        return list(csv.DictReader(f))


def leftovers(outdir) -> list[str]:
    """Hidden files under OUTDIR other than the driver's lock: what an interrupted write leaves. Independent
    of batch.is_temporary on purpose (batch outputs never start with '.')."""
    return sorted(str(p.relative_to(outdir)) for p in Path(outdir).rglob(".*")
                  if p.is_file() and p.name != batch.LOCK_NAME)


def killed_mid_write(path: Path) -> None:
    """Leave what a process killed inside ``atomic_write(path)`` leaves: a subprocess starts the write, writes
    half a file and is SIGKILLed while it sleeps."""
    code = ("import sys, time\nfrom froude.io.atomic import atomic_write\n"
            "def w(tmp):\n    open(tmp, 'w').write('HIERARCHY\\n')\n    print('writing', flush=True)\n"
            "    time.sleep(60)\n"
            "atomic_write(sys.argv[1], w)\n")
    proc = subprocess.Popen([sys.executable, "-c", code, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "writing"
    finally:
        proc.kill()
        proc.wait()


# ---- plans ---------------------------------------------------------------------------------------------
def test_example_plan_parses_and_expands(tmp_path):
    (tmp_path / "chars").mkdir()
    write(tmp_path / "chars" / "elf.yaml", "name: elf\nheight: 1.5\nproportions: {legs: 1.1}\n")
    plan = batch.load_plan(write(tmp_path / "plan.yaml", batch.EXAMPLE_PLAN))
    # characters: child, elf, tall, 7 heights, 3 troll leg scales = 13; each x (4 speeds x 1 strides + 2 accelerations)
    assert len(plan.variations) == 13 * 6
    ids = [v.id for v in plan.variations]
    assert len(set(ids)) == len(ids)
    heights = sorted({dict(v.numbers)["height"] for v in plan.variations
                      if v.character is None and v.character_label.startswith("h")})
    assert heights == pytest.approx([1.0, 1.2, 1.4, 1.6, 1.8, 2.0, 2.2])
    elf = next(v for v in plan.variations if v.character_label == "elf")
    assert elf.character == str(tmp_path / "chars" / "elf.yaml")  # found next to the plan
    v = next(v for v in plan.variations if v.id == "child_v3.5ms_4str")
    assert dict(v.args) == {"target_speed": 3.5, "strides": 4} and v.kind == "scale"
    a = next(v for v in plan.variations if v.id == "tall_to2.5ms_20steps_l2_h4")
    assert a.kind == "accelerate" and dict(a.args)["to_speed"] == 2.5
    assert dict(a.numbers) == {"height": 1.95, "mass": 85}
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
    ("characters: [child]\nspeeds: [fast]\n", "speeds[0]: cannot read 'fast'"),
    ("characters: [child]\nspeeds: [0.8, 80]\n", "speeds[1]: factor 80 is outside"),
    ("characters: [child]\nstrides: 0\n", "strides[0]: a whole number >= 1"),
    ("characters: [child]\naccelerations: [{to_factor: 1.2}]\n", "give exactly one length"),
    ("characters: [child]\naccelerations: [{steps: 8}]\n", "give exactly one goal"),
    ("characters: [child, child]\n", "listed twice"),
    ("characters: [{name: Tall, height: 1.9}, {name: tall, height: 2.0}]\n", "ids are compared ignoring case"),
    ("characters: [{name: '..', height: 1.9}]\n", "characters[0].name: letters, digits"),
    ("characters: [{name: .hidden, height: 1.9}]\n", "starting with a letter or digit"),
    ("characters: [{height: {from: 1.0, to: 2.2, steps: 100000000}}]\n", "characters[0]: expands to 1e+08"),
    ("characters: [{height: {from: 1.0, to: 2.2, steps: 20000}}]\n", "at most 10,000 variations"),
    ("characters: [{height: {from: 1, to: 2, steps: 200}, mass: {from: 50, to: 90, steps: 200}}]\n",
     "expands to 4e+04 characters"),
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


def test_runaway_plan_is_refused_at_once(tmp_path, run_cli):
    """A height range of 1e8 steps (issue 14/18): one line, exit 2, in well under a second, with --dry-run too."""
    plan = write(tmp_path / "plan.yaml", "characters: [{height: {from: 1.0, to: 2.2, steps: 100000000}}]\n")
    t0 = time.perf_counter()
    code, out, err = run_cli("batch", clip("09_01"), "--plan", plan, "-o", tmp_path / "out", "--dry-run")
    assert code == 2 and out == "" and "at most 10,000 variations" in err, err
    assert time.perf_counter() - t0 < 5.0  # unbounded, it grew 180 MB/s until it died
    # tasks are bounded too: clips x variations
    many = batch.parse_plan({"characters": [{"height": {"from": 1.0, "to": 2.0, "steps": 100},
                                                 "mass": {"from": 50, "to": 99, "steps": 50}}], "strides": [1, 2]})
    clips = [batch.Clip(f"c{i}", f"c{i}.bvh") for i in range(101)]
    with pytest.raises(BatchError, match="at most 1,000,000: split it"):
        batch.make_tasks(clips, many)


def test_clip_ids_cannot_collide_or_escape(tmp_path, run_cli):
    """a.bvh and a.BVH would share one output (refused, naming both); '...bvh' gets a safe id inside OUTDIR."""
    clips = tmp_path / "clips"
    (clips / "sub").mkdir(parents=True)
    text = clip("09_01").read_text()
    write(clips / "a.bvh", text)
    write(clips / "A.BVH", text)
    plan = write(tmp_path / "plan.yaml", "characters: [child]\nstrides: 1\n")
    code, out, err = run_cli("batch", clips, "--plan", plan, "-o", tmp_path / "out", "--dry-run")
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1, err
    assert "A.BVH" in err and "a.bvh" in err and "ignoring case" in err
    (clips / "A.BVH").unlink()
    write(clips / "...bvh", text)
    write(clips / "sub" / "..bvh", text)
    write(clips / "sub" / "my clip;rm.bvh", text)
    ids = [c.id for c in batch.find_clips([clips])]
    assert ids == ["__", "a", "sub/_", "sub/my_clip_rm"]
    for c in batch.find_clips([clips]):
        task = batch.make_tasks([c], batch.parse_plan({"characters": ["child"]}))[0]
        dest = (tmp_path / "out" / task.output).resolve()
        assert dest.is_relative_to(tmp_path / "out") and not any(p.startswith(".") for p in Path(task.output).parts)


def test_outdir_is_never_an_input(tmp_path, run_cli):
    """'froude batch same -o same' took the previous outputs for new clips on every rerun: now OUTDIR inside
    an input folder is skipped, and OUTDIR itself (or a file in it) given as an input is refused."""
    clips = tmp_path / "clips"
    clips.mkdir()
    write(clips / "run.bvh", clip("09_01").read_text())
    out = clips / "out"
    (out / "run").mkdir(parents=True)
    write(out / "run" / "child_x1_1str.bvh", clip("09_02").read_text())  # what a previous run wrote
    plan = write(tmp_path / "plan.yaml", "characters: [child]\nstrides: 1\n")
    for inputs in ([clips], [str(clips / "**" / "*.bvh")]):
        code, stdout, err = run_cli("batch", *inputs, "--plan", plan, "-o", out, "--dry-run")
        assert code == 0, err
        assert [l.split("\t")[0] for l in stdout.strip().splitlines()[1:]] == ["run"]
    for inputs in ([out], [clips, out / "run" / "child_x1_1str.bvh"]):
        code, stdout, err = run_cli("batch", *inputs, "--plan", plan, "-o", out, "--dry-run")
        assert code == 2 and "output folder" in err and len(err.strip().splitlines()) == 1, err
    code, stdout, err = run_cli("batch", clips, "--plan", plan, "-o", clips, "--dry-run")
    assert code == 2 and "is the output folder" in err, err


def test_unreachable_scheduler_creates_nothing(tmp_path, run_cli):
    plan = write(tmp_path / "plan.yaml", "characters: [child]\nstrides: 1\n")
    code, out, err = run_cli("batch", clip("09_01"), "--plan", plan, "-o", tmp_path / "out",
                             "--scheduler", "tcp://127.0.0.1:1", "-q")
    assert code == 2 and "cannot reach the Dask scheduler" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "out").exists()


def test_temporaries_are_the_names_atomic_write_uses(tmp_path):
    """The cleanup finds exactly the files atomic_write writes through (taken from real writes), none of the
    outputs; it removes what a process killed mid-write leaves."""
    from froude.io.atomic import atomic_write

    names = []
    for dest in ("child_x1_4str.bvh", "child_x1_4str.report.json", "child_x1_4str.done.json", "index.csv",
                 "index.parquet", "noext"):
        atomic_write(tmp_path / dest, lambda tmp: (names.append(Path(tmp).name), Path(tmp).write_text("x")))
        assert not batch.is_temporary(dest)
    assert len(names) == 6 and all(batch.is_temporary(n) for n in names), names
    assert not batch.is_temporary(batch.LOCK_NAME) and batch.temporaries(tmp_path) == []
    (tmp_path / "clip").mkdir()
    killed_mid_write(tmp_path / "clip" / "child_x1_4str.bvh")
    left = leftovers(tmp_path)
    assert len(left) == 1 and [str(p.relative_to(tmp_path)) for p in batch.temporaries(tmp_path)] == left
    assert batch.clean_stale_temporaries(tmp_path) == 1 and leftovers(tmp_path) == []


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
    bad = batch.prepare_clip(str(clip("02_04")), 70.0, "male", None)  # jumps in place: no machine for it
    row = batch.run_task(bad, batch.Task(batch.Clip("02_04", str(clip("02_04"))), task.variation), plan, str(tmp_path))
    assert row["status"] == "failed" and "locomotion" in row["reason"] and "\n" not in row["reason"]


# ---- acceptance runs on a local Dask cluster -----------------------------------------------------------------
def _bars_failures(rows) -> str:
    bad = [f"{r['clip']}/{r['variation']}: {r['bars_failed']}" for r in rows if r["bars_met"] != "yes"]
    return f"{len(bad)} of {len(rows)} outputs miss physics bars:\n" + "\n".join(bad)


@pytest.mark.slow
def test_acceptance_132_tasks(tmp_path, run_cli):
    """11 clips (9 running, 2 walking) x 4 characters x 3 speeds = 132 rows over runs and walks (issue 17):
    every running row and every walking row at the clip's speed is produced; a walk the machine cannot
    take fails alone, with a one-line reason."""
    if MOCAP is None:
        pytest.skip("real clips not found")
    plan = write(tmp_path / "plan.yaml",
                 "characters: [child, troll, giant, small]\nspeeds: [0.8, 1.0, 1.2]\nstrides: 2\n")
    inputs = [MOCAP / f"{n}.bvh" for n in RUNNING + WALKING]
    out = tmp_path / "out"
    t0 = time.perf_counter()
    code, stdout, err = run_cli("batch", *inputs, "--plan", plan, "-o", out, "--workers", 2)
    elapsed = time.perf_counter() - t0
    rows = read_index(out)
    assert len(rows) == 132
    assert {(r["clip"], r["variation"]) for r in rows} == {
        (c, f"{ch}_x{s}_2str") for c in RUNNING + WALKING for ch in ("child", "troll", "giant", "small")
        for s in ("0.8", "1", "1.2")}
    walking = [r for r in rows if r["clip"] in WALKING]
    running = [r for r in rows if r["clip"] in RUNNING]
    failed = [r for r in rows if r["status"] == "failed"]
    assert code == (1 if failed else 0), err
    assert all(r["reason"] and "\n" not in r["reason"] for r in failed)
    assert [f"{r['clip']}/{r['variation']}: {r['reason']}" for r in running if r["status"] != "ok"] == []
    assert [f"{r['clip']}/{r['variation']}: {r['reason']}" for r in walking
            if r["variation"].endswith("_x1_2str") and r["status"] != "ok"] == []
    assert f"132 tasks: {132 - len(failed)} succeeded, {len(failed)} failed, 0 skipped" in stdout
    # the index agrees with the files: every output loads, its report holds the index's figures
    for r in running[::9]:
        m = load_bvh(out / r["output"])
        assert m.n_frames == int(r["n_frames"])
        rep = json.loads(pipeline.report_path(out / r["output"]).read_text())
        assert rep["froude_U"] == pytest.approx(float(r["froude_U"]), rel=1e-5)
    assert leftovers(out) == []
    print(f"132-task batch on 2 local workers: {elapsed:.1f} s")
    # last: the physics bars (depend on the pipeline, not on the batch): every output meets them but the
    # few that miss the stricter skate bar (measured; a listed one that starts meeting them fails too)
    missing = {f"{r['clip']}/{r['variation']}" for r in running if r["bars_met"] != "yes"}
    assert missing == set(BATCH_MISSES), _bars_failures(running)


#: Outputs of the 132-task plan (2 strides) that miss a bar, measured: none since the skate branch (the last
#: four missed the stricter skate measure at a touchdown or lift-off by 0.2-1.8 mm; benchmarks/bars_matrix.py
#: has the 4-stride matrix). A listed output that starts meeting the bars fails, so that it comes off the list.
BATCH_MISSES: dict = {}


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
    cmd = [sys.executable, "-m", "froude", "batch", *inputs, "--plan", str(plan), "-o", str(out), "-q"]
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
    # no partial output: every BVH in place is complete (a hidden temporary the kill cut short may remain:
    # the rerun must clean it, checked by leftovers() at the end)
    for p in out.rglob("*.bvh"):
        if not p.name.startswith("."):
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
    assert leftovers(out) == []


def _group_workers(pgid: int) -> list[int]:
    """Pids of the Dask worker processes (multiprocessing spawn children) in a process group."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
            cmd = (d / "cmdline").read_bytes().decode(errors="replace")
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[2]) == pgid and "spawn_main" in cmd:
            pids.append(int(d.name))
    return pids


def _start_batch(inputs, plan, out):
    cmd = [sys.executable, "-m", "froude", "batch", *map(str, inputs), "--plan", str(plan), "-o", str(out),
           "-q", "--workers", "2"]
    return subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _wait_markers(proc, out, n, timeout=120.0) -> None:
    deadline = time.monotonic() + timeout
    while len(list(Path(out).rglob("*.done.json"))) < n:
        assert proc.poll() is None, f"batch ended early: {proc.stderr.read()}"
        assert time.monotonic() < deadline, f"fewer than {n} outputs after {timeout} s"
        time.sleep(0.05)


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="finds worker processes through /proc")
def test_worker_killed_mid_write_then_rerun(tmp_path, run_cli):
    """A worker SIGKILLed mid-batch and a temporary left by a write killed midway (a real atomic_write, as a
    worker killed inside it leaves): the run and its rerun leave no temporary, and the index lists as done
    exactly the tasks with done-markers."""
    if MOCAP is None:
        pytest.skip("real clips not found")
    plan = write(tmp_path / "plan.yaml", "characters: [child, small]\nspeeds: [0.9, 1.0, 1.1]\nstrides: 2\n")
    inputs = [MOCAP / f"{n}.bvh" for n in ("09_02", "09_03")]
    out = tmp_path / "out"
    (out / "09_02").mkdir(parents=True)
    killed_mid_write(out / "09_02" / "small_x1_2str.bvh")
    assert len(leftovers(out)) == 1
    proc = _start_batch(inputs, plan, out)
    try:
        _wait_markers(proc, out, 2)
        workers = _group_workers(proc.pid)
        assert len(workers) == 2, workers
        killed_mid_write(out / "09_03" / "child_x1_2str.bvh")  # what a worker killed inside a write leaves
        # The run removes orphans once every task has ended. A task still unfinished now means that removal is
        # still to come; on a loaded machine the last tasks can end while the orphan is being made (a
        # whole-suite run once saw it left), and then only the rerun below can be held to removing it.
        made_while_running = len(list(out.rglob("*.done.json"))) < 12
        try:
            os.kill(workers[0], signal.SIGKILL)
        except ProcessLookupError:  # the run ended (its workers with it) while the orphan was being made
            made_while_running = False
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode in (0, 1), err  # a task whose worker died may fail (KilledWorker); the rerun redoes it
    if made_while_running:
        assert leftovers(out) == []

    def check_index():
        done = {str(m.relative_to(out)).replace(".done.json", ".bvh") for m in out.rglob("*.done.json")}
        rows = read_index(out)
        assert len(rows) == 12
        assert {r["output"] for r in rows if r["status"] in ("ok", "skipped")} == done

    check_index()
    code, _, err = run_cli("batch", *inputs, "--plan", plan, "-o", out, "--workers", 2, "-q")
    assert code == 0, err
    check_index()
    assert {r["status"] for r in read_index(out)} <= {"ok", "skipped"}
    assert leftovers(out) == []
    for p in out.rglob("*.bvh"):
        load_bvh(p)


@pytest.mark.slow
def test_workers_end_with_the_driver(tmp_path):
    """SIGKILL of the driver alone (not its process group): the Dask worker processes end by themselves."""
    if MOCAP is None:
        pytest.skip("real clips not found")
    plan = write(tmp_path / "plan.yaml", "characters: [child, small]\nspeeds: [0.9, 1.0, 1.1]\nstrides: 3\n")
    proc = _start_batch([MOCAP / f"{n}.bvh" for n in ("09_02", "09_03")], plan, tmp_path / "out")
    try:
        _wait_markers(proc, tmp_path / "out", 1)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        t0 = time.monotonic()
        _wait_group_gone(proc.pid, timeout=30.0)
        print(f"workers gone {time.monotonic() - t0:.1f} s after the driver's SIGKILL")
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


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
    cmd = [sys.executable, "-m", "froude", "batch", *(str(MOCAP / f"{n}.bvh") for n in ("09_02", "09_03", "09_04")),
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
    assert leftovers(out) == []


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
