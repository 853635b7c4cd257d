"""SpML converges where its model class contains the truth: the error split, the least-squares stage,
the differentiable discrete-gradient rollout, and the issue's targets on exact and noisy data.

The systems come from ``benchmarks/spml_systems.py`` (a chain of three masses with quartic springs,
two coupled Duffing oscillators: unit mass, linear damping, a polynomial potential); a held-out
system of the same kind is one more factory there.
"""

import numpy as np
import pytest

from _required import extra
from benchmarks.spml_systems import SYSTEMS, predict, prediction_errors
from femrom.inference import Smoothing, SpML, SpMLConfig
from femrom.rom import SecondOrderROM
from femrom.study import spml_error_split

torch = extra("torch")


@pytest.fixture(scope="module", params=sorted(SYSTEMS))
def exact(request):
    """(system, training runs, validation run, the unseen amplitude over three training windows)."""
    system = SYSTEMS[request.param]()
    train, validation = system.training()
    return system, train, validation, system.test(3.0)


def _fit(train, validation, **options):
    return SpML(["damping"], config=SpMLConfig(seed=0, **options), progress=False).fit(train, validation=validation)


def test_the_split_puts_l_bfgs_alones_gap_in_the_optimisation_and_the_dissipation(exact):
    """The issue's diagnosis: L-BFGS alone (the former default) stops far above the truth's loss,
    and what it leaves shows most in the dissipation, which the loss hardly sees."""
    system, train, validation, test = exact
    learner = _fit(train, validation, least_squares=False, max_iterations=300)
    split = spml_error_split(learner.operators_, system.operators, train, test)
    # exact data: the truth's loss is round-off (observed 4e-33); L-BFGS stops at 1e-6 .. 1e-5
    assert split.truth_loss < 1e-28 and split.loss > 1e6 * split.truth_loss, split
    # the damping is 2-3 % of the forces, so its error weighs 1e-3 in the loss: observed after 300
    # iterations 0.26 against a potential within 0.047 (chain), and at the former default (2000) 0.15
    # against 5.5e-3
    assert split.dissipation > 3 * split.potential, split


def test_exact_data_meet_the_targets(exact):
    """Truth in the class, exact data, the default fit: force error <= 1e-4, the unseen amplitude within
    1e-3 over the training window's length and 1e-2 over three times it (discrete gradient at dt / 8)."""
    system, train, validation, test = exact
    learner = _fit(train, validation)
    # the default "auto" smoothing keeps exact data as given (estimated noise 8e-8 .. 5e-6 < 1e-3)
    assert learner.smoothed_ == [False] * len(train)
    split = spml_error_split(learner.operators_, system.operators, train, test)
    # observed 7e-8 (chain) and 9e-12 (Duffing): the least-squares stage lands on the truth
    assert split.potential <= 1e-4, split
    assert split.dissipation <= 1e-3 and split.mass <= 1e-4, split
    errors = prediction_errors(learner.operators_, system, test)
    # observed 7.1e-5 / 1.8e-4 (chain) and 2.2e-4 / 3.4e-4 (Duffing): the scheme's own error at dt / 8
    # (the truth stepped the same way has the same numbers to 3 digits)
    assert errors["window"] <= 1e-3 and errors["total"] <= 1e-2, errors
    stages = [s["stage"] for s in learner.stages_]
    assert stages[:3] == ["step 1", "least squares", "L-BFGS"]
    assert learner.stages_[1]["loss"] < 1e-10 * learner.stages_[0]["loss"]


def test_a_solve_is_kept_only_where_it_lowers_the_checked_loss(exact):
    """Every stage's checked (validation) loss is at most the one before: a least-squares solve or an
    L-BFGS stage that would raise it is not kept."""
    _, train, validation, _ = exact
    learner = _fit(train, validation, max_iterations=60, least_squares_rounds=3)
    losses = [s["validation_loss"] for s in learner.stages_]
    assert all(b <= a * (1 + 1e-12) for a, b in zip(losses, losses[1:])), learner.stages_


