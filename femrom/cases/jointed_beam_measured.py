"""Jointed beam from its measured ring-down: a data-only ROM predicting the backbone at untrained amplitudes.

The hammer-impact record of the half Brake-Reuss beam (``hammer_impact.npz``, three accelerometers;
read from ``femrom.post.brb_data_dir()`` or ``--data``) is the only input (``docs/cases/jointed_beam_measured.md``):

1. **Modal coordinates** (:func:`femrom.post.modal_record`): the post-trigger accelerations
   integrated in the mode-1 band (60-100 Hz), the band's transients trimmed, the displacements'
   singular values (how many coordinates the sensors support), ``q``, ``q'``, ``q''`` on the leading shape.
2. **Split by amplitude** where acc1's measured backbone (``femrom.post.measured_backbone``) has fallen
   by ``split`` of its log range. Forward: train on the high amplitudes, predict the low ones; reverse:
   the other way round.
3. **Models** from the learner registry (:class:`femrom.study.ModelSpec`) on ``SecondOrderData`` without
   input: L-OpInf (linear, a flat backbone by construction), SpML (learned mass, potential, convex
   dissipation), SpML with its ``hysteresis`` term (``SpML-sliders``: the same settings, learned sliders in
   place of the convex dissipation) and Iwan-L-OpInf (learned sliders); the last ``validation`` seconds of the training part
   are what SpML and the Iwan fit judge themselves on.
4. **Prediction** from the test part's first state ``(q, q')`` at ``predict_every`` samples (Newmark
   for the sliders, the discrete-gradient scheme otherwise); acc1's predicted signal through the same
   Hilbert processing, the period error removed (:func:`femrom.post.period_corrected`).
5. **Errors** over the test amplitudes both cover: the frequency shift between the highest and the
   lowest (relative to the measured shift), the damping ratio per window, the frequency offset.

Run ``python -m femrom run jointed_beam_measured [-o results/jointed_beam_measured] [--data DIR]``.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom.cases import case_parser
from femrom.inference import LagrangianOpInf, SecondOrderData, SpMLConfig, TrainingSet
from femrom.post import Backbone, hilbert_backbone, measured_backbone, modal_record, period_corrected, plot_backbones, \
    read_hammer_impact, spectral_peaks, staged_output, write_metrics
from femrom.study import ModelSpec, compare_backbones


@dataclass(frozen=True)
class MeasuredRomCase:
    """Settings of the measured-data ROM study (defaults: about a minute on one core).

    band : mode 1's band [Hz]; trim : seconds dropped at each end (band transients);
    window : Hilbert window [s]; rank : ROM coordinates; every : training columns kept
    (every n-th sample); split : fraction of the log-amplitude range trained on (from the
    top in the forward split); validation : seconds at the end of the training part held
    out for SpML's early stopping; predict_every : the ROM's step in samples;
    reverse : also train on the low amplitudes and predict the high ones;
    in_sample : also predict the training part from its first state (how well each model
    reproduces the backbone it was trained on); spml : the SpML settings.
    """

    band: tuple = (60.0, 100.0)
    trim: float = 0.25
    window: float = 0.2
    rank: int = 1
    every: int = 4
    split: float = 0.5
    validation: float = 0.3
    predict_every: int = 4
    reverse: bool = True
    in_sample: bool = True
    iwan: tuple = (("thresholds", 32),)
    spml: SpMLConfig = SpMLConfig(seed=0, potential_widths=(), dissipation_widths=(), polynomial_start=True,
                                  max_iterations=400)


def split_time(measured: Backbone, fraction: float) -> float:
    """Time where acc1's envelope has fallen by ``fraction`` of its log range (windows interpolated)."""
    log_a = np.log(measured.amplitude)
    target = log_a[0] - fraction * (log_a[0] - log_a[-1])
    return float(np.interp(-target, -log_a, measured.time))


def compare(predicted: Backbone, measured: Backbone, low: float, high: float) -> dict:
    """Frequency shift and damping of ``predicted`` against ``measured`` over amplitudes in ``[low, high]``.

    At the windows of ``predicted`` inside ``[low, high]`` and the measured range, the measured backbone
    interpolated there (:func:`femrom.study.compare_backbones` with ``at="model"``); the shift is between
    the lowest and the highest such amplitude on each curve.
    """
    c = compare_backbones(predicted, measured, (low, high), at="model")
    if len(c) < 2:
        return {"windows": len(c)}
    z_p, z_m = c.damping_model, c.damping_reference
    damping_error = c.damping_relative_errors
    return {
        "windows": len(c),
        "amplitude_range": [float(c.amplitude[0]), float(c.amplitude[-1])],
        "shift_predicted_hz": c.shift_model,
        "shift_measured_hz": c.shift_reference,
        "shift_relative_error": float(abs(c.shift_model - c.shift_reference) / abs(c.shift_reference)),
        "frequency_offset_hz": float(np.mean(c.frequency_model - c.frequency_reference)),
        "damping_predicted_percent": [float(100 * z_p[-1]), float(100 * z_p[0])],
        "damping_measured_percent": [float(100 * z_m[-1]), float(100 * z_m[0])],
        "damping_relative_error_max": float(damping_error.max()),
        "damping_relative_error_mean": float(damping_error.mean()),
    }


