"""Scenes: strict configuration, signals, and 'only the listed effects are assembled'."""

import numpy as np
import pytest
from skfem import MeshLine

import femrom.fem as fem
from femrom.scene import Scene, SceneError, Signal, build

BEAM = {
    "name": "unit",
    "structure": {"geometry": "beam_line", "element": "hermite", "parameters": {"length": 1.0, "mesh_size": 0.1}},
    "material": {"youngs_modulus": 2.1e11, "density": 7850.0, "area": 2e-4, "second_moment": 1.6667e-9},
    "effects": {"inertia": {}, "bending": {}},
    "boundary": {"clamped": ["left"]},
    "initial_conditions": {"kind": "expression", "displacement": "1e-3 * x**2"},
    "time": {"t_end": 0.01, "dt": 1e-3},
    "outputs": {"probes": [{"name": "tip", "at": "right", "component": "w"}]},
}


def _line_mesh(n=10):
    return MeshLine(np.linspace(0.0, 1.0, n + 1)).with_boundaries(
        {"left": lambda x: np.isclose(x[0], 0.0), "right": lambda x: np.isclose(x[0], 1.0)})


def _with(**sections):
    data = {k: (dict(v) if isinstance(v, dict) else v) for k, v in BEAM.items()}
    data.update(sections)
    return data


@pytest.mark.parametrize("data, fragment", [
    (_with(effects={"inertia": {}, "bending": {}, "magic": {}}), "unknown effect 'magic'; valid effects: inertia"),
    (_with(material={"youngs_modulus": 1.0, "density": 1.0, "colour": "red"}), "unknown key 'colour' in [material]"),
    (_with(time={"t_end": 1.0, "dt": -0.1}), "0 < dt <= t_end"),
    (_with(effects={"inertia": {"mass": "consistent", "lump": 1}, "bending": {}}), "unknown key 'lump' in [effects.inertia]"),
    (_with(gravity=9.81), "unknown section 'gravity'"),
    (_with(inputs=[{"load": {"at": "right"}, "signal": {"kind": "step"}}]), "not the 'actuation' effect"),
])
def test_bad_scene_is_one_clear_error(data, fragment):
    with pytest.raises(SceneError) as info:
        Scene.from_dict(data)
    assert fragment in str(info.value)


def test_unknown_integrator_is_named_with_the_registered_schemes():
    """The scene layer sits below the integrators, so ``[time] integrator`` is checked
    where the schemes are registered: by ``scheme_for``, before anything is built."""
    from femrom.integrators import registered_schemes, scheme_for, time_scheme

    scene = Scene.from_dict(_with(time={"t_end": 1.0, "dt": 0.1, "integrator": "rk4"}))
    with pytest.raises(ValueError, match=r"unknown integrator 'rk4' in \[time\]; valid: central_difference, "
                                         r"discrete_gradient, generalized_alpha, implicit_midpoint, newmark"):
        scheme_for(scene.time)
    assert {name for name, cls in registered_schemes().items() if "second_order" in cls.models} == {
        "central_difference", "discrete_gradient", "generalized_alpha", "implicit_midpoint", "newmark"}
    assert time_scheme("verlet").name == "central_difference" and time_scheme("midpoint").name == "implicit_midpoint"
    alpha = scheme_for(Scene.from_dict(_with(time={"t_end": 1.0, "dt": 0.1, "integrator": "generalized_alpha",
                                                   "spectral_radius": 0.6})).time)
    assert alpha.spectral_radius == 0.6


