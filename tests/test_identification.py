"""Identified first-order models (DMDc, ERA, OKID): exact recovery, independent oracles, rates, errors, files.

The oracles are independent implementations used only here: PyDMD's ``DMDc``,
python-control's ``eigensys_realization`` and ``markov``.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linear_sum_assignment

from _required import extra
from femrom.inference import (
    DMDc,
    ERA,
    InputOutputData,
    MarkovParameters,
    OKID,
    SecondOrderData,
    StateSpaceOperators,
    block_hankel,
    impulse_response,
    markov_parameters,
    okid_markov_parameters,
    registered_learners,
    system_impulse_response,
)
from femrom.integrators import Newmark, iterate
from femrom.rom import DiscreteStateSpace, SecondOrderROM, StateSpaceROM
from femrom.scene import SecondOrderSystem

DT = 0.01


def random_system(n: int, m: int, p: int, radius: float, seed: int):
    """A random (A, B, C, D) whose A has spectral radius ``radius``."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    A *= radius / np.max(np.abs(np.linalg.eigvals(A)))
    return A, rng.standard_normal((n, m)), rng.standard_normal((p, n)), rng.standard_normal((p, m))


def simulate(A, B, C, D, U, x0=None):
    """(Y, X) of x+ = A x + B u, y = C x + D u."""
    X = np.zeros((A.shape[0], U.shape[1]))
    if x0 is not None:
        X[:, 0] = x0
    for k in range(U.shape[1] - 1):
        X[:, k + 1] = A @ X[:, k] + B @ U[:, k]
    return C @ X + D @ U, X


def eigenvalue_mismatch(computed, reference) -> float:
    """max |lambda_i - mu_pi(i)| / max |mu| over the best pairing (conjugate pairs need no sorting luck)."""
    cost = np.abs(np.subtract.outer(np.asarray(computed), np.asarray(reference)))
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].max() / np.max(np.abs(reference)))


# -- the data containers ------------------------------------------------------------------

def test_input_output_data_rejects_bad_input_with_one_line_errors():
    U, Y = np.zeros((2, 10)), np.zeros((3, 10))
    with pytest.raises(ValueError, match="inputs is not finite at index"):
        InputOutputData(np.where(np.arange(10) == 4, np.nan, 0.0)[None], Y, DT)
    with pytest.raises(ValueError, match="outputs have 9 columns, inputs have 10"):
        InputOutputData(U, Y[:, :9], DT)
    with pytest.raises(ValueError, match="dt must be a positive number"):
        InputOutputData(U, Y, 0.0)
    with pytest.raises(ValueError, match="trajectory 1 has fewer than 2 samples"):
        InputOutputData(U, Y, DT, starts=(0, 9))
    with pytest.raises(ValueError, match="starts must begin at 0"):
        InputOutputData(U, Y, DT, starts=(1,))
    with pytest.raises(ValueError, match="states must be real numbers"):
        InputOutputData(U, Y, DT, states=np.zeros((2, 10), dtype=complex))
    with pytest.raises(ValueError, match="Markov parameters must be"):
        MarkovParameters(np.zeros((1, 2, 2)))


def test_input_output_data_from_second_order_data_keeps_trajectories_and_step():
    rng = np.random.default_rng(0)
    Q, V, Acc = (rng.standard_normal((3, 12)) for _ in range(3))
    data = SecondOrderData(states=Q, velocities=V, accelerations=Acc, inputs=rng.standard_normal((2, 12)),
                           outputs=rng.standard_normal((4, 12)), starts=(0, 5), diagnostics={"dt": 0.02})
    io = InputOutputData.from_second_order(data)
    np.testing.assert_array_equal(io.states, np.vstack([Q, V]))        # [q^; q^'], the first-order state
    assert io.starts == (0, 5) and io.dt == 0.02 and io.n_outputs == 4
    np.testing.assert_array_equal(io.step_pairs(), np.r_[0:4, 5:11])   # no pair across the start at 5
    assert InputOutputData.from_second_order(data, states="displacement").n_states == 3
    assert InputOutputData.from_second_order(data, states="none").states is None
    with pytest.raises(ValueError, match="unknown state layout 'velocity'"):
        InputOutputData.from_second_order(data, states="velocity")
    with pytest.raises(ValueError, match="no inputs"):
        InputOutputData.from_second_order(SecondOrderData(states=Q, velocities=V, accelerations=Acc))


