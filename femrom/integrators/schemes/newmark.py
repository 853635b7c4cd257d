r"""Newmark's method, and the step it shares with generalized-alpha.

Newmark updates (``h = dt``)

.. math::

    q_{n+1} = q_n + h v_n + h^2 \big[(\tfrac12 - \beta) a_n + \beta a_{n+1}\big], \qquad
    v_{n+1} = v_n + h \big[(1 - \gamma) a_n + \gamma a_{n+1}\big],

with the equation of motion balanced at shifted points (Chung & Hulbert,
J. Appl. Mech. 60:371-375, 1993)

.. math::

    M a_{n+1-\alpha_m} + C v_{n+1-\alpha_f} + K q_{n+1-\alpha_f}
        + f(q_{n+1-\alpha_f}, v_{n+1-\alpha_f}) = F(t_{n+1-\alpha_f}),

where ``x_{n+1-alpha} = (1 - alpha) x_{n+1} + alpha x_n``; Newmark is the case
``alpha_m = alpha_f = 0``. The unknown is ``a_{n+1}``; for a linear model it solves
``S a_{n+1} = rhs`` with the effective matrix

.. math::

    S = (1 - \alpha_m) M + (1 - \alpha_f) \gamma h C + (1 - \alpha_f) \beta h^2 K,

factorised once per ``dt`` (sparse for the full model, dense for a reduced one); a
nonlinear model solves ``S a + f(q^* + c_q a, v^* + c_v a) = rhs`` by Newton
(:class:`~femrom.integrators.ImplicitSolve`: on all dofs, condensed onto the force's
own coordinates, or dense for a small model). A small model whose force is a projected
joint with a compiled law, or learned Jenkins sliders, takes the whole step, Newton and
commit included, in one compiled call (:mod:`femrom.integrators._fused`), the same step to
round-off.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.integrators._fused import fused_step
from femrom.integrators._implicit import ImplicitSolve
from femrom.integrators._newton import Newton
from femrom.integrators._scheme import Scheme, register_scheme, solve_matrix


def newmark_frequencies(omega, dt: float):
    r"""The frequencies at which Newmark average acceleration (``beta = 1/4``, ``gamma = 1/2``)
    steps undamped modes of frequencies ``omega`` [rad/s] at step ``dt``.

    A mode ``q'' + omega^2 q = 0`` obeys ``q_{n+1} - 2 q_n + q_{n-1} = -(omega dt)^2
    (q_{n+1} + 2 q_n + q_{n-1}) / 4``, whose solutions are ``cos(Omega t_n)`` and
    ``sin(Omega t_n)`` with

    .. math::

        \tan(\Omega\, dt / 2) = \omega\, dt / 2,

    a phase lag and no amplitude error. ``omega``: float or ndarray; returns ``Omega`` alike.
    """
    return 2.0 / dt * np.arctan(0.5 * np.asarray(omega) * dt)


def trapezoidal_inverse(Omega, dt: float):
    """``omega = (2 / dt) tan(Omega dt / 2)``: the inverse of :func:`newmark_frequencies`."""
    Omega = np.asarray(Omega, dtype=float)
    if np.any(Omega * dt >= np.pi) or np.any(Omega < 0):
        raise FemromValueError(f"discrete frequencies must lie in [0, pi / dt) = [0, {np.pi / dt:g}) rad/s")
    return 2.0 / dt * np.tan(0.5 * Omega * dt)


def _finish(S):
    return S.tocsr() if sp.issparse(S) else np.asarray(S, dtype=float)


@dataclass
class NewmarkCache:
    """What a Newmark-family step reuses: ``dt``, the effective matrix and its solver
    (linear models) or the nonlinear step's :class:`ImplicitSolve`, and the whole step as one
    compiled call when the force offers it (:func:`~femrom.integrators._fused.fused_step`)."""

    dt: float
    effective_matrix: Any
    solver: Any = None
    nonlinear: ImplicitSolve | None = None
    details: dict = field(default_factory=dict)
    fused: Any = None


class NewmarkFamily(Scheme):
    """The step Newmark and generalized-alpha share; subclasses give ``beta, gamma, alpha_m,
    alpha_f, newton``."""

    def init(self, system, dt: float, make_solver, mass_solver, t0, q0, v0, a0, state0):
        """Build (and for a linear model, factorise) the effective matrix for ``dt``."""
        am, af = self.alpha_m, self.alpha_f
        S = (1.0 - am) * system.mass + ((1.0 - af) * self.beta * dt * dt) * system.stiffness
        if system.damping is not None:
            S = S + ((1.0 - af) * self.gamma * dt) * system.damping
        S = _finish(S)
        cache = NewmarkCache(dt=float(dt), effective_matrix=S)
        if system.nonlinear is None:
            cache.solver = make_solver(S, spd=True)
        else:
            cache.nonlinear = ImplicitSolve(system, S, (1.0 - af) * self.beta * dt * dt,
                                            (1.0 - af) * self.gamma * dt, 1.0, make_solver, self.newton)
            cache.details = cache.nonlinear.details   # the same dict: running totals show in the summary
            cache.fused = fused_step(self, system, dt, S, cache.nonlinear)
            if cache.fused is not None:
                cache.details["compiled_step"] = True
        return cache

    def step(self, system, cache: NewmarkCache, t, q, v, a, state, force, force_end=None):
        """One step from ``(t, q, v, a)``: returns ``(q1, v1, a1, state1, newton_iterations)``."""
        if cache.fused is not None and cache.fused.enabled():
            return cache.fused(q, v, a, state, force)
        h, beta, gamma, af = cache.dt, self.beta, self.gamma, self.alpha_f
        q_pred = q + h * v + ((0.5 - beta) * h * h) * a
        v_pred = v + ((1.0 - gamma) * h) * a
        rhs = self._linear_rhs(system, q, v, a, q_pred, v_pred, force)
        if system.nonlinear is None:
            a1 = cache.solver.solve(rhs, x0=a)
            iterations, state1 = 0, state
        else:
            # the force at the balance point: q_bal = (1 - af) q1 + af q = q_bal(pred) + c_q a1
            q_bal = q_pred if af == 0.0 else (1.0 - af) * q_pred + af * q
            v_bal = v_pred if af == 0.0 else (1.0 - af) * v_pred + af * v
            a1, iterations = cache.nonlinear(rhs, q_bal, v_bal, state, a)
        q1 = q_pred + (beta * h * h) * a1
        v1 = v_pred + (gamma * h) * a1
        if system.nonlinear is not None:
            state1 = system.nonlinear.commit(q1, v1, state)
        return q1, v1, a1, state1, iterations

    def _linear_rhs(self, system, q, v, a, q_pred, v_pred, force):
        am, af = self.alpha_m, self.alpha_f
        q_bal = q_pred if af == 0.0 else (1.0 - af) * q_pred + af * q
        rhs = -(system.stiffness @ q_bal)
        if system.damping is not None:
            v_bal = v_pred if af == 0.0 else (1.0 - af) * v_pred + af * v
            rhs -= system.damping @ v_bal
        if am != 0.0:
            rhs -= am * (system.mass @ a)
        return rhs if force is None else rhs + force

    def step_map(self, parts, dt, forcing):
        r"""``x = [q; v; a]``: the predictors ``P_q x``, ``P_v x`` and ``a_{n+1} = S^{-1}(F_{n+1-alpha_f}
        - C v_bal - K q_bal - alpha_m M a_n)``."""
        M, C, K = parts.mass, parts.damping_matrix, parts.stiffness
        r, h = parts.r, float(dt)
        beta, gamma, am, af = self.beta, self.gamma, self.alpha_m, self.alpha_f
        I, Z = np.eye(r), np.zeros((r, r))
        S = (1.0 - am) * M + ((1.0 - af) * gamma * h) * C + ((1.0 - af) * beta * h * h) * K
        Pq = np.hstack([I, h * I, (0.5 - beta) * h * h * I])
        Pv = np.hstack([Z, I, (1.0 - gamma) * h * I])
        Ea = np.hstack([Z, Z, I])
        Bq = (1.0 - af) * Pq + af * np.hstack([I, Z, Z])          # q_bal before the a_{n+1} part
        Bv = (1.0 - af) * Pv + af * np.hstack([Z, I, Z])
        Aa = -solve_matrix(S, K @ Bq + C @ Bv + am * (M @ Ea))
        A = np.vstack([Pq + beta * h * h * Aa, Pv + gamma * h * Aa, Aa])
        if forcing is None:
            return A, None
        Fa = solve_matrix(S, forcing)
        return A, np.vstack([beta * h * h * Fa, gamma * h * Fa, Fa])


@register_scheme
@dataclass(frozen=True)
class Newmark(NewmarkFamily):
    r"""Newmark's method; the default ``beta = 1/4, gamma = 1/2`` is average acceleration.

    Average acceleration is implicit, unconditionally stable, second order, and
    conserves ``v^T M v / 2 + q^T K q / 2`` exactly for a linear undamped model (it
    is the trapezoidal rule, equivalent to the midpoint rule there: Hairer, Lubich &
    Wanner, Geometric Numerical Integration, IV.2); its frequency map is
    :func:`newmark_frequencies`. Second order needs ``gamma = 1/2``; ``gamma > 1/2``
    adds first-order numerical damping.

    Attributes
    ----------
    beta, gamma : float
        Newmark parameters.
    newton : Newton
        Tolerances and method of the nonlinear step.
    """

    beta: float = 0.25
    gamma: float = 0.5
    newton: Newton = Newton()

    name = "newmark"
    alpha_m = 0.0
    alpha_f = 0.0
    input_time = 1.0

    def __post_init__(self):
        if self.beta < 0 or self.gamma < 0:
            raise FemromValueError(f"Newmark needs beta, gamma >= 0, got {self.beta}, {self.gamma}")

    @property
    def order(self) -> int:  # type: ignore[override]
        return 2 if self.gamma == 0.5 else 1

    @property
    def average_acceleration(self) -> bool:
        """Whether this is the trapezoidal rule (``beta = 1/4``, ``gamma = 1/2``)."""
        return (self.beta, self.gamma) == (0.25, 0.5)

    @property
    def label(self) -> str:
        if self.average_acceleration:
            return "NewmarkAverageAcceleration"
        return f"Newmark(beta={self.beta:g}, gamma={self.gamma:g})"

    def frequency(self, omega, dt):
        if self.average_acceleration:
            return newmark_frequencies(omega, dt)
        return super().frequency(omega, dt)

    def continuous_frequency(self, Omega, dt):
        if self.average_acceleration:
            return trapezoidal_inverse(Omega, dt)
        return super().continuous_frequency(Omega, dt)
