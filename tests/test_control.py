"""femrom.control: MPC against LQR, observers against python-control, bounds, tracking, offset-free
tracking under model mismatch, and a full-order plant against its exact state space."""

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from _required import extra
from femrom.control import (
    ClosedLoopResult,
    DisturbanceModel,
    FullOrderPlant,
    KalmanObserver,
    LinearMPC,
    MPCConfig,
    MPCError,
    MPCWarning,
    PolePlacementObserver,
    QPSolver,
    ReducedPlant,
    StateSpacePlant,
    closed_loop,
    open_loop,
    registered_formulations,
    travelling_wave,
)
from _control_chain import chain
from femrom.integrators import ImplicitMidpoint, Newmark
from femrom.rom import DiscreteStateSpace, SecondOrderROM
from femrom.scene import SecondOrderSystem

control = extra("control")

DT = 0.01


def exact_model(system, scheme="newmark"):
    """The system's own Newmark (or midpoint) state space: a Galerkin ROM with the identity basis."""
    return SecondOrderROM.galerkin(system, np.eye(system.n_dofs)).to_state_space(DT, scheme)


def sines(K, m=2, amplitude=0.05):
    t = DT * np.arange(K)
    return amplitude * np.vstack([np.sin(2 * np.pi * (2 + i) * t + i) for i in range(m)])


def small_lqr_system():
    """Two masses between springs, sampled exactly (zero-order hold): n = 4, m = 2, C = I."""
    Kc = np.array([[2.0, -1.0], [-1.0, 2.0]]) * 4.0
    Ac = np.block([[np.zeros((2, 2)), np.eye(2)], [-Kc, -0.1 * np.eye(2)]])
    Bc = np.vstack([np.zeros((2, 2)), np.eye(2)])
    Ad = sla.expm(Ac * 0.1)
    Bd = np.linalg.solve(Ac, Ad - np.eye(4)) @ Bc
    return DiscreteStateSpace(Ad, Bd, np.eye(4), np.zeros((4, 2)), dt=0.1)


# -- MPC against the LQR ---------------------------------------------------------------------

@pytest.mark.parametrize("formulation, solver", [("condensed", "CLARABEL"), ("sparse", "CLARABEL"),
                                                 ("condensed", "OSQP"), ("condensed_osqp", "OSQP")])
def test_unconstrained_mpc_with_the_dare_terminal_cost_is_the_lqr(formulation, solver):
    """With the LQR cost-to-go as terminal cost, the finite-horizon optimum is the infinite-horizon
    one (Bellman): the first input is -K x for any horizon."""
    model = small_lqr_system()
    Q, R = np.diag([1.0, 2.0, 0.5, 0.1]), np.diag([0.3, 0.1])
    K, _, _ = control.dlqr(model.A, model.B, Q, R)
    mpc = LinearMPC(model, horizon=15, output_weight=Q, input_weight=R, input_bound=None,
                    terminal_weight="dare", formulation=formulation, solver=QPSolver(solver, tolerance=1e-10))
    rng = np.random.default_rng(0)
    for _ in range(3):
        x = rng.standard_normal(4)
        u = mpc.control(x, np.zeros(4))
        # the solvers stop at 1e-10 on a well-conditioned QP (cond H = 7) and python-control solves
        # the DARE by its own call: measured 2e-14 (Clarabel) to 2e-11 (OSQP); 1e-8 leaves room for
        # both, and is far below the gap of the same MPC without the terminal cost (asserted below)
        assert np.linalg.norm(u + K @ x) <= 1e-8 * np.linalg.norm(K @ x)
    assert mpc.statuses == ["optimal"] * 3
    # without the terminal cost a short horizon gives another feedback (measured 80-100 % off):
    # the terminal cost is doing the work
    short = LinearMPC(model, horizon=3, output_weight=Q, input_weight=R, input_bound=None,
                      formulation=formulation, solver=QPSolver(solver, tolerance=1e-10))
    assert np.linalg.norm(short.control(x, np.zeros(4)) + K @ x) > 0.1 * np.linalg.norm(K @ x)


