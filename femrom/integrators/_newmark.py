r"""Newmark and generalized-alpha steps for ``M a + C v + K q + f_nl(q, v) = B u(t)``.

Newmark updates (``h = dt``)

    q_{n+1} = q_n + h v_n + h^2 [(1/2 - beta) a_n + beta a_{n+1}],
    v_{n+1} = v_n + h [(1 - gamma) a_n + gamma a_{n+1}],

with the equation of motion balanced at shifted points (Chung & Hulbert,
J. Appl. Mech. 60:371-375, 1993)

    M a_{n+1-alpha_m} + C v_{n+1-alpha_f} + K q_{n+1-alpha_f}
        + f_nl(q_{n+1-alpha_f}, v_{n+1-alpha_f}) = B u(t_{n+1-alpha_f}),

where ``x_{n+1-alpha} = (1 - alpha) x_{n+1} + alpha x_n``. Newmark is the
case ``alpha_m = alpha_f = 0``. The unknown is ``a_{n+1}``; for a linear
system it solves

    [(1-alpha_m) M + (1-alpha_f) gamma h C + (1-alpha_f) beta h^2 K] a_{n+1} = rhs,

with the bracket (the effective matrix) factorised once per ``dt``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from femrom.integrators._implicit import ImplicitSolve
from femrom.integrators._newton import Newton
from femrom.integrators._schemes import register_scheme


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
    import numpy as np

    return 2.0 / dt * np.arctan(0.5 * np.asarray(omega) * dt)


@dataclass
class NewmarkCache:
    """What a Newmark-family step reuses: ``dt``, the effective matrix and its solver
    (linear systems) or the nonlinear step's :class:`ImplicitSolve`."""

    dt: float
    effective_matrix: Any
    solver: Any = None
    nonlinear: ImplicitSolve | None = None
    details: dict = field(default_factory=dict)


class _NewmarkFamily:
    """Shared step of the Newmark family; subclasses provide ``beta, gamma,
    alpha_m, alpha_f, newton``."""

    def init(self, system, dt: float, make_solver, mass_solver, t0, q0, v0, a0, state0):
        """Build (and for a linear system, factorise) the effective matrix for ``dt``."""
        am, af = self.alpha_m, self.alpha_f
        S = (1.0 - am) * system.mass + ((1.0 - af) * self.beta * dt * dt) * system.stiffness
        if system.damping is not None:
            S = S + ((1.0 - af) * self.gamma * dt) * system.damping
        S = S.tocsr()
        cache = NewmarkCache(dt=float(dt), effective_matrix=S)
        if system.nonlinear is None:
            cache.solver = make_solver(S, spd=True)
        else:
            cache.nonlinear = ImplicitSolve(system, S, (1.0 - af) * self.beta * dt * dt,
                                            (1.0 - af) * self.gamma * dt, 1.0, make_solver, self.newton)
            cache.details = cache.nonlinear.details   # the same dict: running totals show in the summary
        return cache

    def step(self, system, cache: NewmarkCache, t, q, v, a, state):
        """One step from ``(t, q, v, a)``: returns ``(q1, v1, a1, state1, newton_iterations)``."""
        h, beta, gamma, af = cache.dt, self.beta, self.gamma, self.alpha_f
        q_pred = q + h * v + ((0.5 - beta) * h * h) * a
        v_pred = v + ((1.0 - gamma) * h) * a
        t_balance = t + (1.0 - af) * h
        rhs = self._linear_rhs(system, t_balance, q, v, a, q_pred, v_pred)
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

    def _linear_rhs(self, system, t_balance, q, v, a, q_pred, v_pred):
        am, af = self.alpha_m, self.alpha_f
        q_bal = q_pred if af == 0.0 else (1.0 - af) * q_pred + af * q
        rhs = -(system.stiffness @ q_bal)
        if system.damping is not None:
            v_bal = v_pred if af == 0.0 else (1.0 - af) * v_pred + af * v
            rhs -= system.damping @ v_bal
        if am != 0.0:
            rhs -= am * (system.mass @ a)
        f = system.external_force(t_balance)
        return rhs if f is None else rhs + f


