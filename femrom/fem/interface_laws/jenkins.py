r"""The Jenkins interface law: a tangential spring and a Coulomb slider of fixed slip traction."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom.fem._interface_law import ParallelSliderLaw, check_parameters, register_interface_law


@register_interface_law
@dataclass(frozen=True)
class JenkinsLaw(ParallelSliderLaw):
    r"""Jenkins element per contact point: spring ``k_t`` in series with a slider of slip traction ``tau_s``.

    .. math::

        t_t = \operatorname{proj}_{|t| \le \tau_s}\big(k_t (g_t - z)\big), \qquad t_n = k_n g_n,

    with the 2-D radial return (slip along the trial traction) and the slider
    position ``z`` (s, 2) committed after a converged step. The slip traction
    does not depend on the normal pressure (a bolted joint whose pressure is
    set by the preload). Along one tangential direction the loop is the
    elastic-perfectly-plastic (Masing) loop: slip starts at ``|g_t - z| =
    tau_s / k_t``, and a cycle of amplitude ``x_a > tau_s / k_t`` dissipates
    ``4 tau_s (x_a - tau_s / k_t)`` per unit area.

    Parameters
    ----------
    tangential_stiffness : float
        ``k_t > 0`` [Pa/m]: stiffness per unit area of the stuck interface.
    slip_traction : float
        ``tau_s > 0`` [Pa]: tangential traction at which the slider slips.
    normal_stiffness : float
        ``k_n >= 0`` [Pa/m]: linear (bilateral) normal spring; 0 leaves the normal free.
    """

    name = "jenkins"

    tangential_stiffness: float
    slip_traction: float
    normal_stiffness: float = 0.0

    def __post_init__(self):
        check_parameters(self, (("tangential_stiffness", "> 0", lambda v: v > 0),
                                ("slip_traction", "> 0", lambda v: v > 0),
                                ("normal_stiffness", ">= 0", lambda v: v >= 0)))
        object.__setattr__(self, "slider_stiffness", np.array([self.tangential_stiffness]))
        object.__setattr__(self, "slider_strength", np.array([self.slip_traction]))