def test_formulations_solve_the_same_qp():
    """Three ways to write and solve one QP (cvxpy condensed and sparse, OSQP directly) give one plan."""
    model = exact_model(chain())
    rng = np.random.default_rng(1)
    z, window, u_prev = 1e-3 * rng.standard_normal(16), 2e-4 * rng.standard_normal((3, 20)), 0.05 * np.ones(2)
    plans = {}
    for formulation, solver in (("condensed", "CLARABEL"), ("sparse", "CLARABEL"), ("condensed_osqp", "OSQP")):
        mpc = LinearMPC(model, horizon=20, output_weight=1e8, input_weight=1.0, input_rate_weight=10.0,
                        input_bound=0.1, formulation=formulation, solver=QPSolver(solver, tolerance=1e-9))
        mpc.control(z, window, u_prev)
        plans[formulation] = mpc.plan_
    assert set(registered_formulations()) >= {"condensed", "sparse", "condensed_osqp"}
    # bounds are active (a QP, not a linear solve), and the plans agree to the solvers' 1e-9
    # tolerance amplified by the Hessian's conditioning (290): measured 4e-7 (sparse), 3e-9
    # (condensed_osqp); the bound, 1e-6 = 1e-5 of the input bound, is the one docs/control.md states
    assert np.max(np.abs(plans["condensed"])) > 0.1 - 1e-6
    for name in ("sparse", "condensed_osqp"):
        assert np.max(np.abs(plans[name] - plans["condensed"])) < 1e-5 * 0.1, name


@pytest.mark.parametrize("formulation, solver", [("condensed", "CLARABEL"), ("sparse", "CLARABEL"),
                                                 ("condensed", "OSQP"), ("condensed_osqp", "OSQP")])
def test_without_bounds_every_formulation_is_the_tracking_qp_written_out(formulation, solver):
    """No input bound, so nothing can hide a wrong term: the input-rate weight S is active and the
    previous input large, and the plan of every formulation equals the tracking problem of the
    module docstring written here in cvxpy with the states as variables (Clarabel to 1e-12). The
    formulations' solvers stop at 1e-10 on a well-conditioned QP (the LQR model of the test above):
    measured 2e-14 (Clarabel) to 8e-12 (OSQP) relative to the largest input; 1e-8 leaves room for
    both and is far below the 0.87 a plan for -u_prev is off (asserted)."""
    import cvxpy as cp
    model = small_lqr_system()
    A, B, C, D = model.A, model.B, model.C, model.D
    n, m, p, N = A.shape[0], B.shape[1], C.shape[0], 12
    Q, R, S = np.diag([1.0, 2.0, 0.5, 0.1]), np.diag([0.3, 0.1]), np.diag([2.0, 1.0])
    rng = np.random.default_rng(3)
    z0, reference, u_prev = rng.standard_normal(n), rng.standard_normal((p, N)), np.array([1.5, -2.0])
    u, z = cp.Variable((m, N)), cp.Variable((n, N + 1))
    cost, constraints = 0, [z[:, 0] == z0]
    for j in range(N):
        constraints.append(z[:, j + 1] == A @ z[:, j] + B @ u[:, j])
        move = u[:, j] - (u_prev if j == 0 else u[:, j - 1])
        cost += (cp.quad_form(C @ z[:, j] + D @ u[:, j] - reference[:, j], Q) + cp.quad_form(u[:, j], R)
                 + cp.quad_form(move, S))
    written = cp.Problem(cp.Minimize(cost), constraints)
    written.solve(solver="CLARABEL", tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12)
    assert written.status == "optimal"
    expected = u.value
    mpc = LinearMPC(model, horizon=N, output_weight=Q, input_weight=R, input_rate_weight=S, input_bound=None,
                    formulation=formulation, solver=QPSolver(solver, tolerance=1e-10))
    mpc.control(z0, reference, u_prev)
    assert mpc.statuses == ["optimal"]
    scale = np.max(np.abs(expected))
    assert np.max(np.abs(mpc.plan_ - expected)) < 1e-8 * scale
    mpc.control(z0, reference, -u_prev)           # the previous input matters to the plan
    assert np.max(np.abs(mpc.plan_ - expected)) > 0.1 * scale


# -- observers -------------------------------------------------------------------------------