def test_learners_are_registered_as_state_space_learners():
    learners = registered_learners()
    for name, cls in (("dmdc", DMDc), ("era", ERA), ("okid", OKID)):
        assert learners[name] is cls and cls.model == "state_space"


# -- DMDc ---------------------------------------------------------------------------------

def test_dmdc_recovers_the_system_from_noise_free_data():
    A, B, C, D = random_system(6, 2, 3, 0.95, seed=1)
    rng = np.random.default_rng(2)
    U = rng.standard_normal((2, 200))
    Y, X = simulate(A, B, C, D, U, rng.standard_normal(6))
    learner = DMDc(feedthrough=True).fit(InputOutputData(U, Y, DT, states=X))
    ops = learner.operators_
    # full ranks (p = n + m, r = n): least squares on exact data; only round-off remains
    # (eigenvalue condition numbers of a random 6 x 6 A are O(10): 1e-11 leaves a margin)
    assert eigenvalue_mismatch(ops.eigenvalues(), np.linalg.eigvals(A)) < 1e-11
    Ur = ops.state_basis
    np.testing.assert_allclose(Ur @ ops.A @ Ur.T, A, atol=1e-11)
    np.testing.assert_allclose(Ur @ ops.B, B, atol=1e-11)
    truth = markov_parameters(StateSpaceOperators(A, B, C, D, DT), 30)
    assert ops.markov_parameters(30).relative_error(truth) < 1e-11
    assert learner.residual_ < 1e-13 and learner.describe()["spectral_radius"] == pytest.approx(0.95, abs=1e-12)


def test_dmdc_agrees_with_pydmd_with_truncated_ranks():
    pydmd = extra("pydmd")
    A, B, C, D = random_system(12, 2, 3, 0.9, seed=3)
    rng = np.random.default_rng(4)
    U = rng.standard_normal((2, 150))
    _, X = simulate(A, B, C, D, U, rng.standard_normal(12))
    X = X + 1e-2 * rng.standard_normal(X.shape)         # noise: truncation changes the answer
    p, r = 9, 6
    ours = DMDc(rank=p, output_rank=r).fit(InputOutputData(U, None, DT, states=X)).operators_
    theirs = pydmd.DMDc(svd_rank=r, svd_rank_omega=p).fit(X, U[:, :-1])
    # the same algorithm (Proctor et al. 2016) in two codes: agreement to round-off of
    # two SVDs of a 14 x 149 matrix (singular-value gaps O(1e-2): 1e-9 leaves a margin)
    assert eigenvalue_mismatch(ours.eigenvalues(), theirs.eigs) < 1e-9
    Ur = ours.state_basis
    one_step = Ur @ (ours.A @ Ur.T @ X[:, :-1] + ours.B @ U[:, :-1])
    basis = np.real(theirs.basis)
    reference = basis @ np.real(theirs.operator.as_numpy_array) @ basis.T @ X[:, :-1] + np.real(theirs.B) @ U[:, :-1]
    assert np.linalg.norm(one_step - reference) / np.linalg.norm(reference) < 1e-10
    # lower side: the truncation is in effect (full ranks give a different model)
    full = DMDc().fit(InputOutputData(U, None, DT, states=X)).operators_
    Uf = full.state_basis
    untruncated = Uf @ (full.A @ Uf.T @ X[:, :-1] + full.B @ U[:, :-1])
    assert np.linalg.norm(one_step - untruncated) / np.linalg.norm(untruncated) > 1e-2