@register_scheme("newmark")
@dataclass(frozen=True)
class Newmark(_NewmarkFamily):
    r"""Newmark's method; the default ``beta = 1/4, gamma = 1/2`` is average acceleration.

    Average acceleration is implicit, unconditionally stable, second order,
    and conserves ``v^T M v / 2 + q^T K q / 2`` exactly for a linear undamped
    system (it is the trapezoidal rule, equivalent to the midpoint rule there).
    Second order needs ``gamma = 1/2``; ``gamma > 1/2`` adds first-order
    numerical damping.

    Attributes
    ----------
    beta, gamma : float
        Newmark parameters.
    newton : Newton
        Tolerances for nonlinear systems.
    """

    beta: float = 0.25
    gamma: float = 0.5
    newton: Newton = Newton()

    alpha_m = 0.0
    alpha_f = 0.0

    def __post_init__(self):
        if self.beta < 0 or self.gamma < 0:
            raise ValueError(f"Newmark needs beta, gamma >= 0, got {self.beta}, {self.gamma}")

    @classmethod
    def from_config(cls, time_config) -> "Newmark":
        """Average acceleration (a scene's ``integrator = "newmark"``)."""
        return cls()

    @property
    def order(self) -> int:
        return 2 if self.gamma == 0.5 else 1

    @property
    def name(self) -> str:
        if (self.beta, self.gamma) == (0.25, 0.5):
            return "NewmarkAverageAcceleration"
        return f"Newmark(beta={self.beta:g}, gamma={self.gamma:g})"


def NewmarkAverageAcceleration(newton: Newton = Newton()) -> Newmark:
    """Newmark with ``beta = 1/4, gamma = 1/2`` (trapezoidal rule)."""
    return Newmark(beta=0.25, gamma=0.5, newton=newton)


@register_scheme("generalized_alpha")
@dataclass(frozen=True)
class GeneralizedAlpha(_NewmarkFamily):
    r"""Generalized-alpha (Chung & Hulbert 1993) with high-frequency spectral radius ``rho_inf``.

    Parameters from ``rho = spectral_radius`` in [0, 1] (optimal high-frequency
    dissipation, second order):

        alpha_m = (2 rho - 1) / (rho + 1),  alpha_f = rho / (rho + 1),
        gamma = 1/2 - alpha_m + alpha_f,    beta = (1 - alpha_m + alpha_f)^2 / 4.

    ``rho_inf = 1`` is average acceleration; smaller values damp the highest
    modes more. The ``a`` it carries is an *algorithmic* acceleration: it is a
    second-order approximation of ``q''`` at ``t + (alpha_m - alpha_f) dt``,
    not at ``t`` (Arnold & Brüls, Multibody Syst. Dyn. 18:185-202, 2007).
    """

    spectral_radius: float = 1.0
    newton: Newton = Newton()

    order = 2

    def __post_init__(self):
        if not 0.0 <= self.spectral_radius <= 1.0:
            raise ValueError(f"spectral_radius must lie in [0, 1], got {self.spectral_radius}")

    @classmethod
    def from_config(cls, time_config) -> "GeneralizedAlpha":
        """With ``[time] spectral_radius``."""
        return cls(spectral_radius=time_config.spectral_radius)

    @property
    def alpha_m(self) -> float:
        rho = self.spectral_radius
        return (2.0 * rho - 1.0) / (rho + 1.0)

    @property
    def alpha_f(self) -> float:
        rho = self.spectral_radius
        return rho / (rho + 1.0)

    @property
    def gamma(self) -> float:
        return 0.5 - self.alpha_m + self.alpha_f

    @property
    def beta(self) -> float:
        return 0.25 * (1.0 - self.alpha_m + self.alpha_f) ** 2

    @property
    def name(self) -> str:
        return f"GeneralizedAlpha(rho_inf={self.spectral_radius:g})"