def test_kalman_gain_is_python_controls_dlqe():
    model = exact_model(chain())
    W, V = np.diag(np.linspace(1.0, 2.0, 16)), np.diag([0.5, 1.0, 2.0])
    observer = KalmanObserver(model, W, V)
    L, P, _ = control.dlqe(model.A, np.eye(16), model.C, W, V)
    # the predictor gain A M is dlqe's L. python-control solves the same Riccati equation (P agrees
    # exactly here) but forms its gain its own way: measured 4e-16 relative; 1e-12 allows for a
    # different DARE route (P has condition 2e3)
    assert np.linalg.norm(model.A @ observer.gain_ - L) <= 1e-12 * np.linalg.norm(L)
    assert np.linalg.norm(observer.covariance_ - P) <= 1e-12 * np.linalg.norm(P)
    # the dual of the LQR: dlqr(A^T, C^T, W, V) gives L^T
    Kd, _, _ = control.dlqr(model.A.T, model.C.T, W, V)
    assert np.linalg.norm(Kd.T - L) <= 1e-12 * np.linalg.norm(L)
    assert np.max(np.abs(observer.error_poles())) < 1.0
    # augmented with an output disturbance: dlqe on the augmented matrices
    augmented = KalmanObserver(model, W, V, disturbance="output", disturbance_noise=0.1)
    Aa, Ca = augmented.augmented.A, augmented.augmented.C
    La, _, _ = control.dlqe(Aa, np.eye(19), Ca, sla.block_diag(W, 0.1 * np.eye(3)), V)
    assert np.linalg.norm(Aa @ augmented.gain_ - La) <= 1e-12 * np.linalg.norm(La)


def test_pole_placement_observer_places_the_error_poles():
    model = exact_model(chain(n=4, p=2))
    poles = np.linspace(0.3, 0.6, 8)
    observer = PolePlacementObserver(model, poles)
    # place_poles on an (8, 2) pair: measured 3e-11 off; 1e-8
    assert np.allclose(np.sort(observer.error_poles().real), poles, atol=1e-8)
    assert np.max(np.abs(observer.error_poles().imag)) < 1e-8
    with pytest.raises(ValueError, match="inside the unit circle"):
        PolePlacementObserver(model, np.linspace(0.5, 1.2, 8))


def test_observer_error_converges_from_a_wrong_initial_estimate_and_feasible_tracking_is_exact():
    """A reference the model itself produced from a known input: the MPC finds that input again."""
    model = exact_model(chain())
    U = sines(251)
    reference = open_loop(StateSpacePlant(model, u0=U[:, 0]), U)
    rms = np.sqrt(np.mean(reference ** 2))
    rng = np.random.default_rng(2)
    observer = KalmanObserver(model, initial_state=rms * rng.standard_normal(16))
    mpc = LinearMPC(model, horizon=30, output_weight=1 / rms ** 2, input_weight=0.0,
                    input_rate_weight=1e-6 / 0.1 ** 2, input_bound=0.1)
    plant = StateSpacePlant(model, u0=U[:, 0])
    result = closed_loop(plant, mpc, observer, reference, u0=U[:, 0], record_state=lambda plant: plant.state)
    error = np.linalg.norm(result.estimates - result.plant_states, axis=0)
    rho = np.max(np.abs(observer.error_poles()))
    # the filter's error decays like rho^k (rho = 0.97 here: 220 steps give ~1e-3); require the decay
    # and a final error below 1e-2 of the initial one
    assert rho < 0.99 and error[-1] < 1e-2 * error[0]
    assert np.all(error[100:] < error[0])
    # once the estimate has converged the plant follows the reference: measured 4e-4 from k = 150,
    # the observer's remaining error (7e-4 of its start) and the rate weight's bias (1e-6); a loop
    # that fed the windows one sample off would track a shifted reference, 0.14 away from this one
    assert result.tracking_error(start=150) < 2e-3
    # OSQP's stopping test: a bound residual below eps_abs + eps_rel max|u| = 1e-6 (1 + 0.1)
    assert result.max_constraint_violation() <= 1e-6 * 1.1
    metrics = result.metrics()
    assert metrics["n_steps"] == 250 - 30 and metrics["n_fallbacks"] == 0
    assert set(metrics) >= {"tracking_error", "input_effort", "max_constraint_violation", "qp_seconds_per_step"}
    # the MPC finds the input that made the reference again: measured 4e-5 of 0.05 from k = 150
    # (one sample off: 9e-3)
    assert np.max(np.abs(result.inputs[:, 150:] - U[:, 150:result.n_samples])) < 0.02 * 0.05


