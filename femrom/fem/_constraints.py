r"""Constraints of a displacement field: the dofs on named boundaries (sorted int ndarrays, for
:meth:`femrom.fem.Condensation.from_fixed`) and the rigid-body modes a free structure leaves.

On the full dof numbering of a vector basis, regions looked up by name: as in :mod:`._vector_basis`.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from femrom._errors import FemromValueError
from femrom.fem._elasticity import _scalar_element
from femrom.fem._vector_basis import check_component, named_facets, node_locations

__all__ = [
    "dirichlet_dofs",
    "rigid_body_modes",
]


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
    x = node_locations(basis)
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
    comps = sorted({check_component(c) for c in components})
    if not names or not comps:
        raise FemromValueError("need at least one boundary name and one component")
    facets = np.unique(np.concatenate([named_facets(basis.mesh, name) for name in names]))
    dofs = np.asarray(basis.get_dofs(facets).flatten(), dtype=np.int64)
    return np.unique(dofs[np.isin(dofs % 3, comps)])
