r"""numba kernels of the slider laws' return map (see :mod:`femrom.fem._law_kernels`).

Every slider ``m`` of point ``i`` is an isotropic 2-D Jenkins element: trial traction
``t^tr = k_m (g_t - z_m)``, returned radially onto ``|t| <= tau`` (:func:`femrom.fem.radial_return`,
written here for one slider with the same comparisons, so a NaN or a zero limit takes the
same branch), and its consistent tangent ``k_m I`` in stick, ``k_m ratio (I - d d^T)`` in
slip. Two families:

- parallel sliders (``iwan``, ``jenkins``): limit ``f_m``, normal ``t_n = k_n g_n``;
- clamped Iwan: limit ``tau_s f_m`` where the preload closed the point (``c > 0.5``), zero
  (every slider slipping, no traction) where it is open; normal ``c k_n g_n``.

Arrays are float64 and C-contiguous (the callers make them so): ``gap`` (s, 3), ``state``
(s, N, 2) or (s, N + 1, 2) for the clamped law. The callers check the shapes; these
kernels do not.

The joint kernels (``joint_*``) evaluate a projected joint
(:class:`femrom.fem.CompiledJoint`) pair by pair into preallocated arrays, and
:func:`newmark_joint_step` is a whole Newmark-family step of a small model with one, Newton
and commit included (its Python side is ``FusedJointStep`` in :mod:`femrom.integrators._fused`; the
learned sliders' step, which may carry a learned potential, is in :mod:`femrom.fem._scalar_kernels_numba`).
:func:`newmark_joint_batch_march` steps ``B`` runs of one such model together, each step of each
run a :func:`newmark_joint_step` (``FusedJointStep.march_batch``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from femrom.fem._law_kinds import CLAMPED_IWAN


@njit(cache=True, inline="always")
def _radial(trial0, trial1, limit):
    """``(ratio, safe, slipping)`` of one slider: :func:`femrom.fem.radial_return` for a single point, the
    slip direction being ``trial / safe``.

    ``hypot`` as numpy's, not ``sqrt(a^2 + b^2)``: a slider committed in slip sits on ``|t^tr| = limit``
    to round-off, and an ulp of difference in the norm would flip its tangent between stick and slip.
    """
    norm = math.hypot(trial0, trial1)
    slipping = (norm > limit) or (limit <= 0.0)
    safe = norm if norm > 0.0 else 1.0
    ratio = limit / safe if slipping else 1.0
    return ratio, safe, slipping


_NO_RATIOS = np.zeros((1, 1))     # what the law kernels pass when they keep no ratios
CLAMPED = CLAMPED_IWAN          # a law's ``kind`` in the joint kernels below (else parallel sliders)


@njit(cache=True, inline="always")
def _parallel_point(i, g0, g1, g2, state, stiffness, strength, normal_stiffness, tangent, ratios, keep):
    """``(t0, t1, t2, d00, d01, d11, d22)`` of point ``i`` of parallel sliders (tangent entries 0 without it);
    with ``keep``, the sliders' return ratios go to ``ratios[i]``."""
    t0 = t1 = 0.0
    d00 = d01 = d11 = 0.0
    for m in range(state.shape[1]):
        k = stiffness[m]
        trial0, trial1 = k * (g0 - state[i, m, 0]), k * (g1 - state[i, m, 1])
        ratio, safe, slipping = _radial(trial0, trial1, strength[m])
        if keep:
            ratios[i, m] = ratio
        t0 += ratio * trial0
        t1 += ratio * trial1
        if tangent:
            if slipping:
                e0, e1 = trial0 / safe, trial1 / safe
                d00 += k * (ratio * (1.0 - e0 * e0))
                d01 += k * (ratio * (0.0 - e0 * e1))
                d11 += k * (ratio * (1.0 - e1 * e1))
            else:
                d00 += k
                d11 += k
    return t0, t1, normal_stiffness * g2, d00, d01, d11, (normal_stiffness if tangent else 0.0)