# -- bounds ----------------------------------------------------------------------------------

@pytest.mark.parametrize("formulation", ["condensed", "condensed_osqp"])
def test_applied_inputs_respect_the_bound_and_it_is_active(formulation):
    """A reference 5x larger than the bounded inputs can reach: the bound must be active, and OSQP's
    stopping test bounds its violation."""
    model = exact_model(chain())
    U = sines(151, amplitude=0.5)                         # 5x the bound
    reference = open_loop(StateSpacePlant(model, u0=np.zeros(2)), U)
    rms = np.sqrt(np.mean(reference ** 2))
    tolerance = 1e-5
    mpc = LinearMPC(model, horizon=20, output_weight=1 / rms ** 2, input_weight=1e-4 / 0.1 ** 2,
                    input_bound=0.1, formulation=formulation, solver=QPSolver(tolerance=tolerance))
    result = closed_loop(StateSpacePlant(model), mpc, KalmanObserver(model), reference)
    applied = np.abs(result.inputs[:, 1:])
    # OSQP stops when the primal residual is below eps_abs + eps_rel * max|u|, |u| <= ~0.1
    assert result.max_constraint_violation() <= tolerance * (1 + 0.1)
    assert np.all(applied <= 0.1 + tolerance * 1.1)
    # active: most inputs sit at the bound (measured 98 %), and the reference is missed
    assert np.mean(applied >= 0.1 - 1e-4) > 0.5
    assert result.tracking_error() > 0.3


def test_a_wide_bound_changes_nothing_on_a_small_reference():
    """Inactive bounds: the bounded and the unbounded MPC apply the same inputs."""
    model = exact_model(chain())
    U = sines(101, amplitude=0.02)
    reference = open_loop(StateSpacePlant(model), U)
    rms = np.sqrt(np.mean(reference ** 2))
    runs = []
    for bound in (0.1, None):
        mpc = LinearMPC(model, horizon=20, output_weight=1 / rms ** 2, input_weight=1e-4 / 0.01,
                        input_bound=bound, solver=QPSolver("clarabel", tolerance=1e-9))
        runs.append(closed_loop(StateSpacePlant(model), mpc, KalmanObserver(model), reference))
    assert np.max(np.abs(runs[0].inputs)) < 0.1 - 1e-3
    # two interior-point solves at 1e-9 of the same unconstrained optimum
    assert np.max(np.abs(runs[0].inputs - runs[1].inputs)) < 1e-6


# -- offset-free tracking --------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["output", "input"])
def test_disturbance_model_removes_the_offset_of_a_gain_error(kind):
    """The plant's inputs act 10 % stronger than the model's. A constant reference the plant can
    hold (its steady response to a constant input) is reached without offset only with a
    disturbance model."""
    model = exact_model(chain())
    plant_model = DiscreteStateSpace(model.A, 1.1 * model.B, model.C, 1.1 * model.D, dt=DT)
    gain = plant_model.C @ np.linalg.solve(np.eye(16) - plant_model.A, plant_model.B) + plant_model.D
    target = gain @ np.array([0.04, -0.03])               # reachable by the plant inside the bound
    reference = np.repeat(target[:, None], 401, axis=1)
    errors = {}
    for disturbance in (None, kind):
        mpc = LinearMPC(model, horizon=20, output_weight=1 / np.mean(target ** 2), input_weight=0.0,
                        input_rate_weight=1e-3 / 0.01, input_bound=0.1)
        observer = KalmanObserver(model, disturbance=disturbance)
        result = closed_loop(StateSpacePlant(plant_model), mpc, observer, reference)
        steady = result.outputs[:, -20:] - reference[:, -20:][:, :20]
        errors[disturbance] = np.sqrt(np.mean(steady ** 2)) / np.sqrt(np.mean(target ** 2))
    # with the disturbance state the offset goes to the transient's rest after 370 steps
    # (measured 1.7e-5 output, 4e-6 input): 1e-4
    assert errors[kind] < 1e-4
    # without it the model's 10 % gain error leaves an offset of that order (measured 12 %)
    assert errors[None] > 0.05


