r"""Central difference in velocity form (Stoermer-Verlet): explicit, second order, symplectic.

With ``h = dt`` and ``F(t, q, v) = B u(t) - C v - K q - f(q, v)``:

.. math::

    v_{n+1/2} = v_n + \tfrac{h}{2} a_n, \qquad q_{n+1} = q_n + h v_{n+1/2}, \qquad
    M a_{n+1} = F(t_{n+1}, q_{n+1}, v_{n+1}), \qquad v_{n+1} = v_{n+1/2} + \tfrac{h}{2} a_{n+1}.

Damping enters through ``v_{n+1}``, which depends on ``a_{n+1}``:

- a diagonal ``C`` (mass-proportional) with a diagonal mass, or any ``C`` of a small
  dense model: solved exactly, still explicit, ``(M + h/2 C) a_{n+1} = F_{n+1} - K
  q_{n+1} - f - C v_{n+1/2}``; the scheme is Newmark ``beta = 0, gamma = 1/2`` and
  stays **second order**;
- a non-diagonal sparse ``C`` (Rayleigh with a ``K`` part) of the full model: lagged,
  ``C v_{n+1/2}`` replaces ``C v_{n+1}``, an ``O(h)`` force error per step: **first
  order** in the damping term, and the stable step shrinks to about ``(2 / omega)
  (sqrt(1 + zeta^2) - zeta)`` for a mode of damping ratio ``zeta``.

A velocity-dependent ``f`` is lagged at the half step. The full model needs a
diagonal (lumped) mass: only it is "solved". Stability needs ``h <= 2 / omega_max``;
:meth:`CentralDifference.init` bounds ``omega_max`` (of ``K``, plus the nonlinear
tangent at the initial state) from above and refuses a larger step. Lanczos alone
approaches ``omega_max`` from below, so ``2 / estimate`` could let through a step
slightly past the true bound; the check uses ``omega_upper = sqrt(theta + ||r||)``
from the Ritz pair's residual (capped by Gershgorin's bound), see
:mod:`femrom.integrators._stability`; a small dense model's bound is exact. An
undamped mode of frequency ``omega`` is stepped at ``Omega = (2 / h) arcsin(omega h / 2)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.integrators._scheme import Scheme, dense_model, register_scheme
from femrom.integrators._stability import bound_max_frequency, central_difference_bound
from femrom.integrators.schemes._canonical import drift, kick
from femrom.solvers import is_diagonal


def verlet_bound(M, K) -> float:
    """``2 / omega_max`` of the dense pair ``(K, M)``: the Stoermer-Verlet stability limit."""
    w2 = sl.eigvals(K, M).real
    top = float(np.max(w2)) if w2.size else 0.0
    return np.inf if top <= 0 else 2.0 / np.sqrt(top)


@dataclass
class CentralDifferenceCache:
    """``dt``, the (damped) mass solve, the lagged damping, ``omega_max``."""

    dt: float
    inverse_mass: Any = None
    dense_factor: Any = None
    lagged_damping: Any = None
    diagonal_damping: np.ndarray | None = None
    omega_max: float | None = None
    details: dict | None = None


@register_scheme
@dataclass(frozen=True)
class CentralDifference(Scheme):
    """Explicit central difference / velocity Stoermer-Verlet (module docstring).

    Attributes
    ----------
    check_stability : bool
        Bound ``omega_max`` from above before stepping and raise if
        ``dt > 2 / omega_upper``. Turn off only to study an unstable run.
    """

    check_stability: bool = True

    name = "central_difference"
    aliases = ("verlet",)
    order = 2
    models = ("second_order", "canonical")
    input_time = 1.0

    @property
    def label(self) -> str:
        return "CentralDifference"

    def supports(self, system):
        if not dense_model(system) and not is_diagonal(system.mass):
            return "the full model needs a diagonal (lumped) mass matrix; this mass has off-diagonal entries"
        return None

    def frequency(self, omega, dt):
        x = 0.5 * np.asarray(omega, dtype=float) * dt
        if np.any(x > 1.0):
            raise FemromValueError(f"omega dt / 2 exceeds 1: central difference is unstable at dt = {dt:g}")
        return 2.0 / dt * np.arcsin(x)

    def continuous_frequency(self, Omega, dt):
        Omega = np.asarray(Omega, dtype=float)
        if np.any(Omega * dt > np.pi) or np.any(Omega < 0):
            raise FemromValueError(f"discrete frequencies must lie in [0, pi / dt] = [0, {np.pi / dt:g}] rad/s")
        return 2.0 / dt * np.sin(0.5 * Omega * dt)

    def check_step(self, parts, dt):
        if not self.check_stability:
            return
        K = parts.stiffness
        bound = verlet_bound(parts.mass, 0.5 * (K + K.T))
        if dt > bound:
            raise FemromValueError(f"dt = {dt:.6g} exceeds the Stoermer-Verlet bound "
                                   f"2/omega_max = {bound:.6g} of the reduced model")

    def init(self, system, dt: float, make_solver, mass_solver, t0, q0, v0, a0, state0):
        """Check the mass (diagonal for the full model) and that ``dt`` is stable; set up the mass solve."""
        self.check(system)
        cache = CentralDifferenceCache(dt=float(dt), details={})
        if dense_model(system):
            from femrom.integrators._scheme import LinearParts

            parts = LinearParts.of(system)
            cache.dense_factor = sl.lu_factor(parts.mass + 0.5 * dt * parts.damping_matrix)
            cache.details["damping"] = "implicit in v (second order)"
            self.check_step(parts, dt)
            return cache
        m = np.asarray(system.mass.diagonal(), dtype=float)
        cache.inverse_mass = 1.0 / m
        C = system.damping
        if C is not None:
            if is_diagonal(C):
                c = np.asarray(C.diagonal(), dtype=float)
                cache.diagonal_damping = c
                cache.inverse_mass = 1.0 / (m + 0.5 * dt * c)
                cache.details["damping"] = "diagonal, implicit in v (second order)"
            else:
                cache.lagged_damping = sp.csr_matrix(C)
                cache.details["damping"] = "lagged half-step velocity (first order in C)"
        if self.check_stability:
            K = system.stiffness
            if system.nonlinear is not None:
                dfdq, _ = system.nonlinear.tangent(q0, v0, state0)
                if dfdq is not None:
                    K = K + dfdq
            omega = bound_max_frequency(K, system.mass)
            bound = central_difference_bound(omega.upper)
            cache.omega_max = omega.upper
            cache.details.update(omega_max=omega.estimate, omega_max_upper=omega.upper,
                                 omega_max_bound=omega.method, stability_bound=bound)
            if dt > bound:
                raise FemromValueError(
                    f"dt = {dt:.6g} exceeds the central-difference stability bound "
                    f"2/omega_max = {bound:.6g} (omega_max <= {omega.upper:.6g} rad/s, "
                    f"{omega.method} bound; estimate {omega.estimate:.6g})")
        return cache

    def step(self, system, cache: CentralDifferenceCache, t, q, v, a, state, force, force_end=None):
        """One explicit step: returns ``(q1, v1, a1, state1, 0)``."""
        h = cache.dt
        v_half = v + (0.5 * h) * a
        q1 = q + h * v_half
        rhs = -(system.stiffness @ q1)
        if system.nonlinear is not None:
            rhs -= system.nonlinear.force(q1, v_half, state)
        if cache.dense_factor is not None:
            if system.damping is not None:
                rhs -= system.damping @ v_half
            if force is not None:
                rhs += force
            a1 = sl.lu_solve(cache.dense_factor, rhs, check_finite=False)
        else:
            if cache.diagonal_damping is not None:
                rhs -= cache.diagonal_damping * v_half
            elif cache.lagged_damping is not None:
                rhs -= cache.lagged_damping @ v_half
            if force is not None:
                rhs += force
            a1 = cache.inverse_mass * rhs
        v1 = v_half + (0.5 * h) * a1
        state1 = state if system.nonlinear is None else system.nonlinear.commit(q1, v1, state)
        return q1, v1, a1, state1, 0

    def canonical_step_matrix(self, position, momentum, dt):
        """Stoermer-Verlet of a separable ``H``: half kick, drift, half kick."""
        h = float(dt)
        return kick(position, h, 0.5) @ drift(momentum, h, 1.0) @ kick(position, h, 0.5)

    def step_map(self, parts, dt, forcing):
        """``x = [q; v; a]``: ``q_{n+1} = P_q x``, ``(M + h C / 2) a_{n+1} = F - K q_{n+1} - C v_{n+1/2}``."""
        from femrom.integrators._scheme import solve_matrix

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
