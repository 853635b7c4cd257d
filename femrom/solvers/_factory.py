r"""Linear-solver strategies for the repeated solves ``A x = b`` of a time integrator.

An implicit scheme on a linear system solves with the same effective matrix
(e.g. ``M + gamma dt C + beta dt^2 K``) at every step, so a strategy splits the
work into a one-off *setup* (a sparse factorisation, or an algebraic-multigrid
hierarchy) and cheap *solves* that reuse it.

Strategies
----------
``"diagonal"``
    ``x = b / diag(A)`` for a diagonal (lumped) matrix; no setup.
``"superlu"``
    :func:`scipy.sparse.linalg.splu`. Fine for small problems only: on 3D
    elasticity the fill grows so fast that ~1e5 dofs takes minutes and GBs,
    hence its ``max_dofs`` limit (:data:`SUPERLU_MAX_DOFS` by default).
``"pardiso"``
    Intel MKL PARDISO through ``pypardiso``: factorised once (phase 12), then
    forward/backward substitution only (phase 33) for every solve.
``"cholmod"``
    Sparse Cholesky from ``scikit-sparse`` (SPD only), when importable.
``"jacobi-cg"``
    Conjugate gradients preconditioned by the inverse diagonal: no factor at
    all, for matrices that diagonal scaling makes well conditioned whatever
    the mesh, such as a consistent mass matrix (Wathen, IMA J. Numer. Anal. 7,
    1987). SPD only.
``"amg-cg"``
    Conjugate gradients preconditioned by one V-cycle of a pyamg
    smoothed-aggregation hierarchy built with ``B = near_nullspace`` (the
    rigid-body modes for elasticity); GMRES when ``spd=False``. The caller
    passes a warm start ``x0`` (e.g. the previous step's solution).
``"dense"``
    Cholesky or LU of an ndarray (:mod:`._dense`): a reduced model's small matrices.
``"auto"``
    :func:`choose_strategy`, by the matrix alone (diagonal or not, and its
    size): ``"diagonal"`` for a diagonal matrix; ``"superlu"`` below
    :data:`AUTO_SMALL` dofs; otherwise ``"pardiso"`` if importable, else
    ``"cholmod"`` (SPD only) if importable, else ``"superlu"`` up to
    :data:`AUTO_DIRECT_THRESHOLD` (= :data:`SUPERLU_MAX_DOFS`) dofs, else ``"amg-cg"``. ``"jacobi-cg"`` is
    never chosen automatically: ask for it (the fishtail case does, for its
    consistent mass).

Size, not dimension
-------------------
The rule looks at the size only, not at whether the problem is 1D, 2D or 3D
(a matrix does not say). It uses SuperLU only for small problems, whatever
their dimension, so it keeps to "SuperLU only for small or 1D/2D problems";
it does not extend SuperLU to large 1D/2D problems, where a dimension hint
from the scene would be needed and PARDISO, when installed, is a direct
solver as well. The measurements behind it are 3D elasticity
(``docs/benchmarks.md``, sections 3 and 4b): at 2e4 dofs SuperLU and PARDISO
take the same time per step (0.015-0.022 s) and SuperLU sets up 2-3.5x slower;
at 1e5 dofs one SuperLU factorisation takes 17.8 s and 1.7 GB (P1) or 31.4 s
and 2.3 GB (P2), 12-15x PARDISO's fresh factorisation. SuperLU on large 1D or
2D problems was not measured. Where a dimension hint would matter (no PARDISO
and no CHOLMOD, a 1D/2D problem above :data:`SUPERLU_MAX_DOFS` dofs), the
rule takes AMG-CG.

Measured here (3D P1 elasticity, clamped bar, 2 shared cores, a spot check
not kept in ``benchmarks/results``): at 3.5e3 dofs SuperLU factorises in
0.08 s and PARDISO in 0.06 s; at 1.45e4 dofs SuperLU takes 2.4 s and PARDISO
0.43 s. The ladder (``benchmarks/results/fom_ladder.json``) gives 0.55-0.84 s
against 0.16-0.24 s at 2e4 dofs: PARDISO is preferred as soon as the problem
is not tiny.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from typing import Callable

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.solvers._base import (
    STRATEGY_CLASSES,
    LinearSolver,
    is_available,
    is_diagonal,
)
from femrom.solvers._direct import SUPERLU_MAX_DOFS

#: ``"auto"`` uses SuperLU below this size: factor and solve take milliseconds
#: and locating and initialising MKL (about a second, once) is not worth it.
AUTO_SMALL = 5_000
#: Without PARDISO or CHOLMOD, ``"auto"`` uses SuperLU up to its own limit and
#: AMG-preconditioned CG above. Measured on the clamped P1 solid beam (Newmark
#: ``M + dt^2/4 K``, one BLAS thread; docs/benchmarks.md, "Which strategy is the default"): SuperLU /
#: AMG-CG setup 1.06 / 0.77 s and step 0.021 / 0.334 s at 20,262 dofs, 2.1 / 0.4 s
#: and 0.031 / 0.49 s at 37,356, 5.1 / 1.1 s and 0.063 / 0.79 s at 56,790 (0.84
#: against 0.39 GB): SuperLU is 12-16x cheaper a step and ahead after 4-6 steps.
AUTO_DIRECT_THRESHOLD = SUPERLU_MAX_DOFS


def strategies() -> tuple[str, ...]:
    """``"auto"`` and the registered strategy names (what :func:`make_solver` accepts)."""
    return ("auto", *STRATEGY_CLASSES)


def choose_strategy(A, *, spd: bool = True, small: int = AUTO_SMALL,
                    direct_threshold: int = AUTO_DIRECT_THRESHOLD,
                    available: Callable[[str], bool] = is_available) -> str:
    """The concrete strategy ``"auto"`` picks for ``A``: by size and availability only.

    Whether ``A`` is diagonal, its number of rows, and which packages import;
    never the spatial dimension (module docstring, "Size, not dimension").
    ``small``, ``direct_threshold`` and ``available`` are the rule's inputs
    (defaults :data:`AUTO_SMALL`, :data:`AUTO_DIRECT_THRESHOLD`, the packages
    installed here), open so that the rule can be checked at any size. A matrix given
    as an ndarray (a reduced model's) takes ``"dense"``.
    """
    if not sp.issparse(A):
        return "dense"
    if is_diagonal(A):
        return "diagonal"
    n = A.shape[0]
    if n < small:
        return "superlu"
    if available("pardiso"):
        return "pardiso"
    if spd and available("cholmod"):
        return "cholmod"
    return "superlu" if n <= direct_threshold else "amg-cg"


def make_solver(A, strategy: str = "auto", *, near_nullspace=None, rtol: float = 1e-10,
                maxiter: int = 500, spd: bool = True,
                max_dofs: int = SUPERLU_MAX_DOFS) -> LinearSolver:
    r"""Set up a reusable solver of ``A x = b`` for the (n, n) sparse matrix ``A``.

    Parameters
    ----------
    A : (n, n) sparse matrix
        The matrix; symmetric positive definite when ``spd`` (the default).
    strategy : str
        One of :func:`strategies`; ``"auto"`` follows :func:`choose_strategy`
        and the returned solver's ``.name`` says what was chosen.
    near_nullspace : (n, k) ndarray, optional
        Near-null-space vectors for ``"amg-cg"`` (rigid-body modes for
        elasticity, a constant vector for a Laplacian). Ignored otherwise.
    rtol : float
        Relative residual ``||b - A x|| / ||b||`` at which the Krylov strategies stop.
    maxiter : int
        Iteration cap of the Krylov strategies.
    spd : bool
        Whether ``A`` is SPD (PARDISO matrix type 2 and CG) or general
        (matrix type 11 and GMRES; the SPD-only strategies refuse).
    max_dofs : int
        Largest matrix ``"superlu"`` accepts.

    Returns
    -------
    LinearSolver
        Call ``.solve(b, x0=None)`` as often as needed; the setup is reused.
    """
    if strategy != "auto" and strategy not in STRATEGY_CLASSES:
        raise FemromValueError(f"unknown linear-solver strategy {strategy!r}; "
                               f"valid: {', '.join(strategies())}")
    if A.shape[0] != A.shape[1]:
        raise FemromValueError(f"matrix must be square, got shape {A.shape}")
    if strategy == "auto":
        strategy = choose_strategy(A, spd=spd)
    cls = STRATEGY_CLASSES[strategy]
    if not cls.available():
        raise ImportError(f"strategy {strategy!r} needs a package that is not installed "
                          f"({cls.install or cls.package})")
    if cls.spd_only and not spd:
        raise FemromValueError(f"strategy {strategy!r} needs an SPD matrix (spd=True)")
    return cls(A, spd=spd, near_nullspace=near_nullspace, rtol=rtol, maxiter=maxiter,
               max_dofs=max_dofs)


def matrix_digest(A) -> str:
    """A BLAKE2 digest of a sparse matrix's shape, CSR structure and values (equal matrices, equal digests)."""
    A = sp.csr_matrix(A)
    h = hashlib.blake2b(digest_size=20)
    h.update(np.asarray(A.shape, dtype=np.int64).tobytes())
    for array in (A.indptr, A.indices, A.data):
        h.update(np.ascontiguousarray(array).view(np.uint8))
    return h.hexdigest()


class _Reused(LinearSolver):
    """Another user's view of a solver set up before: same solves, no new setup counted."""

    def __init__(self, solver: LinearSolver):
        super().__init__(solver)
        self._solver = solver
        self.name = solver.name

    def _solve(self, b, x0):
        before = self._solver.total_iterations
        x = self._solver.solve(b, x0)
        if before is not None:
            self.last_iterations = self._solver.last_iterations
            self.total_iterations = (self.total_iterations or 0) + self._solver.last_iterations
        return x


class SolverCache:
    r"""A solver factory that sets up each distinct matrix once, for several runs.

    Runs of one model with one time step solve with the same effective matrix
    ``M + gamma dt C + beta dt^2 K``; at 7.6e5 P2 dofs its PARDISO factor takes
    minutes and about 9 GB. Called like :func:`make_solver` by the integrators,
    ``cache(A, spd=True)`` returns, for a matrix equal to one set up before
    (same shape, structure and values: :func:`matrix_digest`), a view of that
    solver that reports no new factorisation; otherwise it sets one up.

    Parameters
    ----------
    strategy : str
        Passed to :func:`make_solver`, as are ``options``.
    size : int
        Setups kept at most; the oldest is dropped first (each may be GBs).
    """

    def __init__(self, strategy: str = "auto", *, size: int = 1, **options):
        if size < 1:
            raise FemromValueError(f"size must be >= 1, got {size}")
        self.strategy, self.size, self.options = strategy, int(size), options
        self._solvers: OrderedDict[tuple, LinearSolver] = OrderedDict()
        self.hits = self.misses = 0

    def __call__(self, A, spd: bool = True) -> LinearSolver:
        key = (matrix_digest(A), bool(spd))
        solver = self._solvers.get(key)
        if solver is not None:
            self.hits += 1
            self._solvers.move_to_end(key)
            return _Reused(solver)
        self.misses += 1
        solver = make_solver(A, self.strategy, spd=spd, **self.options)
        self._solvers[key] = solver
        while len(self._solvers) > self.size:
            self._solvers.popitem(last=False)
        return solver

    def clear(self) -> None:
        """Drop every kept setup (frees the factors)."""
        self._solvers.clear()


#: Signature of a solver factory the integrators call: ``factory(A, spd=...)``.
SolverFactory = Callable[..., LinearSolver]

