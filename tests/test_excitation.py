"""Sampled training and test inputs: multisine, chirp, band-limited noise, the onset."""

import numpy as np
import pytest

from femrom.scene import band_limited_noise, chirp, multisine, onset, sample_times

DT = 0.01


def _values(signal):
    p = dict(signal.parameters)
    return np.asarray(p["times"]), np.asarray(p["values"])


def test_onset_starts_at_rest_and_reaches_one_smoothly():
    t = sample_times(2.0, DT)
    w = onset(t, 0.5)
    assert w[0] == 0.0 and np.all(w[t >= 0.5] == 1.0)
    assert np.all(np.diff(w) >= 0)
    # the raised cosine's slope is pi / (2 t_r) at most: a step of dt moves it by at most that times dt
    assert np.max(np.diff(w)) <= np.pi / (2 * 0.5) * DT * (1 + 1e-12)
    with pytest.raises(ValueError, match="ramp"):
        onset(t, -1.0)


def test_multisine_is_the_sum_of_its_sines_on_the_grid():
    s = multisine([0.03, 0.02], [0.5, 1.5], [0.0, -2.0], 4.0, DT)
    t, u = _values(s)
    exact = 0.03 * np.sin(2 * np.pi * 0.5 * t) + 0.02 * np.sin(2 * np.pi * 1.5 * t - 2.0)
    np.testing.assert_allclose(u, exact, atol=1e-15)           # the same formula: round-off only
    np.testing.assert_allclose(s(t), exact, atol=1e-15)        # the array signal interpolates its samples
    with pytest.raises(ValueError, match="frequencies must be positive"):
        multisine(1.0, [0.0], [0.0], 1.0, DT)


def test_chirp_sweeps_its_band():
    s = chirp(0.1, 0.2, 2.0, 10.0, DT)
    t, u = _values(s)
    assert np.max(np.abs(u)) <= 0.1
    # zero crossings of sin(2 pi phi(t)) fall every half cycle: the local crossing rate is twice the
    # instantaneous frequency 0.2 + 0.18 t; counted over 1 s windows (a crossing more or less at the ends)
    crossings = t[1:][np.signbit(u[1:]) != np.signbit(u[:-1])]
    for start in (1.0, 5.0, 8.0):
        count = np.count_nonzero((crossings >= start) & (crossings < start + 1))
        expected = 2 * (0.2 + 0.18 * (start + 0.5))
        assert abs(count - expected) <= 1.0, (start, count, expected)


def test_band_limited_noise_has_its_rms_and_no_content_outside_the_band():
    s = band_limited_noise(0.03, (0.5, 2.0), 20.0, DT, seed=3)
    _, u = _values(s)
    assert np.sqrt(np.mean(u ** 2)) == pytest.approx(0.03, rel=1e-12)
    spectrum = np.abs(np.fft.rfft(u)) ** 2
    f = np.fft.rfftfreq(u.size, DT)
    inside = (f >= 0.5) & (f <= 2.0)
    # outside the band only round-off of the inverse transform remains: 1e-20 of the power, bound 1e-12
    assert spectrum[~inside].sum() < 1e-12 * spectrum[inside].sum()
    again = _values(band_limited_noise(0.03, (0.5, 2.0), 20.0, DT, seed=3))[1]
    np.testing.assert_array_equal(u, again)                    # seeded: the same samples
    assert not np.array_equal(u, _values(band_limited_noise(0.03, (0.5, 2.0), 20.0, DT, seed=4))[1])
    with pytest.raises(ValueError, match="Nyquist"):
        band_limited_noise(1.0, (0.1, 80.0), 1.0, DT)
    with pytest.raises(ValueError, match="holds no frequency"):
        band_limited_noise(1.0, (0.1, 1.5), 0.5, DT)
