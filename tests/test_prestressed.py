"""A preloaded structure with a frictional joint (femrom.scene.prestressed_model and friends): a joint-law
parameter replaced, calibrated on a frequency it must reproduce, and the Iwan joint about the preload,
on the stacked blocks of tests/test_joint_prestress.py (P1, pressed together by a preload)."""

import numpy as np
import pytest

from femrom.scene import (
    PrestressedModel,
    build,
    calibrate_law_parameter,
    clamped_iwan_joint,
    linearized_modes,
    mode_frequency,
    point_supports,
    preload,
    with_law_parameters,
)
from test_joint_prestress import BLOCK_SUPPORTS, block_scene, joint_options, stacked_blocks


@pytest.fixture(scope="module")
def pressed_blocks():
    """The stacked P1 blocks pressed together (1e5 N), free, preloaded on BLOCK_SUPPORTS: a PrestressedModel."""
    scene = block_scene({"joint": joint_options(), "bolt_preload": {"washers": [["top", "bottom"]], "force": 1.0e5}})
    fom = build(scene, mesh=stacked_blocks(n=2, ny=1))
    supports = point_supports(fom.space, fom.system.condensation, BLOCK_SUPPORTS)
    return PrestressedModel(fom, supports, preload(fom.system, supports=supports), 0.0)


def test_a_law_parameter_is_replaced_and_the_rest_of_the_joint_kept(pressed_blocks):
    system = pressed_blocks.fom.system
    changed = with_law_parameters(system, tangential_stiffness=3e11)
    before, after = system.nonlinear.law.parameters(), changed.nonlinear.law.parameters()
    assert after["tangential_stiffness"] == 3e11
    assert {k: v for k, v in after.items() if k != "tangential_stiffness"} == \
        {k: v for k, v in before.items() if k != "tangential_stiffness"}
    np.testing.assert_array_equal(changed.nonlinear.areas, system.nonlinear.areas)
    assert changed.stiffness is system.stiffness


def test_the_calibrated_parameter_reproduces_the_frequency_it_was_set_by(pressed_blocks):
    # the first elastic mode of the free pressed blocks (six rigid-body modes first) rises with k_t
    # (the stuck interface's shear springs); k_t = 3e11 gives f_6, which the root find must return
    f_low, f_target, f_high = (mode_frequency(pressed_blocks, 6, tangential_stiffness=k) for k in (1e10, 3e11, 1e13))
    assert f_low < f_target < f_high
    value, evaluations = calibrate_law_parameter(pressed_blocks, "tangential_stiffness", f_target, (1e10, 1e13),
                                                 mode=6, xtol=1e-7)
    assert value == pytest.approx(3e11, rel=1e-5) and 3 <= evaluations <= 40
    # the frequency of the preloaded model as it stands (its own k_t = 1e12), and the shape check
    direct = linearized_modes(pressed_blocks.fom.system, pressed_blocks.preload.displacement,
                              pressed_blocks.preload.state, n_modes=7).frequencies[6]
    assert mode_frequency(pressed_blocks, 6) == pytest.approx(direct, rel=1e-12)
    with pytest.raises(RuntimeError, match="mode 6 is not of shape"):
        mode_frequency(pressed_blocks, 6, shape=("vertical", 99))


def test_the_iwan_joint_about_a_uniform_preload_keeps_its_equilibrium(pressed_blocks):
    # a uniform normal pressure carries no tangential traction: the Iwan sliders start unloaded and
    # the static equilibrium under the new law is the preload's (to Newton's tolerance)
    system, q0, z0 = clamped_iwan_joint(pressed_blocks.fom.system, pressed_blocks.preload.displacement,
                                        pressed_blocks.preload.state, pressed_blocks.supports,
                                        friction_coefficient=0.6, chi=-0.5, beta=0.9)
    law = system.nonlinear.law.parameters()
    assert law["name"] == "clamped_iwan" and (law["chi"], law["beta"]) == (-0.5, 0.9)
    assert law["tangential_stiffness"] == pressed_blocks.joint.law.parameters()["tangential_stiffness"]
    q = pressed_blocks.preload.displacement
    assert np.abs(q0 - q).max() < 1e-8 * np.abs(q).max()
    traction = system.nonlinear.tractions(q0, z0)
    assert np.abs(traction[:, :2]).max() < 1e-6 * np.abs(traction[:, 2]).max()


def test_the_iwan_joint_carries_the_reclosed_points_dashpot(pressed_blocks):
    # the dashpot of the reclosed points reaches the law and makes the joint velocity dependent; the static
    # equilibrium (at rest: no rate) is the one without it, bit for bit
    arguments = (pressed_blocks.fom.system, pressed_blocks.preload.displacement, pressed_blocks.preload.state,
                 pressed_blocks.supports)
    options = {"friction_coefficient": 0.6, "chi": -0.5, "beta": 0.9, "closing": 1e-3, "closing_friction": 0.6}
    damped, q0, z0 = clamped_iwan_joint(*arguments, **options, closing_damping=6e12)
    plain, q1, z1 = clamped_iwan_joint(*arguments, **options)
    assert damped.nonlinear.law.closing_damping == 6e12 and damped.nonlinear.velocity_dependent
    assert not plain.nonlinear.velocity_dependent
    assert np.array_equal(q0, q1) and np.array_equal(z0, z1)
