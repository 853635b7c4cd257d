"""Time integrators: observed orders, energy behaviour, stability, the linear path,
nonlinear Newton, failure handling, consumers and restart."""

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from femrom.fem import LocalPotential, NonlinearForce
from femrom.integrators import (
    CentralDifference,
    EnergyRecorder,
    GeneralizedAlpha,
    ImplicitMidpoint,
    IntegrationError,
    Newmark,
    Newton,
    OutputRecorder,
    StepResult,
    Trajectory,
    bound_max_frequency,
    estimate_max_frequency,
    integrate,
    iterate,
)
from femrom.integrators.schemes import implicit_midpoint, newmark
from femrom.scene import SecondOrderSystem
from femrom.solvers import make_solver

FORCING_FREQUENCY = 1.3


# -- test systems ------------------------------------------------------------
def chain_matrices(n: int, seed: int = 1):
    """Spring-mass chain fixed at both ends: lumped masses in [1, 1.5], springs in [1, 2]."""
    rng = np.random.default_rng(seed)
    m = 1.0 + 0.5 * rng.random(n)
    k = 1.0 + rng.random(n + 1)
    K = sp.diags([k[:-1] + k[1:], -k[1:-1], -k[1:-1]], [0, 1, -1], format="csr")
    M = sp.diags(m, format="csr")
    return M, K


def chain(n: int = 8, *, rayleigh=(0.05, 0.01), forced: bool = True, outputs: bool = False):
    """Chain with damping ``C = a M + b K`` (``None``: undamped), ``u = sin(1.3 t)`` on dof 0."""
    M, K = chain_matrices(n)
    C = None if rayleigh is None else (rayleigh[0] * M + rayleigh[1] * K).tocsr()
    kwargs = {}
    if forced:
        B = np.zeros((n, 1))
        B[0, 0] = 1.0
        kwargs.update(input_matrix=B, inputs=lambda t: np.array([np.sin(FORCING_FREQUENCY * t)]))
    if outputs:
        kwargs.update(output_matrix=sp.csr_matrix(np.eye(n)[[0, n - 1]]),
                      output_names=("first", "last"))
    return SecondOrderSystem(mass=M, stiffness=K, damping=C, **kwargs)


def exact_displacements(system, q0, v0, times) -> np.ndarray:
    """(n, k) exact q(t) of the linear chain under ``u = sin(W t)``.

    First-order form x' = A x + b sin(W t), x = (q, v): the periodic particular
    solution is Im[(iW - A)^{-1} b e^{iWt}], the rest is expm(A t) applied to the
    initial mismatch. expm and the dense solves are accurate to ~1e-14, far below
    the 1e-6..1e-3 errors measured below.
    """
    n = system.n_dofs
    M, K = system.mass.toarray(), system.stiffness.toarray()
    C = np.zeros((n, n)) if system.damping is None else system.damping.toarray()
    Minv = np.linalg.inv(M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ C]])
    b = np.zeros(2 * n)
    if system.input_matrix is not None:
        b[n:] = Minv @ np.asarray(system.input_matrix).ravel()
    z = np.linalg.solve(1j * FORCING_FREQUENCY * np.eye(2 * n) - A, b)

    def particular(t):
        return np.imag(z * np.exp(1j * FORCING_FREQUENCY * t))

    x0 = np.concatenate([q0, v0]) - particular(0.0)
    return np.column_stack([(sla.expm(A * t) @ x0 + particular(t))[:n] for t in times])


def sine_gordon_chain(n: int = 40, length: float = 10.0):
    """P1/finite-difference sine-Gordon string q_tt = q_xx - sin q, fixed ends."""
    h = length / (n + 1)
    x = h * np.arange(1, n + 1)
    M = sp.diags(np.full(n, h), format="csr")
    K = (sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1]) / h).tocsr()
    system = SecondOrderSystem(mass=M, stiffness=K,
                               nonlinear=LocalPotential.sine_gordon(np.full(n, h)))
    return system, 3.0 * np.exp(-(x - 0.5 * length) ** 2), np.zeros(n)  # amplitude 3 rad


def initial_state(n: int, seed: int = 0, scale: float = 0.1):
    rng = np.random.default_rng(seed)
    return scale * rng.standard_normal(n), scale * rng.standard_normal(n)


def fitted_order(dts, errors) -> float:
    return float(np.polyfit(np.log(dts), np.log(errors), 1)[0])


