"""Blows on small stateful models and what is read from them (femrom.study.with_impulse, output_ring_down,
ecsw_training; femrom.post.static_qsma, linear_accelerance), against independent computations."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.integrate import solve_ivp

from femrom.fem import JenkinsForce
from femrom.post import linear_accelerance, masing_damping, static_qsma
from femrom.scene import SecondOrderSystem, Signal, SignalVector
from femrom.study import ecsw_training, output_ring_down, reference_ring_down, step_cost, stepped_sine_response, \
    with_impulse

M = np.diag([1.0, 2.0])
K = np.array([[3.0, -1.0], [-1.0, 1.0]])
K_T, F_S = 0.5, 0.1                       # a Jenkins element on dof 0: stick stiffness, slip force
E1 = np.array([1.0, 0.0])


def two_dofs(*, jenkins=True, damping=0.0) -> SecondOrderSystem:
    """``M q'' + C q' + K q + f_J(q_1) = B u``, two inputs (one per dof), outputs ``q_1, q_2``."""
    shaker = Signal.from_dict({"kind": "sine", "amplitude": 0.0, "frequency": 1.0})
    return SecondOrderSystem(mass=sp.csr_matrix(M), stiffness=sp.csr_matrix(K),
                             damping=sp.csr_matrix(damping * (K + K_T * np.outer(E1, E1))),
                             input_matrix=np.eye(2), inputs=SignalVector([shaker, shaker]),
                             output_matrix=sp.csr_matrix(np.eye(2)), output_names=("q1", "q2"),
                             nonlinear=JenkinsForce(K_T, F_S, 2, dofs=[0]) if jenkins else None)


def test_a_blow_replaces_one_input_by_a_half_sine():
    system = with_impulse(two_dofs(), 3.0, 0.2, input=1)
    t = np.linspace(0.0, 0.5, 51)
    u = np.asarray(system.inputs.sampled(t))
    np.testing.assert_allclose(u[1], np.where(t <= 0.2, 3.0 * np.sin(np.pi * np.minimum(t, 0.2) / 0.2), 0.0),
                               atol=1e-12)
    np.testing.assert_array_equal(u[0], 0.0)             # the other input kept (a silent sine)


def test_the_ring_down_of_a_linear_model_follows_an_independent_integration():
    # the stuck model is linear: q'' = M^-1 (u e_1 - (K + k_t e1 e1^T) q - C q'), integrated by an
    # adaptive Runge-Kutta to 1e-11; Newmark at 400 steps per period of the highest mode: 1e-4
    system = with_impulse(two_dofs(jenkins=False, damping=0.01), 2.0, 0.05)
    stuck = K + K_T * np.outer(E1, E1)
    system = SecondOrderSystem(mass=system.mass, stiffness=sp.csr_matrix(stuck), damping=system.damping,
                               input_matrix=system.input_matrix, inputs=system.inputs,
                               output_matrix=system.output_matrix, output_names=system.output_names)
    omega_max = np.sqrt(np.max(np.linalg.eigvals(np.linalg.solve(M, stuck)).real))
    dt = 2 * np.pi / omega_max / 400
    run = output_ring_down(system, None, 3.0, dt)
    C = system.damping.toarray()

    def rhs(t, y):
        u = 2.0 * np.sin(np.pi * t / 0.05) if t <= 0.05 else 0.0
        q, v = y[:2], y[2:]
        return np.concatenate([v, np.linalg.solve(M, u * E1 - stuck @ q - C @ v)])

    n = run.accelerations.shape[1]
    times = dt * np.arange(1, n + 1)
    exact = solve_ivp(rhs, (0.0, times[-1]), np.zeros(4), t_eval=times, rtol=1e-11, atol=1e-13, max_step=0.01)
    acceleration = np.array([rhs(t, y)[2:] for t, y in zip(exact.t, exact.y.T)]).T
    assert run.accelerations.shape == (2, int(round(3.0 / dt)))
    late = times > 0.1                                # after the blow (its kink is resolved to O(dt))
    error = np.max(np.abs(run.accelerations[:, late] - acceleration[:, late])) / np.max(np.abs(acceleration))
    assert error < 1e-3


def test_kept_states_and_training_snapshots_are_the_ring_downs_own():
    system = with_impulse(two_dofs(damping=0.02), 20.0, 0.05)      # slips the element (at q_1 = 0.2)
    z0, dt = system.nonlinear.initial_state(), 0.01
    full = reference_ring_down(system, z0, 1.0, dt)
    run = output_ring_down(system, z0, 1.0, dt, keep_every=4)
    # the same Newmark run: accelerations at steps 1..k, the rest state (t = 0) not listed
    np.testing.assert_allclose(run.accelerations, full.outputs[:, 1:], rtol=1e-12, atol=1e-15)
    steps = np.arange(4, 101, 4)
    assert len(run.snapshots) == steps.size
    np.testing.assert_allclose(np.array([q for q, _ in run.snapshots]).T, full.q[:, steps], rtol=1e-12, atol=1e-15)
    # the blow slips the Jenkins element: its committed slider moves
    assert np.abs(run.snapshots[-1][1]).max() > 0.01
    training = ecsw_training(system, z0, (5.0, 20.0), width=0.05, window=0.4, dt=dt)
    assert list(training.runs) == [5.0, 20.0]
    assert len(training.snapshots) == 2 * 10
    np.testing.assert_array_equal(training.runs[20.0].accelerations, run.accelerations[:, :40])


