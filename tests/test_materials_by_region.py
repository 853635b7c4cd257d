"""Several materials by region ([materials]): springs in series, masses, the one-material
spelling, and the one-line errors of a bad table."""

import numpy as np
import pytest
from skfem import MeshTet

from femrom.fem import ElementMaterial
from femrom.scene import Scene, SceneError, build, element_materials
from femrom.solvers import make_solver

LENGTH, SIDE = 1.0, 0.1
LEFT_LENGTH = 0.4                    # the material interface is the node plane x = 0.4
E_LEFT, E_RIGHT = 5.0e5, 2.0e6
RHO_LEFT, RHO_RIGHT = 1100.0, 7800.0
TRACTION = 1.0e3                     # Pa on the free end: an axial force of TRACTION * SIDE^2


def _bar(overlapping=False, unnamed=False):
    """A box bar along x on a tensor mesh: regions left (x < 0.4) and right, ends named."""
    mesh = MeshTet.init_tensor(np.linspace(0.0, LENGTH, 11), np.linspace(0.0, SIDE, 3), np.linspace(0.0, SIDE, 3))
    mesh = mesh.with_boundaries({"fixed_end": lambda x: np.isclose(x[0], 0.0),
                                 "loaded_end": lambda x: np.isclose(x[0], LENGTH)})
    regions = {"left": lambda x: x[0] < LEFT_LENGTH, "right": lambda x: x[0] > LEFT_LENGTH}
    if overlapping:
        regions["middle"] = lambda x: abs(x[0] - 0.5) < 0.15
    if unnamed:
        regions = {"left": regions["left"]}
    return mesh.with_subdomains(regions)


def _scene(material=None, materials=None, nu=0.0, damping=False):
    data = {
        "name": "bar",
        "structure": {"geometry": "beam_solid", "element": "p2"},
        "effects": {"inertia": {}, "elasticity": {}, "actuation": {}},
        "boundary": {"clamped": ["fixed_end"]},
        "inputs": [{"name": "pull", "signal": {"kind": "step"},
                    "load": {"kind": "surface_traction", "at": "loaded_end", "direction": [1.0, 0.0, 0.0],
                             "magnitude": TRACTION}}],
        "time": {"t_end": 1.0, "dt": 0.1},
        "outputs": {"averages": [{"name": "end_x", "over": "loaded_end", "component": "x"}]},
    }
    if damping:
        data["effects"]["damping"] = {"alpha": 0.3, "beta": 2e-3}
    if material is not None:
        data["material"] = material
    if materials is not None:
        data["materials"] = materials
    return Scene.from_dict(data)


TWO = {"soft": {"regions": ["left"], "youngs_modulus": E_LEFT, "poisson_ratio": 0.0, "density": RHO_LEFT},
       "stiff": {"regions": ["right"], "youngs_modulus": E_RIGHT, "poisson_ratio": 0.0, "density": RHO_RIGHT}}


