"""Eq. 1 of Pollard 1999 from the motion alone: the whole-body COM low-passed and differentiated twice, the
ground force f = m (a_com − g).

The differentiation is documented in :mod:`froude.machine.forces` (the fit's home of forces, which imports
these): a 2nd-order Butterworth filter run forward and backward (zero lag, −6 dB at ``CUTOFF_HZ`` = 8 Hz),
the clip extended at each edge by its constant-acceleration continuation. It lives here, in the body
layer, because the gait decision (:mod:`froude.body.gait`) weighs the feet's contacts against this force:
a flight is a time when it is below 0.2 body weights.
"""
from __future__ import annotations

import math

import numpy as np

from ..core.constants import G_WORLD, GRAVITY, HORIZONTAL_AXES, UP_AXIS
from ..errors import FitError

__all__ = ["CUTOFF_HZ", "FILTER_ORDER", "EDGE_PAD_S", "EDGE_FIT_S", "butter_lowpass", "filtfilt", "smooth_com",
           "ground_force", "vertical_force_bw",
           "acceleration_response", "force_landmarks", "FLIGHT_MIN_FRAMES", "flight_gravity"]

#: Low-pass cutoff of the COM filter [Hz] (−6 dB point of the forward-backward filter).
CUTOFF_HZ = 8.0
#: Order of the Butterworth section (run twice: effective order 2 × FILTER_ORDER).
FILTER_ORDER = 2
#: Length of the constant-acceleration extension added at each edge before filtering [s].
EDGE_PAD_S = 0.5
#: Length of the clip's edge used to fit that extension [s].
EDGE_FIT_S = 0.1
def _quadratic_extension(y: np.ndarray, dt: float, n_fit: int, n_pad: int) -> np.ndarray:
    """(F + 2 n_pad, C) signal extended at both ends by least-squares parabolas of n_fit samples."""
    F = y.shape[0]
    n_fit = max(3, min(n_fit, F))
    t_fit = np.arange(n_fit) * dt
    # Design of a parabola in time; solve both ends with one lstsq each (columns = components).
    A = np.stack([np.ones(n_fit), t_fit, t_fit ** 2], axis=1)
    c0, *_ = np.linalg.lstsq(A, y[:n_fit], rcond=None)
    c1, *_ = np.linalg.lstsq(A, y[F - n_fit:], rcond=None)
    t0 = -np.arange(n_pad, 0, -1) * dt  # before the first sample
    t1 = (n_fit - 1 + np.arange(1, n_pad + 1)) * dt  # after the last sample (time from the fit's start)
    head = np.stack([np.ones(n_pad), t0, t0 ** 2], axis=1) @ c0
    tail = np.stack([np.ones(n_pad), t1, t1 ** 2], axis=1) @ c1
    return np.concatenate([head, y, tail], axis=0)


