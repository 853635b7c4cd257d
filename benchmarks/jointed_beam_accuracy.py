"""What accuracy costs in the jointed-beam model: Craig-Bampton-free modal size and ECSW sample size.

Two sweeps on the case's model (default mesh, 24,522 dofs, 592 interface pairs, the
``clamped_iwan`` joint at the case's default chi and beta), each against its own reference
measured in the same run:

- **modes**: the Galerkin model about the preload with ``--modes`` elastic modes (all pairs):
  its QSMA backbone of mode 1 (16 loads, 1-32 m/s^2 at acc1) against the full model's, the
  worst frequency and damping differences and the total shift, and the QSMA time;
- **sample**: ECSW at ``--tolerances`` on the 10-mode model (trained as the case trains it):
  the sampled pairs, the QSMA differences against all pairs, acc1's worst error over a
  0.15 s ring-down at 300 N, and the mean step time over that ring-down (medians of
  ``--repeats`` alternating blocks, the all-pair model's in the same blocks).

Run ``python -m benchmarks.jointed_beam_accuracy`` (about 10 minutes); it prints
two tables and writes ``benchmarks/results/jointed_beam_accuracy.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from femrom.cases import jointed_beam as case
from femrom.post import static_qsma, with_linear_damping
from femrom.rom import ecsw_joint, hyper_reduced_system
from femrom.study import ecsw_training, modal_qsma, output_ring_down, with_impulse

RESULTS = Path(__file__).resolve().parent / "results" / "jointed_beam_accuracy.json"


def differences(curve, reference) -> dict:
    f = np.interp(np.log(reference.amplitude), np.log(curve.amplitude), curve.frequency_hz)
    z = np.interp(np.log(reference.amplitude), np.log(curve.amplitude), curve.damping_ratio)
    shift = float(curve.frequency_hz[0] - curve.frequency_hz[-1])
    return {"max_frequency_difference_hz": float(np.max(np.abs(f - reference.frequency_hz))),
            "max_damping_relative_difference": float(np.max(np.abs(z / reference.damping_ratio - 1))),
            "shift_hz": shift}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--modes", type=int, nargs="+", default=[4, 6, 10, 16])
    parser.add_argument("--tolerances", type=float, nargs="+", default=[3e-2, 1e-2, 3e-3, 1e-3])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    config = case.JointedBeamCase(n_modes=max(args.modes))
    setup = config.calibrated(config.scene(case.SCENE))
    model, q0, z0 = config.iwan_joint(setup)
    damping = 0.00139
    modes = setup.modes
    tic = time.perf_counter()
    full = static_qsma(model, config.qsma_amplitudes, reference=q0, state=z0, mode=modes.shapes[:, 6],
                       supports=setup.left_face, rigid_modes=modes.shapes[:, :6])
    full_seconds = time.perf_counter() - tic
    reference = with_linear_damping(full.backbone(0), damping)  # linear + joint
    rows_modes = []
    for n in args.modes:
        reduced = dataclasses.replace(config, n_modes=n).reduced(setup, model, q0, z0, damping)
        tic = time.perf_counter()
        curve = modal_qsma(reduced, z0, config.qsma_amplitudes, damping)
        rows_modes.append({"modes": n, **differences(curve, reference), "qsma_seconds": time.perf_counter() - tic})
    rows_modes.append({"modes": "full", **differences(reference, reference), "qsma_seconds": full_seconds})

    reduced = case.JointedBeamCase().reduced(setup, model, q0, z0, damping)
    dt = config.dt(setup)
    snapshots = ecsw_training(reduced, z0, config.training_impacts, width=config.impact_width,
                              window=config.training_window, dt=dt).snapshots
    all_curve = modal_qsma(reduced, z0, config.qsma_amplitudes, damping)
    blow = with_impulse(reduced, 300.0, config.impact_width)
    models = {"all": (blow, z0)}
    samples = {}
    for tolerance in args.tolerances:
        sampling = ecsw_joint(reduced, snapshots, z0, tolerance=tolerance)
        hyper, z_hyper = hyper_reduced_system(reduced, sampling, z0)
        curve = modal_qsma(hyper, z_hyper, config.qsma_amplitudes, damping)
        models[tolerance] = (with_impulse(hyper, 300.0, config.impact_width), z_hyper)
        samples[tolerance] = {"tolerance": tolerance, "pairs": int(sampling.pairs.size),
                              "training_residual": sampling.residual, **differences(curve, all_curve)}
    seconds = {key: [] for key in models}
    accelerations = {}
    for _ in range(args.repeats):
        for key, (system_, state) in models.items():
            run = output_ring_down(system_, state, config.training_window, dt)
            seconds[key].append(run.seconds / (run.accelerations.shape[1] - 1))
            accelerations[key] = run.accelerations[0]
    base = statistics.median(seconds["all"])
    for tolerance, row in samples.items():
        step = statistics.median(seconds[tolerance])
        row["acc1_max_error"] = float(np.max(np.abs(accelerations[tolerance] - accelerations["all"]))
                                      / np.max(np.abs(accelerations["all"])))
        row["ms_per_step"] = 1e3 * step
        row["step_ratio_to_all_pairs"] = step / base
    result = {"machine": platform.platform(), "modes_sweep": rows_modes, "sample_sweep": list(samples.values()),
              "all_pairs_ms_per_step": 1e3 * base, "pairs": int(reduced.nonlinear.force_model.n_pairs),
              "repeats": args.repeats}
    print("| modes | max |f - f_full| (Hz) | max damping difference | shift 1-32 m/s^2 (Hz) | QSMA s |\n|---|---|---|---|---|")
    for row in rows_modes:
        print(f"| {row['modes']} | {row['max_frequency_difference_hz']:.4f} | "
              f"{100 * row['max_damping_relative_difference']:.1f} % | {row['shift_hz']:.3f} | {row['qsma_seconds']:.2f} |")
    print("\n| ECSW tolerance | pairs | max |f - f_all| (Hz) | acc1 error | ms/step | / all pairs |\n|---|---|---|---|---|---|")
    for row in samples.values():
        print(f"| {row['tolerance']:g} | {row['pairs']} | {row['max_frequency_difference_hz']:.4f} | "
              f"{row['acc1_max_error']:.1e} | {row['ms_per_step']:.2f} | {row['step_ratio_to_all_pairs']:.2f} |")
    print(f"all {result['pairs']} pairs: {result['all_pairs_ms_per_step']:.2f} ms/step")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=1))
    print(f"written: {RESULTS}")


if __name__ == "__main__":
    main()
