r"""Loads of a displacement field on named mesh regions or at points: columns of the input
matrix ``B``, (n_total,) ndarrays.

On the full dof numbering of a vector basis, regions looked up by name: as in :mod:`._vector_basis`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import skfem
from skfem.helpers import dot

from femrom._errors import FemromValueError
from femrom.fem._elasticity import _scalar_element
from femrom.fem._outputs import probe_rows
from femrom.fem._vector_basis import facet_basis, named_facets

__all__ = [
    "point_load",
    "surface_pressure",
    "surface_traction",
]


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
    fb = facet_basis(basis, named_facets(basis.mesh, boundary))

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
    facets = named_facets(basis.mesh, boundary)
    interior = basis.mesh.f2t[1, facets] >= 0
    if np.any(interior):
        raise FemromValueError(f"boundary {boundary!r} has {int(interior.sum())} interior facets; "
                               "pressure needs outer-boundary facets (outward normal)")
    fb = facet_basis(basis, facets)
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
