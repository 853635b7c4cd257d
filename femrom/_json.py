"""One JSON helper for the whole package: numpy values and nested containers to plain JSON types."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np


def jsonable(value, *, non_finite: str = "text"):
    """``value`` as strict JSON types: numpy arrays and scalars, tuples and paths converted,
    anything else as its ``repr``. Non-finite floats become the strings ``"inf"``, ``"-inf"``,
    ``"nan"`` (``non_finite="text"``) or ``null`` (``non_finite="null"``: no number where none is
    finite; the record says why, e.g. a model's ``diverged`` or ``failed`` entry)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v, non_finite=non_finite) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v, non_finite=non_finite) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), non_finite=non_finite)
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer, int)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        value = float(value)
        if math.isfinite(value):
            return value
        return None if non_finite == "null" else str(value)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, str) or value is None:
        return value
    return repr(value)


def dumps(value, *, non_finite: str = "text", **options) -> str:
    """``json.dumps`` of :func:`jsonable` ``(value, non_finite=non_finite)``."""
    return json.dumps(jsonable(value, non_finite=non_finite), **options)
