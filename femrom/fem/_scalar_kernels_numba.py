r"""numba kernels of learned scalar functions and of a whole discrete-gradient step (see :class:`femrom.fem.CompiledScalar`).

A scalar function ``phi(x) = T3[x,x,x] + T4[x,x,x,x] + sum |a_k . x|^3 / 3 + sum (b_k . x)^4 / 4
+ N(x) - N(0) - grad N(0) . x`` (any part may be absent) is a tuple of arrays, :attr:`CompiledScalar.parts`;
:func:`scalar_vgh` returns its value and writes its gradient and Hessian, the same formulas as the
numpy reference (:mod:`femrom.inference._networks`), equal to round-off: the symmetric tensors contracted on
their leading indices in sweeps over contiguous slices (``T4[x, x, ., .]`` over the index pairs ``i <= l``
once), the layers' products as BLAS products, ``tanh`` by one
``exp`` (:func:`_tanh`), the network's Hessian forward over reverse, ``J^T diag(delta sigma'') J`` with the layer Jacobians
``J_l = W_l diag(sigma'_{l-1}) J_{l-1} + U_l``, formed only when the Hessian is asked for. A step allocates
its workspaces once (:func:`_workspace`) and evaluates values alone (no gradient, no Jacobian) where only
values are used. :func:`discrete_gradient_step` is one
step of :class:`femrom.integrators.DiscreteGradient` for a model whose nonlinear force is a learned
potential of ``q`` and/or a learned dissipation of ``q'``: the predictor, the Newton iterations on the
midpoint velocity (the two-point Gauss quadrature of the average vector field, Gonzalez's projection,
the update test with the stagnation floor) and the end-of-step acceleration, in one call.
:func:`newmark_sliders_step` and :func:`newmark_sliders_march` are a Newmark-family step (a trajectory) of a
model with learned Jenkins sliders, alone or beside a learned potential (``FusedSlidersStep`` of
:mod:`femrom.integrators._fused`).
:func:`discrete_gradient_march` steps a whole trajectory in one call, by that Newton iteration or by a chord
iteration (one Jacobian a step, values and gradients at the other iterates, a predictor from the extrapolated
learned force) to the same fixed point (:func:`_dg_solve`).

The small linear-algebra helpers are repeated here, not imported, so that numba's on-disk cache
(``cache=True``, per file) cannot go stale when another kernel file changes.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Status codes of :func:`discrete_gradient_step` and :func:`discrete_gradient_march` (0: converged;
#: ``STATE_NOT_FINITE``: a marched step's new ``q`` is not finite).
NOT_CONVERGED, NOT_FINITE, SINGULAR, STATE_NOT_FINITE = 1, 2, 3, 4

#: ``SMALL_STEP`` and the Gauss nodes of :mod:`femrom.integrators.schemes.discrete_gradient`.
SMALL_STEP = 1e-6
_NODE0 = 0.5 - 0.5 / math.sqrt(3.0)
_NODE1 = 0.5 + 0.5 / math.sqrt(3.0)


# _norm and _lu_solve repeat femrom.fem._law_kernels_numba's on purpose: numba's on-disk cache keys a
# compiled function on its own file, so a kernel calling another file's would keep a stale copy of it.
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
    pivots = np.empty(A.shape[0], dtype=np.int64)
    if not _lu_factor(A, pivots):
        return False
    _lu_back(A, pivots, b)
    return True


@njit(cache=True)
def _lu_factor(A, pivots):
    """``A`` (n, n) overwritten by its LU factors with partial pivoting (row ``k`` swapped with ``pivots[k]``);
    False if singular; :func:`_lu_back` solves with them."""
    n = A.shape[0]
    for k in range(n):
        pivot, largest = k, abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > largest:
                pivot, largest = i, abs(A[i, k])
        if largest == 0.0 or not math.isfinite(largest):
            return False
        pivots[k] = pivot
        if pivot != k:
            for j in range(k, n):           # the multipliers left of k stay where they were formed
                A[k, j], A[pivot, j] = A[pivot, j], A[k, j]
        for i in range(k + 1, n):
            factor = A[i, k] / A[k, k]
            A[i, k] = factor
            if factor != 0.0:
                for j in range(k + 1, n):
                    A[i, j] -= factor * A[k, j]
    return True


@njit(cache=True)
def _lu_back(LU, pivots, b):
    """``b`` overwritten by ``A^-1 b`` from :func:`_lu_factor`'s factors (O(n^2))."""
    n = LU.shape[0]
    for k in range(n):
        p = pivots[k]
        if p != k:
            b[k], b[p] = b[p], b[k]
        for i in range(k + 1, n):
            factor = LU[i, k]
            if factor != 0.0:
                b[i] -= factor * b[k]
    for i in range(n - 1, -1, -1):
        total = b[i]
        for j in range(i + 1, n):
            total -= LU[i, j] * b[j]
        b[i] = total / LU[i, i]


