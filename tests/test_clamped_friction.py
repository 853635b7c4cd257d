"""The clamped-friction law: dry friction with the preload's contact status and slip traction frozen."""

import numpy as np
import pytest

from femrom.fem import ClampedFrictionLaw, DryFrictionLaw, clamped_state, interface_law

K_N, K_T, MU = 1e12, 5e10, 0.5


def _preload(g_n):
    """Points at normal gaps ``g_n`` (s,), sliders at zero: the clamped state and the dry law."""
    gap = np.column_stack([np.zeros_like(g_n), np.zeros_like(g_n), g_n])
    state = clamped_state(gap, np.zeros((g_n.size, 2)), normal_stiffness=K_N, friction_coefficient=MU)
    return gap, state


def test_under_a_fixed_normal_gap_it_is_dry_friction():
    # the same tangential cycle at a fixed penetration: tractions and dissipation equal dry friction's
    g_n = np.array([-1e-6, -2e-7, -5e-8])
    gap, clamped = _preload(g_n)
    law, dry = ClampedFrictionLaw(K_N, K_T), DryFrictionLaw(K_N, K_T, MU)
    z_c, z_d = clamped, np.zeros((3, 2))
    path = 4e-6 * np.sin(np.linspace(0, 4 * np.pi, 81))
    for u in path:
        g = gap.copy()
        g[:, 0] = u
        t_c, D_c = law.evaluate(g, z_c)
        t_d, D_d = dry.evaluate(g, z_d)
        assert np.allclose(t_c, t_d, rtol=1e-12, atol=1e-6)
        assert np.allclose(law.dissipation(g, z_c), dry.dissipation(g, z_d), rtol=1e-12, atol=1e-18)
        assert np.allclose(D_c[:, :2, :2], D_d[:, :2, :2], rtol=1e-12)  # no normal coupling here, though
        z_c, z_d = law.commit(g, z_c), dry.commit(g, z_d)
    assert np.allclose(z_c[:, :2], z_d)


def test_open_points_carry_nothing_and_closed_ones_hold_tension():
    gap, state = _preload(np.array([-1e-6, 2e-6]))
    law = ClampedFrictionLaw(K_N, K_T)
    pulled = gap + np.array([1e-7, 0.0, 3e-6])  # both pulled apart by 3 um
    traction, D = law.evaluate(pulled, state)
    assert np.allclose(traction[1], 0.0) and np.allclose(D[1], 0.0)        # open at the preload: nothing
    assert traction[0, 2] == pytest.approx(K_N * 2e-6)                       # bilateral: tension, frozen status
    assert traction[0, 0] == pytest.approx(K_T * 1e-7)                       # stuck: the spring


def test_a_jenkins_cycle_dissipates_the_closed_form():
    # 1-D cycles of amplitude x_a beyond slip: 4 tau_s (x_a - tau_s / k_t) per unit area
    gap, state = _preload(np.array([-1e-6]))
    tau = MU * K_N * 1e-6
    x_a = 3 * tau / K_T
    law = ClampedFrictionLaw(K_N, K_T)
    u = x_a * np.sin(np.linspace(0, 2 * np.pi, 4001))
    energy, z = 0.0, state
    for k in range(1, u.size):  # start one quarter in (monotonic loading), then two full cycles
        g = gap.copy()
        g[:, 0] = u[k]
        energy += float(law.dissipation(g, z)[0])
        z = law.commit(g, z)
    start, cycle = energy, 0.0
    for k in range(1, u.size):
        g = gap.copy()
        g[:, 0] = u[k]
        cycle += float(law.dissipation(g, z)[0])
        z = law.commit(g, z)
    # the discrete path samples the turning points exactly: equal to round-off (measured 1e-15)
    assert cycle == pytest.approx(4 * tau * (x_a - tau / K_T), rel=1e-9)
    assert start < cycle   # the first (virgin) cycle starts from the centre


def test_the_law_is_registered_and_checks_its_parameters():
    assert isinstance(interface_law("clamped_friction", normal_stiffness=K_N, tangential_stiffness=K_T),
                      ClampedFrictionLaw)
    with pytest.raises(ValueError, match="tangential_stiffness"):
        ClampedFrictionLaw(K_N, -1.0)
    with pytest.raises(ValueError, match=r"gap must be \(s, 3\) and dry_state \(s, 2\)"):
        clamped_state(np.zeros((3, 2)), np.zeros((3, 2)), normal_stiffness=K_N, friction_coefficient=MU)
