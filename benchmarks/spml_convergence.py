"""SpML where its model class contains the truth: what each stage of the fit costs and buys.

Systems from ``tests/_spml_systems.py`` (unit mass, linear damping, a polynomial potential of
degree <= 4, released from rest at four training amplitudes, one validation amplitude, an unseen
test amplitude; exact data from DOP853 at rtol 1e-13, or 1 % Gaussian noise of each field's RMS):
``chain3`` (the issue's reproduction), ``duffing2`` and ``chain8`` (r = 8, for the training time).
Fits, all with ``SpML(["damping"])`` and ``SpMLConfig(seed=0)`` otherwise:

- ``lbfgs``: L-BFGS alone from step 1 (``least_squares=False``, the former default);
- ``default``: least squares, L-BFGS, least squares again (the default);
- ``rollout``: the default and a rollout refinement (8 samples a window from every 8th sample,
  2 substeps, at most 30 iterations);
- ``smoothed``: the default on trajectories denoised first (:class:`femrom.inference.Smoothing`,
  its defaults: one spline per coordinate through the states, velocities and accelerations), the
  equation-error fit alone (``output_error=False``);
- ``output_error``: the same and the output-error stage after it (SpML's defaults on noisy data:
  the raw trajectories simulated, Levenberg-Marquardt on the noise-weighted misfit).

With noise, ``--seeds`` repeats each fit on independent noise draws (the table then adds the median
and range per system and fit).

Each row: training seconds (one thread), seconds per stage, the final training loss against the
truth's loss on the same data, the split of :func:`femrom.study.spml_error_split` (potential,
dissipation, mass, frequency and decay rates at rest), and the unseen amplitude's prediction error
(discrete gradient at dt / 8) over the training window's length and three times it; the truth's own
prediction error (the scheme's floor) for reference.

Run ``python -m benchmarks.spml_convergence [--systems chain3 duffing2 chain8] [--fits ...] [--seeds 0 1 2]``;
it prints a table and writes ``benchmarks/results/spml_convergence.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path


from benchmarks.spml_systems import SYSTEMS, chain, predict, prediction_errors
from femrom.inference import Smoothing, SpML, SpMLConfig
from femrom.study import spml_error_split

ROOT = Path(__file__).resolve().parents[1]

FAMILIES = {**SYSTEMS, "chain8": lambda: chain(8)}
FITS = {
    "lbfgs": {"least_squares": False},
    "default": {},
    "rollout": {"rollout_steps": 8, "rollout_stride": 8, "rollout_substeps": 2, "rollout_iterations": 30},
    "smoothed": {"output_error": False},
    "output_error": {"output_error": True},
}
#: Fits on denoised trajectories.
SMOOTHED = {"smoothed", "output_error"}


def run(system_name: str, fit: str, noise: float, seed: int = 0) -> dict:
    import torch

    torch.set_num_threads(1)
    system = FAMILIES[system_name]()
    train, validation = system.training(noise, seed)
    test = system.test(3.0)
    tic = time.perf_counter()
    learner = SpML(["damping"], config=SpMLConfig(seed=0, **FITS[fit]), progress=False,
                   smoothing=Smoothing() if fit in SMOOTHED else None).fit(train, validation=validation)
    seconds = time.perf_counter() - tic
    split = spml_error_split(learner.operators_, system.operators, train, test, predict=predict)
    errors = prediction_errors(learner.operators_, system, test)
    return {"system": system_name, "r": system.r, "fit": fit, "noise": noise, "seed": seed,
            "training_seconds": seconds,
            "iterations": learner.iterations_,
            "stages": [{k: v for k, v in s.items()} for s in learner.stages_],
            "split": split.as_dict(), "window": errors["window"], "total": errors["total"]}


def table(rows: list) -> str:
    head = ("| system | noise | seed | fit | train s | stages (s) | loss / truth's | force | dissipation | mass | "
            "freq | decay | window | 3 windows | conservative only | dissipative only |")
    lines = [head, "|" + "---|" * 16]
    for row in rows:
        s = row["split"]
        stages = ", ".join(f"{st['stage'].replace('least squares', 'LS')} {st['seconds']:.1f}"
                           for st in row["stages"][1:])
        lines.append(f"| {row['system']} | {row['noise']:g} | {row.get('seed', 0)} | {row['fit']} | "
                     f"{row['training_seconds']:.1f} | "
                     f"{stages} | {s['loss']:.2e} / {s['truth_loss']:.1e} | {s['potential']:.1e} | "
                     f"{s['dissipation']:.1e} | {s['mass']:.1e} | {s['linear_frequency']:.1e} | "
                     f"{s['linear_decay']:.1e} | {row['window']:.1e} | {row['total']:.1e} | "
                     f"{s['prediction_conservative']:.1e} | {s['prediction_dissipative']:.1e} |")
    return "\n".join(lines)


def spread(rows: list) -> str:
    """Median (min-max) of each error over the seeds, per system, noise and fit."""
    import numpy as np

    keys = ("potential", "dissipation", "mass")
    groups = {}
    for row in rows:
        groups.setdefault((row["system"], row["noise"], row["fit"]), []).append(row)
    lines = ["| system | noise | fit | seeds | force | dissipation | mass | window | 3 windows |", "|" + "---|" * 9]
    for (system, noise, fit), group in groups.items():
        cells = []
        for values in ([r["split"][k] for r in group] for k in keys):
            cells.append(f"{np.median(values):.1e} ({min(values):.1e}-{max(values):.1e})")
        for key in ("window", "total"):
            values = [r[key] for r in group]
            cells.append(f"{np.median(values):.1e} ({min(values):.1e}-{max(values):.1e})")
        lines.append(f"| {system} | {noise:g} | {fit} | {len(group)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--systems", nargs="+", default=["chain3", "duffing2", "chain8"], choices=sorted(FAMILIES))
    parser.add_argument("--fits", nargs="+", default=list(FITS), choices=list(FITS))
    parser.add_argument("--noise", nargs="+", type=float, default=[0.0, 0.01])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0], help="noise seeds (noisy data only)")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "spml_convergence.json"))
    args = parser.parse_args(argv)
    rows, floors = [], {}
    for name in args.systems:
        system = FAMILIES[name]()
        floors[name] = prediction_errors(system.operators, system, system.test(3.0))
        for noise in args.noise:
            for seed in (args.seeds if noise else [0]):
                for fit in args.fits:
                    rows.append(run(name, fit, noise, seed))
                    print(table(rows[-1:]).splitlines()[-1], flush=True)
    print(table(rows))
    if len(args.seeds) > 1:
        print(spread(rows))
    print("the truth at dt / 8 (the scheme's floor):",
          {k: (f"{v['window']:.1e}", f"{v['total']:.1e}") for k, v in floors.items()})
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
                                          "floors": floors, "rows": rows}, indent=2, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