@njit(cache=True)
def _tanh(z):
    """``tanh z`` by one ``exp``, ``(1 - e^{-2|z|}) / (1 + e^{-2|z|})`` signed (about half the cost of ``math.tanh``,
    within an ulp or two of it); ``math.tanh`` below ``|z| = 1/4``, where the difference would lose relative
    accuracy."""
    a = abs(z)
    if a < 0.25:
        return math.tanh(z)
    e = math.exp(-2.0 * a)
    t = (1.0 - e) / (1.0 + e)
    return t if z >= 0.0 else -t


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


#: The workspace a caller allocates once for repeated evaluations (a march's steps): :func:`_workspace`.
scalar_workspace = _workspace


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
    # -- monomials: B3 = T3[x,.,.], B4 = T4[x,x,.,.]; the tensors are symmetric (SymmetricPolynomial), so the
    # contractions run on the leading indices: sums of coefficients times the contiguous slices T[i] and
    # T[i, l] (numpy contracts the last index; equal to round-off)
    if T3.shape[0] > 0:
        mono = work[3]
        n3, n2 = r * r * r, r * r
        b4 = mono[n3:n3 + n2]
        b3 = mono[n3 + n2:n3 + 2 * n2]
        F4 = T4.reshape((n2, n2))
        F3 = T3.reshape((r, n2))
        # B4 = sum_{i <= l} (2 - [i = l]) x_i x_l T4[i, l, ., .]: the symmetric pairs once (r (r + 1) / 2 sweeps
        # of length r^2 instead of r^4 + r^3 products)
        for i in range(n2):
            b4[i] = 0.0
        for i in range(r):
            for l in range(i, r):
                c = x[i] * x[l] * (1.0 if l == i else 2.0)
                row = i * r + l
                for j in range(n2):
                    b4[j] += c * F4[row, j]
        c = x[0]
        for i in range(n2):
            b3[i] = c * F3[0, i]
        for l in range(1, r):
            c = x[l]
            for i in range(n2):
                b3[i] += c * F3[l, i]
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
                    t = _tanh(z)
                    d = 1.0 - t * t
                    hv[o + i], ds[o + i], dds[o + i] = t, d, -2.0 * t * d
                else:
                    # softplus log(1 + e^z) = max(z, 0) + log1p(e^-|z|), its derivative the sigmoid, one exp
                    ez = math.exp(-abs(z))
                    s = 1.0 / (1.0 + ez) if z >= 0.0 else ez / (1.0 + ez)
                    hv[o + i] = max(z, 0.0) + math.log1p(ez)
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
def _step_workspace(r, potential, has_potential, dissipation, has_dissipation):
    """The arrays a step works in: the terms' workspaces (:func:`_workspace`) and
    ``(grad, hess, dgrad, jac, q1, qm, delta, point, nonlinear)``."""
    empty = (np.empty(0), np.empty((0, r)), np.empty((0, r)), np.empty(0))
    work_u = _workspace(potential, r) if has_potential else empty
    work_f = _workspace(dissipation, r) if has_dissipation else empty
    vectors = (np.empty(r), np.empty((r, r)), np.zeros(r), np.zeros((r, r)), np.empty(r), np.empty(r), np.empty(r),
               np.empty(r), np.zeros(r))
    return work_u, work_f, vectors