def test_dmdc_never_pairs_columns_across_trajectories():
    A, B, C, D = random_system(4, 1, 2, 0.9, seed=5)
    rng = np.random.default_rng(6)
    parts = []
    for seed in range(2):
        U = rng.standard_normal((1, 40))
        parts.append((U, *simulate(A, B, C, D, U, rng.standard_normal(4))))
    U = np.hstack([p[0] for p in parts])
    Y = np.hstack([p[1] for p in parts])
    X = np.hstack([p[2] for p in parts])
    right = DMDc().fit(InputOutputData(U, Y, DT, states=X, starts=(0, 40)))
    wrong = DMDc().fit(InputOutputData(U, Y, DT, states=X))
    assert right.residual_ < 1e-13                       # exact data, exact fit
    assert wrong.residual_ > 1e-3                        # one false pair (39 -> 40) spoils it


def test_dmdc_errors_name_the_culprit():
    rng = np.random.default_rng(7)
    data = InputOutputData(rng.standard_normal((2, 20)), None, DT, states=rng.standard_normal((3, 20)))
    with pytest.raises(ValueError, match="rank must be an integer between 1 and 5"):
        DMDc(rank=6).fit(data)
    with pytest.raises(ValueError, match="output_rank must be an integer between 1 and 2"):
        DMDc(rank=4, output_rank=4).fit(InputOutputData(data.inputs, None, DT, states=data.states[:2]))
    short = InputOutputData(data.inputs[:, :4], None, DT, states=data.states[:, :4])
    with pytest.raises(ValueError, match=r"\(\[X; U\] has 5 rows and 3 step pairs\)"):
        DMDc(rank=5).fit(short)
    with pytest.raises(ValueError, match="output_rank 4 exceeds rank 3"):
        DMDc(rank=3, output_rank=4)
    with pytest.raises(ValueError, match="no states"):
        DMDc().fit(InputOutputData(data.inputs, None, DT))
    with pytest.raises(TypeError, match="takes InputOutputData"):
        DMDc().fit(data.inputs)
    collinear = InputOutputData(np.vstack([data.inputs[:1], data.inputs[:1]]), None, DT, states=data.states)
    with pytest.raises(ValueError, match="exceeds the numerical rank 4 of"):
        DMDc(rank=5).fit(collinear)


# -- ERA ----------------------------------------------------------------------------------

def test_era_realises_the_markov_parameters_of_a_known_mimo_system_like_python_control():
    control = extra("control")
    A, B, C, D = random_system(6, 3, 4, 0.9, seed=8)
    truth = markov_parameters(StateSpaceOperators(A, B, C, D, DT), 41)
    learner = ERA(6, rows=20, columns=20).fit(truth)
    ops = learner.operators_
    # exact Markov parameters of an order-6 system: the realisation is exact up to round-off,
    # also beyond the 41 parameters it saw (Y_41 ... Y_79: 0.9^79 ~ 2e-4 of Y_1, still resolved)
    longer = markov_parameters(StateSpaceOperators(A, B, C, D, DT), 80)
    assert ops.markov_parameters(80).relative_error(longer) < 1e-11
    assert eigenvalue_mismatch(ops.eigenvalues(), np.linalg.eigvals(A)) < 1e-10
    np.testing.assert_array_equal(ops.D, D)
    # python-control's ERA on the same (p, m, N) array with the same Hankel sizes
    theirs, singular_values = control.eigensys_realization(np.moveaxis(truth.parameters, 0, -1), 6, m=20, n=20)
    np.testing.assert_allclose(learner.hankel_singular_values_[:6], singular_values[:6], rtol=1e-12)
    assert markov_parameters(theirs, 80).relative_error(ops.markov_parameters(80)) < 1e-11
    # lower side: one order too few leaves a visible Markov error
    assert ERA(5, rows=20, columns=20).fit(truth).markov_error_ > 1e-3


