"""Dense factorisations for small systems (a reduced model's (r, r) matrices)."""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp

from femrom.solvers._base import LinearSolver, LinearSolverError, register_strategy


@register_strategy
class DenseSolver(LinearSolver):
    """Cholesky (``spd``; LU when the matrix turns out indefinite) or LU of a dense matrix.

    ``"auto"`` picks it for a matrix given as an ndarray: the operators of a reduced model.
    """

    name = "dense"

    def __init__(self, A, *, spd: bool = True, **common):
        super().__init__(A)
        start = time.perf_counter()
        A = np.asarray(A.toarray() if sp.issparse(A) else A, dtype=float)
        if not np.all(np.isfinite(A)):
            raise LinearSolverError("dense matrix has non-finite entries")
        self._cholesky = None
        if spd:
            try:
                self._cholesky = sl.cho_factor(A, check_finite=False)
            except np.linalg.LinAlgError:
                self._cholesky = None
        if self._cholesky is None:
            self._lu = sl.lu_factor(A, check_finite=False)
            if np.any(np.diag(self._lu[0]) == 0.0):
                raise LinearSolverError("dense matrix is singular (a zero pivot in its LU factorisation)")
        self.setup_seconds = time.perf_counter() - start
        self.n_factorizations = 1

    def _solve(self, b, x0):
        if self._cholesky is not None:
            return sl.cho_solve(self._cholesky, b, check_finite=False)
        return sl.lu_solve(self._lu, b, check_finite=False)