def test_disturbance_models_are_checked_for_detectability():
    model = exact_model(chain())
    with pytest.raises(ValueError, match="unknown disturbance model 'state'"):
        KalmanObserver(model, disturbance="state")
    integrator = DiscreteStateSpace(np.eye(2), np.eye(2), np.eye(2), np.zeros((2, 2)), dt=1.0)
    with pytest.raises(ValueError, match="output disturbance model is not detectable"):
        DisturbanceModel.output(integrator).augment(integrator)


# -- plants ----------------------------------------------------------------------------------

@pytest.mark.parametrize("scheme, name", [(Newmark(), "newmark"), (ImplicitMidpoint(), "midpoint")])
def test_full_order_plant_is_its_exact_state_space(scheme, name):
    """The FOM stepped by its own integrator with piecewise-linear inputs equals the Galerkin ROM
    with the identity basis exported by to_state_space: the same recurrence, round-off apart."""
    system = chain()
    U = sines(101) + 0.01 * np.random.default_rng(3).standard_normal((2, 101))
    fom = open_loop(FullOrderPlant(system, DT, scheme=scheme, u0=U[:, 0]), U)
    model = exact_model(system, name)
    z0 = model.initial_state(np.zeros(16), U[:, 0])
    reduced = open_loop(StateSpacePlant(model, z0, U[:, 0]), U)
    # 100 steps of two implementations of one linear map: 1e-12 relative leaves room for round-off
    assert np.linalg.norm(fom - reduced) <= 1e-12 * np.linalg.norm(fom)
    stepper = open_loop(ReducedPlant(SecondOrderROM.galerkin(system, np.eye(8)), DT, u0=U[:, 0], scheme=name), U)
    assert np.linalg.norm(stepper - fom) <= 1e-12 * np.linalg.norm(fom)


def test_closed_loop_on_the_full_order_model_with_a_truncated_rom():
    """The controller's model keeps 8 of 12 modes (0.8-5.2 Hz); the plant is the FOM stepping with
    its own Newmark integrator. A feasible reference (the FOM's response to 2-3 Hz inputs) is
    tracked within the issue's 10 %, better than the ROM predicts it open loop."""
    system = chain(n=12, p=4)
    _, modes = sla.eigh(system.stiffness.toarray(), system.mass.toarray())
    model = SecondOrderROM.galerkin(system, modes[:, :8], mass_orthonormal=True).to_state_space(DT)
    U = sines(231, amplitude=0.04)
    reference = open_loop(FullOrderPlant(system, DT), U)
    rms = np.sqrt(np.mean(reference ** 2))
    mpc = LinearMPC(model, horizon=30, output_weight=1 / rms ** 2, input_weight=0.0,
                    input_rate_weight=1e-4 / 0.01, input_bound=0.1, formulation="condensed_osqp")
    result = closed_loop(FullOrderPlant(system, DT), mpc, KalmanObserver(model, disturbance="output"), reference)
    metrics = result.metrics()
    # the ROM alone, open loop, misses the reference by 7.5 % (the truncated modes); feedback from
    # the outputs brings the closed loop to 3.6 % (measured): below the 10 % and below the
    # open-loop error, which a controller ignoring the outputs could not beat
    open_rom = open_loop(StateSpacePlant(model), U)
    open_error = np.sqrt(np.mean((open_rom - reference) ** 2)) / rms
    assert 0.05 < open_error
    assert metrics["tracking_error"] < min(0.1, 0.7 * open_error)
    assert metrics["max_constraint_violation"] <= 1e-6 * 1.1 and metrics["n_fallbacks"] == 0


def test_output_noise_reaches_only_the_observer_and_a_result_saves(tmp_path):
    model = exact_model(chain())
    U = sines(101)
    reference = open_loop(StateSpacePlant(model), U)
    rms = np.sqrt(np.mean(reference ** 2))
    runs = []
    for noise in (None, 0.1 * rms):
        mpc = LinearMPC(model, horizon=20, output_weight=1 / rms ** 2, input_weight=1e-4 / 0.01, input_bound=0.1)
        runs.append(closed_loop(StateSpacePlant(model), mpc, KalmanObserver(model), reference, output_noise=noise,
                                record_state=lambda plant: plant.state))
    clean, noisy = runs
    noisy.save(tmp_path / "loop.h5", metadata={"controller": mpc.describe()})
    loaded = ClosedLoopResult.load(tmp_path / "loop.h5")
    for name in ("outputs", "inputs", "reference", "estimates", "qp_seconds", "plant_states"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(noisy, name))
    assert loaded.statuses == noisy.statuses and loaded.metrics() == noisy.metrics()
    # the recorded outputs are the plant's own, C z + D u, to round-off
    exact = model.C @ noisy.plant_states + model.D @ noisy.inputs
    assert np.max(np.abs(noisy.outputs - exact)) <= 1e-12 * np.max(np.abs(exact))
    # the noise moved the estimates and hence the inputs, and the tracking got worse
    assert np.max(np.abs(noisy.estimates - clean.estimates)) > 1e-3 * np.max(np.abs(clean.estimates))
    assert noisy.tracking_error() > clean.tracking_error()