def test_two_material_bar_is_two_springs_in_series():
    """With nu = 0 the exact field is u_x piecewise linear in x (uniform stress F/A in each
    part), which P2 on a mesh with a node plane at the interface represents exactly: the end
    moves F (L_1 / (E_1 A) + L_2 / (E_2 A)) up to the solve's round-off."""
    model = build(_scene(materials=TWO), mesh=_bar())
    system = model.system
    q = make_solver(system.stiffness).solve(np.asarray(system.input_matrix)[:, 0])
    end = float((system.output_matrix @ q)[0])
    area = SIDE * SIDE
    force = TRACTION * area
    exact = force * (LEFT_LENGTH / (E_LEFT * area) + (LENGTH - LEFT_LENGTH) / (E_RIGHT * area))
    # a direct sparse solve of a well-conditioned 1e3-dof system: 1e-9 is round-off with margin
    assert abs(end - exact) < 1e-9 * exact
    # the swapped materials give another answer: the moduli really sit where the regions are
    swapped = {"soft": {**TWO["soft"], "regions": ["right"]}, "stiff": {**TWO["stiff"], "regions": ["left"]}}
    model = build(_scene(materials=swapped), mesh=_bar())
    q = make_solver(model.system.stiffness).solve(np.asarray(model.system.input_matrix)[:, 0])
    other = force * (LEFT_LENGTH / (E_RIGHT * area) + (LENGTH - LEFT_LENGTH) / (E_LEFT * area))
    assert abs(float((model.system.output_matrix @ q)[0]) - other) < 1e-9 * other
    assert abs(other - exact) > 0.2 * exact          # 1.4 mm against 1.1 mm


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_total_mass_is_the_sum_of_density_times_volume(mass):
    """1^T M e_x = sum_i rho_i V_i: every element carries its own density (to round-off, 1e-12);
    a free bar, so that the system's mass is the whole mass."""
    scene = Scene.from_dict({**_scene_dict(), "effects": {"inertia": {"mass": mass}, "elasticity": {}}})
    system = build(scene, mesh=_bar()).system
    unit = np.zeros(system.n_dofs)
    unit[0::3] = 1.0
    exact = RHO_LEFT * LEFT_LENGTH * SIDE ** 2 + RHO_RIGHT * (LENGTH - LEFT_LENGTH) * SIDE ** 2
    assert abs(unit @ (system.mass @ unit) - exact) < 1e-12 * exact
    # one density everywhere would be off by far more than round-off
    assert abs(RHO_LEFT * LENGTH * SIDE ** 2 - exact) > 0.5 * exact


def _scene_dict():
    return {"name": "bar", "structure": {"geometry": "beam_solid", "element": "p2"}, "materials": TWO,
            "time": {"t_end": 1.0, "dt": 0.1}}


def test_one_material_gives_identical_matrices_in_either_spelling():
    """[material] and one [materials] table covering every region: the same M, K, C, B bit for bit."""
    constants = {"youngs_modulus": 2.0e6, "poisson_ratio": 0.45, "density": 1100.0}
    one = build(_scene(material=constants, damping=True), mesh=_bar()).system
    by_region = build(_scene(materials={"all": {"regions": ["left", "right"], **constants}}, damping=True),
                      mesh=_bar()).system
    for name in ("mass", "stiffness", "damping"):
        a, b = getattr(one, name).tocsr(), getattr(by_region, name).tocsr()
        assert np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices), name
        assert np.array_equal(a.data, b.data), name
    assert np.array_equal(np.asarray(one.input_matrix), np.asarray(by_region.input_matrix))


def test_per_element_constants_follow_the_regions():
    materials = _scene(materials=TWO).materials
    mesh = _bar()
    field = element_materials(materials, mesh)
    assert isinstance(field, ElementMaterial) and field.n_elements == mesh.nelements
    assert np.all(field.youngs_modulus[mesh.subdomains["left"]] == E_LEFT)
    assert np.all(field.density[mesh.subdomains["right"]] == RHO_RIGHT)


