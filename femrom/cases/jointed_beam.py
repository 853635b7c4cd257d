"""Jointed beam: preload, calibrated modes, backbones (QSMA, ring-down, measured) and stepped sine.

The bolted half Brake-Reuss beam of ``jointed_beam.toml`` (free-free, three bolts at
12 kN, dry-friction interface elements on the lap joint's node pairs), end to end:

1. **Preload and calibration** (:meth:`femrom.study.JointedBeamModel.calibrated`, as in the
   ``jointed_beam_prestress`` case): frictionless preload, friction on, and the one calibrated
   stiffness, the interface's tangential stiffness ``k_t``, set so that the first bending mode
   is the measured 80.5 Hz. The next modes are predictions against the measured 221.7 and 297.7 Hz.
2. **QSMA on the full model with dry friction** (:func:`femrom.post.static_qsma`):
   static loads ``alpha M phi_1`` in Newton on all 24,522 dofs, Masing damping; amplitudes
   as acc1's acceleration. No joint parameter is fitted for this curve.
3. **The Iwan joint** (law ``clamped_iwan``: the preload's contact status and slip traction
   ``mu p_0`` frozen, slip spread over Segalman's Iwan element): ``mu`` the textbook 0.6,
   ``chi`` and ``beta`` fitted on the measured backbone by QSMA of the 10-mode model
   (``--no-fit`` keeps the defaults, the fit's result on the default mesh); QSMA of the full
   and the 10-mode model under it.
4. **Hyper-reduction** (:meth:`femrom.study.JointedBeamModel.hyper_reduced`): short ring-downs of the 10-mode model
   with all pairs at two blows train ECSW, which samples the joint's slip remainder on a few
   weighted pairs (the stuck joint stays exact); validated against all pairs.
5. **The impact ring-down** on the hyper-reduced model: the hammer as a 0.3 ms half-sine,
   linear modal damping from the data (the measured damping at the lowest amplitude),
   acc1's band-passed backbone (60-100 Hz, Hilbert, 0.2 s windows) with Newmark's period
   error removed (:func:`femrom.post.period_corrected`: ``f = tan(pi f_h dt) / (pi dt)``).
6. **The measured backbone** of the same processing (``data/brb/hammer_impact.npz``).
7. **The measured range** (:class:`femrom.study.MeasuredRangeJoint`): the ``clamped_iwan`` joint whose
   points open at the preload touch again (``closing``) with a Hunt-Crossley normal dashpot
   (``closing_damping``); ``mu``, ``closing`` and ``closing_damping`` fitted on the
   response-controlled stepped sine (5-80 m/s^2 at acc3) and the hammer's backbone at acc3
   (``--fit-range`` refits, about 30-40 min; the defaults are that fit's result), with the shaker's
   attached mass read off the data; its modal model hyper-reduced by ECSW trained on periodic
   solutions (:func:`femrom.study.periodic_training`).
8. **The forced response** at the shaker (``shaker1``) by harmonic balance
   (:func:`femrom.study.harmonic_balance_sweep`): 0.2, 0.5, 1 and 1.5 N over 79-81.5 Hz by 0.05 Hz,
   swept upwards as the test does, beside the measured response-controlled levels; and the EPMC
   backbone of mode 1 at acc3 to 90 m/s^2 beside the measured phase-resonance backbone
   (:func:`femrom.post.phase_resonance_backbone`). ``--time-domain`` adds the marched stepped sine of
   the hammer model at 0.2 and 1.5 N (79.6-80.6 Hz by 0.1 Hz; a few minutes).

Run ``python -m femrom run jointed_beam [-o results/jointed_beam] [--quick] [--no-fit] [--fit-range] [--time-domain]``.
"""


from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom.cases import case_parser
from femrom.integrators import HarmonicBalance
from femrom.post import Backbone, DatasetNotFoundError, hilbert_backbone, measured_backbone, period_corrected, phase_resonance_backbone, \
    plot_backbones, plot_forced_response, read_hammer_impact, read_response_controlled, resonance_force, \
    staged_output, static_qsma, with_linear_damping, write_metrics
