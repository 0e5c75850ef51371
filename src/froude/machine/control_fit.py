"""Least-squares fit of the stance control, Pollard 1999 eq. 2 (SI in, SI and dimensionless out).

    f_leg(τ) = k (l_d(τ) − l),   l_d(τ) = l0 + a + b τ + c τ²

is linear in (k, k a, k b, k c):

    f_leg = k (l0 − l) + (k a) + (k b) τ + (k c) τ²

so one (weighted) linear least-squares solve gives all four; then a = (k a)/k etc.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from froude.core.constants import GRAVITY
from froude.errors import FitError
from froude.machine.dynamics import Control
from froude.machine.units import time_unit

__all__ = ["LegForceFit", "fit_leg_control", "control_from_si"]


@dataclass(frozen=True)
class LegForceFit:
    """Result of :func:`fit_leg_control` (SI).

    k:   leg stiffness [N/m]
    a, b, c: desired-length coefficients [m] (l_d = l0 + a + b τ + c τ²)
    l0:  touchdown leg length used [m]
    r2:  coefficient of determination of f_leg (weighted if weights were given) [-]
    rms: RMS residual force [N] (weighted RMS if weights were given)
    n:   number of samples used
    residual: (N,) residual force f_leg − model [N]
    """

    k: float
    a: float
    b: float
    c: float
    l0: float
    r2: float
    rms: float
    n: int
    residual: np.ndarray

    def predict(self, tau, l_m):
        """Model leg force [N] at phase tau (N,) and leg length l_m (N,) [m]."""
        tau = np.asarray(tau, float)
        return self.k * (self.l0 + self.a + self.b * tau + self.c * tau * tau - np.asarray(l_m, float))

    def to_control(self, m_kg, T_c_s, g=GRAVITY):
        """Dimensionless :class:`Control` for body mass m [kg] and nominal stance time T_c [s]."""
        return control_from_si(self.k, self.a, self.b, self.c, T_c_s, m_kg, self.l0, g)


def control_from_si(k_N_per_m, a_m, b_m, c_m, T_c_s, m_kg, l0_m, g=GRAVITY):
    """Dimensionless Control from SI values.

    K = k l0/(m g); a, b, c divided by l0; T_c divided by √(l0/g).
    """
    if not (m_kg > 0 and l0_m > 0 and T_c_s > 0):
        raise FitError(f"need m > 0, l0 > 0, T_c > 0 (got m={m_kg}, l0={l0_m}, T_c={T_c_s})")
    return Control(K=float(k_N_per_m) * l0_m / (m_kg * g), a=float(a_m) / l0_m,
                   b=float(b_m) / l0_m, c=float(c_m) / l0_m, T_c=float(T_c_s) / time_unit(l0_m, g))


def fit_leg_control(tau, l_m, f_leg_N, l0_m, weights=None):
    """Fit eq. 2 over one stance (or several, pooled).

    tau:     (N,) stance phase, 0 at touchdown, 1 at the nominal end of stance [-]
    l_m:     (N,) actual leg length |COM − foot| [m]
    f_leg_N: (N,) measured force along the leg, positive pushing the COM away from the foot [N]
    l0_m:    touchdown leg length [m] (scalar)
    weights: optional (N,) non-negative sample weights (e.g. 0 to drop a sample)

    Returns :class:`LegForceFit`. Raises FitError for too few samples, a degenerate design
    (e.g. no leg compression) or a non-positive stiffness.
    """
    tau = np.asarray(tau, float).ravel()
    l = np.asarray(l_m, float).ravel()
    f = np.asarray(f_leg_N, float).ravel()
    if not (tau.shape == l.shape == f.shape):
        raise FitError(f"tau, l, f_leg must have the same shape, got {tau.shape}, {l.shape}, {f.shape}")
    w = np.ones_like(f) if weights is None else np.asarray(weights, float).ravel()
    if w.shape != f.shape or np.any(w < 0):
        raise FitError("weights must be (N,) and non-negative")
    use = np.isfinite(tau) & np.isfinite(l) & np.isfinite(f) & (w > 0)
    n = int(np.count_nonzero(use))
    if n < 4:
        raise FitError(f"need at least 4 valid stance samples to fit k, a, b, c; got {n}")
    sw = np.sqrt(w[use])
    compression = l0_m - l[use]
    tu = tau[use]
    A = np.stack([compression, np.ones(n), tu, tu * tu], axis=1)
    # Column scaling: compression is centimetres, the rest order one; keeps lstsq well-conditioned.
    colscale = np.sqrt(np.sum(A * A, axis=0))
    if np.any(colscale == 0):
        raise FitError("degenerate stance samples (no compression or constant phase)")
    Aw = A * sw[:, None] / colscale
    coef, *_ = np.linalg.lstsq(Aw, f[use] * sw, rcond=None)
    if np.linalg.matrix_rank(Aw) < 4:
        raise FitError("stance samples do not determine k, a, b, c (rank-deficient design)")
    k, ka, kb, kc = coef / colscale
    if not k > 0:
        raise FitError(f"fitted leg stiffness is not positive (k = {k:.4g} N/m)")
    resid_all = np.full_like(f, np.nan)
    resid = f[use] - A @ (coef / colscale)
    resid_all[use] = resid
    ww = w[use]
    fbar = np.sum(ww * f[use]) / np.sum(ww)
    ss_tot = float(np.sum(ww * (f[use] - fbar) ** 2))
    ss_res = float(np.sum(ww * resid ** 2))
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else float("nan")
    rms = math.sqrt(ss_res / float(np.sum(ww)))
    return LegForceFit(k=float(k), a=float(ka / k), b=float(kb / k), c=float(kc / k), l0=float(l0_m),
                       r2=float(r2), rms=rms, n=n, residual=resid_all)
