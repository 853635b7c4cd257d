"""Preconditioned Krylov strategies: smoothed-aggregation AMG and Jacobi."""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femrom._errors import FemromValueError
from femrom.solvers._base import LinearSolver, LinearSolverError, register_strategy


class _PreconditionedKrylov(LinearSolver):
    """CG (or GMRES when not SPD) with a fixed preconditioner ``self._preconditioner``.

    Stops when ``||b - A x|| <= rtol ||b||``; raises :class:`LinearSolverError`
    when ``maxiter`` iterations do not get there.
    """

    def __init__(self, A, *, rtol: float, maxiter: int, spd: bool):
        super().__init__(A)
        self._A = sp.csr_matrix(A, dtype=float)
        self._rtol, self._maxiter, self._spd = float(rtol), int(maxiter), spd
        self.last_iterations = 0
        self.total_iterations = 0

    def _solve(self, b, x0):
        if b.ndim != 1:
            return np.column_stack([self._solve(col, None) for col in b.T])
        count = [0]

        def callback(_):
            count[0] += 1

        if self._spd:
            x, info = spla.cg(self._A, b, x0=x0, rtol=self._rtol, atol=0.0,
                              maxiter=self._maxiter, M=self._preconditioner, callback=callback)
        else:
            x, info = spla.gmres(self._A, b, x0=x0, rtol=self._rtol, atol=0.0, restart=50,
                                 maxiter=self._maxiter, M=self._preconditioner,
                                 callback=callback, callback_type="pr_norm")
        self.last_iterations = count[0]
        self.total_iterations += count[0]
        if info != 0:
            b_norm = max(np.linalg.norm(b), np.finfo(float).tiny)
            residual = np.linalg.norm(b - self._A @ x) / b_norm
            raise LinearSolverError(
                f"{self.name} did not reach rtol={self._rtol:g} in {self._maxiter} iterations "
                f"(relative residual {residual:.3g})")
        return x


@register_strategy
class AMGKrylovSolver(_PreconditionedKrylov):
    r"""Smoothed-aggregation AMG (pyamg) as a preconditioner of CG (or GMRES).

    Stops when ``||b - A x|| <= rtol ||b||``; raises :class:`LinearSolverError`
    when ``maxiter`` iterations do not get there.
    """

    name = "amg-cg"
    package = "pyamg"

    def __init__(self, A, *, near_nullspace=None, rtol: float = 1e-10, maxiter: int = 500,
                 spd: bool = True, **common):
        super().__init__(A, rtol=rtol, maxiter=maxiter, spd=spd)
        import pyamg

        A = self._A
        B = None if near_nullspace is None else np.asarray(near_nullspace, dtype=float)
        if B is not None:
            B = B.reshape(A.shape[0], -1)
        start = time.perf_counter()
        hierarchy = pyamg.smoothed_aggregation_solver(
            A, B=B, symmetry="hermitian" if spd else "nonsymmetric")
        self._preconditioner = hierarchy.aspreconditioner(cycle="V")
        self.setup_seconds = time.perf_counter() - start
        self.n_factorizations = 1
        self.n_levels = len(hierarchy.levels)


@register_strategy
class JacobiCGSolver(_PreconditionedKrylov):
    r"""CG preconditioned by ``diag(A)^{-1}``: no factorisation, O(nnz) memory.

    For SPD matrices that diagonal scaling makes well conditioned independently
    of the mesh: the consistent mass matrix of Lagrange elements (Wathen, IMA
    J. Numer. Anal. 7, 1987). Used there, e.g. for the one mass solve of an
    implicit scheme's initial acceleration, it avoids a second direct factor
    next to the effective matrix's.
    """

    name = "jacobi-cg"
    spd_only = True

    def __init__(self, A, *, rtol: float = 1e-10, maxiter: int = 500, spd: bool = True, **common):
        if not spd:
            raise FemromValueError("strategy 'jacobi-cg' needs an SPD matrix (spd=True)")
        super().__init__(A, rtol=rtol, maxiter=maxiter, spd=True)
        start = time.perf_counter()
        diagonal = self._A.diagonal()
        if not np.all(diagonal > 0):
            raise LinearSolverError("jacobi-cg needs a positive diagonal (an SPD matrix)")
        self._preconditioner = sp.diags(1.0 / diagonal).tocsr()
        self.setup_seconds = time.perf_counter() - start

