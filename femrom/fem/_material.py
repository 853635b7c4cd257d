r"""Isotropic material constants per element: several materials on one mesh.

A solid made of regions of different materials (a soft robot's elastomer
body, stiff couples and a strain-limiting strip) has piecewise-constant
coefficients, one value per tetrahedron ``e``:

.. math::

    K = \sum_e \int_{T_e} \sigma_e(\phi_J) : \varepsilon(\phi_I)\,dx, \qquad
    \sigma_e = 2\mu_e\,\varepsilon + \lambda_e\,\mathrm{tr}(\varepsilon) I, \qquad
    M = \sum_e \rho_e \int_{T_e} \phi_I \cdot \phi_J\,dx ,

with ``(lambda_e, mu_e)`` the Lame parameters of ``(E_e, nu_e)``. Element
integrals are exact with constants per element, so the assembly takes the
arrays as they are (:func:`femrom.fem.elasticity_stiffness`,
:func:`femrom.fem.vector_mass`). :class:`SolidSpace` reads the same three
attributes from a single material (floats) or from an :class:`ElementMaterial`
(arrays).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError

__all__ = ["ElementMaterial"]


@dataclass(frozen=True, eq=False)
class ElementMaterial:
    """Young's modulus, Poisson ratio and density of every element of a mesh.

    Attributes
    ----------
    youngs_modulus : (n_elements,) ndarray
        ``E_e > 0`` (Pa), one per column of ``mesh.t``.
    poisson_ratio : (n_elements,) ndarray
        ``nu_e`` in ``(-1, 0.5)``.
    density : (n_elements,) ndarray
        ``rho_e > 0`` (kg/m^3).

    Raises
    ------
    FemromValueError
        Arrays of different shapes, not one-dimensional, or values out of range
        (the message names the attribute and its worst value).
    """

    youngs_modulus: np.ndarray
    poisson_ratio: np.ndarray
    density: np.ndarray

    def __post_init__(self):
        arrays = {}
        for name in ("youngs_modulus", "poisson_ratio", "density"):
            value = np.array(getattr(self, name), dtype=float)
            value.setflags(write=False)
            arrays[name] = value
            object.__setattr__(self, name, value)
        shapes = {value.shape for value in arrays.values()}
        if len(shapes) != 1 or arrays["density"].ndim != 1:
            raise FemromValueError(f"ElementMaterial needs three 1D arrays of one length, got shapes "
                                   f"{[v.shape for v in arrays.values()]}")
        for name in ("youngs_modulus", "density"):
            value = arrays[name]
            if value.size and not (np.all(np.isfinite(value)) and value.min() > 0):
                raise FemromValueError(f"ElementMaterial {name} must be finite and > 0, got min {value.min()}")
        nu = arrays["poisson_ratio"]
        if nu.size and not (np.all(np.isfinite(nu)) and nu.min() > -1.0 and nu.max() < 0.5):
            raise FemromValueError(f"ElementMaterial poisson_ratio must lie in (-1, 0.5), got "
                                   f"[{nu.min()}, {nu.max()}]")

    @property
    def n_elements(self) -> int:
        return int(self.density.size)

    def with_unit_density(self) -> "ElementMaterial":
        """The same elastic constants with ``rho_e = 1`` (mass matrices that are volume integrals)."""
        return ElementMaterial(self.youngs_modulus, self.poisson_ratio, np.ones(self.n_elements))
