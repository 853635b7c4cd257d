"""FOM sweep on Dask against a sequential loop: 8 small-fishtail trajectories, 2 workers.

The sweep: the small fishtail (``femrom/cases/fishtail.py``, level ``small``, about 2e4
P2 dofs, 300 Newmark steps of 1 ms) over 2 Young's moduli x 4 pressure
amplitudes. Both ways run the same function per point
(:func:`femrom.study.run_sweep_point`: build the model unless the previous point
on that process had the same material, integrate, stream ``q`` into the point's
own store file) and end with one merged store:

- ``sequential``: a loop in this process (its BLAS and PARDISO use both cores);
- ``sequential_1thread``: the same loop in a child process with one BLAS/MKL
  thread (``MKL_NUM_THREADS=1`` ...), the workers' setting: it separates what
  the two workers gain by running in parallel from what one process loses to
  two MKL threads on a shared machine (docs/benchmarks.md, "Noise");
- ``dask``: :func:`femrom.study.run_sweep` on a ``LocalCluster`` of 2 worker
  processes with one thread each.

They alternate ``--repeats`` times (in rotated order), so a change of the
machine's load hits all. Reported per repeat: wall seconds of each, and the
ratios sequential / dask.

Run ``python -m benchmarks.sweep_dask [--repeats 2] [--level small]``;
it prints a table and writes ``benchmarks/results/sweep_dask.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "sweep_dask.json"


def sweep_scene(level: str):
    from femrom.cases import fishtail
    from femrom.scene import SweepConfig

    scene = fishtail.load_scene(level)
    amplitude = dict(scene.inputs[0].signal.parameters)["amplitude"]
    sweep = SweepConfig(parameters=(("material.youngs_modulus", (0.9e6, 1.1e6)),
                                    ("inputs.0.signal.amplitude", tuple(amplitude * f for f in (0.5, 1.0, 1.5, 2.0)))))
    return dataclasses.replace(scene, sweep=sweep)


def sequential(scene, out: Path) -> float:
    """The same points, one after the other in this process, merged into one store."""
    from femrom.scene import build
    from femrom.snapshots import SnapshotStore
    from femrom.study import run_sweep_point, sweep_runs

    tic = time.perf_counter()
    parts = out / "parts"
    parts.mkdir(parents=True)
    runs = sweep_runs(scene)
    for run in runs:
        run_sweep_point(scene, run, str(parts / f"{run.name}.h5"))
    merged = SnapshotStore.create(out / "sweep.h5", build(scene), fields=scene.sweep.fields, overwrite=True)
    for run in runs:
        merged.import_trajectory(parts / f"{run.name}.h5", run.name)
    merged.close()
    return time.perf_counter() - tic


def sequential_1thread(level: str, out: Path) -> float:
    """:func:`sequential` in a child process with one BLAS/MKL/OpenMP thread."""
    import subprocess

    env = dict(os.environ, MKL_NUM_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    done = subprocess.run([sys.executable, "-m", "benchmarks.sweep_dask", "--child", str(out), "--level", level],
                          env=env, cwd=ROOT, capture_output=True, text=True, check=True)
    return float(done.stdout.strip().splitlines()[-1])


def dask(scene, out: Path, workers: int) -> float:
    from femrom.study import run_sweep

    tic = time.perf_counter()
    run_sweep(scene, out, n_workers=workers, progress=None)
    return time.perf_counter() - tic


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--level", default="small")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:        # sequential_1thread's child: print the seconds
        print(sequential(sweep_scene(args.level), Path(args.child)))
        return 0
    from femrom.post import machine_description

    scene = sweep_scene(args.level)
    ways = ("sequential", "sequential_1thread", "dask")
    rows = []
    for repeat in range(args.repeats):
        order = ways[repeat % 3:] + ways[:repeat % 3]
        row = {"repeat": repeat, "load_before": os.getloadavg()}
        for way in order:
            work = Path(tempfile.mkdtemp(prefix="femrom_sweep_"))
            try:
                if way == "sequential":
                    row[way] = sequential(scene, work)
                elif way == "sequential_1thread":
                    row[way] = sequential_1thread(args.level, work)
                else:
                    row[way] = dask(scene, work, args.workers)
            finally:
                shutil.rmtree(work, ignore_errors=True)
            print(f"repeat {repeat}: {way} {row[way]:.1f} s", flush=True)
        row["load_after"] = os.getloadavg()
        row["ratio"] = row["sequential"] / row["dask"]
        row["ratio_1thread"] = row["sequential_1thread"] / row["dask"]
        rows.append(row)
    result = {
        "benchmark": "sweep_dask", "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "machine": machine_description(), "level": args.level, "n_runs": 8, "workers": args.workers,
        "steps_per_run": scene.time.n_steps, "rows": rows,
        "median_sequential_seconds": statistics.median(r["sequential"] for r in rows),
        "median_sequential_1thread_seconds": statistics.median(r["sequential_1thread"] for r in rows),
        "median_dask_seconds": statistics.median(r["dask"] for r in rows),
        "median_ratio": statistics.median(r["ratio"] for r in rows),
        "median_ratio_1thread": statistics.median(r["ratio_1thread"] for r in rows),
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=2) + "\n")
    print("| repeat | sequential [s] | sequential, 1 thread [s] | dask, 2 workers [s] | ratios | load before |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['repeat']} | {r['sequential']:.1f} | {r['sequential_1thread']:.1f} | {r['dask']:.1f} | "
              f"{r['ratio']:.2f}, {r['ratio_1thread']:.2f} | {r['load_before'][0]:.2f} |")
    print(f"median ratios {result['median_ratio']:.2f} (sequential / dask), {result['median_ratio_1thread']:.2f} "
          f"(sequential, 1 thread / dask); {RESULTS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
