"""The jointed-beam case end to end (quick settings): calibration, predictions, QSMA, the reduced
model's validation against the full model, the ring-down, the metrics the issue asks for."""

import numpy as np
import pytest

import _required
from femrom.cases import jointed_beam as case


@pytest.fixture(scope="module")
def metrics(tmp_path_factory):
    # the Iwan joint at the fitted chi, beta (the case's defaults; fitting needs the full QSMA grid)
    config = case.JointedBeamCase(ring_down=1.0, qsma_amplitudes=(1.0, 1.76, 3.1, 5.46, 9.61, 16.9, 30.0), fit_iwan=False,
                                  training_impacts=(300.0,), training_window=0.1,
                                  forced_levels=(2e-4, 0.05), forced_frequencies=(80.3,))
    return case.run(config, tmp_path_factory.mktemp("jointed_beam"), progress=lambda line: None)


def test_one_calibrated_stiffness_and_two_predicted_modes(metrics):
    calibration = metrics["calibration"]
    assert calibration["parameter"] == "tangential_stiffness"
    assert abs(calibration["f1_hz"] / 80.5 - 1) < 3e-3          # target 0.3 %; the root find gives 1e-7
    first, second = metrics["predictions"]
    # measured on the default mesh: 220.21 Hz (-0.67 %) and 303.10 Hz (+1.81 %); target 3 %
    assert abs(first["error"]) < 0.03 and abs(second["error"]) < 0.03
    assert first["shape"].startswith("in-plane bending") and second["shape"].startswith("vertical bending")
    assert metrics["linear_frequencies_hz"][0] == pytest.approx(80.5, rel=1e-6)


def test_qsma_of_the_full_reduced_and_hyper_reduced_iwan_models(metrics):
    f1 = metrics["calibration"]["f1_hz"]
    rows = metrics["backbone"]
    # 1 m/s^2 with dry friction: every pair stuck, the loading curve is the linearised mode's (an eigenvalue)
    assert rows["fom_qsma"][0]["frequency_hz"] == pytest.approx(f1, rel=1e-6)
    # the Iwan joint micro-slips from the lowest loads (its weakest sliders): measured 80.464 Hz at 1 m/s^2
    full, reduced, hyper = rows["fom_qsma_iwan"], rows["reduced_qsma_iwan"], rows["hyper_qsma_iwan"]
    assert f1 - 0.1 < full[0]["frequency_hz"] < f1 - 0.01
    shift = full[0]["frequency_hz"] - full[-1]["frequency_hz"]
    assert shift > 0.1                                           # measured 0.246 Hz from 1 to 30 m/s^2
    for a, b, c in zip(full, reduced, hyper):
        # the 10-mode model against the 24,522-dof one under the same law: measured 0.016 Hz apart at
        # 30 m/s^2 (7 % of the shift: the modes miss some local flexibility of the slipping pairs)
        assert abs(a["frequency_hz"] - b["frequency_hz"]) < 0.15 * shift
        assert b["damping_ratio"] == pytest.approx(a["damping_ratio"], rel=0.1)
        # the sampled joint against all pairs: measured 0.0035 Hz and 1.7e-5 in damping ratio at most
        assert abs(c["frequency_hz"] - b["frequency_hz"]) < 0.05 * shift
        assert c["damping_ratio"] == pytest.approx(b["damping_ratio"], rel=0.05)
    for name in ("fom_qsma", "fom_qsma_iwan"):     # the joint slips: softer and more damped at 30 m/s^2
        assert rows[name][-1]["frequency_hz"] < f1 - 0.02
        assert rows[name][-1]["damping_ratio"] > rows[name][0]["damping_ratio"] * 1.1
    sampling = metrics["hyper_reduction"]
    assert sampling["sampled_pairs"] < 0.2 * sampling["of_pairs"]          # measured 46 of 592 (default run)
    assert sampling["validation"]["300_n_acc1_max_error"] < 1e-2           # measured 8e-4


def test_the_ring_down_follows_the_quasi_static_backbone(metrics):
    transient = metrics["backbone"]["transient"]
    assert len(transient) >= 3
    assert 5.0 < transient[0]["amplitude_m_s2"] < 60.0   # a 300 N blow: measured 16.3 m/s^2 in the first window
    for row in transient:
        assert set(row) == {"amplitude_m_s2", "frequency_hz", "damping_ratio"}
    # the decaying joint softens less and damps less: frequency rises, damping falls as the amplitude decays
    assert transient[-1]["frequency_hz"] > transient[0]["frequency_hz"] + 0.02
    assert transient[-1]["damping_ratio"] < transient[0]["damping_ratio"]
    # a dynamic route against the quasi-static one on the same (sampled) model (Masing's rules hold for
    # this law): Newmark's period error removed, on the default run's 16 loads they agree to measured
    # 0.002-0.007 Hz and 0.6-2.9 % in damping over 2-16 m/s^2; here QSMA has 7 loads, interpolated in
    # log amplitude, and the bounds are 2x those
    hyper = metrics["backbone"]["hyper_qsma_iwan"]
    amplitudes = np.log([r["amplitude_m_s2"] for r in hyper])
    for row in transient:
        a = np.log(row["amplitude_m_s2"])
        if amplitudes[0] <= a <= amplitudes[-1]:
            f = np.interp(a, amplitudes, [r["frequency_hz"] for r in hyper])
            z = np.interp(a, amplitudes, [r["damping_ratio"] for r in hyper])
            assert row["frequency_hz"] == pytest.approx(f, abs=0.015)
            assert row["damping_ratio"] == pytest.approx(z, rel=0.06)


def test_the_measured_backbone_is_compared_when_the_data_are_there(metrics):
    if "measured" not in metrics["backbone"]:     # the case leaves it out, with a note, without the data
        _required.missing(f"jointed-beam data absent: {metrics['notes']}", _required.DATA)
    measured = metrics["backbone"]["measured"]
    assert measured[0]["amplitude_m_s2"] > 10 * measured[-1]["amplitude_m_s2"]
    comparison = metrics["against_measured"]["fom_qsma"]
    assert comparison is not None and comparison["shift_measured_hz"] > 0.1


def test_the_stepped_sine_tends_to_the_stuck_joints_response_at_small_force(metrics):
    tiny, small = metrics["forced_response"]
    assert tiny["force_n"] == 2e-4 and small["force_n"] == 0.05
    assert tiny["all_converged"] and small["all_converged"]
    deviation = {}
    for level in (tiny, small):
        for name in ("acc1", "acc2", "acc3"):
            (point,) = level["outputs"][name]
            assert set(point) >= {"frequency_hz", "amplitude_m_s2", "phase_rad"}
        (point,) = level["outputs"]["acc1"]
        deviation[level["force_n"]] = abs(point["amplitude_m_s2"] / point["linear_amplitude_m_s2"] - 1)
    # the Iwan joint's softening vanishes as the amplitude^(1 + chi) = amplitude^0.5: at 2e-4 N (0.03 m/s^2)
    # the resonance is some 0.007 Hz below the stuck one, 0.2 Hz above the drive: a few % at most
    assert deviation[2e-4] < 0.06
    assert deviation[0.05] > 2 * deviation[2e-4]       # at 0.05 N (8 m/s^2) the joint clearly slips
    assert small["outputs"]["acc1"][0]["amplitude_m_s2"] > 2.0   # near resonance: a real response
