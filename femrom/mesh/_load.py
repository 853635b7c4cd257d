"""Reading .msh files into scikit-fem meshes with named boundaries and subdomains."""

from __future__ import annotations

import contextlib
import io
import os
from collections.abc import Mapping
from pathlib import Path

import meshio
import numpy as np
from skfem import Mesh
from skfem.io.meshio import BOUNDARY_TYPE_MAPPING, from_meshio

from femrom.mesh._errors import MeshError
from femrom.mesh._generate import generate_mesh

# meshio cell type -> dimension, for the element types scikit-fem can import.
_ELEMENT_DIMENSION = {
    "line": 1,
    "triangle": 2, "triangle6": 2, "quad": 2, "quad9": 2,
    "tetra": 3, "tetra10": 3, "hexahedron": 3, "hexahedron27": 3, "wedge": 3,
}
_CELL_DIMENSION = {"vertex": 0, "line3": 1, "pyramid": 3, "pyramid13": 3, "wedge15": 3,
                   "hexahedron20": 3, "tetra4": 3, "quad8": 2, **_ELEMENT_DIMENSION}

# Relative spread of a dropped coordinate above which a 1D/2D mesh is not flat.
_FLATNESS_TOLERANCE = 1e-9


def load_mesh(path: str | os.PathLike) -> Mesh:
    """Read a mesh file into a scikit-fem mesh with named boundaries and subdomains.

    Element type decides the mesh class (``line`` -> ``MeshLine1``,
    ``triangle`` -> ``MeshTri1``, ``tetra`` -> ``MeshTet1``, ...). Physical
    groups of dimension ``d - 1`` become ``mesh.boundaries`` (facet indices;
    the facets of a 1D mesh are its nodes) and those of dimension ``d`` become
    ``mesh.subdomains`` (element indices). A 1D mesh keeps x only and a 2D mesh
    x and y; the dropped coordinates must be constant.

    Parameters
    ----------
    path : path-like
        A Gmsh ``.msh`` file (any version meshio reads) or another meshio format.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    MeshError
        The file is corrupt, truncated, or holds no usable elements.
    """
    path = Path(path).expanduser()
    if not path.is_file():
        raise FileNotFoundError(f"mesh file not found: '{path}'")
    raw = _read(path)
    element_type = _element_type(raw, path)
    _check_flat(raw, element_type, path)
    _check_no_orphan_nodes(raw, element_type, path)
    raw.cell_sets = {name: cells for name, cells in raw.cell_sets.items()
                     if not name.startswith("gmsh:")}
    try:
        mesh = from_meshio(raw, force_meshio_type=element_type,
                           # orientation means nothing for the point facets of 1D meshes
                           ignore_orientation=_ELEMENT_DIMENSION[element_type] == 1)
    except Exception as exc:
        raise MeshError(f"cannot build a scikit-fem mesh from '{path}': {exc}") from exc
    _check_boundaries_found(raw, mesh, element_type, path)
    return mesh


def build_mesh(geometry: str | os.PathLike, parameters: Mapping[str, float] | None = None,
               **options) -> Mesh:
    """:func:`generate_mesh` (cached) then :func:`load_mesh`; ``options`` go to the former.

    A ``mesh_size`` parameter is compared with the mesh gmsh made: a mean element edge
    outside ``[0.1, 10]`` times it means gmsh did not honour it (a size below its
    tolerances, e.g. ``1e-300``, gives its default size) and is one :class:`MeshError`.
    Measured edge/size: 1.0 (beam line), 1.1 (tests' bracket), 0.46 (fishtail).
    """
    mesh = load_mesh(generate_mesh(geometry, parameters, **options))
    size = (parameters or {}).get("mesh_size")
    if size:
        edge = float(np.linalg.norm(mesh.p[:, mesh.t[0]] - mesh.p[:, mesh.t[1]], axis=0).mean())
        if not 0.1 * size <= edge <= 10.0 * size:
            raise MeshError(f"geometry '{Path(str(geometry)).name}': mesh_size = {size:g} asked for, gmsh made "
                            f"elements of mean edge {edge:.3g} (outside 0.1-10x: the size was not honoured)")
    return mesh


def boundary_facets(mesh: Mesh, name: str) -> np.ndarray:
    """Facet indices of the named boundary.

    Returns
    -------
    (k,) int ndarray
        Columns of ``mesh.facets``; for a 1D mesh, facet ``i`` is node
        ``mesh.facets[0, i]``.

    Raises
    ------
    MeshError
        The mesh has no such boundary (the message lists the ones it has).
    """
    return _named(mesh.boundaries, name, "boundary")


