r"""Lean time stepping of small dense reduced systems.

``M q'' + C q' + K q + f(q, q') = B u(t)`` with (r, r) dense operators. The
full-order integrators of :mod:`femrom.integrators` accept such a system
wrapped as a ``SecondOrderSystem`` of csr matrices, but their per-step Python
overhead (step objects, solver strategies, checks) dominates at r ~ 20
(measured in ``tests/test_rom.py``). Here, for a linear system, every scheme
is one precomputed linear map

.. math::

    x_{k+1} = A x_k + F u_{k+\theta},

applied with one small matrix-vector product per step (``theta = 1`` for
Newmark and Stoermer-Verlet, ``1/2`` for the midpoint rule). A nonlinear
force adds a dense Newton iteration per step.

Schemes (``h = dt``):

- ``"newmark"`` (average acceleration, ``beta = 1/4, gamma = 1/2``):
  ``S a_{k+1} = B u_{k+1} - C v^* - K q^*`` with the predictors
  ``q^* = q + h v + h^2 a / 4``, ``v^* = v + h a / 2`` and
  ``S = M + h C / 2 + h^2 K / 4``; state ``x = [q; v; a]``.
- ``"midpoint"``: ``S v_m = M v - h K q / 2 + h B u_{k+1/2} / 2`` with the same
  ``S``; ``q_{k+1} = q + h v_m``, ``v_{k+1} = 2 v_m - v``; state ``[q; v]``.
- ``"verlet"`` (velocity Stoermer-Verlet): ``v_{1/2} = v + h a / 2``,
  ``q_{k+1} = q + h v_{1/2}``, ``(M + h C / 2) a_{k+1} = B u_{k+1} - K q_{k+1}
  - C v_{1/2}``, ``v_{k+1} = v_{1/2} + h a_{k+1} / 2`` (explicit; stable for
  ``h < 2 / omega_max``, checked).

All three are second order; Newmark average acceleration and the midpoint
rule conserve ``v^T M v / 2 + q^T K q / 2`` exactly for ``C = 0, u = 0``
(Hairer, Lubich & Wanner, Geometric Numerical Integration, 2006, IV.2), and
Stoermer-Verlet conserves a modified energy (no drift).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl

#: Reduced schemes by name.
SCHEMES = ("newmark", "midpoint", "verlet")


def _solve_matrix(S: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    return sl.lu_solve(sl.lu_factor(S), rhs)


def linear_step_map(M, C, K, B, dt: float, scheme: str):
    """``(A, F, size)`` of the linear one-step map ``x1 = A x + F u``.

    Returns
    -------
    A : (s r, s r) ndarray
        With ``s = 3`` (``[q; v; a]``) for Newmark/Verlet and 2 for the midpoint rule.
    F : (s r, m) ndarray or None
    """
    r = K.shape[0]
    h = float(dt)
    I, Z = np.eye(r), np.zeros((r, r))
    C = Z if C is None else C
    if scheme == "newmark":
        beta, gamma = 0.25, 0.5
        S = M + gamma * h * C + beta * h * h * K
        Pq = np.hstack([I, h * I, (0.5 - beta) * h * h * I])
        Pv = np.hstack([Z, I, (1.0 - gamma) * h * I])
        Aa = -_solve_matrix(S, K @ Pq + C @ Pv)
        A = np.vstack([Pq + beta * h * h * Aa, Pv + gamma * h * Aa, Aa])
        if B is None:
            return A, None
        Fa = _solve_matrix(S, B)
        return A, np.vstack([beta * h * h * Fa, gamma * h * Fa, Fa])
    if scheme == "midpoint":
        S = M + 0.5 * h * C + 0.25 * h * h * K
        Avm = _solve_matrix(S, np.hstack([-0.5 * h * K, M]))
        A = np.vstack([np.hstack([I, Z]) + h * Avm, 2.0 * Avm - np.hstack([Z, I])])
        if B is None:
            return A, None
        Fvm = _solve_matrix(S, 0.5 * h * B)
        return A, np.vstack([h * Fvm, 2.0 * Fvm])
    if scheme == "verlet":
        S = M + 0.5 * h * C
        Pq = np.hstack([I, h * I, 0.5 * h * h * I])       # q1 = q + h v + h^2 a / 2
        Ph = np.hstack([Z, I, 0.5 * h * I])               # v_half
        Aa = -_solve_matrix(S, K @ Pq + C @ Ph)
        A = np.vstack([Pq, Ph + 0.5 * h * Aa, Aa])
        if B is None:
            return A, None
        Fa = _solve_matrix(S, B)
        return A, np.vstack([np.zeros_like(Fa), 0.5 * h * Fa, Fa])
    raise ValueError(f"unknown reduced scheme {scheme!r}; valid: {SCHEMES}")


def verlet_bound(M, K) -> float:
    """``2 / omega_max`` of ``(K, M)``: the Stoermer-Verlet stability limit."""
    w2 = sl.eigvals(K, M).real
    top = float(np.max(w2)) if w2.size else 0.0
    return np.inf if top <= 0 else 2.0 / np.sqrt(top)


def run_linear(A: np.ndarray, x0: np.ndarray, n_steps: int, forcing: np.ndarray | None):
    """(s, n_steps + 1) ndarray: ``x_{k+1} = A x_k + forcing[:, k]``.

    One BLAS call per step and nothing else: the forcing is written next to
    the states in a C-ordered (n_steps + 1, 2 s) buffer whose row ``k`` is
    ``[x_k, f_k]``, and ``x_{k+1} = [A, I] [x_k; f_k]`` is a single
    ``dot(..., out=)`` into the next row (no temporaries). Without forcing,
    ``dot(A, x_k, out=)`` on an (n_steps + 1, s) buffer. At r ~ 20 a step is
    dominated by the interpreter's call overhead (``benchmarks/rom_step.py``),
    so the fused call saves the separate vector add of a step.
    """
    s = x0.size
    dot = np.dot
    if forcing is None:
        X = np.empty((n_steps + 1, s))
        X[0] = x0
        for k in range(n_steps):
            dot(A, X[k], out=X[k + 1])
        return X.T
    Aug = np.ascontiguousarray(np.hstack([A, np.eye(s)]))
    buffer = np.empty((n_steps + 1, 2 * s))
    buffer[0, :s] = x0
    buffer[:n_steps, s:] = forcing[:, :n_steps].T
    buffer[n_steps, s:] = 0.0
    for k in range(n_steps):
        dot(Aug, buffer[k], out=buffer[k + 1, :s])
    return buffer[:, :s].T


def run_nonlinear(M, C, K, B, nonlinear, dt: float, scheme: str, q0, v0, times,
                  force_at, tol: float = 1e-10, max_iterations: int = 25):
    """Step a system with a (projected) nonlinear force; returns ``(Q, V, A)`` (r, k).

    ``force_at(t) -> (r,) ndarray`` is ``B u(t)`` (zeros without inputs).
    Newton on the step's unknown with the dense tangent
    ``M + c_v (C + df/dv) + c_q (K + df/dq)``.
    """
    r = K.shape[0]
    h = float(dt)
    C = np.zeros((r, r)) if C is None else C
    n = len(times)
    Q, Vel, Acc = np.empty((r, n)), np.empty((r, n)), np.empty((r, n))
    state = nonlinear.initial_state()

    def fnl(q, v):
        return nonlinear.force(q, v, state)

    def jac(q, v):
        Jq, Jv = nonlinear.tangent(q, v, state)
        return (np.zeros((r, r)) if Jq is None else Jq), (np.zeros((r, r)) if Jv is None else Jv)

    q, v = np.array(q0, dtype=float), np.array(v0, dtype=float)
    a = np.linalg.solve(M, force_at(times[0]) - C @ v - K @ q - fnl(q, v))
    Q[:, 0], Vel[:, 0], Acc[:, 0] = q, v, a
    for k in range(n - 1):
        t = times[k]
        if scheme in ("newmark", "midpoint"):
            if scheme == "newmark":
                cq, cv = 0.25 * h * h, 0.5 * h
                qp, vp = q + h * v + 0.25 * h * h * a, v + 0.5 * h * a
                f_ext = force_at(t + h)
                x = a.copy()

                def parts(x):
                    return qp + cq * x, vp + cv * x, M @ x
            else:
                cq, cv = 0.5 * h, 1.0
                f_ext = force_at(t + 0.5 * h)
                x = v + 0.5 * h * a   # unknown v_mid, scaled equation: M (v_m - v) / (h/2) + ...

                def parts(x):
                    return q + 0.5 * h * x, x, M @ (x - v) / (0.5 * h)
            for _ in range(max_iterations):
                qx, vx, inertia = parts(x)
                R = inertia + C @ vx + K @ qx + fnl(qx, vx) - f_ext
                Jq, Jv = jac(qx, vx)
                mass_factor = 1.0 if scheme == "newmark" else 1.0 / (0.5 * h)
                T = mass_factor * M + cv * (C + Jv) + cq * (K + Jq)
                dx = np.linalg.solve(T, -R)
                x = x + dx
                if np.linalg.norm(dx) <= tol * max(np.linalg.norm(x), 1e-300):
                    break
            else:
                raise RuntimeError(f"reduced Newton did not converge at t = {t + h:.6g}")
            if scheme == "newmark":
                a1 = x
                q, v = qp + cq * a1, vp + cv * a1
            else:
                q, v = q + h * x, 2.0 * x - v
            a = np.linalg.solve(M, force_at(t + h) - C @ v - K @ q - fnl(q, v))
        else:  # verlet: explicit, velocity-dependent forces lagged at the half step
            vh = v + 0.5 * h * a
            q = q + h * vh
            a = np.linalg.solve(M + 0.5 * h * C, force_at(t + h) - K @ q - C @ vh - fnl(q, vh))
            v = vh + 0.5 * h * a
        state = nonlinear.commit(q, v, state)
        if not np.all(np.isfinite(q)):
            raise RuntimeError(f"reduced state became non-finite at t = {t + h:.6g}")
        Q[:, k + 1], Vel[:, k + 1], Acc[:, k + 1] = q, v, a
    return Q, Vel, Acc
