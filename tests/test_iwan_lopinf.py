"""The learned Iwan term (parallel Jenkins sliders along a reduced direction) and its learner."""

import numpy as np
import pytest

from femrom.inference import (
    IwanLOpInf,
    LearnedHysteresis,
    ReducedOperators,
    SecondOrderData,
    concatenate,
    learner_class,
    slider_stretches,
)
from femrom.rom import SecondOrderROM

TWO_PI = 2 * np.pi


def two_dof_model(weights=None, damping=0.002):
    """Modes near 2 and 3 Hz, light viscous damping, an input, and 8 sliders on a = (1, 0.4)."""
    K = np.array([[4.0, 0.5], [0.5, 9.0]]) * TWO_PI ** 2
    C = damping * K / TWO_PI
    B = np.array([[1.0], [0.3]])
    phi = 1e-3 * np.geomspace(1e-2, 1, 8)
    k = np.array([0, 50, 0, 200, 0, 300, 0, 100.0]) if weights is None else weights
    hysteresis = LearnedHysteresis(np.array([1.0, 0.4]), phi, k)
    return K, C, B, hysteresis


def ring_downs(ops, amplitudes=(5.0, 20.0), steps=3000, dt=1e-3):
    rom = SecondOrderROM(ops, np.eye(ops.r))
    t = np.arange(steps) * dt
    runs = []
    for amplitude in amplitudes:
        u = np.where(t < 0.01, amplitude * np.sin(np.pi * t / 0.01), 0.0)[None]
        solution = rom.predict(t, u, initial=np.zeros(ops.r), scheme="newmark")
        runs.append(SecondOrderData(solution.q, solution.v, solution.a, inputs=u, times=t))
    return runs


def test_play_operator_by_hand():
    """Loading 0 -> 2, reversal to -1 and back to 0 with phi = 1 and 3 (worked out on paper)."""
    x = np.array([0.0, 1.0, 2.0, 0.5, -1.0, 0.0])
    E = slider_stretches(x, [1.0, 3.0])
    np.testing.assert_allclose(E[0], [0, 1, 1, -0.5, -1, 0])
    np.testing.assert_allclose(E[1], x)              # never reaches 3: stuck throughout
    # a second trajectory restarts loaded from rest at its first column
    E2 = slider_stretches(np.r_[x, 5.0, 4.0], [1.0, 3.0], starts=(0, 6))
    np.testing.assert_allclose(E2[:, 6:], [[1.0, 0.0], [3.0, 2.0]])


def test_cycle_dissipation_is_masing():
    """The work of the force over a steady cycle of amplitude A is sum_{phi_i < A} 4 k_i phi_i (A - phi_i)
    (each slipping slider traces a parallelogram); the trapezoidal path integral on 20,000 points per
    cycle resolves it to 1e-6, and the sliders with phi_i >= A add nothing."""
    term = LearnedHysteresis([1.0], [0.1, 0.3, 0.6, 2.0], [5.0, 2.0, 1.0, 7.0])
    A = 1.0
    s = np.linspace(0, 2 * TWO_PI, 40001)
    x = A * np.sin(s)
    f = term.forces(x[None])[0]
    second = slice(20000, 40001)                      # the steady cycle (the first starts from rest)
    work = np.trapezoid(f[second], x[second])
    expected = sum(4 * k * p * (A - p) for k, p in zip(term.weights, term.thresholds) if p < A)
    assert work == pytest.approx(expected, rel=1e-6)
    assert expected == pytest.approx(1.8 + 1.68 + 0.96)