# -- observed order against the exact MDOF solution -----------------------------
ORDER_CASES = {
    "newmark-average-acceleration": (Newmark(), (0.05, 0.01)),
    "generalized-alpha-0.8": (GeneralizedAlpha(0.8), (0.05, 0.01)),
    "generalized-alpha-0.5": (GeneralizedAlpha(0.5), (0.05, 0.01)),
    "implicit-midpoint": (ImplicitMidpoint(), (0.05, 0.01)),
    "central-difference-undamped": (CentralDifference(), None),
    # mass-proportional damping is diagonal: handled implicitly in v, still 2nd order
    "central-difference-diagonal-damping": (CentralDifference(), (0.05, 0.0)),
}


@pytest.mark.parametrize("case", list(ORDER_CASES))
def test_observed_order_against_exact_solution(case):
    scheme, rayleigh = ORDER_CASES[case]
    system = chain(rayleigh=rayleigh)
    q0, v0 = initial_state(system.n_dofs)
    T, dts, errors = 4.0, [], []
    for n_steps in (50, 100, 200, 400):  # omega_max dt <= 0.16: asymptotic regime
        trajectory = Trajectory(every=n_steps // 10, fields=("q",))
        integrate(system, scheme, q0, v0, T / n_steps, n_steps, consumers=[trajectory])
        exact = exact_displacements(system, q0, v0, trajectory.t)
        errors.append(np.max(np.abs(trajectory.q - exact)))
        dts.append(T / n_steps)
    # rate fitted over 3 halvings (scikit-fem convention: within 0.1 of theory)
    assert abs(fitted_order(dts, errors) - scheme.order) < 0.1
    assert errors[-1] < 1e-4  # absolute ceiling: measured 2e-5..5e-5 at dt = 0.01


def test_central_difference_with_lagged_damping_is_first_order():
    # Rayleigh damping with a K part is not diagonal: C v is lagged half a step,
    # an O(dt) force error, as documented in CentralDifference.
    system = chain(rayleigh=(0.05, 0.05))
    q0, v0 = initial_state(system.n_dofs)
    T, dts, errors = 4.0, [], []
    for n_steps in (50, 100, 200, 400):
        trajectory = Trajectory(every=n_steps // 10, fields=("q",))
        integrate(system, CentralDifference(), q0, v0, T / n_steps, n_steps,
                  consumers=[trajectory])
        errors.append(np.max(np.abs(trajectory.q - exact_displacements(system, q0, v0,
                                                                       trajectory.t))))
        dts.append(T / n_steps)
    assert abs(fitted_order(dts, errors) - 1.0) < 0.1  # measured 1.06


def test_newmark_names_and_parameters():
    assert Newmark(beta=0.25, gamma=0.5) == Newmark()
    assert Newmark().label == "NewmarkAverageAcceleration" and Newmark().order == 2
    assert Newmark().name == "newmark" and GeneralizedAlpha(0.5).name == "generalized_alpha"
    assert Newmark(gamma=0.6, beta=0.3).order == 1  # gamma != 1/2 is first order
    ga = GeneralizedAlpha(0.5)
    # Chung & Hulbert (1993), eq. 25: rho = 1/2 gives alpha_m = 0, alpha_f = 1/3
    assert ga.alpha_m == pytest.approx(0.0) and ga.alpha_f == pytest.approx(1.0 / 3.0)
    assert ga.gamma == pytest.approx(0.5 + 1.0 / 3.0)
    assert ga.beta == pytest.approx(0.25 * (1.0 + 1.0 / 3.0) ** 2)
    ga1 = GeneralizedAlpha(1.0)
    assert (ga1.beta, ga1.gamma) == (0.25, 0.5)  # rho_inf = 1 is average acceleration
    with pytest.raises(ValueError, match="spectral_radius"):
        GeneralizedAlpha(1.5)


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.8])
def test_generalized_alpha_high_frequency_spectral_radius(rho):
    # A single oscillator with omega dt = 1e4 sits in the high-frequency limit,
    # where the amplification matrix has spectral radius rho_inf (a double
    # eigenvalue -rho_inf, hence the n rho^n growth factor the fit absorbs).
    omega, dt = 1.0, 1e4
    system = SecondOrderSystem(mass=sp.identity(1, format="csr"),
                               stiffness=sp.csr_matrix([[omega**2]]))
    trajectory = Trajectory(fields=("q", "v", "a"))
    integrate(system, GeneralizedAlpha(rho), np.array([1.0]), np.array([0.0]), dt, 60,
              consumers=[trajectory])
    size = np.abs(trajectory.a[0]) + np.abs(trajectory.v[0]) / dt + np.abs(trajectory.q[0]) / dt**2
    if rho == 0.0:
        assert size[-1] < 1e-12 * size[1]  # annihilated after a few steps
        return
    rate = np.exp(np.polyfit(np.arange(30, 61), np.log(size[30:]), 1)[0])
    assert rate == pytest.approx(rho, abs=0.03 * rho)  # the n-factor biases by ~1/30


