"""The jointed beam's forced response marched in time and by harmonic balance: cost and agreement.

The model: the jointed-beam case's hyper-reduced Iwan model (10 modes, the ``clamped_iwan`` joint
sampled by ECSW on ring-downs; Newmark is energy-stable for this law), driven on the shaker at
``--levels`` over ``--frequencies``. Per repeat, alternating:

- ``time``: the marched stepped sine (:func:`femrom.study.stepped_sine_response`: 32 steps a period,
  steady state to 1e-2 of the amplitude a period, from rest at each level);
- ``hb1`` / ``hb3``: :func:`femrom.study.harmonic_balance_sweep` at H = 1 and H = 3 with 16 samples
  (each point from the previous one, chord steps);
- ``hb_reference``: H = 7, 128 samples, once, the reference of the amplitudes.

Reported: seconds per run (median and range over the repeats), ratio to the time march's median,
and the largest relative difference of acc3's amplitude from the reference. Run
``python -m benchmarks.forced_response_cost`` (about 3 minutes on 2 cores); it prints a table and
writes ``benchmarks/results/forced_response_cost.json`` (``--out``). The case's full grid:
``--levels 0.2 0.5 1 1.5 --frequencies $(seq 79 0.05 81.5) --repeats 1 --out
benchmarks/results/forced_response_cost_grid.json`` (about 15 minutes).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from femrom.cases.jointed_beam import SCENE, JointedBeamCase
from femrom.study import harmonic_balance_sweep, stepped_sine_response

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "forced_response_cost.json"


def acc3(rows):
    return np.array([[p["amplitude_m_s2"] for p in row["outputs"]["acc3"]] for row in rows])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=float, nargs="+", default=[0.2, 1.5])
    parser.add_argument("--frequencies", type=float, nargs="+",
                        default=list(np.round(np.arange(79.8, 80.6 + 1e-9, 0.1), 3)))
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS, help="the JSON written (default %(default)s)")
    args = parser.parse_args(argv)
    config = JointedBeamCase()
    setup = config.calibrated(config.scene(SCENE))
    model, q0, z0 = config.iwan_joint(setup)
    reduced = config.reduced(setup, model, q0, z0, 0.00138)
    _, sampling, hyper, z_hyper = config.hyper_reduced(reduced, z0, config.dt(setup))
    frequencies, levels = np.array(args.frequencies), list(args.levels)
    runs = {
        "time": lambda: stepped_sine_response(hyper, z_hyper, 1, frequencies, levels, steps_per_period=32,
                                              tolerance=1e-2)[1],
        "hb1": lambda: harmonic_balance_sweep(hyper, z_hyper, 1, frequencies, levels, harmonics=1, samples=16)["rows"],
        "hb3": lambda: harmonic_balance_sweep(hyper, z_hyper, 1, frequencies, levels, harmonics=3, samples=16)["rows"],
    }
    reference = acc3(harmonic_balance_sweep(hyper, z_hyper, 1, frequencies, levels, harmonics=7, samples=128)["rows"])
    seconds = {name: [] for name in runs}
    errors = {}
    for _ in range(args.repeats):
        for name, run in runs.items():
            tic = time.perf_counter()
            rows = run()
            seconds[name].append(time.perf_counter() - tic)
            errors[name] = float(np.max(np.abs(acc3(rows) / reference - 1)))
    base = statistics.median(seconds["time"])
    table = [{"method": name, "seconds_median": statistics.median(s), "seconds_min": min(s), "seconds_max": max(s),
              "ratio_to_time": statistics.median(s) / base, "max_relative_difference_acc3": errors[name]}
             for name, s in seconds.items()]
    print(f"{len(levels)} levels x {len(frequencies)} frequencies, {sampling.pairs.size} sampled pairs")
    print("| method | s (median) | range | / time march | max rel. diff. acc3 vs H = 7, N = 128 |")
    print("|---|---|---|---|---|")
    for row in table:
        print(f"| {row['method']} | {row['seconds_median']:.2f} | {row['seconds_min']:.2f}-{row['seconds_max']:.2f} | "
              f"{row['ratio_to_time']:.3f} | {row['max_relative_difference_acc3']:.2e} |")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                                   "levels_n": levels, "frequencies_hz": frequencies.tolist(),
                                   "sampled_pairs": int(sampling.pairs.size), "repeats": args.repeats,
                                   "rows": table}, indent=1))


if __name__ == "__main__":
    main()
