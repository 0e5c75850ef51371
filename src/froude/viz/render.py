"""Renders of motions: capsule figures in filmstrips (the paper's Fig. 3), stills, GIF and MP4 videos.

A figure is drawn as thick round-capped lines along the skeleton's bones ("capsules"), a disc for the
head, a soft shadow on the ground and a ground line (side camera) or ground grid (three-quarter, front).
Limbs are shaded by side: the side away from the camera darker, the near side lighter, so left and
right read at a glance. Projection is orthographic: a point p [m] appears at (p·right, p·up) on screen,
with the camera basis built from the runner's mean heading, so every runner travels left to right. A take
that turns (``body.path``) is drawn unrolled along its path (``body.path.straighten``): the camera follows
the curve, and the speed shown is the speed along the path.

Everything is drawn at one common scale [px/m] across rows and panels, so a child looks small next to
a giant. matplotlib (and imageio + imageio-ffmpeg for GIF/MP4) are optional extras imported lazily;
a missing one raises FroudeError with the pip command that installs it.

Public API: ``filmstrip_image`` (the RGB array plus the drawn geometry), ``render_filmstrip`` (PNG),
``render_video`` (GIF/MP4), ``render_frame`` (a still PNG of the video layout), ``build_rig``,
``camera_basis``.

The parts: the rig (points and capsules) in ``viz.rig``, the camera, scene and figure drawing and the
filmstrip in ``viz.draw``; this module renders videos and stills and writes the files. The public names
of the parts are importable from here too.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ..core.constants import UP_AXIS
from ..core.motion import Motion
from ..errors import FroudeError
from ..io.atomic import atomic_write
from .draw import (
    _DPI,
    _TEXT,
    CAMERAS,
    INSTALL_HINT,
    Filmstrip,
    _Actor,
    _actors,
    _blank_axes,
    _even,
    _FigureArtists,
    _ground_artists,
    _new_figure,
    _rgb,
    _screen,
    _shadow_outline,
    camera_basis,
    filmstrip_image,
    snapshot_times,
)
from .rig import CENTRE, LEFT, RIGHT, Rig, build_rig

__all__ = ["CAMERAS", "CENTRE", "LEFT", "RIGHT", "Filmstrip", "Rig", "build_rig", "camera_basis", "filmstrip_image",
           "render_filmstrip", "render_frame", "render_video", "snapshot_times", "video_times"]

VIDEO_EXTENSIONS = (".gif", ".mp4")
STILL_EXTENSIONS = (".png",)


def _imageio():
    try:
        import imageio.v2 as iio2
        import imageio.v3 as iio3
    except ImportError:
        raise FroudeError(f"GIF/MP4 output needs imageio: {INSTALL_HINT}") from None
    return iio2, iio3


def _fit_width(text, max_px: float, renderer) -> None:
    """Shorten a matplotlib Text's string with an ellipsis until it is at most ``max_px`` pixels wide (a long
    clip name in a narrow panel); a string that fits is left as it is."""
    full = text.get_text()
    keep = len(full)
    while keep > 1 and text.get_window_extent(renderer).width > max_px:
        keep -= 1
        text.set_text(full[:keep].rstrip() + "…")


# ---- video -----------------------------------------------------------------------------------------
class _VideoScene:
    """One figure with a panel per motion; ``frame(t)`` updates the artists and returns the RGB image."""

    def __init__(self, actors: list[_Actor], width: int, height: int | None):
        from scipy.ndimage import gaussian_filter1d

        n = len(actors)
        self.actors = actors
        self.width = _even(width)
        panel_w = self.width / n
        self.height = _even(height if height else max(200.0, 0.75 * panel_w))
        tallest = max(a.rig.stature for a in actors)
        span_y = 1.55 * tallest
        self.px_per_m = self.height / span_y
        self.span_x = panel_w / self.px_per_m
        self.span_y = span_y
        self.fig, self.canvas = _new_figure(self.width, self.height)
        self.panels = []
        font = max(8.0, min(14.0, 0.06 * self.height * 72 / _DPI))
        for i, act in enumerate(actors):
            ax = _blank_axes(self.fig, (i / n, 0, 1 / n, 1))
            m = act.motion
            # the camera follows a smoothed pelvis (σ = 0.25 s) so the stride's sway does not shake it
            p, R = act.body.world(m)
            pelvis = p[:, act.body.roles["pelvis"]].copy()
            pelvis[:, UP_AXIS] = act.sole
            sigma = max(1e-6, 0.25 / m.frame_time)
            follow = gaussian_filter1d(pelvis, sigma, axis=0, mode="nearest") if m.n_frames > 1 else pelvis
            self_follow = _screen(follow, act.basis)  # (F, 2)
            xr = (self_follow[:, 0].min() - self.span_x, self_follow[:, 0].max() + self.span_x)
            _ground_artists(ax, act, xr, ticks=True)
            fa = _FigureArtists(ax, act, self.px_per_m, z0=10)
            title = ax.text(0.03, 0.96, act.label, transform=ax.transAxes, ha="left", va="top", fontsize=font,
                            color=_TEXT, weight="bold", zorder=50)
            _fit_width(title, 0.94 * panel_w, self.canvas.get_renderer())
            # the clock shares the speed's line, so a long clip name never runs into it
            second_line = 0.96 - 1.5 * font * _DPI / 72 / self.height
            ax.text(0.03, second_line, f"{act.speed:.2f} m/s",
                    transform=ax.transAxes, ha="left", va="top", fontsize=0.85 * font, color="#555555", zorder=50)
            clock = ax.text(0.97, second_line, "", transform=ax.transAxes, ha="right", va="top",
                            fontsize=0.85 * font, color="#777777", zorder=50, family="monospace")
            if i > 0:  # a thin divider between panels
                ax.plot([0, 0], [0, 1], transform=ax.transAxes, color="#cccccc", lw=1.0, zorder=60)
            self.panels.append((ax, act, fa, self_follow, clock))

    def prepare(self, times: np.ndarray) -> None:
        """Sample every motion at the output times (T,) [s] and project, all frames at once."""
        self.times = np.asarray(times, dtype=float)
        self.tracks = []
        for _ax, act, _fa, follow, _clock in self.panels:
            m = act.motion
            snap = m.sample(self.times)
            p, R = act.body.world(snap)
            pts = act.rig.points(p, R)  # (T, P, 3)
            u = np.clip(self.times / m.frame_time, 0.0, m.n_frames - 1)
            i0 = np.minimum(np.floor(u).astype(int), max(m.n_frames - 2, 0))
            i1 = np.minimum(i0 + 1, m.n_frames - 1)
            w = (u - i0)[:, None]
            centre = follow[i0] * (1 - w) + follow[i1] * w  # (T, 2) camera target
            self.tracks.append((_screen(pts, act.basis), _shadow_outline(act, pts[:, act.rig.pelvis]), centre,
                                np.minimum(self.times, m.duration)))

    def frame(self, k: int) -> np.ndarray:
        """(H, W, 3) uint8 image of output frame k (each motion clamped to its own end)."""
        for (ax, _act, fa, _follow, clock), (xy, shadow, centre, clock_t) in zip(self.panels, self.tracks):
            fa.set(xy[k], shadow[k])
            c = centre[k]
            ax.set_xlim(c[0] - 0.5 * self.span_x, c[0] + 0.5 * self.span_x)
            ax.set_ylim(c[1] - 0.14 * self.span_y, c[1] + 0.86 * self.span_y)
            clock.set_text(f"{clock_t[k]:.2f} s")
        return _rgb(self.canvas)


def video_times(motions: Sequence[Motion], fps: float) -> np.ndarray:
    """(n,) output frame times [s] covering the longest motion: n = floor(max duration * fps) + 1."""
    if not fps > 0:
        raise FroudeError(f"fps must be > 0, got {fps}")
    duration = max(m.duration for m in motions)
    return np.arange(int(np.floor(duration * fps + 1e-9)) + 1) / fps


# ---- output files ----------------------------------------------------------------------------------
def _check_path(path, allowed: tuple[str, ...]) -> Path:
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in allowed:
        raise FroudeError(f"{path}: unknown output extension '{path.suffix}'; use {', '.join(allowed)}")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise FroudeError(f"{path}: folder '{folder}' does not exist")
    return path


def _atomic(path: Path, write: Callable[[str], None]) -> None:
    """Run write(temp_path) on a temp file beside ``path`` (same extension), then move it into place."""
    atomic_write(path, write)


def _write_png(path: Path, image: np.ndarray) -> None:
    from PIL import Image  # a dependency of matplotlib

    _atomic(path, lambda tmp: Image.fromarray(np.ascontiguousarray(image)).save(tmp, format="PNG"))


def render_filmstrip(
    motions: Sequence[Motion],
    path,
    labels: Sequence[str] | None = None,
    interval: float = 0.066,
    camera: str = "side",
    width: int = 2400,
    spacing: float | None = None,
) -> Filmstrip:
    """Write the filmstrip of ``filmstrip_image`` as a PNG (atomically) and return it."""
    path = _check_path(path, STILL_EXTENSIONS)
    strip = filmstrip_image(motions, labels, interval, camera, width, spacing)
    _write_png(path, strip.image)
    return strip


def render_frame(
    motions: Sequence[Motion],
    path,
    labels: Sequence[str] | None = None,
    time: float = 0.0,
    camera: str = "side",
    width: int = 960,
    height: int | None = None,
) -> np.ndarray:
    """Write one frame of the video layout (a panel per motion) at ``time`` [s] as a PNG; return it (H, W, 3)."""
    path = _check_path(path, STILL_EXTENSIONS)
    scene = _VideoScene(_actors(motions, labels, camera), width, height)
    scene.prepare(np.array([float(time)]))
    image = scene.frame(0)
    _write_png(path, image)
    return image


#: x264 constant rate factor of the MP4s (what imageio's quality 7 meant: visually clean, small files).
MP4_CRF = 15


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """Linux: have the kernel send SIGKILL to this child when its parent dies (even by SIGKILL)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, 9)  # PR_SET_PDEATHSIG, SIGKILL
    except Exception:
        pass


