r"""The implicit midpoint rule: symplectic, second order, every quadratic invariant conserved.

On the first-order form ``q' = v, M v' = F - C v - K q - f`` with ``h = dt``,
``q_m = (q_n + q_{n+1}) / 2`` and ``v_m = (v_n + v_{n+1}) / 2``:

.. math::

    q_{n+1} = q_n + h v_m, \qquad
    M (v_{n+1} - v_n) = h \big[F(t_n + h/2) - C v_m - K q_m - f(q_m, v_m)\big].

Eliminating ``q_m = q_n + h v_m / 2`` leaves one equation for ``v_m``,

.. math::

    S v_m + \tfrac h2 f(q_n + \tfrac h2 v_m, v_m) = M v_n - \tfrac h2 K q_n + \tfrac h2 F(t_n + h/2),
    \qquad S = M + \tfrac h2 C + \tfrac{h^2}{4} K,

linear when ``f`` is absent (``S`` factorised once per ``dt``). The rule conserves
``v^T M v / 2 + q^T K q / 2`` exactly for a linear undamped model (Hairer, Lubich &
Wanner, Geometric Numerical Integration, 2006, Thm IV.2.1) and steps an undamped mode
at ``tan(Omega h / 2) = omega h / 2``, as the trapezoidal rule does.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from femrom.integrators._implicit import ImplicitSolve
from femrom.integrators._newton import Newton, newton_loop
from femrom.integrators._scheme import Scheme, register_scheme, solve_matrix
from femrom.integrators.schemes._canonical import midpoint_step_matrix
from femrom.integrators.schemes.newmark import newmark_frequencies, trapezoidal_inverse


@dataclass
class MidpointCache:
    """What a midpoint step reuses: ``dt``, the effective matrix, its solver (linear
    models) or the nonlinear step's :class:`ImplicitSolve`, the mass solver."""

    dt: float
    effective_matrix: Any
    mass_solver: Any
    solver: Any = None
    nonlinear: ImplicitSolve | None = None
    details: dict = field(default_factory=dict)


def end_acceleration(system, mass_solver, force_end, q1, v1, state1):
    """``a = M^-1 (F(t + h) - C v - K q - f(q, v; s))`` at a step's end (schemes that do not carry it)."""
    rhs = -(system.stiffness @ q1)
    if system.damping is not None:
        rhs = rhs - system.damping @ v1
    if system.nonlinear is not None:
        rhs = rhs - system.nonlinear.force(q1, v1, state1)
    F = None if force_end is None else force_end()
    return mass_solver.solve(rhs if F is None else rhs + F)


@register_scheme
@dataclass(frozen=True)
class ImplicitMidpoint(Scheme):
    """Implicit midpoint rule (module docstring).

    Attributes
    ----------
    accelerations : bool
        Whether each step also returns ``a_{n+1}`` from the equation of motion at the new
        state: one extra mass solve per step (the rule itself never needs it). ``False``
        yields ``a = None``.
    newton : Newton
        Tolerances and method of the nonlinear step.
    """

    accelerations: bool = True
    newton: Newton = Newton()

    name = "implicit_midpoint"
    aliases = ("midpoint",)
    order = 2
    models = ("second_order", "canonical", "first_order")
    input_time = 0.5
    carries_acceleration = False

    @property
    def label(self) -> str:
        return "ImplicitMidpoint"

    @property
    def uses_mass_solver(self) -> bool:  # type: ignore[override]
        """Whether steps solve with M (the driver frees M's factor otherwise)."""
        return self.accelerations

    def frequency(self, omega, dt):
        return newmark_frequencies(omega, dt)

    def continuous_frequency(self, Omega, dt):
        return trapezoidal_inverse(Omega, dt)

    def init(self, system, dt: float, make_solver, mass_solver, t0, q0, v0, a0, state0):
        """Build (and for a linear model, factorise) ``M + dt/2 C + dt^2/4 K``."""
        S = system.mass + (0.25 * dt * dt) * system.stiffness
        if system.damping is not None:
            S = S + (0.5 * dt) * system.damping
        S = S.tocsr() if sp.issparse(S) else np.asarray(S, dtype=float)
        cache = MidpointCache(dt=float(dt), effective_matrix=S,
                              mass_solver=mass_solver() if self.accelerations else None)
        if system.nonlinear is None:
            cache.solver = make_solver(S, spd=True)
        else:
            # M (v_m - v) + h/2 [K q_m + C v_m + f(q_m, v_m) - F] = 0 with q_m = q + h/2 v_m
            cache.nonlinear = ImplicitSolve(system, S, 0.5 * dt, 1.0, 0.5 * dt, make_solver, self.newton)
            cache.details = cache.nonlinear.details   # the same dict: running totals show in the summary
        return cache

    def step(self, system, cache: MidpointCache, t, q, v, a, state, force, force_end=None):
        """One step from ``(t, q, v)``: returns ``(q1, v1, a1, state1, newton_iterations)``."""
        h = cache.dt
        guess = v if a is None else v + (0.5 * h) * a
        rhs = system.mass @ v - (0.5 * h) * (system.stiffness @ q)
        if force is not None:
            rhs += (0.5 * h) * force
        if system.nonlinear is None:
            v_mid = cache.solver.solve(rhs, x0=guess)
            iterations = 0
        else:
            v_mid, iterations = cache.nonlinear(rhs, q, np.zeros_like(v), state, guess)
        q1 = q + h * v_mid
        v1 = 2.0 * v_mid - v
        state1 = state if system.nonlinear is None else system.nonlinear.commit(q1, v1, state)
        a1 = None
        if self.accelerations:
            a1 = end_acceleration(system, cache.mass_solver, force_end, q1, v1, state1)
        return q1, v1, a1, state1, iterations

    def canonical_step_matrix(self, position, momentum, dt):
        return midpoint_step_matrix(position, momentum, float(dt))

    def canonical_nodes(self, quadrature=2):
        """The gradient at the step's midpoint (symplectic; every quadratic invariant kept)."""
        return np.array([0.5]), np.array([1.0])

    def first_order_step(self, rhs, jacobian, y, h, newton):
        """Newton on ``y_1 - y - h f((y + y_1) / 2) = 0`` from the explicit Euler predictor."""
        identity = np.eye(y.size)

        def evaluate(y1):
            fm = rhs(0.5 * (y + y1))
            J = identity - 0.5 * h * jacobian(0.5 * (y + y1))
            return y1 - y - h * fm, np.linalg.norm(y) + h * np.linalg.norm(fm), lambda r: np.linalg.solve(J, r)

        return newton_loop(evaluate, y + h * rhs(y), newton)[0]

    def step_map(self, parts, dt, forcing):
        """``x = [q; v]``: ``S v_m = M v - h K q / 2 + h F_{k+1/2} / 2``, ``q_{k+1} = q + h v_m``,
        ``v_{k+1} = 2 v_m - v``."""
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
