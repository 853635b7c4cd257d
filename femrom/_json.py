"""One JSON helper for the whole package: numpy values and nested containers to plain JSON types."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np


def jsonable(value):
    """``value`` as strict JSON types: numpy arrays and scalars, tuples and paths converted,
    non-finite floats as the strings ``"inf"``, ``"-inf"``, ``"nan"``, anything else as its ``repr``."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer, int)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        value = float(value)
        return value if math.isfinite(value) else str(value)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, str) or value is None:
        return value
    return repr(value)


def dumps(value, **options) -> str:
    """``json.dumps`` of :func:`jsonable` ``(value)``."""
    return json.dumps(jsonable(value), **options)
