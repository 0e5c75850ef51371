"""Studio latency: from a control change to the new motion at the page (issue 7, bar: <= 50 ms median).

Runs the studio as ``froude view`` does (worker and player threads running, the runners playing at 30 Hz as
solid limbs) on the embedded sample, 4 strides at 120 Hz, with one live websocket client speaking viser's
protocol and draining like a browser tab (it gets its own session, as a tab does). Each change is posted
with ``Tab.request`` — what every GUI handler calls —
and the clock stops when a message carrying the new motion's hash (the page's state readout, sent in the
same flush as the runner's new pose) reaches the client. The hash is known in advance from an identical
session on a second copy of the clip, so nothing is cached for the studio. Speeds and heights are all
different (the speed and height sliders); the character presets repeat, as when a user flips between them
(a preset's body is built once per clip and remembered).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_studio.py [--repeats 15]

Prints per kind of change: change -> first new motion at the page (the preview, when the studio expects a
slow result and shows one), change -> IK-corrected result at the page (the bar), and the worker's own
compute and push times.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import socket  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _tab_process(url: str, version: str, conn) -> None:
    """A browser tab stand-in in its own process (as a browser is): a websocket client speaking viser's
    subprotocol that decodes every message as it arrives and answers "when did the first message after t0
    containing this text arrive?" (perf_counter is the system's monotonic clock, the same in both)."""
    import zstandard  # viser's own dependency
    from websockets.sync.client import connect

    ws = connect(url, subprotocols=[f"viser-v{version}"], max_size=None, open_timeout=10)
    arrivals: list[tuple[float, bytes]] = []
    arrived = threading.Condition()

    def drain() -> None:
        unzip = zstandard.ZstdDecompressor()
        try:
            for msg in ws:
                t = time.perf_counter()
                # viser's frame: [u64 msgpack size][u64 zstd size][zstd(msgpack)][binary buffers]
                size, packed = int.from_bytes(msg[:8], "little"), int.from_bytes(msg[8:16], "little")
                body = unzip.decompress(msg[16:16 + packed], max_output_size=size)
                with arrived:
                    arrivals.append((t, body))
                    arrived.notify_all()
        except Exception:
            pass

    threading.Thread(target=drain, daemon=True).start()
    import msgspec  # viser's own dependency

    # what a page sends first: viser opens the tab's session at its first camera message
    ws.send(msgspec.msgpack.encode({
        "type": "ViewerCameraMessage", "wxyz": (1.0, 0.0, 0.0, 0.0), "position": (0.0, 1.0, 4.0), "fov": 0.9,
        "near": 0.01, "far": 100.0, "image_height": 800, "image_width": 1280, "look_at": (0.0, 1.0, 0.0),
        "up_direction": (0.0, 1.0, 0.0)}))
    conn.send("ready")
    while True:
        req = conn.recv()
        if req is None:
            break
        needle, t0, timeout = req
        t_end, seen, found = time.perf_counter() + timeout, 0, float("nan")
        with arrived:
            while found != found:
                for t, body in arrivals[seen:]:
                    if t >= t0 and needle in body:
                        found = t
                        break
                seen = len(arrivals)
                left = t_end - time.perf_counter()
                if found != found and (left <= 0 or not arrived.wait(left)):
                    break
        conn.send(found)
    ws.close()


class _Tab:
    """The parent's handle on the tab process."""

    def __init__(self, url: str, version: str):
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_tab_process, args=(url, version, child), daemon=True)
        self.proc.start()
        assert self.conn.recv() == "ready"

    def arrival_of(self, needle: bytes, t0: float, timeout: float = 10.0) -> float:
        """When the first message after t0 containing ``needle`` reached the tab (NaN after timeout)."""
        self.conn.send((needle, t0, timeout))
        return self.conn.recv()

    def close(self) -> None:
        self.conn.send(None)
        self.proc.join(timeout=5)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15, help="changes per kind (default 15)")
    args = ap.parse_args()

    import viser

    from froude.apps.studio.app import Studio
    from froude.apps.studio.session import Params, Session
    from froude.flow import pipeline
    from froude.io.samples import sample_path

    t = time.perf_counter()
    prep = pipeline.prepare(sample_path())
    print(f"prepare (once per clip): {time.perf_counter() - t:.2f} s")
    oracle = Session(pipeline.prepare(sample_path()))  # knows each change's hash; shares nothing with the studio
    studio = Studio(prep, port=_free_port()).start()
    tab = _Tab(f"ws://127.0.0.1:{studio.server.get_port()}", viser.__version__)
    session = studio.wait_for_tabs(1)[0]  # the tab's own session (each browser tab has one)
    time.sleep(1.0)  # the initial scene
    print(f"result: {session.good.n_frames} frames at {prep.motion.fps:.0f} Hz (4 strides), "
          f"{len(session.good.track.capsule_radii)} capsules; player at 30 Hz")

    # the speed slider's own grid (step 0.05), every value once, slower and faster than the clip in turn
    speeds = [1.05, 1.15, 1.0, 1.2, 0.95, 1.25, 0.9, 1.3, 0.85, 1.35, 0.8, 1.4, 0.75, 1.45, 1.1]
    changes = [("speed", lambda i: Params(speed=speeds[i % len(speeds)])),
               ("height", lambda i: Params(height=round(1.405 + 0.031 * i, 3))),
               ("character", lambda i: Params(character=("child", "giant", "small", "troll")[i % 4]))]
    cols = ("first motion at page", "IK result at page", "worker wakes", "result compute", "result push",
            "server to page")
    rows = {name: {k: [] for k in cols} for name, _ in changes}
    try:
        for name, make in changes:
            for i in range(args.repeats):
                params = make(i)
                want = oracle.solve(params, report=False).hash.encode()
                time.sleep(0.25)  # the previous change's report has gone out
                t0 = time.perf_counter()
                session.request(params)
                t_first = tab.arrival_of(b" hash=", t0)
                t_res = tab.arrival_of(b"hash=" + want, t0)
                t_ok = tab.arrival_of(b"hash=" + want + b" status=ok", t0)  # done: its report is shown
                assert np.isfinite(t_ok), f"the page never showed {params} ({session.message})"
                r = rows[name]
                r["first motion at page"].append(t_first - t0)
                r["IK result at page"].append(t_res - t0)
                while not session.timing.started_at >= t0:  # the worker files its timing after the last push
                    time.sleep(0.001)
                tm = session.timing
                r["worker wakes"].append(tm.started_at - t0)
                r["result compute"].append(tm.result_compute)
                r["result push"].append(tm.result_push)
                r["server to page"].append(t_res - tm.result_flushed_at)
            print(f"changes of {name}: {args.repeats}")
    finally:
        tab.close()
        studio.stop()
    print(f"\n{'change':<11}{'step':<22}{'median ms':>10}{'p90 ms':>9}{'min ms':>9}")
    for name, r in rows.items():
        for k, v in r.items():
            a = 1e3 * np.asarray(v)
            print(f"{name:<11}{k:<22}{np.nanmedian(a):>10.1f}{np.nanpercentile(a, 90):>9.1f}{np.nanmin(a):>9.1f}")
    every = 1e3 * np.concatenate([r["IK result at page"] for r in rows.values()])
    med = float(np.nanmedian(every))
    print(f"\nbar (change -> new IK-corrected motion at the page <= 50 ms median, all changes): {med:.1f} ms "
          f"[{'PASS' if med <= 50 else 'FAIL'}]")


if __name__ == "__main__":
    main()
