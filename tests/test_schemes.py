"""One scheme registry for the full and the reduced models: each scheme steps a sparse full model
and a dense reduced one alike, declares its frequency map, and a model about a reference state
is the model itself seen from there."""

import numpy as np
import pytest
import scipy.sparse as sp

from femrom import FemromError
from femrom.fem import JenkinsForce, LocalPotential
from femrom.inference import ERA, LagrangianOpInf, galerkin, reduce_snapshots
from femrom.integrators import (
    Newmark,
    Shaker,
    StepResult,
    Stepper,
    Trajectory,
    integrate,
    march,
    registered_schemes,
    time_scheme,
)
from femrom.scene import SecondOrderSystem

SCHEMES = sorted(name for name, cls in registered_schemes().items() if "second_order" in cls.models)


def relative(A, B):
    return float(np.linalg.norm(A - B) / np.linalg.norm(B))


def chain(n=12, seed=3, *, nonlinear=None, damping=0.02):
    """Fixed-fixed chain with lumped masses (central difference needs them), mass-proportional damping
    (diagonal: central difference treats it implicitly on both the sparse and the dense path), one input."""
    rng = np.random.default_rng(seed)
    m = 1.0 + 0.5 * rng.random(n)
    k = 1.0 + rng.random(n + 1)
    K = sp.diags([k[:-1] + k[1:], -k[1:-1], -k[1:-1]], [0, 1, -1], format="csr")
    M = sp.diags(m, format="csr")
    B = np.zeros((n, 1))
    B[n // 2, 0] = 1.0
    return SecondOrderSystem(mass=M, stiffness=K, damping=None if damping is None else damping * M,
                             input_matrix=B, nonlinear=nonlinear,
                             output_matrix=sp.csr_matrix(np.eye(n)[[0, n - 1]]))


def duffing_layer(n):
    return LocalPotential.of_density("duffing", np.full(3, 0.5), dofs=[2, 5, 9], n_dofs=n, linear=0.2,
                                     cubic=3.0, name="layer")


@pytest.mark.parametrize("scheme", SCHEMES)
def test_a_scheme_steps_the_full_model_and_its_exact_projection_alike(scheme):
    """The sparse chain with a cubic spring layer, and its Galerkin model on the identity basis
    (dense operators, the projected force): the same scheme gives the same trajectory. Both solve
    the same equations; the two paths differ in sparse/dense summation order and in Newton's
    stopping point (its tolerance 1e-10 relative), so 1e-8 over 400 steps of a forced, damped run."""
    n = 12
    system = chain(n, nonlinear=duffing_layer(n))
    reduced = galerkin(system, np.eye(n)).system
    assert reduced.is_dense and not system.is_dense
    times = 0.05 * np.arange(401)
    U = np.sin(1.1 * times)[None, :]
    q0 = 0.3 * np.sin(np.linspace(0, np.pi, n))
    full = march(system, scheme, times, q0, np.zeros(n), inputs=U)
    small = march(reduced, scheme, times, q0, np.zeros(n), inputs=U)
    assert full["path"] == small["path"] == "steps"
    assert relative(small["q"], full["q"]) < 1e-8, relative(small["q"], full["q"])
    assert full["newton_iterations"] > 0 or scheme == "central_difference"


@pytest.mark.parametrize("scheme", SCHEMES)
def test_frequency_map_is_the_phase_the_scheme_steps_an_undamped_mode_at(scheme):
    """An undamped mode q'' + w^2 q = 0 stepped at w dt = 0.6 for 2000 steps: the discrete solution
    is cos(Omega t_k) with Omega = scheme.frequency(w, dt) (to round-off; a wrong map, even by the
    scheme's own O(dt^2) phase error of 1.5 %, misses by far more), and continuous_frequency inverts it."""
    w, dt = 2.0, 0.3
    system = SecondOrderSystem(mass=np.eye(1), stiffness=np.array([[w * w]]))
    times = dt * np.arange(2001)
    run = march(system, scheme, times, np.ones(1), np.zeros(1))
    step = time_scheme(scheme)
    Omega = step.frequency(w, dt)
    assert abs(Omega - w) > 1e-3 * w                          # the map is not the identity here
    if scheme == "generalized_alpha":
        # its third (spurious) root is excited by the start: the response is cos(Omega t) plus a
        # small non-oscillating part; the period is checked on a long run in the next test
        assert np.max(np.abs(run["q"][0] - np.cos(Omega * times))) < 0.05
    else:
        np.testing.assert_allclose(run["q"][0], np.cos(Omega * times), atol=1e-9)
    assert abs(step.continuous_frequency(Omega, dt) - w) < 1e-12 * w


def test_generalized_alpha_frequency_matches_a_measured_period():
    """Generalized-alpha's map (from its step map's eigenvalues) against the zero crossings of a run."""
    w, dt = 2.0, 0.05
    system = SecondOrderSystem(mass=np.eye(1), stiffness=np.array([[w * w]]))
    times = dt * np.arange(40001)
    step = time_scheme("generalized_alpha", spectral_radius=1.0)
    q = march(system, step, times, np.ones(1), np.zeros(1))["q"][0]
    crossings = np.flatnonzero(np.diff(np.sign(q)) != 0)
    # linear interpolation of the crossing times
    tc = times[crossings] - q[crossings] * dt / (q[crossings + 1] - q[crossings])
    measured = np.pi * (tc.size - 1) / (tc[-1] - tc[0])
    assert abs(measured - step.frequency(w, dt)) < 1e-7 * w


def test_central_difference_refuses_a_consistent_mass_and_too_large_a_step():
    n = 6
    K = sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
    M = sp.diags([4.0 * np.ones(n), np.ones(n - 1), np.ones(n - 1)], [0, 1, -1], format="csr") / 6.0
    consistent = SecondOrderSystem(mass=M, stiffness=K)
    reason = time_scheme("central_difference").supports(consistent)
    assert reason is not None and "diagonal (lumped) mass" in reason
    with pytest.raises(FemromError, match="cannot step this model: the full model needs a diagonal"):
        march(consistent, "central_difference", np.linspace(0, 1, 11), np.zeros(n), np.zeros(n))
    # a dense model with the same (consistent) mass is stepped: its (M + h C / 2) is factorised
    dense = SecondOrderSystem(mass=M.toarray(), stiffness=K.toarray())
    assert time_scheme("central_difference").supports(dense) is None
    with pytest.raises(FemromError, match="exceeds the Stoermer-Verlet bound"):
        march(dense, "verlet", np.linspace(0, 10, 6), np.zeros(n), np.zeros(n))


def test_aliases_and_unknown_names():
    assert type(time_scheme("midpoint")) is type(time_scheme("implicit_midpoint"))
    assert type(time_scheme("verlet")) is type(time_scheme("central_difference"))
    with pytest.raises(FemromError, match="unknown time scheme 'rk5'; valid: central_difference, "
                                          "discrete_gradient, generalized_alpha, implicit_midpoint, newmark, rk4, "
                                          "symplectic_euler_a, symplectic_euler_b"):
        time_scheme("rk5")
    # a scheme of another kind of model is refused where a second-order one steps
    system = SecondOrderSystem(mass=np.eye(1), stiffness=np.eye(1))
    with pytest.raises(FemromError, match="scheme 'rk4' does not step second-order models; valid: "
                                          "central_difference, discrete_gradient, generalized_alpha"):
        march(system, "rk4", np.linspace(0, 1, 5), np.ones(1), np.zeros(1))


def test_discrete_gradient_conserves_the_energy_of_a_sparse_full_model():
    """The full (sparse) chain with a quartic spring layer and no damping or input: the discrete
    gradient keeps v^T M v / 2 + q^T K q / 2 + U(q) to Newton's tolerance (1e-10 of the step's
    velocity) over 2000 large steps, where the midpoint rule, symplectic but not energy-exact for a
    quartic potential, drifts by more than 1e-6."""
    n = 12
    layer = LocalPotential.of_density("duffing", np.full(3, 0.5), dofs=[2, 5, 9], n_dofs=n, linear=0.0,
                                      cubic=40.0, name="layer")
    system = SecondOrderSystem(mass=chain(n).mass, stiffness=chain(n).stiffness, nonlinear=layer)
    times = 0.4 * np.arange(2001)
    q0 = 0.8 * np.sin(np.linspace(0, np.pi, n))
    energy = {}
    for scheme in ("discrete_gradient", "implicit_midpoint"):
        run = march(system, scheme, times, q0, np.zeros(n))
        energy[scheme] = np.array([system.energy(run["q"][:, k], run["v"][:, k]) for k in range(times.size)])
    E0 = energy["discrete_gradient"][0]
    assert np.max(np.abs(energy["discrete_gradient"] - E0)) < 1e-8 * E0
    assert np.max(np.abs(energy["implicit_midpoint"] - E0)) > 1e-6 * E0


def damped_forced_model(nonlinear=None, sparse=False):
    """r = 3, random SPD M, K, C (C about 1/40 of K), two inputs: big enough for coupling, small
    enough that every matrix can be written out in the reference."""
    rng = np.random.default_rng(7)
    r = 3

    def spd(scale):
        A = rng.standard_normal((r, r))
        return scale * (A @ A.T + r * np.eye(r))

    M, K, C = spd(1.0), spd(4.0), spd(0.1)
    B = rng.standard_normal((r, 2))
    wrap = sp.csr_matrix if sparse else np.asarray
    system = SecondOrderSystem(mass=wrap(M), stiffness=wrap(K), damping=wrap(C), input_matrix=B, nonlinear=nonlinear)
    return system, (M, K, C, B), rng.standard_normal(r), rng.standard_normal(r)


def discrete_energy_balance(system, matrices, run, U, h):
    """``E_{k+1} - E_k - h v_m . (B u_{k+1/2} - C v_m)`` per step, with ``u_{k+1/2}`` the mean of the
    two samples (what the midpoint family steps with), the energies and the damping's share."""
    M, K, C, B = matrices
    Q, V = run["q"], run["v"]
    E = np.array([system.energy(Q[:, k], V[:, k]) for k in range(Q.shape[1])])
    vm = 0.5 * (V[:, 1:] + V[:, :-1])
    Fm = B @ (0.5 * (U[:, 1:] + U[:, :-1]))
    power = h * np.einsum("ik,ik->k", vm, Fm - C @ vm)
    dissipated = h * np.einsum("ik,ik->k", vm, C @ vm)
    return np.diff(E) - power, E, dissipated


def test_discrete_gradient_balances_the_energy_of_a_damped_forced_linear_model_as_the_midpoint_rule():
    """A linear model with damping and inputs, sparse so that the scheme's own step (not the shared
    linear map) runs: E = v^T M v / 2 + q^T K q / 2 changes per step by exactly h v_m . (B u_{k+1/2}
    - C v_m) (module docstring of the scheme; multiply the step by q_{k+1} - q_k = h v_m). One
    linear solve per step, so the balance holds to round-off: 1e-12 of the largest energy (measured
    1e-15). The step is the implicit midpoint rule, here written out in the test as one 2r x 2r
    solve per step, [I, -h/2 I; h/2 K, M + h/2 C] x_{k+1} = [I, h/2 I; -h/2 K, M - h/2 C] x_k + [0; h
    B u_{k+1/2}]: equal to round-off (1e-12 relative over 300 steps; measured 1e-14), as are the
    library's midpoint rule and the dense model's linear map."""
    system, matrices, q0, v0 = damped_forced_model(sparse=True)
    M, K, C, B = matrices
    r, h = M.shape[0], 0.1
    times = h * np.arange(301)
    U = np.vstack([np.sin(1.3 * times), np.cos(0.7 * times)])
    run = march(system, "discrete_gradient", times, q0, v0, inputs=U)
    assert run["path"] == "steps"
    residual, E, dissipated = discrete_energy_balance(system, matrices, run, U, h)
    assert np.max(np.abs(residual)) < 1e-12 * np.max(E), np.max(np.abs(residual))
    # the damping takes out a visible share: without C v_m the balance would miss by this much
    assert np.sum(dissipated) > 0.05 * E[0], (np.sum(dissipated), E[0])
    I = np.eye(r)
    lhs = np.block([[I, -0.5 * h * I], [0.5 * h * K, M + 0.5 * h * C]])
    rhs = np.block([[I, 0.5 * h * I], [-0.5 * h * K, M - 0.5 * h * C]])
    x = np.concatenate([q0, v0])
    X = [x]
    for k in range(times.size - 1):
        x = np.linalg.solve(lhs, rhs @ x + np.concatenate([np.zeros(r), h * B @ (0.5 * (U[:, k] + U[:, k + 1]))]))
        X.append(x)
    X = np.array(X).T
    assert relative(run["q"], X[:r]) < 1e-12 and relative(run["v"], X[r:]) < 1e-12
    midpoint = march(system, "implicit_midpoint", times, q0, v0, inputs=U)
    dense = march(damped_forced_model()[0], "discrete_gradient", times, q0, v0, inputs=U)
    assert dense["path"] == "linear map"
    assert relative(midpoint["q"], run["q"]) < 1e-12 and relative(dense["q"], run["q"]) < 1e-12


def test_discrete_gradient_balances_the_energy_of_a_damped_forced_nonlinear_model():
    """The same damped, forced model with a quartic spring layer on two dofs (the nonlinear step, a
    Newton iteration): E = v^T M v / 2 + q^T K q / 2 + U(q) changes per step by exactly h v_m . (B
    u_{k+1/2} - C v_m) (the discrete gradient's identity). Newton stops when its update is below
    1e-10 of v_m and converges quadratically, so the balance holds to 1e-10 of the largest energy
    (measured 3e-16 relative); the damping's share of the balance is far larger."""
    layer = LocalPotential.of_density("duffing", np.full(2, 0.5), dofs=[0, 2], n_dofs=3, linear=0.0,
                                      cubic=20.0, name="layer")
    system, matrices, q0, v0 = damped_forced_model(nonlinear=layer)
    h = 0.1
    times = h * np.arange(301)
    U = np.vstack([np.sin(1.3 * times), np.cos(0.7 * times)])
    run = march(system, "discrete_gradient", times, q0, v0, inputs=U)
    assert run["path"] == "steps" and run["newton_iterations"] > 0
    residual, E, dissipated = discrete_energy_balance(system, matrices, run, U, h)
    potential = max(layer.potential(run["q"][:, k]) for k in range(times.size))
    assert potential > 0.05 * np.max(E)                       # the quartic layer matters
    assert np.max(np.abs(residual)) < 1e-10 * np.max(E), np.max(np.abs(residual))
    assert np.sum(dissipated) > 0.05 * E[0], (np.sum(dissipated), E[0])


def test_a_model_about_a_reference_is_the_model_seen_from_there():
    """A chain with a constant load and grounded Jenkins sliders, moved to a reference q_0 with the
    sliders' state there: the model about q_0 started at x = 0 follows the original started at q_0,
    x(t) = q(t) - q_0, to the solvers' round-off (same scheme, same equations in shifted variables),
    and so does its Galerkin model on the identity basis, which keeps the load f_0 - K q_0."""
    n = 10
    joint = JenkinsForce(np.array([2.0, 3.0]), np.array([0.05, 0.08]), n, dofs=[3, 7], name="joint")
    rng = np.random.default_rng(0)
    base = chain(n, nonlinear=joint)
    system = SecondOrderSystem(mass=base.mass, stiffness=base.stiffness, damping=base.damping,
                               input_matrix=base.input_matrix, nonlinear=joint, load=0.1 * rng.standard_normal(n),
                               output_matrix=base.output_matrix)
    q0 = 0.2 * rng.standard_normal(n)
    state0 = joint.commit(q0, np.zeros(n), joint.initial_state())
    times = 0.05 * np.arange(301)
    U = np.sin(2.0 * times)[None, :]
    original = march(system, Newmark(), times, q0, np.zeros(n), inputs=U, state0=state0)
    about = system.about(q0)
    assert np.allclose(about.load, system.load - system.stiffness @ q0)
    shifted = march(about, Newmark(), times, np.zeros(n), np.zeros(n), inputs=U, state0=state0)
    np.testing.assert_allclose(shifted["q"] + q0[:, None], original["q"], atol=1e-12)
    projected = galerkin(system, np.eye(n), reference=q0).system
    reduced = march(projected, Newmark(), times, np.zeros(n), np.zeros(n), inputs=U, state0=state0)
    np.testing.assert_allclose(reduced["q"] + q0[:, None], original["q"], atol=1e-10)


def test_stepper_and_integrate_agree_on_a_full_model():
    """The one-step-at-a-time Stepper on the sparse chain with sliders equals the streaming driver
    under the same input (samples of the same sine: Newmark samples it at the step's end)."""
    n = 10
    joint = JenkinsForce(np.array([2.0, 3.0]), np.array([0.05, 0.08]), n, dofs=[3, 7], name="joint")
    system = chain(n, nonlinear=joint)
    dt, steps = 0.05, 200
    driven = SecondOrderSystem(mass=system.mass, stiffness=system.stiffness, damping=system.damping,
                               input_matrix=system.input_matrix, nonlinear=joint,
                               inputs=lambda t: np.array([np.sin(2.0 * t)]))
    q0 = 0.3 * np.ones(n)
    trajectory = Trajectory()
    integrate(driven, Newmark(), q0, np.zeros(n), dt, steps, consumers=[trajectory])
    stepper = Stepper(system, "newmark", dt, q0, np.zeros(n), u0=np.zeros(1))
    Q = np.column_stack([q0] + [(stepper.step([np.sin(2.0 * dt * k)]), stepper.q)[1]
                                for k in range(1, steps + 1)])
    # the driver's clock accumulates t + dt, the stepper's samples are at k dt: 1e-15 apart
    assert relative(Q, trajectory.q) < 1e-10


def test_step_result_at_rest():
    rest = StepResult.at_rest(3, state=np.array([0.5]))
    assert rest.step == 0 and rest.t == 0.0 and not rest.q.any() and not rest.v.any() and not rest.a.any()
    assert rest.state[0] == 0.5
    with pytest.raises(FemromError, match="q has shape"):
        StepResult.at_rest(3, q=np.ones(4))


def test_validation_data_are_judged_or_refused():
    """L-OpInf reports its residual on held-out data: round-off on another run of the same linear
    system (exact derivatives), percents on a run of a 10 % stiffer one. ERA has nothing to judge."""
    n = 8
    system = chain(n, damping=0.02)
    m = system.mass.diagonal()
    V = np.linalg.qr(np.random.default_rng(1).standard_normal((n, n)))[0] / np.sqrt(m)[:, None]   # V^T M V = I

    def data(stiffness_scale, seed):
        model = SecondOrderSystem(mass=system.mass, stiffness=stiffness_scale * system.stiffness,
                                  damping=system.damping, input_matrix=system.input_matrix)
        times = 0.02 * np.arange(1501)
        U = np.sin((1.3 + seed) * times)[None, :] + 0.5 * np.cos(3.1 * times)[None, :]
        q0 = np.random.default_rng(seed).standard_normal(n)
        run = march(model, Newmark(), times, q0, np.zeros(n), inputs=U)
        return reduce_snapshots(V, run["q"], 0.02, product=system.mass, velocities=run["v"],
                                accelerations=run["a"], derivatives="stored", inputs=U)

    learner = LagrangianOpInf(["damping"]).fit(data(1.0, 0), validation=data(1.0, 1))
    assert learner.validation_residual_ < 1e-8
    learner = LagrangianOpInf(["damping"]).fit(data(1.0, 0), validation=data(1.1, 1))
    assert learner.validation_residual_ > 1e-2
    assert LagrangianOpInf(["damping"]).fit(data(1.0, 0)).validation_residual_ is None
    with pytest.raises(FemromError, match="ERA does not use validation data"):
        ERA(order=2).fit(None, validation=object())


@pytest.mark.parametrize("scheme", ["newmark", "implicit_midpoint", "discrete_gradient", "central_difference"])
def test_a_prewarped_stepped_sine_of_a_linear_model_is_its_frequency_response(scheme):
    """A damped linear chain on a Shaker, swept with prewarping by the scheme's own frequency map:
    for the trapezoidal family (a bilinear transform: the discrete response is the continuous one at
    the warped frequency) the steady first harmonics are the continuous receptance
    ``-w^2 (K - w^2 M + i w C)^-1 f`` at the requested frequencies, to the steady-state tolerance,
    for N = 32 steps a period (unprewarped they miss by about (pi/N)^2 / 3 = 3 % in frequency).
    Central difference is no bilinear transform: its map corrects the undamped frequencies, the
    damped, forced response keeps an O((w h)^2) error, here below 1 %."""
    from femrom.integrators import SteadyStateCriterion, SteppedSine

    n = 8
    system = chain(n, damping=0.05)
    M, K, C = (A.toarray() for A in (system.mass, system.stiffness, system.damping))
    frequencies = np.linspace(0.1, 0.4, 4)
    sweep = SteppedSine(frequencies, steps_per_period=32,
                        steady_state=SteadyStateCriterion(tolerance=1e-9, max_periods=4000))
    result = sweep.run(Shaker(system, 0, scheme=scheme), [1.0])
    E = system.output_matrix.toarray()
    f = system.input_matrix[:, 0]
    for k, fk in enumerate(frequencies):
        w = 2 * np.pi * fk
        exact = -w * w * (E @ np.linalg.solve(K - w * w * M + 1j * w * C, f))
        phasor = result.levels[0].phasors[:, k]
        error = np.max(np.abs(phasor - exact)) / np.max(np.abs(exact))
        if scheme == "central_difference":
            assert 1e-6 < error < 1e-2, (scheme, fk, error)
        else:
            assert error < 1e-6, (scheme, fk, error)


def test_a_shaker_drives_the_full_model_and_its_exact_projection_alike():
    """The chain with sliders on a Shaker, and its Galerkin model on the identity basis: the same
    stepped-sine phasors (same scheme, same samples; dense against sparse round-off and Newton's
    stopping point only)."""
    from femrom.integrators import SteadyStateCriterion, SteppedSine

    n = 10
    joint = JenkinsForce(np.array([2.0, 3.0]), np.array([0.05, 0.08]), n, dofs=[3, 7], name="joint")
    system = chain(n, nonlinear=joint, damping=0.05)
    sweep = SteppedSine([0.15, 0.2], steps_per_period=32,
                        steady_state=SteadyStateCriterion(tolerance=1e-6, max_periods=400))
    full = sweep.run(Shaker(system, 0), [0.5]).levels[0].phasors
    reduced = sweep.run(Shaker(galerkin(system, np.eye(n)).system, 0), [0.5]).levels[0].phasors
    assert relative(reduced, full) < 1e-8
