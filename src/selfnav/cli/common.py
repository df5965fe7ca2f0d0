"""Helpers shared by the sub-commands: JSON output."""
from __future__ import annotations

from selfnav.io.jsonio import dumps


def emit_json(obj) -> None:
    """Print one JSON object on stdout (NaN and inf become null)."""
    print(dumps(obj, sort_keys=False))
