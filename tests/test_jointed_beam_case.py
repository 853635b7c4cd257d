"""The jointed-beam case end to end (quick settings): calibration, predictions, QSMA, the reduced
model's validation against the full model, the ring-down, the metrics the issue asks for."""

import numpy as np
import pytest

from femrom.cases import jointed_beam as case

#: ring-down windows compared with QSMA: the 1 s ring-down's 0.2 s windows at 16.3 down to 12.1 m/s^2,
#: all inside QSMA's 1-30 m/s^2 (measured 4 of 4)
MIN_COMPARED = 4


@pytest.fixture(scope="module")
def metrics(tmp_path_factory, brb_data):
    # the Iwan joint at the fitted chi, beta (the case's defaults; fitting needs the full QSMA grid:
    # test_the_documented_headline_numbers below runs it); the measured backbone from the data
    config = case.JointedBeamCase(ring_down=1.0, qsma_amplitudes=(1.0, 1.76, 3.1, 5.46, 9.61, 16.9, 30.0), fit_iwan=False,
                                  training_impacts=(300.0,), training_window=0.1,
                                  forced_levels=(2e-4, 1.5), forced_frequencies=(80.3, 80.35, 80.4),
                                  time_domain=True, time_domain_levels=(2e-4, 0.05), time_domain_frequencies=(80.3,))
    return case.run(config, tmp_path_factory.mktemp("jointed_beam"), progress=lambda line: None, data_dir=brb_data)


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
    compared = 0
    for row in transient:
        a = np.log(row["amplitude_m_s2"])
        if amplitudes[0] <= a <= amplitudes[-1]:
            f = np.interp(a, amplitudes, [r["frequency_hz"] for r in hyper])
            z = np.interp(a, amplitudes, [r["damping_ratio"] for r in hyper])
            assert row["frequency_hz"] == pytest.approx(f, abs=0.015)
            assert row["damping_ratio"] == pytest.approx(z, rel=0.06)
            compared += 1
    # every window of the ring-down is compared (a backbone out of order or out of range compares none)
    assert compared >= MIN_COMPARED, (compared, len(transient))


def test_the_measured_backbone_is_read_and_compared(metrics):
    measured = metrics["backbone"]["measured"]
    assert measured[0]["amplitude_m_s2"] > 10 * measured[-1]["amplitude_m_s2"]
    # docs/cases/jointed_beam.md: 0.172 Hz from 1 to 23.9 m/s^2 (the same processing of the same file:
    # deterministic; the band admits a change of filter round-off, not of the processing)
    comparison = metrics["against_measured"]["fom_qsma"]
    assert comparison is not None and 0.165 < comparison["shift_measured_hz"] < 0.18
    assert comparison["amplitudes_m_s2"][0] == pytest.approx(1.0, abs=0.05)
    assert comparison["amplitudes_m_s2"][1] == pytest.approx(23.9, abs=0.1)


def test_the_stepped_sine_tends_to_the_stuck_joints_response_at_small_force(metrics):
    tiny, small = metrics["stepped_sine_time_domain"]
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


@pytest.mark.slow
def test_the_documented_headline_numbers(tmp_path, brb_data):
    """The default run of docs/cases/jointed_beam.md (16 QSMA loads, chi and beta fitted on the impact
    data, 3 s ring-down; the stepped sine left out): 150-240 s on 2 shared cores. Measured on the default
    mesh: the Iwan model's shift 1.180 x the measured (0.2027 against 0.1717 Hz from 1 to 23.9 m/s^2),
    its worst damping error 10.8 %; the dry-friction model's 1.226 x and 49.6 %; the ring-down's 1.197 x
    and 12.0 %. The fit, the mesh and the processing are deterministic; the bands admit what a
    different gmsh or BLAS moves (the docs' load-grid dependence of the dry-friction shift, 0.04 in
    the ratio) and each keeps a lower side, so that a model that stops softening or damping, or one
    that agrees by construction, fails."""
    config = case.JointedBeamCase(forced=False)
    assert config.fit_iwan
    metrics = case.run(config, tmp_path / "jointed_beam", progress=lambda line: None, data_dir=brb_data)
    iwan = metrics["joint"]["iwan"]
    assert iwan["fitted"] and -1.0 < iwan["chi"] < 0.0 and iwan["beta"] > 0     # Segalman's range for lap joints
    against = metrics["against_measured"]

    def ratio(name):
        return against[name]["shift_model_hz"] / against[name]["shift_measured_hz"]

    assert 0.165 < against["fom_qsma_iwan"]["shift_measured_hz"] < 0.18            # the documented 0.172 Hz
    # "the Iwan model's is 1.18 times the measured shift": within the factor of 2 by far
    assert 1.13 < ratio("fom_qsma_iwan") < 1.23, ratio("fom_qsma_iwan")
    # "damping within 30 %: met by the Iwan joint (worst error 11 %)"
    assert 0.05 < against["fom_qsma_iwan"]["damping_max_relative_error"] < 0.15
    # "the dry-friction model's 1.23 times", and it misses the damping target (50 %)
    assert 1.15 < ratio("fom_qsma") < 1.33, ratio("fom_qsma")
    assert 0.3 < against["fom_qsma"]["damping_max_relative_error"] < 0.65
    # the reduced and hyper-reduced Iwan models stay near the full one (measured 1.114 and 1.103, 10.2 and 9.2 %)
    for name in ("reduced_qsma_iwan", "hyper_qsma_iwan"):
        assert 1.05 < ratio(name) < 1.23 and against[name]["damping_max_relative_error"] < 0.15, name
    # "transient: 0.125 Hz against 0.104, 12 %" over its own 2.1-15.6 m/s^2
    assert 1.1 < ratio("transient") < 1.3 and 0.05 < against["transient"]["damping_max_relative_error"] < 0.2


