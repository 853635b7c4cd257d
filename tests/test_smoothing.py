"""Denoising trajectories before a fit (:class:`femrom.inference.Smoothing`): the noise estimate, the
joint spline through states, velocities and accelerations, its choice of smoothing from the data, and
the learners' ``smoothing=`` option."""

import numpy as np
import pytest

from benchmarks.spml_systems import chain, duffing
from femrom._errors import FemromError
from femrom.inference import LagrangianOpInf, SecondOrderData, Smoothing, concatenate, noise_level
from femrom.inference._smoothing import _inverse_band


def _relative(X, Y):
    return float(np.linalg.norm(X - Y) / np.linalg.norm(Y))


@pytest.fixture(scope="module")
def runs():
    """(exact, 1 % noisy) runs of the Duffing pair over the training window."""
    system = duffing()
    return system.run(1.1, system.t_train), system.run(1.1, system.t_train, noise=0.01, seed=5)


def test_noise_level_reads_the_noise_off_the_differences():
    t = np.linspace(0.0, 20.0, 2001)
    rng = np.random.default_rng(0)
    y = np.sin(1.3 * t) + 0.3 * np.cos(4.1 * t)
    # 2000 samples: the estimate's own spread is about 1/sqrt(K) times a constant (observed 1-3 %)
    assert noise_level(y + 0.01 * rng.standard_normal(t.size)) == pytest.approx(0.01, rel=0.1)
    # a smooth signal alone: the sixth differences at 100 samples a period are (2 pi / 100)^6 of it
    assert noise_level(y) < 1e-6


def test_the_robust_noise_level_ignores_kinks_the_mean_square_one_counts():
    """A stick-slip-like signal (a jump in the slope every 250 samples) without noise: the mean-square
    estimate reads its kinks as noise; the median one does not, and both read white noise alike."""
    t = np.linspace(0.0, 20.0, 2001)
    y = np.abs(np.sin(0.8 * t))                                   # kinks at the zeros of the sine
    assert noise_level(y) > 1e-4                                  # observed 1.1e-3
    assert noise_level(y, robust=True) < 1e-6                     # observed 3e-8: the smooth arcs
    noisy = y + 0.01 * np.random.default_rng(2).standard_normal(t.size)
    assert noise_level(noisy, robust=True) == pytest.approx(0.01, rel=0.1)


def test_auto_smooths_the_noisy_trajectory_and_keeps_the_exact_one(runs):
    """:meth:`Smoothing.auto` judges each trajectory by its regressors' estimated noise: the 1 %
    noisy run is smoothed as :class:`Smoothing` would, the exact one passes bit for bit (its
    estimate, 1e-7, is four orders below the threshold)."""
    exact, noisy = runs
    auto = Smoothing.auto()
    assert auto.threshold == 1e-3 and Smoothing.of("auto") == auto
    levels = auto.noise(exact) + auto.noise(noisy)
    assert levels[0] < 1e-5 and 5e-3 < levels[1] < 5e-2, levels      # observed 4e-7 and 1.5e-2
    kept = auto.apply(exact)
    assert np.array_equal(kept.states, exact.states)
    assert np.array_equal(kept.accelerations, exact.accelerations)
    assert kept.diagnostics["smoothing"]["trajectories"] == [{"kept": True, "noise": levels[0]}]
    smoothed, always = auto.apply(noisy), Smoothing().apply(noisy)
    np.testing.assert_array_equal(smoothed.states, always.states)
    # both in one data set: each trajectory on its own
    both = auto.apply(concatenate([exact, noisy]))
    np.testing.assert_array_equal(both.states[:, :exact.n_samples], exact.states)
    np.testing.assert_array_equal(both.states[:, exact.n_samples:], always.states)


def test_the_band_of_the_inverse_is_exact():
    rng = np.random.default_rng(1)
    n, b = 40, 4
    A = rng.standard_normal((n, n))
    S = A @ A.T + n * np.eye(n)
    S[np.abs(np.subtract.outer(np.arange(n), np.arange(n))) > b] = 0.0
    S += 10 * n * np.eye(n)                                   # still SPD after the cut
    from scipy.linalg import cholesky_banded

    band = np.zeros((b + 1, n))
    for d in range(b + 1):
        band[b - d, d:] = np.diag(S, d)
    Z, inverse = _inverse_band(cholesky_banded(band)), np.linalg.inv(S)
    for d in range(b + 1):
        np.testing.assert_allclose(Z[b - d, d:], np.diag(inverse, d), rtol=1e-10, atol=1e-16)


def test_exact_data_pass_nearly_unchanged(runs):
    """On exact data the estimated noise is the smooth part's own differences and the risk estimate
    picks a tiny lambda: the curve is the data to the spline's approximation error."""
    exact, _ = runs
    smooth = Smoothing().apply(exact)
    # observed 2.7e-8, 1.1e-7, 1.1e-6
    assert _relative(smooth.states, exact.states) < 1e-6
    assert _relative(smooth.velocities, exact.velocities) < 1e-5
    assert _relative(smooth.accelerations, exact.accelerations) < 1e-4


