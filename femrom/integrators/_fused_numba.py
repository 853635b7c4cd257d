r"""numba kernel of one Newmark-family step of a small model with a projected joint (see :mod:`._fused`).

One call does what :meth:`femrom.integrators.NewmarkFamily.step` does with the dense Newton of
:class:`~femrom.integrators.ImplicitSolve` and a :class:`~femrom.fem.TransformedForce` joint,
in the same order of operations: the predictors, the linear right-hand side, Newton on the new
acceleration (the pairs' gaps ``W q + x_0``, the law on every pair and slider, ``W^T g`` and
``S + c_q W^T D W``, an LU solve with partial pivoting, the residual and update tests of
:func:`~femrom.integrators.newton_loop`), the update of ``q`` and ``v`` and the commit of the
slider states. The law's pieces are the joint kernels of :func:`femrom.fem.compiled_kernels`.

Sums run in loops where numpy calls BLAS, so results agree with the numpy path to round-off,
not bit for bit. numba's on-disk cache keys a function on its own file only: after editing the
joint kernels, clear the cache (``__pycache__/*.nbi``, ``*.nbc``) of this module too.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from femrom.fem import compiled_kernels

_laws = compiled_kernels()
if _laws is None:  # pragma: no cover - the caller imports this module only with the kernels on
    raise ImportError("the compiled law kernels are off")

#: ``status`` of :func:`newmark_joint_step`.
CONVERGED, NOT_CONVERGED, NOT_FINITE, SINGULAR = 0, 1, 2, 3


@njit(cache=True)
def _norm(x):
    total = 0.0
    for i in range(x.size):
        total += x[i] * x[i]
    return math.sqrt(total)


@njit(cache=True)
def _matvec(A, x, out):
    for i in range(A.shape[0]):
        total = 0.0
        for j in range(A.shape[1]):
            total += A[i, j] * x[j]
        out[i] = total
    return out


@njit(cache=True)
def _lu_solve(A, b):
    """Solve ``A x = b`` in place (``A`` overwritten by its LU factors, ``b`` by ``x``); False if singular."""
    n = A.shape[0]
    for k in range(n):
        pivot, largest = k, abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > largest:
                pivot, largest = i, abs(A[i, k])
        if largest == 0.0 or not math.isfinite(largest):
            return False
        if pivot != k:
            for j in range(n):
                A[k, j], A[pivot, j] = A[pivot, j], A[k, j]
            b[k], b[pivot] = b[pivot], b[k]
        for i in range(k + 1, n):
            factor = A[i, k] / A[k, k]
            if factor != 0.0:
                for j in range(k + 1, n):
                    A[i, j] -= factor * A[k, j]
                b[i] -= factor * b[k]
    for i in range(n - 1, -1, -1):
        total = b[i]
        for j in range(i + 1, n):
            total -= A[i, j] * b[j]
        b[i] = total / A[i, i]
    return True


@njit(cache=True)
def newmark_joint_step(q, v, a, force, has_force, mass, damping, has_damping, stiffness, S,
                       h, beta, gamma, alpha_m, alpha_f, c_q, w, rtol, atol, max_iterations,
                       kind, W, local_offset, gap_offset, areas, slider_stiffness, strength, normal_stiffness,
                       state):
    """One step from ``(q, v, a)`` with the joint's ``state`` frozen in Newton and committed after.

    Returns ``(q1, v1, a1, state1, iterations, status, residual, tolerance)``; ``status`` is
    :data:`CONVERGED` or why not (then ``residual`` and ``tolerance`` are the last test's).
    """
    r = q.size
    s = areas.size
    q_pred = np.empty(r)
    v_pred = np.empty(r)
    for i in range(r):
        q_pred[i] = q[i] + h * v[i] + ((0.5 - beta) * h * h) * a[i]
        v_pred[i] = v[i] + ((1.0 - gamma) * h) * a[i]
    if alpha_f == 0.0:
        q_bal = q_pred
        v_bal = v_pred
    else:
        q_bal = (1.0 - alpha_f) * q_pred + alpha_f * q
        v_bal = (1.0 - alpha_f) * v_pred + alpha_f * v
    work = np.empty(r)
    b = -_matvec(stiffness, q_bal, np.empty(r))
    if has_damping:
        b -= _matvec(damping, v_bal, work)
    if alpha_m != 0.0:
        b -= alpha_m * _matvec(mass, a, work)
    if has_force:
        b = b + force
    norm_b = _norm(b)

    x = a.copy()
    gap = np.empty((s, 3))
    g = np.empty(3 * s)
    D = np.empty((s, 3, 3))
    f = np.empty(r)
    Sx = np.empty(r)
    R = np.empty(r)
    P = np.empty((r, r))
    J = np.empty((r, r))
    rows = np.empty((3, r))
    at = np.empty(r)
    eps = np.finfo(np.float64).eps
    c = w * c_q
    iterations = -1
    norm = tolerance = np.nan
    for iteration in range(max_iterations + 1):
        for i in range(r):
            at[i] = q_bal[i] + c_q * x[i]
        _laws.joint_gaps(W, local_offset, gap_offset, at, gap)
        _laws.joint_law(kind, gap, state, slider_stiffness, strength, normal_stiffness, areas, g, D)
        _laws.joint_project_force(W, g, f)
        _matvec(S, x, Sx)
        scale = _norm(Sx) + norm_b + w * _norm(f)
        for i in range(r):
            R[i] = Sx[i] - b[i] + w * f[i]
        norm = _norm(R)
        if not math.isfinite(norm):
            return q_pred, v_pred, x, state.copy(), iteration, NOT_FINITE, norm, tolerance
        tolerance = atol + rtol * scale
        if norm <= tolerance:
            iterations = iteration
            break
        if iteration == max_iterations:
            return q_pred, v_pred, x, state.copy(), iteration, NOT_CONVERGED, norm, tolerance
        _laws.joint_project_tangent(W, D, P, rows)
        for i in range(r):
            for j in range(r):
                J[i, j] = S[i, j] + c * P[i, j]
        if not _lu_solve(J, R):
            return q_pred, v_pred, x, state.copy(), iteration, SINGULAR, norm, tolerance
        for i in range(r):
            x[i] = x[i] - R[i]
        if _norm(R) <= 4.0 * eps * _norm(x):
            iterations = iteration + 1
            break

    q1 = np.empty(r)
    v1 = np.empty(r)
    for i in range(r):
        q1[i] = q_pred[i] + (beta * h * h) * x[i]
        v1[i] = v_pred[i] + (gamma * h) * x[i]
    _laws.joint_gaps(W, local_offset, gap_offset, q1, gap)
    state1 = _laws.joint_commit(kind, gap, state, slider_stiffness, strength)
    return q1, v1, x, state1, iterations, CONVERGED, norm, tolerance
