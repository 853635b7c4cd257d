"""Data-only ROMs from band-limited multi-channel records (issue 17, part 4).

``femrom.post.modal_record`` on synthetic records with known modal coordinates, then
the jointed beam's measured hammer-impact ring-down (``femrom/cases/jointed_beam_measured.py``;
skipped when the data are absent, ``$FEMROM_BRB_DATA`` or ``femrom data fetch brb``; failed
under ``FEMROM_REQUIRE_DATA``).

The bands on the measured record are regression pins: each was set around the value one run of the
case measured (stated beside it), with no independent reference for the learned models' errors;
a change that moves one past its band needs the run and docs/cases/jointed_beam_measured.md
looked at again, not only the band.
"""

from __future__ import annotations

import numpy as np
import pytest

from femrom.cases import jointed_beam_measured as case
from femrom.post import band_limited_integrals, modal_record

RATE = 2000.0
BAND = (60.0, 100.0)


def _decay(f_hz, zeta, amplitude, t):
    w = 2 * np.pi * f_hz
    return amplitude * np.exp(-zeta * w * t) * np.cos(w * np.sqrt(1 - zeta**2) * t)


def _shapes(c, r, seed=0):
    return np.linalg.qr(np.random.default_rng(seed).standard_normal((c, r)))[0]


def test_two_in_band_modes_are_recovered_exactly_by_their_subspace():
    t = np.arange(4000) / RATE
    modal = np.vstack([_decay(72.0, 0.01, 5.0, t), _decay(91.0, 0.02, 2.0, t)])   # accelerations
    phi = _shapes(3, 2)
    record = modal_record(phi @ modal, RATE, BAND, rank=2, trim=0.1)
    # the channels' band displacement has rank 2: the third singular value is round-off
    # (observed 1.2e-15 relative; 1e-12 leaves room for the FFT's round-off), the second is
    # mode 2's (observed 0.079 s[0]: weaker and faster decaying; > 0.03 says it is seen)
    s = record.singular_values
    assert s[2] < 1e-12 * s[0] and s[1] > 0.03 * s[0]
    # the shapes span the true shapes (projectors equal to round-off)
    np.testing.assert_allclose(record.shapes @ record.shapes.T, phi @ phi.T, atol=1e-10)
    # the coordinates are the true modal band integrals in the recovered frame, exactly
    # (by linearity of the band integration; round-off of two FFTs)
    truth = band_limited_integrals(modal, RATE, BAND)
    R = record.shapes.T @ phi
    kept = slice(200, 4000 - 200)
    for got, ref in ((record.data.states, truth.displacement), (record.data.velocities, truth.velocity),
                     (record.data.accelerations, truth.acceleration)):
        scale = np.abs(ref).max()
        np.testing.assert_allclose(got, R @ ref[:, kept], atol=1e-10 * scale)
    assert record.data.times[0] == pytest.approx(0.1) and record.data.inputs is None
    # acceleration of one channel from modal accelerations
    np.testing.assert_allclose(record.channel_acceleration(record.data.accelerations, 1),
                               (phi @ truth.acceleration)[1, kept], atol=1e-10 * np.abs(modal).max())


