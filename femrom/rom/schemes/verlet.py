"""Velocity Stoermer-Verlet for reduced models."""

import numpy as np
import scipy.linalg as sl

from femrom.rom._schemes import ReducedScheme, register_reduced_scheme, solve_matrix


def verlet_bound(M, K) -> float:
    """``2 / omega_max`` of ``(K, M)``: the Stoermer-Verlet stability limit."""
    w2 = sl.eigvals(K, M).real
    top = float(np.max(w2)) if w2.size else 0.0
    return np.inf if top <= 0 else 2.0 / np.sqrt(top)


@register_reduced_scheme
class VerletScheme(ReducedScheme):
    r"""Velocity Stoermer-Verlet, state ``[q; v; a]``; explicit.

    ``v_{1/2} = v + h a / 2``, ``q_{k+1} = q + h v_{1/2}``, ``(M + h C / 2)
    a_{k+1} = F_{k+1} - K q_{k+1} - C v_{1/2}``, ``v_{k+1} = v_{1/2} + h a_{k+1} /
    2``. Stable for ``h < 2 / omega_max`` (checked); a velocity-dependent
    force is lagged at the half step. Conserves a modified energy (no drift).
    """

    name = "verlet"
    input_time = "end"
    carries_acceleration = True

    def check(self, parts, dt):
        K = parts.stiffness
        bound = verlet_bound(parts.mass, 0.5 * (K + K.T))
        if dt > bound:
            raise ValueError(f"dt = {dt:.6g} exceeds the Stoermer-Verlet bound "
                             f"2/omega_max = {bound:.6g} of the reduced model")

    def step_map(self, parts, dt, forcing):
        M, C, K = parts.mass, parts.damping_matrix, parts.stiffness
        r, h = parts.r, float(dt)
        I, Z = np.eye(r), np.zeros((r, r))
        S = M + 0.5 * h * C
        Pq = np.hstack([I, h * I, 0.5 * h * h * I])       # q1 = q + h v + h^2 a / 2
        Ph = np.hstack([Z, I, 0.5 * h * I])               # v_half
        Aa = -solve_matrix(S, K @ Pq + C @ Ph)
        A = np.vstack([Pq, Ph + 0.5 * h * Aa, Aa])
        if forcing is None:
            return A, None
        Fa = solve_matrix(S, forcing)
        return A, np.vstack([np.zeros_like(Fa), 0.5 * h * Fa, Fa])

    def step(self, parts, nonlinear, dt, t, q, v, a, state, force, newton):
        M, C, K, h = parts.mass, parts.damping_matrix, parts.stiffness, float(dt)
        vh = v + 0.5 * h * a
        q1 = q + h * vh
        a1 = np.linalg.solve(M + 0.5 * h * C, force - K @ q1 - C @ vh - nonlinear.force(q1, vh, state))
        return q1, vh + 0.5 * h * a1, a1, 0
