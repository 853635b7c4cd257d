"""Fishtail mesh ladder: what the FOM and its ROMs cost from 2e4 to the papers' 7.8e5 dofs.

Each mesh level of ``femrom/cases/fishtail.py`` (small ~2e4, medium ~1e5, large ~7.6e5
free P2 dofs; the MORwiki "Artificial Fishtail" of Siebelts, Kater & Meurer 2018
has n = 779,232) runs the case's own pipeline, :func:`fishtail.run`, in a
subprocess of its own (so that its peak memory is its own):

1. mesh generation (gmsh, cached) and assembly of K, M, C = a M + b K, B, E;
2. two Newmark runs of ``--steps`` steps (sigmoid pressure: training; step:
   test), the effective matrix factorised once for both (``auto``: PARDISO),
   the mass solve by Jacobi-CG; q, q', q'' streamed into an HDF5 snapshot
   store in ``--store-dir`` (default: the system's temporary directory),
   never held in memory;
3. a mass-orthonormal POD basis by the out-of-core randomized SVD reading the
   store;
4. one projection pass per run; the intrusive Galerkin ROM, L-OpInf and plain
   OpInf for each r from the stored Newmark derivatives; each ROM on the
   unseen step input: output error, full-field error in the mass norm, time
   per step and speedup over the FOM;
5. peak resident memory (``ru_maxrss``) of the level's process; the parent
   samples the child's RSS and kills it above ``--memory-limit-gb``.

Run from the repository root::

    python -m benchmarks.fishtail_ladder --levels small                  # ~20 s
    python -m benchmarks.fishtail_ladder --levels small medium large     # ~13 min (large: 11 min, 12.4 GB)

Results: ``benchmarks/results/fishtail_ladder.json`` (levels merged into the
existing file) and a table on stdout; the discussion is in docs/cases/fishtail.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

RESULTS = ROOT / "benchmarks" / "results" / "fishtail_ladder.json"
LEARNERS = ("galerkin", "lopinf", "opinf")


def run_level(level: str, *, steps: int, ranks, store_dir: Path, out_dir: Path, svd_power: int) -> dict:
    """One level through the case's pipeline; the numbers the ladder table needs."""
    from femrom.cases import fishtail
    from femrom.post import machine_description

    load_before = os.getloadavg()
    tic = time.perf_counter()
    store = store_dir / f"femrom_fishtail_{level}.h5"
    dt = fishtail.load_scene(level).time.dt
    metrics = fishtail.run(out_dir, level=level, t_end=steps * dt, ranks=ranks, ladders=False, render=False,
                           reverse=False, learners=LEARNERS, store_path=store, svd_power_iterations=svd_power)
    wall = time.perf_counter() - tic
    rows = [{k: row.get(k) for k in ("r", "learner", "fit_seconds", "seconds_per_step", "speedup",
                                     "train_output_error", "test_output_error", "test_field_error",
                                     "test_energy_ratio", "stiffness_min_eig", "damping_min_eig")}
            for row in metrics["roms"]]
    fom = metrics["fom"]
    return {
        "level": level, "mesh_size": metrics["mesh_size"], "n_dofs": metrics["n_dofs"], "steps": steps,
        "dt": fom["sigmoid"]["dt"], "machine": machine_description(),
        "load_before": load_before, "load_after": os.getloadavg(), "wall_seconds": wall,
        "build_seconds": metrics["build_seconds"], "build_timings": metrics["build_timings"],
        "solver": fom["sigmoid"]["solver"],
        "factorization_seconds": metrics["factorization_seconds"],
        "setup_seconds": {k: v["setup_seconds"] for k, v in fom.items()},
        "fom_seconds_per_step": metrics["fom_seconds_per_step"],
        "fom_seconds_per_step_test_run": fom["step"]["stepping_seconds"] / fom["step"]["n_steps"],
        "snapshot_seconds": {k: v["consumer_seconds"] for k, v in fom.items()},
        "store_gb": metrics["snapshots"]["bytes"] / 2**30,
        "svd_seconds": metrics["pod"]["seconds"], "svd_passes": metrics["pod"]["passes"],
        "singular_values": metrics["pod"]["singular_values"],
        "projection_seconds": metrics["projection_seconds"],
        "peak_rss_gb_after_fom": metrics["peak_rss_gb_after_fom"], "peak_rss_gb": metrics["peak_rss_gb"],
        "roms": rows,
    }


