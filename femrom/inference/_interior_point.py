r"""A primal-dual interior-point method for the structured regression (dense Newton steps).

The problem of :mod:`._problem` after the free blocks are eliminated
(:func:`femrom.inference._structured_lstsq.eliminate_free`) has square blocks only,

.. math::

    \min_{X = [X_1, \dots, X_b]} \; f(X) = \langle X G, X\rangle + 2\langle X, H^\top\rangle + c
    \quad\text{s.t.}\quad X_j = X_j^\top, \qquad
    S_j := X_j - \varepsilon_j I \succeq 0 \;\; (\text{"psd" blocks}),

a convex quadratic program over a product of semidefinite cones. On POD
data ``G`` is very ill-conditioned (``kappa(G) ~ 1e7 - 1e10``); first-order
methods then crawl, while a Newton method whose linear systems are solved
directly is insensitive to ``kappa(G)``. This module is such a method:

- **Coordinates.** Every symmetric block in the orthonormal ``svec`` basis
  (:mod:`._svec`): ``x`` has ``m = b r (r + 1) / 2`` entries and
  ``f = x^T P x + 2 q^T x + c`` with a sparse Hessian ``2 P``.
- **Primal-dual path following** with Nesterov-Todd scaling and Mehrotra's
  predictor-corrector, as in Todd, Toh & Tutuncu (SIAM J. Optim. 8, 1998)
  and Vandenberghe's notes on the cone QP solver of CVXOPT ("The CVXOPT
  linear and quadratic cone program solvers", 2010). The primal iterate is
  always feasible (``S_j = X_j - eps_j I`` is the slack, kept positive
  definite), so only the dual residual ``sym(grad f)_j - Z_j`` and the
  complementarity ``<S_j, Z_j>`` are driven to zero. With the scaling
  ``R_j`` (``R^{-1} S R^{-T} = R^T Z R = Lambda`` diagonal), a Newton step
  solves the dense symmetric positive-definite system

  .. math::

      (2 P + \mathrm{blockdiag}_j(W_j^{-1} \otimes_s W_j^{-1}))\, \Delta x
      = -r_{\mathrm{dual}} + \mathrm{svec}(R_j^{-\top} Y_j R_j^{-1}),
      \qquad W_j = R_j R_j^\top,

  by one Cholesky factorisation (``m^3 / 3`` flops) shared by the
  predictor and the corrector.
- **Start.** The unconstrained symmetric least-squares point (one solve with
  ``2 P``; if it is feasible it is the optimum and nothing else runs), its slack
  eigenvalues floored at ``START_FLOOR`` times the largest, and
  ``Z_j = mu_0 S_j^{-1}`` (on the central path).
- **Certificate.** Every iterate is feasible, so :func:`~femrom.inference._duality_gap.gap_bound`
  with ``Lambda = Z`` bounds its gap rigorously whatever the conditioning
  (:mod:`._duality_gap`); near the end :func:`exact_gap_bound` evaluates the dual
  function exactly with the Newton matrix.

Cost: the dense Newton matrix has ``m^2`` entries and its factorisation
``m^3 / 3`` flops (two blocks: ``r = 30``: ``m = 930``, 10 ms; ``r = 60``: 3660,
0.4 s; ``r = 100``: 10100, 0.8 GB and ~8 s on one core; ``r = 150``: 22650, 4.1 GB
and 68 s on two, :func:`blocked_cholesky`; ``r = 200``: 40200, 12.9 GB and 4.5 min),
about 10-15 iterations.
:func:`femrom.inference.solve_fast` uses this method for ill-conditioned data
up to ``FastSolver.ipm_max_unknowns``.
"""

from __future__ import annotations

import contextlib
import os

import numpy as np
import scipy.linalg as sla

from femrom._progress import Steps
from femrom.inference._duality_gap import gap_bound, relative_gap, smallest_eigenvalue
from femrom.inference._problem import GramProblem
from femrom.inference._svec import hessian, smat, svec, svec_index, sym, sym_kron


# -- Nesterov-Todd scaling ---------------------------------------------------------
def _factor(S: np.ndarray) -> np.ndarray:
    """``L`` with ``S = L L^T`` (Cholesky; a symmetric square root if that fails)."""
    try:
        return np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        g, P = np.linalg.eigh(S)
        return P * np.sqrt(np.maximum(g, np.finfo(float).tiny))


