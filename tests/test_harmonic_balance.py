"""Harmonic balance, its continuation and EPMC: a linear 2-dof against the exact FRF, the AFT
Jacobian against finite differences, a Duffing oscillator against the time-marched steady state,
a Jenkins oscillator's EPMC backbone against its first-harmonic closed form, QSMA and a
ring-down's Hilbert backbone, and bad input."""

import numpy as np
import pytest
import scipy.sparse as sp

from femrom.fem import JenkinsForce, LocalPotential
from femrom.integrators import (
    FourierBasis,
    HarmonicBalance,
    HarmonicBalanceError,
    Newton,
    Shaker,
    SteadyStateCriterion,
    SteppedSine,
    default_samples,
    epmc,
    force_response,
    frequency_response,
)
from femrom.post import epmc_backbone, hilbert_backbone, static_qsma
from femrom.rom import SecondOrderROM
from femrom.scene import SecondOrderSystem

W0 = 2.0 * np.pi     # 1 Hz


def sdof(zeta, nonlinear=None, stiffness=W0 ** 2):
    return SecondOrderSystem(
        mass=sp.csr_matrix([[1.0]]), stiffness=sp.csr_matrix([[stiffness]]),
        damping=None if zeta == 0 else sp.csr_matrix([[2.0 * zeta * W0]]), input_matrix=np.ones((1, 1)),
        output_matrix=sp.csr_matrix([[1.0]]), output_names=("x",), nonlinear=nonlinear)


def two_dof(nonlinear=None):
    M = sp.diags([1.0, 0.5]).tocsr()
    K = sp.csr_matrix(np.array([[3.0, -1.0], [-1.0, 1.0]]) * W0 ** 2)
    C = (0.02 * M + 0.001 * K).tocsr()
    return SecondOrderSystem(mass=M, stiffness=K, damping=C, input_matrix=np.array([[0.0], [1.0]]),
                             output_matrix=sp.identity(2, format="csr"), nonlinear=nonlinear)


# -- pieces --------------------------------------------------------------------------------
def test_fourier_basis_inverts_and_differentiates():
    basis = FourierBasis(4, 9)                       # the smallest N = 2H + 1
    assert np.allclose(basis.analysis @ basis.synthesis, np.eye(9), atol=1e-14)
    tau = 2 * np.pi * np.arange(9) / 9
    Z = np.zeros(9)
    Z[[3, 8]] = 1.0                                   # cos 2 tau + sin 4 tau
    assert np.allclose(basis.synthesis_derivative @ Z, -2 * np.sin(2 * tau) + 4 * np.cos(4 * tau), atol=1e-13)
    assert default_samples(1) == 8 and default_samples(7) == 32 and default_samples(8) == 64
    with pytest.raises(ValueError, match="samples"):
        FourierBasis(4, 8)
    with pytest.raises(ValueError, match="harmonics"):
        FourierBasis(-1)


def test_linear_two_dof_equals_the_exact_frf_to_round_off():
    """One Newton step (linear) at each frequency, and the continued curve, against
    ``(K - w^2 M + i w C)^-1 b`` (the force ``F sin(w t)``: phasor ``Y = b_1 + i a_1``)."""
    system = two_dof()
    hb = HarmonicBalance(system, 0, harmonics=3, samples=16)
    M, K, C = (A.toarray() for A in (system.mass, system.stiffness, system.damping))
    b = np.array([0.0, 1.0])

    def exact(w, F):
        return np.linalg.solve(K - w * w * M + 1j * w * C, F * b)

    for f in (0.3, 0.618, 1.2, 1.9):
        w = 2 * np.pi * f
        solution = hb.solve(w, 2.5)
        Y = hb.phasor(solution.coefficients)
        # measured 3.4e-16 relative
        assert np.max(np.abs(Y - exact(w, 2.5))) < 1e-13 * np.max(np.abs(exact(w, 2.5)))
        assert solution.iterations <= 1
        assert np.max(np.abs(solution.coefficients[3:])) < 1e-13 * np.max(np.abs(Y))   # no higher harmonics
    tight = Newton(rtol=1e-14)
    curve = frequency_response(hb, 2.5, 2 * np.pi * 0.3, 2 * np.pi * 2.2, ds=0.05, newton=tight)
    assert curve.frequency_hz[0] == pytest.approx(0.3) and curve.frequency_hz[-1] == pytest.approx(2.2)
    reference = np.array([exact(w, 2.5) for w in curve.omega])
    # each corrector stops at a residual of 1e-14 of the balanced forces, which the resonances
    # (0.5 % damping) amplify: measured 7.5e-13
    assert np.max(np.abs(curve.phasor - reference) / np.abs(reference).max(axis=1, keepdims=True)) < 1e-11
    # the step control resolves both resonances (1 and 2 Hz): points within 1 % of each peak
    f = curve.frequency_hz
    assert np.sum(np.abs(f - 1.0) < 0.01) >= 5 and np.sum(np.abs(f - 2.0) < 0.02) >= 5
    force = force_response(hb, 2 * np.pi * 0.618, 0.5, 4.0)
    assert force.force[-1] == pytest.approx(4.0)
    assert np.allclose(force.phasor / force.force[:, None], exact(2 * np.pi * 0.618, 1.0), rtol=1e-11)