# -- energy -----------------------------------------------------------------------
LONG_RUN_STEPS = 100_000


def undamped_chain_20():
    M, K = chain_matrices(20)
    system = SecondOrderSystem(mass=M, stiffness=K)
    q0, v0 = initial_state(20, scale=1.0)
    omega_max = estimate_max_frequency(K, M)
    return system, q0, v0, omega_max


@pytest.mark.parametrize("scheme", [Newmark(), ImplicitMidpoint(accelerations=False)],
                         ids=["newmark", "midpoint"])
def test_linear_energy_is_conserved_over_a_long_run(scheme):
    system, q0, v0, omega_max = undamped_chain_20()
    dt = 1.0 / omega_max  # omega_max dt = 1: large phase errors, energy still exact
    energy = EnergyRecorder(system, every=10)
    integrate(system, scheme, q0, v0, dt, LONG_RUN_STEPS, consumers=[energy])
    E = energy.total
    # Both schemes conserve v'Mv/2 + q'Kq/2 exactly in exact arithmetic; each step
    # adds O(eps) relative roundoff, so even a systematic bias stays below
    # 1e5 steps * 1.1e-16 = 1e-11. Measured: 1.2e-12 (Newmark), 1.8e-12 (midpoint).
    assert np.max(np.abs(E - E[0])) / E[0] < 1e-10


def test_central_difference_energy_oscillates_without_drift():
    system, q0, v0, omega_max = undamped_chain_20()
    h = 1.0 / omega_max
    energy = EnergyRecorder(system)
    integrate(system, CentralDifference(), q0, v0, h, LONG_RUN_STEPS, consumers=[energy])
    E = energy.total
    # Stoermer-Verlet conserves E_h = v'Mv/2 + q'Kq/2 - (h^2/8)|M^{-1}Kq|_M^2 exactly
    # per mode (omega^2 q^2 weighted by 1 - (h omega)^2/4), so E oscillates in
    # [E_h, E_h / c], c = 1 - (h omega_max)^2 / 4: a relative band (h w)^2 / (4 - (h w)^2).
    x = (h * omega_max) ** 2
    band = (E.max() - E.min()) / E.min()
    assert 0.01 * x < band <= x / (4.0 - x)  # measured 0.149 for a bound of 0.333
    # No drift: the E - E_h term of mode j has amplitude <= (h w_j)^2 E_j / (8 c) and
    # frequency 2 w_j, so the means over two windows of length W differ by at most
    # h^2 w_max E / (4 c W).  Measured 5.1e-6 against 3.3e-5.
    window = LONG_RUN_STEPS // 10
    drift = abs(E[-window:].mean() - E[:window].mean()) / E[0]
    assert drift <= x / (4.0 * (1.0 - x / 4.0) * omega_max * window * h)


@pytest.mark.parametrize("scheme", [Newmark(), ImplicitMidpoint()], ids=["newmark", "midpoint"])
def test_damped_energy_decreases_by_the_discrete_dissipation(scheme):
    system = chain(n=20, rayleigh=(0.02, 0.02), forced=False)
    q0, v0 = initial_state(20, scale=1.0)
    trajectory, energy = Trajectory(fields=("q", "v")), EnergyRecorder(system)
    dt = 1.0
    integrate(system, scheme, q0, v0, dt, 400, consumers=[trajectory, energy])
    E = energy.total
    # exact discrete identity of both (linear) schemes:
    # E_{n+1} - E_n = -dt vbar' C vbar, vbar = (v_n + v_{n+1}) / 2  <= 0
    vbar = 0.5 * (trajectory.v[:, 1:] + trajectory.v[:, :-1])
    dissipated = dt * np.einsum("ik,ik->k", vbar, system.damping @ vbar)
    assert np.allclose(np.diff(E), -dissipated, rtol=1e-8, atol=1e-14 * E[0])
    assert np.all(np.diff(E) <= 1e-14 * E[0])  # never increases (roundoff aside)
    assert E[-1] < 1e-3 * E[0]


