"""Per-frame data of a motion (input or output): COM, ground force, foot contacts and markers, phase.

One table, one row per frame, SI units in every column name::

    time_s
    com_{x,y,z}_m, com_v{x,y,z}_m_s        the body model's COM and its velocity (zero-lag low-pass, the
                                           same differentiation as the fit and the report)
    com_force_{x,y,z}_N                    ground force from the COM acceleration, eq. 1: m (a - g)
                                           (the report's peak_vertical_force_bw is max(com_force_y_N) / (m g)
                                           over the inner frames)
    machine_com_{x,y,z}_m, machine_force_{x,y,z}_N, machine_stance_{left,right}
                                           outputs only: the simple machine's COM path, its ground force
                                           and its stance per foot (the physics the motion was built from)
    contact_{left,right}                   1 when the foot is on the ground (froude's gait detection)
    {left,right}_{ankle,toe,toe_end}_{x,y,z}_m   foot markers
    phase                                  flight, left, right or double (feet on the ground)

Written as CSV (``.csv``), Parquet (``.parquet``, needs pyarrow) or NumPy (``.npz``), atomically; a value
that is not finite is an error, never a cell. The table is built by ``report.frames.frame_table``.
"""
from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from ..core.constants import GRAVITY, UP_AXIS
from ..errors import FroudeError
from .atomic import atomic_write

DATA_SUFFIXES = (".csv", ".parquet", ".npz")
#: The column suffix of each axis (x, y, z: world axes, +Y up).
AXIS_NAMES = "xyz"
#: Frames at each end left out of the report's force peak (the filter's edges are least trustworthy).
EDGE_FRAMES = 3


def peak_vertical_force_bw(table: dict, mass: float) -> float:
    """The report's peak vertical force [body weights] recomputed from a table's com_force column."""
    fy = np.asarray(table[f"com_force_{AXIS_NAMES[UP_AXIS]}_N"])
    inner = slice(EDGE_FRAMES, max(EDGE_FRAMES, len(fy) - EDGE_FRAMES))
    return float(np.max(fy[inner]) / (mass * GRAVITY))


def write_frame_data(table: dict, path: str | os.PathLike) -> Path:
    """Write a frame table as .csv, .parquet or .npz (by suffix), atomically; returns the path."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in DATA_SUFFIXES:
        raise FroudeError(f"{path}: per-frame data is written as {', '.join(DATA_SUFFIXES)}")
    for name, col in table.items():
        if col.dtype.kind == "f" and not np.all(np.isfinite(col)):
            bad = int(np.flatnonzero(~np.isfinite(col))[0])
            raise FroudeError(f"{path}: column {name} is not finite at frame {bad}: nothing written")
    if suffix == ".csv":
        text = _csv_text(table)

        def write_csv(tmp: str) -> None:
            Path(tmp).write_text(text, newline="\n")

        return atomic_write(path, write_csv)
    if suffix == ".npz":
        def write_npz(tmp):
            with open(tmp, "wb") as f:  # a file object: np.savez would append .npz to a bare name
                np.savez(f, **table)

        return atomic_write(path, write_npz)
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise FroudeError(f"{path}: Parquet needs pyarrow: pip install pyarrow (or write .csv or .npz)") from None
    arrow = pa.table({k: (v.astype(str) if v.dtype.kind == "U" else v) for k, v in table.items()})
    return atomic_write(path, lambda tmp: pq.write_table(arrow, tmp))


def _csv_text(table: dict) -> str:
    names = list(table)
    cells = []
    for name in names:
        col = table[name]
        if col.dtype.kind == "f":
            cells.append([f"{x:.9g}" for x in col])
        else:
            cells.append([str(x) for x in col])
    buf = io.StringIO()
    buf.write(",".join(names) + "\n")
    for row in zip(*cells):
        buf.write(",".join(row) + "\n")
    return buf.getvalue()


def read_frame_data(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a table written by ``write_frame_data`` back as {name: array}."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        with np.load(path) as z:
            return {k: z[k] for k in z.files}
    if suffix == ".parquet":
        import pyarrow.parquet as pq

        t = pq.read_table(path)
        return {k: t.column(k).to_numpy() for k in t.column_names}
    lines = path.read_text().splitlines()
    names = lines[0].split(",")
    rows = [line.split(",") for line in lines[1:]]
    out = {}
    for k, name in enumerate(names):
        col = [r[k] for r in rows]
        try:
            out[name] = np.array(col, float)
        except ValueError:
            out[name] = np.array(col)
    return out
