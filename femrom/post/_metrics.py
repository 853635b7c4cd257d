"""Metrics of a prediction against a reference: functions of ``(reference, prediction)``."""

from __future__ import annotations

import numpy as np


def relative_error(reference: np.ndarray, approximation: np.ndarray) -> float:
    """``||approximation - reference||_F / ||reference||_F`` (``inf`` if the approximation is not finite)."""
    reference, approximation = np.asarray(reference, float), np.asarray(approximation, float)
    if not np.all(np.isfinite(approximation)):
        return float("inf")
    return float(np.linalg.norm(approximation - reference) / np.linalg.norm(reference))