@pytest.mark.parametrize("rho", [0.8, 0.5])
def test_generalized_alpha_dissipates_high_frequencies_only(rho):
    system, _, _, omega_max = undamped_chain_20()
    _, modes = sla.eigh(system.stiffness.toarray(), system.mass.toarray())
    remaining = []
    for mode in (modes[:, 0], modes[:, -1]):  # omega dt = 0.07 and 1.0
        energy = EnergyRecorder(system)
        integrate(system, GeneralizedAlpha(rho), mode, np.zeros(20), 1.0 / omega_max, 2000,
                  consumers=[energy])
        remaining.append(energy.total[-1] / energy.total[0])
    # Numerical dissipation of an undamped system, concentrated at high frequency.
    # Measured after 2000 steps: lowest mode keeps 0.99993 (rho 0.8) / 0.998 (0.5),
    # highest keeps 0.12 / 2e-19; Newmark keeps both (test above).
    assert remaining[0] > 0.99
    assert remaining[1] < 0.2


# -- central-difference stability --------------------------------------------------
def test_estimate_max_frequency_matches_dense_eigensolver():
    M, K = chain_matrices(200)  # above the dense cutoff: Lanczos runs
    exact = np.sqrt(sla.eigh(K.toarray(), M.toarray(), eigvals_only=True)[-1])
    assert estimate_max_frequency(K, M) == pytest.approx(exact, rel=1e-3)  # lambda to 1e-3
    # a consistent (non-diagonal) mass takes the generalized path
    M_consistent = (M + 0.1 * sp.diags([np.full(199, 0.1)] * 2, [1, -1])).tocsr()
    exact = np.sqrt(sla.eigh(K.toarray(), M_consistent.toarray(), eigvals_only=True)[-1])
    assert estimate_max_frequency(K, M_consistent) == pytest.approx(exact, rel=1e-3)


def test_central_difference_refuses_an_unstable_step():
    system = chain(n=30, rayleigh=None)
    omega_max = np.sqrt(sla.eigh(system.stiffness.toarray(), system.mass.toarray(),
                                 eigvals_only=True)[-1])
    q0, v0 = initial_state(30)
    with pytest.raises(ValueError, match=r"dt = .* exceeds the central-difference stability "
                                         r"bound 2/omega_max = (\d|\.)+"):
        iterate(system, CentralDifference(), q0, v0, 1.01 * 2 / omega_max, 10)
    run = iterate(system, CentralDifference(), q0, v0, 0.99 * 2 / omega_max, 10)
    assert run.summary().details["stability_bound"] == pytest.approx(2 / omega_max, rel=1e-3)


def clustered_chain(n: int = 400):
    """Uniform springs, masses in [1, 1.01]: the top eigenvalues cluster (spacing ~1e-5),
    so Lanczos at rtol 1e-3 stops visibly below lambda_max, while Gershgorin is loose (1.9e-3)."""
    m = 1.0 + 0.01 * np.random.default_rng(1).random(n)
    K = sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
    return SecondOrderSystem(mass=sp.diags(m, format="csr"), stiffness=K)


def test_central_difference_refuses_a_step_just_above_the_true_bound():
    system = clustered_chain()  # 400 dofs: above the dense cutoff, Lanczos runs
    exact = np.sqrt(sla.eigh(system.stiffness.toarray(), system.mass.toarray(),
                             eigvals_only=True)[-1])
    true_bound = 2.0 / exact
    omega = bound_max_frequency(system.stiffness, system.mass)
    assert omega.method == "ritz residual"
    assert omega.estimate <= exact <= omega.upper  # Ritz value below, residual bound above
    # 1e-5 past the true bound (dense eigensolve: exact to ~1e-15). The Lanczos estimate
    # alone is 7.7e-5 low here, so 2 / estimate would have let this step through:
    dt = true_bound * (1.0 + 1e-5)
    assert 2.0 / omega.estimate > dt
    q0, v0 = initial_state(400)
    with pytest.raises(ValueError, match=r"^dt = .* exceeds the central-difference stability "
                                         r"bound 2/omega_max = \d\.\d+ \(omega_max <= "):
        iterate(system, CentralDifference(), q0, v0, dt, 10)
    # The margin is what the tolerance allows: ARPACK stops at ||r|| <= rtol theta (rtol 1e-3),
    # so the checked bound is at most a factor 1/sqrt(1 + rtol) below the true one
    # (measured 3.4e-4 below); a step 0.1 % under the true bound still runs.
    run = iterate(system, CentralDifference(), q0, v0, 0.999 * true_bound, 10)
    details = run.summary().details
    assert true_bound / np.sqrt(1.0 + 1e-3) <= details["stability_bound"] <= true_bound
    assert details["omega_max"] <= exact <= details["omega_max_upper"]
    assert len(list(run)) == 11


