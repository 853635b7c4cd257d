"""Lines of probes ([[outputs.lines]]): n points along a polyline, each the mean of a
displacement component over its nearest nodes."""

import numpy as np
import pytest
from skfem import MeshTet

from femrom.fem import SolidSpace, nearest_node_rows
from femrom.scene import LineConfig, Scene, SceneError, build

LINE = {"name": "centreline", "start": [0.03, 0.043, 0.057], "end": [0.96, 0.047, 0.052], "points": 5,
        "components": ["x", "z"], "nodes": 6}


def _mesh():
    return MeshTet.init_tensor(np.linspace(0.0, 1.0, 9), np.linspace(0.0, 0.1, 3), np.linspace(0.0, 0.1, 3))


def _scene(lines, **outputs):
    return Scene.from_dict({
        "name": "box", "structure": {"geometry": "beam_solid", "element": "p2"},
        "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3, "density": 1e3},
        "effects": {"inertia": {}, "elasticity": {}}, "time": {"t_end": 1.0, "dt": 0.1},
        "outputs": {"lines": lines, **outputs}})


@pytest.fixture(scope="module")
def model():
    return build(_scene([LINE]), mesh=_mesh())


def test_outputs_are_named_point_by_point(model):
    names = model.system.output_names
    assert len(names) == 10 and model.system.output_matrix.shape == (10, model.system.n_dofs)
    assert names[:3] == ("centreline_00_x", "centreline_00_z", "centreline_01_x")
    assert names[-1] == "centreline_04_z"
    points = LineConfig.from_dict(LINE, 0).locations()
    np.testing.assert_allclose(points[:, 0], np.linspace(0.03, 0.96, 5), rtol=0, atol=1e-15)


def test_a_rigid_translation_reads_the_translation_everywhere(model):
    """Each row holds n weights 1/n on one component: a translation is read exactly (to the
    round-off of summing six 1/6 weights, 1e-15)."""
    space, cond = model.space, model.system.condensation
    q = np.zeros(space.n_total)
    shift = {"x": 0.3, "y": -0.7, "z": 1.1}
    for c, a in shift.items():
        q[space.coordinates(c)[0]] = a
    y = model.system.output_matrix @ cond.vector(q)
    expected = np.tile([shift["x"], shift["z"]], 5)
    np.testing.assert_allclose(y, expected, rtol=0, atol=1e-15)


def test_a_linear_field_reads_its_value_at_the_centroid_of_the_nearest_nodes(model):
    """The nodal interpolant of a linear field is exact at the nodes, so a row reads the field
    at the centroid of its nodes; the nodes are found here by brute force over all distances."""
    space, cond = model.space, model.system.condensation
    field = {"x": lambda x, y, z: 0.2 + 2.0 * x - 3.0 * y + 0.5 * z,
             "z": lambda x, y, z: -1.0 + x + 4.0 * y - 2.0 * z}
    q = sum(space.interpolate(f, c) for c, f in field.items())
    y = model.system.output_matrix @ cond.vector(q)
    _, where = space.coordinates("x")                        # every scalar node: (3, n_nodes)
    for i, point in enumerate(LineConfig.from_dict(LINE, 0).locations()):
        distances = np.linalg.norm(where - point[:, None], axis=0)
        nearest = np.argsort(distances, kind="stable")[:LINE["nodes"]]
        # no tie at the 6th / 7th node of these points (else the choice would be arbitrary)
        assert np.sort(distances)[LINE["nodes"]] > np.sort(distances)[LINE["nodes"] - 1] + 1e-9
        centroid = where[:, nearest].mean(axis=1)
        for k, c in enumerate(("x", "z")):
            assert abs(y[2 * i + k] - field[c](*centroid)) < 1e-13
        # the centroid is not the point itself: the test would catch reading at the point
        assert np.linalg.norm(centroid - point) > 1e-3


def test_one_nearest_node_is_that_node():
    space = SolidSpace(_mesh(), "p1")
    row = nearest_node_rows(space.basis, [[0.126, 0.0, 0.049]], 2, 1)
    dofs, where = space.coordinates("z")
    closest = dofs[np.argmin(np.linalg.norm(where - np.array([[0.126], [0.0], [0.049]]), axis=0))]
    assert row.nnz == 1 and row[0, closest] == 1.0


def test_a_polyline_spaces_points_by_arc_length():
    line = LineConfig.from_dict({"name": "bent", "path": [[0, 0, 0], [1, 0, 0], [1, 0, 2]], "points": 4,
                                 "components": ["x"]}, 0)
    np.testing.assert_allclose(line.locations(), [[0, 0, 0], [1, 0, 0], [1, 0, 1], [1, 0, 2]], atol=1e-15)
    assert [p.name for p in line.probes()] == ["bent_00_x", "bent_01_x", "bent_02_x", "bent_03_x"]
    assert LineConfig.from_dict({**LINE, "points": 101}, 0).probes()[-1].name == "centreline_100_z"


@pytest.mark.parametrize("change, fragment", [
    ({"points": 1}, "[outputs.lines[0]] points must be a whole number >= 2, got 1"),
    ({"nodes": 0}, "[outputs.lines[0]] nodes must be a whole number >= 1, got 0"),
    ({"end": None}, "[outputs.lines[0]] needs 'start' and 'end' points"),
    ({"path": [[0, 0, 0], [1, 0, 0]]}, "give 'path' (a polyline) or 'start' and 'end', not both"),
    ({"start": None, "end": None, "path": [[0, 0, 0], [0, 0, 0]]}, "two equal consecutive points"),
    ({"components": "xz"}, "components must be a list of names"),
    ({"components": ["x", "x"]}, "components are listed twice"),
    ({"colour": "red"}, "unknown key 'colour' in [outputs.lines[0]]"),
])
def test_bad_line_specs_are_one_line_errors(change, fragment):
    line = {k: v for k, v in {**LINE, **change}.items() if v is not None}
    with pytest.raises(SceneError) as info:
        _scene([line])
    assert fragment in str(info.value) and "\n" not in str(info.value)


def test_clashing_names_and_bad_places_are_one_line_errors():
    with pytest.raises(SceneError, match="output names must be unique"):
        _scene([LINE], probes=[{"name": "centreline_00_x", "at": [0.5, 0.05, 0.05], "component": "x"}])
    with pytest.raises(SceneError, match=r"\[outputs.probes\[0\] \(centreline_00_w\)\] unknown component 'w'"):
        build(_scene([{**LINE, "components": ["w"]}]), mesh=_mesh())
    with pytest.raises(SceneError, match=r"lies outside the mesh"):
        build(_scene([{**LINE, "end": [2.0, 0.05, 0.05]}]), mesh=_mesh())


def test_a_point_probe_may_average_its_nearest_nodes(model):
    mid = LineConfig.from_dict(LINE, 0).locations()[2].tolist()
    scene = _scene([], probes=[{"name": "mid", "at": mid, "component": "x", "nodes": 6}])
    row = build(scene, mesh=_mesh()).system.output_matrix
    assert np.allclose(row.toarray(), model.system.output_matrix[4].toarray())     # centreline_02_x