def test_era_tangential_outputs_realise_forty_channels_through_few_directions():
    A, B, C, D = random_system(6, 6, 40, 0.9, seed=9)     # 6 x 40, the robot's channel count
    truth = markov_parameters(StateSpaceOperators(A, B, C, D, DT), 31)
    full = ERA(6).fit(truth)
    tangential = ERA(6, output_directions=6).fit(truth)
    # rank C = 6: six output directions hold every Markov parameter exactly
    assert full.markov_error_ < 1e-11 and tangential.markov_error_ < 1e-11
    assert full.describe()["hankel_shape"] == [15 * 40, 15 * 6]
    assert tangential.describe()["hankel_shape"] == [15 * 6, 15 * 6]
    # lower side: fewer directions than rank C lose part of the response
    assert ERA(6, output_directions=3).fit(truth).markov_error_ > 1e-2


def test_block_hankel_layout():
    Y = np.arange(6 * 2 * 1, dtype=float).reshape(6, 2, 1)   # Y_k = [[2k], [2k + 1]]
    H = block_hankel(Y, rows=2, columns=3, shift=1)
    np.testing.assert_array_equal(H, [[4, 6, 8], [5, 7, 9], [6, 8, 10], [7, 9, 11]])


def test_era_errors_name_the_culprit():
    A, B, C, D = random_system(4, 2, 2, 0.8, seed=10)
    truth = markov_parameters(StateSpaceOperators(A, B, C, D, DT), 21)
    with pytest.raises(ValueError, match="order 5 exceeds the numerical rank 4"):
        ERA(5).fit(truth)
    with pytest.raises(ValueError, match="needs 22 Markov parameters"):
        ERA(2, rows=11, columns=10).fit(truth)
    with pytest.raises(ValueError, match="order 30 exceeds the size of the"):
        ERA(30).fit(truth)
    with pytest.raises(TypeError, match="use OKID"):
        ERA(2).fit(InputOutputData(np.zeros((2, 5)), np.zeros((2, 5)), DT))
    with pytest.raises(ValueError, match="order must be a positive integer"):
        ERA(0)
    with pytest.raises(ValueError, match="Markov parameters is not finite"):
        MarkovParameters(np.where(truth.parameters > 0, np.nan, 0.0))


# -- full-order (Newmark) systems: impulse responses and runs ------------------------------

def small_structure(n: int = 3):
    """A damped chain of n masses, 2 force inputs, 2 displacement outputs (order 2 n)."""
    K = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr") * 400.0
    M = sp.diags(np.linspace(1.0, 1.5, n), format="csr")
    B = np.zeros((n, 2))
    B[0, 0] = B[-1, 1] = 1.0
    E = sp.csr_matrix(np.eye(n)[[0, n - 1]])
    return SecondOrderSystem(mass=M, stiffness=K, damping=(0.5 * M + 1e-3 * K).tocsr(), input_matrix=B,
                             inputs=lambda t: np.zeros(2), output_matrix=E)


def test_impulse_responses_of_the_full_order_system_and_its_state_space_agree():
    system = small_structure()
    dt, count = 0.02, 40
    fom = system_impulse_response(system, dt, count)
    # the Galerkin ROM with the identity basis is the FOM; its Newmark state space (shifted
    # state z = x - E u, D = C E) has the Markov parameters of the sampled impulse response
    state_space = SecondOrderROM.galerkin(system, np.eye(3)).to_state_space(dt)
    exact = markov_parameters(state_space, count)
    assert fom.relative_error(exact) < 1e-12
    assert np.linalg.norm(exact.feedthrough) > 1e-6        # Newmark's end-of-step input: D != 0
    stepped = impulse_response(lambda: state_space.stepper(initial=np.zeros(6)), 2, count, dt=dt)
    assert stepped.relative_error(exact) < 1e-13
    # and ERA of order 2n = 6 realises them: the poles of Newmark's step map
    ops = ERA(6).fit(fom).operators_
    assert eigenvalue_mismatch(ops.eigenvalues(), state_space.poles()) < 1e-9


