r"""Canonical Hamiltonian systems with a quadratic part and a known potential.

For ``y = [q; p]`` (``q, p`` of shape (m,)) and

.. math::

    H(q, p) = \tfrac12 q^\top D_q q + \tfrac12 p^\top D_p p + H_{nl}(q, p), \qquad
    \dot q = \partial H / \partial p, \quad \dot p = -\partial H / \partial q,

:class:`CanonicalSystem` holds the symmetric ``D_q``, ``D_p`` (dense or
sparse) and a potential object with

- ``value(q, p) -> (k,)`` for (m, k) columns (or a float for (m,) vectors),
- ``gradient(q, p) -> (dH_nl/dq, dH_nl/dp)``, each shaped like ``q``,
- ``hessian(q, p) -> (H_qq, H_qp, H_pp)`` at one state, each an (m,) diagonal
  (a pointwise potential) or an (m, m) dense block (a projected one).

Two implicit one-step schemes, both second order, solved by Newton on the
symmetric tangent ``grad^2 H`` (``I - c h J grad^2 H`` is the step Jacobian):

- ``"midpoint"``: ``y_1 = y_0 + h J grad H((y_0 + y_1)/2)``. Symplectic;
  conserves every quadratic invariant exactly (the NLS mass) and ``H`` up to a
  bounded ``O(h^2)`` oscillation without drift when ``H`` is not quadratic
  (Hairer, Lubich & Wanner, Geometric Numerical Integration, 2006, IV.2, IX.8).
- ``"avf"``: the average vector field method (Quispel & McLaren, J. Phys. A
  41, 045206, 2008), ``y_1 = y_0 + h J int_0^1 grad H(y_0 + s (y_1 - y_0)) ds``;
  conserves ``H`` exactly (``H(y_1) - H(y_0) = h G^T J G = 0``) but is not
  symplectic. The integral is taken by Gauss-Legendre quadrature with
  ``quadrature`` points, exact when ``grad H`` is a polynomial of degree
  ``<= 2 quadrature - 1`` in ``s`` (the cubic NLS gradient needs 2).
"""

from __future__ import annotations

import contextlib
import functools
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from threadpoolctl import threadpool_limits

from femrom.integrators._newton import ConvergenceError, Newton
from femrom.integrators._scheme import time_scheme


def _block(h, m: int):
    """A Hessian block as an (m, m) matrix (dense or sparse) from an (m,) diagonal or a matrix."""
    if sp.issparse(h):
        return h
    h = np.asarray(h, dtype=float)
    return sp.diags(h) if h.ndim == 1 else h


@dataclass(frozen=True, eq=False)
class CanonicalSystem:
    r"""``H = q^T D_q q / 2 + p^T D_p p / 2 + H_nl(q, p)`` with symmetric ``D_q``, ``D_p``.

    Attributes
    ----------
    position : (m, m) ndarray or sparse
        ``D_q``.
    momentum : (m, m) ndarray or sparse
        ``D_p``.
    potential : object or None
        ``H_nl`` with ``value``, ``gradient``, ``hessian`` (module docstring).
    """

    position: Any
    momentum: Any
    potential: Any = None

    @property
    def m(self) -> int:
        return self.position.shape[0]

    @functools.cached_property
    def _linear_hessian(self) -> np.ndarray:
        m = self.m
        H = np.zeros((2 * m, 2 * m))
        H[:m, :m] = _dense(self.position)
        H[m:, m:] = _dense(self.momentum)
        return H

    def _diagonal_index(self, i: int, j: int) -> np.ndarray:
        """Flat indices of the diagonal of block (i, j) in the (2m, 2m) Hessian."""
        m = self.m
        k = np.arange(m)
        return (i * m + k) * (2 * m) + j * m + k

    def hamiltonian(self, q: np.ndarray, p: np.ndarray):
        """``H`` for (m,) vectors (a float) or (m, k) columns ((k,) ndarray)."""
        value = 0.5 * (np.sum(q * (self.position @ q), axis=0) + np.sum(p * (self.momentum @ p), axis=0))
        if self.potential is not None:
            value = value + self.potential.value(q, p)
        return value

    def gradient(self, y: np.ndarray) -> np.ndarray:
        """(2m,) ``grad H`` at ``y = [q; p]``."""
        m = self.m
        q, p = y[:m], y[m:]
        gq, gp = self.position @ q, self.momentum @ p
        if self.potential is not None:
            nq, np_ = self.potential.gradient(q, p)
            gq, gp = gq + nq, gp + np_
        return np.concatenate([gq, gp])

    def rhs(self, y: np.ndarray) -> np.ndarray:
        """(2m,) ``J grad H = [dH/dp; -dH/dq]``."""
        g = self.gradient(y)
        m = self.m
        return np.concatenate([g[m:], -g[:m]])

    def hessian(self, y: np.ndarray):
        """(2m, 2m) symmetric ``grad^2 H``: dense when ``D_q`` is dense, else sparse CSR."""
        m = self.m
        if isinstance(self.position, np.ndarray):
            H = self._linear_hessian.copy()
            if self.potential is not None:
                flat = H.reshape(-1)
                for (i, j), h in zip(((0, 0), (0, 1), (1, 1)), self.potential.hessian(y[:m], y[m:])):
                    if np.ndim(h) == 1:
                        flat[self._diagonal_index(i, j)] += h
                        if i != j:
                            flat[self._diagonal_index(j, i)] += h
                    else:
                        h = _dense(h)
                        H[i * m:(i + 1) * m, j * m:(j + 1) * m] += h
                        if i != j:
                            H[j * m:(j + 1) * m, i * m:(i + 1) * m] += h.T
            return H
        blocks = [[self.position, None], [None, self.momentum]]
        if self.potential is not None:
            hqq, hqp, hpp = (_block(h, m) for h in self.potential.hessian(y[:m], y[m:]))
            blocks = [[self.position + hqq, hqp], [hqp.T, self.momentum + hpp]]
        return sp.bmat(blocks, format="csr")


