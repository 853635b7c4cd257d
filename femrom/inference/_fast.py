r"""A dedicated solver for the structured regression of :mod:`._problem`.

It aims at the same optimum as the conic program of :mod:`._sdp`, working on
the (p, p) Gram matrix, r x r eigendecompositions and, on ill-conditioned
data, dense Newton systems in the ``r (r + 1) / 2`` entries of each symmetric
block. After scaling (:meth:`GramProblem.scaled`):

1. **Free blocks eliminated.** The input operator ``B`` is unconstrained, so
   it is minimised out in closed form (a Schur complement of ``G``) and
   recovered at the end: ``X_F = -(X_S G_SF + H_F^T) G_FF^{-1}``.
2. **Method chosen** (``FastOptions.method = "auto"``) from the condition
   number of the reduced Gram matrix and the number of unknowns
   ``m = b r (r + 1) / 2``:

   - **interior point** (:mod:`._ipm`: Nesterov-Todd scaling, Mehrotra
     predictor-corrector, dense Cholesky of the Newton matrix) when
     ``kappa(G) > ipm_condition`` (POD data: ``kappa ~ 1e5-1e10``) or
     ``m <= ipm_small_unknowns``, as long as ``m <= ipm_max_unknowns``. Newton
     steps solved directly do not care about ``kappa(G)``; the method finds
     the active faces by itself and stops in 9-15 iterations at a certified
     gap. Cost ``~m^3 / 3`` flops a step (r = 30: 0.03 s; r = 60: 0.6 s;
     r = 100: ~10 s).
   - **first order** (steps 3-6) otherwise: cheap per iteration, fast when
     ``G`` is well conditioned (random data: r = 100 in ~0.35 s).

   If the first method does not certify its point the other one runs and
   the better point is returned.
3. **Symmetric least squares.** Ignoring definiteness, the optimality
   conditions of the symmetric blocks are coupled Lyapunov equations
   ``sym((X G + H^T)_j) = 0``. They are solved by conjugate gradients
   preconditioned by the exact block-diagonal Lyapunov inverse (diagonal in
   the eigenbasis of each ``G_jj``). When the solution already satisfies
   ``X_j >= eps_j I`` it is the optimum (the problem is convex) and the
   solver stops.
4. **Active set on eigenspaces** otherwise: the faces ``X_j = eps_j I +
   U_j A_j U_j^T`` read off the clipped solution turn the problem into a
   symmetric least-squares problem in the ``A_j`` again (step 3's solver);
   faces shrink where ``A_j`` has negative eigenvalues and grow where the
   multiplier ``Lambda_j = sym(grad f)_j`` is negative on the complement or
   couples to the face.
5. **ADMM** if that is not certified, on ``min f(X) + indicator_S(Z)  s.t.  X = Z``:

   .. math::

       X^{k+1} = (\rho (Z^k - U^k) - 2 H^\top)(2 G + \rho I)^{-1}, \quad
       Z^{k+1} = \Pi_S(\alpha X^{k+1} + (1 - \alpha) Z^k + U^k), \quad
       U^{k+1} = U^k + \alpha X^{k+1} + (1 - \alpha) Z^k - Z^{k+1},

   where ``(2 G + rho I)^{-1}`` comes from one eigendecomposition of ``G``,
   ``Pi_S`` symmetrises each block and clips its eigenvalues at ``eps_j``,
   ``alpha = 1.6`` over-relaxes and ``rho = sqrt(g_min g_max)``; the fixed-point
   map is Anderson-accelerated (coefficients from the (m, m) normal equations
   of the residual differences), and the positive eigenspaces of the projected
   matrices seed step 4 after 10, 20, ..., 50 iterations, then every
   ``polish_every``: on well-conditioned data the active set is right after
   10-20 iterations, so early polishes end the run.
6. **Certificate.** A candidate is accepted when its relative duality gap is
   below ``tol``: first the rigorous bound :func:`femrom.inference._ipm.gap_bound`
   (no linear solve; it needs ``G > 0``), else the estimate of
   :func:`_gap_estimate`; the best feasible candidate by objective is
   returned in any case, with its gap in ``info``.

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
import weakref
from dataclasses import dataclass, replace

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference._ipm import blas_threads, gap_bound, relative_gap, smallest_eigenvalue, solve_ipm
from femrom.inference._problem import GramProblem


#: Solution methods of :func:`solve_fast`.
METHODS = ("auto", "first_order", "interior_point")


@dataclass(frozen=True)
class FastOptions:
    """Tolerances of :func:`solve_fast`.

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
        ``"first_order"``: steps 2-5 of the module docstring; ``"interior_point"``:
        :func:`femrom.inference._ipm.solve_ipm`; ``"auto"``: the interior-point
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
        dense Newton matrix takes ``8 m^2`` bytes: 1.2 GB at 12 000, ``r = 108``).
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
    ipm_max_unknowns: int = 12_000
    ipm_max_iterations: int = 60

    def __post_init__(self):
        if self.method not in METHODS:
            raise FemromValueError(f"unknown method {self.method!r}; valid: {METHODS}")