from femrom.rom import ecsw_joint, hyper_reduced_system
from femrom.study import JointedBeamModel, MeasuredRangeJoint, backbone_shift, compare_backbones, \
    harmonic_balance_sweep, modal_qsma, output_ring_down, periodic_training, stepped_sine_response, with_impulse

SCENE = Path(__file__).with_suffix(".toml")
#: What ``--fit-range`` fits of the measured-range joint (``chi`` stays at its start, Mindlin-Goodman's
#: cubic micro-slip, ``chi = 0``), the AFT's samples a period in each EPMC of the fit, and how the scaled
#: residuals are summed (the largest: the form of the targets, 0.1 Hz and 20 % at every level).
RANGE_FIT_PARAMETERS = ("friction_coefficient", "closing", "closing_damping")
RANGE_FIT_SAMPLES = 16
RANGE_FIT_NORM = "max"
BAND, WINDOW = (60.0, 100.0), 0.2


@dataclass(frozen=True)
class JointedBeamCase(JointedBeamModel):
    """What the case runs: the model chain's settings (:class:`femrom.study.JointedBeamModel`) and the
    case's own (defaults: the default run, a few minutes on 2 cores)."""

    ring_down: float = 3.0                      #: simulated seconds after the blow
    qsma_amplitudes: tuple = tuple(np.round(np.logspace(0, np.log10(32.0), 16), 4))  #: acc1 [m/s^2]
    forced: bool = True
    forced_levels: tuple = (0.2, 0.5, 1.0, 1.5)  #: shaker force amplitudes [N]
    forced_frequencies: tuple = tuple(np.round(np.arange(79.0, 81.5 + 1e-9, 0.05), 3))  #: [Hz], swept upwards
    forced_harmonics: int = 1                    #: harmonic balance's H (docs/cases/jointed_beam.md: accuracy)
    forced_samples: int = 16                     #: its AFT samples per period
    measured_range_joint: MeasuredRangeJoint = MeasuredRangeJoint()
    fit_range: bool = False                      #: refit the measured-range joint (--fit-range)
    range_training_forces: tuple = (0.2, 0.8, 2.0)   #: periodic solutions at 80.3 Hz ECSW trains on [N]
    range_ecsw_tolerance: float = 3e-3
    time_domain: bool = False                    #: also the marched stepped sine of the hammer model
    time_domain_levels: tuple = (0.2, 1.5)
    time_domain_frequencies: tuple = tuple(np.round(np.arange(79.6, 80.6 + 1e-9, 0.1), 3))
    forced_steps_per_period: int = 32
    forced_tolerance: float = 1e-2
    fit_iwan: bool = True                       #: fit chi and beta on the measured backbone (when the data are there)
    fit_start: tuple = (-0.5, 0.5)              #: (chi, beta) the fit starts from
    fit_evaluations: int = 50                   #: Nelder-Mead budget of the fit (one 10-mode QSMA each)


def against_measured(model: Backbone, measured: Backbone, low: float = 1.0) -> dict | None:
    """The model at the measured windows' amplitudes above ``low`` inside both ranges
    (:func:`femrom.study.compare_backbones`): frequency shifts from the lowest such amplitude to the
    highest, damping ratios, and the worst relative damping error."""
    c = compare_backbones(model, measured, (low, np.inf), at="reference")
    if len(c) < 2:
        return None
    return {"amplitudes_m_s2": [float(c.amplitude[0]), float(c.amplitude[-1])],
            "shift_model_hz": c.shift_model, "shift_measured_hz": c.shift_reference,
            "damping_max_relative_error": float(np.max(c.damping_relative_errors)),
            "damping_model": [float(z) for z in c.damping_model],
            "damping_measured": [float(z) for z in c.damping_reference]}


def shift_1_to_30(backbone: Backbone) -> dict:
    """Frequency shift and damping ratios from 1 to 30 m/s^2 at acc1 (inside the backbone's range)."""
    s = backbone_shift(backbone, 1.0, 30.0)
    return {"from_m_s2": s.pop("from_amplitude"), "to_m_s2": s.pop("to_amplitude"), **s}


