"""Newmark average acceleration for reduced models."""

import numpy as np

from femrom.rom._schemes import ReducedScheme, newton_solve, register_reduced_scheme, solve_matrix


@register_reduced_scheme
class NewmarkScheme(ReducedScheme):
    r"""Average acceleration (``beta = 1/4, gamma = 1/2``), state ``[q; v; a]``.

    ``S a_{k+1} = F_{k+1} - C v^* - K q^*`` with the predictors ``q^* = q + h v +
    h^2 a / 4``, ``v^* = v + h a / 2`` and ``S = M + h C / 2 + h^2 K / 4``.
    Second order; conserves ``v^T M v / 2 + q^T K q / 2`` exactly for ``C =
    0, F = 0`` (Hairer, Lubich & Wanner, Geometric Numerical Integration, IV.2).
    """

    name = "newmark"
    input_time = "end"
    carries_acceleration = True

    def step_map(self, parts, dt, forcing):
        M, C, K = parts.mass, parts.damping_matrix, parts.stiffness
        r, h = parts.r, float(dt)
        I, Z = np.eye(r), np.zeros((r, r))
        beta, gamma = 0.25, 0.5
        S = M + gamma * h * C + beta * h * h * K
        Pq = np.hstack([I, h * I, (0.5 - beta) * h * h * I])
        Pv = np.hstack([Z, I, (1.0 - gamma) * h * I])
        Aa = -solve_matrix(S, K @ Pq + C @ Pv)
        A = np.vstack([Pq + beta * h * h * Aa, Pv + gamma * h * Aa, Aa])
        if forcing is None:
            return A, None
        Fa = solve_matrix(S, forcing)
        return A, np.vstack([beta * h * h * Fa, gamma * h * Fa, Fa])

    def step(self, parts, nonlinear, dt, t, q, v, a, state, force, newton):
        M, C, K, h = parts.mass, parts.damping_matrix, parts.stiffness, float(dt)
        cq, cv = 0.25 * h * h, 0.5 * h
        qp, vp = q + h * v + 0.25 * h * h * a, v + 0.5 * h * a

        def residual_and_jacobian(x):
            qx, vx = qp + cq * x, vp + cv * x
            R = M @ x + C @ vx + K @ qx + nonlinear.force(qx, vx, state) - force
            Jq, Jv = nonlinear.tangent(qx, vx, state)
            J = M + cv * (C + (0.0 if Jv is None else Jv)) + cq * (K + (0.0 if Jq is None else Jq))
            return R, J

        a1, iterations = newton_solve(residual_and_jacobian, a.copy(), newton, t + h)
        return qp + cq * a1, vp + cv * a1, None, iterations
