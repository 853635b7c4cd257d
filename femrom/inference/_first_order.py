r"""The first-order path of the structured regression: active set on eigenspaces, then ADMM.

Cheap per iteration and fast when the Gram matrix ``G`` is well conditioned
(random data: r = 100 in ~0.35 s); :func:`~femrom.inference.solve_fast` takes it
under ``method="auto"`` unless ``G`` is ill-conditioned or the problem small.

1. **Symmetric least squares.** Ignoring definiteness, the optimum solves
   coupled Lyapunov equations (:func:`~femrom.inference._face_lstsq.solve_faces`
   on the whole symmetric space). When the solution already satisfies
   ``X_j >= eps_j I`` it is the optimum (the problem is convex) and the path stops.
2. **Active set on eigenspaces** otherwise (``_polish``): the faces
   ``X_j = eps_j I + U_j A_j U_j^T`` read off the clipped solution turn the problem
   into a symmetric least-squares problem in the ``A_j`` again; faces shrink where
   ``A_j`` has negative eigenvalues and grow where the multiplier
   ``Lambda_j = sym(grad f)_j`` is negative on the complement or couples to the face.
3. **ADMM** if that is not certified (``_admm``), on
   ``min f(X) + indicator_S(Z)  s.t.  X = Z``:

   .. math::

       X^{k+1} = (\rho (Z^k - U^k) - 2 H^\top)(2 G + \rho I)^{-1}, \quad
       Z^{k+1} = \Pi_S(\alpha X^{k+1} + (1 - \alpha) Z^k + U^k), \quad
       U^{k+1} = U^k + \alpha X^{k+1} + (1 - \alpha) Z^k - Z^{k+1},

   where ``(2 G + rho I)^{-1}`` comes from one eigendecomposition of ``G``,
   ``Pi_S`` symmetrises each block and clips its eigenvalues at ``eps_j``,
   ``alpha = 1.6`` over-relaxes and ``rho = sqrt(g_min g_max)``; the fixed-point
   map is Anderson-accelerated (coefficients from the (m, m) normal equations
   of the residual differences), and the positive eigenspaces of the projected
   matrices seed step 2 after 10, 20, ..., 50 iterations, then every
   ``polish_every``: on well-conditioned data the active set is right after
   10-20 iterations, so early polishes end the run.

A point is accepted when its relative duality gap (:mod:`._duality_gap`) is below
``tol``; the best feasible point by objective is returned in any case. ``options``
is the :class:`~femrom.inference.FastSolver` whose settings apply.
"""

from __future__ import annotations

import numpy as np

from femrom.inference._duality_gap import gap_estimate
from femrom.inference._face_lstsq import embed, make_faces, solve_faces
from femrom.inference._problem import GramProblem


def solve_first_order(problem: GramProblem, options, info):
    """The first-order path (module docstring); returns ``(X, status)``.

    ``options`` is the :class:`~femrom.inference.FastSolver` (its settings); ``info``
    receives ``iterations``, ``cg_iterations``, ``gap_estimate`` and ``active``.
    """
    r = problem.r
    nb = len(problem.blocks)
    full = make_faces(problem, ([None] * nb, [0.0] * nb))
    As = solve_faces(problem, full, [np.zeros((r, r)) for _ in range(nb)], options, info)
    X = embed(problem, full, As, False)
    if problem.is_feasible(X, tol=0.0):
        return X, "optimal (unconstrained)"
    # active set from the clipped unconstrained solution: often exact at once
    Z, faces = _project_with_faces(problem, X)
    start = _polish(problem, faces, Z, options, info)
    if problem.objective(Z) < problem.objective(start[0]):
        start = (Z, gap_estimate(problem, Z, options, info))
    if start[1] <= options.tol:
        info["gap_estimate"] = float(start[1])
        info["active"] = _active_counts(problem, start[0])
        return start[0], "optimal"
    return _admm(problem, start, options, info)


def _active_counts(problem: GramProblem, X: np.ndarray) -> dict:
    """Per "psd" block, the eigenvalues of ``X_j`` held at the bound ``eps_j``."""
    out = {}
    for b, s in zip(problem.blocks, problem.slices()):
        if b.structure == "psd":
            g = np.linalg.eigvalsh(X[:, s])
            out[b.name] = int(np.sum(g <= b.shift + 1e-12 * max(abs(g[-1]), 1e-300)))
    return out


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


def _polish(problem: GramProblem, face_bases, Z: np.ndarray, options, info):
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
            faces = make_faces(problem, (Us, offsets))
            As0 = []
            for face, s in zip(faces, problem.slices()):
                Zj = Z[:, s] - face.offset * np.eye(r)
                As0.append(Zj if face.U is None else face.U.T @ Zj @ face.U)
            As = solve_faces(problem, faces, As0, options, info)
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
        X = problem.project(embed(problem, faces, As, True))
        gap = gap_estimate(problem, X, options, info)
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


def _admm(problem: GramProblem, start, options, info):
    """ADMM with Anderson acceleration and periodic polishing (module docstring, steps 2-3).

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
                best_gap = gap_estimate(problem, Zp, options, info)
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