def response_controlled_peaks(levels, forces) -> list[dict]:
    """What the response-controlled levels say a force-controlled test would peak at: per force ``F``, the
    level amplitude whose smallest force is ``F`` (log-log interpolation between the levels) and the
    frequency of that smallest force (:func:`femrom.post.resonance_force`); ``None`` outside the levels."""
    table = sorted((force, level.level_m_s2, frequency)
                   for level, (frequency, force) in ((level, resonance_force(level)) for level in levels))
    force, amplitude, frequency = (np.array(column) for column in zip(*table))
    rows = []
    for F in forces:
        if not force[0] <= F <= force[-1]:
            rows.append({"force_n": float(F), "amplitude_m_s2": None, "frequency_hz": None})
            continue
        x = np.log(F)
        rows.append({"force_n": float(F), "amplitude_m_s2": float(np.exp(np.interp(x, np.log(force), np.log(amplitude)))),
                     "frequency_hz": float(np.interp(x, np.log(force), frequency))})
    return rows


def measured_range_section(config: JointedBeamCase, setup, damping: float, data_dir, progress, seconds: dict,
                           notes: list) -> dict:
    """Steps 7 and 8 of the module docstring: the measured-range joint, its hyper-reduced modal model, the EPMC
    backbone and the forced response by harmonic balance, against the response-controlled data."""
    levels = None
    try:
        levels = read_response_controlled(data_dir)
    except FileNotFoundError as exc:
        notes.append(f"response-controlled data not found ({exc}); the model's curves are computed without them")
    joint = config.measured_range_joint
    fit = None
    if config.fit_range:
        if levels is None:
            raise DatasetNotFoundError("--fit-range needs the response-controlled data (femrom data fetch brb)")
        progress("jointed beam: fitting the measured-range joint (mu, kappa, lambda; chi fixed) on the "
                 "response-controlled and hammer backbones at acc3 (EPMC per evaluation) ...")
        hammer = measured_backbone(read_hammer_impact(None if data_dir is None else Path(data_dir)), channel="acc3")
        fit = config.fit_measured_range(setup, phase_resonance_backbone(levels), hammer, damping, start=joint,
                                        parameters=RANGE_FIT_PARAMETERS, samples=RANGE_FIT_SAMPLES,
                                        norm=RANGE_FIT_NORM, progress=progress)
        joint = fit.pop("joint")
        seconds["fit_measured_range"] = fit["seconds"]
    dashpot = f", closing damping {joint.closing_damping:.3g} Pa s/m^2" if joint.closing_damping else ""
    progress(f"jointed beam: measured-range joint (mu {joint.friction_coefficient:.3g}, chi {joint.chi:+.3g}, "
             f"beta {joint.beta:.3g}, closing {joint.closing:.3g}{dashpot}, shaker mass {1e3 * joint.shaker_mass:.3g} g) "
             "...")
    clock = time.perf_counter()
    reduced, z0 = config.measured_range(setup, joint, damping)
    peak_frequency = 80.3
    snapshots = periodic_training(reduced, z0, 1, peak_frequency, config.range_training_forces,
                                  harmonics=config.forced_harmonics, samples=config.forced_samples)
    sampling = ecsw_joint(reduced, snapshots, z0, tolerance=config.range_ecsw_tolerance)
    hyper, z_hyper = hyper_reduced_system(reduced, sampling, z0)
    seconds["measured_range_model"] = time.perf_counter() - clock
    progress(f"  ECSW on {len(snapshots)} periodic states: {sampling.pairs.size} of {sampling.n_pairs} pairs, "
             f"residual {sampling.residual:.2g} ({seconds['measured_range_model']:.1f} s)")
    # the sampled joint against every pair at the largest force, near its peak
    check = {}
    for name, model, state in (("all_pairs", reduced, z0), ("hyper", hyper, z_hyper)):
        hb = HarmonicBalance(model, 1, harmonics=config.forced_harmonics, samples=config.forced_samples, state=state)
        omega = 2 * np.pi * 80.4
        check[name] = float(omega**2 * abs(hb.phasor(hb.solve(omega, max(config.forced_levels)).coefficients)[2]))
    validation = {"force_n": max(config.forced_levels), "frequency_hz": 80.4, "acc3_all_pairs_m_s2": check["all_pairs"],
                  "acc3_hyper_m_s2": check["hyper"],
                  "relative_difference": check["hyper"] / check["all_pairs"] - 1.0}
    progress("jointed beam: EPMC backbone of mode 1 at acc3 (H = 3) ...")
    clock = time.perf_counter()
    _, backbone = config.measured_range_backbone(hyper, z_hyper, harmonics=3, samples=16)
    seconds["epmc_backbone"] = time.perf_counter() - clock
    progress(f"jointed beam: forced response by harmonic balance (H = {config.forced_harmonics}, "
             f"{config.forced_samples} samples), {len(config.forced_levels)} levels x "
             f"{len(config.forced_frequencies)} frequencies ...")
    sweep = harmonic_balance_sweep(hyper, z_hyper, 1, config.forced_frequencies, config.forced_levels,
                                   harmonics=config.forced_harmonics, samples=config.forced_samples,
                                   progress=lambda line: progress(f"  {line}"))
    seconds["forced_response_hb"] = sweep["seconds"]
    peaks = []
    for row in sweep["rows"]:
        points = row["outputs"]["acc3"]
        k = int(np.argmax([p["amplitude_m_s2"] for p in points]))
        peaks.append({"force_n": row["force_n"], "amplitude_m_s2": points[k]["amplitude_m_s2"],
                      "frequency_hz": points[k]["frequency_hz"]})
    backbones = {"epmc (model, shaker attached)": backbone}
    result = {"joint": joint.parameters(), "fit": fit, "hyper_reduction": {**sampling.describe(),
              "training": f"periodic solutions at {peak_frequency} Hz, forces {list(config.range_training_forces)} N",
              "validation": validation},
              "backbone_epmc_acc3": [{"amplitude_m_s2": float(a), "frequency_hz": float(f), "damping_ratio": float(z)}
                                     for a, f, z in zip(backbone.amplitude, backbone.frequency_hz,
                                                        backbone.damping_ratio)],
              "peaks": peaks, "newton_iterations_per_point": float(np.mean(sweep["iterations"])),
              "forced_response": sweep["rows"], "_backbones": backbones, "_measured_levels": levels}
    if levels is not None:
        measured = phase_resonance_backbone(levels)
        backbones["measured, response-controlled (phase resonance)"] = measured
        try:
            backbones["measured, hammer (no shaker)"] = measured_backbone(
                read_hammer_impact(None if data_dir is None else Path(data_dir)), channel="acc3")
        except FileNotFoundError:
            pass
        la = np.log(backbone.amplitude)
        f_model = np.interp(np.log(measured.amplitude), la, backbone.frequency_hz)
        z_model = np.interp(np.log(measured.amplitude), la, backbone.damping_ratio)
        result["against_response_controlled"] = [
            {"amplitude_m_s2": float(a), "frequency_measured_hz": float(fm), "frequency_model_hz": float(f),
             "frequency_difference_hz": float(f - fm), "damping_measured": float(zm), "damping_model": float(z),
             "damping_relative_error": float(z / zm - 1.0)}
            for a, fm, f, zm, z in zip(measured.amplitude, measured.frequency_hz, f_model, measured.damping_ratio,
                                       z_model)]
        expected = response_controlled_peaks(levels, [p["force_n"] for p in peaks])
        for peak, estimate in zip(peaks, expected):
            peak["response_controlled_estimate"] = estimate
    return result


