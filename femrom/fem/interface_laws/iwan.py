r"""Segalman's four-parameter Iwan law, discretised into parallel Jenkins elements."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom.fem._interface_law import ParallelSliderLaw, check_parameters, register_interface_law


@register_interface_law
@dataclass(frozen=True)
class IwanLaw(ParallelSliderLaw):
    r"""The 4-parameter Iwan element of Segalman (J. Appl. Mech. 72 (2005) 752-760) per contact point.

    An Iwan element is a continuum of Jenkins elements in parallel; the one of
    *slip displacement* ``phi`` (it slips when its spring is stretched by
    ``phi``) has stiffness density ``rho(phi) dphi``, and Segalman's
    density is a truncated power law plus a delta at the top,

    .. math::

        \rho(\phi) = R \phi^\chi \, [H(\phi) - H(\phi - \phi_{max})] + S \delta(\phi - \phi_{max}).

    Under monotone loading from a virgin state (1-D) the traction is
    ``t(u) = int_0^u phi rho dphi + u int_u^inf rho dphi``, i.e.

    .. math::

        t(u) = K_T u - \frac{R\, u^{\chi + 2}}{(\chi + 1)(\chi + 2)} \quad (u < \phi_{max}), \qquad
        t(u) = F_S \quad (u \ge \phi_{max}),

    and a cycle of amplitude ``u_a < phi_max`` dissipates
    ``D = 4 R u_a^{chi + 3} / ((chi + 2)(chi + 3))`` per unit area: a power
    law of exponent ``3 + chi`` in the amplitude (in the force amplitude
    ``t_a ~ K_T u_a`` as ``u_a -> 0``). From the four parameters (Segalman's
    eqs. for ``phi_max``, ``R``, ``S``):

    .. math::

        \phi_{max} = \frac{F_S (1 + \beta)}{K_T (\beta + \frac{\chi + 1}{\chi + 2})}, \quad
        R = \frac{F_S (\chi + 1)}{\phi_{max}^{\chi + 2} (\beta + \frac{\chi + 1}{\chi + 2})}, \quad
        S = \frac{F_S}{\phi_{max}} \frac{\beta}{\beta + \frac{\chi + 1}{\chi + 2}},

    so that ``int rho = K_T`` and ``int phi rho = F_S``.

    Discretisation. As Segalman proposes, ``[0, phi_max]`` is cut into
    ``n_sliders`` intervals whose lengths grow geometrically with ratio
    ``alpha`` (``dphi_m = dphi_1 alpha^(m-1)``), fine where the weak sliders
    that dissipate at small amplitude are. Each interval becomes one Jenkins
    element whose stiffness and slip traction are the interval's exact
    moments, ``k_m = int rho dphi`` and ``f_m = int phi rho dphi`` (in
    closed form for the power law), and the delta one more element (``k =
    S``, ``f = S phi_max``, omitted when ``beta = 0``). The moments make the
    discrete element keep ``K_T`` and ``F_S`` exactly (the stuck stiffness and
    the macro-slip traction) and slip fully at ``u = phi_max``, as the
    continuous one does; in between the backbone and the dissipation carry
    a discretisation error set by ``alpha`` (measured in docs/joint.md). In 2-D
    every element is an isotropic Jenkins element with a radial return
    (:class:`femrom.fem.JenkinsLaw`), acting on both tangential directions;
    the normal is a linear spring.

    Parameters
    ----------
    slip_traction : float
        ``F_S > 0`` [Pa]: traction at macro-slip.
    tangential_stiffness : float
        ``K_T > 0`` [Pa/m]: stiffness per unit area at vanishing load.
    chi : float
        ``-1 < chi`` [-]: exponent of the density (the dissipation grows as the
        amplitude to ``3 + chi``; lap joints give ``-1 < chi < 0``).
    beta : float
        ``beta >= 0`` [-]: weight of the delta, ``S / (R phi_max^(chi+1) / (chi+1))``
        (0: the traction reaches ``F_S`` smoothly).
    normal_stiffness : float
        ``k_n >= 0`` [Pa/m]: linear (bilateral) normal spring.
    n_sliders : int
        ``>= 1``: Jenkins elements for the power-law part (default 60).
    alpha : float
        ``>= 1``: ratio of successive interval lengths (default 1.2; 1 is uniform).

    State: (s, N, 2) positions of the N Jenkins elements' sliders (N = ``n_sliders``, + 1 with the delta).
    """

    name = "iwan"

    slip_traction: float
    tangential_stiffness: float
    chi: float
    beta: float
    normal_stiffness: float = 0.0
    n_sliders: int = 60
    alpha: float = 1.2

    def __post_init__(self):
        check_parameters(self, (("slip_traction", "> 0", lambda v: v > 0),
                                ("tangential_stiffness", "> 0", lambda v: v > 0),
                                ("chi", "> -1", lambda v: v > -1),
                                ("beta", ">= 0", lambda v: v >= 0),
                                ("normal_stiffness", ">= 0", lambda v: v >= 0),
                                ("n_sliders", "an integer >= 1", lambda v: v >= 1 and v == int(v)),
                                ("alpha", ">= 1", lambda v: v >= 1)))
        F, K, chi, beta = self.slip_traction, self.tangential_stiffness, self.chi, self.beta
        c = (chi + 1.0) / (chi + 2.0)
        phi_max = F * (1.0 + beta) / (K * (beta + c))
        R = F * (chi + 1.0) / (phi_max ** (chi + 2.0) * (beta + c))
        S = F * beta / (phi_max * (beta + c))
        N, a = self.n_sliders, self.alpha
        lengths = a ** np.arange(N) if a > 1.0 else np.ones(N)
        nodes = np.concatenate([[0.0], np.cumsum(lengths)]) * (phi_max / lengths.sum())
        nodes[-1] = phi_max
        stiffness = R * np.diff(nodes ** (chi + 1.0)) / (chi + 1.0)
        strength = R * np.diff(nodes ** (chi + 2.0)) / (chi + 2.0)
        if beta > 0.0:
            stiffness, strength = np.append(stiffness, S), np.append(strength, S * phi_max)
        for key, value in (("phi_max", phi_max), ("density_coefficient", R), ("delta_stiffness", S),
                           ("slider_stiffness", stiffness), ("slider_strength", strength),
                           ("slider_nodes", nodes)):
            object.__setattr__(self, key, value)

    def backbone(self, u) -> np.ndarray:
        r"""The continuous element's virgin traction ``t(u)`` (closed form above), odd in ``u``."""
        u = np.abs(np.asarray(u, dtype=float))
        chi, R = self.chi, self.density_coefficient
        inside = self.tangential_stiffness * u - R * u ** (chi + 2.0) / ((chi + 1.0) * (chi + 2.0))
        return np.sign(u) * np.where(u < self.phi_max, inside, self.slip_traction)

    def cycle_dissipation(self, amplitude) -> np.ndarray:
        r"""The continuous element's dissipation per cycle at displacement amplitude ``u_a``.

        ``4 R u_a^(chi+3) / ((chi+2)(chi+3))`` below ``phi_max``; above it every
        slider slips and ``D = 4 F_S u_a - 4 int phi^2 rho dphi =
        4 F_S u_a - 4 (R phi_max^(chi+3) / (chi+3) + S phi_max^2)``.
        """
        u = np.abs(np.asarray(amplitude, dtype=float))
        chi, R, S, p = self.chi, self.density_coefficient, self.delta_stiffness, self.phi_max
        micro = 4.0 * R * u ** (chi + 3.0) / ((chi + 2.0) * (chi + 3.0))
        macro = 4.0 * self.slip_traction * u - 4.0 * (R * p ** (chi + 3.0) / (chi + 3.0) + S * p * p)
        return np.where(u < p, micro, macro)
