r"""Implicit midpoint rule for ``M q'' + C q' + K q + f_nl(q, q') = B u(t)``.

On the first-order form ``q' = v, M v' = B u - C v - K q - f_nl`` with
``h = dt``, ``q_m = (q_n + q_{n+1}) / 2`` and ``v_m = (v_n + v_{n+1}) / 2``:

    q_{n+1} = q_n + h v_m,
    M (v_{n+1} - v_n) = h [B u(t_n + h/2) - C v_m - K q_m - f_nl(q_m, v_m)].

Eliminating ``q_m = q_n + h v_m / 2`` leaves one equation for ``v_m``:

    M (v_m - v_n) + (h/2) [C v_m + K q_m + f_nl(q_m, v_m) - B u(t_n + h/2)] = 0,

linear with matrix ``M + (h/2) C + (h^2/4) K`` (factorised once per ``dt``)
when ``f_nl`` is absent. The rule is symplectic, second order, and conserves
every quadratic invariant: ``v^T M v / 2 + q^T K q / 2`` exactly for a linear
undamped system (Hairer, Lubich & Wanner, Geometric Numerical Integration,
2006, Thm IV.2.1).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from femrom.integrators._implicit import ImplicitSolve
from femrom.integrators._newton import Newton
from femrom.integrators._schemes import register_scheme


@dataclass
class MidpointCache:
    """What a midpoint step reuses: ``dt``, the effective matrix, its solver (linear
    systems) or the nonlinear step's :class:`ImplicitSolve`, the mass solver."""

    dt: float
    effective_matrix: Any
    mass_solver: Any
    solver: Any = None
    nonlinear: ImplicitSolve | None = None
    details: dict = field(default_factory=dict)


@register_scheme("implicit_midpoint")
@dataclass(frozen=True)
class ImplicitMidpoint:
    """Implicit midpoint rule (symplectic, second order).

    Attributes
    ----------
    accelerations : bool
        Whether each step also returns ``a_{n+1}`` from ``M a = B u - C v - K q
        - f_nl`` at the new state: one extra mass solve per step (the scheme
        itself never needs it). ``False`` yields ``a = None``.
    newton : Newton
        Tolerances for nonlinear systems.
    """

    accelerations: bool = True
    newton: Newton = Newton()

    order = 2
    name = "ImplicitMidpoint"

    @classmethod
    def from_config(cls, time_config) -> "ImplicitMidpoint":
        """With accelerations (a scene's ``integrator = "implicit_midpoint"``)."""
        return cls()

    @property
    def uses_mass_solver(self) -> bool:
        """Whether steps solve with M (the driver frees M's factor otherwise)."""
        return self.accelerations

    def init(self, system, dt: float, make_solver, mass_solver, t0, q0, v0, a0, state0):
        """Build (and for a linear system, factorise) ``M + dt/2 C + dt^2/4 K``."""
        S = system.mass + (0.25 * dt * dt) * system.stiffness
        if system.damping is not None:
            S = S + (0.5 * dt) * system.damping
        S = S.tocsr()
        cache = MidpointCache(dt=float(dt), effective_matrix=S,
                              mass_solver=mass_solver() if self.accelerations else None)
        if system.nonlinear is None:
            cache.solver = make_solver(S, spd=True)
        else:
            # M (v_m - v) + h/2 [K q_m + C v_m + f(q_m, v_m) - B u] = 0 with q_m = q + h/2 v_m
            cache.nonlinear = ImplicitSolve(system, S, 0.5 * dt, 1.0, 0.5 * dt, make_solver, self.newton)
            cache.details = cache.nonlinear.details   # the same dict: running totals show in the summary
        return cache

    def step(self, system, cache: MidpointCache, t, q, v, a, state):
        """One step from ``(t, q, v)``: returns ``(q1, v1, a1, state1, newton_iterations)``."""
        h = cache.dt
        guess = v if a is None else v + (0.5 * h) * a
        f_ext = system.external_force(t + 0.5 * h)
        rhs = system.mass @ v - (0.5 * h) * (system.stiffness @ q)
        if f_ext is not None:
            rhs += (0.5 * h) * f_ext
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
            a1 = cache.mass_solver.solve(system.residual_force(t + h, q1, v1, state1))
        return q1, v1, a1, state1, iterations
