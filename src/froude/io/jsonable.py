"""The one JSON helper: plain Python from NumPy, no NaN or Infinity in any file froude writes.

Strict JSON (RFC 8259) has no NaN: a figure that cannot be measured is written as ``null``, and the
writer says why next to it (see ``metrics.Report.to_dict``).
"""
from __future__ import annotations

import json
import math

import numpy as np


def jsonable(x):
    """Recursively convert NumPy scalars/arrays, tuples and dicts to plain Python; NaN/±Inf → None."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    return x


def dumps(x, **kw) -> str:
    """``json.dumps`` of ``jsonable(x)`` with NaN refused (a non-finite number left would raise)."""
    return json.dumps(jsonable(x), allow_nan=False, **kw)
