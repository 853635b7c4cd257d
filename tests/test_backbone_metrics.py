"""Backbones against each other (femrom.study.compare_backbones, backbone_errors, backbone_shift) and the
backbone maps (femrom.post.period_corrected, with_linear_damping), against closed forms."""

import numpy as np
import pytest

from femrom.post import Backbone, hilbert_backbone, period_corrected, with_linear_damping
from femrom.study import backbone_errors, backbone_shift, compare_backbones


def log_linear(amplitudes, f0, slope, z0, z_slope) -> Backbone:
    """``f = f0 - slope ln A``, ``zeta = z0 + z_slope ln A`` at the given windows: linear in ``ln A``, so
    that the backbone's interpolation is exact between and beyond its windows' values."""
    a = np.asarray(amplitudes, dtype=float)
    return Backbone(time=np.arange(a.size, dtype=float), amplitude=a, frequency_hz=f0 - slope * np.log(a),
                    damping_ratio=z0 + z_slope * np.log(a))


MODEL = log_linear(np.geomspace(0.5, 40.0, 9)[::-1], 80.0, 0.05, 0.002, 0.0004)      # decaying: A falls
REFERENCE = log_linear(np.geomspace(1.0, 30.0, 13), 80.2, 0.04, 0.0015, 0.0005)


def test_log_spaced_comparison_over_the_overlap_of_the_ranges():
    # the range (0.2, 100) is clipped to both backbones': [max(0.2, 0.5, 1), min(100, 40, 30)] = [1, 30]
    errors = backbone_errors(MODEL, REFERENCE, (0.2, 100.0))
    shift_m, shift_r = 0.05 * np.log(30.0), 0.04 * np.log(30.0)
    assert errors["amplitude_range"] == [1.0, 30.0]
    assert errors["frequency_shift_hz"] == pytest.approx(shift_m, rel=1e-12)
    assert errors["reference_shift_hz"] == pytest.approx(shift_r, rel=1e-12)
    assert errors["frequency_shift_error"] == pytest.approx(abs(shift_m - shift_r) / shift_r, rel=1e-10)
    # f_m - f_r = -0.2 - 0.01 ln A: largest at A = 30; zeta_m / zeta_r - 1 worst at one end
    assert errors["frequency_max_difference_hz"] == pytest.approx(0.2 + 0.01 * np.log(30.0), rel=1e-12)
    ends = np.array([1.0, 30.0])
    ratio = (0.002 + 0.0004 * np.log(ends)) / (0.0015 + 0.0005 * np.log(ends)) - 1
    assert errors["damping_max_error"] == pytest.approx(np.max(np.abs(ratio)), rel=1e-10)


def test_a_backbones_own_windows_keep_their_values_and_the_other_is_interpolated():
    c = compare_backbones(MODEL, REFERENCE, (2.0, 20.0), at="model")
    inside = np.sort(MODEL.amplitude[(MODEL.amplitude >= 2.0) & (MODEL.amplitude <= 20.0)])
    np.testing.assert_array_equal(c.amplitude, inside)
    np.testing.assert_array_equal(c.frequency_model, 80.0 - 0.05 * np.log(inside))
    np.testing.assert_allclose(c.frequency_reference, 80.2 - 0.04 * np.log(inside), rtol=1e-13)
    assert c.shift_model == pytest.approx(0.05 * np.log(inside[-1] / inside[0]), rel=1e-12)
    c = compare_backbones(MODEL, REFERENCE, (2.0, 20.0), at="reference")
    inside = REFERENCE.amplitude[(REFERENCE.amplitude >= 2.0) & (REFERENCE.amplitude <= 20.0)]
    np.testing.assert_array_equal(c.amplitude, inside)
    np.testing.assert_allclose(c.damping_model, 0.002 + 0.0004 * np.log(inside), rtol=1e-12)
    # given amplitudes: those inside the overlap, sorted, both interpolated
    c = compare_backbones(MODEL, REFERENCE, at=[50.0, 3.0, 0.7, 10.0])
    np.testing.assert_array_equal(c.amplitude, [3.0, 10.0])
    np.testing.assert_allclose(c.damping_relative_errors,
                               np.abs((0.002 + 0.0004 * np.log(c.amplitude)) / (0.0015 + 0.0005 * np.log(c.amplitude))
                                      - 1), rtol=1e-12)


def test_disjoint_ranges_give_no_comparison():
    low = log_linear([0.1, 0.2, 0.4], 80.0, 0.05, 0.002, 0.0)
    errors = backbone_errors(low, REFERENCE, (0.0, np.inf))
    assert errors["frequency_shift_error"] is None and errors["damping_max_error"] is None
    assert errors["amplitude_range"] == [1.0, 0.4]           # lo > hi: where the ranges would meet
    assert len(compare_backbones(low, REFERENCE, at="model")) == 0
    with pytest.raises(ValueError, match="at must be"):
        compare_backbones(MODEL, REFERENCE, at="linear")


def test_shift_between_two_amplitudes_clipped_to_the_backbone():
    s = backbone_shift(REFERENCE, 0.5, 20.0)          # clipped below to the backbone's 1.0
    assert (s["from_amplitude"], s["to_amplitude"]) == (1.0, 20.0)
    assert s["frequency_shift_hz"] == pytest.approx(0.04 * np.log(20.0), rel=1e-12)
    assert s["damping_low"] == pytest.approx(0.0015, rel=1e-12)
    assert s["damping_high"] == pytest.approx(0.0015 + 0.0005 * np.log(20.0), rel=1e-12)
    assert backbone_shift(REFERENCE, 40.0, 50.0)["frequency_shift_hz"] is None


def test_period_correction_recovers_the_frequency_of_a_newmark_oscillator():
    # x'' + w^2 x = 0 stepped by the average-acceleration rule (written out here), coarse: 16 steps
    # per period; its period is too long, f_h = arctan(pi f dt) / (pi dt) (1.3 % low here)
    f, dt, n = 10.0, 1.0 / 160.0, 4000
    w2 = (2 * np.pi * f) ** 2
    x, v, a = 1.0, 0.0, -w2
    signal = np.empty(n)
    for k in range(n):
        signal[k] = a
        # x+ = x + dt v + dt^2 (a + a+) / 4, a+ = -w2 x+
        x_new = (x + dt * v + dt * dt * a / 4) / (1 + w2 * dt * dt / 4)
        a_new = -w2 * x_new
        v = v + dt * (a + a_new) / 2
        x, a = x_new, a_new
    raw = hilbert_backbone(signal, 1.0 / dt, (5.0, 15.0), window=2.0)
    np.testing.assert_allclose(raw.frequency_hz, np.arctan(np.pi * f * dt) / (np.pi * dt), rtol=1e-5)
    corrected = period_corrected(raw, dt)
    # the Hilbert estimate of a pure tone to 1e-5; the map is exact for a linear oscillator
    np.testing.assert_allclose(corrected.frequency_hz, f, rtol=1e-5)
    np.testing.assert_array_equal(corrected.amplitude, raw.amplitude)
    np.testing.assert_array_equal(corrected.damping_ratio, raw.damping_ratio)


def test_linear_damping_adds_to_the_damping_ratio_only():
    damped = with_linear_damping(REFERENCE, 0.0014)
    np.testing.assert_array_equal(damped.damping_ratio, REFERENCE.damping_ratio + 0.0014)
    np.testing.assert_array_equal(damped.frequency_hz, REFERENCE.frequency_hz)