@njit(cache=True)
def _dg_residual(x, q, v, force, has_force, mass, damping, has_damping, stiffness, matrix, h,
                 potential, has_potential, u0, dissipation, has_dissipation, jacobian, R, Jt, work_u, work_f, vectors):
    r"""The discrete-gradient residual at the midpoint velocity ``x = v_m`` (r,) into ``R`` (r,):

    ``R = M (x - v) / (h/2) + C x + K (q + h x / 2) - F + grad_bar U(q, q + h x) + grad F(x)``,

    ``grad_bar U`` by the two Gauss nodes and Gonzalez's projection (above :data:`SMALL_STEP`), ``u0 = U(q)``;
    with ``jacobian``, also ``J = (2/h) M + C + (h/2) K + h int_0^1 s d^2U ds + d^2F(x)`` into ``Jt`` (r, r)
    (the Hessians at the two nodes and at ``x``); without, gradients and values only. The learned terms' part
    ``grad_bar U + grad F(x)`` also goes to ``vectors[8]`` (the chord march's predictor)."""
    r = q.size
    grad, hess, dgrad, jac, q1, qm, delta, point, nonlinear = vectors
    for i in range(r):
        nonlinear[i] = 0.0
    mode = 2 if jacobian else 1
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
        if jacobian:
            for j in range(r):
                Jt[i, j] = matrix[i, j]
    if has_potential:
        for i in range(r):
            dgrad[i] = 0.0
            if jacobian:
                for j in range(r):
                    jac[i, j] = 0.0
        for node in range(2):
            s = _NODE0 if node == 0 else _NODE1
            for i in range(r):
                point[i] = q[i] + s * delta[i]
            _vgh(point, potential, mode, grad, hess, work_u)
            for i in range(r):
                dgrad[i] += 0.5 * grad[i]
                if jacobian:
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
            nonlinear[i] += dgrad[i]
            if jacobian:
                for j in range(r):
                    Jt[i, j] += h * jac[i, j]
    if has_dissipation:
        _vgh(x, dissipation, mode, grad, hess, work_f)
        for i in range(r):
            R[i] += grad[i]
            nonlinear[i] += grad[i]
            if jacobian:
                for j in range(r):
                    Jt[i, j] += hess[i, j]


@njit(cache=True)
def _end_rhs(q1, v1, force_end, has_force_end, damping, has_damping, stiffness, potential, has_potential,
             dissipation, has_dissipation, rhs, work_u, work_f, vectors):
    """``F(t_{k+1}) - C v1 - K q1 - grad U(q1) - grad F(v1)`` into ``rhs``: ``M a_{k+1}``; returns ``U(q1)``
    (0 without a potential)."""
    r = q1.size
    grad, hess = vectors[0], vectors[1]
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
    u1 = 0.0
    if has_potential:
        u1 = _vgh(q1, potential, 1, grad, hess, work_u)
        for i in range(r):
            rhs[i] -= grad[i]
    if has_dissipation:
        _vgh(v1, dissipation, 1, grad, hess, work_f)
        for i in range(r):
            rhs[i] -= grad[i]
    if has_force_end:
        for i in range(r):
            rhs[i] += force_end[i]
    return u1


