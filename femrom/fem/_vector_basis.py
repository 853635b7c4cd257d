r"""What the loads, outputs and constraints of a displacement field share: a vector basis's named
regions, its components and the locations of its nodes.

Everything lives on the full dof numbering of a vector basis
``skfem.Basis(mesh, ElementVector(ElementTetP1() or ElementTetP2()))``
(``n_total = basis.N``; component ``c`` of scalar node ``s`` is dof ``3 s + c``).
Regions are looked up by name in ``mesh.boundaries`` (facets) and
``mesh.subdomains`` (elements) through :mod:`femrom.mesh`; an unknown name
raises ``MeshError`` listing the valid ones.
"""

from __future__ import annotations

import numpy as np
import skfem

from femrom._errors import FemromValueError
from femrom.fem._elasticity import _scalar_element
from femrom.mesh import boundary_facets, subdomain_elements


def named_facets(mesh, name: str) -> np.ndarray:
    """Facets of a named boundary; MeshError listing the valid names otherwise."""
    return np.asarray(boundary_facets(mesh, name))


def named_elements(mesh, name: str) -> np.ndarray:
    """Elements of a named subdomain; MeshError listing the valid names otherwise."""
    return np.asarray(subdomain_elements(mesh, name))


def check_component(component: int) -> int:
    """``component`` (0, 1 or 2 for x, y, z) as an int, or one FemromValueError."""
    if component not in (0, 1, 2):
        raise FemromValueError(f"component must be 0, 1 or 2 (x, y, z), got {component!r}")
    return int(component)


def facet_basis(basis, facets: np.ndarray) -> skfem.FacetBasis:
    """Vector facet basis with the same element and dof numbering as ``basis``."""
    return skfem.FacetBasis(basis.mesh, basis.elem, facets=facets)


def node_locations(basis) -> np.ndarray:
    """(n_nodes, 3) ndarray: location of each scalar node (vertex or edge midpoint)."""
    elem = _scalar_element(basis)
    mesh = basis.mesh
    element_dofs = basis.dofs.element_dofs[0::3] // 3  # (n_local, n_elements), whole mesh
    p = mesh.p
    x0 = p[:, mesh.t[0]]
    A = np.stack([p[:, mesh.t[k]] - x0 for k in (1, 2, 3)], axis=1)  # (3 [x], 3 [k], n_e)
    locations = np.zeros((basis.N // 3, 3))
    for a, X in enumerate(elem.doflocs):  # reference coordinates of local node a
        locations[element_dofs[a]] = (x0 + np.einsum("xke,k->xe", A, X)).T
    return locations