def linear_fits_by_rank(acc, rate: float, t0: float, train_span, config: "MeasuredRomCase") -> list[dict]:
    """L-OpInf at every rank 1..c on the training part: its modes (frequency, damping) and the
    relative residual of each coordinate's equation (how well a linear oscillator explains it)."""
    rows = []
    for r in range(1, acc.shape[0] + 1):
        data = modal_record(acc, rate, config.band, rank=r, trim=config.trim, every=config.every,
                            start_time=t0).data
        train = data.between(*train_span)
        ops = LagrangianOpInf(["damping"]).fit(train).operators_
        M, C, K = ops.mass_matrix, ops.damping, ops.stiffness
        A = np.block([[np.zeros((r, r)), np.eye(r)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
        poles = np.linalg.eigvals(A)
        poles = poles[poles.imag > 0]
        residual = M @ train.accelerations + C @ train.velocities + K @ train.states
        relative = np.linalg.norm(residual, axis=1) / np.linalg.norm(M @ train.accelerations, axis=1)
        rows.append({"rank": r, "frequencies_hz": (poles.imag / (2 * np.pi)).tolist(),
                     "damping_percent": (-100 * poles.real / np.abs(poles)).tolist(),
                     "coordinate_residuals": relative.tolist()})
    return rows


def fit_models(train: SecondOrderData, validation: SecondOrderData, config: MeasuredRomCase) -> dict:
    """L-OpInf, SpML, SpML with sliders and Iwan-L-OpInf (:class:`femrom.study.ModelSpec`) on the training part, on the modal
    coordinates themselves (identity basis); SpML and the Iwan fit judge themselves on ``validation``."""
    training = TrainingSet(None, np.eye(config.rank), {"train": train}, validation={"validation": validation})
    specs = (ModelSpec("lopinf", "L-OpInf", {"terms": ("damping",)}),
             ModelSpec("spml", "SpML", {"terms": ("damping",), "config": config.spml, "progress": False}),
             ModelSpec("spml", "SpML-sliders", {"terms": ("damping", "hysteresis"), "config": config.spml,
                                                "progress": False}),
             ModelSpec("iwan_lopinf", "Iwan-L-OpInf", {"terms": ("damping",), **dict(config.iwan)}))
    return {spec.label: spec.fit(training, config.rank) for spec in specs}


def predict_backbone(rom, record, q0, v0, start: float, duration: float, config: MeasuredRomCase,
                     rate: float) -> tuple[Backbone, dict]:
    dt = config.predict_every / rate
    times = start + np.arange(int(duration / dt)) * dt
    started = time.perf_counter()
    # the sliders' return mapping steps with Newmark (the same period error as the midpoint rule)
    solution = rom.predict(times, initial=(q0, v0),
                           scheme="newmark" if rom.operators_.stateful else "discrete_gradient")
    seconds = time.perf_counter() - started
    acc1 = record.channel_acceleration(solution.a, 0)
    backbone = hilbert_backbone(acc1, 1 / dt, config.band, window=config.window, start_time=start)
    return period_corrected(backbone, dt), {"predict_seconds": seconds, "steps": len(times), "dt": dt}


def _linear_summary(learner) -> dict:
    ops = learner.operators_
    m, k = float(ops.mass_matrix[0, 0]), float(ops.stiffness[0, 0])
    c = float(ops.damping[0, 0]) if ops.damping is not None else 0.0
    return {"f_linear_hz": float(np.sqrt(k / m) / (2 * np.pi)), "zeta_linear_percent": 100 * c / (2 * np.sqrt(k * m))}


def run(config: MeasuredRomCase, out: Path, progress=print, data_dir=None) -> dict:
    """The study (module docstring); writes ``metrics.json`` and ``backbones_*.png`` into ``out``."""
    out = Path(out)
    record_file = read_hammer_impact(data_dir)
    measured = measured_backbone(record_file, band=config.band, window=config.window, trim=config.trim)
    keep = record_file.time >= 0
    acc = record_file.acceleration[:, keep]
    rate = record_file.sample_rate
    t0 = float(record_file.time[keep][0])
    full = modal_record(acc, rate, config.band, rank=acc.shape[0], trim=config.trim, start_time=t0)
    s = full.singular_values     # how many coordinates the sensors support, and each one's spectral peak
    ranks = {"singular_values": s.tolist(), "relative": (s / s[0]).tolist(), "coordinate_peaks_hz": [
        spectral_peaks(q, rate, min_frequency=40.0, max_frequency=140.0).tolist() for q in full.data.states]}
    progress("singular values of the band displacements (relative): "
             + ", ".join(f"{x:.2e}" for x in ranks["relative"])
             + "; coordinate peaks in 40-140 Hz [Hz]: " + "; ".join(", ".join(f"{p:.2f}" for p in peaks) or "-"
                                                        for peaks in ranks["coordinate_peaks_hz"]))
    record = modal_record(acc, rate, config.band, rank=config.rank, trim=config.trim, every=config.every,
                          start_time=t0)
    data = record.data
    t_first, t_last = float(data.times[0]), float(data.times[-1]) + config.every / rate
    t_split = split_time(measured, config.split)
    a_split = float(np.exp(np.interp(t_split, measured.time, np.log(measured.amplitude))))
    progress(f"split at {t_split:.2f} s (acc1 {a_split:.2f} m/s^2)")
    splits = {"forward": ((t_first, t_split), (t_split, t_last))}       # (train, test) spans [s]
    if config.reverse:
        splits["reverse"] = ((t_split, t_last), (t_first, t_split))
    ranks["linear_fits"] = linear_fits_by_rank(acc, rate, t0, (t_first, t_split), config)
    for row in ranks["linear_fits"]:
        progress(f"L-OpInf at r = {row['rank']} (forward training part): modes "
                 + ", ".join(f"{f:.2f} Hz / {z:.3f} %" for f, z in zip(row["frequencies_hz"], row["damping_percent"]))
                 + "; residual per coordinate " + ", ".join(f"{x:.2g}" for x in row["coordinate_residuals"]))
    metrics = {"config": dataclasses.asdict(config), "rank_check": ranks, "shape": record.shapes[:, 0].tolist(),
               "split_time_s": t_split, "split_amplitude_m_s2": a_split, "measured": measured.rows(), "splits": {}}
    for name, (train_span, test_span) in splits.items():
        progress(f"{name}: train {train_span[0]:.2f}-{train_span[1]:.2f} s, test {test_span[0]:.2f}-{test_span[1]:.2f} s")
        train = data.between(train_span[0], train_span[1] - config.validation)
        validation = data.between(train_span[1] - config.validation, train_span[1])
        models = fit_models(train, validation, config)
        test = data.between(*test_span)
        q0, v0 = test.states[:, 0], test.velocities[:, 0]
        in_test = (measured.time >= test_span[0]) & (measured.time <= test_span[1])
        low, high = float(measured.amplitude[in_test].min()), float(measured.amplitude[in_test].max())
        entry, curves = {"train_s": list(train_span), "test_s": list(test_span),
                         "test_amplitudes_m_s2": [low, high], "models": {}}, {"measured": measured}
        for model, rom in models.items():
            backbone, info = predict_backbone(rom, record, q0, v0, test_span[0], test_span[1] - test_span[0],
                                              config, rate)
            result = compare(backbone, measured, low, high)
            result.update(info, fit_seconds=rom.fit_seconds_, **_linear_summary(rom),
                          predicted=backbone.rows())
            entry["models"][model] = result
            curves[model] = backbone
            if "shift_relative_error" in result:
                progress(f"  {model}: shift {result['shift_predicted_hz']:+.4f} Hz (measured "
                         f"{result['shift_measured_hz']:+.4f}, error {100 * result['shift_relative_error']:.0f} %), "
                         f"damping error max {100 * result['damping_relative_error_max']:.0f} %, "
                         f"offset {result['frequency_offset_hz']:+.4f} Hz")
            if config.in_sample:
                first = data.between(*train_span)
                fitted, _ = predict_backbone(rom, record, first.states[:, 0], first.velocities[:, 0],
                                             train_span[0], train_span[1] - train_span[0], config, rate)
                in_train = (measured.time >= train_span[0]) & (measured.time <= train_span[1])
                result["in_sample"] = compare(fitted, measured, float(measured.amplitude[in_train].min()),
                                              float(measured.amplitude[in_train].max()))
                if "shift_relative_error" in result["in_sample"]:
                    progress(f"    in sample: shift {result['in_sample']['shift_predicted_hz']:+.4f} Hz (measured "
                             f"{result['in_sample']['shift_measured_hz']:+.4f}), damping error max "
                             f"{100 * result['in_sample']['damping_relative_error_max']:.0f} %")
        plot_backbones(out / f"backbones_{name}.png", curves)
        metrics["splits"][name] = entry
    write_metrics(out / "metrics.json", metrics)
    return metrics


def main(argv=None) -> int:
    parser = case_parser("jointed_beam_measured", __doc__,
                         quick="the forward split only, without the in-sample predictions (tests)")
    parser.add_argument("--data", type=Path, help="the folder of hammer_impact.npz (default: femrom.post.brb_data_dir())")
    parser.add_argument("--no-reverse", action="store_true", help="only the forward split (train high, test low)")
    args = parser.parse_args(argv)
    config = MeasuredRomCase(reverse=not (args.no_reverse or args.quick), in_sample=not args.quick)
    with staged_output(args.out) as folder:
        metrics = run(config, folder, progress=lambda line: print(line, file=sys.stderr, flush=True),
                      data_dir=args.data)
    for name, entry in metrics["splits"].items():
        print(f"{name}: " + "; ".join(
            f"{model}: shift error {100 * r['shift_relative_error']:.0f} %, damping error {100 * r['damping_relative_error_max']:.0f} %"
            for model, r in entry["models"].items() if "shift_relative_error" in r))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
