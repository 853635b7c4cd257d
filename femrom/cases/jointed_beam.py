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
7. The stepped-sine forced response of the hyper-reduced model at the shaker (``shaker1``):
   by default 0.2 and 1.5 N at 79.6-80.6 Hz in 0.1 Hz steps; ``--full-sweep`` the
   issue's 0.2, 0.5, 1 and 1.5 N at 79-81.5 Hz in 0.05 Hz steps; beside each point the stuck
   joint's linear response at that force (:func:`femrom.study.stepped_sine_response`).

Run ``python -m femrom run jointed_beam [-o results/jointed_beam] [--full-sweep] [--quick] [--no-fit]``.
"""


from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom.cases import case_parser
from femrom.post import Backbone, hilbert_backbone, measured_backbone, period_corrected, plot_backbones, \
    read_hammer_impact, staged_output, static_qsma, with_linear_damping, write_metrics
from femrom.study import JointedBeamModel, backbone_shift, compare_backbones, modal_qsma, output_ring_down, \
    stepped_sine_response, with_impulse

SCENE = Path(__file__).with_suffix(".toml")
BAND, WINDOW = (60.0, 100.0), 0.2


@dataclass(frozen=True)
class JointedBeamCase(JointedBeamModel):
    """What the case runs: the model chain's settings (:class:`femrom.study.JointedBeamModel`) and the
    case's own (defaults: the default run, a few minutes on 2 cores)."""

    ring_down: float = 3.0                      #: simulated seconds after the blow
    qsma_amplitudes: tuple = tuple(np.round(np.logspace(0, np.log10(32.0), 16), 4))  #: acc1 [m/s^2]
    forced: bool = True
    forced_levels: tuple = (0.2, 1.5)            #: shaker force amplitudes [N] (--full-sweep: 0.2, 0.5, 1, 1.5)
    forced_frequencies: tuple = tuple(np.round(np.arange(79.6, 80.6 + 1e-9, 0.1), 3))  #: (--full-sweep: 79-81.5 by 0.05)
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
    forced = None
    if config.forced:
        progress(f"jointed beam: stepped sine, {len(config.forced_levels)} levels x "
                 f"{len(config.forced_frequencies)} frequencies ...")
        tic_forced = time.perf_counter()
        # beside each point the stuck joint's (linear) response at that force: the nonlinearity is their
        # difference; at small forces they agree to the steady-state tolerance
        _, forced = stepped_sine_response(hyper, z_hyper, 1, config.forced_frequencies, config.forced_levels,
                                          steps_per_period=config.forced_steps_per_period,
                                          tolerance=config.forced_tolerance, linear_key="linear_amplitude_m_s2",
                                          progress=lambda line: progress(f"  {line}"))
        seconds["stepped_sine"] = time.perf_counter() - tic_forced

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
    if forced is not None:
        metrics["forced_response"] = forced
    write_metrics(out / "metrics.json", metrics)
    return metrics


def main(argv=None) -> int:
    parser = case_parser("jointed_beam", __doc__, quick="short ring-down and few QSMA loads (tests)")
    parser.add_argument("--full-sweep", action="store_true",
                        help="the stepped sine at 0.2, 0.5, 1, 1.5 N over 79-81.5 Hz by 0.05 Hz (about 40 min)")
    parser.add_argument("--no-forced", action="store_true", help="skip the stepped sine")
    parser.add_argument("--no-fit", action="store_true", help="the Iwan joint's chi and beta as given, not fitted")
    parser.add_argument("--data", type=Path, help="the folder of hammer_impact.npz (default: femrom.post.brb_data_dir())")
    args = parser.parse_args(argv)
    config = JointedBeamCase(forced=not args.no_forced, fit_iwan=not args.no_fit)
    if args.full_sweep:
        config = dataclasses.replace(config, forced_levels=(0.2, 0.5, 1.0, 1.5),
                                     forced_frequencies=tuple(np.round(np.arange(79.0, 81.5 + 1e-9, 0.05), 3)))
    if args.quick:
        config = dataclasses.replace(config, ring_down=1.0, qsma_amplitudes=(1.0, 3.0, 10.0, 30.0), fit_iwan=False,
                                     training_impacts=(300.0,), training_window=0.1,
                                     forced_levels=(1.5,), forced_frequencies=(80.3, 80.4))
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