def test_qsma_along_the_loading_path_of_a_jenkins_element():
    # the closed form of tests/test_qsma.py: stuck while k_t |q_1| <= F_s, then slipping at F_s
    system = two_dofs()
    stuck = K + K_T * np.outer(E1, E1)
    w2, V = np.linalg.eigh(np.linalg.solve(np.sqrt(M), np.linalg.solve(np.sqrt(M), stuck).T))
    phi = np.linalg.solve(np.sqrt(M), V[:, 0])            # mass-normalised first mode of the stuck model
    amplitudes = np.geomspace(0.01, 1.0, 12)              # output 0's acceleration amplitudes
    result = static_qsma(system, amplitudes, reference=np.zeros(2), state=None, mode=phi, output=0)
    alphas = amplitudes / abs(phi[0])

    def solve(F):
        q = np.linalg.solve(stuck, F)
        return q if K_T * abs(q[0]) <= F_S else np.linalg.solve(K, F - np.sign(q[0]) * F_S * E1)

    a = np.array([phi @ M @ solve(alpha * M @ phi) for alpha in alphas])
    omega, _, zeta = masing_damping(a, alphas)
    np.testing.assert_allclose(result.modal_amplitude, a, rtol=1e-9)
    np.testing.assert_allclose(result.frequency_hz, omega / (2 * np.pi), rtol=1e-9)
    np.testing.assert_allclose(result.damping_ratio, zeta, rtol=1e-7, atol=1e-12)
    backbone = result.backbone(0)
    stuck_loads = K_T * np.abs([solve(alpha * M @ phi)[0] for alpha in alphas]) <= F_S
    assert 2 < stuck_loads.sum() < 12                      # both regimes sampled
    # while stuck the model is linear: output 0 reaches the amplitude its load was set for
    np.testing.assert_allclose(backbone.amplitude[stuck_loads], amplitudes[stuck_loads], rtol=1e-9)
    assert np.all(backbone.damping_ratio[~stuck_loads] > 0)


def test_the_stuck_accelerance_is_the_modal_sum():
    # C = c K_t (proportional): modal damping zeta_j = c w_j / 2,
    # H = sum_j w^2 (E phi_j)(phi_j^T f) / (w_j^2 - w^2 + i 2 zeta_j w_j w)
    c = 0.01
    system = two_dofs(damping=c)
    stuck = K + K_T * np.outer(E1, E1)
    w2, V = np.linalg.eigh(np.linalg.solve(np.sqrt(M), np.linalg.solve(np.sqrt(M), stuck).T))
    Phi = np.linalg.solve(np.sqrt(M), V)
    force = np.array([0.0, 1.0])
    frequencies = np.array([0.05, 0.15, 0.3])
    H = linear_accelerance(system, system.nonlinear.initial_state(), force, frequencies)
    expected = []
    for f in frequencies:
        w = 2 * np.pi * f
        terms = [w * w * np.outer(Phi[:, j], Phi[:, j]) @ force / (w2[j] - w * w + 1j * c * w2[j] * w)
                 for j in range(2)]
        expected.append(np.abs(sum(terms)))
    np.testing.assert_allclose(H, np.column_stack(expected), rtol=1e-10)


def test_a_stuck_joints_stepped_sine_is_its_linear_response():
    # at 1e-3 N the Jenkins element never slips (k_t |q_1| << F_s): the steady state is the stuck
    # model's, F |H(f)|, to the steady-state tolerance; at 3 N it slips and the response departs
    system = two_dofs(damping=0.1)
    z0 = system.nonlinear.initial_state()
    frequencies = (0.15, 0.25)
    result, rows = stepped_sine_response(system, z0, 1, frequencies, (1e-3, 3.0), steps_per_period=32,
                                         tolerance=1e-3, linear_key="linear")
    small, large = rows
    for name in ("q1", "q2"):
        for point in small["outputs"][name]:
            assert point["amplitude_m_s2"] == pytest.approx(point["linear"], rel=1e-2)
    assert small["outputs"]["q1"][0]["linear"] * 3e3 == pytest.approx(large["outputs"]["q1"][0]["linear"], rel=1e-12)
    assert max(abs(p["amplitude_m_s2"] / p["linear"] - 1) for p in large["outputs"]["q1"]) > 0.05
    assert len(result.levels) == 2


def test_the_stepped_sine_response_with_its_levels_batched_is_the_same():
    # this joint has no compiled step: the batch steps each level by the scheme's step, the same numbers
    system = two_dofs(damping=0.1)
    z0 = system.nonlinear.initial_state()
    args = (system, z0, 1, (0.15, 0.25), (1e-3, 3.0))
    _, rows = stepped_sine_response(*args, steps_per_period=32, tolerance=1e-3)
    _, batched = stepped_sine_response(*args, steps_per_period=32, tolerance=1e-3, batched=True)
    assert batched == rows


def test_the_step_cost_leaves_the_first_step_out():
    system = with_impulse(two_dofs(damping=0.02), 20.0, 0.05)
    cost = step_cost(system, np.zeros(2), system.nonlinear.initial_state(), 0.01, 50)
    assert (cost["n_dofs"], cost["steps"]) == (2, 50)
    assert 0 < 49 * cost["seconds_per_step"] <= cost["seconds_total"]
    assert cost["newton_iterations"] >= 50
