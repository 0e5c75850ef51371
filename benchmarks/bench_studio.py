"""Studio latency: from a control change to the new motion at the page (issue 7, bar: ≤ 50 ms median).

Runs the studio in-process on the embedded sample (4 strides at 120 Hz), with one live websocket client
(the viser protocol, draining like a browser tab would) and the player thread off, so every byte the
client receives after a change belongs to that change. For each change it calls ``Studio.apply`` — the
same function the GUI handlers post to — and measures:

  preview compute   machine path + time-warped reference on the target skeleton + FK of all frames
  preview push      track swap + scene node updates + flush (in the server)
  preview at page   change → first message of the update received by the client   <- the bar
  result compute    the full pipeline.scale (IK included) + FK of all frames
  result push       track swap, numbers, plot, node updates, flush

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_studio.py [--repeats 15]
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


class _Tab:
    """A websocket client speaking viser's subprotocol; records when each message arrives."""

    def __init__(self, url: str, version: str):
        from websockets.sync.client import connect

        self.ws = connect(url, subprotocols=[f"viser-v{version}"], max_size=None, open_timeout=10)
        self.arrivals: list[tuple[float, int]] = []
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._drain, daemon=True)
        self._thread.start()

    def _drain(self) -> None:
        try:
            for msg in self.ws:
                with self._lock:
                    self.arrivals.append((time.perf_counter(), len(msg)))
        except Exception:
            pass

    def first_after(self, t0: float, timeout: float = 5.0) -> float:
        t_end = time.perf_counter() + timeout
        while time.perf_counter() < t_end:
            with self._lock:
                for t, _ in self.arrivals:
                    if t >= t0:
                        return t
            time.sleep(0.0005)
        return float("nan")

    def close(self) -> None:
        self.ws.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15, help="changes per kind (default 15)")
    args = ap.parse_args()

    import viser

    from froude import pipeline
    from froude.samples import sample_path
    from froude.studio.app import Studio
    from froude.studio.session import Params

    t = time.perf_counter()
    prep = pipeline.prepare(sample_path())
    print(f"prepare (once per clip): {time.perf_counter() - t:.2f} s")
    studio = Studio(prep, port=_free_port())  # threads not started: no playback traffic
    tab = _Tab(f"ws://127.0.0.1:{studio.server.get_port()}", viser.__version__)
    time.sleep(1.0)  # the initial scene
    n = studio.good.n_frames
    print(f"result: {n} frames at {prep.motion.fps:.0f} Hz (4 strides), {studio.good.track.segments.shape[1]} bones")

    rows = {k: [] for k in ("preview compute", "preview push", "preview at page", "result compute", "result push",
                            "result at page")}
    changes = [("speed", lambda i: Params(speed=1.0 + 0.02 * (i % 10 + 1))),
               ("character", lambda i: Params(character=("child", "giant", "small", "troll")[i % 4]))]
    try:
        for name, make in changes:
            for i in range(args.repeats):
                t0 = time.perf_counter()
                timing = studio.apply(make(i))
                t_page = tab.first_after(t0)
                rows["preview compute"].append(timing.preview_compute)
                rows["preview push"].append(timing.preview_push)
                rows["preview at page"].append(t_page - t0)
                rows["result compute"].append(timing.result_compute)
                rows["result push"].append(timing.result_push)
                # the result's bytes: first arrival after its push began
                t_res = t0 + timing.preview_compute + timing.preview_push + timing.result_compute
                rows["result at page"].append(tab.first_after(t_res) - t0)
                assert not studio.message.startswith("error"), studio.message
                time.sleep(0.3)  # let this change's last messages (the report) arrive before the next t0
            print(f"changes of {name}: {args.repeats}")
    finally:
        tab.close()
        studio.stop()
    print(f"\n{'step':<18}{'median ms':>10}{'p90 ms':>9}{'min ms':>9}")
    for k, v in rows.items():
        a = 1e3 * np.asarray(v)
        print(f"{k:<18}{np.nanmedian(a):>10.1f}{np.nanpercentile(a, 90):>9.1f}{np.nanmin(a):>9.1f}")
    med = 1e3 * np.nanmedian(rows["preview at page"])
    full = 1e3 * np.nanmedian(rows["result at page"])
    print(f"\nbar (change -> new motion at the page <= 50 ms median): preview {med:.1f} ms "
          f"[{'PASS' if med <= 50 else 'FAIL'}]; IK result {full:.1f} ms [{'PASS' if full <= 50 else 'FAIL'}]")


if __name__ == "__main__":
    main()
