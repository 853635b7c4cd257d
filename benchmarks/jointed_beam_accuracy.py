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
from femrom.rom import ecsw_joint, hyper_reduced_system

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
    setup = case.prestressed(config)
    beam, system = setup["beam"], setup["system"]
    supports = case.point_supports(beam.fom.space, system.condensation, case.prestress.SUPPORTS[:3])
    model, q0, z0 = case.iwan_joint(setup, supports, mu=config.friction_coefficient, chi=config.iwan_chi,
                                    beta=config.iwan_beta)
    damping = 0.00139
    modes = setup["modes"]
    tic = time.perf_counter()
    full, _ = case.qsma(model, config.qsma_amplitudes, reference=q0, state=z0, phi=modes.shapes[:, 6],
                        supports=supports, rigid_modes=modes.shapes[:, :6], progress=lambda line: None)
    full_seconds = time.perf_counter() - tic
    reference = full.backbone(0)
    reference = dataclasses.replace(reference, damping_ratio=reference.damping_ratio + damping)  # linear + joint
    rows_modes = []
    for n in args.modes:
        reduced = case.reduced_model(setup, case.JointedBeamCase(n_modes=n), model, q0, z0, damping)
        curve, seconds = case.reduced_qsma(reduced, z0, config.qsma_amplitudes, damping)
        rows_modes.append({"modes": n, **differences(curve, reference), "qsma_seconds": seconds})
    rows_modes.append({"modes": "full", **differences(reference, reference), "qsma_seconds": full_seconds})

    reduced = case.reduced_model(setup, case.JointedBeamCase(), model, q0, z0, damping)
    f1 = float(modes.frequencies[6])
    dt = 1.0 / (config.steps_per_period * f1)
    snapshots = case.ecsw_training(reduced, z0, config, dt)[0]
    all_curve, _ = case.reduced_qsma(reduced, z0, config.qsma_amplitudes, damping)
    blow = case.with_blow(reduced, 300.0, config.impact_width)
    models = {"all": (blow, z0)}
    samples = {}
    for tolerance in args.tolerances:
        sampling = ecsw_joint(reduced, snapshots, z0, tolerance=tolerance)
        hyper, z_hyper = hyper_reduced_system(reduced, sampling, z0)
        curve, _ = case.reduced_qsma(hyper, z_hyper, config.qsma_amplitudes, damping)
        models[tolerance] = (case.with_blow(hyper, 300.0, config.impact_width), z_hyper)
        samples[tolerance] = {"tolerance": tolerance, "pairs": int(sampling.pairs.size),
                              "training_residual": sampling.residual, **differences(curve, all_curve)}
    seconds = {key: [] for key in models}
    accelerations = {}
    for _ in range(args.repeats):
        for key, (system_, state) in models.items():
            acc, sec, _, _ = case.ring_down(system_, state, config.training_window, dt)
            seconds[key].append(sec / (acc.shape[1] - 1))
            accelerations[key] = acc[0]
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
