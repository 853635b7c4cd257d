r"""Generalized-alpha (Chung & Hulbert, J. Appl. Mech. 60:371-375, 1993)."""

from __future__ import annotations

from dataclasses import dataclass

from femrom._errors import FemromValueError
from femrom.integrators._newton import Newton
from femrom.integrators._scheme import register_scheme
from femrom.integrators.schemes.newmark import NewmarkFamily


@register_scheme
@dataclass(frozen=True)
class GeneralizedAlpha(NewmarkFamily):
    r"""Generalized-alpha with high-frequency spectral radius ``rho_inf``.

    Parameters from ``rho = spectral_radius`` in [0, 1] (optimal high-frequency
    dissipation, second order):

    .. math::

        \alpha_m = \frac{2\rho - 1}{\rho + 1}, \quad \alpha_f = \frac{\rho}{\rho + 1}, \quad
        \gamma = \tfrac12 - \alpha_m + \alpha_f, \quad \beta = \tfrac14 (1 - \alpha_m + \alpha_f)^2.

    ``rho_inf = 1`` is average acceleration; smaller values damp the highest
    modes more. The ``a`` it carries is an *algorithmic* acceleration: a
    second-order approximation of ``q''`` at ``t + (alpha_m - alpha_f) dt``,
    not at ``t`` (Arnold & Bruls, Multibody Syst. Dyn. 18:185-202, 2007). The
    forcing is sampled at ``t + (1 - alpha_f) h``; the frequency map is the
    step map's (:meth:`~femrom.integrators.Scheme.frequency`).
    """

    spectral_radius: float = 1.0
    newton: Newton = Newton()

    name = "generalized_alpha"
    order = 2
    physical_acceleration = False

    def __post_init__(self):
        if not 0.0 <= self.spectral_radius <= 1.0:
            raise FemromValueError(f"spectral_radius must lie in [0, 1], got {self.spectral_radius}")

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
    def input_time(self) -> float:  # type: ignore[override]
        return 1.0 - self.alpha_f

    @property
    def label(self) -> str:
        return f"GeneralizedAlpha(rho_inf={self.spectral_radius:g})"
