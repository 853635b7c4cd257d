r"""Can the L-OpInf Newton systems be solved by conjugate gradients in O(r^3) a step?

Issue 31 (part 3) asked for matrix-free Newton-CG steps with a preconditioner
from eigendecompositions, O(r^3) an inner iteration instead of the dense
interior-point method's O(r^6) factorisations. This script measures what such
steps cost on the fit ladder's real data (:mod:`benchmarks.fit_ladder`: a
damped, forced string, mass-orthonormal POD, Tikhonov 1e-8), after block
scaling and the elimination of ``B^`` (the problem the interior-point method
solves), with unknowns ``X = [K, C]`` (symmetric) and Gram matrix ``G`` (2r, 2r):

1. **The unconstrained Hessian** ``H(K, C) = (sym(K G11 + C G21), sym(K G12 + C G22))``
   (the symmetric least-squares normal equations; every Newton matrix is ``2 H``
   plus the cone terms). Conjugate gradients to a relative residual of 1e-10
   (at most ``--max-cg`` iterations) on ``H X = -sym(H^T)`` with

   - ``none``;
   - ``block_jacobi``: the exact Lyapunov inverse of each diagonal block
     (``sym(K G11) = R``: diagonal in the eigenbasis of ``G11``);
   - ``ldl_k`` / ``ldl_c``: block LDL^T with the exact Lyapunov inverse of one
     diagonal block and, for the Schur complement, the Lyapunov inverse of the
     Schur complement of ``G`` (``G22 - G21 G11^-1 G12``, or the other way):
     exact if the unknowns were not symmetric.

   For ``ldl_k`` also the iterations to a relative objective gap of 1e-8 (CG
   minimises the energy norm, which is what a certified gap measures; the
   certificate itself needs the small residual). Also reported: ``kappa(G)`` and the singular values of the normalised K-C
   coupling ``G11^-1/2 G12 G22^-1/2`` near 1 (the directions that make the
   block-diagonal preconditioners fail).
2. **The interior-point Newton systems** (``--ipm-sizes``): the dense method runs
   as usual, and every Newton system it solves directly is solved again by
   conjugate gradients, preconditioned by ``ldl_k`` with the Nesterov-Todd terms
   ``W^-1 E W^-1`` added as their diagonal in the same eigenbases; the iterations
   to 1e-10 and the error against the direct solution are recorded.

3. **Deflation on the coupling directions** (``--deflation-sizes``): the preconditioned
   Hessian ``ldl_k^-1 H`` formed densely, its eigenvalues above 2 (the outliers that
   make CG slow), and how much of their eigenvectors lies outside
   ``S_U = {X : (I - P_U) X (I - P_U) = 0}`` (each block's rows or columns in ``U``),
   with ``U`` spanned by the top ``k`` coupling directions mapped back to ``K^`` and
   ``C^`` (``G11^-1/2 w_i``, ``G22^-1/2 z_i`` of the coupling's singular vectors).
   Where the outliers lie in ``S_U``, CG with ``S_U`` as a coarse space (the
   balancing preconditioner ``(I - Q H) ldl_k^-1 (I - H Q) + Q``,
   ``Q = W (W^T H W)^-1 W^T``) is run too: its iterations to 1e-10 against the size of
   the coarse space, which a solver would factorise densely every Newton step.

Run ``python -m benchmarks.newton_cg_probe [--sizes 30 60 100] [--ipm-sizes 30] [--deflation-sizes 30 60]``;
it prints a table and writes ``benchmarks/results/newton_cg_probe.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path
from typing import ClassVar

import numpy as np

from benchmarks.fit_ladder import mass_pod, string_data
from femrom.inference import LagrangianOpInf, reduce_snapshots
from femrom.inference._interior_point import DenseNewton, blas_threads, solve_ipm
from femrom.inference._structured_lstsq import eliminate_free
from femrom.inference._svec import smat, svec, sym

PRECONDITIONERS = ("none", "block_jacobi", "ldl_k", "ldl_c")


def reduced_problem(M, Q, U, dt, r):
    """The scaled problem in ``K^``, ``C^`` alone that the interior-point method solves."""
    data = reduce_snapshots(mass_pod(M, Q, r), Q, dt, product=M, inputs=U, order=4)
    problem = LagrangianOpInf(["damping"], regularization=1e-8).regression(data)
    return eliminate_free(problem.scaled()[0])[0]


class Lyapunov:
    """``R -> X`` with ``sym(X A) + nu o X = R`` in the eigenbasis of ``A`` (``nu``: extra
    diagonal in that basis, e.g. the Nesterov-Todd terms' diagonal)."""

    def __init__(self, A):
        self.g, self.V = np.linalg.eigh(A)
        self.set_extra(None)

    def set_extra(self, Winv):
        d = 0.5 * (self.g[:, None] + self.g[None, :])
        if Winv is not None:                    # diagonal of E -> W^-1 E W^-1 in this basis
            O = self.V.T @ Winv @ self.V
            w = np.diag(O)
            extra = np.outer(w, w) + O * O
            np.fill_diagonal(extra, w * w)
            d = 2.0 * d + extra                  # the Newton matrix is 2 H + NT
        self.d = d

    def __call__(self, R):
        return self.V @ ((self.V.T @ R @ self.V) / self.d) @ self.V.T


def preconditioner(name, G, r):
    """``(R1, R2) -> (X1, X2)``: an approximate inverse of ``H``."""
    G11, G12, G21, G22 = G[:r, :r], G[:r, r:], G[r:, :r], G[r:, r:]
    if name == "none":
        return lambda R1, R2: (R1, R2)
    if name == "block_jacobi":
        L1, L2 = Lyapunov(G11), Lyapunov(G22)
        return lambda R1, R2: (L1(R1), L2(R2))
    if name == "ldl_k":
        La, Ls = Lyapunov(G11), Lyapunov(G22 - G21 @ np.linalg.solve(G11, G12))
        Gab, Gba, swap = G12, G21, False
    else:
        La, Ls = Lyapunov(G22), Lyapunov(G11 - G12 @ np.linalg.solve(G22, G21))
        Gab, Gba, swap = G21, G12, True

    def apply(R1, R2):
        Ra, Rb = (R2, R1) if swap else (R1, R2)
        ya = La(Ra)
        yb = Ls(Rb - sym(ya @ Gab))
        xa = ya - La(sym(yb @ Gba))
        return (yb, xa) if swap else (xa, yb)
    return apply


def pcg(apply, precondition, rhs, tol=1e-10, max_iterations=3000, monitor=None):
    """Conjugate gradients on pairs of symmetric matrices; returns ``(X, iterations)``
    (``monitor(X)`` is called at every iterate)."""
    x = [np.zeros_like(b) for b in rhs]
    res = [b.copy() for b in rhs]
    z = list(precondition(*res))
    d = [zi.copy() for zi in z]
    rz = sum(np.sum(a * b) for a, b in zip(res, z))
    norm = np.sqrt(sum(np.sum(b * b) for b in rhs))
    for it in range(max_iterations):
        if monitor is not None:
            monitor(x)
        if np.sqrt(sum(np.sum(a * a) for a in res)) <= tol * norm:
            return x, it
        Ad = apply(d)
        step = rz / sum(np.sum(a * b) for a, b in zip(d, Ad))
        x = [a + step * b for a, b in zip(x, d)]
        res = [a - step * b for a, b in zip(res, Ad)]
        z = list(precondition(*res))
        rz_new = sum(np.sum(a * b) for a, b in zip(res, z))
        d = [a + (rz_new / rz) * b for a, b in zip(z, d)]
        rz = rz_new
    return x, max_iterations


def inverse_root(A):
    """``A^-1/2`` of a symmetric positive-definite ``A``."""
    w, V = np.linalg.eigh(A)
    return (V / np.sqrt(w)) @ V.T


def unconstrained(problem, max_cg):
    r, G = problem.r, problem.gram

    def hessian(Xs):
        Y = np.hstack(Xs) @ G
        return [sym(Y[:, :r]), sym(Y[:, r:])]

    rhs = [-sym(problem.cross.T[:, :r]), -sym(problem.cross.T[:, r:])]
    g = np.linalg.eigvalsh(G)

    coupling = np.linalg.svd(inverse_root(G[:r, :r]) @ G[:r, r:] @ inverse_root(G[r:, r:]),
                             compute_uv=False)
    row = {"r": r, "unknowns": r * (r + 1), "kappa": float(g[-1] / g[0]),
           "coupling_max": float(coupling[0]),
           "coupling_above_0.99": int(np.sum(coupling > 0.99)),
           "coupling_above_0.9999": int(np.sum(coupling > 0.9999)), "cg": {}}
    for name in PRECONDITIONERS:
        M = preconditioner(name, G, r)
        tic = time.perf_counter()
        X, its = pcg(hessian, M, rhs, max_iterations=max_cg)
        seconds = time.perf_counter() - tic
        R = [a - b for a, b in zip(hessian(X), rhs)]
        residual = np.sqrt(sum(np.sum(a * a) for a in R) / sum(np.sum(b * b) for b in rhs))
        row["cg"][name] = {"iterations": its, "seconds": seconds, "relative_residual": float(residual),
                           "seconds_per_iteration": seconds / max(its, 1)}
        if name == "ldl_k" and its < max_cg:
            # the objective, which is what a certified gap measures: iterations to a relative
            # objective gap of 1e-8 against the converged point (CG minimises the energy norm)
            values = []
            pcg(hessian, M, rhs, max_iterations=its,
                monitor=lambda Xs, out=values: out.append(problem.objective(np.hstack(Xs))))
            gaps = (np.asarray(values) - values[-1]) / abs(values[-1])
            row["cg"][name]["iterations_to_objective_gap_1e-8"] = int(np.argmax(gaps <= 1e-8))
    return row


class ProbedNewton(DenseNewton):
    """The dense Newton solver, every cone-term system also solved by preconditioned CG."""

    record: ClassVar[list] = []
    max_cg: ClassVar[int] = 5000

    def __init__(self, problem, index):
        super().__init__(problem, index)
        self.problem = problem

    def factor(self, terms):
        super().factor(terms)
        self.pre = None
        if any(t is not None for t in terms):
            G, r = self.problem.gram, self.r
            La, Ls = Lyapunov(G[:r, :r]), Lyapunov(G[r:, r:] - G[r:, :r] @ np.linalg.solve(G[:r, :r], G[:r, r:]))
            La.set_extra(terms[0])
            Ls.set_extra(terms[1])
            G12, G21 = 2.0 * G[:r, r:], 2.0 * G[r:, :r]

            def apply(R1, R2):
                y1 = La(R1)
                y2 = Ls(R2 - sym(y1 @ G12))
                return y1 - La(sym(y2 @ G21)), y2
            self.pre = apply

    def solve(self, rhs_blocks, refinements=2):
        out = super().solve(rhs_blocks, refinements)
        if self.pre is not None:
            def apply(Xs):
                x = np.concatenate([svec(X, self.index) for X in Xs])
                y = self.apply(x)
                return [smat(y[c], self.index, self.r) for c in self.cut]
            X, its = pcg(apply, self.pre, [R.copy() for R in rhs_blocks], max_iterations=self.max_cg)
            error = np.sqrt(sum(np.sum((a - b) ** 2) for a, b in zip(X, out))
                            / sum(np.sum(b * b) for b in out))
            self.record.append({"iterations": its, "error": float(error)})
        return out


def dense_operator(apply, m, index, r):
    """The (m, m) matrix of ``(R1, R2) -> (X1, X2)`` in svec coordinates."""
    n = m // 2
    out = np.empty((m, m))
    for a in range(m):
        e = np.zeros(m)
        e[a] = 1.0
        X1, X2 = apply(smat(e[:n], index, r), smat(e[n:], index, r))
        out[:, a] = np.concatenate([svec(X1, index), svec(X2, index)])
    return 0.5 * (out + out.T)


def deflation(problem, ks, max_cg):
    """Section 3 of the module docstring: outliers of ``ldl_k^-1 H``, their share in
    ``S_U`` for the top ``k`` coupling directions, and deflated CG."""
    import scipy.linalg as sla
    from femrom.inference._svec import svec_index
    r, G = problem.r, problem.gram
    index = svec_index(r)
    n = index[0].size
    m = 2 * n

    def hessian(R1, R2):
        Y = np.hstack([R1, R2]) @ G
        return sym(Y[:, :r]), sym(Y[:, r:])
    H = dense_operator(hessian, m, index, r)
    P = dense_operator(preconditioner("ldl_k", G, r), m, index, r)   # ~ H^-1
    w, V = sla.eigh(H, np.linalg.inv(P))
    outliers = V[:, w > 2.0]

    Wl, _, Zr = np.linalg.svd(inverse_root(G[:r, :r]) @ G[:r, r:] @ inverse_root(G[r:, r:]))
    rng = np.random.default_rng(0)
    rhs = rng.standard_normal(m)
    row = {"r": r, "unknowns": m, "outliers_above_2": int(outliers.shape[1]),
           "largest": float(w[-1]), "k": {}}

    def cg(M):
        # the probe's CG on one vector: H and the preconditioner as dense matrices
        return pcg(lambda d: [H @ d[0]], lambda v: (M(v),), [rhs], max_iterations=max_cg)[1]
    row["cg_ldl_k"] = cg(lambda v: P @ v)
    i, l, _ = index
    for k in ks:
        U = np.linalg.qr(np.hstack([inverse_root(G[:r, :r]) @ Wl[:, :k],
                                    inverse_root(G[r:, r:]) @ Zr[:k].T]))[0]
        off = np.eye(r) - U @ U.T
        share = []
        for v in outliers.T:
            K, C = smat(v[:n], index, r), smat(v[n:], index, r)
            share.append((np.sum((off @ K @ off) ** 2) + np.sum((off @ C @ off) ** 2)) / (v @ v))
        share = np.asarray(share)
        # coarse space: the rotated basis matrices with a row or column in U, both blocks
        T = np.hstack([U, sla.null_space(U.T)])
        picked = np.flatnonzero(np.minimum(i, l) < U.shape[1])
        basis = np.zeros((n, picked.size))
        for col, a in enumerate(picked):
            e = np.zeros(n)
            e[a] = 1.0
            basis[:, col] = svec(T @ smat(e, index, r) @ T.T, index)
        W = sla.block_diag(basis, basis)
        factor = sla.cho_factor(W.T @ H @ W)

        def coarse(v, W=W, factor=factor):
            return W @ sla.cho_solve(factor, W.T @ v)

        def balanced(v, coarse=coarse):
            y = P @ (v - H @ coarse(v))
            return y - coarse(H @ y) + coarse(v)
        row["k"][k] = {"subspace": int(U.shape[1]), "outside_median": float(np.median(share)),
                       "outside_max": float(share.max()), "outliers_outside_10pc": int(np.sum(share > 0.1)),
                       "coarse_unknowns": int(W.shape[1]), "cg_deflated": cg(balanced)}
    return row


def ipm_systems(problem, max_cg):
    import femrom.inference._interior_point as ipm
    record = []

    class Newton(ProbedNewton):
        pass
    Newton.record, Newton.max_cg = record, max_cg
    original = ipm.DenseNewton
    ipm.DenseNewton = Newton
    try:
        info = {}
        _, status = solve_ipm(problem, info=info)
    finally:
        ipm.DenseNewton = original
    return {"r": problem.r, "status": status, "ipm_iterations": info["ipm_iterations"],
            "gap": info["gap_estimate"], "systems": record}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[30, 60, 100])
    parser.add_argument("--ipm-sizes", type=int, nargs="*", default=[30])
    parser.add_argument("--deflation-sizes", type=int, nargs="*", default=[])
    parser.add_argument("--deflation-k", type=int, nargs="+", default=[4, 6, 8, 10, 12])
    parser.add_argument("--max-cg", type=int, default=3000)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args(argv)
    M, Q, U, dt = string_data()
    rows, systems, deflated = [], [], []
    with blas_threads(1):
        for r in args.sizes:
            row = unconstrained(reduced_problem(M, Q, U, dt, r), args.max_cg)
            rows.append(row)
            cg = "  ".join(f"{k} {v['iterations']} it ({1e3 * v['seconds_per_iteration']:.2f} ms/it, "
                           f"res {v['relative_residual']:.0e})" for k, v in row["cg"].items())
            cg += f"  ldl_k to an objective gap of 1e-8: {row['cg']['ldl_k'].get('iterations_to_objective_gap_1e-8')} it"
            print(f"r={r:4d} kappa {row['kappa']:.1e} coupling>0.9999: {row['coupling_above_0.9999']:3d}  {cg}",
                  flush=True)
        for r in args.ipm_sizes:
            out = ipm_systems(reduced_problem(M, Q, U, dt, r), 5000)
            systems.append(out)
            print(f"r={r:4d} interior point: {out['ipm_iterations']} iterations, {out['status']}; CG iterations "
                  f"per Newton system: {[s['iterations'] for s in out['systems']]}", flush=True)
        for r in args.deflation_sizes:
            row = deflation(reduced_problem(M, Q, U, dt, r), args.deflation_k, args.max_cg)
            deflated.append(row)
            print(f"r={r:4d} ldl_k: {row['outliers_above_2']} of {row['unknowns']} eigenvalues above 2 "
                  f"(largest {row['largest']:.1e}), CG {row['cg_ldl_k']} it", flush=True)
            for k, v in row["k"].items():
                print(f"        k={k:3d}: U of {v['subspace']}, outliers outside S_U: median "
                      f"{v['outside_median']:.3f}, max {v['outside_max']:.3f} ({v['outliers_outside_10pc']} above "
                      f"0.1); coarse space {v['coarse_unknowns']} unknowns, deflated CG {v['cg_deflated']} it",
                      flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    payload = {"benchmark": "newton_cg_probe", "machine": platform.platform(),
               "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "load_average": os.getloadavg(),
               "description": __doc__.split("\n\n")[1], "unconstrained": rows, "ipm_systems": systems, "deflation": deflated}
    (args.out / "newton_cg_probe.json").write_text(json.dumps(payload, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
