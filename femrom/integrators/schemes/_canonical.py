"""Step matrices of linear canonical systems ``q' = D_p p``, ``p' = -D_q q``, shared by the schemes."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl


def kick(position, h: float, c: float) -> np.ndarray:
    """``p -= c h D_q q``."""
    r = position.shape[0]
    return np.block([[np.eye(r), np.zeros((r, r))], [-c * h * position, np.eye(r)]])


def drift(momentum, h: float, c: float) -> np.ndarray:
    """``q += c h D_p p``."""
    r = momentum.shape[0]
    return np.block([[np.eye(r), c * h * momentum], [np.zeros((r, r)), np.eye(r)]])


def midpoint_step_matrix(position, momentum, h: float) -> np.ndarray:
    """``(I - h A / 2)^-1 (I + h A / 2)`` with ``A = [[0, D_p], [-D_q, 0]]``."""
    r = position.shape[0]
    A = np.block([[np.zeros((r, r)), momentum], [-position, np.zeros((r, r))]])
    return sl.solve(np.eye(2 * r) - 0.5 * h * A, np.eye(2 * r) + 0.5 * h * A)
