"""femrom.mesh: parametric geometries, cached generation, named boundaries and regions."""

import re
import signal
import textwrap

import gmsh
import meshio
import numpy as np
import pytest
from skfem import MeshLine1, MeshTet1, MeshTri1

import femrom.mesh as fm
from femrom.mesh import MeshError

# Coordinates come out of gmsh/OpenCASCADE in double precision; the OCC boxes
# are exact up to ~1e-12 relative, so 1e-9 tells "on the plane" from "not".
PLANE = 1e-9
# Sums of element measures over a polyhedral domain are exact up to round-off
# of a few hundred terms: 1e-10 relative.
MEASURE = 1e-10

SOLID = {"length": 0.6, "width": 0.1, "height": 0.05, "mesh_size": 0.05}


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """Private cache directory; FEMROM_CACHE pointed elsewhere to catch leaks."""
    monkeypatch.setenv("FEMROM_CACHE", str(tmp_path / "env-cache"))
    return tmp_path / "cache"


@pytest.fixture(scope="module")
def solid(tmp_path_factory):
    return fm.build_mesh("beam_solid", SOLID, cache_dir=tmp_path_factory.mktemp("solid"))


def write_geo(directory, name, text):
    path = directory / f"{name}.geo"
    path.write_text(textwrap.dedent(text))
    return path


def triangle_areas(p, tri):
    """Areas of triangles with vertex columns ``tri`` (3, k) of points ``p`` (3, n)."""
    a, b, c = (p[:, tri[i]] for i in range(3))
    return 0.5 * np.linalg.norm(np.cross((b - a).T, (c - a).T), axis=1)


def tet_volumes(p, t):
    a, b, c, d = (p[:, t[i]] for i in range(4))
    return np.abs(np.einsum("ij,ij->j", b - a, np.cross((c - a).T, (d - a).T).T)) / 6


# --- finding geometries ---------------------------------------------------------------

def test_shipped_geometries_are_found_by_bare_name():
    assert fm.find_geometry("beam_line").name == "beam_line.geo"
    assert fm.find_geometry("beam_solid.geo").name == "beam_solid.geo"
    assert fm.geometry_parameters("beam_line") == ("length", "mesh_size", "probe_position")
    assert fm.geometry_parameters("beam_solid") == ("length", "width", "height", "mesh_size")


def test_mesh_path_directories_come_first(tmp_path, monkeypatch):
    own = write_geo(tmp_path, "beam_line", """\
        DefineConstant[ h = {0.5, Name "Parameters/h"} ];
        Point(1) = {0, 0, 0, h}; Point(2) = {1, 0, 0, h}; Line(1) = {1, 2};
        """)
    monkeypatch.setenv("FEMROM_MESH_PATH", f"{tmp_path / 'missing'}:{tmp_path}")
    with pytest.warns(UserWarning, match="missing is not a folder; it is skipped"):
        assert fm.find_geometry("beam_line") == own.resolve()
        assert fm.find_geometry(own) == own.resolve()
        assert fm.geometry_parameters("beam_line") == ("h",)


def test_unknown_geometry_lists_the_available_ones():
    with pytest.raises(MeshError, match=r"unknown geometry 'no_such_beam'.*beam_line, beam_solid"):
        fm.find_geometry("no_such_beam")
    with pytest.raises(MeshError, match="not found: 'nowhere/x.geo'"):
        fm.find_geometry("nowhere/x.geo")
    with pytest.raises(MeshError, match=r"\.geo file, got 'beam\.step'"):
        fm.find_geometry("beam.step")


def test_parameters_are_read_past_comments_strings_and_nested_braces(tmp_path):
    path = write_geo(tmp_path, "tricky", """\
        // DefineConstant[ commented = 1 ];
        /* DefineConstant[ blocked = 2 ]; */
        DefineConstant[
          a = {1, Name "Parameters/a, with comma // and slashes"},
          b = {2, Choices{0, 1, 2}, Name "Parameters/b"}, c = 3
        ];
        d = DefineNumber[4, Name "Parameters/d"];
        e = a + b;
        """)
    assert fm.geometry_parameters(path) == ("a", "b", "c", "d")


