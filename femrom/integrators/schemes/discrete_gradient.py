r"""Implicit midpoint with the average-vector-field discrete gradient of every conservative force.

With ``v_m = (v_k + v_{k+1}) / 2``, ``q_{k+1} = q_k + h v_m`` and

.. math::

    M \frac{v_{k+1} - v_k}{h} + C v_m + K \frac{q_k + q_{k+1}}{2}
        + \sum_{\text{conservative}} \bar\nabla U_j(q_k, q_{k+1})
        + \sum_{\text{other}} f_j\big(\tfrac{q_k + q_{k+1}}{2}, v_m\big) = F_{k+1/2},

the energy ``E = v^T M v / 2 + q^T K q / 2 + sum_j U_j(q)`` changes by exactly

.. math::

    E_{k+1} - E_k = h\, v_m \cdot \big(F_{k+1/2} - C v_m - \textstyle\sum_{\text{other}} f_j\big):

without input it never increases when ``C >= 0`` and every other force takes power
out (``v . f_j(q, v) >= 0``, e.g. a learned dissipation function), and it is conserved
without them. (Multiply the step by ``q_{k+1} - q_k = h v_m``: ``(v_{k+1} - v_k)^T M
v_m`` is the kinetic, ``(q_{k+1} - q_k)^T K q_m`` the quadratic and the discrete
gradient the nonlinear potential's difference.) Second order; a linear model is the
midpoint rule, and its frequency map is the midpoint rule's.

A stateful force with a *step force* (:attr:`femrom.fem.NonlinearForce.step_force`: a joint
whose law has an energy-consistent ``step_traction``, e.g. ``dry_friction``) enters with it,
``bar f(q_k, q_{k+1}; s_k)`` in place of ``f(q_m, v_m; s_k)``. Its work ``bar f . (q_{k+1} -
q_k)`` is at least the change of the energy it stores plus what it dissipates, so that

.. math::

    E_{k+1} - E_k + D_k \le h\, v_m \cdot \big(F_{k+1/2} - C v_m\big)

with ``E`` including the joint's stored energy and ``D_k`` its dissipation: a penalty contact
that opens or closes, sticks or slips within a step takes energy out or keeps it, never
adds it (:meth:`femrom.fem.DryFrictionLaw.step_traction`). The trapezoidal rule's mean
``(f_k + f_{k+1}) / 2`` has no such bound, and gains energy when a pair opens within a step.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from femrom.integrators._fused import fused_discrete_gradient
from femrom.integrators._newton import newton_loop
from femrom.integrators._scheme import register_scheme
from femrom.integrators.schemes.implicit_midpoint import ImplicitMidpoint, end_acceleration

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


def _added(J, B, sparse: bool):
    """``J + B``: sparse for a sparse step matrix, else a dense ndarray (never ``np.matrix``)."""
    if sparse:
        return J + B
    return J + (B.toarray() if sp.issparse(B) else np.asarray(B))


def forces_of(nonlinear) -> tuple:
    """The summands of a nonlinear force, one by one (a sum's forces or terms, else itself)."""
    for attribute in ("forces", "terms"):
        parts = getattr(nonlinear, attribute, None)
        if isinstance(parts, (tuple, list)):
            return tuple(parts)
    return (nonlinear,)


@dataclass
class DiscreteGradientCache:
    """``dt``, the linear step's matrix ``(2/h) M + C + (h/2) K``, the solvers."""

    dt: float
    matrix: Any
    make_solver: Any
    mass_solver: Any
    linear: Any = None
    details: dict = field(default_factory=dict)
    fused: Any = None


@register_scheme
@dataclass(frozen=True)
class DiscreteGradient(ImplicitMidpoint):
    r"""Implicit midpoint, the conservative forces by their discrete gradient (module docstring).

    A linear model is stepped by the midpoint rule itself: the step map, the frequency map,
    the canonical step matrix and the end-of-step acceleration are :class:`ImplicitMidpoint`'s;
    only the nonlinear step and, for canonical models, the quadrature of the gradient differ.

    Newton on ``v_m`` with the exact Jacobian ``(2/h) M + C + df/dv + (h/2) (K + df/dq)
    + h int_0^1 s d^2U(q_k + s Delta) ds``, converged when ``||dv_m|| <= rtol max(||v_m||,
    ||v_k|| + h ||a_k|| / 2)`` or when, from the third iteration on, the updates stop
    shrinking (the round-off floor: near rest the absolute round-off of a network's
    gradient exceeds ``rtol ||v||``). Small dense models solve the Jacobian densely, the
    full model with its sparse strategy. A small model whose nonlinear force is a learned
    potential and/or dissipation with compiled functions steps in one compiled call, and
    ``march``/``predict`` step its whole trajectory in one, by default by a chord iteration to
    the same fixed point and update test (one Jacobian a step, the predictor from the
    extrapolated learned force; ``Newton.refactor_ratio = 0``: this Newton, iteration for
    iteration; :meth:`femrom.integrators._fused.FusedDiscreteGradientStep.march`).

    Attributes
    ----------
    accelerations : bool
        Whether each step also returns ``a_{n+1}`` from the equation of motion.
    newton : Newton
        ``rtol`` and ``max_iterations`` of the update test.
    """

    name = "discrete_gradient"
    aliases = ("avf",)
    models = ("second_order", "canonical")

    @property
    def label(self) -> str:
        return "DiscreteGradient"

    def init(self, system, dt: float, make_solver, mass_solver, t0, q0, v0, a0, state0):
        h = float(dt)
        J = system.mass / (0.5 * h)
        if system.damping is not None:
            J = J + system.damping
        J = J + 0.5 * h * system.stiffness
        J = J.tocsr() if sp.issparse(J) else np.asarray(J, dtype=float)
        cache = DiscreteGradientCache(dt=h, matrix=J, make_solver=make_solver,
                                      mass_solver=mass_solver() if self.accelerations else None)
        if system.nonlinear is None:
            cache.linear = make_solver(J, spd=True)
        else:
            cache.fused = fused_discrete_gradient(self, system, h, J)
            if cache.fused is not None:
                cache.details["compiled_step"] = True
        return cache

    def step(self, system, cache: DiscreteGradientCache, t, q, v, a, state, force, force_end=None):
        if cache.fused is not None and cache.fused.enabled():
            return cache.fused(t, q, v, a, state, force, force_end)
        M, C, K, h = system.mass, system.damping, system.stiffness, cache.dt
        if system.nonlinear is None:
            # the midpoint rule: ((2/h) M + C + (h/2) K) v_m = (2/h) M v - K q + F
            rhs = M @ v / (0.5 * h) - K @ q
            if force is not None:
                rhs = rhs + force
            x, iterations = cache.linear.solve(rhs), 0
        else:
            forces = forces_of(system.nonlinear)
            states = state if len(forces) > 1 else (state,)
            if states is None:
                states = (None,) * len(forces)
            conservative = [(f, f.potential(q)) for f in forces if f.conservative]
            stepped = [(f.step_force, s) for f, s in zip(forces, states)
                       if not f.conservative and callable(getattr(f, "step_force", None))]
            other = [(f, s) for f, s in zip(forces, states)
                     if not f.conservative and not callable(getattr(f, "step_force", None))]
            sparse = sp.issparse(cache.matrix)

            def evaluate(x):
                q1 = q + h * x
                qm = q + 0.5 * h * x
                parts = [M @ (x - v) / (0.5 * h)]
                if C is not None:
                    parts.append(C @ x)
                parts.append(K @ qm)
                if force is not None:
                    parts.append(-force)
                J = cache.matrix
                for f, potential0 in conservative:
                    grad, Jq = discrete_gradient(f, q, q1, potential0)
                    parts.append(grad)
                    if Jq is not None:
                        J = J + h * Jq
                for step_force, s in stepped:
                    # the step's force from q to q1 (its work bounds the stored energy's change plus
                    # the dissipation), d q1 / d v_m = h
                    fbar, J1 = step_force(q, q1, s)
                    parts.append(fbar)
                    J = _added(J, h * J1, sparse)
                for f, s in other:
                    parts.append(f.force(qm, x, s))
                    Jq, Jv = f.tangent(qm, x, s)
                    if Jv is not None:
                        J = _added(J, Jv, sparse)
                    if Jq is not None:
                        J = _added(J, 0.5 * h * Jq, sparse)
                R = sum(parts)
                scale = 0.0                     # the update test below, not the residual's
                if sparse:
                    return R, scale, lambda r: cache.make_solver(sp.csr_matrix(J), spd=False).solve(r)
                return R, scale, lambda r: np.linalg.solve(J, r)

            a_now = np.zeros_like(v) if a is None else a
            x0 = v + 0.5 * h * a_now
            reference = float(np.linalg.norm(v)) + 0.5 * h * float(np.linalg.norm(a_now))
            x, iterations = newton_loop(evaluate, x0, self.newton, update_scale=reference, stagnation=True,
                                        where=f" at t = {t + h:.6g}")
        q1, v1 = q + h * x, 2.0 * x - v
        state1 = state if system.nonlinear is None else system.nonlinear.commit(q1, v1, state)
        a1 = end_acceleration(system, cache.mass_solver, force_end, q1, v1, state1) if self.accelerations else None
        return q1, v1, a1, state1, iterations

    def canonical_nodes(self, quadrature=2):
        r"""Gauss-Legendre nodes and weights on [0, 1]: the average vector field ``int_0^1 grad H(y_0 + s
        (y_1 - y_0)) ds`` (Quispel & McLaren 2008), exact when ``grad H`` is a polynomial of degree
        ``<= 2 quadrature - 1`` along the step (the cubic NLS gradient needs 2): ``H`` kept exactly."""
        x, w = np.polynomial.legendre.leggauss(int(quadrature))
        return 0.5 * (x + 1.0), 0.5 * w
