r"""Least squares on faces of the semidefinite cone: the inner solve of the structured regression.

A *face* of block ``j`` is ``X_j = offset_j I + U_j A_j U_j^T`` (``U_j`` (r, k) with
orthonormal columns; ``U_j = None``: ``X_j = A_j``, the whole symmetric space).
Ignoring definiteness, the optimality conditions of ``f(X) = <X G, X> + 2 <X, H^T> + c``
over the ``A_j`` are coupled Lyapunov equations

.. math::

    \operatorname{sym}\big(U_j^\top (X G + H^\top)_j U_j\big) = 0 ,

solved by conjugate gradients preconditioned by the exact block-diagonal Lyapunov
inverse (diagonal in the eigenbasis of each ``U_j^T G_jj U_j``), or, with at most
``dense_unknowns`` unknowns, as one dense symmetric system in the orthonormal
basis of :func:`~femrom.inference._svec.sym_basis` (exact whatever the conditioning).
The first-order path (:mod:`._first_order`) and the duality-gap estimate
(:mod:`._duality_gap`) call :func:`solve_faces`; ``options`` is the
:class:`~femrom.inference.FastSolver` (``cg_tol``, ``cg_max_iterations``,
``dense_unknowns``) and ``info`` its counters (``cg_iterations``, ``dense_solves``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom.inference._problem import GramProblem
from femrom.inference._svec import sym_basis


@dataclass
class Face:
    """``X_j = offset I + U A U^T`` (``U = None``: ``X_j = A``, the whole symmetric space)."""

    U: np.ndarray | None
    offset: float
    precond_vectors: np.ndarray
    precond_values: np.ndarray

    @property
    def size(self) -> int:
        return self.precond_values.size


def make_faces(problem: GramProblem, bases) -> list[Face]:
    """The faces of ``bases = (U_j's, offset_j's)``, each with the eigendecomposition of
    ``U_j^T G_jj U_j`` (its preconditioner)."""
    faces = []
    for U, offset, s in zip(*bases, problem.slices()):
        Gjj = problem.gram[s, s]
        Gt = Gjj if U is None else U.T @ Gjj @ U
        g, W = np.linalg.eigh(0.5 * (Gt + Gt.T))
        faces.append(Face(U=U, offset=offset, precond_vectors=W, precond_values=g))
    return faces


def embed(problem, faces, As, with_offset: bool) -> np.ndarray:
    """(r, p) ``X`` with blocks ``U_j A_j U_j^T`` (plus ``offset_j I`` if ``with_offset``)."""
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


def solve_faces(problem: GramProblem, faces, As0, options, info):
    """Minimise ``f`` over ``X_j = offset_j I + U_j A_j U_j^T`` by preconditioned CG."""
    G, Ht = problem.gram, problem.cross.T
    sizes = [f.size for f in faces]
    if not any(sizes):
        return As0

    def hess(Ds):
        return _restrict(problem, faces, 2.0 * (embed(problem, faces, Ds, False) @ G))

    X0 = embed(problem, faces, As0, True)
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


def _solve_faces_dense(problem, faces, As0, res, info):
    """The face problem as a dense symmetric system (few unknowns): exact whatever
    the conditioning, where conjugate gradients would crawl.

    With ``T`` the embedded basis matrices ``X_a`` (r, p), the Hessian is
    ``H_ab = <X_a, 2 X_b G>`` and the right side ``<E_a, residual_j>``.
    """
    r, G = problem.r, problem.gram
    bases, embedded = [], []
    for face, s in zip(faces, problem.slices()):
        E = sym_basis(face.size)
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