def subdomain_elements(mesh: Mesh, name: str) -> np.ndarray:
    """Element indices (columns of ``mesh.t``) of the named subdomain, a (k,) int ndarray.

    Raises
    ------
    MeshError
        The mesh has no such subdomain (the message lists the ones it has).
    """
    return _named(mesh.subdomains, name, "subdomain")


def _named(groups: dict | None, name: str, kind: str) -> np.ndarray:
    groups = groups or {}
    if name not in groups:
        raise MeshError(f"mesh has no {kind} '{name}'; available: "
                        f"{', '.join(sorted(groups)) or 'none'}")
    return groups[name]


def _read(path: Path) -> meshio.Mesh:
    """meshio's reader, with every failure turned into a MeshError naming the file."""
    # meshio.read prints and calls sys.exit on unreadable files: call the gmsh
    # reader directly for .msh, and catch SystemExit for the other formats.
    messages = io.StringIO()
    try:
        with contextlib.redirect_stdout(messages):
            if path.suffix == ".msh":
                return meshio.gmsh.read(path)
            return meshio.read(path)
    except (Exception, SystemExit) as exc:
        detail = messages.getvalue().strip() if isinstance(exc, SystemExit) else str(exc)
        reason = f"{type(exc).__name__}: {detail}" if detail else type(exc).__name__
        raise MeshError(f"cannot read mesh file '{path}' (corrupt or truncated?): "
                        f"{reason}") from exc


def _element_type(raw: meshio.Mesh, path: Path) -> str:
    """The single element type of the highest dimension present."""
    types = {block.type for block in raw.cells if len(block.data)}
    unknown = sorted(t for t in types if t not in _CELL_DIMENSION)
    if unknown:
        raise MeshError(f"mesh file '{path}' has unsupported cell types: {', '.join(unknown)}")
    if not types or max(_CELL_DIMENSION[t] for t in types) == 0:
        raise MeshError(f"mesh file '{path}' has no elements")
    dimension = max(_CELL_DIMENSION[t] for t in types)
    top = sorted(t for t in types if _CELL_DIMENSION[t] == dimension)
    if len(top) > 1 or top[0] not in _ELEMENT_DIMENSION:
        raise MeshError(f"mesh file '{path}' has {dimension}D elements of type(s) "
                        f"{', '.join(top)}; scikit-fem needs one of "
                        f"{', '.join(t for t, d in _ELEMENT_DIMENSION.items() if d == dimension)}")
    return top[0]


def _check_flat(raw: meshio.Mesh, element_type: str, path: Path) -> None:
    """A 1D (2D) mesh must have constant y, z (z): scikit-fem keeps x (x, y) only."""
    dimension = _ELEMENT_DIMENSION[element_type]
    points = raw.points
    extent = max(float(np.ptp(points, axis=0).max()), np.finfo(float).tiny)
    dropped = points[:, dimension:]
    if dropped.size and np.ptp(dropped, axis=0).max() > _FLATNESS_TOLERANCE * extent:
        axes = "y and z" if dimension == 1 else "z"
        if dimension == 2 and np.ptp(points[:, 2]) > 0.05 * extent:   # a solid's surface, not a tilted sheet
            raise MeshError(f"mesh '{path}' has surface elements ({element_type}) only, but its points span "
                            f"3D: a solid without volume elements (mesh it in 3D: gmsh -3, a Physical Volume), "
                            f"or a 2D mesh off the z = const plane")
        raise MeshError(f"{dimension}D mesh '{path}' is not flat: its {axes} coordinates vary, "
                        f"but scikit-fem keeps only the first {dimension}")


def _check_no_orphan_nodes(raw: meshio.Mesh, element_type: str, path: Path) -> None:
    """Every node must belong to an element, or it would add a zero row to each matrix."""
    used = np.zeros(len(raw.points), dtype=bool)
    for block in raw.cells:
        if block.type == element_type:
            used[block.data.ravel()] = True
    if not used.all():
        raise MeshError(f"mesh file '{path}' has {int((~used).sum())} nodes outside every "
                        f"{element_type} element (geometry entities outside the physical groups?)")


def _check_boundaries_found(raw: meshio.Mesh, mesh: Mesh, element_type: str,
                            path: Path) -> None:
    """Each named facet set must match as many mesh facets as it lists."""
    facet_type = BOUNDARY_TYPE_MAPPING.get(element_type)
    boundaries = mesh.boundaries or {}
    for name, cells in raw.cell_sets_dict.items():
        if facet_type in cells:
            expected = len(np.unique(cells[facet_type]))
            found = len(boundaries.get(name, ()))
            if found != expected:
                raise MeshError(f"boundary '{name}' of '{path}' lists {expected} facets but "
                                f"only {found} are facets of the mesh")
