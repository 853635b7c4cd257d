"""Helpers of the built-in terms' Galerkin projections."""

import numpy as np
import scipy.sparse as sp


def dense(A) -> np.ndarray:
    return A.toarray() if sp.issparse(A) else np.asarray(A, dtype=float)


def symmetric_projection(A, V: np.ndarray) -> np.ndarray:
    """``V^T A V`` symmetrised (round-off only) for a symmetric ``A``."""
    P = V.T @ np.asarray(A @ V)
    return 0.5 * (P + P.T)
