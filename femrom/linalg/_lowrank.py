"""The result of a truncated SVD: A ~ U diag(s) Vt, with how it was obtained."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np


@dataclass(frozen=True, eq=False)
class LowRankSVD:
    """A ~ U diag(s) Vt with U^T W U = I in the inner product W used.

    Unpacks as a triple, ``U, s, Vt = randomized_svd(...)``; the other fields
    are attributes.

    Attributes
    ----------
    U : (n, r) ndarray
        Left singular vectors, orthonormal in the inner product used.
    s : (r,) ndarray
        Singular values, decreasing.
    Vt : (r, K) ndarray
        Right singular vectors (Euclidean orthonormal rows).
    passes : int
        Passes over the data (1 for the streaming sketch).
    total_energy : float
        ||A||_W^2 = trace(A^T W A), accumulated in the first pass: the
        denominator of the retained energy sum(s_i^2) / ||A||_W^2.
    n_columns : int
        Number K of snapshot columns seen.
    sketch_size : int
        Number of columns of the range sketch (rank + oversampling, capped by K).
    method : str
        Which algorithm produced it.
    """

    U: np.ndarray
    s: np.ndarray
    Vt: np.ndarray
    passes: int
    total_energy: float
    n_columns: int
    sketch_size: int
    method: str

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.U, self.s, self.Vt))

    @property
    def rank(self) -> int:
        return self.s.size

    @property
    def retained_energy(self) -> np.ndarray:
        """(r,) cumulative sum(s_i^2, i <= j) / ||A||_W^2."""
        return np.cumsum(self.s**2) / self.total_energy if self.total_energy > 0 else np.ones_like(self.s)