@pytest.mark.parametrize("materials, mesh_options, fragment", [
    ({**TWO, "extra": {"regions": ["fin"], "youngs_modulus": 1e6, "poisson_ratio": 0.3, "density": 1e3}}, {},
     "[materials.extra] unknown region 'fin'; the mesh's regions: left, right"),
    ({"soft": TWO["soft"]}, {}, "[materials] region 'right' has no material"),
    ({**TWO, "mid": {**TWO["soft"], "regions": ["middle"]}}, {"overlapping": True},
     "[materials.mid] region 'middle' overlaps a region of [materials."),
    ({"soft": TWO["soft"]}, {"unnamed": True}, "elements lie in no named region"),
])
def test_bad_region_tables_are_one_line_errors_when_built(materials, mesh_options, fragment):
    scene = _scene(materials=materials)
    with pytest.raises(SceneError) as info:
        build(scene, mesh=_bar(**mesh_options))
    assert fragment in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("sections, fragment", [
    ({"materials": {"soft": {**TWO["soft"], "youngs_modulus": -2.0e6}}},
     "[materials.soft] youngs_modulus must be a finite positive number, got -2000000.0"),
    ({"materials": {"soft": {**TWO["soft"], "poisson_ratio": 0.5}}},
     "[materials.soft] poisson_ratio must lie in (-1, 0.5)"),
    ({"materials": {"soft": {"youngs_modulus": 1e6, "density": 1e3}}}, "missing key 'poisson_ratio' in [materials.soft]"),
    ({"materials": {"a": TWO["soft"], "b": TWO["soft"]}},
     "[materials] region 'left' has two materials: [materials.a] and [materials.b]"),
    ({"materials": {"soft": {**TWO["soft"], "area": 1.0}}}, "unknown key 'area' in [materials.soft]"),
    ({"materials": TWO, "material": {"youngs_modulus": 1.0, "density": 1.0}}, "give one of [material]"),
    ({}, "missing section [material] (or [materials], by region)"),
    ({"materials": {}}, "[materials] must be a table of [materials.<region>] tables"),
])
def test_bad_material_tables_are_one_line_errors_when_read(sections, fragment):
    data = {"name": "bar", "structure": {"geometry": "beam_solid", "element": "p2"},
            "effects": {"inertia": {}, "elasticity": {}}, "time": {"t_end": 1.0, "dt": 0.1}, **sections}
    with pytest.raises(SceneError) as info:
        Scene.from_dict(data)
    assert fragment in str(info.value) and "\n" not in str(info.value)


def test_materials_on_a_line_are_refused():
    from skfem import MeshLine

    mesh = MeshLine(np.linspace(0.0, 1.0, 5)).with_subdomains({"all": lambda x: x[0] >= 0})
    scene = Scene.from_dict({"name": "line", "structure": {"geometry": "beam_line", "element": "p1"},
                             "materials": {"all": TWO["soft"] | {"regions": ["all"]}},
                             "effects": {"inertia": {}, "elasticity": {}}, "time": {"t_end": 1.0, "dt": 0.1}})
    with pytest.raises(SceneError, match=r"\[materials\] \(a material per region\) needs a solid mesh"):
        build(scene, mesh=mesh)


def test_a_sweep_varies_one_region_material():
    from femrom.scene import SweepConfig

    data = {**_scene_dict(), "effects": {"inertia": {}, "elasticity": {}}}
    sweep = SweepConfig.from_dict({"parameters": {"materials.stiff.youngs_modulus": [1e5, 2e5]}}, data)
    scene = Scene.from_dict(data).with_parameters([(sweep.parameters[0][0], 1e5)])
    assert [m.youngs_modulus for m in scene.materials] == [E_LEFT, 1e5]
    with pytest.raises(SceneError, match=r"poisson_ratio must lie in \(-1, 0.5\)"):
        SweepConfig.from_dict({"parameters": {"materials.stiff.poisson_ratio": [0.6]}}, data)
    with pytest.raises(SceneError, match=r"\[materials.fin\] has no number 'density'"):
        SweepConfig.from_dict({"parameters": {"materials.fin.density": [1.0]}}, data)


def test_a_conditioning_refusal_names_the_region_materials():
    """A density in the wrong units (1e-200 kg/m^3) is refused before the run, and the message
    lists the [materials] tables, as it lists [material] for a one-material scene."""
    from femrom.integrators import ConditioningError, simulate

    tiny = {**TWO, "stiff": {**TWO["stiff"], "density": 1e-200}, "soft": {**TWO["soft"], "density": 1e-200}}
    model = build(_scene(materials=tiny), mesh=_bar())
    with pytest.raises(ConditioningError) as info:
        simulate(model, progress=False)
    message = str(info.value)
    assert "[materials] soft: youngs_modulus = 500000" in message and "stiff: youngs_modulus = 2e+06" in message
