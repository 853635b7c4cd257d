"""The clamped Iwan law: Segalman's element with macro-slip traction mu p_0 at the preload's closed points."""

import numpy as np
import pytest

from femrom.fem import ClampedIwanLaw, IwanLaw, clamped_iwan_state, clamped_state, interface_law

K_N, K_T, MU, CHI, BETA = 1e12, 5e10, 0.5, -0.5, 0.4


def _preload(g_n, law):
    """Points at normal gaps ``g_n`` (s,), sliders at zero: the clamped-Iwan state."""
    gap = np.column_stack([np.zeros_like(g_n), np.zeros_like(g_n), g_n])
    clamped = clamped_state(gap, np.zeros((g_n.size, 2)), normal_stiffness=K_N, friction_coefficient=MU)
    return gap, clamped_iwan_state(law, gap, clamped)


def _cycle(law, gap, state, path, component=0):
    """Walk the tangential displacement along ``path``: (tractions (k, s), dissipation per step (k, s), state)."""
    tractions, dissipated = [], []
    for u in path:
        g = gap.copy()
        g[:, component] = u
        tractions.append(law.traction(g, state)[:, component])
        dissipated.append(law.dissipation(g, state))
        state = law.commit(g, state)
    return np.array(tractions), np.array(dissipated), state


def test_each_closed_point_is_the_iwan_element_of_its_own_slip_traction():
    # the power-law density's slider stiffnesses do not depend on F_S and its strengths scale with it,
    # so a point of slip traction tau = mu p_0 is exactly IwanLaw(F_S = tau): equal to round-off
    law = ClampedIwanLaw(K_N, K_T, CHI, BETA)
    g_n = np.array([-1e-6, -2e-7])
    gap, state = _preload(g_n, law)
    taus = MU * K_N * -g_n
    path = 3 * taus[0] / K_T * np.sin(np.linspace(0, 3 * np.pi, 121))
    t_c, d_c, _ = _cycle(law, gap, state, path)
    for i, tau in enumerate(taus):
        single = IwanLaw(tau, K_T, CHI, BETA, n_sliders=law.n_sliders, alpha=law.alpha)
        t_i, d_i, _ = _cycle(single, gap[i:i + 1], single.initial_state(1), path)
        assert np.allclose(t_c[:, i], t_i[:, 0], rtol=1e-10, atol=1e-9 * tau)
        assert np.allclose(d_c[:, i], d_i[:, 0], rtol=1e-9, atol=1e-12 * tau * path.max())


def test_small_cycles_dissipate_the_power_law_of_the_pressure():
    # D = F_S^2 D_1(u_a / F_S) = 4 R_1 F_S^-(chi+1) u_a^(chi+3) / ((chi+2)(chi+3)) below phi_max: at one
    # amplitude the lightly pressed point dissipates (F_a / F_b)^-(chi+1) times more; the discrete element
    # carries the slider discretisation error (a few %, docs/joint.md), the ratio of two much less
    law = ClampedIwanLaw(K_N, K_T, CHI, 0.0, n_sliders=60, alpha=1.1)
    g_n = np.array([-1e-6, -1e-7])
    gap, state = _preload(g_n, law)
    taus = MU * K_N * -g_n
    u_a = 0.05 * law.unit_element.phi_max * taus[1]        # well inside micro-slip for both points
    path = u_a * np.sin(np.linspace(np.pi / 2, 2.5 * np.pi, 4001))   # from the top: one closed cycle after
    _, _, state = _cycle(law, gap, state, [u_a * np.sin(x) for x in np.linspace(0, np.pi / 2, 400)])
    _, dissipated, _ = _cycle(law, gap, state, path)
    cycle = dissipated.sum(axis=0)
    exact = np.array([law.cycle_dissipation(u_a, tau) for tau in taus])
    assert np.allclose(cycle, exact, rtol=0.05)
    ratio = cycle[1] / cycle[0]
    assert ratio == pytest.approx((taus[1] / taus[0]) ** -(CHI + 1), rel=0.01)
    assert ratio > 2.5    # sqrt(10) = 3.16: a wrong exponent (e.g. Jenkins' zero) fails here


