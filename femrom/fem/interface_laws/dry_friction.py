r"""Elastic dry friction: a unilateral normal penalty and an elastic Coulomb slider (2-D radial return)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom.fem._interface_law import (
    InterfaceLaw,
    check_parameters,
    radial_return,
    radial_return_tangent,
    register_interface_law,
    split_gap,
)


@register_interface_law
@dataclass(frozen=True)
class DryFrictionLaw(InterfaceLaw):
    r"""Penalty contact with elastic Coulomb friction per contact point.

    .. math::

        p = k_n \max(-g_n, 0), \qquad t_n = -p, \qquad
        t_t = \operatorname{proj}_{|t| \le \mu p}\big(k_t (g_t - z)\big),

    the normal traction a penalty on the penetration (zero when open,
    ``g_n >= 0``), the tangential one a spring ``k_t`` in series with a
    Coulomb slider whose limit is ``mu p``, returned radially (slip along the
    trial traction, so the traction stays on the cone ``|t_t| = mu p``).
    Committing sets ``z = g_t - t_t / k_t`` (an open point's slider follows
    the gap: its spring is unloaded). The consistent tangent couples the
    normal into the tangential traction while slipping:
    ``dt_t / dg_n = -mu k_n d`` (``d`` the slip direction) for a closed point,
    so it is not symmetric.

    Parameters
    ----------
    normal_stiffness : float
        ``k_n > 0`` [Pa/m]: contact pressure per unit penetration.
    tangential_stiffness : float
        ``k_t > 0`` [Pa/m]: tangential stiffness per unit area while stuck.
    friction_coefficient : float
        ``mu >= 0`` [-]: Coulomb coefficient (0: frictionless contact).

    State: (s, 2) slider positions ``z``.
    """

    name = "dry_friction"

    normal_stiffness: float
    tangential_stiffness: float
    friction_coefficient: float

    def __post_init__(self):
        check_parameters(self, (("normal_stiffness", "> 0", lambda v: v > 0),
                                ("tangential_stiffness", "> 0", lambda v: v > 0),
                                ("friction_coefficient", ">= 0", lambda v: v >= 0)))

    def initial_state(self, n_points: int) -> np.ndarray:
        return np.zeros((int(n_points), 2))

    def _slider(self, gap, state):
        g_t, g_n = split_gap(gap)
        closed = g_n < 0.0
        pressure = np.where(closed, -self.normal_stiffness * g_n, 0.0)
        trial = self.tangential_stiffness * (g_t - state)
        return g_t, g_n, closed, pressure, trial, radial_return(trial, self.friction_coefficient * pressure)

    def evaluate(self, gap, state, tangent=True):
        g_t, g_n, closed, pressure, _, (t, ratio, direction, slipping) = self._slider(gap, state)
        traction = np.empty((g_n.size, 3))
        traction[:, :2] = t
        traction[:, 2] = -pressure
        if not tangent:
            return traction, None
        D = np.zeros((g_n.size, 3, 3))
        D[:, :2, :2] = self.tangential_stiffness * radial_return_tangent(ratio, direction, slipping)
        # slipping: t_t = mu p d, dp/dg_n = -k_n where closed
        coupling = slipping & closed
        D[:, :2, 2] = np.where(coupling[:, None], -self.friction_coefficient * self.normal_stiffness * direction, 0.0)
        D[:, 2, 2] = np.where(closed, self.normal_stiffness, 0.0)
        return traction, D

    def commit(self, gap, state):
        g_t, *_rest, (t, _, _, _) = self._slider(gap, state)
        return g_t - t / self.tangential_stiffness

    def dissipation(self, gap, state):
        *_rest, trial, (t, _, _, _) = self._slider(gap, state)
        return np.einsum("si,si->s", t, (trial - t) / self.tangential_stiffness)

    def stored_energy(self, gap, state):
        g_t, g_n = split_gap(gap)
        slip = g_t - state
        return 0.5 * self.tangential_stiffness * np.einsum("si,si->s", slip, slip) \
            + 0.5 * self.normal_stiffness * np.minimum(g_n, 0.0) ** 2