@njit(cache=True)
def discrete_gradient_step(q, v, a, has_a, force, has_force, force_end, has_force_end, mass, damping, has_damping,
                           stiffness, matrix, h, rtol, max_iterations, accelerations,
                           potential, has_potential, dissipation, has_dissipation):
    """``(q1, v1, a1, iterations, status)`` of one discrete-gradient step (the module docstring); ``matrix`` is
    ``(2/h) M + C + (h/2) K``. Newton with the exact Jacobian at every iterate: the numpy reference's iteration."""
    r = q.size
    eps_floor = 1e-300
    work_u, work_f, vectors = _step_workspace(r, potential, has_potential, dissipation, has_dissipation)
    u0 = _vgh(q, potential, 0, vectors[0], vectors[1], work_u) if has_potential else 0.0
    x = np.empty(r)
    for i in range(r):
        x[i] = v[i] + (0.5 * h * a[i] if has_a else 0.0)
    reference = _norm(v) + (0.5 * h * _norm(a) if has_a else 0.0)
    R = np.empty(r)
    Jt = np.empty((r, r))
    previous = np.inf
    iterations, status = 0, NOT_CONVERGED
    for iteration in range(max_iterations + 1):
        _dg_residual(x, q, v, force, has_force, mass, damping, has_damping, stiffness, matrix, h,
                     potential, has_potential, u0, dissipation, has_dissipation, True, R, Jt, work_u, work_f, vectors)
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
    q1 = np.empty(r)
    v1 = np.empty(r)
    for i in range(r):
        q1[i] = q[i] + h * x[i]
        v1[i] = 2.0 * x[i] - v[i]
    a1 = np.zeros(r)
    if status == 0 and accelerations:
        rhs = np.empty(r)
        _end_rhs(q1, v1, force_end, has_force_end, damping, has_damping, stiffness, potential, has_potential,
                 dissipation, has_dissipation, rhs, work_u, work_f, vectors)
        Mf = mass.copy()
        if not _lu_solve(Mf, rhs):
            status = SINGULAR
        a1 = rhs
    return q1, v1, a1, iterations, status


@njit(cache=True)
def _dg_solve(x, q, v, force, has_force, mass, damping, has_damping, stiffness, matrix, h, rtol, max_iterations,
              reference, chord, refactor_ratio, potential, has_potential, u0, dissipation, has_dissipation,
              LU, pivots, held, R, Jt, work_u, work_f, vectors):
    r"""One step's iteration on ``x = v_m`` (r,), in place from the predictor to the solution of
    :func:`_dg_residual`'s ``R(x) = 0``; returns ``(iterations, jacobians, status, contraction)``.

    ``chord`` False: Newton, ``J(x)`` formed and factorised at every iterate (the reference's iteration,
    :func:`discrete_gradient_step`). ``chord`` True: the simplified Newton ``x <- x - J_*^{-1} R(x)`` with the
    factors ``LU``, ``pivots`` of a Jacobian ``J_*`` formed earlier (held across steps: ``held[0] = 1``;
    formed at the first iterate otherwise), values and gradients only, as long as each update is at most
    ``refactor_ratio`` times the one before; a slower update switches the rest of the step to Newton. Either
    way the step converges on the reference's update test ``||dx|| <= rtol max(||x||, reference)`` (with a
    contraction ``rho <= refactor_ratio`` the chord's remaining error is below ``rho / (1 - rho)`` of that
    update), and Newton's stagnation test applies from its third update on. ``jacobians``: Jacobians formed
    (each the potential's Hessian at the two Gauss nodes and the dissipation's at ``x``); ``contraction``: the
    largest ratio of successive chord updates (0 if fewer than two)."""
    r = x.size
    eps_floor = 1e-300
    newton = not chord
    previous = np.inf
    since = 0
    jacobians = 0
    contraction = 0.0
    for iteration in range(max_iterations + 1):
        form = newton or held[0] == 0
        _dg_residual(x, q, v, force, has_force, mass, damping, has_damping, stiffness, matrix, h,
                     potential, has_potential, u0, dissipation, has_dissipation, form, R, Jt, work_u, work_f, vectors)
        if not math.isfinite(_norm(R)):
            return iteration, jacobians, NOT_FINITE, contraction
        if iteration == max_iterations:
            return iteration, jacobians, NOT_CONVERGED, contraction
        if form:
            for i in range(r):
                for j in range(r):
                    LU[i, j] = Jt[i, j]
            jacobians += 1
            if not _lu_factor(LU, pivots):
                held[0] = 0
                return iteration, jacobians, SINGULAR, contraction
            held[0] = 1
        _lu_back(LU, pivots, R)
        for i in range(r):
            x[i] -= R[i]
        size = _norm(R)
        if not newton and previous < np.inf:
            contraction = max(contraction, size / max(previous, eps_floor))
        if size <= rtol * max(_norm(x), reference, eps_floor):
            return iteration + 1, jacobians, 0, contraction
        if newton:
            if since >= 2 and size >= 0.5 * previous:
                return iteration + 1, jacobians, 0, contraction
            since += 1
        elif size > refactor_ratio * previous:
            newton, since = True, 0
        previous = size
    return max_iterations, jacobians, NOT_CONVERGED, contraction