def finite_difference_jacobian(hb, z, omega, force, h):
    J = np.empty((z.size, z.size))
    for i in range(z.size):
        e = np.zeros_like(z)
        e[i] = h
        J[:, i] = (hb.residual(z + e, omega, force, jacobian=False)["residual"]
                   - hb.residual(z - e, omega, force, jacobian=False)["residual"]) / (2 * h)
    return J


class JenkinsWithoutDerivative(JenkinsForce):
    """The same law without the forward derivative of its step: the AFT falls back to the
    per-sample tangent with the state frozen."""
    local_step_derivative = None


def test_aft_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    # a cubic spring between the two masses and a van der Pol-like velocity term are not at hand;
    # a cubic grounded spring on each dof (stateless) and a Jenkins element between them (memory)
    cubic = two_dof(LocalPotential.cubic(np.ones(2), 40.0))
    hb = HarmonicBalance(cubic, 0, harmonics=4, samples=32)
    z = 0.3 * rng.standard_normal(hb.n_unknowns)
    J = hb.residual(z, 5.0, 1.0)["jacobian"]
    J_fd = finite_difference_jacobian(hb, z, 5.0, 1.0, 1e-6)
    # measured 3.6e-11 relative (central differences, h = 1e-6 on O(1) coefficients)
    assert np.max(np.abs(J - J_fd)) < 1e-8 * np.max(np.abs(J))

    relative = sp.csr_matrix(np.array([[-1.0, 1.0]]))
    slider = JenkinsForce(0.5 * W0 ** 2, 0.05 * W0 ** 2, 2, local_map=relative)
    hb = HarmonicBalance(two_dof(slider), 0, harmonics=4, samples=64)
    z = hb.solve(2 * np.pi * 0.8, 30.0).coefficients.reshape(-1)
    r = hb.residual(z, 2 * np.pi * 0.8, 30.0)
    assert r["aft"].state_change == 0.0                   # the loop closes after the first march
    J_fd = finite_difference_jacobian(hb, z, 2 * np.pi * 0.8, 30.0, 1e-7)
    slipping = np.ptp(hb.basis.synthesis @ (z.reshape(9, 2) @ np.array([-1.0, 1.0]))) / 2
    assert slipping > 3 * 0.1           # the relative motion's amplitude is 3 slip distances and more
    # exact derivative of the sampled loop (the stick/slip pattern does not change within h):
    # measured 2.0e-10 relative (the differences' round-off at h = 1e-7)
    assert np.max(np.abs(r["jacobian"] - J_fd)) < 1e-8 * np.max(np.abs(J_fd))

    frozen = JenkinsWithoutDerivative(0.5 * W0 ** 2, 0.05 * W0 ** 2, 2, local_map=relative)
    hb_frozen = HarmonicBalance(two_dof(frozen), 0, harmonics=4, samples=64)
    J_frozen = hb_frozen.residual(z, 2 * np.pi * 0.8, 30.0)["jacobian"]
    # the frozen-state tangent misses the slider's dependence on earlier samples: measured
    # 2.0e-2 of the largest entry here; Newton still converges to the same solution (1.2e-10
    # apart), in 10 iterations instead of 2
    gap = np.max(np.abs(J_frozen - J_fd)) / np.max(np.abs(J_fd))
    assert 1e-4 < gap < 0.1
    exact_solve = hb.solve(2 * np.pi * 0.8, 30.0)
    frozen_solve = hb_frozen.solve(2 * np.pi * 0.8, 30.0)
    assert np.allclose(frozen_solve.coefficients, exact_solve.coefficients, rtol=0, atol=1e-9)
    assert frozen_solve.iterations > exact_solve.iterations