def test_the_marched_stepped_sine_agrees_with_harmonic_balance(metrics):
    # the same hyper-reduced model and points, marched to steady state and by harmonic balance (H = 3):
    # the march stops when its amplitude changes by less than 1e-2 a period (forced_tolerance) and
    # steps 32 times a period (Newmark's period error, prewarped at the drive frequency)
    for level in metrics["stepped_sine_time_domain"]:
        for point in level["outputs"]["acc3"]:
            assert abs(point["hb_relative_difference"]) < 0.05, point


def test_the_measured_range_joint_by_harmonic_balance(metrics):
    result = metrics["measured_range"]
    validation = result["hyper_reduction"]["validation"]
    # ECSW trained on periodic solutions against every pair at 1.5 N, 80.4 Hz: measured 8e-4
    assert abs(validation["relative_difference"]) < 0.02
    assert result["hyper_reduction"]["sampled_pairs"] < 0.2 * result["hyper_reduction"]["of_pairs"]
    tiny, large = metrics["forced_response"]
    assert tiny["force_n"] == 2e-4 and large["force_n"] == 1.5
    for level in (tiny, large):
        for name in ("acc1", "acc2", "acc3"):
            assert [p["frequency_hz"] for p in level["outputs"][name]] == [80.3, 80.35, 80.4]
            for point in level["outputs"][name]:
                assert set(point) >= {"frequency_hz", "amplitude_m_s2", "phase_rad", "linear_amplitude_m_s2"}
    # at 2e-4 N the joint barely slips: the response is the stuck joint's to a few per cent (the Iwan
    # density's weakest sliders soften it as amplitude^(1 + chi)); at 1.5 N it is far from it
    for point in tiny["outputs"]["acc3"]:
        assert abs(point["amplitude_m_s2"] / point["linear_amplitude_m_s2"] - 1) < 0.06
    assert all(abs(p["amplitude_m_s2"] / p["linear_amplitude_m_s2"] - 1) > 0.2 for p in large["outputs"]["acc3"])
    # the EPMC backbone reaches the measured range and is compared level by level
    backbone = result["backbone_epmc_acc3"]
    assert backbone[0]["amplitude_m_s2"] < 5 and backbone[-1]["amplitude_m_s2"] > 80
    rows = result["against_response_controlled"]
    assert len(rows) == 8
    # the fitted joint against the measured backbone (docs/cases/jointed_beam.md): every level within
    # 0.2 Hz (measured at most 0.155 Hz, at 40 m/s^2) and the damping within the 20 % (measured
    # -1 to +13 %; the fit without the Hunt-Crossley dashpot missed by -43 % at 80 m/s^2); a model
    # without the reclosing contact keeps softening (0.35 Hz low at 80 m/s^2)
    assert max(abs(r["frequency_difference_hz"]) for r in rows) < 0.2
    assert max(abs(r["damping_relative_error"]) for r in rows) < 0.2
    # the force-controlled peaks the response-controlled levels imply: 1.5 N lies between the 60.2 m/s^2
    # level (smallest force 1.103 N at 80.35 Hz) and the 70.3 m/s^2 one (1.549 N at 80.45 Hz); by hand,
    # log-log: x = ln(1.5 / 1.103) / ln(1.549 / 1.103) = 0.9055, 60.2 (70.3 / 60.2)^x = 69.3 m/s^2 at 80.44 Hz;
    # 2e-4 N is below the lowest level's smallest force (0.0295 N): no estimate
    tiny_peak, large_peak = result["peaks"]
    assert tiny_peak["response_controlled_estimate"]["amplitude_m_s2"] is None
    estimate = large_peak["response_controlled_estimate"]
    assert estimate["amplitude_m_s2"] == pytest.approx(69.3, abs=0.1)
    assert estimate["frequency_hz"] == pytest.approx(80.44, abs=0.01)


