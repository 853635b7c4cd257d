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
    hence the :data:`SUPERLU_MAX_DOFS` limit.
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

import ctypes
import functools
import hashlib
import importlib.util
from collections import OrderedDict
import time
from typing import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

#: Strategy names accepted by :func:`make_solver`.
STRATEGIES = ("auto", "diagonal", "superlu", "pardiso", "cholmod", "amg-cg", "jacobi-cg")
#: ``"auto"`` uses SuperLU below this size: factor and solve take milliseconds
#: and locating and initialising MKL (about a second, once) is not worth it.
AUTO_SMALL = 5_000
#: SuperLU refuses larger matrices. The project notes report 269 s and 15 GB at
#: 1.37e5 dofs of 3D elasticity; measured here with scipy 1.17 (COLAMD): 17.8 s,
#: 1.7 GB (P1) and 31.4 s, 2.3 GB (P2) at 1.0e5 dofs, 12-15x PARDISO's factor time
#: and growing faster with n (docs/benchmarks.md, section 4b). A conservative guard.
SUPERLU_MAX_DOFS = 60_000
#: Without PARDISO or CHOLMOD, ``"auto"`` uses SuperLU up to its own limit and
#: AMG-preconditioned CG above. Measured on the clamped P1 solid beam (Newmark
#: ``M + dt^2/4 K``, one BLAS thread; docs/benchmarks.md, "Which strategy is the default"): SuperLU /
#: AMG-CG setup 1.06 / 0.77 s and step 0.021 / 0.334 s at 20,262 dofs, 2.1 / 0.4 s
#: and 0.031 / 0.49 s at 37,356, 5.1 / 1.1 s and 0.063 / 0.79 s at 56,790 (0.84
#: against 0.39 GB): SuperLU is 12-16x cheaper a step and ahead after 4-6 steps.
AUTO_DIRECT_THRESHOLD = SUPERLU_MAX_DOFS


class LinearSolverError(RuntimeError):
    """A linear solve failed (singular/indefinite matrix, CG did not converge)."""


