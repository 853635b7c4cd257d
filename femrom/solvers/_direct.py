"""Direct strategies without extra packages: a diagonal, SciPy's SuperLU, CHOLMOD."""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femrom._errors import FemromValueError
from femrom.solvers._base import LinearSolver, LinearSolverError, is_diagonal, register_strategy

#: SuperLU refuses larger matrices. The project notes report 269 s and 15 GB at
#: 1.37e5 dofs of 3D elasticity; measured here with scipy 1.17 (COLAMD): 17.8 s,
#: 1.7 GB (P1) and 31.4 s, 2.3 GB (P2) at 1.0e5 dofs, 12-15x PARDISO's factor time
#: and growing faster with n (docs/benchmarks.md, section 4b). A conservative guard.
SUPERLU_MAX_DOFS = 60_000


@register_strategy
class DiagonalSolver(LinearSolver):
    """``x = b / d`` for ``A = diag(d)``."""

    name = "diagonal"

    def __init__(self, A, *, spd: bool = True, **common):
        super().__init__(A)
        if not is_diagonal(A):
            raise FemromValueError("strategy 'diagonal' needs a diagonal matrix")
        d = np.asarray(A.diagonal(), dtype=float)
        if np.any(d == 0.0):
            raise LinearSolverError(f"diagonal matrix has {np.count_nonzero(d == 0)} zero entries")
        self._inverse = 1.0 / d

    def _solve(self, b, x0):
        return b * self._inverse if b.ndim == 1 else b * self._inverse[:, None]


@register_strategy
class SuperLUSolver(LinearSolver):
    """Sparse LU of SciPy (SuperLU), for small problems (at most ``max_dofs`` unknowns)."""

    name = "superlu"

    def __init__(self, A, *, spd: bool = True, max_dofs: int = SUPERLU_MAX_DOFS, **common):
        super().__init__(A)
        if A.shape[0] > max_dofs:
            raise FemromValueError(f"superlu is limited to {max_dofs} dofs (got {A.shape[0]}); "
                                   "use 'pardiso', 'cholmod' or 'amg-cg'")
        start = time.perf_counter()
        try:
            self._lu = spla.splu(sp.csc_matrix(A, dtype=float))
        except RuntimeError as err:  # "Factor is exactly singular"
            raise LinearSolverError(f"superlu factorisation failed: {err}") from err
        self.setup_seconds = time.perf_counter() - start
        self.n_factorizations = 1

    def _solve(self, b, x0):
        return self._lu.solve(b)


@register_strategy
class CholmodSolver(LinearSolver):
    """Sparse Cholesky (CHOLMOD via scikit-sparse); SPD matrices only."""

    name = "cholmod"
    package = "sksparse"
    install = "scikit-sparse"
    spd_only = True

    def __init__(self, A, *, spd: bool = True, **common):
        super().__init__(A)
        from sksparse.cholmod import cholesky

        start = time.perf_counter()
        try:
            self._factor = cholesky(sp.csc_matrix(A, dtype=float))
        except Exception as err:  # CholmodNotPositiveDefiniteError and friends
            raise LinearSolverError(f"cholmod factorisation failed: {err}") from err
        self.setup_seconds = time.perf_counter() - start
        self.n_factorizations = 1

    def _solve(self, b, x0):
        return self._factor(b)
