"""Meshes: parametric Gmsh geometries -> cached .msh files -> scikit-fem meshes.

Geometry sources live in the repository's ``meshes/`` folder (and in the
directories of ``FEMROM_MESH_PATH``); each declares its dimensions and mesh
size with ``DefineConstant`` and names its boundaries and regions with physical
groups::

    mesh = build_mesh("beam_solid", {"length": 0.72, "mesh_size": 0.005})
    clamped = boundary_facets(mesh, "left")

A jointed structure keeps duplicated nodes on its two interface faces;
:func:`interface_pairs` matches them and lumps the interface area onto the pairs.
"""

from femrom.mesh._errors import MeshError
from femrom.mesh._generate import default_cache_dir, generate_mesh
from femrom.mesh._geometry import available_geometries, find_geometry, geometry_parameters
from femrom.mesh._interface import InterfacePairs, interface_pairs
from femrom.mesh._load import boundary_facets, build_mesh, load_mesh, subdomain_elements

__all__ = [
    "InterfacePairs",
    "MeshError",
    "available_geometries",
    "boundary_facets",
    "build_mesh",
    "default_cache_dir",
    "find_geometry",
    "generate_mesh",
    "geometry_parameters",
    "interface_pairs",
    "load_mesh",
    "subdomain_elements",
]