# -- Duffing: harmonic balance against the time-marched steady state -----------------------
ZETA_DUFFING, CUBIC = 0.05, 10.5
FORCE_DUFFING = 2.0 * (2 * ZETA_DUFFING * W0 ** 2)      # twice the force of a unit linear peak


def test_duffing_harmonic_balance_matches_the_time_marched_steady_state():
    """Frequencies on the way up through the jump band (1.161-1.237 Hz): the sweep and the
    harmonic balance, continued from point to point, stay on the upper branch."""
    system = sdof(ZETA_DUFFING, LocalPotential.cubic(np.ones(1), CUBIC))
    frequencies = np.array([0.9, 1.05, 1.2])
    # time march: N = 128 steps per period, prewarped (the fundamental at the requested
    # frequency; the 3rd harmonic, 1.5 % of the response, warped by 1.8e-4), steady state to 1e-6
    sweep = SteppedSine(frequencies, steps_per_period=128, steady_state=SteadyStateCriterion(1e-6, max_periods=2000))
    marched = sweep.run(Shaker(SecondOrderROM.galerkin(system, np.eye(1)), 0, quantity="displacement"),
                        FORCE_DUFFING).levels[0]
    assert marched.converged.all()
    hb = HarmonicBalance(system, 0, harmonics=7)
    z, amplitudes = None, []
    for f in frequencies:
        solution = hb.solve(2 * np.pi * f, FORCE_DUFFING, initial=z)
        z = solution.coefficients.reshape(-1)
        amplitudes.append(abs(hb.phasor(solution.coefficients)[0]))
    error = np.abs(np.array(amplitudes) / marched.amplitude[0] - 1)
    # the bound 1e-3; measured 3.8e-6, 1.4e-5, 2.3e-5: the time march's error, which
    # falls as N^-2 (1.5e-5 / 5.4e-5 / 9.3e-5 at N = 64, 1.0e-6 / 3.5e-6 / 5.5e-6 at N = 256);
    # H = 7 leaves harmonics of 4e-6 of the fundamental out
    assert error.max() < 1e-3
    assert amplitudes[2] > 1.4      # the upper branch at 1.2 Hz (the lower one is 0.4)


def test_duffing_frequency_response_turns_at_the_saddle_nodes():
    system = sdof(ZETA_DUFFING, LocalPotential.cubic(np.ones(1), CUBIC))
    curve = frequency_response(HarmonicBalance(system, 0, harmonics=5), FORCE_DUFFING, 2 * np.pi * 0.8,
                               2 * np.pi * 1.5)
    f = curve.frequency_hz
    turns = f[1:-1][np.diff(np.sign(np.diff(f))) != 0]
    # first-order harmonic balance puts the saddle nodes at 1.237 and 1.161 Hz (tests of the
    # stepped sine); the higher harmonics move them by less than the step between points
    assert turns.size == 2
    # measured 1.2380 and 1.1617 Hz at H = 5, 3 iterations at most per point
    assert turns[0] == pytest.approx(1.237, abs=3e-3) and turns[1] == pytest.approx(1.161, abs=3e-3)
    assert curve.iterations.max() <= 10


# -- Jenkins: EPMC against closed forms, QSMA and a ring-down ------------------------------
EPS = 0.1                  # k_t / k
SLIP = 1.0                 # x_s = F_s / k_t