def _ffmpeg_exe() -> str:
    """Path of the ffmpeg binary imageio-ffmpeg ships (FroudeError with the install hint if missing)."""
    try:
        from imageio_ffmpeg import get_ffmpeg_exe
    except ImportError:
        raise FroudeError(f"MP4 output needs imageio-ffmpeg: {INSTALL_HINT}") from None
    return get_ffmpeg_exe()


def _encode_mp4(ffmpeg: str, tmp: str, frames, fps: float, width: int, height: int) -> None:
    """Pipe RGB frames (height, width, 3) uint8 into an ffmpeg child that writes H.264 to ``tmp``.

    The child ends with froude: in its own session (a Ctrl-C in the terminal reaches froude, which stops
    it), killed and reaped on any interrupt or error here, and (Linux) killed by the kernel if froude
    itself is killed. A failed encode is a FroudeError with ffmpeg's last message.
    """
    import subprocess
    import sys

    cmd = [ffmpeg, "-y", "-loglevel", "error", "-f", "rawvideo", "-vcodec", "rawvideo",
           "-s", f"{width}x{height}", "-pix_fmt", "rgb24", "-r", f"{fps:.6g}", "-i", "-", "-an",
           "-vcodec", "libx264", "-pix_fmt", "yuv420p", "-crf", str(MP4_CRF),
           "-preset", "veryfast",  # encoding shares 2 cores with drawing
           "-f", "mp4", tmp]
    linux = sys.platform.startswith("linux")
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True, preexec_fn=_die_with_parent if linux else None)
    assert proc.stdin is not None and proc.stderr is not None  # both are pipes
    try:
        try:
            for im in frames:
                proc.stdin.write(np.ascontiguousarray(im, dtype=np.uint8).tobytes())
        except BrokenPipeError:
            pass  # ffmpeg stopped: its message is read below
        proc.stdin.close()
        err = proc.stderr.read().decode(errors="replace").strip()
        code = proc.wait()
    except BaseException:
        proc.kill()
        proc.wait()
        raise
    finally:
        proc.stderr.close()
    if code != 0:
        last = err.splitlines()[-1] if err else f"exit status {code}"
        raise FroudeError(f"ffmpeg could not encode the video: {last}")