def test_open_points_carry_nothing_and_the_stuck_stiffness_is_k_t():
    law = ClampedIwanLaw(K_N, K_T, CHI, BETA)
    gap, state = _preload(np.array([-1e-6, 2e-6]), law)
    pulled = gap + np.array([1e-12, 0.0, 3e-6])
    traction, D = law.evaluate(pulled, state)
    assert np.allclose(traction[1], 0.0) and np.allclose(D[1], 0.0)       # open at the preload: nothing
    assert traction[0, 2] == pytest.approx(K_N * 2e-6)                      # bilateral, frozen status
    assert D[0, 0, 0] == pytest.approx(K_T, rel=1e-12)                      # every slider stuck: K_T
    assert traction[0, 0] == pytest.approx(K_T * 1e-12, rel=1e-9)
    assert law.stored_energy(pulled, state)[1] == 0.0


def test_the_tangent_is_the_derivative_of_the_traction():
    # in micro-slip some sliders slip, some stick: the consistent tangent against central differences
    law = ClampedIwanLaw(K_N, K_T, CHI, BETA)
    gap, state = _preload(np.array([-1e-6, -3e-7]), law)
    loaded = gap + np.array([[0.4, 0.2, -0.1], [0.3, -0.5, 0.05]]) * MU * K_N * 3e-7 / K_T
    _, D = law.evaluate(loaded, state)
    h = 1e-7 * MU * K_N * 3e-7 / K_T     # small enough not to cross a slider's stick/slip kink
    for c in range(3):
        step = np.zeros(3)
        step[c] = h
        fd = (law.traction(loaded + step, state) - law.traction(loaded - step, state)) / (2 * h)
        assert np.allclose(D[:, :, c], fd, rtol=1e-5, atol=1e-6 * K_T)
    assert 0.1 * K_T < D[1, 0, 0] < K_T     # partly slipping: softer than stuck, not free