def nt_scaling(S: np.ndarray, Z: np.ndarray):
    r"""``(R, R^{-1}, lambda)`` with ``R^{-1} S R^{-T} = R^T Z R = diag(lambda)``.

    From ``S = L_s L_s^T``, ``Z = L_z L_z^T`` and the SVD ``L_z^T L_s = U diag(lambda) V^T``:
    ``R = L_s V diag(lambda)^{-1/2}``, ``R^{-1} = diag(lambda)^{-1/2} U^T L_z^T``
    (Todd, Toh & Tutuncu 1998; Vandenberghe 2010, sec. 4.3). ``W = R R^T`` is the
    Nesterov-Todd scaling point, ``W Z W = S``.
    """
    Ls, Lz = _factor(S), _factor(Z)
    U, lam, Vt = np.linalg.svd(Lz.T @ Ls)
    root = np.sqrt(lam)
    return (Ls @ Vt.T) / root, (U.T @ Lz.T) / root[:, None], lam


def _max_step(lam: np.ndarray, D: np.ndarray) -> float:
    """Largest ``alpha`` with ``diag(lam) + alpha D >= 0``."""
    root = 1.0 / np.sqrt(lam)
    t = np.linalg.eigvalsh(root[:, None] * D * root[None, :])[0]
    return np.inf if t >= 0 else -1.0 / t