#: The chord march's predictor: the weights of the polynomial extrapolation of the learned terms' force from the
#: last 1, 2, 3, 4 steps (orders 0 to 3).
_EXTRAPOLATION = ((1.0, 0.0, 0.0, 0.0), (2.0, -1.0, 0.0, 0.0), (3.0, -3.0, 1.0, 0.0), (4.0, -6.0, 4.0, -1.0))


@njit(cache=True)
def discrete_gradient_march(forces, has_force, forces_end, mass, damping, has_damping, stiffness, matrix, h, rtol,
                            max_iterations, accelerations, refactor_ratio, hold_updates, order,
                            potential, has_potential, dissipation, has_dissipation, Q, V, A, iterations, jacobians):
    r"""``n`` discrete-gradient steps in one call: row ``k + 1`` of ``Q``, ``V``, ``A`` (n + 1, r) from row ``k``
    (row 0 given), the forcing of step ``k`` at its input time ``t_k + h/2`` in ``forces[k]`` (n, r) and on the
    grid at ``t_{k+1}`` in ``forces_end[k]`` (n, r) (the end acceleration ``M a_{k+1} = F(t_{k+1}) - C v_{k+1}
    - K q_{k+1} - grad U(q_{k+1}) - grad F(v_{k+1})``, ``M`` factorised once, its potential value the next
    step's ``U(q_k)``; ``A`` rows NaN without ``accelerations``).

    Each step solves :func:`_dg_residual`'s ``R(v_m) = 0`` by :func:`_dg_solve`. ``refactor_ratio = 0``:
    Newton from the reference's predictor ``v_k + h a_k / 2``, the reference's iteration
    (:func:`discrete_gradient_step`) step for step. Otherwise the chord iteration, its Jacobian held into the
    next step when the step converged in at most ``hold_updates`` updates (else formed anew at the next
    step's first iterate; ``hold_updates = 0``: once a step), from the predictor

    ``((2/h) M + C + (h/2) K) x = (2/h) M v_k - K q_k + F_{k+1/2} - g^``,

    the linear part exact and the learned terms' force ``g = grad_bar U + grad F(v_m)`` extrapolated by a
    polynomial of degree ``min(order, steps so far - 1)`` through its values ``g_{k-1}, g_{k-2}, ...`` at the
    previous steps' last iterates (the reference's predictor at the first step). A chord step that fails (no
    convergence in ``max_iterations``, a non-finite residual) is redone by Newton from the reference's
    predictor, whose status is the step's. ``iterations``, ``jacobians`` (n,) int: per step, updates and
    Jacobians formed.

    Returns ``(step, status)``: ``(n, 0)``, or the failing step's index and status (``STATE_NOT_FINITE``: its
    new ``q`` is not finite)."""
    n, r = forces.shape[0], Q.shape[1]
    chord = refactor_ratio > 0.0
    work_u, work_f, vectors = _step_workspace(r, potential, has_potential, dissipation, has_dissipation)
    nonlinear = vectors[8]
    R = np.empty(r)
    Jt = np.empty((r, r))
    LU = np.empty((r, r))
    pivots = np.zeros(r, dtype=np.int64)
    held = np.zeros(1, dtype=np.int64)
    mass_lu = mass.copy()
    mass_pivots = np.zeros(r, dtype=np.int64)
    if accelerations and not _lu_factor(mass_lu, mass_pivots):
        return 0, SINGULAR
    linear_lu = matrix.copy()
    linear_pivots = np.zeros(r, dtype=np.int64)
    if chord and not _lu_factor(linear_lu, linear_pivots):
        chord = False
    x = np.empty(r)
    past = np.zeros((4, r))
    stored = 0
    # the states in their own arrays (BLAS's rounding may depend on where a vector starts: the step's is the
    # per-step kernel's)
    q, v, a, q1, v1 = np.empty(r), np.empty(r), np.empty(r), np.empty(r), np.empty(r)
    q1[:] = Q[0]
    v1[:] = V[0]
    u0 = _vgh(q1, potential, 0, vectors[0], vectors[1], work_u) if has_potential else 0.0
    for k in range(n):
        q[:] = Q[k]
        v[:] = V[k]
        a[:] = A[k]
        has_a = accelerations or k == 0
        if not accelerations and has_potential:
            u0 = _vgh(q, potential, 0, vectors[0], vectors[1], work_u)
        reference = _norm(v) + (0.5 * h * _norm(a) if has_a else 0.0)
        if chord and stored > 0:
            weights = _EXTRAPOLATION[min(order, stored - 1)]
            for i in range(r):
                total = forces[k, i] if has_force else 0.0
                for j in range(r):
                    total += mass[i, j] * v[j] / (0.5 * h) - stiffness[i, j] * q[j]
                for j in range(4):
                    total -= weights[j] * past[j, i]
                x[i] = total
            _lu_back(linear_lu, linear_pivots, x)
        else:
            for i in range(r):
                x[i] = v[i] + (0.5 * h * a[i] if has_a else 0.0)
        its, jacs, status, contraction = _dg_solve(
            x, q, v, forces[k], has_force, mass, damping, has_damping, stiffness, matrix, h, rtol, max_iterations,
            reference, chord, refactor_ratio, potential, has_potential, u0, dissipation, has_dissipation, LU,
            pivots, held, R, Jt, work_u, work_f, vectors)
        if status != 0 and chord:
            for i in range(r):
                x[i] = v[i] + (0.5 * h * a[i] if has_a else 0.0)
            more, more_jacs, status, contraction = _dg_solve(
                x, q, v, forces[k], has_force, mass, damping, has_damping, stiffness, matrix, h, rtol,
                max_iterations, reference, False, refactor_ratio, potential, has_potential, u0, dissipation,
                has_dissipation, LU, pivots, held, R, Jt, work_u, work_f, vectors)
            its, jacs = its + more, jacs + more_jacs
        iterations[k], jacobians[k] = its, jacs
        if status != 0:
            return k, status
        if its > hold_updates:
            held[0] = 0
        finite = True
        for i in range(r):
            q1[i] = q[i] + h * x[i]
            v1[i] = 2.0 * x[i] - v[i]
            Q[k + 1, i], V[k + 1, i] = q1[i], v1[i]
            finite = finite and math.isfinite(q1[i])
        if not finite:
            return k, STATE_NOT_FINITE
        if accelerations:
            u0 = _end_rhs(q1, v1, forces_end[k], has_force, damping, has_damping, stiffness, potential,
                          has_potential, dissipation, has_dissipation, a, work_u, work_f, vectors)
            _lu_back(mass_lu, mass_pivots, a)
            A[k + 1] = a
        else:
            for i in range(r):
                A[k + 1, i] = np.nan
        for i in range(r):
            past[3, i], past[2, i], past[1, i], past[0, i] = past[2, i], past[1, i], past[0, i], nonlinear[i]
        stored += 1
    return n, 0