def butter_lowpass(order: int, cutoff_hz: float, fs: float) -> list[tuple[tuple, tuple]]:
    """Digital Butterworth low-pass as second-order sections [(b0, b1, b2), (1, a1, a2)], each with unit
    gain at 0 Hz; the same filter as ``scipy.signal.butter(order, cutoff_hz, fs=fs, output="sos")``
    (analogue prototype, pre-warped bilinear transform). Written here because importing scipy.signal
    costs the command line about a second (it pulls in scipy.stats)."""
    warped = 2.0 * fs * math.tan(math.pi * cutoff_hz / fs)
    sections = []
    for k in range(order // 2):  # one conjugate pole pair per section, zeros at z = -1 (Nyquist)
        p = warped * complex(math.cos(math.pi * (2 * k + order + 1) / (2 * order)),
                             math.sin(math.pi * (2 * k + order + 1) / (2 * order)))
        z = (2 * fs + p) / (2 * fs - p)
        a1, a2 = -2.0 * z.real, abs(z) ** 2
        g = (1.0 + a1 + a2) / 4.0
        sections.append(((g, 2 * g, g), (1.0, a1, a2)))
    if order % 2:  # the real pole
        z = (2 * fs - warped) / (2 * fs + warped)
        g = (1.0 - z) / 2.0
        sections.append(((g, g, 0.0), (1.0, -z, 0.0)))
    return sections


def _sos_pass(sections, x: np.ndarray) -> np.ndarray:
    """One causal pass over axis 0 of x (N, C), every section started in its steady state for x[0]
    (as scipy's ``sosfilt`` with ``sosfilt_zi(sos) * x[0]``: unit DC gain, so each state is set by x[0])."""
    y = np.array(x, float)
    for (b0, b1, b2), (_, a1, a2) in sections:
        for c in range(y.shape[1]):
            col = y[:, c].tolist()
            x0 = col[0]
            # transposed direct form II; steady state for a constant input x0 (output x0)
            z1 = (b2 - a2) * x0
            z0 = (b1 - a1) * x0 + z1
            for i, xi in enumerate(col):
                yi = b0 * xi + z0
                z0 = b1 * xi - a1 * yi + z1
                z1 = b2 * xi - a2 * yi
                col[i] = yi
            y[:, c] = col
    return y


def filtfilt(sections, x: np.ndarray) -> np.ndarray:
    """Zero-phase forward-backward filtering of x (N, C) along axis 0, without padding (the callers
    extend the signal themselves): ``scipy.signal.sosfiltfilt(sos, x, axis=0, padtype=None)``."""
    forward = _sos_pass(sections, x)
    return _sos_pass(sections, forward[::-1])[::-1]


def smooth_com(p_world_com: np.ndarray, frame_time: float, cutoff_hz: float = CUTOFF_HZ):
    """Zero-lag low-pass COM and its first two derivatives.

    p_world_com: (F, 3) COM positions [m]; frame_time [s]; cutoff_hz: −6 dB cutoff [Hz].
    Returns (p (F, 3) [m], v (F, 3) [m/s], a (F, 3) [m/s²]).
    """
    p = np.asarray(p_world_com, float)
    F = p.shape[0]
    if F < 8:
        raise FitError(f"the clip is too short to differentiate ({F} frames)")
    fs = 1.0 / frame_time
    if not 0 < cutoff_hz < 0.5 * fs:
        raise FitError(f"COM filter cutoff {cutoff_hz} Hz must lie in (0, {0.5 * fs:.1f}) Hz")
    n_pad = int(round(EDGE_PAD_S / frame_time))
    n_fit = int(round(EDGE_FIT_S / frame_time))
    ext = _quadratic_extension(p, frame_time, n_fit, n_pad)
    ps = filtfilt(butter_lowpass(FILTER_ORDER, cutoff_hz, fs), ext)
    v = np.gradient(ps, frame_time, axis=0)
    a = np.gradient(v, frame_time, axis=0)
    sl = slice(n_pad, n_pad + F)
    return ps[sl], v[sl], a[sl]


def acceleration_response(freq_hz: np.ndarray, frame_time: float, cutoff_hz: float = CUTOFF_HZ) -> np.ndarray:
    """Steady-state gain [1/s²] of :func:`smooth_com`'s acceleration for a sinusoid of the COM position at
    freq_hz (N,) [Hz], sampled every frame_time [s]: the forward-backward filter's |H|² times the two
    central differences' −sin²(ω dt)/dt² (real: the chain has zero phase). Away from the clip's edges, the
    acceleration ``smooth_com`` measures of a periodic motion is its harmonics times this gain (aliases of
    harmonics above the Nyquist frequency aside), so a model's motion can be seen through the same
    instrument without sampling it (:func:`froude.machine.walk_shape.stance_force_profile`)."""
    w_dt = 2.0 * math.pi * np.asarray(freq_hz, float) * frame_time
    z1 = np.exp(-1j * w_dt)
    gain = np.ones(w_dt.shape)
    for (b0, b1, b2), (_, a1, a2) in butter_lowpass(FILTER_ORDER, cutoff_hz, 1.0 / frame_time):
        h = (b0 + z1 * (b1 + z1 * b2)) / (1.0 + z1 * (a1 + z1 * a2))
        gain = gain * np.abs(h) ** 2
    return -gain * np.sin(w_dt) ** 2 / frame_time ** 2


def ground_force(a_world_com: np.ndarray, mass: float) -> np.ndarray:
    """Eq. 1: total ground force f = m (a_com − g) (F, 3) [N]; a_world_com (F, 3) [m/s²], mass [kg]."""
    return mass * (np.asarray(a_world_com, float) - G_WORLD)


def vertical_force_bw(p_world_com: np.ndarray, frame_time: float, cutoff_hz: float = CUTOFF_HZ) -> np.ndarray:
    """(F,) vertical ground force of eq. 1 [body weights] from the COM path p_world_com (F, 3) [m]
    (``smooth_com``; 1 for a body at rest, 0 in flight)."""
    _, _, a = smooth_com(p_world_com, frame_time, cutoff_hz)
    return 1.0 + a[:, UP_AXIS] / GRAVITY


#: Fewest frames of a flight phase the flight-gravity parabola is fitted to (3 samples determine it: at
#: 30 Hz a 0.12 s flight has 3-4 frames; a physical output's COM is an exact parabola there).
FLIGHT_MIN_FRAMES = 3


def flight_gravity(com: np.ndarray, frame_time: float, flights,
                   min_frames: int = FLIGHT_MIN_FRAMES) -> tuple[float, list[float], float]:
    """Gravity seen in flight: one parabola curvature shared by the COM height of every flight phase.

    com: (F, 3) [m]; flights: [(start, stop), ...] frame intervals. Returns g [m/s^2] (9.81 for physical
    motion) from one least-squares fit y_i(t) = c_i + b_i t − g t²/2 over all flights of at least
    ``min_frames`` frames (each its own height and vertical speed, gravity common: short flights of a 30 Hz
    clip then still constrain it together), the per-phase values, and the RMS horizontal COM acceleration
    in flight [m/s^2] (≈ 0 for physical motion: nothing pushes a body in the air). NaN when no flight is
    long enough.
    """
    used = [(a, b) for a, b in flights if b - a >= min_frames]
    if not used:
        return float("nan"), [], float("nan")
    n = len(used)
    rows, ys, gs, acc_h = [], [], [], []
    for i, (a, b) in enumerate(used):
        t = np.arange(b - a) * frame_time
        t = t - t.mean()  # centred: better conditioned, same curvature
        A = np.zeros((b - a, 2 * n + 1))
        A[:, 2 * i] = 1.0
        A[:, 2 * i + 1] = t
        A[:, -1] = -0.5 * t * t
        rows.append(A)
        ys.append(com[a:b, UP_AXIS])
        gs.append(-2.0 * np.polyfit(t, com[a:b, UP_AXIS], 2)[0])
        for ax in HORIZONTAL_AXES:
            acc_h.append(2.0 * np.polyfit(t, com[a:b, ax], 2)[0])
    sol, *_ = np.linalg.lstsq(np.concatenate(rows), np.concatenate(ys), rcond=None)
    return float(sol[-1]), [float(x) for x in gs], float(np.sqrt(np.mean(np.square(acc_h))))


#: Least prominence [BW] of a local maximum of the vertical force that counts as a peak: a tenth of the
#: walking acceptance's force tolerance on the landmarks (0.1 BW), so a ripple that the tolerance cannot see
#: does not move a landmark's time.
MIN_PEAK_PROMINENCE_BW = 0.01


def prominence_bw(fy_bw: np.ndarray) -> np.ndarray:
    """(N,) prominence [BW] of each sample of fy_bw (N,) that is a local maximum (≥ both neighbours; 0
    elsewhere and at the ends): its height above the higher of the lowest values on each side before the
    force rises above it again (or the profile ends), as ``scipy.signal.peak_prominences`` defines it
    (written here: importing scipy.signal costs more than a second of start-up)."""
    y = np.asarray(fy_bw, float)
    out = np.zeros(y.size)
    for i in np.flatnonzero((y[1:-1] >= y[:-2]) & (y[1:-1] >= y[2:])) + 1:
        higher_left = np.flatnonzero(y[:i] > y[i])
        higher_right = np.flatnonzero(y[i + 1:] > y[i])
        left = y[(higher_left[-1] + 1 if higher_left.size else 0):i + 1].min()
        right = y[i:(i + 1 + higher_right[0] if higher_right.size else y.size)].min()
        out[i] = y[i] - max(left, right)
    return out


def force_landmarks(tau: np.ndarray, fy_bw: np.ndarray, tau_double: float) -> dict:
    """The two peaks and the trough of the vertical force over one stance.

    tau: (N,) stance phase 0 … 1; fy_bw: (N,) total vertical ground force [BW]; tau_double: the phase
    length of one double support. The weight-acceptance peak is the largest local maximum of the force
    in the first 2·tau_double of the stance, the push-off peak the largest in the last 2·tau_double (each
    double support and as long again into single support: where the gait literature places them, around
    the other foot's liftoff and touchdown; the window's largest value if it holds no local maximum);
    the trough is the smallest force between them. Extrema are refined to the parabola's vertex.
    Returns {peak1, trough, peak2 [BW], tau_peak1, tau_trough, tau_peak2 [-]}.
    """
    w = min(max(2.0 * tau_double, 0.15), 0.45)
    # A peak is a local maximum: the force at the stance's very start or end is the tail of the other
    # foot's peak (the profile of a periodic walk wraps around), not this stance's. One that stands less
    # than MIN_PEAK_PROMINENCE_BW above the force around it is a ripple on a rising or falling flank (a
    # brisk walk's machine, seen through the clip's filter, shows 0.003 BW ones), not a peak.
    interior = prominence_bw(fy_bw) >= MIN_PEAK_PROMINENCE_BW
    first = tau <= w
    last = tau >= 1.0 - w
    first = first & interior if (first & interior).any() else first
    last = last & interior if (last & interior).any() else last
    i1 = np.flatnonzero(first)[np.argmax(fy_bw[first])]
    i2 = np.flatnonzero(last)[np.argmax(fy_bw[last])]
    mid = np.arange(i1, i2 + 1)
    it = mid[np.argmin(fy_bw[mid])]
    out = {}
    for key, i in (("peak1", i1), ("trough", it), ("peak2", i2)):
        out[key], out["tau_" + key] = parabola_vertex(tau, fy_bw, int(i))
    return out


def parabola_vertex(x, y, i):
    """(y, x) at the vertex of the parabola through samples i − 1, i, i + 1 of an extremum (evenly spaced
    x), so a landmark is not quantised to the sample grid; the sample itself at an end or when the vertex
    would leave the three samples."""
    if 0 < i < len(y) - 1:
        den = y[i - 1] - 2.0 * y[i] + y[i + 1]
        if den != 0.0:
            d = 0.5 * (y[i - 1] - y[i + 1]) / den
            if abs(d) <= 1.0:
                return float(y[i] - 0.25 * (y[i - 1] - y[i + 1]) * d), float(x[i] + d * (x[i + 1] - x[i]))
    return float(y[i]), float(x[i])