@njit(cache=True, inline="always")
def _clamped_point(i, g0, g1, g2, state, stiffness, unit_strength, normal_stiffness, tangent, ratios, keep):
    """``(t0, t1, t2, d00, d01, d11, d22)`` of point ``i`` of the clamped Iwan law (``ratios``, ``keep``: as
    :func:`_parallel_point`)."""
    n = state.shape[1] - 1
    closed = state[i, n, 1] > 0.5
    slip_traction = state[i, n, 0]
    t0 = t1 = 0.0
    diagonal = w00 = w01 = w11 = 0.0
    for m in range(n):
        k = stiffness[m]
        trial0, trial1 = k * (g0 - state[i, m, 0]), k * (g1 - state[i, m, 1])
        limit = slip_traction * unit_strength[m] if closed else 0.0
        ratio, safe, slipping = _radial(trial0, trial1, limit)
        if keep:
            ratios[i, m] = ratio
        t0 += ratio * trial0
        t1 += ratio * trial1
        if tangent:
            diagonal += ratio * k
            if slipping:
                e0, e1 = trial0 / safe, trial1 / safe
                weight = ratio * k
                w00 += weight * e0 * e0
                w01 += weight * e0 * e1
                w11 += weight * e1 * e1
    t2 = normal_stiffness * g2 if closed else 0.0
    d22 = normal_stiffness if (tangent and closed) else 0.0
    return t0, t1, t2, diagonal - w00, -w01, diagonal - w11, d22


@njit(cache=True)
def parallel_sliders(gap, state, stiffness, strength, normal_stiffness, tangent):
    """``(traction (s, 3), D (s, 3, 3))`` of parallel sliders; ``D`` is (0, 3, 3) without ``tangent``."""
    s = state.shape[0]
    traction = np.zeros((s, 3))
    D = np.zeros((s if tangent else 0, 3, 3))
    for i in range(s):
        t0, t1, t2, d00, d01, d11, d22 = _parallel_point(i, gap[i, 0], gap[i, 1], gap[i, 2], state, stiffness,
                                                         strength, normal_stiffness, tangent, _NO_RATIOS, False)
        traction[i, 0], traction[i, 1], traction[i, 2] = t0, t1, t2
        if tangent:
            D[i, 0, 0], D[i, 0, 1], D[i, 1, 0], D[i, 1, 1] = d00, d01, d01, d11
            D[i, 2, 2] = d22
    return traction, D


@njit(cache=True)
def parallel_sliders_commit(gap, state, stiffness, strength):
    """(s, N, 2) slider positions after a converged step: ``z_m = g_t - t_m / k_m``."""
    s, n = state.shape[0], state.shape[1]
    new = np.empty((s, n, 2))
    for i in range(s):
        g0, g1 = gap[i, 0], gap[i, 1]
        for m in range(n):
            k = stiffness[m]
            trial0, trial1 = k * (g0 - state[i, m, 0]), k * (g1 - state[i, m, 1])
            ratio, _, _ = _radial(trial0, trial1, strength[m])
            new[i, m, 0] = g0 - ratio * trial0 / k
            new[i, m, 1] = g1 - ratio * trial1 / k
    return new


@njit(cache=True)
def clamped_iwan(gap, state, stiffness, unit_strength, normal_stiffness, tangent):
    """``(traction (s, 3), D (s, 3, 3))`` of the clamped Iwan law; ``D`` is (0, 3, 3) without ``tangent``."""
    s = state.shape[0]
    traction = np.zeros((s, 3))
    D = np.zeros((s if tangent else 0, 3, 3))
    for i in range(s):
        t0, t1, t2, d00, d01, d11, d22 = _clamped_point(i, gap[i, 0], gap[i, 1], gap[i, 2], state, stiffness,
                                                        unit_strength, normal_stiffness, tangent, _NO_RATIOS, False)
        traction[i, 0], traction[i, 1], traction[i, 2] = t0, t1, t2
        if tangent:
            D[i, 0, 0], D[i, 0, 1], D[i, 1, 0], D[i, 1, 1] = d00, d01, d01, d11
            D[i, 2, 2] = d22
    return traction, D


