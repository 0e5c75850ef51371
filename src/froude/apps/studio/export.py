"""The studio's downloads: the result as BVH (units, rate, root motion or in place), its physics report,
the comparison CSV and an MP4 of the scene."""
from __future__ import annotations

import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import FroudeError
from ...flow.result import Output, in_place_motion
from ...io.bvh import bvh_text
from ...viz.render import render_video
from .session import with_report

if TYPE_CHECKING:  # a part of Tab: its methods use the attributes Tab.__init__ sets
    _TabPart = Any
else:
    _TabPart = object

#: Export choices for the BVH download.
BVH_UNITS = ("the clip's", "metres", "centimetres")
BVH_RATES = ("the clip's", "24 Hz", "30 Hz", "60 Hz", "120 Hz")

BVH_ROOT = ("root motion", "in place")


class _Export(_TabPart):
    """The export part of :class:`~froude.apps.studio.app.Tab` (a mixin: the tab's state lives in Tab)."""

    # ---- downloads
    def _send(self, event, name: str, data: bytes) -> None:
        client = event.client if event is not None and event.client is not None else self.client
        if client is not None:
            client.send_file_download(name, data, save_immediately=True)

    @property
    def _good_result(self) -> Output:
        """The last good result's output (a good result is a solved one, never an IK-free preview)."""
        assert self.good.result is not None
        return self.good.result

    def _on_download_bvh(self, event) -> None:
        """The result as BVH: in the clip's units or metres/centimetres, at the clip's rate or another, with
        its root motion or in place (the CLI's ``in_place_motion``: only the forward progression between
        touchdowns comes off the root, so the sway and the surge within each step stay)."""
        units, rate, root = str(self.gui_bvh_units.value), str(self.gui_bvh_fps.value), str(self.gui_bvh_root.value)
        if units not in BVH_UNITS or rate not in BVH_RATES or root not in BVH_ROOT:  # crafted values
            self._show_error("BVH export options must be chosen from their lists")
            return
        # in place before resampling: the machine path's touchdowns are on the result's own frames
        motion = in_place_motion(self._good_result) if root == "in place" else self._good_result.motion
        if rate != BVH_RATES[0]:
            motion = motion.resample(float(rate.split()[0]))
        scale = {"metres": 1.0, "centimetres": 0.01}.get(units)
        self._send(event, self._file_stem() + ".bvh", bvh_text(motion, scale).encode())

    def _on_download_report(self, event) -> None:
        res = with_report(self.session.prep, self.good).result
        assert res is not None and res.report is not None  # with_report computes it
        self._send(event, self._file_stem() + ".report.json", res.report.to_json().encode())

    def _on_download_csv(self, event) -> None:
        """Per-frame data (COM, ground force, contacts, machine path) through ``froude.io.framedata``."""
        try:
            # lazy: optional: a build without per-frame data says so instead
            from ...io.framedata import write_frame_data
            from ...report.frames import frame_table  # lazy: optional: a build without per-frame data says so instead
        except ImportError:
            self._show_error("per-frame CSV needs froude.io.framedata, which this build does not have")
            return
        res = self._good_result
        path = res.path if res.path is not None and len(res.path.times) == res.motion.n_frames else None
        try:
            table = frame_table(res.motion, res.retarget.body, machine_path=path)
            with tempfile.TemporaryDirectory(prefix="froude-studio-") as d:
                data = write_frame_data(table, Path(d) / "frames.csv").read_bytes()
        except FroudeError as e:
            self._show_error(e)
            return
        self._send(event, self._file_stem() + ".csv", data)

    def _on_download_mp4(self, event) -> None:
        """Render the reference and the result (and the naive one when shown) with ``froude render``'s
        capsules and this camera, then send the file. Takes seconds: the status says so."""
        motions = [self.session.prep.motion, self._good_result.motion]
        labels = ["reference", f"physical ({self.good.params.character})"]
        if self.gui_show_naive.value and self.naive is not None and self.naive.result is not None:
            motions.append(self.naive.result.motion)
            labels.append("naive")
        self._set_status(f"*rendering the MP4 ({len(motions)} runners) ...*")
        try:
            with tempfile.TemporaryDirectory(prefix="froude-studio-") as d:
                out = Path(d) / "render.mp4"
                render_video(motions, out, labels=labels, fps=30.0, camera=str(self.gui_camera.value), width=960)
                data = out.read_bytes()
        except FroudeError as e:
            self._show_error(e)
            return
        self._set_status(None)
        self._send(event, self._file_stem() + ".mp4", data)

    def _file_stem(self) -> str:
        p = self.good.params
        tag = f"x{p.speed:g}" if p.mode == "scale" else f"to{p.to_factor:g}x{p.steps}"
        return f"{Path(self.clip_name).stem}_{p.character}_{p.mode}_{tag}"