def render_video(
    motions: Sequence[Motion],
    path,
    labels: Sequence[str] | None = None,
    fps: float = 30.0,
    camera: str = "side",
    width: int = 960,
    height: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[int, int, int]:
    """Render motions side by side (one panel each, common scale, camera following each runner) at real
    time to a GIF or MP4 (by extension), written atomically. Shorter motions hold their last pose.

    width, height: frame size [px] (rounded to even numbers; height defaults to 0.75 x panel width).
    progress(done, total) is called after every frame. Returns (frames, height, width).
    """
    path = _check_path(path, VIDEO_EXTENSIONS)
    mp4 = path.suffix.lower() == ".mp4"
    ffmpeg = _ffmpeg_exe() if mp4 else None  # a missing extra is said before any drawing
    iio3 = None if mp4 else _imageio()[1]
    actors = _actors(motions, labels, camera)
    times = video_times([a.motion for a in actors], fps)
    scene = _VideoScene(actors, width, height)
    scene.prepare(times)

    def frames():
        for k in range(len(times)):
            yield scene.frame(k)
            if progress:
                progress(k + 1, len(times))

    def write(tmp: str) -> None:
        if ffmpeg is not None:
            _encode_mp4(ffmpeg, tmp, frames(), fps, scene.width, scene.height)
        else:
            assert iio3 is not None
            # GIF delays are whole centiseconds; Pillow merges identical consecutive frames, so
            # frames are nudged apart only by their content (the clock text changes every frame)
            with iio3.imopen(tmp, "w", plugin="pillow", extension=".gif") as f:
                f.write(np.stack(list(frames())), duration=1000.0 / fps, loop=0)

    _atomic(path, write)
    return len(times), scene.height, scene.width