# -- a Newmark-family step of learned sliders, alone or beside a learned potential ------------------------------
# _matvec and _newmark_predict repeat femrom.fem._law_kernels_numba's (numba's per-file cache).
@njit(cache=True)
def _matvec(A, x, out):
    for i in range(A.shape[0]):
        total = 0.0
        for j in range(A.shape[1]):
            total += A[i, j] * x[j]
        out[i] = total
    return out


@njit(cache=True)
def _newmark_predict(q, v, a, force, has_force, mass, damping, has_damping, stiffness, h, beta, gamma, alpha_m,
                     alpha_f):
    """``(q_pred, v_pred, q_bal, b)``: the Newmark-family predictors, the balance point's displacement before
    the new acceleration's part, and the linear right-hand side ``force - K q_bal - C v_bal - alpha_m M a``."""
    r = q.size
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
    return q_pred, v_pred, q_bal, b


@njit(cache=True)
def _sliders_force(direction, thresholds, weights, stretch, coordinate, q):
    """``(x, sum_i k_i e_i, sum of the stuck sliders' k_i)`` at ``q``: the return map
    ``e_i = clip(e_i^0 + (x - x^0), -phi_i, phi_i)``, ``x = a . q``, stuck where ``|trial| < phi_i``."""
    x = 0.0
    for j in range(q.size):
        x += direction[j] * q[j]
    total = 0.0
    stuck = 0.0
    for i in range(thresholds.size):
        trial = stretch[i] + (x - coordinate)
        phi = thresholds[i]
        e = min(max(trial, -phi), phi)
        total += weights[i] * e
        if abs(trial) < phi:
            stuck += weights[i]
    return x, total, stuck