def test_learner_recovers_the_model_that_made_the_data():
    """Ring-downs of a known 2-dof model with sliders (all slipping at the larger blow): with the
    same direction and thresholds the learner returns K^, C^, B^ and the weights to the solver's
    tolerance (the data satisfy the model to 1e-16); the best linear model leaves 11 % residual."""
    K, C, B, hysteresis = two_dof_model()
    ops = ReducedOperators.from_matrices(K, damping=C, input_matrix=B, nonlinear=hysteresis)
    data = concatenate(ring_downs(ops))
    learner = IwanLOpInf(["damping"], thresholds=hysteresis.thresholds, direction=hysteresis.direction,
                         regularization=0.0).fit(data)
    fitted = learner.operators_
    assert learner.residual_ < 1e-7
    assert learner.linear_residual_ > 1e-2
    np.testing.assert_allclose(fitted.stiffness, K, rtol=1e-8)
    np.testing.assert_allclose(fitted.damping, C, rtol=1e-5, atol=1e-7 * np.abs(C).max())
    np.testing.assert_allclose(fitted.input_matrix, B, rtol=1e-7)
    np.testing.assert_allclose(learner.hysteresis_.weights, hysteresis.weights, atol=1e-5 * hysteresis.weights.max())


def test_learner_defaults_fit_and_predict_an_untrained_blow():
    """Default settings (32 monotone thresholds over the data's range; a = e_1 would be another model,
    so the direction is given), on a model whose weights grow with the threshold (as the default's
    constraint assumes) but sit on another grid: trained on 5 and 20 N, the model predicts a 10 N
    ring-down better than the best linear model by more than 10x."""
    K, C, B, hysteresis = two_dof_model(weights=np.array([10, 20, 40, 60, 80, 120, 160, 200.0]))
    ops = ReducedOperators.from_matrices(K, damping=C, input_matrix=B, nonlinear=hysteresis)
    train = ring_downs(ops)
    (test,) = ring_downs(ops, amplitudes=(10.0,), steps=6000)
    learner = IwanLOpInf(["damping"], direction=hysteresis.direction).fit(train)
    linear = IwanLOpInf(["damping"], thresholds=[1e9], direction=hysteresis.direction).fit(train)  # never slips
    errors = []
    for model in (learner, linear):
        rom = SecondOrderROM(model.operators_, np.eye(2))
        solution = rom.predict(test.times, test.inputs, initial=np.zeros(2), scheme="newmark")
        errors.append(np.linalg.norm(solution.q - test.states) / np.linalg.norm(test.states))
    assert learner.hysteresis_.thresholds.size == 32
    assert errors[0] < 0.05
    assert errors[1] > 10 * errors[0]


def test_free_energy_never_grows():
    """Newmark with the return-mapped sliders: E = v.v/2 + q.K q/2 + sum k e^2/2 is non-increasing at
    every step for any k >= 0 without damping or input (the slip work k e . slip >= 0); and it does
    decrease (the sliders dissipate), by more than 5 % over the run from a large release."""
    rng = np.random.default_rng(3)
    G = rng.standard_normal((3, 3))
    K = G @ G.T + 3 * np.eye(3)
    term = LearnedHysteresis(rng.standard_normal(3), np.geomspace(1e-3, 1.0, 10), rng.uniform(0, 2, 10))
    rom = SecondOrderROM(ReducedOperators.from_matrices(K, nonlinear=term), np.eye(3))
    stepper = rom.stepper(0.05, initial=np.array([2.0, -1.0, 0.5]))
    energies = []
    for _ in range(2000):
        stepper.step()
        energies.append(0.5 * stepper.v @ stepper.v + 0.5 * stepper.q @ K @ stepper.q
                        + term.stored_energy(stepper.state))
    energies = np.array(energies)
    assert np.all(np.diff(energies) <= 1e-12 * energies[0])
    assert energies[-1] < 0.95 * energies[0]


