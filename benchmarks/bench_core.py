"""Benchmark of the core on one core: BVH load, FK, COM, Jacobians, memory.

    python benchmarks/bench_core.py [--frames N] [--repeats R] [--no-hour]

Builds a temporary BVH of N (default 10 000) frames by repeating the real frames of the bundled 09_01 clip
(CMU subject 09, a run; T-pose frame left out), then times ``load_bvh`` on it, FK (``fk_soa`` through
``BodyModel.fk``), FK + whole-body COM (``BodyModel.com``: target >= 200 000 frames/s), and the frame-major
COM + COM Jacobian and foot-marker point Jacobians. Prints the bytes per frame of a Motion and the peak RSS
of loading a 1-hour 120 Hz clip (432 000 frames) in a fresh process (skip with --no-hour).
"""
import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from froude import BodyModel, load_bvh  # noqa: E402
from froude.core.kinematics import com_jacobian, forward_kinematics, point_jacobian, points_world  # noqa: E402
from froude.io.samples import sample_path  # noqa: E402

TARGET_FK_COM = 200_000  # frames/s, issue 2


def write_long_clip(path: Path, n_frames: int, source: Path | None = None) -> None:
    """A BVH of n_frames made by repeating the source clip's mocap frames (its first, T-pose, row skipped)."""
    text = (source or sample_path()).read_text().replace("\r\n", "\n")
    header = text[: text.index("MOTION")]
    lines = text[text.index("MOTION") :].split("\n")
    frame_time = lines[2]
    rows = [r for r in lines[3:] if r.strip()][1:]
    with open(path, "w") as f:
        f.write(f"{header}MOTION\nFrames: {n_frames}\n{frame_time}\n")
        block = "\n".join(rows) + "\n"
        for _ in range(n_frames // len(rows)):
            f.write(block)
        rest = n_frames % len(rows)
        if rest:
            f.write("\n".join(rows[:rest]) + "\n")


def best_time(fn, repeats: int) -> float:
    fn()  # warm-up: imports, first-call allocations
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def rate(n: int, seconds: float) -> str:
    return f"{n / seconds:>12,.0f} frames/s  ({seconds * 1e3:8.2f} ms)"


def hour_peak_rss(tmp: Path) -> str:
    """Peak RSS of a fresh process that loads a 1-hour 120 Hz clip (measured, not estimated)."""
    n = 3600 * 120
    path = tmp / "hour.bvh"
    write_long_clip(path, n)
    size_mb = path.stat().st_size / 1e6
    code = (
        "import resource, time, froude\n"
        "t = time.perf_counter()\n"
        f"m = froude.load_bvh({str(path)!r})\n"
        "dt = time.perf_counter() - t\n"
        "print(m.n_frames, dt, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    )
    env = dict(os.environ)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    frames, seconds, rss_kb = out.split()
    path.unlink()
    return (f"1-hour 120 Hz clip ({int(frames):,} frames, file {size_mb:,.0f} MB): load {float(seconds):.1f} s "
            f"= {int(frames) / float(seconds):,.0f} frames/s, peak RSS {int(rss_kb) / 1024:,.0f} MB")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-hour", action="store_true", help="skip the 1-hour clip memory measurement")
    args = ap.parse_args()
    n = args.frames
    load_before = os.getloadavg()

    with tempfile.TemporaryDirectory(prefix="froude-bench-") as tmp:
        tmp = Path(tmp)
        path = tmp / "long.bvh"
        write_long_clip(path, n)
        t_load = best_time(lambda: load_bvh(path), max(1, args.repeats // 2))
        motion = load_bvh(path)
        assert motion.n_frames == n, motion.n_frames
        body = BodyModel.from_skeleton(motion.skeleton)
        J = motion.skeleton.n_joints

        t_fk = best_time(lambda: body.fk(motion), args.repeats)
        t_com = best_time(lambda: body.com(motion), args.repeats)
        t_com_mk = best_time(lambda: body.com_and_markers(motion), args.repeats)

        def com_and_jacobian():
            p, R = forward_kinematics(motion.skeleton, motion.root_positions, motion.rotations)
            return com_jacobian(motion.skeleton, p, R, body.seg_mass, body.seg_joint, body.segment_points(p, R))

        t_comjac = best_time(com_and_jacobian, max(1, args.repeats // 2))

        joint_index = body.marker_joint.reshape(-1)
        p_local = body.marker_local.reshape(-1, 3)

        def marker_jacobians():
            p, R = forward_kinematics(motion.skeleton, motion.root_positions, motion.rotations)
            return point_jacobian(motion.skeleton, p, R, joint_index, points_world(p, R, joint_index, p_local))

        t_ptjac = best_time(marker_jacobians, max(1, args.repeats // 2))

        bytes_per_frame = (motion.root_positions.nbytes + motion.rotations.nbytes
                           + (0 if motion.translations is None else motion.translations.nbytes)) / n
        print(f"froude core benchmark: {n:,} frames of CMU 09_01 repeated, {J} joints, "
              f"{motion.skeleton.n_channels} channels; one core (OMP/OPENBLAS/MKL_NUM_THREADS=1); best of "
              f"{args.repeats}; load average before: {', '.join(f'{x:.2f}' for x in load_before)} "
              f"(figures are only meaningful on an otherwise idle machine)")
        print(f"  load_bvh                          {rate(n, t_load)}   file {path.stat().st_size / 1e6:.1f} MB")
        print(f"  FK (fk_soa via BodyModel.fk)      {rate(n, t_fk)}")
        com_rate = n / t_com
        print(f"  FK + COM (BodyModel.com)          {rate(n, t_com)}   target >= {TARGET_FK_COM:,}: "
              f"{'PASS' if com_rate >= TARGET_FK_COM else 'FAIL'}")
        print(f"  FK + COM + 6 foot markers         {rate(n, t_com_mk)}")
        print(f"  FK + COM + COM Jacobian (3x{3 + 3 * J}) {rate(n, t_comjac)}")
        print(f"  FK + 6 marker Jacobians (6x3x{3 + 3 * J}) {rate(n, t_ptjac)}")
        print(f"  memory: a Motion holds {bytes_per_frame:,.0f} bytes/frame "
              f"(root 3 + rotations {J}x4 float64) = {bytes_per_frame * 432_000 / 1e6:,.0f} MB for 1 h at 120 Hz")
        print(f"  peak RSS of this process so far: "
              f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:,.0f} MB")
        if not args.no_hour:
            print("  " + hour_peak_rss(tmp))


if __name__ == "__main__":
    main()