@njit(cache=True)
def clamped_iwan_commit(gap, state, stiffness, unit_strength):
    """(s, N + 1, 2) state after a converged step: sliders ``z_m = g_t - t_m / k_m``, row ``N`` kept."""
    s, n = state.shape[0], state.shape[1] - 1
    new = state.copy()
    for i in range(s):
        closed = state[i, n, 1] > 0.5
        slip_traction = state[i, n, 0]
        g0, g1 = gap[i, 0], gap[i, 1]
        for m in range(n):
            k = stiffness[m]
            trial0, trial1 = k * (g0 - state[i, m, 0]), k * (g1 - state[i, m, 1])
            limit = slip_traction * unit_strength[m] if closed else 0.0
            ratio, _, _ = _radial(trial0, trial1, limit)
            new[i, m, 0] = g0 - ratio * trial0 / k
            new[i, m, 1] = g1 - ratio * trial1 / k
    return new


# -- a projected joint: gaps from k coordinates, the law on every pair, force and tangent back --------------

@njit(cache=True)
def joint_gaps(W, local_offset, gap_offset, q, gap):
    """Fill ``gap`` (s, 3) with ``(W q + local_offset).reshape(s, 3) + gap_offset``, as
    :meth:`femrom.fem.TransformedForce.local_force_and_blocks` forms it (``W`` (3 s, k))."""
    k = W.shape[1]
    for i in range(gap.shape[0]):
        for c in range(3):
            row = 3 * i + c
            x = 0.0
            for j in range(k):
                x += W[row, j] * q[j]
            gap[i, c] = (x + local_offset[row]) + gap_offset[i, c]


@njit(cache=True)
def joint_law(kind, gap, state, stiffness, strength, normal_stiffness, areas, g, D, ratios):
    """Fill ``g`` (3 s,) with the pairs' forces ``A_i t_i``, ``D`` (s, 3, 3) with ``A_i dt_i/dDelta_i`` and
    ``ratios`` (s, N) with the sliders' return ratios (what :func:`joint_commit_ratios` commits with)."""
    for i in range(gap.shape[0]):
        if kind == CLAMPED:
            t0, t1, t2, d00, d01, d11, d22 = _clamped_point(i, gap[i, 0], gap[i, 1], gap[i, 2], state, stiffness,
                                                            strength, normal_stiffness, True, ratios, True)
        else:
            t0, t1, t2, d00, d01, d11, d22 = _parallel_point(i, gap[i, 0], gap[i, 1], gap[i, 2], state, stiffness,
                                                             strength, normal_stiffness, True, ratios, True)
        area = areas[i]
        g[3 * i], g[3 * i + 1], g[3 * i + 2] = area * t0, area * t1, area * t2
        D[i, 0, 0], D[i, 0, 1], D[i, 0, 2] = area * d00, area * d01, 0.0
        D[i, 1, 0], D[i, 1, 1], D[i, 1, 2] = area * d01, area * d11, 0.0
        D[i, 2, 0], D[i, 2, 1], D[i, 2, 2] = 0.0, 0.0, area * d22


@njit(cache=True)
def joint_project_force(W, g, f):
    """``f = W^T g`` (k,)."""
    k = W.shape[1]
    for j in range(k):
        f[j] = 0.0
    for row in range(W.shape[0]):
        x = g[row]
        for j in range(k):
            f[j] += W[row, j] * x
    return f