def test_one_mode_in_the_band_gives_rank_one_and_its_shape():
    t = np.arange(8000) / RATE
    phi = _shapes(3, 2, seed=1)
    # mode 1 at 80 Hz in the band, mode 2 at 300 Hz (ten times stronger) outside it
    acc = phi @ np.vstack([_decay(80.0, 0.005, 1.0, t), _decay(300.0, 0.005, 10.0, t)])
    record = modal_record(acc, RATE, BAND, rank=1, trim=0.25, every=2)
    s = record.singular_values
    # what leaks of the 300 Hz mode through the band's flanks (the abrupt start) is tiny:
    # observed s2/s1 1.6e-4; 1e-3 bounds it well below the in-band mode
    assert s[1] < 1e-3 * s[0]
    # the shape is mode 1's up to the sign convention (largest entry positive): observed 9e-6 off; 1e-3
    shape = phi[:, 0] * np.sign(phi[np.argmax(np.abs(phi[:, 0])), 0])
    np.testing.assert_allclose(record.shapes[:, 0], shape, atol=1e-3)
    assert record.data.states.shape == (1, (8000 - 1000 + 1) // 2)
    assert record.data.diagnostics["dt"] == pytest.approx(2 / RATE)


@pytest.mark.parametrize("kwargs, word", [({"rank": 4}, "rank"), ({"rank": 0}, "rank"),
                                          ({"every": 0}, "every"), ({"trim": 10.0}, "trim")])
def test_bad_arguments_raise_one_line(kwargs, word):
    acc = np.random.default_rng(0).standard_normal((3, 1000))
    with pytest.raises(ValueError, match=word):
        modal_record(acc, RATE, BAND, **kwargs)


# ----------------------------------------------------------------------------- measured data


@pytest.fixture(scope="module")
def measured(tmp_path_factory, brb_data):
    # the case's defaults; the in-sample predictions (docs only) are left out to keep the test short
    config = case.MeasuredRomCase(in_sample=False)
    return case.run(config, tmp_path_factory.mktemp("brb_measured"), progress=lambda line: None, data_dir=brb_data)


def test_the_three_sensors_support_one_coordinate_in_the_mode_1_band(measured):
    ranks = measured["rank_check"]
    s = ranks["relative"]
    # band displacements 60-100 Hz, 0.25 s trimmed: observed 1, 5.3e-3, 2.7e-4. The second
    # and third directions hold under 0.6 % of the amplitude (noise, phase between sensors):
    # 1e-2 and 1e-3 bound them (regression pin at 2x and 4x the run); a second mode in the band
    # would stand near 1e-1 or above
    assert s[1] < 1e-2 and s[2] < 1e-3
    # the first coordinate is mode 1 alone: one periodogram peak in 40-140 Hz, at 80.50 Hz
    # (the README's 80.5 Hz; 0.1 Hz is a few bins of the 5.1 s record)
    assert len(ranks["coordinate_peaks_hz"][0]) == 1
    assert ranks["coordinate_peaks_hz"][0][0] == pytest.approx(80.5, abs=0.1)
    # the other coordinates show no line of their own (many peaks of similar height: noise)
    assert all(len(p) > 3 for p in ranks["coordinate_peaks_hz"][1:])
    # a linear oscillator explains coordinate 1 to 7.5e-4 (relative residual of its equation);
    # the extra coordinates of r = 2, 3 only to 2.6e-2 and 0.19 (observed): 10x worse at least
    # (regression pin: 2e-3 is 2.7x the measured 7.5e-4)
    fits = {row["rank"]: row for row in ranks["linear_fits"]}
    assert fits[1]["coordinate_residuals"][0] < 2e-3
    assert min(fits[3]["coordinate_residuals"][1:]) > 10 * fits[1]["coordinate_residuals"][0]
    # and the first mode is the same at every rank: 80.44 Hz (the training part's average)
    for row in fits.values():
        assert min(abs(f - 80.44) for f in row["frequencies_hz"]) < 0.01


def test_split_by_amplitude_and_the_measured_shift_on_the_untrained_amplitudes(measured):
    # half the log range of acc1's envelope (23.9 -> 0.654 m/s^2): observed 2.31 s, 3.95 m/s^2
    assert measured["split_amplitude_m_s2"] == pytest.approx(np.sqrt(23.9 * 0.654), rel=0.02)
    forward = measured["splits"]["forward"]["models"]
    # measured frequency rise over the untrained low amplitudes (about 2.7 -> 0.7 m/s^2):
    # observed +0.061 Hz; 0.04-0.08 Hz is the backbone table of docs/backbone.md (regression pin)
    for result in forward.values():
        assert 0.04 < result["shift_measured_hz"] < 0.08


def test_spml_bends_the_backbone_the_right_way_but_misses_the_shift_l_opinf_is_flat(measured):
    forward = measured["splits"]["forward"]["models"]
    lopinf, spml = forward["L-OpInf"], forward["SpML"]
    # L-OpInf is linear: a flat backbone by construction (observed 3e-6 Hz: Hilbert round-off)
    assert abs(lopinf["shift_predicted_hz"]) < 1e-3
    # SpML's learned quartic softens: its frequency rises as the amplitude falls (observed
    # +5.3e-4 Hz), so it is closer to the measured shift than L-OpInf's, but a smooth
    # potential's shift falls as the amplitude squared and the 30 % target is missed
    # (observed error 99 %, docs/cases/jointed_beam_measured.md): the band is 0 < shift < 0.1 x measured
    # (regression pin around the measured +5.3e-4 Hz against +0.061 Hz)
    assert 0 < spml["shift_predicted_hz"] < 0.1 * spml["shift_measured_hz"]
    assert spml["shift_relative_error"] < lopinf["shift_relative_error"]


def test_spml_damping_against_l_opinf_on_untrained_amplitudes(measured):
    # SpML's least-squares stage switches its convex dissipation off on both splits (its random start
    # validates worse than none, and L-BFGS cannot switch it back on: docs/cases/jointed_beam_measured.md,
    # "What the least-squares stage changed"), so its damping is linear like L-OpInf's
    splits = measured["splits"]
    # forward (train high, test low): both keep the training part's damping (observed max relative
    # errors: SpML 0.4829, L-OpInf 0.4833; measured 0.152 -> 0.139 %, predicted 0.206 % by both)
    forward = splits["forward"]["models"]
    assert forward["SpML"]["damping_relative_error_max"] == pytest.approx(
        forward["L-OpInf"]["damping_relative_error_max"], abs=0.03)
    # target missed: both sides stated (regression pin around the measured 0.48)
    assert 0.35 < forward["SpML"]["damping_relative_error_max"] < 0.6
    # SpML's damping is flat over the test amplitudes (observed 0.20583 -> 0.20584 %; pin 2 %)
    low, high = forward["SpML"]["damping_predicted_percent"][1], forward["SpML"]["damping_predicted_percent"][0]
    assert 0.98 * low < high < 1.02 * low
    # reverse (train low, test high): SpML's damping no longer grows with the amplitude (observed
    # 0.149 -> 0.145 % from the lowest to the highest, against the measured 0.174 -> 0.214 %: the same
    # c over the quartic's higher frequency), max error 0.32 against L-OpInf's flat 0.150 % (0.30):
    # the 30 % target missed by both (regression pin around the measured 0.32 and 0.97)
    reverse = splits["reverse"]["models"]
    low, high = reverse["SpML"]["damping_predicted_percent"][1], reverse["SpML"]["damping_predicted_percent"][0]
    assert 0.93 * low < high < 1.01 * low
    assert 0.25 < reverse["SpML"]["damping_relative_error_max"] < 0.4
    assert 0.25 < reverse["L-OpInf"]["damping_relative_error_max"] < 0.4
    # upward, the quartic overshoots the frequency shift (observed 1.08 Hz against 0.043 Hz measured:
    # error 24; regression pin 10-40)
    assert 10 < reverse["SpML"]["shift_relative_error"] < 40


def test_learned_sliders_on_the_untrained_amplitudes(measured):
    splits = measured["splits"]
    forward, reverse = splits["forward"]["models"], splits["reverse"]["models"]
    iwan, spml = forward["Iwan-L-OpInf"], forward["SpML"]
    # forward (train high, test low): the sliders learned on the high amplitudes bend the backbone
    # the measured way, ten times more than SpML's quartic (observed +0.0084 Hz against +0.00053 Hz),
    # but keep only 13 % of the measured +0.064 Hz: the 30 % target is missed (both sides stated;
    # regression pin around the run's values)
    assert 10 * spml["shift_predicted_hz"] < iwan["shift_predicted_hz"] < 0.3 * iwan["shift_measured_hz"]
    # and the damping on the low amplitudes is closer than SpML's and L-OpInf's (observed max
    # relative error 0.27 against 0.48 and 0.48; regression pin at 0.8x)
    assert iwan["damping_relative_error_max"] < 0.8 * min(spml["damping_relative_error_max"],
                                                          forward["L-OpInf"]["damping_relative_error_max"])
    # reverse (train low, test high): the shift stays bounded (observed error 0.65: 0.015 Hz against
    # 0.043 Hz) where SpML's quartic overshoots 24-fold; 1.0 separates the two (regression pin)
    assert reverse["Iwan-L-OpInf"]["shift_relative_error"] < 1.0 < reverse["SpML"]["shift_relative_error"]
    assert reverse["Iwan-L-OpInf"]["shift_predicted_hz"] > 0
