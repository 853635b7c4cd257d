"""Velocity and displacement from an acceleration record by integration in a frequency band."""

import numpy as np
import pytest

from femrom.post import band_limited_integrals

RATE, F, ZETA = 2048.0, 80.0, 0.002


def ring_down(duration=4.0, delay=0.5):
    """A decaying mode starting at ``delay``: exact q, v, a (q = A e^{-z w t} sin(w_d t))."""
    t = np.arange(int(duration * RATE)) / RATE
    s = np.clip(t - delay, 0.0, None)
    w = 2 * np.pi * F
    wd = w * np.sqrt(1 - ZETA**2)
    e = np.exp(-ZETA * w * s) * (t >= delay)
    q = 1e-3 * e * np.sin(wd * s)
    v = 1e-3 * e * (wd * np.cos(wd * s) - ZETA * w * np.sin(wd * s))
    a = 1e-3 * e * ((ZETA**2 * w**2 - wd**2) * np.sin(wd * s) - 2 * ZETA * w * wd * np.cos(wd * s))
    return t, q, v, a


def test_a_ring_down_integrates_to_its_exact_velocity_and_displacement():
    t, q, v, a = ring_down()
    result = band_limited_integrals(a, RATE, (60.0, 100.0))
    # 0.2 s after the blow's onset (a broadband kink the band cannot hold: 3 % of the amplitude at 0.05 s,
    # 3e-4 at 0.2 s, 4e-5 at 0.5 s), the band holds the mode but for its Lorentzian tails
    inside = (t > 0.7) & (t < 3.5)
    assert np.max(np.abs(result.displacement - q)[inside]) < 1e-3 * np.max(np.abs(q))   # measured 3.2e-4
    assert np.max(np.abs(result.velocity - v)[inside]) < 1e-3 * np.max(np.abs(v))       # measured 2.3e-4
    # consistency: v' = a_band and q' = v, up to the central difference's (w h)^2 / 6 = 1.0e-2 at 80 Hz
    dv = np.gradient(result.velocity, 1 / RATE)
    dq = np.gradient(result.displacement, 1 / RATE)
    assert np.max(np.abs(dv - result.acceleration)[inside]) < 1.5e-2 * np.max(np.abs(a))
    assert np.max(np.abs(dq - result.velocity)[inside]) < 1.5e-2 * np.max(np.abs(v))


def test_an_offset_and_a_suspension_mode_do_not_drift_into_the_displacement():
    t, q, v, a = ring_down()
    # an accelerometer offset and a 2 Hz bungee mode: twice-integrated in time they grow without bound
    polluted = a + 0.05 * np.max(np.abs(a)) + 0.05 * np.max(np.abs(a)) * np.sin(2 * np.pi * 2.0 * t)
    result = band_limited_integrals(polluted, RATE, (60.0, 100.0))
    inside = (t > 0.7) & (t < 3.5)
    error = np.max(np.abs(result.displacement - q)[inside]) / np.max(np.abs(q))
    h = 1 / RATE
    naive = np.cumsum(np.cumsum(polluted) * h) * h    # plain double integration
    naive_error = np.max(np.abs(naive - q)[inside]) / np.max(np.abs(q))
    assert error < 1e-3 and naive_error > 100 * error     # measured 3.2e-4 against 7.9e4


def test_several_channels_and_bad_input():
    _, q, _, a = ring_down()
    both = band_limited_integrals(np.vstack([a, 2 * a]), RATE, (60.0, 100.0))
    assert both.displacement.shape == (2, a.size)
    assert np.allclose(both.displacement[1], 2 * both.displacement[0])
    with pytest.raises(ValueError, match="band must satisfy"):
        band_limited_integrals(a, RATE, (0.0, 100.0))
    with pytest.raises(ValueError, match="band must satisfy"):
        band_limited_integrals(a, RATE, (60.0, 1000.0))
    with pytest.raises(ValueError, match="acceleration must be a finite"):
        band_limited_integrals(np.array([1.0, np.nan] * 8), RATE, (60.0, 100.0))