def test_the_rollout_is_the_discrete_gradient_scheme_and_refines_without_harm(exact):
    """The differentiable rollout predicts what the numpy discrete-gradient ROM predicts (a polynomial
    potential: the two-point quadrature is exact, Gonzalez's correction vanishes). A rollout stage
    lowers the rollout loss but fits the scheme's trajectories at its step: from a converged fit on
    exact data it moves the force by the scheme's error (observed 5e-4 and 6e-4 at dt / 2), which is
    why it is off by default."""
    from femrom.inference._spml_torch import Rollout

    system, train, validation, _ = exact
    learner = _fit(train, validation, rollout_steps=3, rollout_stride=40, rollout_iterations=4,
                   rollout_substeps=2)
    stage = learner.stages_[-1]
    assert stage["stage"] == "rollout" and stage["rollout_loss"] <= stage["rollout_loss_before"]
    split = spml_error_split(learner.operators_, system.operators, train, system.test(1.0))
    assert 1e-5 < split.potential <= 1e-2, split
    # the module at the exported weights against the ROM on one window
    module = learner._module
    data = train[1]
    window = {"q": data.states[:, :6], "v": data.velocities[:, :6], "u": None, "dt": system.dt}
    rollout = Rollout(module, [window], steps=5, substeps=2, stride=10, newton=8)
    with torch.no_grad():
        q, v = (x.numpy()[0].T for x in rollout.predict())
    t = (system.dt / 2) * np.arange(11)
    rom = SecondOrderROM(learner.operators_).predict(t, initial=(data.states[:, 0], data.velocities[:, 0]),
                                                     scheme="discrete_gradient")
    np.testing.assert_allclose(q, rom.q[:, ::2], rtol=0, atol=1e-10 * np.abs(rom.q).max())
    np.testing.assert_allclose(v, rom.v[:, ::2], rtol=0, atol=1e-9 * np.abs(rom.v).max())


@pytest.fixture(scope="module", params=sorted(SYSTEMS))
def noisy(request):
    """(name, system, 1 % noisy training runs, validation run, the unseen amplitude exactly over three
    windows, and three fits: on the raw data, on the smoothed data alone (``output_error=False``), and
    the defaults (smoothing, then the output-error stage)): noise of 1 % of each field's RMS on states,
    velocities and accelerations (seed 0)."""
    system = SYSTEMS[request.param]()
    train, validation = system.training(noise=0.01)
    raw = SpML(["damping"], config=SpMLConfig(seed=0), smoothing=None, progress=False).fit(
        train, validation=validation)
    smooth = _fit(train, validation, output_error=False)
    default = _fit(train, validation)
    return request.param, system, train, validation, system.test(3.0), raw, smooth, default


def test_one_percent_noise_raw_data_fit_as_well_as_the_data_allow_but_miss(noisy):
    """Without smoothing the optimiser reaches the truth's loss, yet the force misses its target by 3x
    (Duffing) to 30x (chain): the error is the estimator's (noise in the states is noise in the
    regressors), not the optimiser's. This is the lower side of the smoothing test below: the fit
    on raw data cannot pass it. (No output-error stage: it follows a smoothing only.)"""
    name, system, train, _, test, raw, _, _ = noisy
    assert all(s["stage"] != "output error" for s in raw.stages_)
    split = spml_error_split(raw.operators_, system.operators, train, test)
    # observed: chain 4.57e-3 against the truth's 4.62e-3; Duffing 3.33e-4 against 3.35e-4
    assert split.loss <= split.truth_loss, split
    # observed: chain force 3.4e-2, mass 3.0e-2; Duffing 3.2e-3, 2.3e-2 (the targets: 1e-3 and the
    # smoothed fits' 3e-3 / 4e-4)
    assert split.potential > 2e-3 and split.mass > 1e-2, split


