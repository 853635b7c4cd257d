"""Jointed beam ROMs from model data: SpML (with and without learned sliders), L-OpInf, Iwan-L-OpInf and
Galerkin against the hyper-reduced Iwan model.

Issue 17, part 3. The reference ("FOM" of this study) is the jointed-beam case's 10-mode model with
its ECSW-sampled ``clamped_iwan`` joint (:class:`femrom.study.JointedBeamModel`, the model chain both
cases share; it stands in for the 24,522-dof model, against which it is validated in
``docs/cases/jointed_beam.md``). Its ring-downs after hammer
blows at two levels train the models; a third level is the (interpolation) test, predicted from rest
over ten times the training window. Per r: POD of the 10 modal coordinates, SpML and L-OpInf fitted
on the projected ``q^, q^', q^''`` and the hammer input, Galerkin the reference projected on the same
directions with its sampled joint (``femrom.study.compare_ring_downs``). Once, the per-step cost of the
24,522-dof model with the joint (condensed Newton) is measured, so that step costs compare with the
true FOM too. ``accuracy_cost_<frequency|damping>_<test>.png`` draw each model's backbone errors against
its step's cost, beside the reference's and the full model's steps.

Run ``python -m femrom run jointed_beam_rom [-o results/jointed_beam_rom] [--quick] [--extrapolation]``.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom.cases import case_parser
from femrom.inference import SpMLConfig
from femrom.integrators import Newmark, Newton, SteadyStateCriterion, SteppedSine
from femrom.post import period_corrected, plot_accuracy_cost_groups, plot_backbones, staged_output, write_metrics
from femrom.scene import Signal, SignalVector
from femrom.study import (
    RING_DOWN_COLUMNS,
    JointedBeamModel,
    ModelSpec,
    RingDownComparison,
    SteppedSineTest,
    compare_ring_downs,
    reference_ring_down,
    step_cost,
    with_impulse,
)

SCENE = Path(__file__).with_name("jointed_beam.toml")     # the jointed-beam case's scene
BAND, WINDOW = (60.0, 100.0), 0.2                          # acc1's mode-1 band [Hz] and Hilbert window [s]


@dataclass(frozen=True)
class JointedBeamRomCase:
    """What the study runs (defaults: about ten minutes on 2 shared cores)."""

    training_blows: tuple = (150.0, 600.0)      #: hammer peaks [N] of the training ring-downs
    training_window: float = 0.3                #: their length [s]
    validation_blow: float = 400.0              #: SpML's early-stopping trajectory [N]
    validation_window: float = 0.15
    test_blows: tuple = (300.0,)                #: predicted from rest (300 N: between the training levels)
    horizon_factor: float = 10.0                #: test length / training window
    shaker_training: tuple = (5.0, 80.0)       #: a training run driven by the shaker: (amplitude [N], frequency [Hz])
    ranks: tuple = (1, 3, 5)
    models: tuple = ("galerkin", "lopinf", "spml", "spml_hyst", "iwan", "iwan_band")
    #: IwanLOpInf variants: the regression on all rows, and on rows band-passed around mode 1
    iwan: tuple = (("iwan", ()), ("iwan_band", (("band", (40.0, 150.0)),)))
    spml_iterations: int = 2000
    forced_rank: int = 3                        #: the ROMs that run the stepped sine (0: none)
    forced_levels: tuple = (0.2, 1.5)           #: shaker amplitudes [N] (the jointed-beam case's)
    forced_frequencies: tuple = tuple(np.round(np.arange(79.6, 80.6 + 1e-9, 0.2), 3))
    forced_steps_per_period: int = 32
    forced_tolerance: float = 1e-2
    full_model_steps: int = 30                  #: steps of the 24,522-dof model for its step cost (0: skip)
    damping_ratio: float = 0.00139              #: linear modal damping (the measured lowest-amplitude ratio)


def model_specs(config: JointedBeamRomCase) -> tuple:
    """The compared models as registry specs: the projection, L-OpInf and SpML on damping and input
    terms, SpML with learned sliders (``spml_hyst``: its ``"hysteresis"`` term), and the ``iwan_lopinf``
    variants of ``config.iwan``, in the order of ``config.models``."""
    linear = {"terms": ("damping", "input")}
    spml = SpMLConfig(max_iterations=config.spml_iterations, seed=0)
    specs = {"galerkin": ModelSpec("galerkin"), "lopinf": ModelSpec("lopinf", options=linear),
             "spml": ModelSpec("spml", options={**linear, "config": spml}),
             # the sliders carry the joint's dissipation and softening (no convex dissipation beside them,
             # SpML's default with sliders), the monomials the smooth stiffness: with the potential's
             # network too, the shift missed by 24 % at r = 3 (docs/spml.md, "SpML with learned sliders")
             "spml_hyst": ModelSpec("spml", "spml_hyst", {"terms": ("damping", "input", "hysteresis"),
                                                          "config": dataclasses.replace(spml, potential_widths=())}),
             **{name: ModelSpec("iwan_lopinf", name, {**linear, **dict(options)}) for name, options in config.iwan}}
    return tuple(specs[name] for name in config.models)


def stepped_sines(hyper, rest_state, comparison: dict, config: JointedBeamRomCase, progress=print) -> dict:
    """The stepped sine at the shaker (input 1) on the reference and on the ROMs of rank ``config.forced_rank``
    (:class:`femrom.study.SteppedSineTest`: Newmark, the sensors through each model's basis)."""
    sweep = SteppedSine(np.asarray(config.forced_frequencies), steps_per_period=config.forced_steps_per_period,
                        steady_state=SteadyStateCriterion(tolerance=config.forced_tolerance))
    experiment = SteppedSineTest(hyper, sweep, config.forced_levels, input=1, rest_state=rest_state)
    return experiment.compare({name: model for (name, rank), model in comparison["models"].items()
                               if rank == config.forced_rank}, progress=progress)


def reference_models(config: JointedBeamRomCase, progress=print) -> dict:
    """The jointed-beam case's models (:class:`femrom.study.JointedBeamModel` at its defaults): the full
    model with the Iwan joint at its preloaded rest (``model``, ``q0``, ``z0``), the 10-mode model with
    the ECSW-sampled joint (``hyper``, ``z_hyper``, the reference of this study), ``dt = 1 / (128 f1)``,
    the model chain's settings (``case``) and the seconds taken."""
    tic = time.perf_counter()
    case = JointedBeamModel()
    progress("jointed beam ROMs: preload, k_t calibration, the Iwan joint (chi, beta: the case's fit) ...")
    setup = case.calibrated(case.scene(SCENE))
    model, q_iwan, z_iwan = case.iwan_joint(setup)
    reduced = case.reduced(setup, model, q_iwan, z_iwan, config.damping_ratio)
    f1, dt = setup.f1, case.dt(setup)
    seconds = {"setup": time.perf_counter() - tic}

    progress("jointed beam ROMs: ECSW sample of the joint (the case's training) ...")
    tic_ecsw = time.perf_counter()
    _, sampling, hyper, z_hyper = case.hyper_reduced(reduced, z_iwan, dt)
    seconds["ecsw"] = time.perf_counter() - tic_ecsw
    progress(f"  {sampling.pairs.size} of {sampling.n_pairs} pairs")
    return {"case": case, "model": model, "q0": q_iwan, "z0": z_iwan, "hyper": hyper, "z_hyper": z_hyper,
            "sampling": sampling, "dt": dt, "f1": f1, "seconds": seconds}


def reference_runs(models: dict, config: JointedBeamRomCase, progress=print) -> tuple[list, list, list]:
    """The reference's training runs (the blows and the shaker), validation run and tests ``(run, system)``."""
    case, hyper, z_hyper, dt = models["case"], models["hyper"], models["z_hyper"], models["dt"]

    def blow(peak):
        return with_impulse(hyper, peak, case.impact_width)

    def shaken(amplitude, frequency):
        """The reference driven by the shaker alone (a sine from rest, zero at t = 0)."""
        sine = Signal.from_dict({"kind": "sine", "amplitude": float(amplitude), "frequency": float(frequency)})
        silent = Signal.from_dict({"kind": "impulse", "amplitude": 0.0, "start": 0.0, "duration": case.impact_width})
        return dataclasses.replace(hyper, inputs=SignalVector([silent, sine]))

    progress("jointed beam ROMs: reference ring-downs (10 modes, sampled joint) ...")
    training = [reference_ring_down(blow(p), z_hyper, config.training_window, dt, label=f"{p:g} N")
                for p in config.training_blows]
    if config.shaker_training:
        amplitude, frequency = config.shaker_training
        training.append(reference_ring_down(shaken(amplitude, frequency), z_hyper, config.training_window, dt,
                                            label=f"shaker {amplitude:g} N {frequency:g} Hz"))
    validation = [reference_ring_down(blow(config.validation_blow), z_hyper, config.validation_window, dt,
                                      label=f"{config.validation_blow:g} N")]
    horizon = config.horizon_factor * config.training_window
    tests = [(reference_ring_down(blow(p), z_hyper, horizon, dt, label=f"{p:g} N"), blow(p))
             for p in config.test_blows]
    return training, validation, tests


def run(config: JointedBeamRomCase, out: Path, progress=print) -> dict:
    tic = time.perf_counter()
    models = reference_models(config, progress)
    case, model, q_iwan, z_iwan = models["case"], models["model"], models["q0"], models["z0"]
    hyper, z_hyper, sampling, dt, f1 = (models[k] for k in ("hyper", "z_hyper", "sampling", "dt", "f1"))
    seconds = dict(models["seconds"])

    full_cost = None
    if config.full_model_steps:
        progress(f"jointed beam ROMs: {config.full_model_steps} steps of the full model with the joint ...")
        # seconds per step after a 300 N blow (Newmark, condensed Newton), the first step excluded
        full_cost = step_cost(with_impulse(model, 300.0, 3e-4), q_iwan, z_iwan, dt, config.full_model_steps,
                              scheme=Newmark(newton=Newton(method="condensed")))
        progress(f"  full model: {full_cost['n_dofs']} dofs, {full_cost['seconds_per_step']:.3g} s/step")

    tic_ref = time.perf_counter()
    training, validation, tests = reference_runs(models, config, progress)
    seconds["reference_runs"] = time.perf_counter() - tic_ref
    reference_step = tests[0][0].seconds_per_step

    settings = RingDownComparison(ranks=config.ranks, models=model_specs(config), band=BAND, window=WINDOW,
                                  range_window=0.05, range_trim=0.05)
    progress(f"jointed beam ROMs: models at r = {', '.join(map(str, config.ranks))} ...")
    tic_cmp = time.perf_counter()
    comparison = compare_ring_downs(hyper, z_hyper, training, validation, tests, settings,
                                    correction=lambda b: period_corrected(b, dt),
                                    progress=lambda line: progress(line))
    seconds["comparison"] = time.perf_counter() - tic_cmp
    rows = comparison["rows"]
    for row in rows:
        row["speedup_vs_reference"] = reference_step / row["seconds_per_step"]
        if full_cost is not None:
            row["speedup_vs_full_model"] = full_cost["seconds_per_step"] / row["seconds_per_step"]

    forced = None
    if config.forced_rank and config.forced_levels:
        progress(f"jointed beam ROMs: stepped sine at {', '.join(f'{F:g}' for F in config.forced_levels)} N, "
                 f"{len(config.forced_frequencies)} frequencies, reference and r = {config.forced_rank} ROMs ...")
        tic_forced = time.perf_counter()
        forced = stepped_sines(hyper, z_hyper, comparison, config, progress)
        seconds["stepped_sine"] = time.perf_counter() - tic_forced

    out.mkdir(parents=True, exist_ok=True)
    for run_, _ in tests:
        curves = {("reference" if m == "reference" else f"{m} r={r}"): b
                  for (m, r, label), b in comparison["backbones"].items() if label == run_.label}
        plot_backbones(out / f"backbone_{run_.label.replace(' ', '')}.png", curves,
                       title=f"jointed beam ROMs, {run_.label} blow, acc1", amplitude_label="acc1 amplitude [m/s^2]")
    for error, what in (("frequency_shift_error", "frequency shift"), ("damping_max_error", "damping")):
        for run_, _ in tests:
            shown = [row for row in rows if row["test"] == run_.label and row[error] is not None]
            plot_accuracy_cost_groups(
                out / f"accuracy_cost_{error.split('_')[0]}_{run_.label.replace(' ', '')}.png", shown,
                "seconds_per_step", error, "r", "model",
                title=f"jointed beam ROMs, {run_.label} blow: {what} error against the step's cost",
                marks={"reference (10 modes, ECSW)": reference_step,
                       "full model": None if full_cost is None else full_cost["seconds_per_step"]})
    backbones = {f"{m}/{r}/{label}": [{"amplitude_m_s2": x["amplitude"], "frequency_hz": x["frequency_hz"],
                                       "damping_ratio": x["damping_ratio"]} for x in b.rows()]
                 for (m, r, label), b in comparison["backbones"].items()}
    metrics = {
        "case": "jointed_beam_rom", "columns": list(RING_DOWN_COLUMNS),
        "reference": f"{case.n_modes}-mode model about the preload, clamped_iwan joint sampled on "
                     f"{sampling.pairs.size} of {sampling.n_pairs} pairs (ECSW)",
        "config": dataclasses.asdict(config), "dt": dt, "f1_hz": f1,
        "trained_amplitude_range_m_s2": comparison["amplitude_range"],
        "pod_singular_values": [float(s) for s in comparison["singular_values"]],
        "reference_seconds_per_step": reference_step,
        "full_model": full_cost,
        "rows": rows, "backbones": backbones,
        "stepped_sine": None if forced is None else {
            "rank": config.forced_rank, "rows": forced["rows"],
            "responses": {name: result.rows() for name, result in forced["results"].items()}},
        "seconds": {**seconds, "total": time.perf_counter() - tic},
    }
    write_metrics(out / "metrics.json", metrics)
    return metrics


def main(argv=None) -> int:
    parser = case_parser("jointed_beam_rom", __doc__, quick="r = 2 only, short fits, no full-model steps, "
                        "a two-frequency stepped sine at 0.2 N")
    parser.add_argument("--extrapolation", action="store_true", help="also test a 1000 N blow (outside training)")
    parser.add_argument("--ranks", type=int, nargs="+", help="reduced dimensions (default 1 3 5)")
    args = parser.parse_args(argv)
    config = JointedBeamRomCase()
    if args.quick:
        config = dataclasses.replace(config, ranks=(2,), spml_iterations=200, full_model_steps=0, horizon_factor=3.0,
                                     forced_rank=2, forced_levels=(0.2,), forced_frequencies=(79.8, 80.2))
    if args.ranks:
        config = dataclasses.replace(config, ranks=tuple(args.ranks))
    if config.forced_rank not in config.ranks:
        config = dataclasses.replace(config, forced_rank=0)
    if args.extrapolation:
        config = dataclasses.replace(config, test_blows=config.test_blows + (1000.0,))
    with staged_output(args.out) as folder:
        metrics = run(config, folder, progress=lambda line: print(line, file=sys.stderr, flush=True))
    for row in metrics["rows"]:
        print(f"{row['model']:9s} r={row['r']} {row['test']}: shift error {row['frequency_shift_error']}, "
              f"damping error {row['damping_max_error']}, time error {row['time_domain_error']:.3g}, "
              f"{1e3 * row['seconds_per_step']:.3g} ms/step, fit {row['fit_seconds']:.1f} s, stable {row['stable']}")
    for row in (metrics["stepped_sine"] or {}).get("rows", []):
        print(f"stepped sine {row['model']:9s} {row['force_n']:g} N: peak {row['peak_frequency_hz']:.3f} Hz "
              f"({row['peak_frequency_difference_hz']:+.3f} from the reference), amplitude error "
              f"{100 * row['peak_amplitude_error']:+.1f} % at the peak, {100 * row['amplitude_max_error']:.1f} % worst")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