def _child(level, args) -> dict:
    import psutil

    out = Path(args.store_dir) / f"fishtail_ladder_{level}.json"
    out.unlink(missing_ok=True)
    # python -m from the checkout's root: this checkout's femrom, not another installed one
    cmd = [sys.executable, "-m", "benchmarks.fishtail_ladder", "--worker", level, "--steps", str(args.steps),
           "--ranks", *map(str, args.ranks), "--store-dir", str(args.store_dir),
           "--svd-power", str(args.svd_power), "--worker-out", str(out)]
    proc = subprocess.Popen(cmd, cwd=ROOT)
    peak = 0.0
    while proc.poll() is None:
        try:
            rss = psutil.Process(proc.pid).memory_info().rss / 2**30
        except psutil.Error:
            rss = 0.0
        peak = max(peak, rss)
        if rss > args.memory_limit_gb:
            proc.kill()
            print(f"[{level}] killed: RSS {rss:.1f} GB above --memory-limit-gb {args.memory_limit_gb}", flush=True)
            return {"level": level, "error": f"killed at {rss:.1f} GB RSS"}
        time.sleep(1.0)
    if proc.returncode != 0 or not out.exists():
        return {"level": level, "error": f"worker exited with {proc.returncode}"}
    result = json.loads(out.read_text())
    result["sampled_peak_rss_gb"] = peak
    return result


def table(results) -> str:
    lines = ["| level | dofs | build s | factor s | FOM s/step | store GB | SVD s | peak GB | r | learner | fit s "
             "| ROM s/step | speedup | output err | field err |",
             "|" + "---|" * 15]
    for res in results:
        if "error" in res:
            lines.append(f"| {res['level']} | failed: {res['error']} |" + " |" * 13)
            continue
        for row in res["roms"]:
            lines.append(
                f"| {res['level']} | {res['n_dofs']} | {res['build_seconds']:.1f} | "
                f"{res['factorization_seconds']:.1f} | {res['fom_seconds_per_step']:.3f} | "
                f"{res['store_gb']:.2f} | {res['svd_seconds']:.1f} | {res['peak_rss_gb']:.1f} | {row['r']} | "
                f"{row['learner']} | {row['fit_seconds']:.2f} | {row['seconds_per_step']:.2e} | "
                f"{row['speedup']:.0f} | {row['test_output_error']:.2e} | {row['test_field_error']:.2e} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--levels", nargs="+", default=["small", "medium", "large"],
                        choices=("tiny", "small", "medium", "large"))
    parser.add_argument("--steps", type=int, default=150, help="Newmark steps of 1 ms per run")
    parser.add_argument("--ranks", type=int, nargs="+", default=[4, 8, 12])
    parser.add_argument("--store-dir", default=tempfile.gettempdir(),
                        help="where the snapshot stores go (the large level: 5.2 GB at 150 steps)")
    parser.add_argument("--svd-power", type=int, default=2, help="power iterations of the randomized SVD")
    parser.add_argument("--memory-limit-gb", type=float, default=20.0)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--worker-out", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        from femrom.post import jsonable

        with tempfile.TemporaryDirectory(prefix=f"fishtail_{args.worker}_", dir=args.store_dir) as work:
            res = run_level(args.worker, steps=args.steps, ranks=args.ranks, store_dir=Path(args.store_dir),
                            out_dir=Path(work), svd_power=args.svd_power)
        Path(args.worker_out).write_text(json.dumps(jsonable(res), indent=2))
        return 0
    merged = json.loads(args.out.read_text()) if args.out.exists() else {"levels": {}}
    results = []
    for level in args.levels:
        print(f"[{level}] running ...", flush=True)
        res = _child(level, args)
        results.append(res)
        merged["levels"][level] = res
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(merged, indent=2) + "\n")
    print(table(results))
    print(f"results in {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