def test_scene_file_errors_name_the_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[structure\n")
    with pytest.raises(SceneError, match="broken.toml: invalid TOML"):
        Scene.from_toml(path)
    with pytest.raises(SceneError, match="scene file not found"):
        Scene.from_toml(tmp_path / "absent.toml")


def test_unknown_component_and_boundary_are_named():
    with pytest.raises(ValueError, match="unknown component 'z'; valid: w, slope"):
        build(Scene.from_dict(_with(outputs={"probes": [{"at": "right", "component": "z"}]})), mesh=_line_mesh())
    with pytest.raises(ValueError, match="no boundary 'middle'"):
        build(Scene.from_dict(_with(boundary={"clamped": ["middle"]})), mesh=_line_mesh())


def test_signals():
    t = np.array([-1.0, 0.0, 0.25, 0.5, 1.0, 2.0])
    assert np.allclose(Signal.from_dict({"kind": "step", "amplitude": 2.0})(t), [0, 2, 2, 2, 2, 2])
    impulse = Signal.from_dict({"kind": "impulse", "amplitude": 3.0, "duration": 1.0})
    assert np.allclose(impulse(t), [0, 0, 3 * np.sin(np.pi / 4), 3, 0, 0], atol=1e-12)
    sine = Signal.from_dict({"kind": "sine", "frequency": 0.25})
    assert np.allclose(sine(t), [0, 0, np.sin(np.pi / 8), np.sin(np.pi / 4), 1, 0], atol=1e-12)
    sig = Signal.from_dict({"kind": "sigmoid", "midpoint": 1.0, "width": 0.1})
    assert sig(1.0) == pytest.approx(0.5) and sig(2.0) > 0.9999
    arr = Signal.from_dict({"kind": "array", "times": [0.0, 1.0], "values": [0.0, 4.0]})
    assert np.allclose(arr(t), [0, 0, 1, 2, 4, 0])
    with pytest.raises(SceneError, match="unknown signal kind 'chirp'"):
        Signal.from_dict({"kind": "chirp"})
    with pytest.raises(SceneError, match="unknown key 'freq'"):
        Signal.from_dict({"kind": "sine", "freq": 1.0})


def test_scene_without_damping_or_inputs_never_assembles_them(monkeypatch):
    """Principle 1 of DESIGN.md: nothing is assembled that the scene does not list."""
    def forbidden(*args, **kwargs):
        raise AssertionError("assembled an operator the scene does not list")

    monkeypatch.setattr(fem, "rayleigh_damping", forbidden)
    monkeypatch.setattr(fem.LineSpace, "load_vector", forbidden)
    monkeypatch.setattr(fem.LocalPotential, "sine_gordon", forbidden)
    model = build(Scene.from_dict(BEAM), mesh=_line_mesh())
    s = model.system
    assert s.damping is None and s.input_matrix is None and s.inputs is None and s.nonlinear is None
    assert s.effects == ("inertia", "stiffness", "outputs")
    # and the same scene with damping and an input does assemble them (the
    # monkeypatched functions are really the ones the builder calls)
    damped = _with(effects={"inertia": {}, "bending": {}, "damping": {"alpha": 0.1}})
    with pytest.raises(AssertionError, match="does not list"):
        build(Scene.from_dict(damped), mesh=_line_mesh())
    actuated = _with(effects={"inertia": {}, "bending": {}, "actuation": {}},
                     inputs=[{"load": {"at": "right", "component": "w"}, "signal": {"kind": "step"}}])
    with pytest.raises(AssertionError, match="does not list"):
        build(Scene.from_dict(actuated), mesh=_line_mesh())


def test_full_scene_assembles_every_listed_effect():
    data = _with(
        effects={"inertia": {"mass": "lumped"}, "bending": {}, "damping": {"alpha": 0.5, "beta": 1e-5},
                 "actuation": {}},
        inputs=[{"name": "tip_force", "load": {"at": "right", "component": "w", "magnitude": 2.0},
                 "signal": {"kind": "sine", "frequency": 5.0}}],
    )
    model = build(Scene.from_dict(data), mesh=_line_mesh())
    s = model.system
    assert s.has_diagonal_mass
    assert (s.damping - (0.5 * s.mass + 1e-5 * s.stiffness)).count_nonzero() == 0
    # the tip load column is 2 at the tip deflection dof, zero elsewhere
    assert s.input_matrix.shape == (s.n_dofs, 1) and s.input_matrix.sum() == pytest.approx(2.0)
    assert s.external_force(0.05) == pytest.approx(np.sin(2 * np.pi * 5.0 * 0.05) * s.input_matrix[:, 0])
    # the initial condition 1e-3 x^2 is interpolated in value and slope; the tip probe reads it
    assert float(s.outputs(model.initial_displacement)[0]) == pytest.approx(1e-3)
    assert np.all(s.full_field(model.initial_displacement)[:2] == 0)  # clamped dofs stay zero


def test_scene_edits_return_new_scenes_that_build_what_they_say():
    scene = Scene.from_dict(BEAM)
    finer = scene.with_geometry(mesh_size=0.05).with_time(dt=5e-4, t_end=0.02)
    # the edit is a new scene; the original and the untouched entries stay as they were
    assert dict(scene.structure.parameters)["mesh_size"] == 0.1 and scene.time.dt == 1e-3
    assert dict(finer.structure.parameters) == {"length": 1.0, "mesh_size": 0.05}
    assert (finer.time.dt, finer.time.t_end, finer.time.integrator) == (5e-4, 0.02, scene.time.integrator)
    # the geometry parameter reaches the mesh: 10 -> 20 Hermite elements, clamped at one end,
    # 2 dofs per node: 2 * 10 and 2 * 20 free dofs
    assert (build(scene).system.n_dofs, build(finer).system.n_dofs) == (20, 40)
    with pytest.raises(TypeError):
        scene.with_time(timestep=1e-3)     # not a [time] entry


def test_free_coordinates_locate_each_component_in_the_free_dof_vector():
    model = build(Scene.from_dict(BEAM), mesh=_line_mesh())
    x_nodes = np.linspace(0.0, 1.0, 11)
    index, points = model.free_coordinates()                 # the first component: w
    # the clamped node x = 0 has no free dof; the 10 others in node order
    assert points.shape == (1, 10) and index.shape == (10,)
    np.testing.assert_allclose(points[0], x_nodes[1:], rtol=0, atol=1e-15)
    # the initial condition is the nodal interpolant of 1e-3 x^2 (values exact to round-off),
    # so the positions pick the values out of the free vector and nothing else
    np.testing.assert_allclose(model.initial_displacement[index], 1e-3 * points[0] ** 2, rtol=1e-14)
    slope_index, slope_points = model.free_coordinates("slope")
    # slopes: central differences of 1e-3 x^2 with step 1e-6 (exact for a quadratic up to
    # round-off 1e-3 * 1e-16 / 1e-6 = 1e-13)
    np.testing.assert_allclose(model.initial_displacement[slope_index], 2e-3 * slope_points[0], rtol=0, atol=1e-12)
    # together the two components are every free dof, once
    np.testing.assert_array_equal(np.sort(np.concatenate([index, slope_index])), np.arange(model.system.n_dofs))