def run(config: JointedBeamCase, out: Path, progress=print, data_dir=None) -> dict:
    tic = time.perf_counter()
    progress("jointed beam: preload and k_t calibration on f1 = 80.5 Hz ...")
    setup = config.calibrated(config.scene(SCENE))
    beam, system = setup.beam, setup.system
    f1 = setup.f1
    linear = setup.linear_predictions()
    progress(f"  {system.n_dofs} dofs, k_t = {setup.tangential_stiffness:.4g} Pa/m, f1 = {f1:.3f} Hz; predictions "
             + ", ".join(f"{p['measured_hz']} -> {p['model_hz']:.1f} Hz ({100 * p['error']:+.2f} %)"
                         for p in linear["predictions"]))
    backbones, notes = {}, []
    measured = None
    try:
        record = read_hammer_impact(None if data_dir is None else Path(data_dir) / "hammer_impact.npz")
        measured = measured_backbone(record)
        backbones["measured"] = measured
    except FileNotFoundError as exc:
        notes.append(f"measured data not found ({exc}); the measured backbone is left out")
    damping = float(measured.damping_ratio[np.argmin(measured.amplitude)]) if measured is not None else 0.0014
    modes = setup.modes
    common = {"mode": modes.shapes[:, 6], "supports": setup.left_face, "rigid_modes": modes.shapes[:, :6],
              "progress": lambda line: progress(f"  {line}")}
    seconds = {}
    progress(f"jointed beam: QSMA on the full model, dry friction ({len(config.qsma_amplitudes)} static loads) ...")
    clock = time.perf_counter()
    static = static_qsma(system, config.qsma_amplitudes, reference=beam.preload.displacement,
                         state=beam.preload.state, **common)
    seconds["qsma_fom_dry"] = time.perf_counter() - clock

    # the Iwan joint: chi and beta fitted on the measured backbone (mu the textbook value)
    iwan = {"mu": config.friction_coefficient, "chi": config.iwan_chi, "beta": config.iwan_beta, "fitted": False}
    if config.fit_iwan and measured is not None:
        progress("jointed beam: fitting the Iwan joint's chi and beta on the measured backbone (10-mode QSMA) ...")
        fit = config.fit_iwan_on(setup, measured, damping, config.qsma_amplitudes, start=config.fit_start,
                                 evaluations=config.fit_evaluations, progress=progress)
        iwan.update(chi=fit["chi"], beta=fit["beta"], fitted=True, fit=fit)
        seconds["fit"] = fit["seconds"]
    model, q_iwan, z_iwan = config.iwan_joint(setup, chi=iwan["chi"], beta=iwan["beta"])
    progress(f"jointed beam: QSMA on the full model, Iwan joint (chi {iwan['chi']:+.3f}, beta {iwan['beta']:.3f}) ...")
    clock = time.perf_counter()
    static_iwan = static_qsma(model, config.qsma_amplitudes, reference=q_iwan, state=z_iwan, **common)
    seconds["qsma_fom_iwan"] = time.perf_counter() - clock
    reduced = config.reduced(setup, model, q_iwan, z_iwan, damping)
    clock = time.perf_counter()
    curve_reduced = modal_qsma(reduced, z_iwan, config.qsma_amplitudes, damping)
    seconds["qsma_reduced_iwan"] = time.perf_counter() - clock
    # QSMA's damping is the joint's alone: the linear modal damping of the other models adds to it
    backbones["fom_qsma"] = with_linear_damping(static.backbone(0), damping)
    backbones["fom_qsma_iwan"] = with_linear_damping(static_iwan.backbone(0), damping)
    backbones["reduced_qsma_iwan"] = curve_reduced

    # hyper-reduction: ECSW trained on short all-pair ring-downs
    dt = config.dt(setup)
    training, sampling, hyper, z_hyper = config.hyper_reduced(reduced, z_iwan, dt, progress=progress)
    for peak, training_run in training.runs.items():
        seconds[f"training_{peak:g}_n"] = training_run.seconds
    seconds["all_pairs_ms_per_step"] = next(iter(training.runs.values())).ms_per_step
    progress(f"  {sampling.pairs.size} of {sampling.n_pairs} pairs, training residual {sampling.residual:.2g}")
    validation = config.hyper_validation(training, hyper, z_hyper, dt)
    curve_hyper = modal_qsma(hyper, z_hyper, config.qsma_amplitudes, damping)
    backbones["hyper_qsma_iwan"] = curve_hyper
    validation["qsma_max_frequency_difference_hz"] = float(np.max(np.abs(curve_hyper.frequency_hz
                                                                         - curve_reduced.frequency_hz)))
    validation["qsma_max_damping_difference"] = float(np.max(np.abs(curve_hyper.damping_ratio
                                                                    - curve_reduced.damping_ratio)))
    progress(f"jointed beam: hyper-reduced model, {config.impact_peak:g} N blow, {config.ring_down:g} s ring-down ...")
    blow = output_ring_down(with_impulse(hyper, config.impact_peak, config.impact_width), z_hyper, config.ring_down,
                            dt)
    acc = blow.accelerations
    seconds["ring_down"] = blow.seconds
    backbones["transient"] = period_corrected(hilbert_backbone(acc[0], 1.0 / dt, BAND, window=WINDOW), dt)
    time_domain = None
    if config.time_domain:
        progress(f"jointed beam: marched stepped sine of the hammer model, {len(config.time_domain_levels)} levels x "
                 f"{len(config.time_domain_frequencies)} frequencies ...")
        tic_forced = time.perf_counter()
        # beside each point the stuck joint's (linear) response at that force
        _, time_domain = stepped_sine_response(hyper, z_hyper, 1, config.time_domain_frequencies,
                                               config.time_domain_levels,
                                               steps_per_period=config.forced_steps_per_period,
                                               tolerance=config.forced_tolerance, linear_key="linear_amplitude_m_s2",
                                               progress=lambda line: progress(f"  {line}"))
        seconds["stepped_sine_time_domain"] = time.perf_counter() - tic_forced
        # the same model and points by harmonic balance (H = 3, 64 samples): the march's steady state
        # against the periodic solution (their difference: the march's tolerance and its period error)
        clock = time.perf_counter()
        check = harmonic_balance_sweep(hyper, z_hyper, 1, config.time_domain_frequencies, config.time_domain_levels,
                                       harmonics=3, samples=64)
        seconds["stepped_sine_hb_same_points"] = time.perf_counter() - clock
        for marched, balanced in zip(time_domain, check["rows"]):
            for name, points in marched["outputs"].items():
                for point, other in zip(points, balanced["outputs"][name]):
                    point["hb_amplitude_m_s2"] = other["amplitude_m_s2"]
                    point["hb_relative_difference"] = point["amplitude_m_s2"] / other["amplitude_m_s2"] - 1.0
    measured_range = measured_range_section(config, setup, damping, data_dir, progress, seconds, notes) \
        if config.forced else None

    out.mkdir(parents=True, exist_ok=True)
    plot_backbones(out / "backbone.png", backbones, title="jointed beam, mode 1 at acc1",
                   amplitude_label="acc1 amplitude [m/s^2]")
    rows = {name: [{"amplitude_m_s2": r["amplitude"], "frequency_hz": r["frequency_hz"],
                    "damping_ratio": r["damping_ratio"]} for r in b.rows()] for name, b in backbones.items()}
    metrics = {
        "case": "jointed_beam", "n_dofs": system.n_dofs, "mesh": dict(beam.fom.scene.structure.parameters),
        "calibration": {"parameter": "tangential_stiffness", "value_pa_per_m": setup.tangential_stiffness,
                        "target_f1_hz": 80.5, "f1_hz": f1, "eigensolves": setup.evaluations},
        **linear,
        "joint": {"law_dry_model": "dry_friction", "law_dynamics": "clamped_iwan",
                  **{k: v for k, v in system.nonlinear.law.parameters().items() if k != "name"},
                  "iwan": {k: v for k, v in iwan.items()}},
        "linear_damping_ratio": damping,
        "backbone": rows,
        "shift_1_to_30_m_s2": {name: shift_1_to_30(b) for name, b in backbones.items()},
        "against_measured": {} if measured is None else {
            name: against_measured(b, measured) for name, b in backbones.items() if name != "measured"},
        "hyper_reduction": {**sampling.describe(), "training_impacts_n": list(config.training_impacts),
                            "training_window_s": config.training_window, "validation": validation},
        "transient_model": f"{config.n_modes} elastic modes of the prestressed beam (Galerkin about the preload), "
                           f"the clamped_iwan joint sampled on {sampling.pairs.size} of {sampling.n_pairs} "
                           "interface pairs (ECSW, the stuck joint exact)",
        "reduced_model": {"n_modes": config.n_modes, "dt": dt, "steps": acc.shape[1] - 1,
                          "seconds": blow.seconds, "ms_per_step": blow.ms_per_step,
                          "all_pairs_ms_per_step": seconds["all_pairs_ms_per_step"],
                          "newton_iterations": blow.newton_iterations, "impact_peak_n": config.impact_peak,
                          "impact_width_s": config.impact_width},
        "seconds": {**seconds, "total": time.perf_counter() - tic},
        "notes": notes,
    }
    if time_domain is not None:
        metrics["stepped_sine_time_domain"] = time_domain
    if measured_range is not None:
        metrics["forced_response"] = measured_range.pop("forced_response")
        metrics["measured_range"] = {k: v for k, v in measured_range.items() if not k.startswith("_")}
        plot_forced_response(out / "forced_response.png", metrics["forced_response"], output="acc3",
                             measured=measured_range["_measured_levels"],
                             title="jointed beam: acc3 at the shaker, harmonic balance")
        plot_backbones(out / "backbone_acc3.png", measured_range["_backbones"],
                       title="jointed beam, mode 1 at acc3: measured range", amplitude_label="acc3 amplitude [m/s^2]")
    metrics["seconds"]["total"] = time.perf_counter() - tic
    write_metrics(out / "metrics.json", metrics)
    return metrics