def _jordan(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    return 0.5 * (A @ B + B @ A)


def _assemble(problem: GramProblem, blocks) -> np.ndarray:
    X = np.zeros((problem.r, problem.p))
    for A, s in zip(blocks, problem.slices()):
        X[:, s] = A
    return X


# -- Newton systems --------------------------------------------------------------
#: Newton matrices with at least this many unknowns are factorised with every BLAS
#: thread (the solver otherwise runs on one, see :mod:`._structured_lstsq`): at m = 10 100
#: (r = 100) a Cholesky took 6.6 s on one thread and 3.6 s on two with another
#: process busy; at m = 3 660 two threads were slower under that load (1.5 s
#: against 0.34 s), where the work per thread is too small to hide the contention.
THREADED_UNKNOWNS = 8000

#: Newton matrices with at least this many unknowns are factorised by
#: :func:`blocked_cholesky` instead of LAPACK's ``potrf``: OpenBLAS's threaded
#: ``syrk`` (called by its ``potrf``) crashes the process with two threads from order
#: ~16 000 here (measured 2026-11-27 with scipy's and numpy's OpenBLAS, 0.3.31 and 0.3.30:
#: orders 15 000 complete, 16 000 segfault in ``potrf`` and in a bare ``syrk``; one
#: thread completes, at half the speed; the same family of faults as OpenBLAS
#: issues #2562 and #2821). The blocked form calls ``potrf`` only on small diagonal
#: blocks and ``gemm`` for the updates, and ran at order 16 000 in 19 s on two
#: threads (35 s for ``potrf`` on one).
BLOCKED_UNKNOWNS = 14_000
CHOLESKY_BLOCK = 4096


def blocked_cholesky(A: np.ndarray, block: int = CHOLESKY_BLOCK) -> np.ndarray:
    r"""The lower Cholesky factor of the Fortran-ordered ``A``, in place, by tiles.

    With tiles ``A_ij`` of ``block`` rows and columns, for every ``j``:
    ``L_jj = chol(A_jj)`` (``potrf``), ``L_ij = A_ij L_jj^{-T}`` below it (``trsm``),
    and ``A_ik <- A_ik - L_ij L_kj^T`` for ``j < k <= i`` (``gemm``). Every call works
    on one tile, so the temporaries are a few tiles (128 MB each at 4096). Only the
    lower triangle holds the factor (what ``cho_solve(..., lower=True)`` reads); the
    strict upper triangle is workspace. Raises ``LinAlgError`` if ``A`` is not
    positive definite.
    """
    from scipy.linalg.blas import dgemm, dtrsm
    from scipy.linalg.lapack import dpotrf

    n = A.shape[0]
    tiles = [slice(j, min(j + block, n)) for j in range(0, n, block)]
    for t, J in enumerate(tiles):
        c, info = dpotrf(A[J, J], lower=1, clean=0)
        if info != 0:
            raise np.linalg.LinAlgError(f"not positive definite (leading minor {J.start + info})")
        A[J, J] = c
        for I in tiles[t + 1:]:
            A[I, J] = dtrsm(1.0, c, A[I, J], side=1, lower=1, trans_a=1)
        for u, Kt in enumerate(tiles[t + 1:], start=t + 1):
            right = A[Kt, J]
            for I in tiles[u:]:
                A[I, Kt] = dgemm(-1.0, A[I, J], right, beta=1.0, c=A[I, Kt], trans_b=1)
    return A


def newton_bytes(m: int) -> int:
    """Memory the dense Newton matrix of ``m`` unknowns takes, with a quarter for
    the rest of the method (the sparse Hessian, the factorisation's tiles, iterates)."""
    return int(1.25 * 8 * m * m)


def available_bytes() -> int | None:
    """The memory available to a new allocation (``psutil``), ``None`` where it is not known."""
    import psutil
    try:
        return int(psutil.virtual_memory().available)
    except (OSError, RuntimeError, AttributeError):   # pragma: no cover - exotic platforms
        return None


def blas_threads(limit: int | None):
    """``threadpoolctl`` limit of the BLAS threads for a block (``None``: unchanged)."""
    if limit is None:
        return contextlib.nullcontext()
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - optional
        return contextlib.nullcontext()
    return threadpool_limits(limits=limit, user_api="blas")


class DenseNewton:
    r"""``2 P + sum_j D_j`` assembled densely and factored by Cholesky (``m^3 / 3`` flops).

    ``D_j = W_j^{-1} (x)_s W_j^{-1}`` is the Nesterov-Todd term of the cone
    ``X_j - eps_j I >= 0``. The sparse ``2 P`` is added entry by entry. Close to
    the optimum the matrix mixes entries of size ``1/mu`` with the data Hessian
    (``kappa ~ 1e8-1e10`` itself), and Cholesky can break down: then the diagonal
    is raised by ``delta N_ii`` (``delta = 1e-12``, ``1e-10``, ...: a relative
    perturbation, as in SDP codes), and every solve is followed by two steps of
    iterative refinement with the exact matrix, applied blockwise
    (``2 P x + svec(W^{-1} X W^{-1})``).
    """

    def __init__(self, problem: GramProblem, index):
        self.r, self.index = problem.r, index
        self.n = index[0].size
        self.nb = len(problem.blocks)
        self.m = self.nb * self.n
        self.hess = hessian(problem).tocoo()
        self.hess_csr = self.hess.tocsr()
        self.cut = [slice(j * self.n, (j + 1) * self.n) for j in range(self.nb)]
        self.matrix = np.empty((self.m, self.m), order="F")   # LAPACK factors it in place
        self.fac = None
        self.terms = [None] * self.nb

    def factor(self, terms) -> None:
        """``terms[j]``: ``None`` (no cone term) or ``W_j^{-1}``."""
        N = self.matrix
        self.terms = list(terms)
        for delta in (0.0, 1e-12, 1e-10, 1e-8, 1e-6):
            N[:] = 0.0
            for c, term in zip(self.cut, terms):
                if term is not None:
                    sym_kron(term, self.index, out=N[c, c])
            N[self.hess.row, self.hess.col] += self.hess.data
            if delta:
                diagonal = N[np.diag_indices(self.m)]
                N[np.diag_indices(self.m)] = diagonal + delta * np.maximum(
                    diagonal, np.finfo(float).tiny)
            try:
                # lift the solver's one-thread limit for a large factorisation
                with blas_threads((os.cpu_count() or 1) if self.m >= THREADED_UNKNOWNS else None):
                    if self.m >= BLOCKED_UNKNOWNS:
                        self.fac = (blocked_cholesky(N), True)
                    else:
                        self.fac = sla.cho_factor(N, lower=True, overwrite_a=True, check_finite=False)
                return
            except np.linalg.LinAlgError:
                continue
        raise np.linalg.LinAlgError("Newton matrix is not positive definite")

    def apply(self, x: np.ndarray) -> np.ndarray:
        """The exact (unregularised) Newton matrix times ``x``."""
        y = self.hess_csr @ x
        for c, term in zip(self.cut, self.terms):
            if term is not None:
                y[c] += svec(term @ smat(x[c], self.index, self.r) @ term, self.index)
        return y

    def solve(self, rhs_blocks, refinements: int = 2) -> list[np.ndarray]:
        rhs = np.concatenate([svec(R, self.index) for R in rhs_blocks])
        dx = sla.cho_solve(self.fac, rhs, check_finite=False)
        for _ in range(refinements):
            dx += sla.cho_solve(self.fac, rhs - self.apply(dx), check_finite=False)
        return [smat(dx[c], self.index, self.r) for c in self.cut]


# -- the interior-point iteration ----------------------------------------------------
#: A point whose certified relative gap is above ``tol`` but below this is
#: reported "optimal_inaccurate" (the vocabulary of cvxpy): seen on rank-deficient
#: data, where the dual residual of the Newton solves stalls near 1e-8.
INACCURATE = 1e-6

#: Starting point: slack eigenvalues are floored at this fraction of the largest
#: one, and ``mu_0`` is this fraction of ``f(X_0) / nu`` (chosen on string POD and
#: random problems, r = 10-30: 8-13 iterations against 9-22 for the
#: identity-scaled start of Vandenberghe's notes).
START_FLOOR = 1e-2
START_MU = 1e-2


def solve_ipm(problem: GramProblem, *, tol: float = 1e-8, max_iterations: int = 60,
              info: dict | None = None):
    """Minimise ``problem`` (square blocks only) by the interior-point method above.

    Parameters
    ----------
    problem : GramProblem
        "psd" and "symmetric" blocks of size r, no "free" block.
    tol : float
        Stop at a point whose certified gap (:func:`gap_bound`) is below ``tol``
        times its objective.
    max_iterations : int
    info : dict, optional
        Receives ``ipm_iterations``, ``gap_estimate`` (relative, certified when
        ``G`` is nonsingular), ``certificate`` and ``active`` (per "psd" block,
        the eigenvalues held at the bound).

    Returns
    -------
    X : (r, p) ndarray
        Feasible; blocks exactly symmetric.
    status : {"optimal", "optimal (unconstrained)", "optimal_inaccurate", "max_iterations", "stalled"}
    """
    info = {} if info is None else info
    r, nb = problem.r, len(problem.blocks)
    g_min = smallest_eigenvalue(problem.gram)
    info["certificate"] = "bound" if g_min > 0 else "complementarity"
    newton = DenseNewton(problem, svec_index(r))
    # unconstrained symmetric least squares: the optimum if it is feasible, else
    # the starting point
    newton.factor([None] * nb)
    grad0 = problem.gradient(np.zeros((r, problem.p)))
    X_ls = newton.solve([-sym(grad0[:, s]) for s in problem.slices()])
    X = _assemble(problem, X_ls)
    if problem.is_feasible(X, tol=0.0):
        # the gap is round-off of the solve; bounded all the same when G > 0
        gap = gap_bound(problem, X, g_min=g_min) if g_min > 0 else 0.0
        info.update(ipm_iterations=0, gap_estimate=relative_gap(gap, problem.objective(X), problem),
                    active={b.name: 0 for b in problem.blocks if b.structure == "psd"})
        return X, "optimal (unconstrained)"
    Xb, status, state = _path_following(problem, newton, X_ls, tol, max_iterations, g_min)
    info.update(state)
    return _assemble(problem, Xb), status


def _path_following(problem, newton, X_ls, tol, max_iterations, g_min):
    """Mehrotra predictor-corrector iterations from the least-squares point ``X_ls``;
    returns the best certified iterate, the status and an ``info`` update."""
    r, nb = problem.r, len(problem.blocks)
    eye = np.eye(r)
    shifts = [b.shift for b in problem.blocks]
    cone = [b.structure == "psd" for b in problem.blocks]
    nu = r * sum(cone)

    # starting point: slack eigenvalues floored, Z = mu_0 S^{-1} (on the central path)
    Xb = [A.copy() for A in X_ls]
    spectra = {j: np.linalg.eigh(Xb[j] - shifts[j] * eye) for j in range(nb) if cone[j]}
    floor = START_FLOOR * max(max(np.abs(g).max(), np.finfo(float).tiny)
                              for g, _ in spectra.values())
    for j, (g, P) in spectra.items():
        Xb[j] = shifts[j] * eye + (P * np.maximum(g, floor)) @ P.T
    mu0 = START_MU * max(problem.objective(_assemble(problem, Xb)), np.finfo(float).tiny) / nu
    Zb = [None] * nb
    for j, (g, P) in spectra.items():
        Zb[j] = (P * (mu0 / np.maximum(g, floor))) @ P.T

    best = (np.inf, None, None)
    status = "max_iterations"
    it = best_iteration = 0
    # a line per step on a terminal (every 30 s in a log) where a fit takes minutes
    steps = Steps(f"L-OpInf interior point ({newton.m} unknowns)",
                  enabled=None if newton.m >= THREADED_UNKNOWNS else False)
    for it in range(1, max_iterations + 1):
        X = _assemble(problem, Xb)
        grad = problem.gradient(X)
        S = [Xb[j] - shifts[j] * eye if cone[j] else None for j in range(nb)]
        rdual = [sym(grad[:, s]) - (Zb[j] if cone[j] else 0.0)
                 for j, s in enumerate(problem.slices())]
        comp = sum(float(np.sum(S[j] * Zb[j])) for j in range(nb) if cone[j])
        mu = comp / nu
        f = problem.objective(X)
        residual = sum(float(np.sum(R * R)) for R in rdual)
        if g_min > 0:   # gap_bound with Lambda = Z, and with the best Lambda for X
            bound = min(comp + residual / (4.0 * g_min), gap_bound(problem, X, g_min=g_min))
        else:           # no certificate: the interior-point gap at a tiny dual residual
            bound = comp if residual <= (1e-10 * max(abs(f), 1.0)) ** 2 else np.inf
        rel = relative_gap(bound, f, problem)
        steps.update(f"gap bound {rel:.1e}")
        if rel < best[0] and _feasible(problem, Xb):
            best = (rel, [A.copy() for A in Xb], [None if Zj is None else Zj.copy() for Zj in Zb])
            best_iteration = it
        if best[0] <= tol:
            status = "optimal"
            break
        if g_min > 0 and comp <= 0.1 * tol * abs(f) and best[1] is not None:
            # complementarity is done but the dual residual (round-off of the Newton
            # solves) keeps the ball bound above tol: evaluate the dual function
            # exactly instead, and stop either way (smaller mu only worsens N)
            exact = exact_gap_bound(problem, newton, best[1], best[2], g_min)
            exact = relative_gap(exact, f, problem)
            status = "optimal" if exact <= tol else "stalled"
            best = (min(best[0], exact), best[1], best[2])
            break
        if best[1] is not None and it - best_iteration >= 5:
            # five iterations without a better certified point; before the first one
            # (singular G: no bound until the dual residual is tiny) keep going
            status = "stalled"
            break
        try:
            scalings = [nt_scaling(S[j], Zb[j]) if cone[j] else None for j in range(nb)]
            newton.factor([sc[1].T @ sc[1] if sc is not None else None for sc in scalings])
        except (np.linalg.LinAlgError, ValueError):
            status = "stalled"
            break

        def direction(Ys):
            """Newton step for the scaled complementarity right-hand side ``Ys``."""
            rhs = [-rdual[j] + (scalings[j][1].T @ Ys[j] @ scalings[j][1] if cone[j] else 0.0)
                   for j in range(nb)]
            dX = newton.solve(rhs)
            ds, dz, alpha = [None] * nb, [None] * nb, np.inf
            for j in range(nb):
                if cone[j]:
                    Rinv, lam = scalings[j][1], scalings[j][2]
                    ds[j] = sym(Rinv @ dX[j] @ Rinv.T)
                    dz[j] = Ys[j] - ds[j]
                    alpha = min(alpha, _max_step(lam, ds[j]), _max_step(lam, dz[j]))
            return dX, ds, dz, alpha

        # predictor (affine scaling): Lambda o (ds + dz) = -Lambda o Lambda, so Y = -Lambda
        Ya = [-np.diag(sc[2]) if sc is not None else None for sc in scalings]
        try:
            _, dsa, dza, alpha_a = direction(Ya)
        except (np.linalg.LinAlgError, ValueError):
            status = "stalled"
            break
        alpha_a = min(1.0, alpha_a)
        mu_a = sum(float(np.sum((np.diag(sc[2]) + alpha_a * dsa[j])
                                * (np.diag(sc[2]) + alpha_a * dza[j])))
                   for j, sc in enumerate(scalings) if sc is not None) / nu
        sigma = min(1.0, max(0.0, mu_a / mu)) ** 3
        # corrector: Mehrotra's second-order term and centring, same factorisation
        Yc = [None] * nb
        for j, sc in enumerate(scalings):
            if sc is not None:
                lam = sc[2]
                rc = -np.diag(lam * lam) - _jordan(dsa[j], dza[j]) + sigma * mu * eye
                Yc[j] = rc / (0.5 * (lam[:, None] + lam[None, :]))
        try:
            dX, ds, dz, alpha = direction(Yc)
        except (np.linalg.LinAlgError, ValueError):
            status = "stalled"
            break
        alpha = min(1.0, 0.99 * alpha)
        if not alpha > 1e-10:      # no progress possible (or non-finite directions)
            status = "stalled"
            break
        for j in range(nb):
            Xb[j] = Xb[j] + alpha * dX[j]
            if cone[j]:
                Rinv = scalings[j][1]
                Zb[j] = Zb[j] + alpha * sym(Rinv.T @ dz[j] @ Rinv)
    steps.close()
    rel, Xb, Zb = best
    if status != "optimal" and rel <= INACCURATE:
        status = "optimal_inaccurate"
    if Xb is None:          # no iterate passed the feasibility check (round-off): project
        Xb = _blocks_of(problem, problem.project(_assemble(problem, X_ls)))
    active = {}
    for j, b in enumerate(problem.blocks):
        if cone[j] and Zb is not None:
            sv, P = np.linalg.eigh(Xb[j] - shifts[j] * eye)
            zv = np.einsum("ij,ik,kj->j", P, Zb[j], P)
            active[b.name] = int(np.sum(sv < zv))
    return Xb, status, {"ipm_iterations": it, "gap_estimate": float(rel), "active": active}


def exact_gap_bound(problem: GramProblem, newton: DenseNewton, Xb, Zb, g_min: float) -> float:
    r"""Rigorous bound of ``f(X) - f*`` from the dual function at ``Lambda = Z``, absolute.

    ``g(Lambda) = min_{X'} L(X') = f(X') - <Lambda, X' - eps I>`` over symmetric
    ``X'``: its minimiser ``X' = X + D`` solves ``2 P D = -(sym grad f(X) - Lambda)``
    (``newton`` is refactored without cone terms). With ``R = grad L(X')`` (the
    residual of that solve),

    .. math::

        f(X) - f^\star \le f(X) - g(\Lambda) \le \langle \Lambda, X - \varepsilon I\rangle
            + \langle R, -D\rangle + \langle D G, D\rangle + \|R\|^2 / (4 g_{\min}),

    each term evaluated without cancellation. Tighter than :func:`gap_bound`
    when the dual residual is not aligned with the smallest eigenvalues of ``G``.
    """
    r, slices = problem.r, problem.slices()
    eye = np.eye(r)
    X = _assemble(problem, Xb)
    grad = problem.gradient(X)
    lam = [Zb[j] if Zb[j] is not None else np.zeros((r, r)) for j in range(len(Xb))]
    newton.factor([None] * len(Xb))
    D = newton.solve([-(sym(grad[:, s]) - lam[j]) for j, s in enumerate(slices)])
    Xp = X + _assemble(problem, D)
    gradp = problem.gradient(Xp)
    Dm = X - Xp
    bound = float(np.sum((Dm @ problem.gram) * Dm))
    residual = 0.0
    for j, (b, s) in enumerate(zip(problem.blocks, slices)):
        R = sym(gradp[:, s]) - lam[j]
        bound += float(np.sum(R * Dm[:, s]))
        residual += float(np.sum(R * R))
        if b.structure == "psd":
            bound += float(np.sum(lam[j] * (Xb[j] - b.shift * eye)))
    return max(bound, 0.0) + residual / (4.0 * g_min)


def _blocks_of(problem: GramProblem, X: np.ndarray) -> list[np.ndarray]:
    return [X[:, s] for s in problem.slices()]


def _feasible(problem: GramProblem, Xb) -> bool:
    """Every "psd" block at or above its shift (a Cholesky attempt of ``X_j - eps_j I``)."""
    for b, A in zip(problem.blocks, Xb):
        if b.structure == "psd":
            try:
                np.linalg.cholesky(A - b.shift * np.eye(problem.r))
            except np.linalg.LinAlgError:
                return False
    return True