def test_the_law_is_registered_and_checks_its_parameters():
    law = interface_law("clamped_iwan", normal_stiffness=K_N, tangential_stiffness=K_T, chi=CHI, beta=BETA)
    assert isinstance(law, ClampedIwanLaw) and law.n_elements == 21
    with pytest.raises(ValueError, match="chi"):
        ClampedIwanLaw(K_N, K_T, -1.5, BETA)
    with pytest.raises(ValueError, match=r"gap must be \(s, 3\) and clamped \(s, 4\)"):
        clamped_iwan_state(law, np.zeros((3, 3)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match=r"clamped_iwan state must be \(2, 22, 2\)"):
        law.traction(np.zeros((2, 3)), np.zeros((2, 4)))


@pytest.mark.parametrize("compiled", [True, False])
def test_closing_lets_an_open_point_touch_again_without_friction(compiled):
    from femrom.fem import use_compiled_laws
    kappa = 1e-3
    law = ClampedIwanLaw(K_N, K_T, CHI, BETA, closing=kappa)
    plain = ClampedIwanLaw(K_N, K_T, CHI, BETA)
    # point 0 closed at the preload, 1 open by 2 um, 2 open by 1 um; motion closes 1 um of gap on
    # points 1 and 2 and slides them tangentially: point 2 touches (penetration 0), then 1 um more on 2
    gap, state = _preload(np.array([-1e-6, 2e-6, 1e-6]), law)
    moved = gap + np.array([[1e-9, 0, 0], [5e-7, 0, -1e-6], [5e-7, 0, -2e-6]])
    previous = use_compiled_laws(compiled)
    try:
        t, D = law.evaluate(moved, state)
        t0, D0 = plain.evaluate(moved, state)
    finally:
        use_compiled_laws(previous)
    # the closed point and the still-open point: the plain law's traction, bit for bit
    assert np.array_equal(t[:2], t0[:2]) and np.array_equal(D[:2], D0[:2])
    # the touching point: normal penalty kappa k_n on its penetration, no tangential traction (frictionless)
    assert t[2, 2] == pytest.approx(kappa * K_N * -1e-6, rel=1e-12)
    assert np.all(t[2, :2] == 0) and D[2, 2, 2] == pytest.approx(kappa * K_N) and np.all(D[2, :2, :2] == 0)
    assert law.stored_energy(moved, state)[2] == pytest.approx(0.5 * kappa * K_N * 1e-12, rel=1e-12)
    # the step derivative's normal row is the tangent's (the Jacobian harmonic balance builds)
    dgap = np.random.default_rng(0).standard_normal((3, 3, 4)) * 1e-9
    dstate = np.zeros(state.shape + (4,))
    dt, _ = law.step_derivative(moved, state, dgap, dstate)
    assert np.allclose(dt[:, 2], np.einsum("sc,scm->sm", D[:, 2], dgap), rtol=1e-12, atol=0)
    with pytest.raises(ValueError, match="closing"):
        ClampedIwanLaw(K_N, K_T, CHI, BETA, closing=-1.0)


def test_reclosed_friction_tangent_and_step_derivative_are_the_derivatives():
    # a reclosed point's slip limit follows its penetration (kappa mu_c k_n (-g_n) f_m): the tangent's
    # coupling column and the step derivative against central differences of the traction and of the
    # committed state, in micro-slip (some sliders slipping); with the coupling dropped the normal
    # column of dt_t would be zero and the check fails (it is 2e-2 of K_T kappa here)
    kappa, mu_c = 1e-2, 0.5
    law = ClampedIwanLaw(K_N, K_T, CHI, BETA, closing=kappa, closing_friction=mu_c)
    gap, state = _preload(np.array([-1e-6, 2e-7]), law)
    state = law.commit(gap, state)
    tau = kappa * mu_c * K_N * 3e-7                      # macro-slip traction at 3e-7 m of penetration
    moved = gap + np.array([[0.3, 0.1, -0.2], [0.0, 0.0, -5e-7 / (tau / (kappa * K_T))]]) * tau / (kappa * K_T)
    moved[1, :2] = np.array([0.35, -0.25]) * tau / (kappa * K_T)
    assert law._reclosed(moved, state)[1]
    _, D = law.evaluate(moved, state)
    h = 1e-7 * tau / (kappa * K_T)
    for c in range(3):
        step = np.zeros(3)
        step[c] = h
        fd = (law.traction(moved + step, state) - law.traction(moved - step, state)) / (2 * h)
        assert np.allclose(D[:, :, c], fd, rtol=1e-5, atol=1e-7 * K_T * kappa)
    assert abs(D[1, 0, 2]) > 1e-3 * kappa * K_T           # the coupling is there
    rng = np.random.default_rng(1)
    dgap = rng.standard_normal((2, 3, 2))
    dstate = np.zeros(state.shape + (2,))
    dt, dz = law.step_derivative(moved, state, dgap, dstate)
    for m in range(2):
        e = h * dgap[:, :, m]
        fd_t = (law.traction(moved + e, state) - law.traction(moved - e, state)) / (2 * h)
        fd_z = (law.commit(moved + e, state) - law.commit(moved - e, state)) / (2 * h)
        assert np.allclose(dt[:, :, m], fd_t, rtol=1e-5, atol=1e-7 * K_T * kappa)
        assert np.allclose(dz[..., m], fd_z, rtol=1e-5, atol=1e-6)


def test_a_closing_law_offers_no_compiled_step_kernel():
    # the fused compiled step knows the preload's contact status only: with reclosing points the numpy
    # step must run (a kernel here would drop the reclosed points' tractions)
    assert ClampedIwanLaw(K_N, K_T, CHI, BETA).kernel_arguments() is not None
    assert ClampedIwanLaw(K_N, K_T, CHI, BETA, closing=1e-3).kernel_arguments() is None