def test_an_lopinf_rom_learned_from_fom_snapshots_controls_the_fom():
    """The issue's chain in small: FOM snapshots of a random multisine, a mass-orthonormal POD
    basis, L-OpInf (nonintrusive), its Newmark state space, MPC and Kalman observer, closed loop on
    the FOM against a feasible reference the training never saw (2-3 Hz sines from rest)."""
    import dataclasses

    from femrom.basis import POD
    from femrom.inference import LagrangianOpInf, reduce_snapshots
    from femrom.integrators import Trajectory, integrate

    system = chain(n=12, p=4)
    rng = np.random.default_rng(5)
    frequencies, phases = rng.uniform(0.3, 6.0, (2, 6)), rng.uniform(0, 2 * np.pi, (2, 6))

    def training_input(t):
        return 0.025 * np.sum(np.sin(2 * np.pi * frequencies * t + phases), axis=1)

    trajectory = Trajectory()
    integrate(dataclasses.replace(system, inputs=training_input), Newmark(), np.zeros(12), np.zeros(12), DT, 600,
              consumers=[trajectory], progress=False)
    Q = trajectory.q
    inputs = np.column_stack([training_input(t) for t in trajectory.t])
    basis = POD(rank=6, product=system.mass).fit(Q).basis_
    data = reduce_snapshots(basis, Q, DT, product=system.mass, velocities=trajectory.v,
                            accelerations=trajectory.a, derivatives="stored", inputs=inputs,
                            outputs=system.output_matrix @ Q)
    rom = SecondOrderROM(basis=basis, product=system.mass, learner=LagrangianOpInf.for_system(system)).fit(data)
    model = rom.to_state_space(DT)
    U = sines(231, amplitude=0.04)
    reference = open_loop(FullOrderPlant(system, DT), U)
    rms = np.sqrt(np.mean(reference ** 2))
    mpc = LinearMPC(model, horizon=30, output_weight=1 / rms ** 2, input_weight=0.0,
                    input_rate_weight=1e-4 / 0.01, input_bound=0.1)
    result = closed_loop(FullOrderPlant(system, DT), mpc, KalmanObserver(model, disturbance="output"), reference)
    open_error = np.sqrt(np.mean((open_loop(StateSpacePlant(model), U) - reference) ** 2)) / rms
    # measured: the ROM predicts the reference open loop to 2.3 %, the closed loop tracks it to 0.9 %;
    # the target is 10 %, and feedback must beat the open-loop prediction
    assert result.tracking_error() < min(0.1, 0.7 * open_error)
    assert result.max_constraint_violation() <= 1e-6 * 1.1


def test_the_observer_gives_the_models_own_state_back():
    """Newmark's state space carries z = [q; v] - E u; model_state(u) = z + E u is [q; v] again.
    Against the FOM with the identity basis the filtered estimate converges to the FOM's q, v."""
    system = chain()
    model = exact_model(system)
    U = sines(91, amplitude=0.02)
    reference = open_loop(StateSpacePlant(model), U)
    rms = np.sqrt(np.mean(reference ** 2))
    observer = KalmanObserver(model, initial_state=np.full(16, rms))
    mpc = LinearMPC(model, horizon=20, output_weight=1 / rms ** 2, input_weight=1e-3 / 0.01, input_bound=0.1)
    plant = FullOrderPlant(system, DT)
    result = closed_loop(plant, mpc, observer, reference,
                         record_state=lambda plant: np.concatenate([plant.last.q, plant.last.v]))
    estimated = result.estimates + model.input_offset @ result.inputs
    error = np.linalg.norm(estimated - result.plant_states, axis=0)
    # the filter's error decays like rho^k (rho = 0.97): measured 0.012 of the start after 70 steps;
    # the estimate taken for [q; v] without the input offset stays 0.34 off
    assert error[-1] < 0.05 * error[0]
    # and the last one is observer.model_state(u) of the last input
    np.testing.assert_allclose(observer.model_state(result.inputs[:, -1]), estimated[:, -1], rtol=1e-14, atol=0)