def test_one_percent_noise_smoothing_alone_meets_the_prediction_targets(noisy):
    """The data smoothed first (one spline per coordinate through the states, velocities and
    accelerations, the smoothing chosen from the data), the equation-error fit alone: the unseen
    amplitude within 1e-2 over the training window's length and 1e-1 over three times it (10x the
    exact-data targets), the force 3-4x closer than on raw data but above its 1e-3 target: what
    remains is the noise inside the signal's band, which no smoothing removes (docs/spml.md)."""
    name, system, train, _, test, raw, smooth, _ = noisy
    # the default "auto" smoothing estimated 1.3-2.2e-2 relative noise on every run (threshold 1e-3)
    assert raw.smoothed_ is None and smooth.smoothed_ == [True] * len(train)
    split = spml_error_split(smooth.operators_, system.operators, train, test)
    raw_split = spml_error_split(raw.operators_, system.operators, train, test)
    errors = prediction_errors(smooth.operators_, system, test)
    assert errors["finite"]
    # observed (seed 0): chain 6.1e-3 / 2.1e-2, Duffing 4.7e-3 / 1.7e-2; over five noise seeds at most
    # 9.1e-3 / 5.5e-2 (the raw fits: up to 2.6e-2 / 0.15)
    assert errors["window"] <= 1e-2 and errors["total"] <= 1e-1, errors
    # the force 3-4x and the mass 8-60x closer (observed chain 8.2e-3 against 3.4e-2 and 3.4e-3 against
    # 3.0e-2; Duffing 1.1e-3 against 3.2e-3 and 3.9e-4 against 2.3e-2)
    assert split.potential < 0.5 * raw_split.potential and split.mass < 0.3 * raw_split.mass, (split, raw_split)


def test_one_percent_noise_the_defaults_refine_by_output_error_to_the_datas_floor(noisy):
    """The defaults add the output-error stage (the measured trajectories simulated, their misfit
    weighted by the estimated noise: the maximum-likelihood fit): the predictions 3-10x closer than
    smoothing alone's, the force at the data's own floor. That floor is what
    ``benchmarks/spml_noise_floor.py`` measures, the same estimator of exactly the true class with
    the mass known: on these data 7.5e-4 (Duffing) and 1.5e-3 (chain), so the 1e-3 force target is
    met on the Duffing pair and asks more of the chain's data than they determine."""
    name, system, train, _, test, _, smooth, default = noisy
    stage = [s for s in default.stages_ if s["stage"] == "output error"]
    assert len(stage) == 1 and stage[0]["kept"], default.stages_
    stage = stage[0]
    # the cost ends at the noise's expectation, half the number of residuals (observed Duffing 4885 / 4812,
    # chain 7143 / 7218; from 7047 and 18157), and the held-out run's falls too
    assert abs(stage["cost"] / stage["expected"] - 1.0) < 0.05 < stage["cost_before"] / stage["expected"] - 1.0
    assert stage["validation_cost"] < stage["validation_cost_before"]
    split = spml_error_split(default.operators_, system.operators, train, test)
    before = spml_error_split(smooth.operators_, system.operators, train, test)
    errors = prediction_errors(default.operators_, system, test)
    errors_before = prediction_errors(smooth.operators_, system, test)
    # observed (seed 0): Duffing 1.3e-3 / 4.4e-3 against 4.7e-3 / 1.7e-2, chain 1.3e-3 / 2.0e-3 against
    # 6.1e-3 / 2.1e-2; over five noise seeds at most 3.6e-3 / 8.2e-3 (Duffing) and 2.4e-3 / 3.9e-3 (chain)
    assert errors["window"] <= 0.5 * errors_before["window"] and errors["total"] <= 0.5 * errors_before["total"], \
        (errors, errors_before)
    assert errors["window"] <= 1e-2 and errors["total"] <= 1e-1, errors
    # observed (seed 0): Duffing 7.7e-4 against 1.1e-3, chain 2.0e-3 against 8.2e-3; over five seeds
    # Duffing 5.2e-4 .. 7.7e-4 (the floor 4.4e-4 .. 7.5e-4 on seeds 0-2), chain 1.8e-3 .. 3.7e-3 (the floor
    # 1.5e-3 .. 3.6e-3)
    assert split.potential < before.potential, (split, before)
    assert split.potential <= {"duffing2": 1e-3, "chain3": 2.5e-3}[name], split
    if split.potential > 1e-3:
        pytest.xfail(f"1 % noise, {name}: force {split.potential:.2e} against 1e-3, the data's maximum-likelihood "
                     f"floor 1.5e-3 (benchmarks/spml_noise_floor.py)")


def test_predict_helper_returns_the_samples():
    system = SYSTEMS["duffing2"]()
    run = system.run(1.0, 1.0)
    Q, V = predict(system.operators, run)
    assert Q.shape == run.states.shape and V.shape == run.velocities.shape
    # the true model at dt / 8 against the exact run over one second: the scheme's error only
    assert np.abs(Q - run.states).max() < 1e-4
