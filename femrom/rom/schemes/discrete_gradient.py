r"""The implicit midpoint rule with a discrete gradient of the potential: the energy never increases."""

import numpy as np

from femrom.rom._schemes import ReducedScheme, newton_solve, register_reduced_scheme
from femrom.rom.schemes.midpoint import MidpointScheme

#: Below this ``||q1 - q0||^2`` (relative to ``||q||^2 + 1``) the correction of the
#: discrete gradient is dropped: it is ``O(||q1 - q0||^2)`` and the division would only
#: amplify the round-off of ``U(q1) - U(q0)``.
SMALL_STEP = 1e-24


def discrete_gradient(term, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    r"""Gonzalez's discrete gradient of a conservative term's potential ``U``:

    .. math::

        \bar\nabla U(q_0, q_1) = \nabla U(q_m)
            + \frac{U(q_1) - U(q_0) - \nabla U(q_m) \cdot \Delta}{\Delta \cdot \Delta}\, \Delta,
        \qquad q_m = \tfrac12 (q_0 + q_1),\ \Delta = q_1 - q_0,

    so that ``grad . Delta = U(q1) - U(q0)`` exactly (Gonzalez, J. Nonlinear Sci. 6, 1996),
    and ``grad = grad U(q_m) + O(|Delta|^2)`` (second order).
    """
    qm, delta = 0.5 * (q0 + q1), q1 - q0
    g = term.force(qm)
    dd = float(delta @ delta)
    if dd <= SMALL_STEP * (float(qm @ qm) + 1.0):
        return g
    return g + ((term.potential(q1) - term.potential(q0) - float(g @ delta)) / dd) * delta


@register_reduced_scheme
class DiscreteGradientScheme(ReducedScheme):
    r"""Implicit midpoint for ``M q'' + C q' + K q + f(q, q') = F``, the conservative forces by their discrete gradient.

    With ``v_m = (v_k + v_{k+1}) / 2``, ``q_{k+1} = q_k + h v_m`` and

    .. math::

        M \frac{v_{k+1} - v_k}{h} + C v_m + K \frac{q_k + q_{k+1}}{2}
            + \sum_{\text{conservative}} \bar\nabla U_j(q_k, q_{k+1})
            + \sum_{\text{other}} f_j\big(\tfrac{q_k + q_{k+1}}{2}, v_m\big) = F_{k+1/2},

    the energy ``E = v^T M v / 2 + q^T K q / 2 + sum_j U_j(q)`` changes by exactly

    .. math::

        E_{k+1} - E_k = h\, v_m \cdot \big(F_{k+1/2} - C v_m - \textstyle\sum_{\text{other}} f_j\big):

    without input it never increases when ``C >= 0`` and every other force
    takes power out (``v . f_j(q, v) >= 0``, e.g. a learned dissipation function,
    :class:`~femrom.inference.LearnedDissipation`), and is conserved without them.
    (Multiply the step by ``q_{k+1} - q_k = h v_m``: ``(v_{k+1} - v_k)^T M v_m`` is the
    kinetic, ``(q_{k+1} - q_k)^T K q_m`` the quadratic and the discrete gradient the
    nonlinear potential's difference.) Second order. A linear model is the midpoint rule.

    Newton on ``v_m`` uses ``(2/h) M + C + dF/dv + (h/2) (K + d^2U/dq^2(q_m))``: the tangent of the
    midpoint gradient, not of the discrete gradient's correction (``O(h^2 |v_m|^2)``), so
    Newton converges linearly at a small rate; the residual itself is exact.
    """

    name = "discrete_gradient"
    input_time = "mid"
    carries_acceleration = False

    def step_map(self, parts, dt, forcing):
        return MidpointScheme().step_map(parts, dt, forcing)

    def step(self, parts, nonlinear, dt, t, q, v, a, state, force, newton):
        M, C, K, h = parts.mass, parts.damping_matrix, parts.stiffness, float(dt)
        if hasattr(nonlinear, "terms"):        # several forces together: one state each
            terms = nonlinear.terms
            states = state if state is not None else (None,) * len(terms)
        else:
            terms, states = (nonlinear,), (state,)
        conservative = [t_ for t_ in terms if t_.conservative]
        other = [(t_, s) for t_, s in zip(terms, states) if not t_.conservative]

        def residual_and_jacobian(x):
            q1 = q + h * x
            qm = q + 0.5 * h * x
            R = M @ (x - v) / (0.5 * h) + C @ x + K @ qm - force
            J = M / (0.5 * h) + C + 0.5 * h * K
            for term in conservative:
                R = R + discrete_gradient(term, q, q1)
                Jq, _ = term.tangent(qm)
                if Jq is not None:
                    J = J + 0.5 * h * Jq
            for term, s in other:
                R = R + term.lhs(qm, x, state=s)
                Jq, Jv = term.tangent(qm, x, s)
                J = J + (0.0 if Jv is None else Jv) + 0.5 * h * (0.0 if Jq is None else Jq)
            return R, J

        v_mid, iterations = newton_solve(residual_and_jacobian, v + 0.5 * h * a, newton, t + h)
        return q + h * v_mid, 2.0 * v_mid - v, None, iterations
