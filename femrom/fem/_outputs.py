r"""Outputs of a displacement field: rows of the output matrix ``E``, (p, n_total) sparse matrices
that read a component at points, over the nodes nearest to points, or averaged over a named region.

On the full dof numbering of a vector basis, regions looked up by name: as in :mod:`._vector_basis`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import skfem

from femrom._errors import FemromValueError
from femrom.fem._elasticity import _scalar_element
from femrom.fem._vector_basis import check_component, facet_basis, named_elements, named_facets, node_locations
from femrom.mesh import MeshError

__all__ = [
    "average_rows",
    "nearest_node_rows",
    "probe_rows",
]


def probe_rows(basis, points, component: int) -> sp.csr_matrix:
    r"""Rows that read one displacement component at given points.

    ``(E q)_k = u_c(x_k) = \sum_I q_I \phi_{I,c}(x_k)``, interpolated through
    the element containing ``x_k`` (skfem ``CellBasis.probes``), hence exact
    for displacement fields in the FE space (no snapping to nodes).

    Parameters
    ----------
    basis : skfem.CellBasis
        Vector P1/P2 basis on a ``MeshTet``.
    points : (p, 3) array_like
        Probe locations inside the mesh (m).
    component : int
        0, 1 or 2 for ``u_x``, ``u_y``, ``u_z``.

    Returns
    -------
    (p, n_total) scipy.sparse.csr_matrix
        At most ``n_local`` nonzeros per row, each row sums to 1 over the dofs
        of ``component`` (partition of unity).
    """
    _scalar_element(basis)
    c = check_component(component)
    x = np.atleast_2d(np.asarray(points, dtype=float))
    if x.ndim != 2 or x.shape[1] != 3:
        raise FemromValueError(f"points must have shape (p, 3), got {np.shape(points)}")
    try:
        P = basis.probes(x.T).tocsr()
    except ValueError as err:
        lo, hi = basis.mesh.p.min(axis=1), basis.mesh.p.max(axis=1)
        raise FemromValueError(f"a probe point lies outside the mesh (bounding box {lo} to {hi})"
                               ) from err
    # skfem stacks the rows component-major: row c * p + k is u_c(x_k).
    n = x.shape[0]
    return P[c * n:(c + 1) * n]


def nearest_node_rows(basis, points, component: int, nodes: int, *, tree=None) -> sp.csr_matrix:
    r"""Rows that average one displacement component over the nodes nearest to given points.

    .. math::

        (E q)_k = \frac{1}{n} \sum_{s \in N_n(x_k)} q_{3 s + c},

    ``N_n(x_k)`` the ``n`` scalar nodes (vertices, and on P2 edge midpoints)
    nearest to ``x_k`` in the Euclidean distance (ties broken by a k-d tree, in
    a fixed order). A nodal interpolant of a linear field is exact at the
    nodes, so such a row reads the field at the centroid of the ``n`` nodes;
    a translation ``q_{3 s + c} = a`` reads ``a`` exactly.

    Parameters
    ----------
    basis : skfem.CellBasis
        Vector P1/P2 basis on a ``MeshTet``.
    points : (p, 3) array_like
        Where to read (m); each must lie in the mesh's bounding box.
    component : int
        0, 1 or 2 for ``u_x``, ``u_y``, ``u_z``.
    nodes : int
        ``n >= 1``, at most the number of nodes.
    tree : scipy.spatial.cKDTree, optional
        The k-d tree of the basis's node locations (:func:`node_tree`), to reuse over many calls.

    Returns
    -------
    (p, n_total) scipy.sparse.csr_matrix
        ``n`` entries ``1 / n`` per row; each row sums to 1.
    """
    _scalar_element(basis)
    c = check_component(component)
    x = np.atleast_2d(np.asarray(points, dtype=float))
    if x.ndim != 2 or x.shape[1] != 3 or not np.all(np.isfinite(x)):
        raise FemromValueError(f"points must be finite, of shape (p, 3), got {np.shape(points)}")
    tree = node_tree(basis) if tree is None else tree
    locations = tree.data
    if isinstance(nodes, bool) or not isinstance(nodes, (int, np.integer)) or not 1 <= nodes <= len(locations):
        raise FemromValueError(f"nodes must be a whole number in [1, {len(locations)}], got {nodes!r}")
    lo, hi = locations.min(axis=0), locations.max(axis=0)
    pad = 1e-9 * float(np.max(hi - lo))
    outside = np.flatnonzero(np.any((x < lo - pad) | (x > hi + pad), axis=1))
    if outside.size:
        raise FemromValueError(f"point {x[outside[0]].tolist()} lies outside the mesh (bounding box "
                               f"{lo.tolist()} to {hi.tolist()})")
    _, nearest = tree.query(x, k=int(nodes))
    nearest = np.asarray(nearest).reshape(x.shape[0], int(nodes))
    rows = np.repeat(np.arange(x.shape[0]), int(nodes))
    return sp.csr_matrix((np.full(rows.size, 1.0 / nodes), (rows, 3 * nearest.ravel() + c)),
                         shape=(x.shape[0], basis.N))


def node_tree(basis):
    """A ``scipy.spatial.cKDTree`` of the scalar nodes' locations (its ``data``: (n_nodes, 3))."""
    from scipy.spatial import cKDTree

    return cKDTree(node_locations(basis))


def average_rows(basis, region: str, component: int) -> sp.csr_matrix:
    r"""Row that reads the mean of one displacement component over a named region.

    .. math::

        y = \frac{1}{|\Gamma|} \int_{\Gamma} u_c \, ds \quad\text{(boundary, area-weighted)}
        \qquad
        y = \frac{1}{|\Omega_s|} \int_{\Omega_s} u_c \, dx \quad\text{(subdomain, volume-weighted)}

    Parameters
    ----------
    basis : skfem.CellBasis
        Vector P1/P2 basis on a ``MeshTet``.
    region : str
        Key of ``basis.mesh.boundaries`` or of ``basis.mesh.subdomains``.
    component : int
        0, 1 or 2.

    Returns
    -------
    (1, n_total) scipy.sparse.csr_matrix
        Sums to 1 (the mean of a constant field is that constant).
    """
    _scalar_element(basis)
    c = check_component(component)
    mesh = basis.mesh
    in_boundaries = region in (mesh.boundaries or {})
    in_subdomains = region in (mesh.subdomains or {})
    if in_boundaries and in_subdomains:
        raise FemromValueError(f"{region!r} names both a boundary and a subdomain; rename one")
    if in_boundaries:
        region_basis = facet_basis(basis, named_facets(mesh, region))
    elif in_subdomains:
        region_basis = skfem.CellBasis(mesh, basis.elem, elements=named_elements(mesh, region))
    else:
        raise MeshError(f"mesh has no boundary or subdomain {region!r}; boundaries: "
                        f"{', '.join(sorted(mesh.boundaries or {})) or 'none'}; subdomains: "
                        f"{', '.join(sorted(mesh.subdomains or {})) or 'none'}")

    @skfem.LinearForm
    def component_integral(v, w):
        return v[c]

    row = component_integral.assemble(region_basis)
    # Partition of unity: the entries sum to the region's measure.
    return sp.csr_matrix(row / row.sum())