def newmark_run(system, dt, K, seed):
    """(inputs, [q; v], outputs) of a Newmark run from rest under random input samples (u_0 = 0)."""
    rng = np.random.default_rng(seed)
    samples = np.hstack([np.zeros((2, 1)), rng.standard_normal((2, K - 1))])
    driven = dataclasses.replace(system, inputs=lambda t: np.array(
        [np.interp(t, dt * np.arange(K), row) for row in samples]))
    results = list(iterate(driven, Newmark(), np.zeros(3), np.zeros(3), dt, K - 1, progress=False))
    Q, V = np.column_stack([r.q for r in results]), np.column_stack([r.v for r in results])
    return samples, np.vstack([Q, V]), np.asarray(system.output_matrix @ Q)


def test_dmdc_with_both_input_samples_recovers_the_newmark_state_space(tmp_path):
    system = small_structure()
    dt = 0.02
    U, X, Y = newmark_run(system, dt, 300, seed=19)
    exact = markov_parameters(SecondOrderROM.galerkin(system, np.eye(3)).to_state_space(dt), 100)
    both = DMDc(input_samples="both").fit(InputOutputData(U, Y, dt, states=X))
    # Newmark's [q; v] obey x+ = A x + B_0 u_k + B_1 u_k+1 exactly: with both samples DMDc is
    # exact, D = C B_1 included (round-off through 100 steps of poles |z| ~ 0.99: 1e-9)
    assert both.operators_.markov_parameters(100).relative_error(exact) < 1e-9
    rom = StateSpaceROM(both.operators_)
    prediction = rom.predict(dt * np.arange(U.shape[1]), U, initial=rom.initial_state(x0=X[:, 0], u0=U[:, 0]))
    assert np.linalg.norm(prediction.outputs - Y) / np.linalg.norm(Y) < 1e-9
    rom.save(tmp_path / "dmdc.h5")                          # the shifted state survives the file
    loaded = StateSpaceROM.load(tmp_path / "dmdc.h5")
    np.testing.assert_array_equal(loaded.operators_.input_offset, both.operators_.input_offset)
    np.testing.assert_array_equal(loaded.predict(dt * np.arange(U.shape[1]), U, initial=loaded.initial_state(x0=X[:, 0], u0=U[:, 0])).outputs,
                                  prediction.outputs)
    # lower side: Proctor's form (u_k only) cannot represent the u_k+1 term: B is O(1) wrong
    start = DMDc(feedthrough=True).fit(InputOutputData(U, Y, dt, states=X))
    assert start.operators_.markov_parameters(100).relative_error(exact) > 0.1
    with pytest.raises(ValueError, match="unknown input_samples 'end'"):
        DMDc(input_samples="end")


# -- OKID ---------------------------------------------------------------------------------

def test_okid_on_full_order_runs_recovers_the_newmark_state_space():
    system = small_structure()
    dt = 0.02
    samples, _, Y = newmark_run(system, dt, 400, seed=18)       # u_0 = 0: the run is from rest
    data = InputOutputData(samples, Y, dt)
    state_space = SecondOrderROM.galerkin(system, np.eye(3)).to_state_space(dt)
    exact = markov_parameters(state_space, 40)
    # a deadbeat observer of order l exists iff [C; C A; ...; C A^(l-1)] has rank n: displacement
    # outputs of the two end masses need l = 4 here, although l p = 6 >= n already at l = 3
    observability = lambda l: np.linalg.matrix_rank(  # noqa: E731
        np.vstack([state_space.C @ np.linalg.matrix_power(state_space.A, i) for i in range(l)]))
    assert (observability(3), observability(4)) == (5, 6)
    learner = OKID(6, 4, at_rest=True).fit(data)
    # the sampled FOM is exactly an order-6 state space with feedthrough D = C E (Newmark's
    # end-of-step input): OKID recovers it from the run's inputs and outputs alone, to round-off
    # amplified by the lightly damped poles (|z| ~ 0.99 over 40 steps: 1e-8 leaves a margin)
    assert learner.markov_.relative_error(exact, 40) < 1e-8
    assert learner.operators_.markov_parameters(40).relative_error(exact) < 1e-8
    # lower side: l = 3, below the observability index, leaves no exact observer
    assert okid_markov_parameters(data, 3, 40, at_rest=True).relative_error(exact) > 0.1


