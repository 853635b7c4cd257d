r"""Node pairs across a jointed interface: two named faces meshed identically, nodes duplicated.

A jointed structure (e.g. ``meshes/jointed_beam.geo``) keeps separate nodes on
the two faces of a contact interface, at matching positions, with matching
triangles. :func:`interface_pairs` finds the pairs and what a zero-thickness
joint law needs at each one: the unit normal of side ``a`` and a lumped
tributary area, so that a traction :math:`\tau_k` (Pa) at pair ``k`` becomes
the nodal force :math:`f_k = A_k \tau_k` on side ``a`` and :math:`-f_k` on
side ``b``.

Lumping (HRZ: the diagonal of the consistent surface mass matrix scaled to the
triangle's area, the same rule for both orders):

- P1 (3-node triangles): :math:`A/3` per vertex (equal to the row sum
  :math:`\int \phi_i \, dA`);
- P2 (6-node triangles, vertices and edge midpoints): the diagonal of
  :math:`\int \phi_i \phi_j \, dA` is :math:`6A/180` (vertex) and
  :math:`32A/180` (midpoint); scaled to sum to :math:`A`: :math:`A/19` per
  vertex and :math:`16A/57` per midpoint (the row sums would give the vertices
  zero area, useless for node-to-node springs).

The areas of each side sum to that side's triangulated area exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from femrom.mesh._errors import MeshError
from femrom.mesh._load import boundary_facets

__all__ = ["InterfacePairs", "interface_pairs"]

# HRZ-lumped share of a triangle's area per vertex and per edge midpoint.
_VERTEX_SHARE = {1: 1.0 / 3.0, 2: 1.0 / 19.0}
_MIDPOINT_SHARE = 16.0 / 57.0

# Default pairing tolerance relative to the interface's diameter: gmsh copies the
# nodes of a periodic face exactly (measured worst distance 1e-17 m on 0.12 m).
_RELATIVE_TOLERANCE = 1e-8


@dataclass(frozen=True)
class InterfacePairs:
    """Matched nodes of two faces of a jointed interface (returned by :func:`interface_pairs`).

    Attributes
    ----------
    side_a, side_b : str
        Names of the two boundaries.
    order : int
        1: the nodes are mesh vertices; 2: vertices and edge midpoints, node
        ``n_vertices + e`` being the midpoint of edge ``e`` (column of ``mesh.edges``)
        - the scalar P2 numbering of scikit-fem.
    nodes : (s, 2) int ndarray
        ``nodes[k] = (node on side a, node on side b)``, sorted by the node of side a.
    points : (s, 3) ndarray
        Position of pair ``k`` (side a's node; side b's is within ``max_distance``).
    normals : (s, 3) ndarray
        Unit outward normal of side a's body at its node: the area-weighted mean of
        the normals of side a's triangles around the node, normalized.
    areas : (s,) ndarray
        Lumped tributary area of pair ``k`` (see the module docstring); they sum to
        the triangulated area of side a.
    max_distance : float
        Worst distance between paired nodes.
    """

    side_a: str
    side_b: str
    order: int
    nodes: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    max_distance: float

    @property
    def n_pairs(self) -> int:
        return int(self.nodes.shape[0])

    def dofs(self) -> np.ndarray:
        """(s, 2, 3) int ndarray: ``dofs[k, side, c]`` = dof of component ``c`` of the node.

        For femrom's elasticity space (``skfem.ElementVector`` of ``ElementTetP1`` or
        ``ElementTetP2`` on the same mesh, see ``femrom.fem.SolidSpace``) the dof of
        component ``c`` (0, 1, 2 = x, y, z) of scalar node ``s`` is ``3 s + c``:
        vertices first, then P2 edge midpoints. Use ``order = 2`` pairs with a P2 space.
        """
        return 3 * self.nodes[:, :, None] + np.arange(3)

    def local_frames(self) -> np.ndarray:
        """(s, 3, 3) ndarray: rows ``t1, t2, n`` of an orthonormal right-handed frame per pair.

        ``n`` is :attr:`normals`; ``t1`` is the global x axis projected on the
        tangent plane (the y axis where the normal is nearly along x), ``t2 = n x t1``.
        """
        n = self.normals
        axis = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = axis - np.sum(axis * n, axis=1, keepdims=True) * n
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        t2 = np.cross(n, t1)
        return np.stack([t1, t2, n], axis=1)


def interface_pairs(mesh, side_a: str, side_b: str, *, order: int = 1,
                    tolerance: float | None = None) -> InterfacePairs:
    r"""Pair the nodes of two named faces with duplicated, coincident nodes.

    Parameters
    ----------
    mesh : skfem.MeshTet1
        A tetrahedral mesh whose ``boundaries`` name both faces (as loaded by
        :func:`femrom.mesh.load_mesh`); each face's triangles must be boundary
        facets (one element each): the bodies are not fused along the interface.
    side_a, side_b : str
        Names of the two faces; normals are side a's.
    order : int
        1 for a P1 space (vertices), 2 for a P2 space (vertices and edge midpoints).
    tolerance : float, optional
        Largest accepted distance between paired nodes (mesh units); default
        ``1e-8`` times the diameter (bounding-box diagonal) of side a.

    Returns
    -------
    InterfacePairs
        ``s`` pairs: nodes (s, 2), points (s, 3), normals (s, 3), areas (s,).

    Raises
    ------
    MeshError
        Unknown name (listing the valid ones); the same name twice; an invalid
        order or tolerance; triangles of a side shared by two elements (a fused
        interface, e.g. ``bonded = 1``); a node of either side farther than the
        tolerance from every node of the other (the message names the side and
        the worst distance); node counts that differ or two nodes of side a
        sharing one partner; triangles that do not correspond pair for pair.
    """
    if side_a == side_b:
        raise MeshError(f"interface_pairs needs two different faces, got side_a = side_b = {side_a!r}")
    if order not in (1, 2) or isinstance(order, bool):
        raise MeshError(f"order must be 1 (P1, vertices) or 2 (P2, vertices and edge midpoints), got {order!r}")
    if mesh.p.shape[0] != 3 or mesh.t.shape[0] != 4:
        raise MeshError("interface_pairs needs a tetrahedral mesh (MeshTet1), got "
                        f"{type(mesh).__name__} with {mesh.t.shape[0]}-node elements in {mesh.p.shape[0]}D")
    face_a = _Face(mesh, side_a, order)
    face_b = _Face(mesh, side_b, order)
    if tolerance is None:
        tolerance = _RELATIVE_TOLERANCE * float(np.linalg.norm(np.ptp(face_a.points, axis=0)))
    elif not (np.isfinite(tolerance) and tolerance > 0):
        raise MeshError(f"tolerance must be a positive distance, got {tolerance!r}")

    distance, partner = cKDTree(face_b.points).query(face_a.points)
    distance_back = cKDTree(face_a.points).query(face_b.points)[0]
    for name, other, face, gaps in ((side_a, side_b, face_a, distance), (side_b, side_a, face_b, distance_back)):
        worst = int(np.argmax(gaps))
        if gaps[worst] > tolerance:
            raise MeshError(f"interface side {name!r} does not match {other!r}: its node {face.nodes[worst]} at "
                            f"{np.array2string(face.points[worst], precision=6)} is {gaps[worst]:.3g} from the "
                            f"nearest node of {other!r} (worst distance; tolerance {tolerance:.3g}; "
                            f"{face_a.nodes.size} and {face_b.nodes.size} nodes)")
    if face_a.nodes.size != face_b.nodes.size or np.unique(partner).size != partner.size:
        raise MeshError(f"interface sides {side_a!r} ({face_a.nodes.size} nodes) and {side_b!r} "
                        f"({face_b.nodes.size} nodes) do not pair one to one within the tolerance "
                        f"{tolerance:.3g} (worst distance {distance.max():.3g}): nodes closer than the "
                        "tolerance on one side?")
    _check_same_triangles(face_a, face_b, partner, side_a, side_b)

    return InterfacePairs(
        side_a=side_a, side_b=side_b, order=order,
        nodes=np.column_stack([face_a.nodes, face_b.nodes[partner]]),
        points=face_a.points, normals=face_a.normals, areas=face_a.areas,
        max_distance=float(distance.max(initial=0.0)))


class _Face:
    """Nodes, positions, outward nodal normals and lumped areas of one named face."""

    def __init__(self, mesh, name: str, order: int):
        facets = np.asarray(boundary_facets(mesh, name))
        if facets.size == 0:
            raise MeshError(f"interface side {name!r} has no facets")
        shared = int(np.count_nonzero(mesh.f2t[1, facets] >= 0))
        if shared:
            raise MeshError(f"interface side {name!r}: {shared} of its {facets.size} triangles lie between "
                            "two elements - the bodies are fused there (a bonded mesh), there is no "
                            "interface to pair")
        n_vertices = mesh.p.shape[1]
        corners = mesh.facets[:, facets]                          # (3, f)
        a, b, c = (mesh.p[:, corners[i]].T for i in range(3))     # (f, 3) each
        cross = np.cross(b - a, c - a)
        area = 0.5 * np.linalg.norm(cross, axis=1)                # (f,)
        # orient away from the element's fourth vertex: outward
        element = mesh.t[:, mesh.f2t[0, facets]]                  # (4, f)
        inside = mesh.p[:, element].mean(axis=1).T                # element centroids (f, 3)
        sign = np.sign(np.sum(cross * (a - inside), axis=1))
        unit = sign[:, None] * cross / (2.0 * area[:, None])      # (f, 3)

        # local nodes per triangle: 3 vertices (+ 3 edge midpoints for P2)
        columns = [corners.T]
        shares = [np.full((facets.size, 3), _VERTEX_SHARE[order])]
        if order == 2:
            columns.append(n_vertices + mesh.f2e[:, facets].T)
            shares.append(np.full((facets.size, 3), _MIDPOINT_SHARE))
        local = np.hstack(columns)                                # (f, 3 or 6)
        share = np.hstack(shares) * area[:, None]
        self.nodes, index = np.unique(local, return_inverse=True)
        index = index.reshape(local.shape)
        self.triangles = local
        self.areas = np.bincount(index.ravel(), share.ravel(), minlength=self.nodes.size)
        normal = np.zeros((self.nodes.size, 3))
        for k in range(3):
            normal[:, k] = np.bincount(index.ravel(), np.repeat(unit[:, k] * area, local.shape[1]),
                                       minlength=self.nodes.size)
        self.normals = normal / np.linalg.norm(normal, axis=1, keepdims=True)
        self.points = _node_points(mesh, self.nodes)


def _node_points(mesh, nodes: np.ndarray) -> np.ndarray:
    """(k, 3) positions of vertices (index < n_vertices) and edge midpoints (the rest)."""
    n_vertices = mesh.p.shape[1]
    points = np.empty((nodes.size, 3))
    vertex = nodes < n_vertices
    points[vertex] = mesh.p[:, nodes[vertex]].T
    edges = mesh.edges[:, nodes[~vertex] - n_vertices]
    points[~vertex] = 0.5 * (mesh.p[:, edges[0]] + mesh.p[:, edges[1]]).T
    return points


def _check_same_triangles(face_a: _Face, face_b: _Face, partner: np.ndarray, side_a: str,
                          side_b: str) -> None:
    """Side b's triangles, renumbered by the pairing, must be side a's (conforming faces)."""
    to_a = np.empty(face_b.nodes.max() + 1, dtype=np.int64)
    to_a[face_b.nodes[partner]] = face_a.nodes
    triangles_b = np.sort(to_a[face_b.triangles], axis=1)
    triangles_a = np.sort(face_a.triangles, axis=1)
    rows_a = {tuple(row) for row in triangles_a}
    rows_b = {tuple(row) for row in triangles_b}
    if rows_a != rows_b:
        raise MeshError(f"interface sides {side_a!r} and {side_b!r} have matching nodes but "
                        f"{len(rows_a ^ rows_b)} triangles without a counterpart: the faces are "
                        "not meshed conformingly")
