"""JSON output: plain-Python copies of results (arrays to lists, NaN and inf to null)."""
from __future__ import annotations

import json
import math

import numpy as np


def jsonable(o):
    """Plain-Python copy of ``o`` for JSON (arrays to lists, NaN/inf to None)."""
    if isinstance(o, dict):
        return {str(k): jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return jsonable(o.tolist())
    if isinstance(o, (np.floating, float)):
        v = float(o)
        return v if math.isfinite(v) else None
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.bool_,)):
        return bool(o)
    if hasattr(o, "__fspath__"):
        return str(o)
    return o


def dumps(obj, **kw) -> str:
    """``json.dumps`` of :func:`jsonable` (indent 2 unless given)."""
    kw.setdefault("indent", 2)
    return json.dumps(jsonable(obj), **kw)