def test_travelling_wave_reference():
    x = np.linspace(0.0, 1.0, 5)
    t = np.array([0.0, 0.25])
    Y = travelling_wave(x, t, lambda x: 0.1 * x, wavenumber=2 * np.pi, angular_frequency=2 * np.pi)
    assert Y.shape == (5, 2)
    np.testing.assert_allclose(Y[:, 0], 0.1 * x * np.sin(2 * np.pi * x), atol=1e-15)
    # a quarter period later the wave has moved a quarter wavelength towards larger x
    np.testing.assert_allclose(Y[:, 1], 0.1 * x * np.sin(2 * np.pi * x - np.pi / 2), atol=1e-15)


# -- failures and bad input ------------------------------------------------------------------

def test_an_inaccurate_solve_is_a_failure_under_raise(monkeypatch):
    """A solve the solver flags as inaccurate (OSQP stopped short of its tolerance) is applied under
    "shift" and "hold", and raises under "raise" (its move had been applied, up to 60 % off the optimum)."""
    from femrom.control._formulation import QPSolution

    model = exact_model(chain())
    window = 1e-4 * np.ones((3, 10))
    for policy in ("shift", "raise"):
        mpc = LinearMPC(model, horizon=10, output_weight=1e8, input_weight=1.0, input_bound=0.1, on_failure=policy)
        exact = mpc.formulation.solve
        monkeypatch.setattr(mpc.formulation, "solve", lambda: QPSolution("optimal_inaccurate", exact().plan, 0.0, 1))
        if policy == "raise":
            with pytest.raises(MPCError, match="status 'optimal_inaccurate'"):
                mpc.control(np.zeros(16), window)
            continue
        u = mpc.control(np.zeros(16), window)
        assert np.all(np.isfinite(u)) and mpc.n_fallbacks == 0 and mpc.statuses == ["optimal_inaccurate"]


def test_failed_solves_follow_the_stated_policy(monkeypatch):
    """A solver that raises (cvxpy) and one that stops at its iteration limit (OSQP directly):
    "shift" applies the next input of the last plan, "hold" the previous input, "raise" raises."""
    import cvxpy

    model = exact_model(chain())
    window = 1e-4 * np.ones((3, 10))

    def failing(mpc, formulation):
        if formulation == "condensed":
            def solve(**options):
                raise cvxpy.error.SolverError("boom")
            monkeypatch.setattr(mpc.formulation.problem, "solve", solve)
            return "error"
        mpc.formulation.solver.update_settings(max_iter=1)    # stops before converging
        return "user_limit"

    for formulation in ("condensed", "condensed_osqp"):
        for policy in ("shift", "hold", "raise"):
            mpc = LinearMPC(model, horizon=10, output_weight=1e8, input_weight=1.0, input_bound=0.1,
                            formulation=formulation, on_failure=policy)
            first = mpc.control(np.zeros(16), window)
            plan = mpc.plan_.copy()
            status = failing(mpc, formulation)
            if policy == "raise":
                with pytest.raises(MPCError, match=f"status '{status}'"):
                    mpc.control(np.zeros(16), 0.5 * window, first)
                continue
            with pytest.warns(MPCWarning, match="QP solve failed"):
                u = mpc.control(np.zeros(16), 0.5 * window, first)
            expected = plan[:, 1] if policy == "shift" else first
            np.testing.assert_array_equal(u, expected)
            assert mpc.n_fallbacks == 1 and mpc.statuses[-1] == status and np.all(np.isfinite(u))


