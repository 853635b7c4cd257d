"""Dirichlet conditions by condensation, with the map back to full fields."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError


@dataclass(frozen=True, eq=False)
class Condensation:
    """Homogeneous Dirichlet conditions on ``fixed`` dofs of an ``n_total`` system.

    Every operator of a :class:`~femrom.scene.SecondOrderSystem` lives on the
    ``free`` dofs; :meth:`expand` maps free-dof vectors back to full fields
    (zeros on the fixed dofs) for rendering and output.

    Attributes
    ----------
    n_total : int
        Number of dofs before condensation.
    free : (n,) int ndarray
        Sorted indices of the free dofs, ``n = n_total - len(fixed)``.
    fixed : (n_total - n,) int ndarray
        Sorted indices of the constrained dofs.
    """

    n_total: int
    free: np.ndarray
    fixed: np.ndarray

    @classmethod
    def from_fixed(cls, n_total: int, fixed) -> "Condensation":
        fixed = np.unique(np.asarray(fixed, dtype=np.int64))
        if fixed.size and (fixed[0] < 0 or fixed[-1] >= n_total):
            raise FemromValueError(f"fixed dof indices must lie in [0, {n_total}), got "
                                   f"[{fixed[0]}, {fixed[-1]}]")
        mask = np.ones(n_total, dtype=bool)
        mask[fixed] = False
        free = np.flatnonzero(mask)
        free.setflags(write=False)
        fixed.setflags(write=False)
        return cls(n_total=int(n_total), free=free, fixed=fixed)

    @classmethod
    def none(cls, n_total: int) -> "Condensation":
        return cls.from_fixed(n_total, [])

    @property
    def n_free(self) -> int:
        return int(self.free.size)

    def matrix(self, A: sp.spmatrix) -> sp.csr_matrix:
        """Free-free block ``A[free][:, free]`` of an (n_total, n_total) matrix."""
        A = sp.csr_matrix(A)
        return A[self.free][:, self.free].tocsr()

    def rows(self, A):
        """Free rows of an (n_total, k) array or sparse matrix (input columns B)."""
        return A[self.free]

    def columns(self, A):
        """Free columns of a (p, n_total) array or sparse matrix (output rows E)."""
        if sp.issparse(A):
            return sp.csr_matrix(A)[:, self.free]
        return np.asarray(A)[:, self.free]

    def vector(self, x: np.ndarray) -> np.ndarray:
        """Free entries of an (n_total,) or (n_total, k) array."""
        return np.asarray(x)[self.free]

    def expand(self, q: np.ndarray) -> np.ndarray:
        """Full field of a free-dof (n,) or (n, k) array; zeros on fixed dofs."""
        q = np.asarray(q)
        if q.shape[0] != self.n_free:
            raise FemromValueError(f"expected {self.n_free} free dofs, got {q.shape[0]}")
        full = np.zeros((self.n_total,) + q.shape[1:], dtype=q.dtype)
        full[self.free] = q
        return full
