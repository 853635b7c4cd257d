"""``[material]``, one isotropic material, and ``[materials]``, a material per region of the mesh
resolved to constants per element.

A scene with several materials names them by the physical volumes of its
geometry::

    [materials.body]
    regions = ["head"]
    youngs_modulus = 2.0e6
    poisson_ratio = 0.45
    density = 1120.0

    [materials.tail]            # no 'regions': the region named like the table
    youngs_modulus = 1.25e5
    poisson_ratio = 0.45
    density = 1120.0

:func:`element_materials` gives every element of the mesh the constants of the
one material whose regions hold it; the builder passes the result
(:class:`femrom.fem.ElementMaterial`) to every effect that reads the material
(inertia, elasticity, and through their matrices Rayleigh damping and the
conditioning check).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from femrom import fem
from femrom.scene._errors import SceneError
from femrom.scene._tables import as_names, take_table


@dataclass(frozen=True)
class MaterialConfig:
    """Isotropic linear-elastic material (SI). Line structures use ``area`` and
    ``second_moment``: bending rigidity ``E I``, axial rigidity ``E A``, mass
    per length ``rho A``."""

    youngs_modulus: float
    density: float
    poisson_ratio: float | None = None
    area: float | None = None
    second_moment: float | None = None

    @classmethod
    def from_dict(cls, data):
        keys = {"youngs_modulus": None, "density": None, "poisson_ratio": None,
                "area": None, "second_moment": None}
        d = take_table(data, "material", keys, ("youngs_modulus", "density"))
        return cls(**material_constants(d, "material"))


def material_constants(d: dict, where: str) -> dict:
    """The material numbers of table ``[where]`` as floats (None kept), or one SceneError naming the key."""
    for k, v in d.items():
        if v is None:
            continue
        number = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        if k == "poisson_ratio":     # the elasticity form is positive definite for -1 < nu < 1/2
            if not (number and -1.0 < v < 0.5):
                raise SceneError(f"[{where}] poisson_ratio must lie in (-1, 0.5), got {v!r}")
        elif not (number and v > 0):
            raise SceneError(f"[{where}] {k} must be a finite positive number, got {v!r}")
    return {k: (None if v is None else float(v)) for k, v in d.items()}


@dataclass(frozen=True)
class RegionMaterialConfig:
    """One entry of ``[materials]``: an isotropic solid material on named regions (SI).

    ``[materials.<label>]`` gives ``youngs_modulus``, ``poisson_ratio``,
    ``density`` and optionally ``regions``, the physical volumes of the mesh it
    fills (default: the one region named ``label``). Every element of the
    mesh must get exactly one material (checked when the scene is built,
    :func:`femrom.scene.element_materials`).
    """

    label: str
    regions: tuple[str, ...]
    youngs_modulus: float
    poisson_ratio: float
    density: float


def materials_from_dict(data) -> tuple[RegionMaterialConfig, ...]:
    """``[materials]``: a table of material tables, each on its regions; a region listed twice is an error."""
    if not isinstance(data, dict) or not data:
        raise SceneError("[materials] must be a table of [materials.<region>] tables, e.g. "
                         "[materials.body] youngs_modulus = 2e6, poisson_ratio = 0.45, density = 1100")
    materials, owner = [], {}
    for label, table in data.items():
        where = f"materials.{label}"
        d = take_table(table, where, {"youngs_modulus": None, "poisson_ratio": None, "density": None,
                                 "regions": [label]}, ("youngs_modulus", "poisson_ratio", "density"))
        regions = as_names(d.pop("regions"), f"{where}.regions")
        for region in regions:
            if region in owner:
                raise SceneError(f"[materials] region {region!r} has two materials: "
                                 f"[materials.{owner[region]}] and [{where}]")
            owner[region] = label
        materials.append(RegionMaterialConfig(label, regions, **material_constants(d, where)))
    return tuple(materials)


def element_materials(materials, mesh) -> fem.ElementMaterial:
    """The constants of ``materials`` on every element of ``mesh``, each element covered exactly once.

    Parameters
    ----------
    materials : sequence of RegionMaterialConfig
        The scene's ``[materials]`` entries.
    mesh : skfem.Mesh
        A mesh whose ``subdomains`` (physical volumes) the entries name.

    Returns
    -------
    ElementMaterial
        ``(n_elements,)`` arrays of Young's modulus, Poisson ratio and density.

    Raises
    ------
    SceneError
        One line naming the culprit: a region the mesh does not have (listing the
        ones it has), a region whose elements another material's region also holds
        (overlapping physical volumes), or a region (or elements in no region) that
        no material covers.
    """
    subdomains = {name: np.asarray(elements) for name, elements in (mesh.subdomains or {}).items()}
    available = ", ".join(sorted(subdomains)) or "none"
    n = mesh.nelements
    owner = np.full(n, -1)
    values = np.zeros((3, n))
    for index, material in enumerate(materials):
        for region in material.regions:
            if region not in subdomains:
                raise SceneError(f"[materials.{material.label}] unknown region {region!r}; "
                                 f"the mesh's regions: {available}")
            elements = subdomains[region]
            taken = owner[elements]
            if np.any(taken >= 0):
                first = int(taken[taken >= 0][0])
                other = materials[first]
                shared = int(np.count_nonzero(taken == first))
                raise SceneError(f"[materials.{material.label}] region {region!r} overlaps a region of "
                                 f"[materials.{other.label}] ({', '.join(other.regions)}): {shared} elements "
                                 "in both; each element needs exactly one material")
            owner[elements] = index
            values[:, elements] = np.array([[material.youngs_modulus], [material.poisson_ratio],
                                            [material.density]])
    missing = owner < 0
    if np.any(missing):
        for region in sorted(subdomains):
            uncovered = int(np.count_nonzero(missing[subdomains[region]]))
            if uncovered:
                raise SceneError(f"[materials] region {region!r} has no material ({uncovered} elements); "
                                 "list it under the regions of a [materials.<name>] table")
        raise SceneError(f"[materials] {int(missing.sum())} elements lie in no named region of the mesh, "
                         "so no material reaches them; name every volume of the geometry "
                         "(Physical Volume) or use [material]")
    return fem.ElementMaterial(*values)