def jenkins_first_harmonic(amplitude, eps=EPS):
    r"""``k_eq(a)`` and the dissipation ``W(a)`` of ``k_t`` in series with a slider ``F_s`` under
    ``x = a cos(theta)`` (docs/backbone.md): the closed form of one-harmonic balance."""
    a = np.asarray(amplitude, dtype=float)
    kt = eps * W0 ** 2
    switch = np.arccos(np.clip(1 - 2 * SLIP / a, -1, 1))
    k_eq = np.where(a > SLIP, kt / np.pi * (switch - 0.5 * np.sin(2 * switch)), kt)
    W = np.where(a > SLIP, 4 * kt * SLIP * (a - SLIP), 0.0)
    return k_eq, W


def jenkins_system(zeta):
    return sdof(zeta, JenkinsForce(EPS * W0 ** 2, EPS * W0 ** 2 * SLIP, 1))


AMPLITUDES = np.geomspace(0.5, 8.0, 13)


def test_epmc_linear_mode_is_exact():
    modes = epmc(two_dof(), [1e-3, 1.0, 1e3], mode=1, harmonics=3)
    M, K, C = (A.toarray() for A in (two_dof().mass, two_dof().stiffness, two_dof().damping))
    w2, phi = np.linalg.eigh(np.linalg.solve(np.diag(np.sqrt(np.diag(M))), np.linalg.solve(
        np.diag(np.sqrt(np.diag(M))), K).T))
    omega = np.sqrt(w2[1])
    phi = np.linalg.solve(np.diag(np.sqrt(np.diag(M))), phi[:, 1])
    # Rayleigh damping is modal: D = phi^T C phi / (2 omega), Omega = omega_n
    assert np.allclose(modes.omega, omega, rtol=1e-12)
    assert np.allclose(modes.damping_ratio, phi @ C @ phi / (2 * omega), rtol=1e-10)


def test_epmc_one_harmonic_is_the_describing_function():
    """With H = 1 EPMC solves one-harmonic balance: ``Omega^2 = (k + k_eq)/m`` and
    ``xi pi Omega a^2 = W + c pi Omega a^2``. The only error is the AFT's sampling of the
    stick-slip switch: measured 1.0e-5 (frequency) and 3.2e-4 (damping) relative at N = 256."""
    modes = epmc(jenkins_system(0.002), AMPLITUDES, harmonics=1, samples=256)
    k_eq, W = jenkins_first_harmonic(AMPLITUDES)
    omega = np.sqrt(W0 ** 2 + k_eq)
    xi = 2 * 0.002 * W0 + W / (np.pi * omega * AMPLITUDES ** 2)
    assert np.max(np.abs(modes.omega / omega - 1)) < 1e-4
    assert np.max(np.abs(modes.xi / xi - 1)) < 2e-3
    assert np.allclose(modes.modal_amplitude, AMPLITUDES)
    assert np.allclose(modes.output_amplitude[:, 0], AMPLITUDES, rtol=1e-12)


@pytest.fixture(scope="module")
def jenkins_modes():
    return epmc(jenkins_system(0.0), AMPLITUDES, harmonics=7, samples=256)


