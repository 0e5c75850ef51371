"""§5.3: the transition table ⟨U, H, θ0, c⟩ → ⟨U', H'⟩ of the simple machine (eq. 5).

For one dimensionless :class:`Control`, the step map is tabulated on a regular grid of apex speed
U, apex height H and touchdown angle θ0 (all dimensionless, so the table serves any character),
by one vectorised :func:`step` call (internally chunked). Cells whose step is invalid are flagged
(``valid`` False) and hold NaN; valid cells never hold NaN in U', H', t_stance, t_rise.

Lookups are trilinear. A query is *feasible* only if it lies inside the grid and all 8 corner
cells of its grid cube are valid; infeasible queries return NaN and feasible False (or raise
PlanError with ``strict=True``). :meth:`TransitionTable.theta_for_speed` answers the planner's
question "from apex (U, H), which θ0 gives U' = target?".

Tables are cached as ``.npz`` files keyed by a hash of (version, control, grid, integration
settings) in a cache directory (default ``~/.cache/froude/tables``), written atomically.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from froude.errors import PlanError
from froude.io.jsonable import dumps
from froude.machine.dynamics import N_PER_STANCE, Control, fall_time, step

from ..io.atomic import atomic_write

__all__ = ["TABLE_VERSION", "TableGrid", "TransitionTable", "TableLookup", "grid_around",
           "build_table", "load_or_build_table", "table_key", "default_cache_dir"]

#: Bump when the dynamics or the file layout change: old cache files are then ignored.
TABLE_VERSION = 1

_VALUE_FIELDS = ("U_next", "H_next", "t_stance", "t_rise", "t_flight", "t_fall", "step_length",
                 "peak_force")


@dataclass(frozen=True)
class TableGrid:
    """Regular grid: closed ranges [lo, hi] with n nodes each (dimensionless, θ0 in rad)."""

    U: tuple  # (lo, hi, n)  apex speed [√(g l0)]
    H: tuple  # (lo, hi, n)  apex height [l0]
    theta0: tuple  # (lo, hi, n)  touchdown angle [rad]

    def axes(self):
        """(U_nodes (nU,), H_nodes (nH,), theta_nodes (nT,))."""
        return tuple(np.linspace(float(lo), float(hi), int(n)) for lo, hi, n in
                     (self.U, self.H, self.theta0))

    @property
    def shape(self):
        return (int(self.U[2]), int(self.H[2]), int(self.theta0[2]))


#: Default half-width of the touchdown-angle axis of :func:`grid_around` [rad].
THETA_BAND = float(np.radians(15.0))


def grid_around(U, H, theta0, n=64, *, u_factor=(0.3, 2.0), h_band=(-0.08, 0.12),
                theta_band=THETA_BAND, n_theta=None, n_H=None):
    """Grid centred on a running cycle (U, H, θ0) (e.g. a LimitCycle's).

    U from u_factor[0]·U to u_factor[1]·U; H from H + h_band[0] to H + h_band[1] [l0];
    θ0 ± theta_band [rad]. n nodes per axis (n_H, n_theta override for those axes).
    """
    return TableGrid(U=(u_factor[0] * U, u_factor[1] * U, int(n)),
                     H=(H + h_band[0], H + h_band[1], int(n_H or n)),
                     theta0=(theta0 - theta_band, theta0 + theta_band, int(n_theta or n)))


@dataclass(frozen=True)
class TableLookup:
    """Interpolated table values, each of the query's broadcast shape Q (NaN where infeasible).

    U_next, H_next [√(g l0)], [l0]; t_stance, t_rise, t_fall, t_flight [√(l0/g)];
    step_length [l0]; peak_force [m g]; feasible (Q,) bool.
    """

    U_next: np.ndarray
    H_next: np.ndarray
    t_stance: np.ndarray
    t_rise: np.ndarray
    t_fall: np.ndarray
    t_flight: np.ndarray
    step_length: np.ndarray
    peak_force: np.ndarray
    feasible: np.ndarray


@dataclass(frozen=True)
class TransitionTable:
    """Tabulated step map for one control. Arrays are (nU, nH, nT), indexed [iU, iH, iθ].

    U_next, H_next: next apex [√(g l0)], [l0]
    t_stance, t_rise, t_fall: phase durations [√(l0/g)] (t_fall: apex → touchdown of this step)
    t_flight: t_rise + fall time at the same θ0 (NaN where H' < cos θ0, even in valid cells;
              for another next angle use :meth:`flight_time`)
    step_length: contact → next contact with the same θ0 (NaN like t_flight) [l0]
    peak_force: [m g]
    valid: bool; reason: int8 (see froude.machine.dynamics.REASONS)
    """

    control: Control
    grid: TableGrid
    n_per_stance: int
    U_next: np.ndarray
    H_next: np.ndarray
    t_stance: np.ndarray
    t_rise: np.ndarray
    t_fall: np.ndarray
    t_flight: np.ndarray
    step_length: np.ndarray
    peak_force: np.ndarray
    valid: np.ndarray
    reason: np.ndarray

    @property
    def key(self):
        return table_key(self.control, self.grid, self.n_per_stance)

    def axes(self):
        return self.grid.axes()

    # --- interpolation -------------------------------------------------------------------------
    def _locate(self, q, axis):
        lo, hi, n = getattr(self.grid, axis)
        lo, hi, n = float(lo), float(hi), int(n)
        d = (hi - lo) / (n - 1)
        u = (q - lo) / d
        inside = (u >= -1e-9) & (u <= n - 1 + 1e-9)
        i = np.clip(np.floor(u), 0, n - 2).astype(np.intp)
        w = np.clip(u - i, 0.0, 1.0)
        return i, w, inside

    def lookup(self, U, H, theta0, *, strict=False):
        """Trilinear lookup at (U, H, θ0) (broadcast arrays) → :class:`TableLookup`.

        Feasible only inside the grid with all 8 corner cells valid; otherwise NaN. With
        ``strict`` an infeasible query raises PlanError.
        """
        U, H, th = np.broadcast_arrays(*(np.asarray(v, float) for v in (U, H, theta0)))
        iu, wu, inu = self._locate(U, "U")
        ih, wh, inh = self._locate(H, "H")
        it, wt, int_ = self._locate(th, "theta0")
        feas = inu & inh & int_
        vals = {f: np.zeros(U.shape) for f in _VALUE_FIELDS}
        for du in (0, 1):
            for dh in (0, 1):
                for dt in (0, 1):
                    w = (wu if du else 1 - wu) * (wh if dh else 1 - wh) * (wt if dt else 1 - wt)
                    cell = (iu + du, ih + dh, it + dt)
                    feas = feas & self.valid[cell]
                    for f in _VALUE_FIELDS:
                        vals[f] += w * getattr(self, f)[cell]
        nan = np.where(feas, 0.0, np.nan)
        if strict and not np.all(feas):
            bad = np.flatnonzero(~feas.ravel())[0]
            raise PlanError(f"transition table has no feasible step at U={U.ravel()[bad]:.4g}, "
                            f"H={H.ravel()[bad]:.4g}, theta0={th.ravel()[bad]:.4g} "
                            f"(grid U {self.grid.U[:2]}, H {self.grid.H[:2]}, "
                            f"theta0 {self.grid.theta0[:2]})")
        return TableLookup(**{f: vals[f] + nan for f in _VALUE_FIELDS}, feasible=feas)

    def theta_for_speed(self, U, H, U_target, *, theta_ref=None):
        """Touchdown angle θ0 [rad] taking apex (U, H) to next apex speed U' = U_target.

        Vectorised over broadcast U, H, U_target (shape Q). Scans the θ0 grid nodes (bilinear in
        U, H at each node), finds the brackets where the interpolated U' crosses the target
        between two feasible nodes, and solves linearly in θ0 (exact for the trilinear
        interpolant). When several roots exist the one nearest ``theta_ref`` (default: grid
        centre) wins. Returns (theta0 (Q,), feasible (Q,) bool); θ0 is NaN where infeasible.
        U' decreases with θ0 (a steeper leg brakes more), so usually there is one root.
        """
        U, H, tgt = np.broadcast_arrays(*(np.asarray(v, float) for v in (U, H, U_target)))
        thn = self.axes()[2]
        iu, wu, inu = self._locate(U, "U")
        ih, wh, inh = self._locate(H, "H")
        Q = U.shape
        up = np.zeros(Q + (thn.size,))
        ok = np.broadcast_to((inu & inh)[..., None], up.shape).copy()
        for du in (0, 1):
            for dh in (0, 1):
                w = ((wu if du else 1 - wu) * (wh if dh else 1 - wh))[..., None]
                cell = (iu + du, ih + dh)
                ok &= self.valid[cell]
                up += w * np.nan_to_num(self.U_next[cell])
        f = up - tgt[..., None]
        f0, f1 = f[..., :-1], f[..., 1:]
        br = ok[..., :-1] & ok[..., 1:] & (np.sign(f0) != np.sign(f1)) | (ok[..., :-1] & (f0 == 0))
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(f0 != f1, f0 / (f0 - f1), 0.0)
        roots = np.where(br, thn[:-1] + s * (thn[1] - thn[0]), np.nan)
        ref = 0.5 * (thn[0] + thn[-1]) if theta_ref is None else theta_ref
        dist = np.where(br, np.abs(roots - np.asarray(ref, float)[..., None]), np.inf)
        j = np.argmin(dist, axis=-1)
        theta = np.take_along_axis(roots, j[..., None], axis=-1)[..., 0]
        feas = np.isfinite(theta)
        return theta, feas

    @staticmethod
    def flight_time(t_rise, H_next, theta0_next):
        """Liftoff → next touchdown [√(l0/g)] when the next step lands at θ0' (any angle):
        t_rise + fall_time(H', θ0'). NaN where H' < cos θ0'."""
        return np.asarray(t_rise, float) + fall_time(H_next, theta0_next)

    # --- persistence ---------------------------------------------------------------------------
    def save(self, path):
        """Write an .npz atomically (temp file in the same directory + os.replace)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {"version": TABLE_VERSION, "control": [float(v) for v in self.control.as_tuple()],
                "grid": [list(map(float, self.grid.U)), list(map(float, self.grid.H)),
                         list(map(float, self.grid.theta0))],
                "n_per_stance": int(self.n_per_stance), "key": self.key}

        def write(tmp):
            with open(tmp, "wb") as fh:
                np.savez(fh, meta=np.array(dumps(meta)), valid=self.valid, reason=self.reason,
                         **{f: getattr(self, f) for f in _VALUE_FIELDS})

        atomic_write(path, write)
        return path

    @classmethod
    def load(cls, path):
        """Read a table written by :meth:`save`. Raises ValueError on a version mismatch."""
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("version") != TABLE_VERSION:
                raise ValueError(f"{path}: table version {meta.get('version')} != {TABLE_VERSION}")
            g = meta["grid"]
            grid = TableGrid(U=(g[0][0], g[0][1], int(g[0][2])), H=(g[1][0], g[1][1], int(g[1][2])),
                             theta0=(g[2][0], g[2][1], int(g[2][2])))
            return cls(control=Control(*meta["control"]), grid=grid,
                       n_per_stance=int(meta["n_per_stance"]), valid=z["valid"], reason=z["reason"],
                       **{f: z[f] for f in _VALUE_FIELDS})


def table_key(control, grid, n_per_stance=N_PER_STANCE):
    """Hex digest (16 chars) of (TABLE_VERSION, control, grid, n_per_stance); floats exactly."""
    payload = {"version": TABLE_VERSION,
               "control": [float(v).hex() for v in control.as_tuple()],
               "grid": [[float(grid.U[0]).hex(), float(grid.U[1]).hex(), int(grid.U[2])],
                        [float(grid.H[0]).hex(), float(grid.H[1]).hex(), int(grid.H[2])],
                        [float(grid.theta0[0]).hex(), float(grid.theta0[1]).hex(), int(grid.theta0[2])]],
               "n_per_stance": int(n_per_stance)}
    return hashlib.sha256(dumps(payload, sort_keys=True).encode()).hexdigest()[:16]


def default_cache_dir():
    """~/.cache/froude/tables (not created here)."""
    return Path.home() / ".cache" / "froude" / "tables"


def build_table(control, grid, *, n_per_stance=N_PER_STANCE, chunk=None):
    """Tabulate the step map of ``control`` on ``grid`` → :class:`TransitionTable`.

    One vectorised step() call over all nU·nH·nT points (chunked inside step()).
    """
    Ug, Hg, Tg = grid.axes()
    kw = {} if chunk is None else {"chunk": chunk}
    r = step(Ug[:, None, None], Hg[None, :, None], Tg[None, None, :],
             Control(*map(float, control.as_tuple())), n_per_stance=n_per_stance, **kw)
    return TransitionTable(control=Control(*map(float, control.as_tuple())), grid=grid,
                           n_per_stance=int(n_per_stance), U_next=r.U_next, H_next=r.H_next,
                           t_stance=r.t_stance, t_rise=r.t_rise, t_fall=r.t_fall,
                           t_flight=r.t_flight, step_length=r.step_length,
                           peak_force=r.peak_force, valid=r.valid, reason=r.reason)


def load_or_build_table(control, grid, *, cache_dir=None, n_per_stance=N_PER_STANCE):
    """Cached table: load ``<cache_dir>/table_<key>.npz`` if present and current, else build
    and save it (cache_dir created on demand; default :func:`default_cache_dir`).
    Returns (table, loaded_from_cache: bool)."""
    cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = cache_dir / f"table_{table_key(control, grid, n_per_stance)}.npz"
    if path.exists():
        try:
            return TransitionTable.load(path), True
        except (ValueError, OSError, KeyError):
            pass  # stale or corrupt cache entry: rebuild and overwrite
    table = build_table(control, grid, n_per_stance=n_per_stance)
    table.save(path)
    return table, False