def test_noisy_data_come_out_several_times_closer_to_the_truth(runs):
    """1 % noise on each field: the joint curve takes the states' noise down ~6x, the velocities' ~5x and
    the accelerations' ~2x (observed 1.6e-3, 1.7e-3, 5.2e-3 from 1e-2); the derivatives are the curve's."""
    exact, noisy = runs
    smooth = Smoothing().apply(noisy)
    assert _relative(smooth.states, exact.states) < 0.3 * _relative(noisy.states, exact.states)
    assert _relative(smooth.velocities, exact.velocities) < 0.3 * _relative(noisy.velocities, exact.velocities)
    assert _relative(smooth.accelerations, exact.accelerations) < 0.7 * _relative(noisy.accelerations,
                                                                                 exact.accelerations)
    # the velocities are the states' derivative (central differences, O(dt^2) = 1e-3 of the signal)
    dt = exact.times[1] - exact.times[0]
    fd = (smooth.states[:, 2:] - smooth.states[:, :-2]) / (2 * dt)
    assert _relative(fd, smooth.velocities[:, 1:-1]) < 2e-3
    # the noise estimate is the data's, not the known one (1 % of each field's RMS over all coordinates;
    # the report is relative to each coordinate's RMS): within a fifth of it
    report = smooth.diagnostics["smoothing"]
    assert report["fields"] == "all"
    for j, row in enumerate(report["trajectories"][0]):
        for name, value in row["noise"].items():
            X = getattr(noisy, name)
            estimate = value * np.sqrt(np.mean(X[j] ** 2))
            assert 0.8 < estimate / (0.01 * np.sqrt(np.mean(getattr(exact, name) ** 2))) < 1.2, (name, row)


def test_states_alone_when_the_derivatives_are_differences(runs):
    """Derivatives that are finite differences of the states are no independent measurement: ``auto``
    fits the states alone then (and the noise still shrinks)."""
    exact, noisy = runs
    data = SecondOrderData(noisy.states, noisy.velocities, noisy.accelerations, times=noisy.times,
                           diagnostics={"derivative_source": "finite_difference"})
    smooth = Smoothing().apply(data)
    assert smooth.diagnostics["smoothing"]["fields"] == "states"
    assert list(smooth.diagnostics["smoothing"]["trajectories"][0][0]["noise"]) == ["states"]
    assert _relative(smooth.states, exact.states) < 0.5 * _relative(noisy.states, exact.states)
    # derivatives that are placeholders (zeros, as after upsampling) are no measurement either
    blank = SecondOrderData(noisy.states, np.zeros_like(noisy.states), np.zeros_like(noisy.states),
                            times=noisy.times)
    assert Smoothing().apply(blank).diagnostics["smoothing"]["fields"] == "states"


def test_each_trajectory_is_smoothed_on_its_own(runs):
    from femrom.inference import concatenate

    exact, noisy = runs
    both = concatenate([noisy, noisy])
    smooth = Smoothing().apply(both)
    one = Smoothing().apply(noisy)
    K = noisy.n_samples
    np.testing.assert_allclose(smooth.states[:, :K], one.states, rtol=0, atol=1e-12)
    np.testing.assert_allclose(smooth.states[:, K:], one.states, rtol=0, atol=1e-12)


def test_lagrangian_opinf_with_smoothing_learns_a_better_stiffness():
    """A linear chain (no quartic springs) with 1 % noise: L-OpInf's stiffness from the smoothed data
    against from the raw data (errors in variables: the raw fit's bias is the noise's)."""
    system = chain(3, kappa=0.0)
    train = [system.run(a, system.t_train, noise=0.01, seed=i) for i, a in enumerate(system.train_amplitudes)]
    K = system.operators.stiffness
    raw = LagrangianOpInf(["damping"]).fit(train)
    smooth = LagrangianOpInf(["damping"], smoothing=True).fit(train)
    assert smooth.describe()["smoothing"]["degree"] == 5 and raw.describe()["smoothing"] is None
    raw_error, smooth_error = _relative(raw.stiffness_, K), _relative(smooth.stiffness_, K)
    assert smooth_error < 0.5 * raw_error, (raw_error, smooth_error)


@pytest.mark.parametrize("options, culprit", [
    ({"degree": 4}, "Smoothing.degree"), ({"degree": 2.0}, "Smoothing.degree"),
    ({"penalty_order": 5}, "Smoothing.penalty_order"), ({"fields": "some"}, "Smoothing.fields"),
    ({"noise_order": 0}, "Smoothing.noise_order"), ({"log_lambda": float("nan")}, "Smoothing.log_lambda"),
    ({"threshold": -1e-3}, "Smoothing.threshold"), ({"threshold": float("inf")}, "Smoothing.threshold")])
def test_bad_settings_are_refused_in_one_line(options, culprit):
    with pytest.raises(FemromError, match=culprit) as info:
        Smoothing(**options)
    assert "\n" not in str(info.value)


def test_bad_data_and_options_are_refused(runs):
    exact, _ = runs
    with pytest.raises(FemromError, match="at least"):
        Smoothing().apply(SecondOrderData(exact.states[:, :10], exact.velocities[:, :10],
                                          exact.accelerations[:, :10], times=exact.times[:10]))
    with pytest.raises(FemromError, match="uniformly sampled"):
        Smoothing().apply(SecondOrderData(exact.states, exact.velocities, exact.accelerations))
    # a threshold (SpML's default "auto") cannot judge such data: they are kept as given, and said so
    unsampled = Smoothing.auto().apply(SecondOrderData(exact.states, exact.velocities, exact.accelerations))
    assert unsampled.states is exact.states
    assert unsampled.diagnostics["smoothing"]["note"] == "not uniformly sampled: kept as given"
    with pytest.raises(FemromError, match="smoothing must be"):
        LagrangianOpInf(["damping"], smoothing="yes")
