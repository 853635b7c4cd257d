r"""Implicit midpoint with the average-vector-field discrete gradient of the potential: energy never increases."""

import numpy as np

from femrom.rom._schemes import ReducedScheme, register_reduced_scheme
from femrom.rom.schemes.midpoint import MidpointScheme

#: Above this ``||q1 - q0||^2`` (relative to ``||q0||^2 + ||q1||^2 + 1``) the quadrature is
#: projected onto the exact energy identity; below it the quadrature's own error,
#: ``O(||q1 - q0||^5)``, is round-off, and the projection's division by ``||q1 - q0||^2``
#: would only amplify the round-off of ``U(q1) - U(q0)``.
SMALL_STEP = 1e-6

#: Gauss-Legendre nodes and weights on [0, 1], two points: exact for polynomials of degree 3,
#: i.e. for the gradient of a quartic potential along the segment.
GAUSS_NODES = 0.5 + 0.5 * np.array([-1.0, 1.0]) / np.sqrt(3.0)
GAUSS_WEIGHTS = np.array([0.5, 0.5])


def discrete_gradient(term, q0: np.ndarray, q1: np.ndarray, potential0: float | None = None):
    r"""The average-vector-field discrete gradient of a conservative term and its derivative in ``q1``:

    .. math::

        \bar\nabla U(q_0, q_1) = \int_0^1 \nabla U(q_0 + s \Delta)\, ds, \qquad
        \frac{\partial \bar\nabla U}{\partial q_1} = \int_0^1 s\, \nabla^2 U(q_0 + s \Delta)\, ds,
        \qquad \Delta = q_1 - q_0,

    so that ``grad . Delta = U(q1) - U(q0)`` (Quispel & McLaren, J. Phys. A 41, 2008), with the
    integrals by two-point Gauss-Legendre: exact for potentials of degree <= 4 (the
    monomials of degree 3 and 4), for a smooth potential (a tanh network) an error
    ``O(|Delta|^5)``. For steps above :data:`SMALL_STEP` the quadrature is then corrected
    along ``Delta`` by Gonzalez's term ``(U(q1) - U(q0) - grad . Delta) Delta / |Delta|^2``
    (J. Nonlinear Sci. 6, 1996), which makes the identity exact for any potential; below it
    the correction is skipped (it is round-off there, and its division would amplify the
    round-off of ``U(q1) - U(q0)`` enough to stall Newton near rest). The derivative is the
    quadrature's (Newton stays quadratic up to the small correction).
    ``potential0``: ``U(q0)`` when the caller has it (it is the same in every Newton iteration).
    Returns ``(grad (r,), d grad / d q1 (r, r) or None)``.
    """
    delta = q1 - q0
    grad, jac = np.zeros_like(q0), None
    for s, w in zip(GAUSS_NODES, GAUSS_WEIGHTS):
        q = q0 + s * delta
        grad = grad + w * term.force(q)
        H = term.tangent(q)[0]
        if H is not None:
            jac = w * s * H if jac is None else jac + w * s * H
    dd = float(delta @ delta)
    if dd > SMALL_STEP * (float(q1 @ q1) + float(q0 @ q0) + 1.0):
        # Gonzalez's projection onto the energy identity: grad . Delta = U(q1) - U(q0) exactly
        u0 = term.potential(q0) if potential0 is None else potential0
        grad = grad + ((term.potential(q1) - u0 - float(grad @ delta)) / dd) * delta
    return grad, jac


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

    Newton on ``v_m`` with the exact Jacobian ``(2/h) M + C + dF/dv + (h/2) K + h int_0^1 s
    d^2U(q_k + s Delta) ds``, converged when ``||dv_m|| <= tol max(||v_m||, ||v_k|| + h ||a_k||
    / 2)`` or when the updates stop shrinking (round-off).
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
        conservative = [(t_, t_.potential(q)) for t_ in terms if t_.conservative]
        other = [(t_, s) for t_, s in zip(terms, states) if not t_.conservative]

        def residual_and_jacobian(x):
            q1 = q + h * x
            qm = q + 0.5 * h * x
            parts = [M @ (x - v) / (0.5 * h), C @ x, K @ qm, -force]
            J = M / (0.5 * h) + C + 0.5 * h * K
            for term, potential0 in conservative:
                grad, Jq = discrete_gradient(term, q, q1, potential0)
                parts.append(grad)
                if Jq is not None:
                    J = J + h * Jq
            for term, s in other:
                parts.append(term.lhs(qm, x, state=s))
                Jq, Jv = term.tangent(qm, x, s)
                J = J + (0.0 if Jv is None else Jv) + 0.5 * h * (0.0 if Jq is None else Jq)
            return sum(parts), J

        # Newton on v_m; converged when the update is below tol times the step's velocity scale
        # (||v_m|| alone can be ~0 at a turning point), or when, from the third iteration on,
        # it stops shrinking: with the exact Jacobian that is the round-off floor (near rest
        # the absolute round-off of a shifted network gradient, ~eps, exceeds tol ||v||)
        x, scale = v + 0.5 * h * a, float(np.linalg.norm(v)) + 0.5 * h * float(np.linalg.norm(a))
        previous = np.inf
        for iteration in range(1, newton.max_iterations + 1):
            R, J = residual_and_jacobian(x)
            dx = np.linalg.solve(J, -R)
            x = x + dx
            size, reference = float(np.linalg.norm(dx)), max(float(np.linalg.norm(x)), scale, 1e-300)
            if size <= newton.tol * reference or (iteration >= 3 and size >= 0.5 * previous):
                return q + h * x, 2.0 * x - v, None, iteration
            previous = size
        raise RuntimeError(f"reduced Newton did not converge at t = {t + h:.6g}")
