"""Helpers shared by the sub-commands: JSON output, degrees at the edges."""
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
    return o


def emit_json(obj) -> None:
    """Print one JSON object on stdout (NaN and inf become null)."""
    print(json.dumps(jsonable(obj), indent=2, sort_keys=False))