def test_save_load_and_registry(tmp_path):
    K, C, B, hysteresis = two_dof_model()
    ops = ReducedOperators.from_matrices(K, damping=C, input_matrix=B, nonlinear=hysteresis)
    rom = SecondOrderROM(ops, np.eye(2))
    rom.save(tmp_path / "rom.h5")
    back = SecondOrderROM.load(tmp_path / "rom.h5")
    t = np.arange(500) * 1e-3
    u = np.where(t < 0.01, 20.0, 0.0)[None]
    a = rom.predict(t, u, initial=np.zeros(2)).q
    b = back.predict(t, u, initial=np.zeros(2)).q
    np.testing.assert_array_equal(a, b)
    assert learner_class("iwan_lopinf") is IwanLOpInf


@pytest.mark.parametrize("kwargs, match", [
    ({"thresholds": 0}, "thresholds must be a positive integer"),
    ({"thresholds": [1.0, -2.0]}, "thresholds must be a positive integer"),
    ({"threshold_span": (1.0, 0.1)}, "threshold_span"),
    ({"terms": ["mass"]}, "unknown terms"),
    ({"regularization": -1.0}, "regularization"),
    ({"band": (10.0, 5.0)}, "band must be"),
])
def test_learner_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        IwanLOpInf(**kwargs)


@pytest.mark.parametrize("args, match", [
    (([0.0, 0.0], [1.0], [1.0]), "direction"),
    (([1.0], [0.0], [1.0]), "thresholds"),
    (([1.0], [1.0], [-1.0]), "weights"),
    (([1.0], [1.0, 2.0], [1.0]), "weights"),
])
def test_term_bad_parameters(args, match):
    with pytest.raises(ValueError, match=match):
        LearnedHysteresis(*args)


def test_data_that_never_move_along_the_direction():
    q = np.zeros((2, 50))
    q[1] = np.sin(np.arange(50))
    data = SecondOrderData(q, q, q)
    with pytest.raises(ValueError, match="never move along the hysteresis direction"):
        IwanLOpInf(direction=[1.0, 0.0]).fit(data)


def test_band_filtered_fit_recovers_the_model():
    """The balance is linear in the unknowns, so band-passed rows (here 1-10 Hz around the 2 and 3 Hz
    modes) obey it too: the filtered fit recovers the same model, to the filter's edge effects (the
    rows are filtered trajectory by trajectory from rest), far below the linear model's residual."""
    K, C, B, hysteresis = two_dof_model()
    ops = ReducedOperators.from_matrices(K, damping=C, input_matrix=B, nonlinear=hysteresis)
    runs = ring_downs(ops)
    learner = IwanLOpInf(["damping"], thresholds=hysteresis.thresholds, direction=hysteresis.direction,
                         band=(1.0, 10.0), regularization=0.0).fit(runs)
    np.testing.assert_allclose(learner.operators_.stiffness, K, rtol=1e-3)
    np.testing.assert_allclose(learner.hysteresis_.weights, hysteresis.weights, atol=2e-2 * hysteresis.weights.max())
    assert learner.residual_ < 1e-2 * learner.linear_residual_
    with pytest.raises(ValueError, match="uniform time step"):
        IwanLOpInf(band=(1.0, 10.0), direction=[1.0, 0.4]).fit(
            SecondOrderData(runs[0].states, runs[0].velocities, runs[0].accelerations, inputs=runs[0].inputs))


def test_segalman_shaped_weights():
    """With generated thresholds (the default) the weights have the shape of Segalman's density: they
    never decrease below the top slider and vanish above it."""
    K, C, B, hysteresis = two_dof_model()
    ops = ReducedOperators.from_matrices(K, damping=C, input_matrix=B, nonlinear=hysteresis)
    learner = IwanLOpInf(["damping"], thresholds=12, direction=hysteresis.direction).fit(ring_downs(ops))
    k = learner.hysteresis_.weights
    top = int(np.searchsorted(learner.hysteresis_.thresholds, learner.top_threshold_))
    assert 1 <= top < 12 and k.max() > 0
    assert np.all(np.diff(k[:top]) >= -1e-9 * k.max())
    assert np.all(k[top + 1:] <= 1e-9 * k.max())