@njit(cache=True)
def newmark_sliders_step(q, v, a, force, has_force, mass, damping, has_damping, stiffness, S,
                         h, beta, gamma, alpha_m, alpha_f, c_q, w, rtol, atol, max_iterations,
                         direction, thresholds, weights, stretch, coordinate, potential, work):
    """One Newmark-family step of a model whose nonlinear force is learned Jenkins sliders along ``a``
    (:class:`femrom.inference.LearnedHysteresis`: ``a sum_i k_i e_i``, tangent ``(sum of the stuck k_i) a a^T``)
    and, unless ``potential`` is ``None``, a learned potential's gradient ``grad U(q)`` (tangent its Hessian;
    ``potential``: :attr:`femrom.fem.CompiledScalar.parts`, ``work`` its :func:`_workspace`; SpML with sliders).
    ``None`` (for both) is a type of its own to numba: the sliders alone compile without the potential's code
    and pay nothing for it. State: the stretches ``e`` (p,)
    and the coordinate ``x^0``. What ``NewmarkFamily.step`` does with the dense Newton of ``ImplicitSolve``, in
    the same order of operations (as ``newmark_joint_step`` of the law kernels for a joint): the predictors,
    Newton on the new acceleration with the residual test ``|R| <= atol + rtol (|S x| + |b| + w |f|)`` and the
    update test ``|dx| <= 4 eps |x|``, LU with partial pivoting, and the sliders' commit at the new ``q``.

    Returns ``(q1, v1, a1, stretch1, coordinate1, iterations, status, residual, tolerance)``.
    """
    r = q.size
    return _sliders_step(q, v, a, force, has_force, mass, damping, has_damping, stiffness, S,
                         h, beta, gamma, alpha_m, alpha_f, c_q, w, rtol, atol, max_iterations,
                         direction, thresholds, weights, stretch, coordinate, potential,
                         np.zeros(r), np.zeros((r, r)), work)