class LinearSolver:
    """A reusable solver of ``A x = b`` for one fixed (n, n) matrix ``A``.

    Attributes
    ----------
    name : str
        The strategy actually used (``"auto"`` is resolved).
    shape : tuple of int
        Shape of ``A``.
    setup_seconds : float
        Wall time of the factorisation or preconditioner setup.
    n_factorizations : int
        Factorisations (or multigrid setups) this solver performed: 1, or 0
        for ``"diagonal"``. Reuse is the point: it never grows with solves.
    n_solves : int
        Number of calls to :meth:`solve`.
    last_iterations, total_iterations : int or None
        Krylov iterations of the last solve and of all solves (iterative
        strategies only; ``None`` for direct ones).
    """

    name: str = "?"
    last_iterations: int | None = None
    total_iterations: int | None = None

    def __init__(self, A):
        self.shape = A.shape
        self.setup_seconds = 0.0
        self.n_factorizations = 0
        self.n_solves = 0

    def solve(self, b: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """(n,) ndarray ``x`` with ``A x = b``; ``x0`` is a warm start (iterative only)."""
        b = np.asarray(b, dtype=float)
        if b.shape[0] != self.shape[0]:
            raise ValueError(f"right-hand side has {b.shape[0]} rows, expected {self.shape[0]}")
        self.n_solves += 1
        return self._solve(b, x0)

    def _solve(self, b, x0):  # pragma: no cover - interface
        raise NotImplementedError

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(name={self.name!r}, n={self.shape[0]}, "
                f"setup_seconds={self.setup_seconds:.3g}, n_solves={self.n_solves})")


class DiagonalSolver(LinearSolver):
    """``x = b / d`` for ``A = diag(d)``."""

    name = "diagonal"

    def __init__(self, A):
        super().__init__(A)
        d = np.asarray(A.diagonal(), dtype=float)
        if np.any(d == 0.0):
            raise LinearSolverError(f"diagonal matrix has {np.count_nonzero(d == 0)} zero entries")
        self._inverse = 1.0 / d

    def _solve(self, b, x0):
        return b * self._inverse if b.ndim == 1 else b * self._inverse[:, None]


class SuperLUSolver(LinearSolver):
    """Sparse LU of SciPy (SuperLU), for small problems."""

    name = "superlu"

    def __init__(self, A):
        super().__init__(A)
        if A.shape[0] > SUPERLU_MAX_DOFS:
            raise ValueError(f"superlu is limited to {SUPERLU_MAX_DOFS} dofs (got {A.shape[0]}); "
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


class PardisoSolver(LinearSolver):
    """MKL PARDISO factorised once (phase 12) and reused (phase 33).

    ``pypardiso.spsolve`` keeps one factor per matrix and compares the whole
    matrix (or its hash) on every call to decide whether to re-factorise; here
    the low-level :class:`pypardiso.PyPardisoSolver` is driven by phase
    directly, with the 1-based CSR index arrays built once. Locating MKL
    (``PyPardisoSolver()``) costs about a second here, so the library function
    is looked up once per process and each solver keeps its own handle. ``spd=True`` uses
    matrix type 2 (real SPD, upper triangle stored), otherwise 11 (real
    nonsymmetric, full matrix).
    """

    name = "pardiso"

    def __init__(self, A, *, spd: bool = True):
        super().__init__(A)
        self._mtype = 2 if spd else 11
        # one PARDISO handle per factor: internal pointers, parameters, permutation
        self._pt = np.zeros(64, dtype=np.int64)
        self._iparm = np.zeros(64, dtype=np.int32)  # iparm[0] = 0: MKL defaults
        self._perm = np.zeros(0, dtype=np.int32)
        A = sp.csr_matrix(A, dtype=float)
        if spd:
            A = sp.triu(A, format="csr")  # mtype 2 reads the upper triangle only
        A.sum_duplicates()
        A.sort_indices()
        if spd and np.any(A.diagonal() == 0.0):
            raise LinearSolverError("pardiso (SPD): the matrix has zero diagonal entries")
        self._data = np.ascontiguousarray(A.data, dtype=np.float64)
        self._ia = np.ascontiguousarray(A.indptr + 1, dtype=np.int32)
        self._ja = np.ascontiguousarray(A.indices + 1, dtype=np.int32)
        self._n = A.shape[0]
        self._factored = False
        #: how often each PARDISO phase ran (12: analyse + factorise, 33: solve)
        self.phase_calls = {12: 0, 33: 0, -1: 0}
        _mkl_pardiso()  # locating MKL (1-5 s once per process) is not the factorisation
        start = time.perf_counter()
        self._call(12, np.zeros((self._n, 1), order="F"))
        self._factored = True
        self.setup_seconds = time.perf_counter() - start
        self.n_factorizations = 1

    def _call(self, phase: int, b: np.ndarray) -> np.ndarray:
        self.phase_calls[phase] = self.phase_calls.get(phase, 0) + 1
        int_p = ctypes.POINTER(ctypes.c_int32)
        dbl_p = ctypes.POINTER(ctypes.c_double)
        x = np.zeros_like(b)
        error = ctypes.c_int32(0)
        nrhs = 1 if b.ndim == 1 else b.shape[1]
        _mkl_pardiso()(
            self._pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
            ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(1)),
            ctypes.byref(ctypes.c_int32(self._mtype)), ctypes.byref(ctypes.c_int32(phase)),
            ctypes.byref(ctypes.c_int32(self._n)), self._data.ctypes.data_as(dbl_p),
            self._ia.ctypes.data_as(int_p), self._ja.ctypes.data_as(int_p),
            self._perm.ctypes.data_as(int_p), ctypes.byref(ctypes.c_int32(nrhs)),
            self._iparm.ctypes.data_as(int_p), ctypes.byref(ctypes.c_int32(0)),
            b.ctypes.data_as(dbl_p), x.ctypes.data_as(dbl_p), ctypes.byref(error))
        if error.value != 0:
            hint = " (matrix not positive definite? pass spd=False)" if error.value == -4 else ""
            raise LinearSolverError(f"pardiso phase {phase} failed with error {error.value}{hint}")
        return x

    def _solve(self, b, x0):
        x = self._call(33, np.asfortranarray(b, dtype=np.float64))
        return np.ascontiguousarray(x)

    def close(self) -> None:
        """Release PARDISO's memory for this factor (also done on garbage collection)."""
        if getattr(self, "_factored", False):
            self._factored = False
            self._call(-1, np.zeros((self._n, 1), order="F"))

    def __del__(self):
        try:
            self.close()
        except Exception:  # interpreter shutdown: ctypes may already be gone
            pass


@functools.cache
def _mkl_pardiso():
    """The ctypes ``pardiso`` function of MKL, located once (pypardiso does the search)."""
    from pypardiso import PyPardisoSolver

    if ctypes.sizeof(ctypes.c_void_p) != 8:
        raise ImportError("the pardiso strategy needs a 64-bit Python")
    return PyPardisoSolver()._mkl_pardiso


class CholmodSolver(LinearSolver):
    """Sparse Cholesky (CHOLMOD via scikit-sparse); SPD matrices only."""

    name = "cholmod"

    def __init__(self, A):
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


class AMGKrylovSolver(_PreconditionedKrylov):
    r"""Smoothed-aggregation AMG (pyamg) as a preconditioner of CG (or GMRES).

    Stops when ``||b - A x|| <= rtol ||b||``; raises :class:`LinearSolverError`
    when ``maxiter`` iterations do not get there.
    """

    name = "amg-cg"

    def __init__(self, A, *, near_nullspace=None, rtol: float = 1e-10, maxiter: int = 500,
                 spd: bool = True):
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


class JacobiCGSolver(_PreconditionedKrylov):
    r"""CG preconditioned by ``diag(A)^{-1}``: no factorisation, O(nnz) memory.

    For SPD matrices that diagonal scaling makes well conditioned independently
    of the mesh: the consistent mass matrix of Lagrange elements (Wathen, IMA
    J. Numer. Anal. 7, 1987). Used there, e.g. for the one mass solve of an
    implicit scheme's initial acceleration, it avoids a second direct factor
    next to the effective matrix's.
    """

    name = "jacobi-cg"

    def __init__(self, A, *, rtol: float = 1e-10, maxiter: int = 500, spd: bool = True):
        if not spd:
            raise ValueError("strategy 'jacobi-cg' needs an SPD matrix (spd=True)")
        super().__init__(A, rtol=rtol, maxiter=maxiter, spd=True)
        start = time.perf_counter()
        diagonal = self._A.diagonal()
        if not np.all(diagonal > 0):
            raise LinearSolverError("jacobi-cg needs a positive diagonal (an SPD matrix)")
        self._preconditioner = sp.diags(1.0 / diagonal).tocsr()
        self.setup_seconds = time.perf_counter() - start


def is_available(strategy: str) -> bool:
    """Whether the package behind ``strategy`` can be imported here."""
    module = {"pardiso": "pypardiso", "cholmod": "sksparse", "amg-cg": "pyamg"}.get(strategy)
    return module is None or importlib.util.find_spec(module) is not None


def _is_diagonal(A) -> bool:
    if A.nnz > A.shape[0] and A.format in ("csr", "csc"):
        # cheap exit for the usual FE matrix: some row has two stored entries
        counts = np.diff(A.indptr)
        if np.any(counts > 1) and A.data.all():
            return False
    A = sp.coo_matrix(A)
    return bool(np.all((A.row == A.col) | (A.data == 0.0)))


def choose_strategy(A, *, spd: bool = True) -> str:
    """The concrete strategy ``"auto"`` picks for ``A``: by size and availability only.

    Whether ``A`` is diagonal, its number of rows, and which packages import;
    never the spatial dimension (module docstring, "Size, not dimension").
    """
    if _is_diagonal(A):
        return "diagonal"
    n = A.shape[0]
    if n < AUTO_SMALL:
        return "superlu"
    if is_available("pardiso"):
        return "pardiso"
    if spd and is_available("cholmod"):
        return "cholmod"
    return "superlu" if n <= AUTO_DIRECT_THRESHOLD else "amg-cg"


def make_solver(A, strategy: str = "auto", *, near_nullspace=None, rtol: float = 1e-10,
                maxiter: int = 500, spd: bool = True) -> LinearSolver:
    r"""Set up a reusable solver of ``A x = b`` for the (n, n) sparse matrix ``A``.

    Parameters
    ----------
    A : (n, n) sparse matrix
        The matrix; symmetric positive definite when ``spd`` (the default).
    strategy : str
        One of :data:`STRATEGIES`; ``"auto"`` follows :func:`choose_strategy`
        and the returned solver's ``.name`` says what was chosen.
    near_nullspace : (n, k) ndarray, optional
        Near-null-space vectors for ``"amg-cg"`` (rigid-body modes for
        elasticity, a constant vector for a Laplacian). Ignored otherwise.
    rtol : float
        Relative residual ``||b - A x|| / ||b||`` at which ``"amg-cg"`` stops.
    maxiter : int
        Iteration cap of ``"amg-cg"``.
    spd : bool
        Whether ``A`` is SPD (PARDISO matrix type 2 and CG) or general
        (matrix type 11 and GMRES; ``"cholmod"`` refuses).

    Returns
    -------
    LinearSolver
        Call ``.solve(b, x0=None)`` as often as needed; the setup is reused.
    """
    if strategy not in STRATEGIES:
        raise ValueError(f"unknown linear-solver strategy {strategy!r}; "
                         f"valid: {', '.join(STRATEGIES)}")
    if A.shape[0] != A.shape[1]:
        raise ValueError(f"matrix must be square, got shape {A.shape}")
    if strategy == "auto":
        strategy = choose_strategy(A, spd=spd)
    if not is_available(strategy):
        raise ImportError(f"strategy {strategy!r} needs a package that is not installed "
                          f"({'pypardiso' if strategy == 'pardiso' else 'scikit-sparse'})")
    if strategy == "diagonal":
        if not _is_diagonal(A):
            raise ValueError("strategy 'diagonal' needs a diagonal matrix")
        return DiagonalSolver(A)
    if strategy == "superlu":
        return SuperLUSolver(A)
    if strategy == "pardiso":
        return PardisoSolver(A, spd=spd)
    if strategy == "cholmod":
        if not spd:
            raise ValueError("strategy 'cholmod' needs an SPD matrix (spd=True)")
        return CholmodSolver(A)
    if strategy == "jacobi-cg":
        return JacobiCGSolver(A, rtol=rtol, maxiter=maxiter, spd=spd)
    return AMGKrylovSolver(A, near_nullspace=near_nullspace, rtol=rtol, maxiter=maxiter, spd=spd)


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
            raise ValueError(f"size must be >= 1, got {size}")
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