def test_epmc_matches_qsma_on_a_masing_law(jenkins_modes):
    """QSMA (static loading, Masing's rules) and EPMC (periodic motion) of an undamped Jenkins
    oscillator. They agree where the element sticks (both linear, k + k_t) and differ by
    construction beyond slip: QSMA's frequency is the secant ``alpha(a) / a`` of the loading
    curve, EPMC's the first-harmonic stiffness k_eq (plus higher-harmonic effects), and QSMA's
    damping ``D / (2 pi omega^2 a^2)`` takes the secant frequency. The bound is that model
    difference: ``|f_q / f_e - 1| <= (1/2) max |k_sec - k_eq| / (k + k_eq)``, 1.6e-3 here, and
    twice that for the damping (the frequency squared) plus the third harmonic's share."""
    modes = jenkins_modes
    system = jenkins_system(0.0)
    element = system.nonlinear
    # modal forces alpha up to past a = 8.2 x_s (alpha = k a + F_s there), the loading curve
    # sampled finely: its trapezoid is exact on the linear pieces, O(h^2) at the kink
    alphas = np.linspace(0.01, 1.0, 500) * (W0 ** 2 * 8.2 + EPS * W0 ** 2 * SLIP)
    qsma = static_qsma(system, alphas, reference=np.zeros(1), state=element.initial_state(),
                       mode=np.ones(1)).backbone(0, quantity="displacement")
    frequency, damping = qsma.at_amplitude(AMPLITUDES)
    k_eq, _ = jenkins_first_harmonic(AMPLITUDES)
    k_secant = EPS * W0 ** 2 * np.minimum(1.0, SLIP / AMPLITUDES)
    # the model difference in closed form: QSMA's secant against the first-harmonic stiffness
    expected_frequency = np.sqrt((W0 ** 2 + k_secant) / (W0 ** 2 + k_eq)) - 1
    expected_damping = (W0 ** 2 + k_eq) / (W0 ** 2 + k_secant) - 1
    stuck = AMPLITUDES < SLIP
    # stuck: the same linear oscillator (measured 2e-16; QSMA's trapezoid is exact on a line)
    assert np.allclose(modes.frequency_hz[stuck], frequency[stuck], rtol=1e-9)
    assert np.all(modes.damping_ratio[stuck] < 1e-12) and np.all(damping[stuck] < 1e-12)
    slip = AMPLITUDES > 1.01 * SLIP
    # slipping: up to 0.28 % apart in frequency and 0.66 % in damping, and that difference is
    # the closed form's within 3.1e-5 (frequency: the higher harmonics' share at H = 7) and
    # 3.6e-3 (damping, largest just past the slip onset, where the loop is least harmonic)
    assert np.max(np.abs(frequency[slip] / modes.frequency_hz[slip] - 1)) < 3e-3
    assert np.max(np.abs(frequency[slip] / modes.frequency_hz[slip] - 1 - expected_frequency[slip])) < 5e-5
    assert np.max(np.abs(damping[slip] / modes.damping_ratio[slip] - 1 - expected_damping[slip])) < 5e-3
    # with one harmonic only the AFT's sampling and QSMA's loading-curve sampling remain:
    # measured 1.1e-6 (frequency) and 3.5e-4 (damping, N = 256 samples across the slip onset)
    single = epmc(system, AMPLITUDES[slip], harmonics=1, samples=256)
    assert np.max(np.abs(frequency[slip] / single.frequency_hz - 1 - expected_frequency[slip])) < 5e-6
    assert np.max(np.abs(damping[slip] / single.damping_ratio - 1 - expected_damping[slip])) < 1e-3