def main(argv=None) -> int:
    parser = case_parser("jointed_beam", __doc__, quick="short ring-down and few QSMA loads (tests)")
    parser.add_argument("--no-forced", action="store_true",
                        help="skip the measured-range joint, its forced response and EPMC backbone")
    parser.add_argument("--fit-range", action="store_true",
                        help="refit the measured-range joint on the response-controlled and hammer data (20-30 min)")
    parser.add_argument("--time-domain", action="store_true",
                        help="also march the hammer model's stepped sine at 0.2 and 1.5 N (a few minutes)")
    parser.add_argument("--no-fit", action="store_true", help="the Iwan joint's chi and beta as given, not fitted")
    parser.add_argument("--data", type=Path,
                        help="the folder of the jointed-beam data (default: femrom.post.brb_data_dir())")
    args = parser.parse_args(argv)
    config = JointedBeamCase(forced=not args.no_forced, fit_iwan=not args.no_fit, fit_range=args.fit_range,
                             time_domain=args.time_domain)
    if args.quick:
        config = dataclasses.replace(config, ring_down=1.0, qsma_amplitudes=(1.0, 3.0, 10.0, 30.0), fit_iwan=False,
                                     training_impacts=(300.0,), training_window=0.1,
                                     forced_levels=(0.2, 1.5), forced_frequencies=(80.2, 80.3, 80.4),
                                     time_domain_levels=(1.5,), time_domain_frequencies=(80.3, 80.4))
    with staged_output(args.out) as folder:
        metrics = run(config, folder, progress=lambda line: print(line, file=sys.stderr, flush=True),
                      data_dir=args.data)
    shift = metrics["shift_1_to_30_m_s2"]
    print(f"jointed beam: f1 {metrics['calibration']['f1_hz']:.3f} Hz (k_t {metrics['calibration']['value_pa_per_m']:.4g}); "
          + "; ".join(f"{name}: shift {s['frequency_shift_hz']:.3f} Hz" if s["frequency_shift_hz"] is not None
                      else f"{name}: -" for name, s in shift.items())
          + f"; results in {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