def test_okid_recovers_markov_parameters_from_noise_free_data_with_a_deadbeat_observer():
    A, B, C, D = random_system(6, 3, 4, 0.9, seed=11)
    rng = np.random.default_rng(12)
    U = rng.standard_normal((3, 300))
    Y, _ = simulate(A, B, C, D, U, rng.standard_normal(6))    # unknown initial state
    data = InputOutputData(U, Y, DT)
    truth = markov_parameters(StateSpaceOperators(A, B, C, D, DT), 40)
    # l = 3 is above the observability index of a random (A, C) with p = 4, n = 6 (2): a deadbeat
    # observer exists and the regression is exact (round-off; the recursion runs 40 steps through
    # the observer's poles: 1e-10 leaves a margin)
    assert okid_markov_parameters(data, 3, 40).relative_error(truth) < 1e-10
    learner = OKID(6, 3).fit(data)
    assert eigenvalue_mismatch(learner.operators_.eigenvalues(), np.linalg.eigvals(A)) < 1e-9
    assert learner.describe()["regression_residual"] < 1e-12
    # lower side: l p = 4 < n = 6 has no deadbeat observer; the fit is visibly wrong
    assert okid_markov_parameters(data, 1, 40).relative_error(truth) > 1e-2


def test_okid_observer_tracks_the_state_and_approaches_the_kalman_filter():
    import scipy.linalg

    A, B, C, D = random_system(6, 3, 4, 0.9, seed=11)
    process, measurement = 0.3, 0.1                      # standard deviations of w_k and v_k

    def run(K, seed, noisy=True):
        rng = np.random.default_rng(seed)
        U = rng.standard_normal((3, K))
        X = np.zeros((6, K))
        X[:, 0] = 5.0 * rng.standard_normal(6)         # unknown initial state
        W = process * rng.standard_normal((6, K)) if noisy else np.zeros((6, K))
        for k in range(K - 1):
            X[:, k + 1] = A @ X[:, k] + B @ U[:, k] + W[:, k]
        return U, C @ X + D @ U + (measurement * rng.standard_normal((4, K)) if noisy else 0.0)

    def innovations(rom, U, Y):
        Z = rom.estimate_states(U, Y)[:, :-1]
        ops = rom.operators_
        return np.linalg.norm(Y - ops.C @ Z - ops.D @ U, axis=0)

    # exact data: the identified observer converges from rest to the true outputs, at the rate
    # of its spectral radius (measured 0.86: 0.86^200 ~ 1e-13, so 1e-9 after 200 steps is loose)
    exact = StateSpaceROM(learner=OKID(6, 3)).fit(InputOutputData(*run(300, 20, noisy=False), DT))
    assert exact.learner.describe()["observer_spectral_radius"] < 0.95
    U, Y = run(300, 21, noisy=False)
    error = innovations(exact, U, Y)
    assert error[0] > 1.0 and error[200:].max() < 1e-9 * np.abs(Y).max()
    # noisy data: the innovations of the OKID observer against the steady Kalman filter's,
    # sqrt(trace(C P C^T + R)) with P from the Riccati equation of the true system
    P = scipy.linalg.solve_discrete_are(A.T, C.T, process**2 * np.eye(6), measurement**2 * np.eye(4))
    kalman = np.sqrt(np.trace(C @ P @ C.T) + 4 * measurement**2)
    rom = StateSpaceROM(learner=OKID(6, 10)).fit(InputOutputData(*run(3000, 22), DT))
    U, Y = run(4000, 23)
    observed = np.sqrt(np.mean(innovations(rom, U, Y)[100:] ** 2))
    open_loop = np.sqrt(np.mean(np.linalg.norm(Y - rom.predict(DT * np.arange(4000), U).outputs, axis=0)[100:] ** 2))
    # no predictor beats the Kalman filter (below 1 only by the sampling error of 3900 x 4 squares,
    # ~0.6 %); the identified one is within 10 % of it (measured 0.8 %; 31 % with l = 20, whose 143
    # unknowns per output 3000 samples fit less well), the open-loop model far off (3.5 times)
    assert 0.97 < observed / kalman < 1.10, observed / kalman
    assert open_loop > 2.0 * kalman