def test_max_frequency_upper_bounds_hold_on_every_path(monkeypatch):
    M, K = chain_matrices(200)
    # a consistent (non-diagonal) mass: residual in the M^-1 norm
    M_consistent = (M + 0.1 * sp.diags([np.full(199, 0.1)] * 2, [1, -1])).tocsr()
    exact = np.sqrt(sla.eigh(K.toarray(), M_consistent.toarray(), eigvals_only=True)[-1])
    omega = bound_max_frequency(K, M_consistent)
    assert omega.method == "ritz residual"
    assert omega.estimate <= exact <= omega.upper <= exact * np.sqrt(1.0 + 1e-3)
    # ARPACK gives up without a Ritz value: Gershgorin's bound of D^-1/2 K D^-1/2 stands alone
    import scipy.sparse.linalg as spla
    from femrom.integrators import _stability

    def no_convergence(*args, **kwargs):
        raise spla.ArpackNoConvergence("no convergence", np.empty(0), np.empty((200, 0)))

    monkeypatch.setattr(_stability.spla, "eigsh", no_convergence)
    exact = np.sqrt(sla.eigh(K.toarray(), M.toarray(), eigvals_only=True)[-1])
    omega = bound_max_frequency(K, M)
    scaled = np.diag(1.0 / np.sqrt(M.diagonal())) @ K.toarray() @ np.diag(1.0 / np.sqrt(M.diagonal()))
    assert omega.method == "gershgorin"
    assert omega.upper == pytest.approx(np.sqrt(np.abs(scaled).sum(axis=1).max()), rel=1e-14)
    assert omega.upper >= exact


def test_central_difference_needs_a_diagonal_mass():
    M, K = chain_matrices(5)
    M = (M + 0.1 * sp.diags([np.ones(4)] * 2, [1, -1])).tocsr()
    with pytest.raises(ValueError, match="diagonal \\(lumped\\) mass"):
        iterate(SecondOrderSystem(mass=M, stiffness=K), CentralDifference(), np.zeros(5),
                np.zeros(5), 0.1, 1)


# -- failures keep what was streamed -------------------------------------------------
def test_non_finite_state_stops_the_run_and_keeps_the_trajectory():
    system = chain(n=30, rayleigh=None, forced=False)
    omega_max = estimate_max_frequency(system.stiffness, system.mass)
    q0, v0 = initial_state(30)
    trajectory = Trajectory()
    with pytest.raises(IntegrationError, match=r"non-finite state at step \d+ \(t = ") as info:
        integrate(system, CentralDifference(check_stability=False), q0, v0,
                  1.5 * 2 / omega_max, 10_000, consumers=[trajectory])
    k = info.value.step
    assert 10 < k < 10_000 and info.value.t == pytest.approx(k * 1.5 * 2 / omega_max)
    assert list(trajectory.steps) == list(range(k))  # everything before the failure
    assert np.all(np.isfinite(trajectory.q)) and np.all(np.isfinite(trajectory.a))
    assert np.max(np.abs(trajectory.q[:, -1])) > 1e100  # it really blew up


class PoisonedSpring(NonlinearForce):
    """A linear spring ``f = k q`` whose force turns NaN after ``poison_after``
    committed steps; the state (steps committed) checks the freeze/commit contract."""

    conservative = False

    def __init__(self, n, poison_after):
        self.n, self.poison_after = n, poison_after
        self.seen_states = []

    def initial_state(self):
        return 0

    def force(self, q, v, state=None):
        self.seen_states.append(state)
        return np.full(self.n, np.nan) if state >= self.poison_after else 0.1 * q

    def tangent(self, q, v, state=None):
        return 0.1 * sp.identity(self.n, format="csr"), None

    def commit(self, q, v, state):
        return state + 1

    def checkpoint(self, state):
        return {"steps": np.array(state)}

    def restore(self, data):
        return int(data["steps"])