# --- generation and cache -------------------------------------------------------------

def test_generation_is_cached_and_force_regenerates(cache, monkeypatch):
    first = fm.generate_mesh("beam_line", {"mesh_size": 0.5}, cache_dir=cache)
    stamp = first.stat().st_mtime_ns

    def no_gmsh(*args):
        raise AssertionError("gmsh ran although the mesh is cached")

    with monkeypatch.context() as patched:
        patched.setattr("femrom.mesh._generate._run_gmsh", no_gmsh)
        assert fm.generate_mesh("beam_line", {"mesh_size": 1 / 2}, cache_dir=cache) == first
    again = fm.generate_mesh("beam_line", {"mesh_size": 0.5}, cache_dir=cache, force=True)
    assert again == first and again.stat().st_mtime_ns > stamp
    assert [p.name for p in cache.iterdir()] == [first.name]  # no temporary files left
    assert not gmsh.isInitialized()


def test_cache_key_follows_parameters_and_the_default_cache_dir(cache):
    coarse = fm.generate_mesh("beam_line", {"mesh_size": 0.5}, cache_dir=cache)
    fine = fm.generate_mesh("beam_line", {"mesh_size": 0.25}, cache_dir=cache)
    assert coarse != fine
    default = fm.generate_mesh("beam_line", {"mesh_size": 0.5})
    assert default.parent == cache.parent / "env-cache" / "meshes"
    assert default.name == coarse.name


def test_cache_key_follows_the_geometry_text(cache, tmp_path):
    text = """\
        DefineConstant[ h = {0.5, Name "Parameters/h"} ];
        Point(1) = {0, 0, 0, h}; Point(2) = {1, 0, 0, h}; Line(1) = {1, 2};
        """
    geo = write_geo(tmp_path, "line", text)
    before = fm.generate_mesh(geo, cache_dir=cache)
    geo.write_text(textwrap.dedent(text).replace("{1, 0, 0, h}", "{2, 0, 0, h}"))
    after = fm.generate_mesh(geo, cache_dir=cache)
    assert after != before
    assert fm.load_mesh(after).p.max() == pytest.approx(2.0)


def test_failed_write_leaves_no_file(cache, monkeypatch):
    def half_write(path):
        with open(path, "w") as f:
            f.write("$MeshFormat\n4.1 0 8\n")
        raise RuntimeError("disk full")

    monkeypatch.setattr(gmsh, "write", half_write)
    with pytest.raises(MeshError, match="disk full"):
        fm.generate_mesh("beam_line", cache_dir=cache)
    assert list(cache.iterdir()) == []
    assert not gmsh.isInitialized()


def test_sigint_handler_is_restored(cache):
    before = signal.getsignal(signal.SIGINT)
    fm.generate_mesh("beam_line", {"mesh_size": 0.3}, cache_dir=cache)
    assert signal.getsignal(signal.SIGINT) is before


def test_unknown_parameter_names_the_valid_ones(cache):
    with pytest.raises(MeshError, match=r"'beam_solid.geo' has no parameter 'thickness'; "
                                        r"valid: length, width, height, mesh_size"):
        fm.generate_mesh("beam_solid", {"thickness": 0.01}, cache_dir=cache)


@pytest.mark.parametrize("value", ["0.1", None, float("nan"), True])
def test_non_numeric_parameter_is_refused(cache, value):
    with pytest.raises(MeshError, match="parameter 'length' of geometry 'beam_line.geo'"):
        fm.generate_mesh("beam_line", {"length": value}, cache_dir=cache)


def test_gmsh_errors_name_the_geometry(cache):
    with pytest.raises(MeshError, match=r"beam_line\.geo.*probe_position must lie strictly"):
        fm.generate_mesh("beam_line", {"probe_position": 1.0}, cache_dir=cache)
    assert not gmsh.isInitialized()
    assert not cache.exists() or list(cache.iterdir()) == []