@njit(cache=True)
def joint_project_tangent(W, D, P, work):
    """``P = W^T blockdiag(D_i) W`` (k, k) for symmetric blocks ``D_i`` (s, 3, 3); ``work`` (3, k)."""
    k = W.shape[1]
    for a in range(k):
        for b in range(k):
            P[a, b] = 0.0
    for i in range(D.shape[0]):
        for c in range(3):
            for b in range(k):
                work[c, b] = D[i, c, 0] * W[3 * i, b] + D[i, c, 1] * W[3 * i + 1, b] + D[i, c, 2] * W[3 * i + 2, b]
        for a in range(k):
            w0, w1, w2 = W[3 * i, a], W[3 * i + 1, a], W[3 * i + 2, a]
            for b in range(a, k):
                P[a, b] += w0 * work[0, b] + w1 * work[1, b] + w2 * work[2, b]
    for a in range(k):
        for b in range(a):
            P[a, b] = P[b, a]
    return P


@njit(cache=True)
def joint_commit_ratios(gap, state, stiffness, ratios):
    """The committed state at ``gap`` from the return ratios :func:`joint_law` kept at that same ``gap``:
    ``z_m = g_t - ratio_m t^tr_m / k_m`` for the ``ratios.shape[1]`` sliders (a clamped law's last row
    kept), the commit kernels' arithmetic without a second return map."""
    s, n = ratios.shape[0], ratios.shape[1]
    new = state.copy()
    for i in range(s):
        g0, g1 = gap[i, 0], gap[i, 1]
        for m in range(n):
            k = stiffness[m]
            trial0, trial1 = k * (g0 - state[i, m, 0]), k * (g1 - state[i, m, 1])
            ratio = ratios[i, m]
            new[i, m, 0] = g0 - ratio * trial0 / k
            new[i, m, 1] = g1 - ratio * trial1 / k
    return new


@njit(cache=True)
def joint_commit(kind, gap, state, stiffness, strength):
    """The law's committed state at ``gap`` (:func:`clamped_iwan_commit` or :func:`parallel_sliders_commit`)."""
    if kind == CLAMPED:
        return clamped_iwan_commit(gap, state, stiffness, strength)
    return parallel_sliders_commit(gap, state, stiffness, strength)


# -- a whole Newmark-family step of a small model with a projected joint --------------------------------------
# It lives here, not with the integrators, because numba's on-disk cache keys a compiled function on
# its own file only: a step compiled elsewhere would keep calling stale copies of the kernels above
# after they change. Its Python side is femrom.integrators' FusedJointStep.

#: ``status`` of :func:`newmark_joint_step`.
CONVERGED, NOT_CONVERGED, NOT_FINITE, SINGULAR, STATE_NOT_FINITE = 0, 1, 2, 3, 4


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
def newmark_joint_step(q, v, a, force, has_force, mass, damping, has_damping, stiffness, S,
                       h, beta, gamma, alpha_m, alpha_f, c_q, w, rtol, atol, max_iterations,
                       kind, W, local_offset, gap_offset, areas, slider_stiffness, strength, normal_stiffness,
                       state):
    """One step from ``(q, v, a)`` with the joint's ``state`` frozen in Newton and committed after.

    What ``NewmarkFamily.step`` does with the dense Newton of ``ImplicitSolve`` on a projected
    joint (:mod:`femrom.integrators`), in the same order of operations: the predictors, the
    linear right-hand side ``force - K q_bal - C v_bal - alpha_m M a``, Newton on the new
    acceleration from ``a`` (gaps ``W q + x_0``, the law on every pair and slider, ``W^T g``,
    the residual test ``|R| <= atol + rtol (|S x| + |b| + w |f|)``, ``S + w c_q W^T D W``
    solved by LU with partial pivoting, the update test ``|dx| <= 4 eps |x|``), the new ``q``
    and ``v``, and the commit of the sliders at the new ``q``.

    Returns ``(q1, v1, a1, state1, iterations, status, residual, tolerance)``; ``status`` is
    :data:`CONVERGED` or why not (then ``residual`` and ``tolerance`` are the last test's).
    """
    r = q.size
    s = areas.size
    q_pred, v_pred, q_bal, b = _newmark_predict(q, v, a, force, has_force, mass, damping, has_damping, stiffness,
                                                h, beta, gamma, alpha_m, alpha_f)
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
    ratios = np.empty((s, slider_stiffness.size))
    at = np.empty(r)
    evaluated = False                     # whether gap and ratios are those of the final x
    eps = np.finfo(np.float64).eps
    c = w * c_q
    iterations = -1
    norm = tolerance = np.nan
    for iteration in range(max_iterations + 1):
        for i in range(r):
            at[i] = q_bal[i] + c_q * x[i]
        joint_gaps(W, local_offset, gap_offset, at, gap)
        joint_law(kind, gap, state, slider_stiffness, strength, normal_stiffness, areas, g, D, ratios)
        joint_project_force(W, g, f)
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
            evaluated = True
            break
        if iteration == max_iterations:
            return q_pred, v_pred, x, state.copy(), iteration, NOT_CONVERGED, norm, tolerance
        joint_project_tangent(W, D, P, rows)
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
    if evaluated:                         # the last evaluation's gaps are q1's when q1 is that iterate, bit for bit
        for i in range(r):
            if q1[i] != at[i]:
                evaluated = False
    if evaluated:
        state1 = joint_commit_ratios(gap, state, slider_stiffness, ratios)
    else:
        joint_gaps(W, local_offset, gap_offset, q1, gap)
        state1 = joint_commit(kind, gap, state, slider_stiffness, strength)
    return q1, v1, x, state1, iterations, CONVERGED, norm, tolerance


