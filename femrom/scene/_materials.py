"""``[materials]``: a material per region of the mesh, resolved to constants per element.

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

import numpy as np

from femrom import fem
from femrom.scene._errors import SceneError


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

