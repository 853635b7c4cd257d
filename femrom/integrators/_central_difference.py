r"""Central difference in velocity form (Stoermer-Verlet) with a diagonal mass.

With ``h = dt`` and ``F(t, q, v) = B u(t) - C v - K q - f_nl(q, v)``:

    v_{n+1/2} = v_n + (h/2) a_n,
    q_{n+1}   = q_n + h v_{n+1/2},
    M a_{n+1} = F(t_{n+1}, q_{n+1}, v_{n+1}),
    v_{n+1}   = v_{n+1/2} + (h/2) a_{n+1}.

Explicit: only the diagonal mass is "solved". Damping enters through
``v_{n+1}``, which depends on ``a_{n+1}``:

- diagonal ``C`` (e.g. mass-proportional): solved exactly, still explicit,
  ``(M + h/2 C) a_{n+1} = B u - K q_{n+1} - f_nl - C v_{n+1/2}``; the scheme is
  Newmark ``beta = 0, gamma = 1/2`` and stays **second order**;
- non-diagonal ``C`` (e.g. Rayleigh with a ``K`` part): lagged,
  ``C v_{n+1/2}`` replaces ``C v_{n+1}``, an ``O(h)`` force error per step:
  **first order** in the damping term (second order as ``C -> 0``), and the
  stable step shrinks to about ``(2 / omega)(sqrt(1 + zeta^2) - zeta)`` for a
  mode of damping ratio ``zeta``.

A velocity-dependent ``f_nl`` is lagged the same way. Stability needs
``h <= 2 / omega_max``; :meth:`CentralDifference.init` bounds ``omega_max``
(of ``K``, plus the nonlinear tangent at the initial state) from above and
refuses a larger step. Lanczos alone approaches ``omega_max`` from below, so
``2 / estimate`` could let through a step slightly past the true bound; the
check uses ``omega_upper = sqrt(theta + ||r||)`` from the Ritz pair's residual
(capped by Gershgorin's bound), see :mod:`._stability`. With ARPACK's
``rtol = 1e-3`` this margin costs at most about 0.05 % of the step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from femrom.integrators._schemes import register_scheme
from femrom.integrators._stability import bound_max_frequency, central_difference_bound
from femrom.solvers import is_diagonal


@dataclass
class CentralDifferenceCache:
    """``dt``, the inverse of the (damped) diagonal mass, the lagged damping, ``omega_max``."""

    dt: float
    inverse_mass: np.ndarray
    lagged_damping: Any = None
    diagonal_damping: np.ndarray | None = None
    omega_max: float | None = None
    details: dict | None = None


@register_scheme("central_difference")
@dataclass(frozen=True)
class CentralDifference:
    """Explicit central difference / velocity Stoermer-Verlet (second order, symplectic).

    Attributes
    ----------
    check_stability : bool
        Bound ``omega_max`` from above before stepping and raise if
        ``dt > 2 / omega_upper`` (module docstring). Turn off only to study
        an unstable run.
    """

    check_stability: bool = True

    order = 2
    name = "CentralDifference"

    @classmethod
    def from_config(cls, time_config) -> "CentralDifference":
        """With the stability check (a scene's ``integrator = "central_difference"``)."""
        return cls()

    def init(self, system, dt: float, make_solver, mass_solver, t0, q0, v0, a0, state0):
        """Check the mass is diagonal and ``dt`` is stable; precompute the diagonal solve."""
        if not is_diagonal(system.mass):
            raise ValueError("CentralDifference needs a diagonal (lumped) mass matrix; "
                             "this system's mass has off-diagonal entries")
        m = np.asarray(system.mass.diagonal(), dtype=float)
        cache = CentralDifferenceCache(dt=float(dt), inverse_mass=1.0 / m, details={})
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
                raise ValueError(
                    f"dt = {dt:.6g} exceeds the central-difference stability bound "
                    f"2/omega_max = {bound:.6g} (omega_max <= {omega.upper:.6g} rad/s, "
                    f"{omega.method} bound; estimate {omega.estimate:.6g})")
        return cache

    def step(self, system, cache: CentralDifferenceCache, t, q, v, a, state):
        """One explicit step: returns ``(q1, v1, a1, state1, 0)``."""
        h = cache.dt
        v_half = v + (0.5 * h) * a
        q1 = q + h * v_half
        t1 = t + h
        force = -(system.stiffness @ q1)
        if system.nonlinear is not None:
            force -= system.nonlinear.force(q1, v_half, state)
        if cache.diagonal_damping is not None:
            force -= cache.diagonal_damping * v_half
        elif cache.lagged_damping is not None:
            force -= cache.lagged_damping @ v_half
        f_ext = system.external_force(t1)
        if f_ext is not None:
            force += f_ext
        a1 = cache.inverse_mass * force
        v1 = v_half + (0.5 * h) * a1
        state1 = state if system.nonlinear is None else system.nonlinear.commit(q1, v1, state)
        return q1, v1, a1, state1, 0