def solve_fast(problem: GramProblem, options: FastOptions = FastOptions()):
    """Solve ``problem`` (see module docstring); returns ``(X, info)``.

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
        reduced, recover = _eliminate_free(scaled)
        info = {"solver": "fast", "iterations": 0, "cg_iterations": 0, "gap_estimate": 0.0,
                "active": {}}
        if reduced is None:
            Xs = recover(np.zeros((scaled.r, 0)))
            info["status"] = "optimal (least squares)"
        else:
            Xr, status = _solve_square(reduced, options, info)
            Xs = recover(Xr)
            info["status"] = status
        # exact symmetry (eigen-reconstructions are symmetric to round-off), and
        # eigenvalues clipped at the bound should round-off have crossed it
        X = problem.project(unscale(Xs))
    info["seconds"] = time.perf_counter() - tic
    info["objective"] = problem.objective(X)
    return X, info


# -- step 1: free blocks ---------------------------------------------------
def _pinv_sym(A: np.ndarray, rtol: float = 1e-13) -> np.ndarray:
    g, W = np.linalg.eigh(A)
    keep = g > rtol * max(g[-1], np.finfo(float).tiny)
    return (W[:, keep] / g[keep]) @ W[:, keep].T


def _eliminate_free(problem: GramProblem):
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


# -- step 2 and 4: symmetric least squares on faces ------------------------
@dataclass
class _Face:
    """``X_j = offset I + U A U^T`` (``U = None``: ``X_j = A``, the whole symmetric space)."""

    U: np.ndarray | None
    offset: float
    precond_vectors: np.ndarray
    precond_values: np.ndarray

    @property
    def size(self) -> int:
        return self.precond_values.size


def _make_faces(problem: GramProblem, bases) -> list[_Face]:
    faces = []
    for U, offset, s in zip(*bases, problem.slices()):
        Gjj = problem.gram[s, s]
        Gt = Gjj if U is None else U.T @ Gjj @ U
        g, W = np.linalg.eigh(0.5 * (Gt + Gt.T))
        faces.append(_Face(U=U, offset=offset, precond_vectors=W, precond_values=g))
    return faces


def _embed(problem, faces, As, with_offset: bool) -> np.ndarray:
    r = problem.r
    X = np.zeros((r, problem.p))
    for face, A, s in zip(faces, As, problem.slices()):
        block = A if face.U is None else (face.U @ A) @ face.U.T
        if with_offset and face.offset:
            block = block + face.offset * np.eye(r)
        X[:, s] = block
    return X


def _restrict(problem, faces, M: np.ndarray) -> list[np.ndarray]:
    out = []
    for face, s in zip(faces, problem.slices()):
        Mj = M[:, s]
        Mj = 0.5 * (Mj + Mj.T)
        out.append(Mj if face.U is None else face.U.T @ Mj @ face.U)
    return out


def _precondition(faces, Rs) -> list[np.ndarray]:
    out = []
    for face, R in zip(faces, Rs):
        W, g = face.precond_vectors, face.precond_values
        denom = g[:, None] + g[None, :]
        denom = np.where(denom > 0, denom, 1.0)
        out.append(W @ ((W.T @ R @ W) / denom) @ W.T)
    return out


def _dot(As, Bs) -> float:
    return float(sum(np.sum(a * b) for a, b in zip(As, Bs)))


def _solve_faces(problem: GramProblem, faces, As0, options: FastOptions, info):
    """Minimise ``f`` over ``X_j = offset_j I + U_j A_j U_j^T`` by preconditioned CG."""
    G, Ht = problem.gram, problem.cross.T
    sizes = [f.size for f in faces]
    if not any(sizes):
        return As0

    def hess(Ds):
        return _restrict(problem, faces, 2.0 * (_embed(problem, faces, Ds, False) @ G))

    X0 = _embed(problem, faces, As0, True)
    res = [-g for g in _restrict(problem, faces, 2.0 * (X0 @ G + Ht))]
    if sum(k * (k + 1) // 2 for k in sizes) <= options.dense_unknowns:
        return _solve_faces_dense(problem, faces, As0, res, info)
    As = [a.copy() for a in As0]
    z = _precondition(faces, res)
    d = [x.copy() for x in z]
    rz = _dot(res, z)
    norm0 = np.sqrt(_dot(_restrict(problem, faces, 2.0 * Ht), _restrict(problem, faces, 2.0 * Ht)))
    norm0 = max(norm0, np.sqrt(_dot(res, res)), np.finfo(float).tiny)
    for it in range(options.cg_max_iterations):
        if np.sqrt(_dot(res, res)) <= options.cg_tol * norm0:
            break
        Hd = hess(d)
        curvature = _dot(d, Hd)
        if curvature <= 0:
            break
        step = rz / curvature
        As = [a + step * di for a, di in zip(As, d)]
        res = [ri - step * hi for ri, hi in zip(res, Hd)]
        z = _precondition(faces, res)
        rz_new = _dot(res, z)
        d = [zi + (rz_new / rz) * di for zi, di in zip(z, d)]
        rz = rz_new
    info["cg_iterations"] += it
    return [0.5 * (a + a.T) for a in As]


def _sym_basis(k: int) -> np.ndarray:
    """(k (k+1)/2, k, k) orthonormal basis of symmetric matrices: ``E_ii``, ``(E_il + E_li)/sqrt 2``."""
    i, l = np.triu_indices(k)
    E = np.zeros((i.size, k, k))
    idx = np.arange(i.size)
    value = np.where(i == l, 1.0, np.sqrt(0.5))
    E[idx, i, l] = value
    E[idx, l, i] = value
    return E


def _solve_faces_dense(problem, faces, As0, res, info):
    """The face problem as a dense symmetric system (few unknowns): exact whatever
    the conditioning, where conjugate gradients would crawl.

    With ``T`` the embedded basis matrices ``X_a`` (r, p), the Hessian is
    ``H_ab = <X_a, 2 X_b G>`` and the right side ``<E_a, residual_j>``.
    """
    r, G = problem.r, problem.gram
    bases, embedded = [], []
    for face, s in zip(faces, problem.slices()):
        E = _sym_basis(face.size)
        bases.append(E)
        X = np.zeros((E.shape[0], r, problem.p))
        X[:, :, s] = E if face.U is None else np.einsum("ik,akl,jl->aij", face.U, E, face.U)
        embedded.append(X)
    T = np.concatenate(embedded)
    H = 2.0 * np.einsum("aij,bij->ab", T, T @ G)
    rhs = np.concatenate([np.einsum("akl,kl->a", E, R) for E, R in zip(bases, res)])
    step = np.linalg.lstsq(0.5 * (H + H.T), rhs, rcond=1e-14)[0]
    out, start = [], 0
    for A, E in zip(As0, bases):
        n = E.shape[0]
        out.append(A + np.einsum("a,akl->kl", step[start:start + n], E))
        start += n
    info["dense_solves"] = info.get("dense_solves", 0) + 1
    return [0.5 * (a + a.T) for a in out]


def _solve_square(problem: GramProblem, options: FastOptions, info):
    """Choose the method (``FastOptions.method``), fall back to the other one if
    the first does not certify its point, and return the better point."""
    g = np.linalg.eigvalsh(problem.gram)
    info["condition"] = float(g[-1] / g[0]) if g[0] > 0 else np.inf
    m = sum(b.size * (b.size + 1) // 2 for b in problem.blocks)
    ipm_allowed = m <= options.ipm_max_unknowns and any(b.structure == "psd" for b in problem.blocks)
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
            X, status = _solve_first_order(problem, options, sub)
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


def _solve_first_order(problem: GramProblem, options: FastOptions, info):
    r = problem.r
    nb = len(problem.blocks)
    full = _make_faces(problem, ([None] * nb, [0.0] * nb))
    As = _solve_faces(problem, full, [np.zeros((r, r)) for _ in range(nb)], options, info)
    X = _embed(problem, full, As, False)
    if problem.is_feasible(X, tol=0.0):
        return X, "optimal (unconstrained)"
    # active set from the clipped unconstrained solution: often exact at once
    Z, faces = _project_with_faces(problem, X)
    start = _polish(problem, faces, Z, options, info)
    if problem.objective(Z) < problem.objective(start[0]):
        start = (Z, _gap_estimate(problem, Z, options, info))
    if start[1] <= options.tol:
        info["gap_estimate"] = float(start[1])
        info["active"] = _active_counts(problem, start[0])
        return start[0], "optimal"
    return _admm(problem, start, options, info)


def _active_counts(problem: GramProblem, X: np.ndarray) -> dict:
    out = {}
    for b, s in zip(problem.blocks, problem.slices()):
        if b.structure == "psd":
            g = np.linalg.eigvalsh(X[:, s])
            out[b.name] = int(np.sum(g <= b.shift + 1e-12 * max(abs(g[-1]), 1e-300)))
    return out


# -- step 3: ADMM with polishing -------------------------------------------
def _project_with_faces(problem: GramProblem, W: np.ndarray):
    """``Pi_S(W)`` and, per block, the eigenvectors of ``sym(W_j) - eps_j I`` above zero."""
    Z = np.empty_like(W)
    faces = []
    for b, s in zip(problem.blocks, problem.slices()):
        S = 0.5 * (W[:, s] + W[:, s].T)
        if b.structure != "psd":
            Z[:, s] = S
            faces.append((None, 0.0))
            continue
        g, P = np.linalg.eigh(S - b.shift * np.eye(problem.r))
        positive = g > 0
        Z[:, s] = (P[:, positive] * g[positive]) @ P[:, positive].T + b.shift * np.eye(problem.r)
        faces.append((P[:, positive], b.shift) if not positive.all() else (None, 0.0))
    return Z, faces


def _polish(problem: GramProblem, face_bases, Z: np.ndarray, options: FastOptions, info):
    """Solve on the faces and correct them (an active set on eigenspaces); return
    the best feasible point met and its relative gap estimate.

    On a face ``X_j = eps_j I + U_j A_j U_j^T`` the optimum needs ``A_j >= 0``
    (else the negative eigen-directions of ``A_j`` leave the face: *shrink*)
    and the multiplier ``Lambda_j = sym(grad f)_j`` to vanish on ``U_j`` and be
    positive semidefinite on its complement (else the complement's negative
    directions, and the range of the coupling ``(I - U_j U_j^T) Lambda_j U_j``,
    join the face: *expand*). Each face costs one conjugate-gradient solve.
    """
    r = problem.r
    Us = [U for U, _ in face_bases]
    offsets = [o for _, o in face_bases]
    best = None
    for _ in range(options.face_corrections + 1):
        for _shrink in range(r):
            faces = _make_faces(problem, (Us, offsets))
            As0 = []
            for face, s in zip(faces, problem.slices()):
                Zj = Z[:, s] - face.offset * np.eye(r)
                As0.append(Zj if face.U is None else face.U.T @ Zj @ face.U)
            As = _solve_faces(problem, faces, As0, options, info)
            shrunk = False
            for j, (b, face, A) in enumerate(zip(problem.blocks, faces, As)):
                if b.structure != "psd" or not face.size:
                    continue
                g, P = np.linalg.eigh(A - (b.shift if face.U is None else 0.0) * np.eye(A.shape[0]))
                keep = g > 0
                if not keep.all():
                    base = np.eye(r) if face.U is None else face.U
                    Us[j], offsets[j] = base @ P[:, keep], b.shift
                    shrunk = True
            if not shrunk:
                break
        X = problem.project(_embed(problem, faces, As, True))
        gap = _gap_estimate(problem, X, options, info)
        if best is None or problem.objective(X) < problem.objective(best[0]):
            best = (X, gap)
        if gap <= options.tol:
            break
        grad = problem.gradient(X)
        changed = False
        for j, (b, s) in enumerate(zip(problem.blocks, problem.slices())):
            if b.structure != "psd" or Us[j] is None:
                continue
            face = Us[j]
            complement = np.linalg.svd(np.eye(r) - face @ face.T)[0][:, :r - face.shape[1]]
            Lam = 0.5 * (grad[:, s] + grad[:, s].T)
            lam_scale = max(np.linalg.norm(Lam, 2), np.finfo(float).tiny)
            e, Qc = np.linalg.eigh(complement.T @ Lam @ complement)
            extra = [complement @ Qc[:, e < -1e-8 * lam_scale]]
            if face.shape[1]:
                uc, sc, _ = np.linalg.svd(complement @ (complement.T @ Lam @ face),
                                          full_matrices=False)
                extra.append(uc[:, sc > 1e-8 * lam_scale])
            if any(x.shape[1] for x in extra):
                basis = np.linalg.qr(np.hstack([face] + extra))[0]
                Us[j] = basis if basis.shape[1] < r else None
                offsets[j] = b.shift if basis.shape[1] < r else 0.0
                changed = True
        if not changed:
            break
        Z = X
    return best


_G_MIN = weakref.WeakKeyDictionary()


def _g_min(problem: GramProblem) -> float:
    """:func:`smallest_eigenvalue` of ``problem.gram``, computed once per problem."""
    if problem not in _G_MIN:
        _G_MIN[problem] = smallest_eigenvalue(problem.gram)
    return _G_MIN[problem]


def _gap_estimate(problem: GramProblem, X: np.ndarray, options: FastOptions, info) -> float:
    r"""Relative duality gap of a feasible ``X``, from the multipliers it suggests.

    First the rigorous bound :func:`femrom.inference._ipm.gap_bound` (no linear
    solve; accepted when it is below ``tol``), otherwise the estimate below.
    Take ``Lambda_j = Pi_PSD(sym(grad f(X))_j)`` for the ``"psd"`` blocks
    (zero for the others) as dual point; its dual value is
    ``g = min_{X' symmetric} f(X') - sum_j <Lambda_j, X'_j - eps_j I>``, whose
    minimiser ``X'`` solves a symmetric least-squares problem (conjugate
    gradients, warm-started at ``X``). Then ``f(X) - f* <= f(X) - g``, and with
    ``D = X - X'`` the gap is evaluated without cancellation as

    .. math::

        f(X) - g = \langle \nabla f(X'), D\rangle + \langle D G, D\rangle
                   + \sum_j \langle \Lambda_j, X'_j - \varepsilon_j I\rangle .
    """
    bound = gap_bound(problem, X, g_min=_g_min(problem))
    relative = relative_gap(bound, problem.objective(X), problem)
    if relative <= options.tol:
        return relative
    grad = problem.gradient(X)
    r = problem.r
    multipliers = []
    for b, s in zip(problem.blocks, problem.slices()):
        if b.structure == "psd":
            g, P = np.linalg.eigh(0.5 * (grad[:, s] + grad[:, s].T))
            multipliers.append((P * np.maximum(g, 0.0)) @ P.T)
        else:
            multipliers.append(np.zeros((r, r)))
    shifted = replace(problem, cross=problem.cross - 0.5 * np.hstack(multipliers).T)
    nb = len(problem.blocks)
    full = _make_faces(shifted, ([None] * nb, [0.0] * nb))
    As = _solve_faces(shifted, full, [X[:, s] for s in problem.slices()], options, info)
    Xd = _embed(shifted, full, As, False)
    D = X - Xd
    gap = float(np.sum(problem.gradient(Xd) * D) + np.sum((D @ problem.gram) * D))
    for b, s, Lam in zip(problem.blocks, problem.slices(), multipliers):
        shift = b.shift if b.structure == "psd" else 0.0
        gap += float(np.sum(Lam * (Xd[:, s] - shift * np.eye(r))))
    f = problem.objective(X)
    if gap < -max(1e-10 * abs(f), np.finfo(float).eps * abs(problem.target)):
        # f(X) - g(Lambda) >= f(X) - f* >= 0 for an exact dual value: a negative one means
        # the inner solve for X' was not accurate (a singular G), so nothing is certified
        return np.inf
    return relative_gap(max(gap, 0.0), f, problem)


def _admm(problem: GramProblem, start, options: FastOptions, info):
    """ADMM with Anderson acceleration and periodic polishing (module docstring, steps 3-4).

    The ADMM iteration is a fixed-point map ``T`` of ``v = (Z, U)``. Type-II
    Anderson acceleration (Walker & Ni, SIAM J. Numer. Anal. 49, 2011; as in
    SCS 3) extrapolates from the last ``anderson_memory`` residuals
    ``T(v) - v``; a step is kept only if its own residual is at most twice the
    plain one (safeguard), otherwise the history restarts. ``rho`` is balanced
    on the relative primal and dual residuals (Boyd et al. 2011, sec. 3.4.1)
    every ``polish_every`` iterations during the first ``rho_updates`` checks.
    """
    G, Ht = problem.gram, problem.cross.T
    g, W = np.linalg.eigh(G)
    g = np.maximum(g, 0.0)
    alpha = options.relaxation
    rho = max(float(np.sqrt(max(g[0], 1e-12 * g[-1]) * g[-1])), 1e-12)
    Minv = (W / (2.0 * g + rho)) @ W.T

    def T(Z, U):
        X = (rho * (Z - U) - 2.0 * Ht) @ Minv
        Xr = alpha * X + (1.0 - alpha) * Z
        Zn, faces = _project_with_faces(problem, Xr + U)
        return Zn, U + Xr - Zn, X, faces

    Z = start[0]
    U = -problem.gradient(Z) / rho
    best_X, best_f, best_gap = Z, problem.objective(Z), start[1]
    status = "max_iterations"
    stalled = checks = 0
    history_v, history_g = [], []
    pending = None
    next_polish = options.polish_first
    k = 0
    for k in range(1, options.max_iterations + 1):
        Zn, Un, X, faces = T(Z, U) if pending is None else pending
        pending = None
        v = np.concatenate([Z.ravel(), U.ravel()])
        Tv = np.concatenate([Zn.ravel(), Un.ravel()])
        residual = Tv - v
        Z_old = Z
        Z, U = Zn, Un
        if options.anderson_memory:
            history_v.append(Tv)
            history_g.append(residual)
            if len(history_g) > options.anderson_memory + 1:
                history_v.pop(0)
                history_g.pop(0)
            if len(history_g) >= 2:
                dG = np.diff(np.asarray(history_g), axis=0)      # (m, n): rows are differences
                dV = np.diff(np.asarray(history_v), axis=0)
                # least squares min ||residual - dG^T gamma|| by its (m, m) normal
                # equations, Tikhonov-safeguarded (an SVD of the tall (n, m) matrix
                # cost more than the ADMM step itself)
                normal = dG @ dG.T
                normal[np.diag_indices_from(normal)] += 1e-10 * np.trace(normal) + 1e-300
                gamma = np.linalg.solve(normal, dG @ residual)
                cand = Tv - gamma @ dV
                Zc = cand[:Z.size].reshape(Z.shape)     # T needs no feasible Z
                Uc = cand[Z.size:].reshape(U.shape)
                trial = T(Zc, Uc)
                trial_residual = np.sqrt(np.sum((trial[0] - Zc) ** 2) + np.sum((trial[1] - Uc) ** 2))
                if trial_residual <= 2.0 * np.linalg.norm(residual):
                    Z, U, pending = Zc, Uc, trial
                    faces = trial[3]
                else:
                    history_v, history_g = [], []
        if k == next_polish:
            # early polishes find the active set of well-conditioned problems
            # after a few dozen iterations; later ones are spaced out
            next_polish += options.polish_first if k < 5 * options.polish_first else options.polish_every
            checks += 1
            Xp, gap = _polish(problem, faces, Z, options, info)
            fp = problem.objective(Xp)
            stalled = 0 if fp < best_f * (1.0 - options.stall_tol) else stalled + 1
            if fp < best_f or gap <= options.tol:
                # a certified polish ends the search even when round-off puts
                # its objective a hair above an earlier, uncertified point
                best_X, best_f, best_gap = Xp, fp, gap
            Zp = problem.project(Z)     # an accepted Anderson point need not be feasible
            if best_gap > options.tol and problem.objective(Zp) < best_f:
                best_X, best_f = Zp, problem.objective(Zp)
                best_gap = _gap_estimate(problem, Zp, options, info)
            if best_gap <= options.tol:
                status = "optimal"
                break
            if stalled >= options.stall_polishes:
                # no polish has improved the objective for a while: report the
                # (possibly loose, on degenerate data) gap estimate as it is
                status = "stalled"
                break
            if checks <= options.rho_updates:
                primal = np.linalg.norm(X - Z) / max(np.linalg.norm(Z), 1e-300)
                dual = np.linalg.norm(Z - Z_old) / max(np.linalg.norm(U), 1e-300)
                factor = 2.0 if primal > 10.0 * dual else (0.5 if dual > 10.0 * primal else 1.0)
                if factor != 1.0:
                    rho *= factor
                    U = U / factor
                    Minv = (W / (2.0 * g + rho)) @ W.T
                    history_v, history_g, pending = [], [], None
    info["iterations"] = k
    info["gap_estimate"] = float(best_gap)
    info["active"] = _active_counts(problem, best_X)
    return best_X, status