def test_okid_agrees_with_python_control_markov_on_data_from_rest():
    control = extra("control")
    A, B, C, D = random_system(5, 2, 3, 0.6, seed=13)
    rng = np.random.default_rng(14)
    U = rng.standard_normal((2, 400))
    Y, _ = simulate(A, B, C, D, U)
    ours = okid_markov_parameters(InputOutputData(U, Y, DT), 2, 12, at_rest=True)
    # control.markov fits an FIR of 60 terms from rest: its truncation error is ~ 0.6^59 ~ 1e-13
    theirs = np.moveaxis(control.markov(Y, U, 60), -1, 0)[:12]
    assert ours.relative_error(MarkovParameters(theirs, DT)) < 1e-10


def test_okid_error_falls_like_one_over_sqrt_k_with_measurement_noise():
    A, B, C, D = random_system(6, 3, 4, 0.6, seed=1)
    truth = markov_parameters(StateSpaceOperators(A, B, C, D, DT), 10)
    lengths = np.array([1000, 2000, 4000, 8000])
    errors = []
    for K in lengths:
        trials = []
        for seed in range(3):
            rng = np.random.default_rng(100 + seed)
            U = rng.standard_normal((3, K))
            Y, _ = simulate(A, B, C, D, U)
            noisy = Y + 0.1 * np.std(Y) * rng.standard_normal(Y.shape)
            trials.append(okid_markov_parameters(InputOutputData(U, noisy, DT), 10, 10).relative_error(truth))
        errors.append(np.sqrt(np.mean(np.square(trials))))
    slope = np.polyfit(np.log(lengths), np.log(errors), 1)[0]
    # white measurement noise: a least-squares estimate with variance ~ 1/K; the truncation
    # bias 0.6^10 ~ 6e-3 of the observer's tail is far below the 1e-2 .. 5e-3 errors seen.
    # Three seeds per length leave a scatter of about +-0.1 in the fitted slope.
    assert -0.65 < slope < -0.35, slope
    assert errors[-1] < 0.01


def test_okid_errors_name_the_culprit():
    rng = np.random.default_rng(15)
    data = InputOutputData(rng.standard_normal((2, 30)), rng.standard_normal((3, 30)), DT)
    with pytest.raises(ValueError, match="OKID with observer order 10 has 52 unknowns"):
        OKID(2, 10).fit(data)
    with pytest.raises(ValueError, match="OKID needs outputs"):
        OKID(2, 1).fit(InputOutputData(data.inputs, None, DT))
    with pytest.raises(ValueError, match="observer_order must be a positive integer"):
        OKID(2, 0)
    with pytest.raises(TypeError, match="takes InputOutputData"):
        OKID(2, 1).fit(markov_parameters(StateSpaceOperators(np.eye(2) * 0.5, np.ones((2, 2)),
                                                             np.ones((3, 2)), np.zeros((3, 2)), DT), 5))


# -- the ROM: predict, stepper, files -------------------------------------------------------

