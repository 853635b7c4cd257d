r"""The soft robot's mesh levels: what each costs, from the mesh to a Newmark step.

``femrom/cases/soft_robot.toml`` (meshes/soft_robot.geo, P2, materials by region, Rayleigh
damping, six chamber inputs, 40 centreline outputs) at three ``mesh_size`` values:

========  =========  ======================================
level     mesh_size  P2 dofs (before the clamp is removed)
========  =========  ======================================
small     0.045      2.3e4 (the case's default)
medium    0.017      1.0e5
large     0.0115     2.3e5 (the SERPENT papers' size)
========  =========  ======================================

Each level runs in its own process (``--single LEVEL``), so that its peak resident
memory is its own, and measures

1. mesh generation: gmsh from the .geo, in a fresh cache folder (no cache hit);
2. assembly: ``femrom.scene.build`` on that mesh, per stage (mass, stiffness,
   damping, inputs, outputs), and the first two lateral bending frequencies
   (shift-invert Lanczos, to see the mesh's convergence);
3. the Newmark average-acceleration run of the scene's inputs with the scene's
   solver (``auto``): the factorisation, and the seconds per step of ``repeats``
   runs of ``steps`` steps (each step timed without the consumers,
   ``femrom.integrators.StepClock``; the median of all steps of a run, then the
   median over runs, and the fastest run: a shared machine only ever adds time);
4. a baseline measured in the same process, ``K @ q`` (the stiffness times a
   vector), so that a step reads as a multiple of a matrix-vector product that a
   loaded machine slows alike;
5. the peak resident memory (``ru_maxrss``).

The table gives every level's numbers and their ratios to the small level of
the same run. Usage::

    python -m benchmarks.soft_robot_levels [--levels small,medium,large]
                                           [--out benchmarks/results/soft_robot_levels.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from femrom.cases import scene_file

ROOT = Path(__file__).resolve().parents[1]
SCENE = scene_file("soft_robot")
#: mesh_size per level (gmsh 4.15: 2.35e4, 1.04e5 and 2.27e5 P2 dofs)
LEVELS = {"small": 0.045, "medium": 0.017, "large": 0.0115}
#: Newmark steps per timed run and runs per level (a large step takes seconds)
STEPS = {"small": 40, "medium": 15, "large": 8}
REPEATS = {"small": 3, "medium": 3, "large": 3}
MATVEC_REPEATS = 20


def _peak_rss_gb() -> float:
    scale = 1 if sys.platform == "darwin" else 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale / 2**30


def measure(level: str) -> dict:
    """Every number of one level, in this process."""
    from scipy.sparse.linalg import LinearOperator, eigsh

    from femrom.solvers import make_solver

    from femrom.integrators import StepClock, simulate
    from femrom.mesh import generate_mesh, load_mesh
    from femrom.scene import Scene, build

    scene = Scene.from_toml(SCENE).with_geometry(mesh_size=LEVELS[level])
    with tempfile.TemporaryDirectory() as cache:
        tic = time.perf_counter()
        path = generate_mesh("soft_robot", dict(scene.structure.parameters), cache_dir=cache, progress=False)
        mesh_seconds = time.perf_counter() - tic
        mesh = load_mesh(path)
    tic = time.perf_counter()
    model = build(scene, mesh=mesh)
    build_seconds = time.perf_counter() - tic
    system = model.system
    row = {"level": level, "mesh_size": LEVELS[level], "n_total": int(model.space.n_total),
           "n_dofs": int(system.n_dofs), "n_elements": int(mesh.nelements), "mesh_seconds": mesh_seconds,
           "build_seconds": build_seconds,
           "assembly": {k: v for k, v in model.timings.items() if k != "mesh"}}

    # first lateral bending modes (the modes whose tip moves in z), shift-invert about 0 with the
    # scene's solver for K^-1 (scipy's default SuperLU fills in badly on large P2 meshes)
    stiffness_solver = make_solver(system.stiffness, strategy=scene.time.solver)
    inverse = LinearOperator(system.stiffness.shape, matvec=stiffness_solver.solve, dtype=float)
    values, vectors = eigsh(system.stiffness, k=4, M=system.mass, sigma=0.0, which="LM", OPinv=inverse)
    del stiffness_solver, inverse
    order = np.argsort(values)
    tip_z = np.abs((system.output_matrix @ vectors[:, order])[-1])
    lateral = [float(np.sqrt(values[order[k]]) / (2 * np.pi)) for k in range(4) if tip_z[k] > 1e-3 * tip_z.max()]
    row["frequencies_hz"] = [float(np.sqrt(values[k]) / (2 * np.pi)) for k in order]
    row["lateral_hz"] = lateral[:2]

    q = np.random.default_rng(0).standard_normal(system.n_dofs)
    K = system.stiffness
    times = []
    for _ in range(MATVEC_REPEATS):
        tic = time.perf_counter()
        K @ q
        times.append(time.perf_counter() - tic)
    row["matvec_seconds"] = statistics.median(times)

    steps, runs = STEPS[level], []
    for _ in range(REPEATS[level]):
        clock = StepClock()
        result = simulate(model, t_end=steps * scene.time.dt, clock=clock, progress=False)
        runs.append({"factorization_seconds": result.summary["factorization_seconds"],
                     "step_seconds": float(np.median(clock.step_seconds)), "solver": result.summary["solver"]})
    row["runs"] = runs
    row["solver"] = runs[0]["solver"]
    row["factorization_seconds"] = statistics.median(r["factorization_seconds"] for r in runs)
    row["step_seconds"] = statistics.median(r["step_seconds"] for r in runs)
    # a shared machine only ever adds time: the fastest run shows the spread
    row["factorization_seconds_fastest"] = min(r["factorization_seconds"] for r in runs)
    row["step_seconds_fastest"] = min(r["step_seconds"] for r in runs)
    row["step_per_matvec"] = row["step_seconds"] / row["matvec_seconds"]
    row["peak_rss_gb"] = _peak_rss_gb()
    return row


def _table(rows: list[dict]) -> str:
    base = rows[0]
    lines = ["| level | mesh_size | dofs | mesh s | assembly s | factor s (fastest) | s/step (fastest) | "
             "step/matvec | f1, f2 lateral Hz | peak GB | dofs, assembly, factor, step vs " + base["level"] + " |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['level']} | {LEVELS[r['level']]} | failed: {r['error']} |")
            continue
        ratios = ", ".join(f"{r[k] / base[k]:.1f}" for k in ("n_dofs", "build_seconds",
                                                              "factorization_seconds", "step_seconds"))
        lines.append(f"| {r['level']} | {r['mesh_size']} | {r['n_dofs']} | {r['mesh_seconds']:.1f} | "
                     f"{r['build_seconds']:.1f} | {r['factorization_seconds']:.1f} ({r['factorization_seconds_fastest']:.1f}) | "
                     f"{r['step_seconds']:.3f} ({r['step_seconds_fastest']:.3f}) | "
                     f"{r['step_per_matvec']:.0f} | {', '.join(f'{f:.3f}' for f in r['lateral_hz'])} | "
                     f"{r['peak_rss_gb']:.2f} | {ratios} |")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--levels", default="small,medium,large")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "soft_robot_levels.json"))
    parser.add_argument("--single", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.single:
        print(json.dumps(measure(args.single)))
        return
    rows = []
    for level in args.levels.split(","):
        if level not in LEVELS:
            parser.error(f"unknown level {level!r}; valid: {', '.join(LEVELS)}")
        print(f"{level}: mesh_size = {LEVELS[level]} ...", file=sys.stderr, flush=True)
        # python -m from the checkout's root: this checkout's femrom, not another installed one
        child = subprocess.run([sys.executable, "-m", "benchmarks.soft_robot_levels", "--single", level], cwd=ROOT,
                               capture_output=True,
                               text=True, env={**os.environ, "FEMROM_NO_PROGRESS": "1"})
        if child.returncode:
            last = (child.stderr.strip().splitlines() or ["no message"])[-1]
            rows.append({"level": level, "error": f"exit {child.returncode}: {last}"})
        else:
            rows.append(json.loads(child.stdout.strip().splitlines()[-1]))
        print(_table(rows), file=sys.stderr, flush=True)
    table = _table(rows)
    print(table)
    record = {"benchmark": "soft_robot_levels", "scene": "femrom/cases/soft_robot.toml", "rows": rows, "table": table,
              "machine": {"platform": platform.platform(), "processor": platform.processor(),
                          "cpus": os.cpu_count(), "load_average": os.getloadavg()},
              "timestamp": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