@njit(cache=True)
def newmark_joint_batch_march(Q, V, A, forces, has_force, mass, damping, has_damping, stiffness, S,
                              h, beta, gamma, alpha_m, alpha_f, c_q, w, rtol, atol, max_iterations,
                              kind, W, local_offset, gap_offset, areas, slider_stiffness, strength, normal_stiffness,
                              states, iterations, status, failed, norms, tolerances):
    """``n`` steps of ``B`` independent runs of one model with a projected joint, all runs at every step.

    ``Q, V, A`` (n + 1, B, r): row 0 holds each run's start, rows ``1..n`` are filled; ``forces``
    (n, B, r) the forcing of step ``k`` of run ``b`` at ``forces[k, b]`` (ignored without ``has_force``);
    ``states`` (B, s, N, 2) (or N + 1 for the clamped law) each run's committed state, updated in place.
    Every step of every run is :func:`newmark_joint_step`'s, with that run's own Newton (its own
    iterations and tests). ``iterations`` (n, B) gets each step's Newton iterations; a run that fails
    stops there (``status[b]`` why, ``failed[b]`` the 0-based step, ``norms``/``tolerances`` its last
    test; a non-finite new ``q`` is :data:`STATE_NOT_FINITE`) while the others go on. ``status`` must
    come in as :data:`CONVERGED` for the runs to step (a run already failed is skipped)."""
    n, B, r = forces.shape[0], Q.shape[1], Q.shape[2]
    no_force = np.zeros(r)
    for k in range(n):
        for b in range(B):
            if status[b] != CONVERGED:
                continue
            force = forces[k, b] if has_force else no_force
            q1, v1, a1, state1, its, code, norm, tolerance = newmark_joint_step(
                Q[k, b], V[k, b], A[k, b], force, has_force, mass, damping, has_damping, stiffness, S,
                h, beta, gamma, alpha_m, alpha_f, c_q, w, rtol, atol, max_iterations,
                kind, W, local_offset, gap_offset, areas, slider_stiffness, strength, normal_stiffness, states[b])
            iterations[k, b] = its
            if code != CONVERGED:
                status[b], failed[b], norms[b], tolerances[b] = code, k, norm, tolerance
                continue
            finite = True
            for i in range(r):
                if not math.isfinite(q1[i]):
                    finite = False
            if not finite:
                status[b], failed[b] = STATE_NOT_FINITE, k
                continue
            Q[k + 1, b] = q1
            V[k + 1, b] = v1
            A[k + 1, b] = a1
            states[b] = state1