def test_parameter_reassigned_by_the_file_is_reported(cache, tmp_path):
    geo = write_geo(tmp_path, "stubborn", """\
        DefineConstant[ h = {0.5, Name "Parameters/h"} ];
        h = 0.25;
        Point(1) = {0, 0, 0, h}; Point(2) = {1, 0, 0, h}; Line(1) = {1, 2};
        """)
    with pytest.raises(MeshError, match="parameter 'h' of geometry 'stubborn.geo' was set to 0.1"):
        fm.generate_mesh(geo, {"h": 0.1}, cache_dir=cache)


def test_busy_gmsh_session_is_left_alone(cache):
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        with pytest.raises(MeshError, match="already initialized"):
            fm.generate_mesh("beam_line", cache_dir=cache)
        assert gmsh.isInitialized()
    finally:
        gmsh.finalize()


# --- 1D beam axis ---------------------------------------------------------------------

@pytest.mark.parametrize("length, mesh_size, elements", [(1.0, 0.25, 4), (2.5, 0.25, 10),
                                                         (2.5, 0.125, 20)])
def test_line_follows_length_and_mesh_size(cache, length, mesh_size, elements):
    mesh = fm.build_mesh("beam_line", {"length": length, "mesh_size": mesh_size},
                         cache_dir=cache)
    assert isinstance(mesh, MeshLine1) and mesh.p.shape[0] == 1
    # length / mesh_size is a whole number on each side of the mid-span probe,
    # so gmsh splits the axis into exactly that many equal elements.
    assert mesh.t.shape[1] == elements
    assert mesh.p.min() == 0.0 and mesh.p.max() == pytest.approx(length, rel=PLANE)
    sizes = np.diff(np.sort(mesh.p[0]))
    np.testing.assert_allclose(sizes, mesh_size, rtol=PLANE)


def test_line_boundaries_are_the_end_and_probe_nodes(cache):
    mesh = fm.build_mesh("beam_line", {"length": 2.0, "mesh_size": 0.3, "probe_position": 0.3},
                         cache_dir=cache)
    node = {name: mesh.facets[0, fm.boundary_facets(mesh, name)] for name in
            ("left", "right", "probe")}
    assert all(len(n) == 1 for n in node.values())
    assert mesh.p[0, node["left"][0]] == 0.0
    assert mesh.p[0, node["right"][0]] == pytest.approx(2.0, rel=PLANE)
    assert mesh.p[0, node["probe"][0]] == pytest.approx(0.6, rel=PLANE)
    np.testing.assert_array_equal(np.sort(fm.subdomain_elements(mesh, "beam")),
                                  np.arange(mesh.t.shape[1]))
    assert sorted(mesh.boundaries) == ["left", "probe", "right"]
    assert list(mesh.subdomains) == ["beam"]  # gmsh bookkeeping sets are dropped


def test_unknown_boundary_and_subdomain_list_the_known_ones(cache):
    mesh = fm.build_mesh("beam_line", {"mesh_size": 0.5}, cache_dir=cache)
    with pytest.raises(MeshError, match="no boundary 'tip'; available: left, probe, right"):
        fm.boundary_facets(mesh, "tip")
    with pytest.raises(MeshError, match="no subdomain 'joint'; available: beam"):
        fm.subdomain_elements(mesh, "joint")


# --- 3D solid beam --------------------------------------------------------------------

def test_solid_faces_lie_on_their_planes_and_cover_the_box(solid):
    L, W, H = SOLID["length"], SOLID["width"], SOLID["height"]
    assert isinstance(solid, MeshTet1)
    planes = {"left": (0, 0.0), "right": (0, L), "front": (1, 0.0), "back": (1, W),
              "bottom": (2, 0.0), "top": (2, H)}
    areas = {"left": W * H, "right": W * H, "front": L * H, "back": L * H,
             "bottom": L * W, "top": L * W}
    for name, (axis, value) in planes.items():
        facets = fm.boundary_facets(solid, name)
        corners = solid.p[axis][solid.facets[:, facets]]
        np.testing.assert_allclose(corners, value, atol=PLANE * L, err_msg=name)
        area = triangle_areas(solid.p, solid.facets[:, facets]).sum()
        assert area == pytest.approx(areas[name], rel=MEASURE), name
    named = np.sort(np.concatenate([fm.boundary_facets(solid, n) for n in planes]))
    np.testing.assert_array_equal(named, np.sort(solid.boundary_facets()))