def test_epmc_matches_a_ring_down_hilbert_backbone():
    """A free decay of the lightly damped Jenkins oscillator from 8 x_s (central differences at
    T/600 with the element's return map, tests/test_backbone.py's decay slowed to 1 Hz) through the Hilbert
    estimator, against EPMC with the same viscous damping. Both describe the same slow flow;
    the ring-down's amplitude changes within a cycle, which a periodic motion ignores: an
    O(eps^2) difference, the bounds of the Hilbert estimator against equivalent linearisation
    in tests/test_backbone.py (0.03 eps^2 frequency, 0.15 eps^2 damping)."""
    zeta, rate, substeps = 0.002, 100.0, 6         # 100 samples per cycle of the 1 Hz mode
    element = JenkinsForce(EPS * W0 ** 2, EPS * W0 ** 2 * SLIP, 1)
    h = 1 / (rate * substeps)
    c = 2 * zeta * W0
    lead, lag = 1 / h ** 2 + c / (2 * h), 1 / h ** 2 - c / (2 * h)
    samples = np.empty(int(80 * rate))
    slider = element.initial_state()
    x = np.array([8.0 * SLIP])
    force = element.local_force(x, None, slider)
    slider = element.local_commit(x, None, slider)
    x_previous = x - 0.5 * h ** 2 * (W0 ** 2 * x + force)
    samples[0] = x[0]
    for step in range(1, samples.size * substeps):
        x, x_previous = ((2 / h ** 2 - W0 ** 2) * x - lag * x_previous - force) / lead, x
        force = element.local_force(x, None, slider)
        slider = element.local_commit(x, None, slider)
        if step % substeps == 0:
            samples[step // substeps] = x[0]
    hilbert = hilbert_backbone(samples, rate, (0.4, 2.0), window=2.0)
    keep = hilbert.amplitude > 1.5 * SLIP            # slipping, past the kink a window straddles
    assert keep.sum() >= 5 and np.all(np.diff(hilbert.amplitude[keep]) < 0)
    amplitude = hilbert.amplitude[keep][::-1]             # increasing
    modes = epmc(jenkins_system(zeta), amplitude, harmonics=7, samples=256)
    backbone = epmc_backbone(modes, quantity="displacement")
    # EPMC's Omega is undamped; the ring-down's frequency the damped one (a 1.5e-4 shift here)
    damped = backbone.frequency_hz * np.sqrt(1 - backbone.damping_ratio ** 2)
    # measured 0.022 eps^2 (frequency, relative) and 0.118 eps^2 (damping, absolute: 7 % of it)
    assert np.max(np.abs(hilbert.frequency_hz[keep][::-1] / damped - 1)) < 0.03 * EPS ** 2
    assert np.max(np.abs(hilbert.damping_ratio[keep][::-1] - backbone.damping_ratio)) < 0.15 * EPS ** 2


def test_epmc_backbone_reads_outputs_and_acceleration(jenkins_modes):
    modal = epmc_backbone(jenkins_modes)
    acc = epmc_backbone(jenkins_modes, quantity="acceleration")
    assert np.allclose(acc.amplitude, jenkins_modes.omega ** 2 * modal.amplitude)
    slip = jenkins_modes.modal_amplitude > SLIP
    assert modal.method == "epmc" and np.all(np.diff(jenkins_modes.frequency_hz[slip]) < 0)   # softening
    with pytest.raises(ValueError, match="quantity"):
        epmc_backbone(jenkins_modes, quantity="velocity")


# -- bad input -----------------------------------------------------------------------------
def test_bad_input_is_refused():
    system = sdof(0.02)
    with pytest.raises(ValueError, match="input"):
        HarmonicBalance(system, 3)
    with pytest.raises(ValueError, match="force"):
        HarmonicBalance(system, np.ones(2))
    with pytest.raises(ValueError, match="passes"):
        HarmonicBalance(system, 0, passes=0)
    with pytest.raises(ValueError, match="monotonic"):
        epmc(system, [1.0, 0.5, 2.0])
    with pytest.raises(ValueError, match="positive"):
        epmc(system, [0.0, 1.0])
    with pytest.raises(ValueError, match="frequencies"):
        frequency_response(HarmonicBalance(system, 0), 1.0, 2.0, 2.0)
    duffing = sdof(0.0, LocalPotential.cubic(np.ones(1), 1e4))
    with pytest.raises(HarmonicBalanceError, match="Newton"):
        HarmonicBalance(duffing, 0, harmonics=3).solve(2 * np.pi * 3.0, 1e3, newton=Newton(max_iterations=2))


# -- sweeps: chord steps, the stepped sine's rows, periodic states ---------------------------
def test_chord_steps_reach_the_same_solution_for_fewer_jacobians():
    # a Jenkins oscillator swept through its softened resonance (slipping over most of the period):
    # with the Jacobian of the previous point reused, every point meets the same Newton tolerance,
    # so the two sweeps agree to a few times that tolerance (1e-10 of the balanced forces)
    system = jenkins_system(0.03)
    frequencies = 2 * np.pi * np.linspace(0.75, 1.05, 13)
    hb = HarmonicBalance(system, 0, harmonics=3, samples=64)
    counted = {"jacobian": 0}
    residual = hb.residual

    def counting(z, omega, force=0.0, *, xi=0.0, jacobian=True):
        counted["jacobian"] += bool(jacobian)
        return residual(z, omega, force, xi=xi, jacobian=jacobian)

    hb.residual = counting
    runs = {}
    for chord in (None, {}):
        counted["jacobian"], z, amplitudes = 0, None, []
        for omega in frequencies:
            solution = hb.solve(omega, 8.0, initial=z, chord=chord)
            z = solution.coefficients.reshape(-1)
            amplitudes.append(abs(hb.phasor(solution.coefficients)[0]))
        runs["chord" if chord is not None else "newton"] = (np.array(amplitudes), counted["jacobian"])
    (newton, j_newton), (chord, j_chord) = runs["newton"], runs["chord"]
    assert np.max(np.abs(chord / newton - 1)) < 1e-8, np.max(np.abs(chord / newton - 1))
    assert j_chord < 0.7 * j_newton, (j_chord, j_newton)      # measured 13 against 33 exact Jacobians


def test_sweep_rows_are_the_stepped_sines_and_a_linear_models_frf():
    # a linear 2-dof: every point is the exact FRF (one iteration), its acceleration's amplitude and
    # phase as the time-marched stepped sine reports them (the same model marched to steady state)
    from femrom.study import harmonic_balance_sweep
    system = two_dof()
    frequencies = np.array([0.35, 0.62, 1.1])
    swept = harmonic_balance_sweep(system, None, 0, frequencies, (0.5,), harmonics=1)
    (level,) = swept["rows"]
    assert level["force_n"] == 0.5 and level["quantity"] == "acceleration"
    M, K, C = (m.toarray() for m in (system.mass, system.stiffness, system.damping))
    for j, f in enumerate(frequencies):
        w = 2 * np.pi * f
        x = np.linalg.solve(K - w**2 * M + 1j * w * C, 0.5 * np.array([0.0, 1.0]))
        for i, name in enumerate(("y0", "y1")):
            point = level["outputs"][name][j]
            # y = Im(X e^{i w t}) = |X| sin(w t + arg X); the acceleration -w^2 y: the phase turned by pi
            # each point from the previous one, to Newton's 1e-10 of the balanced forces (times the
            # resonance's amplification): measured 1.2e-10
            assert point["amplitude_m_s2"] == pytest.approx(w**2 * abs(x[i]), rel=1e-8)
            assert np.angle(np.exp(1j * (point["phase_rad"] - np.angle(-x[i])))) == pytest.approx(0, abs=1e-8)
            assert point["linear_amplitude_m_s2"] == pytest.approx(point["amplitude_m_s2"], rel=1e-9)
    marched = SteppedSine(frequencies[:2], steps_per_period=256,
                          steady_state=SteadyStateCriterion(1e-7, max_periods=4000)).run(
        Shaker(SecondOrderROM.galerkin(system, np.eye(2)), 0), [0.5]).rows()[0]
    for j in range(2):
        for name in ("y0", "y1"):
            a, b = marched["outputs"][name][j], level["outputs"][name][j]
            # the march's phase error at 256 steps a period: (w dt)^2 / 12 ~ 5e-5 rad
            assert np.angle(np.exp(1j * (a["phase_rad"] - b["phase_rad"]))) == pytest.approx(0, abs=1e-3)
            assert a["amplitude_m_s2"] == pytest.approx(b["amplitude_m_s2"], rel=1e-3)


def test_periodic_states_are_the_afts_march():
    # the states periodic_states returns are the ones the AFT's force was evaluated with: re-evaluating
    # the force at each (q_j, state_j) and transforming gives the AFT's coefficients to round-off
    system = jenkins_system(0.03)
    hb = HarmonicBalance(system, 0, harmonics=3, samples=32)
    solution = hb.solve(2 * np.pi * 1.0, 8.0)
    q, v, states = hb.periodic_states(solution.coefficients, 2 * np.pi * 1.0)
    assert q.shape == (32, 1) and len(states) == 32
    forces = np.array([system.nonlinear.force(q[j], v[j], states[j]) for j in range(32)]).reshape(32, 1)
    aft = hb.aft(solution.coefficients.reshape(-1), 2 * np.pi * 1.0, jacobian=False)
    assert np.allclose(hb.basis.analysis @ forces, aft.coefficients, rtol=0, atol=1e-12 * np.abs(forces).max())
    assert np.ptp([s for s in np.ravel(states)]) > 0          # the slider moves over the period


def test_sweeps_refuse_a_bad_grid():
    from femrom.study import harmonic_balance_sweep, periodic_training
    system = two_dof()
    for frequencies, levels, culprit in (([np.nan], [1.0], "frequencies"), ([-1.0], [1.0], "frequencies"),
                                         ([], [1.0], "frequencies"), ([0.3], [np.inf], "levels"),
                                         ([0.3], [], "levels"), ([0.3], [-1.0], "levels")):
        with pytest.raises(ValueError, match=culprit):
            harmonic_balance_sweep(system, None, 0, frequencies, levels)
    with pytest.raises(ValueError, match="frequencies"):
        periodic_training(system, None, 0, 0.0, [1.0])