@njit(cache=True, inline="always")
def _sliders_step(q, v, a, force, has_force, mass, damping, has_damping, stiffness, S,
                  h, beta, gamma, alpha_m, alpha_f, c_q, w, rtol, atol, max_iterations,
                  direction, thresholds, weights, stretch, coordinate, potential, grad, hess, work):
    """:func:`newmark_sliders_step` in the potential's arrays ``grad`` (r,), ``hess`` (r, r) (zero without a
    potential) and workspace ``work`` (:func:`_workspace`), allocated once by a march."""
    r = q.size
    q_pred, v_pred, q_bal, b = _newmark_predict(q, v, a, force, has_force, mass, damping, has_damping, stiffness,
                                                h, beta, gamma, alpha_m, alpha_f)
    norm_b = _norm(b)
    x = a.copy()
    f = np.empty(r)
    Sx = np.empty(r)
    R = np.empty(r)
    J = np.empty((r, r))
    at = np.empty(r)
    eps = np.finfo(np.float64).eps
    c = w * c_q
    iterations = -1
    norm = tolerance = np.nan
    for iteration in range(max_iterations + 1):
        for i in range(r):
            at[i] = q_bal[i] + c_q * x[i]
        _, total, stuck = _sliders_force(direction, thresholds, weights, stretch, coordinate, at)
        if potential is not None:
            _vgh(at, potential, 2, grad, hess, work)
        for i in range(r):
            f[i] = grad[i] + direction[i] * total
        _matvec(S, x, Sx)
        scale = _norm(Sx) + norm_b + w * _norm(f)
        for i in range(r):
            R[i] = Sx[i] - b[i] + w * f[i]
        norm = _norm(R)
        if not math.isfinite(norm):
            return q_pred, v_pred, x, stretch.copy(), coordinate, iteration, NOT_FINITE, norm, tolerance
        tolerance = atol + rtol * scale
        if norm <= tolerance:
            iterations = iteration
            break
        if iteration == max_iterations:
            return q_pred, v_pred, x, stretch.copy(), coordinate, iteration, NOT_CONVERGED, norm, tolerance
        for i in range(r):
            for j in range(r):
                J[i, j] = S[i, j] + c * (hess[i, j] + stuck * (direction[i] * direction[j]))
        if not _lu_solve(J, R):
            return q_pred, v_pred, x, stretch.copy(), coordinate, iteration, SINGULAR, norm, tolerance
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
    x1 = 0.0
    for j in range(r):
        x1 += direction[j] * q1[j]
    stretch1 = np.empty(thresholds.size)
    for i in range(thresholds.size):
        phi = thresholds[i]
        stretch1[i] = min(max(stretch[i] + (x1 - coordinate), -phi), phi)
    return q1, v1, x, stretch1, x1, iterations, 0, norm, tolerance


@njit(cache=True)
def newmark_sliders_march(q, v, a, forces, has_force, mass, damping, has_damping, stiffness, S,
                          h, beta, gamma, alpha_m, alpha_f, c_q, w, rtol, atol, max_iterations,
                          direction, thresholds, weights, stretch, coordinate, potential, work, Q, V, A):
    """``n`` steps of :func:`newmark_sliders_step` from ``(q, v, a)``, the forcing of step ``k`` in
    ``forces[:, k]``, the states in the columns ``1 .. n`` of ``Q``, ``V``, ``A`` (r, n + 1).

    Returns ``(stretch, coordinate, step, iterations, status, residual, tolerance)``: a step that fails stops
    the march with its status and index (``STATE_NOT_FINITE``: its new ``q`` is not finite); else ``step``
    is ``n``."""
    n = Q.shape[1] - 1
    r = q.size
    iterations = 0
    qk, vk, ak, ek, xk = q.copy(), v.copy(), a.copy(), stretch.copy(), coordinate
    grad, hess = np.zeros(r), np.zeros((r, r))
    for k in range(n):
        qk, vk, ak, ek, xk, its, status, norm, tolerance = _sliders_step(
            qk, vk, ak, forces[:, k].copy(), has_force, mass, damping, has_damping, stiffness, S,
            h, beta, gamma, alpha_m, alpha_f, c_q, w, rtol, atol, max_iterations,
            direction, thresholds, weights, ek, xk, potential, grad, hess, work)
        if status != 0:
            return ek, xk, k, iterations, status, norm, tolerance
        finite = True
        for i in range(qk.size):
            Q[i, k + 1], V[i, k + 1], A[i, k + 1] = qk[i], vk[i], ak[i]
            finite = finite and math.isfinite(qk[i])
        iterations += its
        if not finite:
            return ek, xk, k, iterations, STATE_NOT_FINITE, norm, tolerance
    return ek, xk, n, iterations, 0, np.nan, np.nan