@pytest.mark.parametrize("scheme", [Newmark(), CentralDifference()], ids=["newmark", "central"])
def test_nan_force_stops_the_run_naming_step_and_time(scheme):
    M, K = chain_matrices(6)
    force = PoisonedSpring(6, poison_after=7)
    system = SecondOrderSystem(mass=M, stiffness=K, nonlinear=force)
    trajectory = Trajectory(fields=("q",))
    with pytest.raises(IntegrationError, match=r"step 8 \(t = 0\.4\)") as info:
        integrate(system, scheme, *initial_state(6), 0.05, 20, consumers=[trajectory])
    assert info.value.step == 8
    assert len(trajectory) == 8  # steps 0..7 were streamed before the failure


def test_nonlinear_state_is_frozen_during_newton_and_committed_once_per_step():
    M, K = chain_matrices(6)
    force = PoisonedSpring(6, poison_after=10**9)
    system = SecondOrderSystem(mass=M, stiffness=K, nonlinear=force)
    results = list(iterate(system, Newmark(), *initial_state(6), 0.05, 5))
    assert [r.state for r in results] == [0, 1, 2, 3, 4, 5]
    # every force evaluation inside step k (Newton residuals) saw the state k - 1
    assert force.seen_states == sorted(force.seen_states)
    assert set(force.seen_states) == {0, 1, 2, 3, 4}


def test_newton_failure_names_the_step():
    system, q0, v0 = sine_gordon_chain()
    scheme = Newmark(newton=Newton(rtol=1e-14, max_iterations=1))
    with pytest.raises(IntegrationError, match=r"step 1 \(t = 0\.5\).*Newton did not converge"):
        list(iterate(system, scheme, q0, v0, 0.5, 3))


# -- the linear path ----------------------------------------------------------------
def counting_factory(calls):
    def factory(A, spd=True):
        calls.append(A.shape)
        return make_solver(A, "auto", spd=spd)
    return factory


@pytest.mark.parametrize("scheme", [Newmark(), GeneralizedAlpha(0.8), ImplicitMidpoint()],
                         ids=["newmark", "generalized-alpha", "midpoint"])
def test_linear_system_factorises_once_and_never_runs_newton(scheme, monkeypatch):
    def forbidden(*args, **kwargs):
        raise AssertionError("Newton ran on a linear system")

    monkeypatch.setattr(newmark, "ImplicitSolve", forbidden)
    monkeypatch.setattr(implicit_midpoint, "ImplicitSolve", forbidden)
    system = chain()
    for n_steps in (10, 100):
        calls = []
        summary = integrate(system, scheme, *initial_state(8), 0.05, n_steps,
                            solver=counting_factory(calls))
        assert len(calls) == 2  # lumped mass (for a_0) + the effective matrix, once
        assert summary.n_factorizations == 1  # the diagonal mass needs none
        assert summary.solver == "diagonal+superlu"
        assert summary.newton_iterations == 0 and summary.n_steps == n_steps


def test_nonlinear_system_runs_newton_with_one_factorisation_per_iteration():
    system, q0, v0 = sine_gordon_chain()
    summary = integrate(system, Newmark(newton=Newton(method="full")), q0, v0, 0.05, 20)
    assert summary.newton_iterations >= 20  # at least one iteration per step
    assert summary.n_factorizations == summary.newton_iterations


def test_a_small_system_takes_dense_newton_to_the_same_steps():
    # auto picks dense arrays up to dense_max dofs: no sparse factorisation in the loop, the same
    # Newton iterations and tolerance, so the runs agree to the tolerance (measured 1e-15)
    system, q0, v0 = sine_gordon_chain()
    assert system.n_dofs <= Newton().dense_max
    full, dense = Trajectory(), Trajectory()
    a = integrate(system, Newmark(newton=Newton(method="full", rtol=1e-13)), q0, v0, 0.05, 40, consumers=[full])
    b = integrate(system, Newmark(newton=Newton(rtol=1e-13)), q0, v0, 0.05, 40, consumers=[dense])
    assert b.n_factorizations == 0 < a.n_factorizations
    assert a.newton_iterations == b.newton_iterations
    assert np.max(np.abs(dense.q - full.q)) < 1e-10 * np.max(np.abs(full.q))


