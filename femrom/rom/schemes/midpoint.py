"""The implicit midpoint rule for reduced models."""

import numpy as np

from femrom.rom._schemes import ReducedScheme, newton_solve, register_reduced_scheme, solve_matrix


@register_reduced_scheme
class MidpointScheme(ReducedScheme):
    r"""Implicit midpoint, state ``[q; v]``: ``S v_m = M v - h K q / 2 + h F_{k+1/2} / 2``.

    ``S = M + h C / 2 + h^2 K / 4``, ``q_{k+1} = q + h v_m``, ``v_{k+1} = 2 v_m -
    v``. Symplectic, second order, conserves every quadratic invariant. The
    rule never needs accelerations: they are recovered from the equation of
    motion at the grid points.
    """

    name = "midpoint"
    input_time = "mid"
    carries_acceleration = False

    def step_map(self, parts, dt, forcing):
        M, C, K = parts.mass, parts.damping_matrix, parts.stiffness
        r, h = parts.r, float(dt)
        I, Z = np.eye(r), np.zeros((r, r))
        S = M + 0.5 * h * C + 0.25 * h * h * K
        Avm = solve_matrix(S, np.hstack([-0.5 * h * K, M]))
        A = np.vstack([np.hstack([I, Z]) + h * Avm, 2.0 * Avm - np.hstack([Z, I])])
        if forcing is None:
            return A, None
        Fvm = solve_matrix(S, 0.5 * h * forcing)
        return A, np.vstack([h * Fvm, 2.0 * Fvm])

    def step(self, parts, nonlinear, dt, t, q, v, a, state, force, newton):
        M, C, K, h = parts.mass, parts.damping_matrix, parts.stiffness, float(dt)
        cq = 0.5 * h

        def residual_and_jacobian(x):
            # the unknown is v_mid; the equation is scaled by 2 / h: M (v_m - v) / (h/2) + ...
            qx = q + 0.5 * h * x
            R = M @ (x - v) / (0.5 * h) + C @ x + K @ qx + nonlinear.force(qx, x, state) - force
            Jq, Jv = nonlinear.tangent(qx, x, state)
            J = M / (0.5 * h) + (C + (0.0 if Jv is None else Jv)) + cq * (K + (0.0 if Jq is None else Jq))
            return R, J

        v_mid, iterations = newton_solve(residual_and_jacobian, v + 0.5 * h * a, newton, t + h)
        return q + h * v_mid, 2.0 * v_mid - v, None, iterations
