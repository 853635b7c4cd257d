r"""The L-OpInf regression's own solver: structured least squares over symmetric and semidefinite blocks.

It aims at the same optimum as the conic program of :mod:`._sdp`, working on
the (p, p) Gram matrix, r x r eigendecompositions and, on ill-conditioned
data, dense Newton systems in the ``r (r + 1) / 2`` entries of each symmetric
block. After scaling (:meth:`GramProblem.scaled`):

1. **Free blocks eliminated** (:func:`eliminate_free`). The input operator ``B`` is
   unconstrained, so it is minimised out in closed form (a Schur complement of
   ``G``) and recovered at the end: ``X_F = -(X_S G_SF + H_F^T) G_FF^{-1}``.
2. **Method chosen** (``FastSolver.method = "auto"``) from the condition
   number of the reduced Gram matrix and the number of unknowns
   ``m = b r (r + 1) / 2``:

   - **interior point** (:mod:`._interior_point`: Nesterov-Todd scaling, Mehrotra
     predictor-corrector, dense Cholesky of the Newton matrix) when
     ``kappa(G) > ipm_condition`` (POD data: ``kappa ~ 1e5-1e10``) or
     ``m <= ipm_small_unknowns``, as long as ``m <= ipm_max_unknowns``. Newton
     steps solved directly do not care about ``kappa(G)``; the method finds
     the active faces by itself and stops in 9-15 iterations at a certified
     gap. Cost ``~m^3 / 3`` flops a step (r = 30: 0.03 s; r = 60: 0.6 s;
     r = 100: ~10 s).
   - **first order** (:mod:`._first_order`: symmetric least squares on faces of
     the cone, :mod:`._face_lstsq`, an active set on eigenspaces, then
     Anderson-accelerated ADMM) otherwise: cheap per iteration, fast when
     ``G`` is well conditioned (random data: r = 100 in ~0.35 s).

   If the first method does not certify its point the other one runs and
   the better point is returned.
3. **Certificate.** A candidate is accepted when its relative duality gap is
   below ``tol`` (:mod:`._duality_gap`): first the rigorous bound
   :func:`~femrom.inference._duality_gap.gap_bound` (no linear solve; it needs
   ``G > 0``), else the estimate of :func:`~femrom.inference._duality_gap.gap_estimate`;
   the best feasible candidate by objective is returned in any case, with its gap
   in ``info``.

Why two methods (``docs/inference.md``): on POD data of a damped string
(``kappa(G) ~ 1e7-1e10`` after block scaling) the first-order path needed
thousands of conjugate-gradient iterations per face solve, its active-set
search did not find the right face, and it stopped 5e-6 to 0.18 above the
optimum (r = 12-60); the interior-point path reaches a certified gap below
1e-8 there, but its dense Newton matrix (``8 m^2`` bytes, ``m^3 / 3`` flops)
limits it to ``r`` of about 100.

BLAS threads are limited to one inside the solver when ``threadpoolctl`` is
importable: at these sizes (r <= a few hundred) threading only adds
contention on a shared machine (measured: a 100 x 100 ``eigh`` takes 1.3 ms
on one thread and 0.1 s with two busy threads).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from femrom._errors import FemromRuntimeError, FemromValueError
from femrom.inference import _interior_point
from femrom.inference._first_order import solve_first_order
from femrom.inference._interior_point import blas_threads, solve_ipm
from femrom.inference._problem import GramProblem


#: Solution methods of :func:`solve_fast`.
METHODS = ("auto", "first_order", "interior_point")


@dataclass(frozen=True)
class FastSolver:
    """The regression's own solver (module docstring) with its settings: a learner's default
    ``solver=``.

    ``FastSolver().solve(problem)`` is :func:`solve_fast`: it returns ``(X, info)``, the
    (r, p) operators and what the solve did. ``name`` (``"fast"``) is how a fitted model
    records it.

    Attributes
    ----------
    tol : float
        Accept a point whose estimated optimality gap is below ``tol`` times
        its objective.
    max_iterations : int
        ADMM iterations at most.
    polish_first, polish_every : int
        ADMM iterations between polish attempts: ``polish_first`` for the first
        five attempts, ``polish_every`` after that.
    cg_tol : float
        Relative residual of the conjugate-gradient solves.
    cg_max_iterations : int
    relaxation : float
        ADMM over-relaxation ``alpha`` in (0, 2).
    face_corrections : int
        Active-set corrections of the faces per polish.
    dense_unknowns : int
        Face problems with at most this many unknowns are solved as dense
        linear systems instead of by conjugate gradients.
    stall_polishes, stall_tol : int, float
        Stop when this many polishes in a row improve the objective by less
        than ``stall_tol`` relative (status ``"stalled"``).
    anderson_memory : int
        Anderson-acceleration memory of the ADMM fixed-point map (0: plain ADMM).
    rho_updates : int
        Residual-balancing updates of the ADMM penalty (at the first polishes).
    method : {"auto", "first_order", "interior_point"}
        ``"first_order"``: :mod:`femrom.inference._first_order`; ``"interior_point"``:
        :func:`femrom.inference._interior_point.solve_ipm`; ``"auto"``: the interior-point
        method when the scaled, reduced Gram matrix has ``kappa > ipm_condition``
        or the problem has at most ``ipm_small_unknowns`` unknowns, the
        first-order path otherwise, and the other one whenever the first does
        not certify its point (the better point is returned).
    ipm_condition : float
        ``kappa(G)`` above which "auto" starts with the interior-point method
        (random data: ~6; POD data of a string: 1e5-1e10).
    ipm_small_unknowns : int
        Problems with at most this many symmetric unknowns (``m = b r (r+1)/2``;
        600: ``r <= 24`` with two blocks) take the interior-point method under
        "auto" whatever their conditioning (10-50 ms there).
    ipm_max_unknowns : int
        The interior-point method is not used above this many unknowns (its
        dense Newton matrix takes ``8 m^2`` bytes: 16 GB at 45 000, ``r = 211``). On
        the string data the first-order path stops uncertified 4 % above the
        optimum at r = 150 and 200 (19-20 min), where the interior point certifies
        it in 16 min (r = 150, 6.6 GB resident) and 65 min (r = 200, ``m = 40 200``,
        14.3 GB) on two cores. Nor where the matrix
        would not fit in the memory available (``1.25 x 8 m^2`` bytes against
        ``psutil.virtual_memory().available``): "auto" then takes the first-order path, and
        ``method="interior_point"`` is refused in one line.
    ipm_max_iterations : int
    """

    tol: float = 1e-8
    max_iterations: int = 2000
    polish_every: int = 50
    polish_first: int = 10
    cg_tol: float = 1e-12
    cg_max_iterations: int = 300
    relaxation: float = 1.6
    face_corrections: int = 1
    dense_unknowns: int = 300
    stall_polishes: int = 40
    anderson_memory: int = 10
    rho_updates: int = 0
    stall_tol: float = 1e-12
    method: str = "auto"
    ipm_condition: float = 1e4
    ipm_small_unknowns: int = 600
    ipm_max_unknowns: int = 45_000
    ipm_max_iterations: int = 60

    name: ClassVar[str] = "fast"

    def __post_init__(self):
        if self.method not in METHODS:
            raise FemromValueError(f"unknown method {self.method!r}; valid: {METHODS}")

    def solve(self, problem: GramProblem):
        """:func:`solve_fast` with these settings: ``(X, info)``."""
        return solve_fast(problem, self)


def solve_fast(problem: GramProblem, solver: FastSolver = FastSolver()):
    """Solve ``problem`` (see module docstring) with ``solver``'s settings; returns ``(X, info)``.

    Returns
    -------
    X : (r, p) ndarray
        The operators, symmetric blocks exactly symmetric and feasible.
    info : dict
        ``solver`` ("fast"), ``method`` ("first_order" or "interior_point": the one
        whose point is returned), ``status`` (``"optimal"``, ``"optimal
        (unconstrained)"``, ``"optimal (least squares)"``, ``"max_iterations"``,
        ``"stalled"``), ``seconds``, ``objective``, ``condition`` (``kappa`` of
        the scaled, reduced Gram matrix), ``iterations`` (ADMM),
        ``cg_iterations``, ``ipm_iterations``, ``gap_estimate`` (relative
        duality gap: a rigorous bound when ``certificate`` is "bound"),
        ``active`` (per "psd" block: eigenvalues held at the bound).
    """
    tic = time.perf_counter()
    with blas_threads(1):
        scaled, unscale, obj_scale = problem.scaled()
        reduced, recover = eliminate_free(scaled)
        info = {"solver": "fast", "iterations": 0, "cg_iterations": 0, "gap_estimate": 0.0,
                "active": {}}
        if reduced is None:
            Xs = recover(np.zeros((scaled.r, 0)))
            info["status"] = "optimal (least squares)"
        else:
            Xr, status = _solve_square(reduced, solver, info)
            Xs = recover(Xr)
            info["status"] = status
        # exact symmetry (eigen-reconstructions are symmetric to round-off), and
        # eigenvalues clipped at the bound should round-off have crossed it
        X = problem.project(unscale(Xs))
    info["seconds"] = time.perf_counter() - tic
    info["objective"] = problem.objective(X)
    return X, info


# -- step 1: free blocks eliminated --------------------------------------
def _pinv_sym(A: np.ndarray, rtol: float = 1e-13) -> np.ndarray:
    g, W = np.linalg.eigh(A)
    keep = g > rtol * max(g[-1], np.finfo(float).tiny)
    return (W[:, keep] / g[keep]) @ W[:, keep].T


def eliminate_free(problem: GramProblem):
    """The problem on the square blocks alone, and ``X_S -> X`` adding the free blocks back."""
    G, H = problem.regularized_gram(), problem.cross
    slices = problem.slices()
    S = np.concatenate([np.arange(s.start, s.stop) for b, s in zip(problem.blocks, slices)
                        if b.square] or [np.zeros(0, int)])
    F = np.concatenate([np.arange(s.start, s.stop) for b, s in zip(problem.blocks, slices)
                        if not b.square] or [np.zeros(0, int)])
    r, p = problem.r, problem.p

    if F.size:
        GFF_inv = _pinv_sym(G[np.ix_(F, F)])
        GSF = G[np.ix_(S, F)]
        T = GSF @ GFF_inv                       # (|S|, |F|)
        gram = G[np.ix_(S, S)] - T @ GSF.T
        cross = H[S] - T @ H[F]
        target = problem.target - float(np.sum(H[F] * (GFF_inv @ H[F])))
    else:
        gram, cross, target = G[np.ix_(S, S)], H[S], problem.target

    def recover(XS: np.ndarray) -> np.ndarray:
        X = np.zeros((r, p))
        X[:, S] = XS
        if F.size:
            X[:, F] = -(XS @ GSF + H[F].T) @ GFF_inv if S.size else -H[F].T @ GFF_inv
        return X

    if not S.size:
        return None, recover
    blocks = tuple(replace(b, regularization=0.0) for b in problem.blocks if b.square)
    gram = 0.5 * (gram + gram.T)
    return GramProblem(gram=gram, cross=cross, target=target, blocks=blocks,
                       n_samples=problem.n_samples), recover


# -- step 2: the method -----------------------------------------------------
def _solve_square(problem: GramProblem, options: FastSolver, info):
    """Choose the method (``FastSolver.method``), fall back to the other one if
    the first does not certify its point, and return the better point."""
    g = np.linalg.eigvalsh(problem.gram)
    info["condition"] = float(g[-1] / g[0]) if g[0] > 0 else np.inf
    m = sum(b.size * (b.size + 1) // 2 for b in problem.blocks)
    need, free = _interior_point.newton_bytes(m), _interior_point.available_bytes()
    fits = free is None or need <= free
    if options.method == "interior_point" and not fits:
        raise FemromRuntimeError(
            f"FastSolver(method='interior_point'): its dense Newton matrix of {m} unknowns needs "
            f"{need / 1e9:.1f} GB and {free / 1e9:.1f} GB are available; use method='auto' or 'first_order'")
    ipm_allowed = m <= options.ipm_max_unknowns and fits and any(
        b.structure == "psd" for b in problem.blocks)
    if options.method == "auto":
        order = ["interior_point", "first_order"] if ipm_allowed and (
            info["condition"] > options.ipm_condition or m <= options.ipm_small_unknowns) \
            else ["first_order"] + (["interior_point"] if ipm_allowed else [])
    else:
        order = [options.method]
    best = None
    for method in order:
        sub = {"iterations": 0, "cg_iterations": 0, "gap_estimate": 0.0, "active": {}}
        if method == "interior_point":
            X, status = solve_ipm(problem, tol=options.tol, max_iterations=options.ipm_max_iterations,
                                  info=sub)
        else:
            X, status = solve_first_order(problem, options, sub)
        sub["method"] = method
        f = problem.objective(X)
        for key in ("iterations", "cg_iterations", "ipm_iterations"):   # work done by all
            info[key] = info.get(key, 0) + sub.pop(key, 0)
        if best is None or (_certified(status), -f) > (_certified(best[1]), -best[2]):
            best = (X, status, f, sub)
        if status.startswith("optimal"):    # "optimal_inaccurate" too: see solve_ipm
            break
    X, status, _, sub = best
    info.update(sub)
    return X, status


def _certified(status: str) -> bool:
    return status.startswith("optimal") and status != "optimal_inaccurate"