# -- nonlinear: sine-Gordon ----------------------------------------------------------
@pytest.mark.parametrize("scheme", [Newmark(), ImplicitMidpoint()], ids=["newmark", "midpoint"])
def test_sine_gordon_converges_at_second_order(scheme):
    system, q0, v0 = sine_gordon_chain()
    T, levels = 2.0, (20, 40, 80, 160)
    # reference: same scheme, 8x finer than the finest level, so its own error
    # is 1/64 of the finest error and biases the fitted slope by < 0.02
    reference = list(iterate(system, scheme, q0, v0, T / (8 * levels[-1]), 8 * levels[-1]))[-1].q
    errors = []
    for n_steps in levels:
        *_, last = iterate(system, scheme, q0, v0, T / n_steps, n_steps)
        errors.append(np.max(np.abs(last.q - reference)))
    assert abs(fitted_order([T / n for n in levels], errors) - 2.0) < 0.1


@pytest.mark.parametrize("scheme", [Newmark(), ImplicitMidpoint(accelerations=False)],
                         ids=["newmark", "midpoint"])
def test_sine_gordon_energy_error_is_bounded_and_second_order(scheme):
    # Neither scheme conserves a non-quadratic energy exactly; both are
    # symplectic or conjugate-symplectic, so the energy error stays bounded and
    # O(dt^2) over long times (Hairer, Lubich & Wanner 2006, ch. IX and XV).
    system, q0, v0 = sine_gordon_chain()
    T, deviations, halves = 50.0, [], []
    for dt in (0.1, 0.05):
        energy = EnergyRecorder(system)
        integrate(system, scheme, q0, v0, dt, int(round(T / dt)), consumers=[energy])
        error = np.abs(energy.total / energy.total[0] - 1.0)
        deviations.append(error.max())
        halves.append((error[: len(error) // 2].max(), error[len(error) // 2:].max()))
    # measured at dt = 0.05: 3.8e-4 (Newmark), 1.9e-4 (midpoint)
    assert deviations[1] < 1e-3
    # halving dt divides the error by 4 (measured 3.98 for both): O(dt^2)
    assert 3.0 < deviations[0] / deviations[1] < 5.0
    # bounded, not growing: the second half of the run deviates no more than the
    # first (measured ratios 0.8-1.0; a linear drift would give ~2)
    for first, second in halves:
        assert second < 1.3 * first


# -- consumers, results and restart ----------------------------------------------------
def test_consumers_keep_only_what_they_are_asked_for():
    system = chain(outputs=True)
    q0, v0 = initial_state(8)
    every_third = Trajectory(every=3, fields=("q",))
    full = Trajectory()
    outputs = OutputRecorder(system, every=3)
    summary = integrate(system, Newmark(), q0, v0, 0.05, 10,
                        consumers=[every_third, full, outputs])
    assert list(every_third.steps) == [0, 3, 6, 9]
    assert every_third.q.shape == (8, 4) and full.q.shape == (8, 11)
    np.testing.assert_array_equal(every_third.q, full.q[:, ::3])
    with pytest.raises(AttributeError, match="keeps \\('q',\\)"):
        every_third.v
    np.testing.assert_allclose(outputs.outputs, full.q[[0, 7]][:, ::3], rtol=1e-15)
    assert outputs.names == ("first", "last") and outputs.t == pytest.approx(every_third.t)
    assert summary.n_steps == 10 and summary.steps_per_second > 0
    with pytest.raises(ValueError, match="no outputs"):
        OutputRecorder(chain())
    with pytest.raises(ValueError, match="unknown trajectory fields \\['x'\\]"):
        Trajectory(fields=("q", "x"))


def test_step_zero_has_the_consistent_acceleration_and_results_are_read_only():
    system = chain()
    q0, v0 = initial_state(8)
    first, second = list(iterate(system, Newmark(), q0, v0, 0.05, 1))
    expected = system.residual_force(0.0, q0, v0) / system.mass.diagonal()
    np.testing.assert_allclose(first.a, expected, rtol=1e-14)
    assert (first.step, first.t, second.step, second.t) == (0, 0.0, 1, 0.05)
    with pytest.raises(ValueError, match="read-only"):
        second.q[0] = 1.0
    q0[0] = 99.0  # the caller's array is copied, not aliased
    assert first.q[0] != 99.0


@pytest.mark.parametrize("scheme", [Newmark(), GeneralizedAlpha(0.5), CentralDifference(),
                                    ImplicitMidpoint()],
                         ids=["newmark", "generalized-alpha", "central", "midpoint"])
def test_restart_from_a_step_result_is_bit_exact(scheme):
    system, q0, v0 = sine_gordon_chain(n=20)
    results = list(iterate(system, scheme, q0, v0, 0.05, 20))
    resumed = list(iterate(system, scheme, None, None, 0.05, 10, start=results[10]))
    assert [r.step for r in resumed] == list(range(11, 21))
    for a, b in zip(results[11:], resumed):
        assert a.t == b.t
        np.testing.assert_array_equal(a.q, b.q)
        np.testing.assert_array_equal(a.v, b.v)
    with pytest.raises(ValueError, match="q0 = v0 = None"):
        iterate(system, scheme, q0, v0, 0.05, 1, start=results[10])


def test_bad_arguments_are_named():
    system = chain()
    with pytest.raises(ValueError, match="q0 has shape \\(3,\\), expected \\(8,\\)"):
        iterate(system, Newmark(), np.zeros(3), np.zeros(8), 0.1, 1)
    with pytest.raises(ValueError, match="dt must be positive"):
        iterate(system, Newmark(), np.zeros(8), np.zeros(8), 0.0, 1)
    with pytest.raises(ValueError, match="unknown linear-solver strategy 'magic'"):
        iterate(system, Newmark(), np.zeros(8), np.zeros(8), 0.1, 1, solver="magic")


def test_stepresult_is_a_restart_point_for_a_stateful_force():
    M, K = chain_matrices(6)
    force = PoisonedSpring(6, poison_after=10**9)
    system = SecondOrderSystem(mass=M, stiffness=K, nonlinear=force)
    results = list(iterate(system, Newmark(), *initial_state(6), 0.05, 6))
    saved = force.checkpoint(results[3].state)
    start = StepResult(step=3, t=results[3].t, q=results[3].q, v=results[3].v, a=results[3].a,
                       state=force.restore(saved))
    resumed = list(iterate(system, Newmark(), None, None, 0.05, 3, start=start))
    np.testing.assert_array_equal(resumed[-1].q, results[-1].q)
    assert resumed[-1].state == results[-1].state == 6


@pytest.mark.parametrize("scheme, mass_kept", [(Newmark(), False), (ImplicitMidpoint(), True),
                                               (ImplicitMidpoint(accelerations=False), False)])
def test_the_mass_factor_lives_only_as_long_as_the_scheme_needs_it(scheme, mass_kept):
    """The initial acceleration needs M's factor once; an implicit scheme that never
    solves with M again must not hold it for the whole run (1.2 GB at 5e5 dofs)."""
    import gc
    import weakref

    system = chain(n=30, rayleigh=None, forced=False)
    built = []

    def factory(A, spd=True):
        solver = make_solver(A, "superlu", spd=spd)
        built.append((weakref.ref(solver), A is system.mass))
        return solver

    q0, v0 = initial_state(30)
    run = iterate(system, scheme, q0, v0, 1e-2, 5, solver=factory)
    gc.collect()
    mass_alive = [ref() is not None for ref, is_mass in built if is_mass]
    assert mass_alive and any(mass_alive) == mass_kept
    assert any(ref() is not None for ref, is_mass in built if not is_mass)  # A_eff is kept
    steps = list(run)
    assert len(steps) == 6 and run.summary().n_factorizations == len(built)


def test_newmark_frequencies_are_the_phase_of_average_acceleration():
    """Step one undamped mode q'' + w^2 q = 0 from (1, 0) with Newmark average acceleration
    (the library's scheme) and compare with cos(Omega t) at the predicted discrete frequency."""
    from femrom.integrators import newmark_frequencies

    w, dt, steps = 3.0, 0.2, 400               # w dt = 0.6: a phase lag of ~3 % per period
    system = SecondOrderSystem(mass=sp.identity(1, format="csr"), stiffness=sp.csr_matrix([[w * w]]))
    trajectory = Trajectory(every=1, fields=("q",))
    integrate(system, Newmark(), np.ones(1), np.zeros(1), dt=dt, n_steps=steps, consumers=[trajectory])
    Omega = newmark_frequencies(w, dt)
    t = dt * np.arange(steps + 1)
    # no amplitude error and the predicted phase: round-off over 400 steps only (1e-12); the
    # continuous frequency is off by 1 - Omega / w = 2.9 % and misses by O(1) after 400 steps
    np.testing.assert_allclose(trajectory.q[0], np.cos(Omega * t), rtol=0, atol=1e-12)
    assert np.max(np.abs(trajectory.q[0] - np.cos(w * t))) > 0.5
    np.testing.assert_allclose(newmark_frequencies(np.array([w, 2 * w]), dt)[0], Omega, rtol=0, atol=0)