def test_solid_volume_and_extent(solid):
    L, W, H = SOLID["length"], SOLID["width"], SOLID["height"]
    beam = fm.subdomain_elements(solid, "beam")
    assert len(beam) == solid.t.shape[1]
    assert tet_volumes(solid.p, solid.t[:, beam]).sum() == pytest.approx(L * W * H, rel=MEASURE)
    np.testing.assert_allclose(solid.p.min(axis=1), 0.0, atol=PLANE)
    np.testing.assert_allclose(solid.p.max(axis=1), [L, W, H], rtol=PLANE)


def test_solid_refines_with_mesh_size(solid, cache):
    finer = fm.build_mesh("beam_solid", {**SOLID, "mesh_size": 0.025}, cache_dir=cache)
    # Halving h multiplies the tetrahedra by about 2^3 (less where the
    # 0.05 m height already holds only one or two layers): require at least 4x.
    assert finer.t.shape[1] >= 4 * solid.t.shape[1]
    edges = np.linalg.norm(np.diff(finer.p[:, finer.edges], axis=1)[:, 0], axis=0) / 0.025
    # mesh_size is gmsh's target edge length: the typical (median) edge is
    # within 25 % of it (measured 1.08). Delaunay tets also have some longer
    # edges, face-diagonal like, but at most about twice
    # the target (measured 1.99 max).
    assert 0.8 < np.median(edges) < 1.25
    assert edges.max() < 2.5


# --- reading files --------------------------------------------------------------------

def test_two_dimensional_mesh_loads_as_triangles(cache, tmp_path):
    geo = write_geo(tmp_path, "plate", """\
        SetFactory("OpenCASCADE");
        DefineConstant[ mesh_size = {0.25, Name "Parameters/mesh_size"} ];
        Rectangle(1) = {0, 0, 0, 2, 1};
        Physical Curve("left") = Curve In BoundingBox{-1e-3, -1, -1, 1e-3, 2, 1};
        Physical Surface("plate") = {1};
        MeshSize{PointsOf{Surface{1};}} = mesh_size;
        """)
    mesh = fm.build_mesh(geo, cache_dir=cache)
    assert isinstance(mesh, MeshTri1) and mesh.p.shape[0] == 2
    left = mesh.p[:, mesh.facets[:, fm.boundary_facets(mesh, "left")]]
    np.testing.assert_allclose(left[0], 0.0, atol=PLANE)
    assert np.abs(np.diff(left[1], axis=0)).sum() == pytest.approx(1.0, rel=MEASURE)


def test_line_off_the_x_axis_is_refused(cache, tmp_path):
    geo = write_geo(tmp_path, "slanted", """\
        Point(1) = {0, 0, 0, 0.5}; Point(2) = {1, 1, 0, 0.5}; Line(1) = {1, 2};
        Physical Curve("beam") = {1};
        """)
    with pytest.raises(MeshError, match="1D mesh .*slanted.* is not flat"):
        fm.build_mesh(geo, cache_dir=cache)


def test_missing_file_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="absent.msh"):
        fm.load_mesh(tmp_path / "absent.msh")


@pytest.mark.parametrize("damage", ["garbage", "empty", "half", "tail", "ascii-half"])
def test_damaged_file_is_named(cache, tmp_path, damage):
    good = fm.generate_mesh("beam_solid", SOLID, cache_dir=cache).read_bytes()
    bad = tmp_path / f"{damage}.msh"
    if damage == "ascii-half":
        line = fm.generate_mesh("beam_line", cache_dir=cache)
        ascii_mesh = tmp_path / "ascii.msh"
        meshio.write(ascii_mesh, meshio.gmsh.read(line), file_format="gmsh", binary=False)
        data = ascii_mesh.read_bytes()
        bad.write_bytes(data[:len(data) // 2])
    else:
        bad.write_bytes({"garbage": b"this is not a mesh\n\x00\x01",
                         "empty": b"",
                         "half": good[:len(good) // 2],
                         "tail": good[:-40]}[damage])
    with pytest.raises(MeshError, match=re.escape(f"'{bad}'")):
        fm.load_mesh(bad)