@pytest.mark.parametrize("kind", ["dmdc", "era", "okid"])
def test_state_space_rom_fits_predicts_steps_and_round_trips(kind, tmp_path):
    A, B, C, D = random_system(4, 2, 3, 0.9, seed=16)
    rng = np.random.default_rng(17)
    U = rng.standard_normal((2, 120))
    Y, X = simulate(A, B, C, D, U)
    data = InputOutputData(U, Y, DT, states=X)
    learner, training = {"dmdc": (DMDc(feedthrough=True), data), "okid": (OKID(4, 2, at_rest=True), data),
                         "era": (ERA(4), markov_parameters(StateSpaceOperators(A, B, C, D, DT), 21))}[kind]
    rom = StateSpaceROM(learner=learner).fit(training)
    times = DT * np.arange(U.shape[1])
    prediction = rom.predict(times, U)
    # exact data of an order-4 system: every method reproduces the outputs from rest
    assert np.linalg.norm(prediction.outputs - Y) / np.linalg.norm(Y) < 1e-9
    stepper = rom.stepper(u0=U[:, 0])
    stepped = np.column_stack([stepper.output] + [stepper.step(U[:, k]) for k in range(1, U.shape[1])])
    np.testing.assert_allclose(stepped, prediction.outputs, rtol=0, atol=1e-12 * np.abs(Y).max())
    rom.save(tmp_path / "rom.h5")
    loaded = StateSpaceROM.load(tmp_path / "rom.h5")
    np.testing.assert_array_equal(loaded.predict(times, U).outputs, prediction.outputs)
    assert loaded.operators_.metadata["method"] == kind
    plain = DiscreteStateSpace.load(tmp_path / "rom.h5")        # the MPC's form reads the same file
    np.testing.assert_array_equal(plain.A, rom.operators_.A)
    if kind == "okid":
        np.testing.assert_array_equal(loaded.operators_.observer_gain, rom.operators_.observer_gain)
        # the same matrices; only the memory layout after HDF5 may change the summation order
        np.testing.assert_allclose(loaded.estimate_states(U, Y), rom.estimate_states(U, Y), rtol=1e-12, atol=1e-12)
    else:
        with pytest.raises(ValueError, match="has no observer gain"):
            rom.estimate_states(U, Y)
    if kind == "dmdc":
        np.testing.assert_array_equal(loaded.operators_.state_basis, rom.operators_.state_basis)
        from_state = rom.predict(times, U, initial=rom.initial_state(x0=X[:, 0], u0=U[:, 0]))
        np.testing.assert_array_equal(from_state.outputs, prediction.outputs)
    else:
        with pytest.raises(ValueError, match="state is abstract"):
            rom.predict(times, U, initial=rom.initial_state(x0=np.zeros(4)))
    with pytest.raises(ValueError, match="identified at dt = 0.01"):
        rom.predict(2 * times, U)
    with pytest.raises(ValueError, match="exists at its step dt = 0.01 only"):
        rom.to_state_space(0.02)
    assert [p.name for p in tmp_path.iterdir()] == ["rom.h5"]          # no temporary file left


def test_state_space_rom_refuses_other_learners_and_unfitted_use():
    from femrom.inference import LagrangianOpInf

    with pytest.raises(ValueError, match="fits 'second_order' models"):
        StateSpaceROM(learner=LagrangianOpInf())
    with pytest.raises(ValueError, match="not fitted"):
        StateSpaceROM().predict(DT * np.arange(3), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="no learner"):
        StateSpaceROM().fit(None)


@pytest.mark.parametrize("make, message", [
    (lambda: ERA(4, rows=2.5), "rows must be a positive integer, got 2.5"),
    (lambda: ERA(4.0), "order must be a positive integer, got 4.0"),
    (lambda: ERA(4, input_directions=0), "input_directions must be a positive integer, got 0"),
    (lambda: DMDc(rank=20.0), "rank must be a positive integer, got 20.0"),
    (lambda: DMDc(output_rank=True), "output_rank must be a positive integer, got True"),
    (lambda: OKID(4, 10, columns="5"), "columns must be a positive integer, got '5'"),
    (lambda: OKID(4, 2.0), "observer_order must be a positive integer, got 2.0"),
])
def test_integer_arguments_follow_one_rule(make, message):
    """An integer argument is an int or a numpy integer (2.5 was truncated, 20.0 accepted, True taken as 1)."""
    from femrom import FemromValueError

    with pytest.raises(FemromValueError, match=re.escape(message)):
        make()
    assert ERA(np.int64(4), rows=np.int32(3)).rows == 3 and DMDc(rank=np.int64(2)).rank == 2