def test_bad_input_gives_one_clear_error():
    model = exact_model(chain())
    mpc = LinearMPC(model, horizon=10, output_weight=1.0, input_weight=1.0)
    with pytest.raises(ValueError, match=r"reference has shape \(4, 10\), expected \(3, 10\)"):
        mpc.control(np.zeros(16), np.zeros((4, 10)))
    with pytest.raises(ValueError, match="state has 15 entries, expected 16"):
        mpc.control(np.zeros(15), np.zeros((3, 10)))
    with pytest.raises(ValueError, match="input_bound has shape \\(3,\\)"):
        LinearMPC(model, input_weight=1.0, input_bound=[0.1, 0.1, 0.1])
    with pytest.raises(ValueError, match="input_weight or input_rate_weight must be positive definite"):
        LinearMPC(model, input_weight=0.0)
    with pytest.raises(ValueError, match="output_weight is not positive semidefinite"):
        LinearMPC(model, output_weight=-np.eye(3), input_weight=1.0)
    with pytest.raises(ValueError, match="unknown QP formulation 'dense'"):
        LinearMPC(model, input_weight=1.0, formulation="dense")
    with pytest.raises(ValueError, match="horizon must be a positive integer"):
        LinearMPC(model, horizon=0, input_weight=1.0)
    with pytest.raises(ValueError, match="terminal_weight='dare'.*without feedthrough"):
        LinearMPC(model, input_weight=1.0, terminal_weight="dare")
    # a ROM with a constant load exports it as a last input fixed at 1 (to_state_space's metadata)
    loaded = DiscreteStateSpace(model.A, model.B, model.C, model.D, dt=DT, metadata={"constant_input": True})
    with pytest.raises(ValueError, match="constant input channel"):
        LinearMPC(loaded, input_weight=1.0)
    observer = KalmanObserver(model)
    with pytest.raises(ValueError, match="output has 2 entries, expected 3"):
        observer.update(np.zeros(2), np.zeros(2))
    other = exact_model(chain(p=2))
    with pytest.raises(ValueError, match="observer's model has"):
        closed_loop(StateSpacePlant(model), mpc, KalmanObserver(other), np.zeros((3, 40)))
    with pytest.raises(ValueError, match="reference has shape \\(2, 40\\), expected \\(3, K\\)"):
        closed_loop(StateSpacePlant(model), mpc, observer, np.zeros((2, 40)))
    with pytest.raises(ValueError, match="system needs inputs and outputs"):
        FullOrderPlant(SecondOrderSystem(mass=sp.identity(2, format="csr"), stiffness=sp.identity(2, format="csr")), DT)


def test_a_formulation_written_outside_the_package_registers_and_is_checked_for_dpp():
    import cvxpy as cp

    from femrom.control import QP_FORMULATIONS, CvxpyFormulation, register_formulation

    @register_formulation
    class ProductOfParameters(CvxpyFormulation):
        """Not DPP: a product of two Parameters multiplies the variable."""

        name = "product_of_parameters"

        def __init__(self, problem, config):
            super().__init__(problem, config)
            a, b, x = cp.Parameter(), cp.Parameter(), cp.Variable()
            self.problem = cp.Problem(cp.Minimize(cp.square(x) + a * b * x))
            self.compiled()

    try:
        assert "product_of_parameters" in registered_formulations()
        with pytest.raises(RuntimeError, match="'product_of_parameters' is not DPP"):
            LinearMPC(exact_model(chain()), input_weight=1.0, formulation="product_of_parameters")
    finally:
        QP_FORMULATIONS.remove("product_of_parameters")


def test_the_qp_solver_is_an_object_and_the_old_names_still_work_for_one_release():
    model = exact_model(chain())
    mpc = LinearMPC(model, horizon=5, input_weight=1.0, solver=QPSolver("CLARABEL", tolerance=1e-9))
    assert mpc.config.solver == QPSolver("clarabel", tolerance=1e-9)
    assert mpc.config.formulation_name == "condensed"
    described = mpc.describe()
    assert (described["solver"], described["tolerance"], described["max_iterations"],
            described["solver_options"]) == ("CLARABEL", 1e-9, 10_000, {})
    with pytest.warns(DeprecationWarning, match="QPSolver"):
        old = LinearMPC(model, horizon=5, input_weight=1.0, solver="CLARABEL", tolerance=1e-9)
    assert old.config.solver == mpc.config.solver
    with pytest.raises(TypeError, match="solver must be a QPSolver"):
        MPCConfig(solver="OSQP")
    with pytest.raises(ValueError, match="OSQP only"):
        LinearMPC(model, horizon=5, input_weight=1.0, formulation="condensed_osqp", solver=QPSolver("clarabel"))
