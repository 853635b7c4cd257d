r"""Elastic dry friction: a unilateral normal penalty and an elastic Coulomb slider (2-D radial return)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom.fem._interface_law import (
    InterfaceLaw,
    check_parameters,
    radial_return,
    radial_return_derivative,
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

    For time stepping it has an energy-consistent step traction (:meth:`step_traction`): the
    normal part by the discrete gradient of the penalty potential, the tangential one a blend
    of the midpoint and the end-of-step tractions, so that a midpoint momentum balance
    (:class:`femrom.integrators.DiscreteGradient`) never creates energy when points open,
    close, stick or slip within a step.
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

    def step_traction(self, gap0, gap1, state, tangent=True):
        r"""The traction of a step from ``gap0`` to ``gap1`` that never creates energy, and its tangent in ``gap1``.

        With the penalty potential ``Psi(g_n) = k_n min(g_n, 0)^2 / 2``, the sliders' elastic slip
        ``e = g_t - z`` (stored ``W = k_t |e|^2 / 2``) and the end-of-step return map of
        :meth:`commit` (trial ``t^tr = k_t (g_{t,1} - z)``, ``t_1 = rho t^tr``, ``rho <= 1`` its
        ratio, ``e_1 = t_1 / k_t``, dissipation ``D = t_1 . (z_1 - z)``):

        .. math::

            ar t_n = rac{\Psi(g_{n,1}) - \Psi(g_{n,0})}{g_{n,1} - g_{n,0}}, \qquad
            ar t_t = rac{
ho}{2} k_t e_0 + \Big(rac12 + rac{\sigma^2}{1 + \sigma}\Big) t_1,
            \qquad \sigma = \sqrt{1 - 
ho},

        the normal part the discrete gradient (Gonzalez, J. Nonlinear Sci. 6, 1996) of ``Psi``
        (``Psi'`` of the midpoint when both ends are closed, zero when both are open), so that
        ``bar t_n (g_{n,1} - g_{n,0}) = Delta Psi`` exactly. The tangential part is the
        midpoint traction ``k_t (e_0 + e_1) / 2`` while the point sticks (``rho = 1``) and the
        end-of-step ``t_1`` when it is open or slips far (``rho -> 0``); in between, writing
        ``Delta g_t = (1 + lambda) e_1 - e_0`` with ``lambda = 1 / rho - 1`` (``z_1 - z = lambda
        e_1``),

        .. math::

            ar t_t \cdot \Delta g_t - \Delta W - D
                = rac{k_t \sigma^2}{2} \Big| e_0 - rac{e_1}{1 + \sigma} \Big|^2 \ge 0,

        a perfect square (the weights are the smallest blend from the midpoint for which the
        quadratic form in ``(e_0, e_1)`` is semidefinite). So ``bar t . Delta gap >= Delta Psi
        + Delta W + D`` whatever the step does: with a momentum balance in which the joint's
        work is ``bar t . Delta gap`` (a midpoint balance), the discrete energy never grows by
        more than the input work, and in pure stick the step is the midpoint rule's (the
        trapezoidal rule's for this piecewise linear law). The weight is ``C^1`` in ``rho``
        (``d beta / d rho = -1`` at ``rho = 1``), so the step traction is continuous across
        stick/slip and open/closed, as Newton needs. The tangential part follows Armero &
        Petocz (CMAME 158, 1998) and Laursen & Chawla (IJNME 40, 1997) in spirit: conserve what
        is elastic, dissipate through the return map.

        Parameters
        ----------
        gap0, gap1 : (s, 3) ndarray
            The local relative displacements at the step's start and end.
        state : (s, 2) ndarray
            The sliders committed at the start.
        tangent : bool
            Whether to return ``d bar t / d gap1`` too.

        Returns
        -------
        traction : (s, 3) ndarray
        D : (s, 3, 3) ndarray or None
        """
        g0_t, g0_n = split_gap(gap0)
        g_t, g_n, closed, pressure, trial, (t1, ratio, direction, slipping) = self._slider(gap1, state)
        k_t, k_n, mu = self.tangential_stiffness, self.normal_stiffness, self.friction_coefficient
        elastic0 = k_t * (g0_t - state)
        sigma = np.sqrt(np.clip(1.0 - ratio, 0.0, 1.0))
        weight = 0.5 + sigma**2 / (1.0 + sigma)
        traction = np.empty((g_n.size, 3))
        traction[:, :2] = 0.5 * ratio[:, None] * elastic0 + weight[:, None] * t1
        closed0, closed1 = g0_n < 0.0, closed
        both = closed0 & closed1
        change = g_n - g0_n
        safe = np.where(change != 0.0, change, 1.0)
        psi0, psi1 = 0.5 * k_n * np.minimum(g0_n, 0.0) ** 2, 0.5 * k_n * np.minimum(g_n, 0.0) ** 2
        mixed = closed0 ^ closed1
        traction[:, 2] = np.where(both, 0.5 * k_n * (g0_n + g_n), np.where(mixed, (psi1 - psi0) / safe, 0.0))
        if not tangent:
            return traction, None
        D = np.zeros((g_n.size, 3, 3))
        # normal: d/dg1 of the discrete gradient (k_n / 2 when both are closed; the mixed quotient's derivative)
        mixed_derivative = (np.where(closed1, k_n * g_n, 0.0) * change - (psi1 - psi0)) / safe**2
        D[:, 2, 2] = np.where(both, 0.5 * k_n, np.where(mixed, mixed_derivative, 0.0))
        # tangential: stick k_t / 2 I; slip: gamma(rho) = rho beta(rho) times the trial plus (e0 k_t / 2) rho,
        # rho = mu p / |t^tr| moving with the trial's length and the pressure
        norm = np.hypot(trial[:, 0], trial[:, 1])
        safe_norm = np.where(norm > 0.0, norm, 1.0)
        gamma = ratio * weight
        dweight = -(2.0 + sigma) / (2.0 * (1.0 + sigma) ** 2)
        w = 0.5 * elastic0 + (weight + ratio * dweight)[:, None] * trial      # d bar t_t / d rho
        eye = np.eye(2)
        slip_block = k_t * (gamma[:, None, None] * eye
                            - (ratio / safe_norm)[:, None, None] * w[:, :, None] * direction[:, None, :])
        D[:, :2, :2] = np.where(slipping[:, None, None], slip_block, 0.5 * k_t * eye)
        coupling = slipping & closed1
        D[:, :2, 2] = np.where(coupling[:, None], -(mu * k_n / safe_norm)[:, None] * w, 0.0)
        return traction, D

    def commit(self, gap, state):
        g_t, *_rest, (t, _, _, _) = self._slider(gap, state)
        return g_t - t / self.tangential_stiffness

    def step_derivative(self, gap, state, dgap, dstate):
        r"""Forward derivative of one return-map step along ``m`` directions.

        ``dgap`` (s, 3, m) and ``dstate`` (s, 2, m) are the derivatives of the gap and of the frozen
        sliders; returns ``(dtraction (s, 3, m), dz (s, 2, m))``: of the traction and of the committed
        sliders. ``dt^tr = k_t (dg_t - dz)``, the limit's ``d(mu p) = -mu k_n dg_n`` at a closed point;
        stuck: ``dt_t = dt^tr``, ``z`` kept; slipping: ``dt_t = rho (I - d d^T) dt^tr + d d(mu p)`` and
        ``dz = dg_t - dt_t / k_t`` (the committed ``z = g_t - t_t / k_t``); ``dt_n = k_n dg_n`` where closed,
        zero where open (an open point's slider follows the gap).
        """
        _, _, closed, _, _, (_, ratio, direction, slipping) = self._slider(gap, state)
        dgap = np.asarray(dgap, dtype=float)
        dstate = np.asarray(dstate, dtype=float)
        k_t = self.tangential_stiffness
        dg_t = dgap[:, :2, :]
        dlimit = np.where(closed[:, None], -self.friction_coefficient * self.normal_stiffness * dgap[:, 2], 0.0)
        dt = radial_return_derivative(k_t * (dg_t - dstate), ratio, direction, slipping, dlimit)
        dtraction = np.empty_like(dgap)
        dtraction[:, :2] = dt
        dtraction[:, 2] = np.where(closed[:, None], self.normal_stiffness * dgap[:, 2], 0.0)
        dz = np.where(slipping[:, None, None], dg_t - dt / k_t, dstate)
        return dtraction, dz

    def dissipation(self, gap, state):
        *_rest, trial, (t, _, _, _) = self._slider(gap, state)
        return np.einsum("si,si->s", t, (trial - t) / self.tangential_stiffness)

    def stored_energy(self, gap, state):
        g_t, g_n = split_gap(gap)
        slip = g_t - state
        return 0.5 * self.tangential_stiffness * np.einsum("si,si->s", slip, slip) \
            + 0.5 * self.normal_stiffness * np.minimum(g_n, 0.0) ** 2