@pytest.mark.slow
def test_the_measured_range_fit_reproduces_its_documented_misfit(brb_data):
    """The fit of the measured-range joint (docs/cases/jointed_beam.md: the largest scaled residual 0.963
    at mu 0.4267, kappa 1.213e-4, lambda 1.307e13 with chi = 0, the case's defaults, rounded to 4 digits;
    the case's fitted parameters, AFT samples and norm). Four evaluations from the defaults (a few
    minutes): the first is the defaults' misfit, deterministic up to what a different BLAS moves in EPMC
    (and the 4-digit rounding). Below 1 every level is within 0.1 Hz and 20 %; the band's upper side
    fails the sum-of-squares fit's joint (1.58, its 40 m/s^2 frequency), its lower side a misfit that
    drops the frequency residuals (the largest damping residual is 0.931, the 40 m/s^2 frequency's 0.963)."""
    from femrom.post import measured_backbone, phase_resonance_backbone, read_hammer_impact, \
        read_response_controlled
    from femrom.study import MeasuredRangeJoint
    config = case.JointedBeamCase()
    setup = config.calibrated(config.scene(case.SCENE))
    fit = config.fit_measured_range(setup, phase_resonance_backbone(read_response_controlled(brb_data)),
                                    measured_backbone(read_hammer_impact(brb_data), channel="acc3"), 0.00138,
                                    start=MeasuredRangeJoint(), evaluations=4, progress=lambda line: None,
                                    parameters=case.RANGE_FIT_PARAMETERS, samples=case.RANGE_FIT_SAMPLES,
                                    norm=case.RANGE_FIT_NORM)
    assert fit["evaluations"] == 4 and len(fit["history"]) == 4 and fit["norm"] == "max"
    first = fit["history"][0]
    assert first["friction_coefficient"] == pytest.approx(MeasuredRangeJoint().friction_coefficient)
    assert 0.945 < first["misfit"] < 1.0, first["misfit"]
    assert fit["misfit"] <= first["misfit"]


def test_the_measured_range_joint_refuses_bad_parameters():
    from femrom.study import MeasuredRangeJoint
    for name, value in (("shaker_mass", -1e-3), ("chi", -1.0), ("closing", float("nan")),
                        ("friction_coefficient", 0.0), ("beta", "0.3"), ("closing_damping", -1.0)):
        with pytest.raises(ValueError, match=f"MeasuredRangeJoint: {name}"):
            MeasuredRangeJoint(**{name: value})
    assert MeasuredRangeJoint().closing_damping > 0.0            # the fitted Hunt-Crossley dashpot


def test_the_measured_range_fit_refuses_an_unknown_parameter_in_one_line():
    """Checked before any model is built (the arguments are not looked at)."""
    from femrom._errors import FemromError
    from femrom.study import JointedBeamModel, MeasuredRangeJoint
    fit = JointedBeamModel().fit_measured_range
    with pytest.raises(FemromError) as error:
        fit(None, None, None, 0.00138, parameters=("friction_coefficient", "kappa"))
    assert str(error.value) == ("fit_measured_range: parameters must be among friction_coefficient, chi, closing, "
                                "closing_damping, got 'kappa'")
    for parameters, message in (((), "at least one"), (("chi", "chi"), "distinct")):
        with pytest.raises(FemromError, match=message):
            fit(None, None, None, 0.00138, parameters=parameters)
    with pytest.raises(FemromError, match="closing_damping is fitted on a log scale; start it above 0, got 0.0"):
        fit(None, None, None, 0.00138, parameters=("closing_damping",), start=MeasuredRangeJoint(closing_damping=0.0))
    with pytest.raises(FemromError) as error:
        fit(None, None, None, 0.00138, norm="l1")
    assert str(error.value) == "fit_measured_range: norm must be one of squares, max, got 'l1'"
