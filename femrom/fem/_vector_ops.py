r"""Loads, outputs and constraints of a displacement field on named mesh regions.

Everything here lives on the full dof numbering of a vector basis
``skfem.Basis(mesh, ElementVector(ElementTetP1() or ElementTetP2()))``
(``n_total = basis.N``; component ``c`` of scalar node ``s`` is dof ``3 s + c``):

- loads are columns of the input matrix ``B``: (n_total,) ndarrays;
- outputs are rows of the output matrix ``E``: (p, n_total) sparse matrices;
- constraints are sorted int ndarrays of dofs, for
  :meth:`femrom.fem.Condensation.from_fixed`.

Regions are looked up by name in ``mesh.boundaries`` (facets) and
``mesh.subdomains`` (elements) through :mod:`femrom.mesh`; an unknown name
raises ``MeshError`` listing the valid ones.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np
import scipy.sparse as sp
import skfem
from skfem.helpers import dot

from femrom._errors import FemromValueError
from femrom.fem._elasticity import _scalar_element
from femrom.mesh import MeshError, boundary_facets, subdomain_elements

__all__ = [
    "average_rows",
    "dirichlet_dofs",
    "nearest_node_rows",
    "point_load",
    "probe_rows",
    "rigid_body_modes",
    "surface_pressure",
    "surface_traction",
]


# -- named regions ------------------------------------------------------------
def _named_facets(mesh, name: str) -> np.ndarray:
    """Facets of a named boundary; MeshError listing the valid names otherwise."""
    return np.asarray(boundary_facets(mesh, name))


def _named_elements(mesh, name: str) -> np.ndarray:
    """Elements of a named subdomain; MeshError listing the valid names otherwise."""
    return np.asarray(subdomain_elements(mesh, name))


def _check_component(component: int) -> int:
    if component not in (0, 1, 2):
        raise FemromValueError(f"component must be 0, 1 or 2 (x, y, z), got {component!r}")
    return int(component)


def _facet_basis(basis, facets: np.ndarray) -> skfem.FacetBasis:
    """Vector facet basis with the same element and dof numbering as ``basis``."""
    return skfem.FacetBasis(basis.mesh, basis.elem, facets=facets)


# -- loads (columns of B) -----------------------------------------------------
def surface_traction(basis, boundary: str, traction) -> np.ndarray:
    r"""Load of a constant traction on a named boundary.

    .. math::

        f_I = \int_{\Gamma} t \cdot \phi_I \, ds

    Parameters
    ----------
    basis : skfem.CellBasis
        Vector P1/P2 basis on a ``MeshTet``.
    boundary : str
        Key of ``basis.mesh.boundaries``.
    traction : (3,) array_like
        Force per unit area (Pa), constant over the boundary.

    Returns
    -------
    (n_total,) ndarray
        Consistent nodal forces; their component sums are ``t * area``.
    """
    _scalar_element(basis)
    t = np.asarray(traction, dtype=float)
    if t.shape != (3,):
        raise FemromValueError(f"traction must have shape (3,), got {t.shape}")
    fb = _facet_basis(basis, _named_facets(basis.mesh, boundary))

    @skfem.LinearForm
    def load(v, w):
        return t[0] * v[0] + t[1] * v[1] + t[2] * v[2]

    return load.assemble(fb)


def surface_pressure(basis, boundary: str, pressure: float = 1.0) -> np.ndarray:
    r"""Load of a uniform pressure on a named outer boundary.

    Positive pressure pushes into the body: the traction is ``t = -p n``
    with ``n`` the outward unit normal,

    .. math::

        f_I = -p \int_{\Gamma} n \cdot \phi_I \, ds .

    Parameters
    ----------
    basis : skfem.CellBasis
        Vector P1/P2 basis on a ``MeshTet``.
    boundary : str
        Key of ``basis.mesh.boundaries``; all its facets must be on the outer
        boundary (an interior facet has no outward normal).
    pressure : float
        ``p`` (Pa); the default 1 gives the input column for ``u(t) = p(t)``.

    Returns
    -------
    (n_total,) ndarray
        Consistent nodal forces (linear in ``p``, follower effects ignored).
    """
    _scalar_element(basis)
    facets = _named_facets(basis.mesh, boundary)
    interior = basis.mesh.f2t[1, facets] >= 0
    if np.any(interior):
        raise FemromValueError(f"boundary {boundary!r} has {int(interior.sum())} interior facets; "
                               "pressure needs outer-boundary facets (outward normal)")
    fb = _facet_basis(basis, facets)
    p = float(pressure)

    @skfem.LinearForm
    def load(v, w):
        return -p * dot(w.n, v)

    return load.assemble(fb)


def point_load(basis, point, force, *, snap_to_vertex: bool = True) -> np.ndarray:
    r"""Load of a concentrated force.

    Parameters
    ----------
    basis : skfem.CellBasis
        Vector P1/P2 basis on a ``MeshTet``.
    point : (3,) array_like
        Where the force acts (m).
    force : (3,) array_like
        Force vector (N); the input ``u(t)`` scales it.
    snap_to_vertex : bool
        ``True``: the whole force goes to the three dofs of the mesh vertex
        nearest to ``point`` (a nodal force, the usual engineering load; the
        snap moves the load by up to half an element).
        ``False``: the consistent load of a Dirac force at ``point`` itself,
        :math:`f_I = F \cdot \phi_I(x_0)` through the element containing it
        (for P2 it gives negative shares to vertices).

    Returns
    -------
    (n_total,) ndarray
        Its components sum to ``force``.
    """
    _scalar_element(basis)
    x0 = np.asarray(point, dtype=float)
    F = np.asarray(force, dtype=float)
    if x0.shape != (3,) or F.shape != (3,):
        raise FemromValueError(f"point and force must have shape (3,), got {x0.shape} and {F.shape}")
    if snap_to_vertex:
        vertex = int(np.argmin(np.sum((basis.mesh.p - x0[:, None]) ** 2, axis=0)))
        f = np.zeros(basis.N)
        f[basis.nodal_dofs[:, vertex]] = F
        return f
    rows = sp.vstack([probe_rows(basis, x0[None, :], c) for c in range(3)])  # (3, n_total)
    return np.asarray(rows.T @ F).ravel()


# -- outputs (rows of E) --------------------------------------------------------
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
    c = _check_component(component)
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
    c = _check_component(component)
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

    return cKDTree(_node_locations(basis))


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
    c = _check_component(component)
    mesh = basis.mesh
    in_boundaries = region in (mesh.boundaries or {})
    in_subdomains = region in (mesh.subdomains or {})
    if in_boundaries and in_subdomains:
        raise FemromValueError(f"{region!r} names both a boundary and a subdomain; rename one")
    if in_boundaries:
        region_basis = _facet_basis(basis, _named_facets(mesh, region))
    elif in_subdomains:
        region_basis = skfem.CellBasis(mesh, basis.elem, elements=_named_elements(mesh, region))
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


# -- rigid-body modes and constraints --------------------------------------------
def _node_locations(basis) -> np.ndarray:
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


def rigid_body_modes(basis) -> np.ndarray:
    r"""The six rigid-body displacement fields, the kernel of the free stiffness.

    Columns: translations ``e_x, e_y, e_z`` and rotations
    ``omega x (x - x_c)`` about the axes through the node centroid ``x_c``
    (centring keeps the columns well conditioned). P1 and P2 reproduce these
    linear fields exactly, so ``K @ modes = 0`` to rounding. Pass as the
    near-nullspace ``B`` of ``pyamg.smoothed_aggregation_solver`` (restricted
    to the free dofs).

    Returns
    -------
    (n_total, 6) ndarray
    """
    x = _node_locations(basis)
    r = x - x.mean(axis=0)
    n = x.shape[0]
    modes = np.zeros((n, 3, 6))
    for c in range(3):
        modes[:, c, c] = 1.0
    # omega = e_x: (0, -z, y); e_y: (z, 0, -x); e_z: (-y, x, 0)
    modes[:, 1, 3], modes[:, 2, 3] = -r[:, 2], r[:, 1]
    modes[:, 0, 4], modes[:, 2, 4] = r[:, 2], -r[:, 0]
    modes[:, 0, 5], modes[:, 1, 5] = -r[:, 1], r[:, 0]
    return modes.reshape(3 * n, 6)


def dirichlet_dofs(basis, boundaries: str | Iterable[str],
                   components: Iterable[int] = (0, 1, 2)) -> np.ndarray:
    """Dofs of the given components on named boundaries (to clamp or to slide).

    Parameters
    ----------
    basis : skfem.CellBasis
        Vector P1/P2 basis on a ``MeshTet``.
    boundaries : str or iterable of str
        Keys of ``basis.mesh.boundaries``.
    components : iterable of int
        Constrained components; ``(0, 1, 2)`` clamps, ``(2,)`` only blocks ``u_z``.

    Returns
    -------
    (k,) int64 ndarray
        Sorted unique dof indices (vertex and, for P2, edge-midpoint dofs).
    """
    _scalar_element(basis)
    names = [boundaries] if isinstance(boundaries, str) else list(boundaries)
    comps = sorted({_check_component(c) for c in components})
    if not names or not comps:
        raise FemromValueError("need at least one boundary name and one component")
    facets = np.unique(np.concatenate([_named_facets(basis.mesh, name) for name in names]))
    dofs = np.asarray(basis.get_dofs(facets).flatten(), dtype=np.int64)
    return np.unique(dofs[np.isin(dofs % 3, comps)])