def _dense(b):
    return b.toarray() if sp.issparse(b) else np.asarray(b, dtype=float)


def _apply_j(z: np.ndarray) -> np.ndarray:
    m = z.shape[0] // 2
    return np.concatenate([z[m:], -z[:m]])


def _j_times(H):
    """``J H`` for a (2m, 2m) matrix: rows ``[H_p; -H_q]``."""
    m = H.shape[0] // 2
    if sp.issparse(H):
        H = H.tocsr()
        return sp.vstack([H[m:], -H[:m]], format="csc")
    return np.concatenate([H[m:], -H[:m]])


def _solve(A, b):
    return spla.spsolve(A.tocsc(), b) if sp.issparse(A) else np.linalg.solve(A, b)


@dataclass
class CanonicalTrajectory:
    """What :func:`integrate_canonical` returns.

    Attributes
    ----------
    q, p : (m, k) ndarray
        States at the k = n_steps + 1 times.
    hamiltonian : (k,) ndarray
        ``H`` at every time.
    iterations : (n_steps,) ndarray of int
        Newton iterations of every step.
    seconds : float
        Wall time of the stepping loop.
    """

    q: np.ndarray
    p: np.ndarray
    hamiltonian: np.ndarray
    iterations: np.ndarray
    seconds: float


def integrate_canonical(system: CanonicalSystem, q0: np.ndarray, p0: np.ndarray, dt: float,
                        n_steps: int, scheme: str = "midpoint", newton: Newton = Newton(rtol=1e-12),
                        quadrature: int = 2) -> CanonicalTrajectory:
    r"""Step ``y' = J grad H(y)`` with the implicit midpoint rule or the AVF method.

    Each step solves ``R(y_1) = y_1 - y_0 - h J G(y_0, y_1) = 0`` by Newton
    (``G`` the midpoint gradient or the AVF average) from the explicit Euler
    predictor, until ``||R|| <= atol + rtol (||y_0|| + h ||G||)`` or the update
    is at round-off.

    Parameters
    ----------
    system : CanonicalSystem
    q0, p0 : (m,) ndarray
    dt : float
    n_steps : int
    scheme : str or Scheme
        A registered canonical scheme with a quadrature of the gradient along the step
        (``"midpoint"``: implicit midpoint; ``"avf"``: the discrete gradient).
    newton : Newton
        Tolerances and the iteration limit of each step.
    quadrature : int
        Gauss-Legendre points of the AVF integral.

    Returns
    -------
    CanonicalTrajectory
    """
    step = time_scheme(scheme)
    step.check_kind("canonical")
    nodes, weights = step.canonical_nodes(int(quadrature))
    h = float(dt)
    m = system.m
    Y = np.empty((2 * m, n_steps + 1))
    Y[:, 0] = np.concatenate([np.asarray(q0, float), np.asarray(p0, float)])
    iterations = np.zeros(n_steps, dtype=int)
    identity = sp.identity(2 * m, format="csc") if sp.issparse(system.position) else np.eye(2 * m)
    # small dense solves run fastest on one thread (and do not fight other processes)
    limit = threadpool_limits(1) if identity.shape[0] <= 2048 else contextlib.nullcontext()
    tic = time.perf_counter()
    with limit:
        _steps(system, Y, h, nodes, weights, identity, newton, iterations)
    seconds = time.perf_counter() - tic
    Q, P = Y[:m], Y[m:]
    return CanonicalTrajectory(q=Q, p=P, hamiltonian=np.atleast_1d(system.hamiltonian(Q, P)),
                               iterations=iterations, seconds=seconds)


def _steps(system, Y, h, nodes, weights, identity, newton, iterations):
    eps = np.finfo(float).eps
    for k in range(Y.shape[1] - 1):
        y0 = Y[:, k]
        y1 = y0 + h * system.rhs(y0)
        scale0 = np.linalg.norm(y0)
        for it in range(newton.max_iterations + 1):
            if len(nodes) == 1:
                points = [0.5 * (y0 + y1)]
                G = system.gradient(points[0])
            else:
                points = [y0 + s * (y1 - y0) for s in nodes]
                G = sum(w * system.gradient(z) for w, z in zip(weights, points))
            R = y1 - y0 - h * _apply_j(G)
            norm = np.linalg.norm(R)
            if not np.isfinite(norm):
                raise ConvergenceError(f"step {k}: residual is not finite")
            if norm <= newton.atol + newton.rtol * (scale0 + h * np.linalg.norm(G)):
                break
            if it == newton.max_iterations:
                raise ConvergenceError(f"step {k}: Newton residual {norm:.3g} after {it} iterations")
            if len(nodes) == 1:
                Hs = 0.5 * system.hessian(points[0])
            else:
                Hs = sum(w * s * system.hessian(z) for w, s, z in zip(weights, nodes, points))
            dy = _solve(identity - h * _j_times(Hs), R)
            y1 = y1 - dy
            iterations[k] = it + 1
            if np.linalg.norm(dy) <= 4.0 * eps * np.linalg.norm(y1):
                break
        Y[:, k + 1] = y1
