r"""numba kernels of learned scalar functions and of a whole discrete-gradient step (see :class:`femrom.fem.CompiledScalar`).

A scalar function ``phi(x) = T3[x,x,x] + T4[x,x,x,x] + sum |a_k . x|^3 / 3 + sum (b_k . x)^4 / 4
+ N(x) - N(0) - grad N(0) . x`` (any part may be absent) is a tuple of arrays, :attr:`CompiledScalar.parts`;
:func:`scalar_vgh` returns its value and writes its gradient and Hessian, the same formulas as the
numpy reference (:mod:`femrom.inference._networks`): the contractions as BLAS products (equal to round-off),
the network's Hessian forward over reverse, ``J^T diag(delta sigma'') J`` with the layer Jacobians
``J_l = W_l diag(sigma'_{l-1}) J_{l-1} + U_l``, formed only when the Hessian is asked for. A step allocates
its workspaces once (:func:`_workspace`) and evaluates values alone (no gradient, no Jacobian) where only
values are used. :func:`discrete_gradient_step` is one
step of :class:`femrom.integrators.DiscreteGradient` for a model whose nonlinear force is a learned
potential of ``q`` and/or a learned dissipation of ``q'``: the predictor, the Newton iterations on the
midpoint velocity (the two-point Gauss quadrature of the average vector field, Gonzalez's projection,
the update test with the stagnation floor) and the end-of-step acceleration, in one call.

The small linear-algebra helpers are repeated here, not imported, so that numba's on-disk cache
(``cache=True``, per file) cannot go stale when another kernel file changes.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Status codes of :func:`discrete_gradient_step` (0: converged).
NOT_CONVERGED, NOT_FINITE, SINGULAR = 1, 2, 3

#: ``SMALL_STEP`` and the Gauss nodes of :mod:`femrom.integrators.schemes.discrete_gradient`.
SMALL_STEP = 1e-6
_NODE0 = 0.5 - 0.5 / math.sqrt(3.0)
_NODE1 = 0.5 + 0.5 / math.sqrt(3.0)


@njit(cache=True)
def _norm(x):
    total = 0.0
    for i in range(x.size):
        total += x[i] * x[i]
    return math.sqrt(total)


@njit(cache=True)
def _dot(x, y):
    total = 0.0
    for i in range(x.size):
        total += x[i] * y[i]
    return total


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
def _workspace(parts, r):
    """The arrays :func:`_vgh` works in (allocated once a step, not once an evaluation): a flat array (the
    network's values, sigma', sigma'', Hessian, back-propagated ``dN/dh`` and ``dN/dz``, one layer's
    ``W h`` and ``U x``), the Jacobian ``J = dz/dx`` (units, r) and ``diag(delta sigma'') J`` and the monomials' contractions ``T4[., ., ., x]``, ``T4[., ., x, x]``,
    ``T3[., ., x]``."""
    widths, b_off = parts[4], parts[7]
    n_layers = widths.size
    total = b_off[n_layers] if n_layers > 0 else 0
    widest = 0
    for layer in range(n_layers):
        widest = max(widest, widths[layer])
    m = r if parts[0].shape[0] > 0 else 0
    return (np.empty(3 * total + r * r + 4 * widest), np.empty((total, r)), np.empty((total, r)),
            np.empty(m * m * m + 2 * m * m))


@njit(cache=True)
def scalar_vgh(x, parts, hessian, grad, hess):
    """``phi(x)``; ``grad`` (r,) and, with ``hessian``, ``hess`` (r, r) overwritten with its derivatives."""
    return _vgh(x, parts, 2 if hessian else 1, grad, hess, _workspace(parts, x.size))


@njit(cache=True)
def _vgh(x, parts, mode, grad, hess, work):
    """:func:`scalar_vgh` with a workspace (:func:`_workspace`); ``mode`` 0: the value only (``grad`` is then
    scratch: the network's part of it is not computed), 1: and the gradient, 2: and the Hessian."""
    T3, T4, A, B, widths, has_w, has_u, b_off, w_off, u_off, bias, W, U, output, activation, value0, grad0 = parts
    r = x.size
    hessian = mode == 2
    value = 0.0
    for i in range(r):
        grad[i] = 0.0
    if hessian:
        for i in range(r):
            for j in range(r):
                hess[i, j] = 0.0
    # -- monomials: B3 = T3[x,.,.], B4 = T4[x,x,.,.] (contracted on the last index first, as numpy)
    if T3.shape[0] > 0:
        mono = work[3]
        y4 = mono[0:r * r * r]
        b4 = mono[r * r * r:r * r * r + r * r]
        b3 = mono[r * r * r + r * r:r * r * r + 2 * r * r]
        np.dot(T4.reshape((r * r * r, r)), x, y4)
        np.dot(y4.reshape((r * r, r)), x, b4)
        np.dot(T3.reshape((r * r, r)), x, b3)
        for a in range(r):
            c3, c4 = 0.0, 0.0
            for b in range(r):
                c3 += b3[a * r + b] * x[b]
                c4 += b4[a * r + b] * x[b]
                if hessian:
                    hess[a, b] += 6.0 * b3[a * r + b] + 12.0 * b4[a * r + b]
            value += (c3 + c4) * x[a]
            grad[a] += 3.0 * c3 + 4.0 * c4
    # -- convex powers
    for k in range(A.shape[0]):
        s = 0.0
        for i in range(r):
            s += A[k, i] * x[i]
        value += abs(s) ** 3 / 3.0
        for i in range(r):
            grad[i] += A[k, i] * (abs(s) * s)
        if hessian:
            c = 2.0 * abs(s)
            for i in range(r):
                for j in range(r):
                    hess[i, j] += A[k, i] * c * A[k, j]
    for k in range(B.shape[0]):
        t = 0.0
        for i in range(r):
            t += B[k, i] * x[i]
        value += t ** 4 / 4.0
        for i in range(r):
            grad[i] += B[k, i] * t ** 3
        if hessian:
            c = 3.0 * t * t
            for i in range(r):
                for j in range(r):
                    hess[i, j] += B[k, i] * c * B[k, j]
    # -- the network: forward (values, sigma', sigma'' and, for the Hessian, the rows of J = dz/dx, layer by
    # layer J_l = W_l diag(sigma'_{l-1}) J_{l-1} + U_l), backward (delta = dN/dh; the Hessian J^T diag(delta
    # sigma'') J); all in the workspace
    n_layers = widths.size
    if n_layers > 0:
        flat, J, Jc = work[0], work[1], work[2]
        total = b_off[n_layers]
        widest = 0
        for layer in range(n_layers):
            widest = max(widest, widths[layer])
        hv = flat[0:total]
        ds = flat[total:2 * total]
        dds = flat[2 * total:3 * total]
        e = 3 * total
        net_hess = flat[e:e + r * r].reshape((r, r))
        delta = flat[e + r * r:e + r * r + widest]
        dz = flat[e + r * r + widest:e + r * r + 2 * widest]
        zw = flat[e + r * r + 2 * widest:e + r * r + 3 * widest]
        zu = flat[e + r * r + 3 * widest:e + r * r + 4 * widest]
        for layer in range(n_layers):
            o, w = b_off[layer], widths[layer]
            if hessian:
                if has_w[layer]:
                    p, wp = b_off[layer - 1], widths[layer - 1]
                    for j in range(p, p + wp):                  # diag(sigma') J_{l-1} (Jc is free until the backward pass)
                        for k in range(r):
                            Jc[j, k] = ds[j] * J[j, k]
                    np.dot(W[w_off[layer]:w_off[layer] + w * wp].reshape((w, wp)), Jc[p:p + wp], J[o:o + w])
                else:
                    for i in range(w):
                        for k in range(r):
                            J[o + i, k] = 0.0
                if has_u[layer]:
                    for i in range(w):
                        base = u_off[layer] + i * r
                        for k in range(r):
                            J[o + i, k] += U[base + k]
            if has_w[layer]:
                p, wp = b_off[layer - 1], widths[layer - 1]
                np.dot(W[w_off[layer]:w_off[layer] + w * wp].reshape((w, wp)), hv[p:p + wp], zw[:w])
            if has_u[layer]:
                np.dot(U[u_off[layer]:u_off[layer] + w * r].reshape((w, r)), x, zu[:w])
            for i in range(w):
                z = bias[o + i]
                if has_w[layer]:
                    z += zw[i]
                if has_u[layer]:
                    z += zu[i]
                if activation == 0:
                    t = math.tanh(z)
                    d = 1.0 - t * t
                    hv[o + i], ds[o + i], dds[o + i] = t, d, -2.0 * t * d
                else:
                    s = 0.5 * (1.0 + math.tanh(0.5 * z))
                    hv[o + i] = max(z, 0.0) + math.log1p(math.exp(-abs(z)))
                    ds[o + i], dds[o + i] = s, s * (1.0 - s)
        last = b_off[n_layers - 1]
        net = 0.0
        for i in range(widths[n_layers - 1]):
            net += output[i] * hv[last + i]
        value += net - value0
        for k in range(r):
            value -= grad0[k] * x[k]
            grad[k] -= grad0[k]
        if mode == 0:
            return value
        for i in range(widths[n_layers - 1]):
            delta[i] = output[i]
        for layer in range(n_layers - 1, -1, -1):
            o, w = b_off[layer], widths[layer]
            for i in range(w):
                dz[i] = delta[i] * ds[o + i]
                if hessian:
                    c = delta[i] * dds[o + i]
                    for k in range(r):
                        Jc[o + i, k] = c * J[o + i, k]
            if has_u[layer]:
                for i in range(w):
                    base = u_off[layer] + i * r
                    for k in range(r):
                        grad[k] += U[base + k] * dz[i]
            if has_w[layer]:
                wp = widths[layer - 1]
                for j in range(wp):
                    delta[j] = 0.0
                for i in range(w):
                    base = w_off[layer] + i * wp
                    for j in range(wp):
                        delta[j] += W[base + j] * dz[i]
        if hessian:
            np.dot(J.T, Jc, net_hess)
            for a in range(r):
                for b in range(r):
                    hess[a, b] += net_hess[a, b] if a <= b else net_hess[b, a]
    return value


@njit(cache=True)
def discrete_gradient_step(q, v, a, has_a, force, has_force, force_end, has_force_end, mass, damping, has_damping,
                           stiffness, matrix, h, rtol, max_iterations, accelerations,
                           potential, has_potential, dissipation, has_dissipation):
    """``(q1, v1, a1, iterations, status)`` of one discrete-gradient step (the module docstring); ``matrix`` is
    ``(2/h) M + C + (h/2) K``."""
    r = q.size
    eps_floor = 1e-300
    grad = np.empty(r)
    hess = np.empty((r, r))
    dgrad = np.zeros(r)
    jac = np.zeros((r, r))
    work_u = _workspace(potential, r) if has_potential else (np.empty(0), np.empty((0, r)), np.empty((0, r)), np.empty(0))
    work_f = _workspace(dissipation, r) if has_dissipation else (np.empty(0), np.empty((0, r)), np.empty((0, r)), np.empty(0))
    u0 = _vgh(q, potential, 0, grad, hess, work_u) if has_potential else 0.0
    x = np.empty(r)
    for i in range(r):
        x[i] = v[i] + (0.5 * h * a[i] if has_a else 0.0)
    reference = _norm(v) + (0.5 * h * _norm(a) if has_a else 0.0)
    q1 = np.empty(r)
    qm = np.empty(r)
    delta = np.empty(r)
    point = np.empty(r)
    R = np.empty(r)
    Jt = np.empty((r, r))
    previous = np.inf
    iterations, status = 0, NOT_CONVERGED
    for iteration in range(max_iterations + 1):
        for i in range(r):
            q1[i] = q[i] + h * x[i]
            qm[i] = q[i] + 0.5 * h * x[i]
            delta[i] = q1[i] - q[i]
        for i in range(r):
            total = 0.0
            for j in range(r):
                total += mass[i, j] * (x[j] - v[j])
            R[i] = total / (0.5 * h)
        if has_damping:
            for i in range(r):
                total = 0.0
                for j in range(r):
                    total += damping[i, j] * x[j]
                R[i] += total
        for i in range(r):
            total = 0.0
            for j in range(r):
                total += stiffness[i, j] * qm[j]
            R[i] += total
            if has_force:
                R[i] -= force[i]
            for j in range(r):
                Jt[i, j] = matrix[i, j]
        if has_potential:
            for i in range(r):
                dgrad[i] = 0.0
                for j in range(r):
                    jac[i, j] = 0.0
            for node in range(2):
                s = _NODE0 if node == 0 else _NODE1
                for i in range(r):
                    point[i] = q[i] + s * delta[i]
                _vgh(point, potential, 2, grad, hess, work_u)
                for i in range(r):
                    dgrad[i] += 0.5 * grad[i]
                    for j in range(r):
                        jac[i, j] += (0.5 * s) * hess[i, j]
            dd = _dot(delta, delta)
            if dd > SMALL_STEP * (_dot(q1, q1) + _dot(q, q) + 1.0):
                u1 = _vgh(q1, potential, 0, grad, hess, work_u)
                c = (u1 - u0 - _dot(dgrad, delta)) / dd
                for i in range(r):
                    dgrad[i] += c * delta[i]
            for i in range(r):
                R[i] += dgrad[i]
                for j in range(r):
                    Jt[i, j] += h * jac[i, j]
        if has_dissipation:
            _vgh(x, dissipation, 2, grad, hess, work_f)
            for i in range(r):
                R[i] += grad[i]
                for j in range(r):
                    Jt[i, j] += hess[i, j]
        norm = _norm(R)
        if not math.isfinite(norm):
            iterations, status = iteration, NOT_FINITE
            break
        if iteration == max_iterations:
            iterations = iteration
            break
        if not _lu_solve(Jt, R):
            iterations, status = iteration, SINGULAR
            break
        for i in range(r):
            x[i] -= R[i]
        size = _norm(R)
        if size <= rtol * max(_norm(x), reference, eps_floor) or (iteration >= 2 and size >= 0.5 * previous):
            iterations, status = iteration + 1, 0
            break
        previous = size
    v1 = np.empty(r)
    for i in range(r):
        q1[i] = q[i] + h * x[i]
        v1[i] = 2.0 * x[i] - v[i]
    a1 = np.zeros(r)
    if status == 0 and accelerations:
        rhs = np.empty(r)
        for i in range(r):
            total = 0.0
            for j in range(r):
                total -= stiffness[i, j] * q1[j]
            rhs[i] = total
        if has_damping:
            for i in range(r):
                total = 0.0
                for j in range(r):
                    total += damping[i, j] * v1[j]
                rhs[i] -= total
        if has_potential:
            _vgh(q1, potential, 1, grad, hess, work_u)
            for i in range(r):
                rhs[i] -= grad[i]
        if has_dissipation:
            _vgh(v1, dissipation, 1, grad, hess, work_f)
            for i in range(r):
                rhs[i] -= grad[i]
        if has_force_end:
            for i in range(r):
                rhs[i] += force_end[i]
        Mf = mass.copy()
        if not _lu_solve(Mf, rhs):
            status = SINGULAR
        a1 = rhs
    return q1, v1, a1, iterations, status
