"""Many runs of one reduced joint model at once against one run at a time: cost per run.

The model is the lap joint of ``tests/test_fused_step.py`` (two grounded chains of ``S`` nodes
joined pair by pair by the ``clamped_iwan`` law, 12 sliders, preload ramped along the joint,
one pair open; Galerkin on the stuck joint's 5 lowest modes, 0.5 % modal damping), at ``S =
10`` pairs (the per-call overhead matters) and ``S = 40`` (the law's arithmetic dominates).
``B`` runs are driven by ``F_b sin(2 pi 400 t)`` on the one input column, ``F_b`` spaced
logarithmically from 300 N (nearly stuck) to 8 kN (slipping), ``--steps`` steps of ``dt = 2e-4 s``
from rest, Newmark average acceleration, dense Newton (``rtol = 1e-12``).

Two paths per ``B`` in ``(1, 4, 16)``:

- ``single``: :func:`femrom.integrators.march` once per run (the fused step, one compiled call
  per step and run, inside march's Python loop);
- ``batch``: :func:`femrom.integrators.march_batch` of all ``B`` runs (one compiled call for
  all steps of all runs, each run with its own Newton).

Blocks alternate (single, batch, then the next ``B``; ``--repeats`` times); the medians of the
wall time per run and step (whole calls, set-up included), their spread (min-max) and the
ratio single / batch (also per repeat) are printed and written to
``benchmarks/results/batch_march.json``. An untimed check first: every batched run equals its
single run (largest difference of ``q``, relative to the run's largest ``|q|``; same Newton
iterations).

The stepped sine (``SteppedSine.run`` against ``run_batched``, one ``march_batch`` call per period
for all levels still running) on the 10-pair model with 5 % modal damping (so that the levels
settle), its first two reduced coordinates as outputs: ``B`` levels from 300 N to 8 kN, three
frequencies about the first mode, ``--steps-per-period`` steps a period, tolerance 1e-3; the
medians of ``--repeats`` alternating blocks, wall time per level, and the largest phasor difference.

Run ``python -m benchmarks.batch_march`` (a few minutes).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import platform
import statistics
import subprocess
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from femrom.fem import ClampedIwanLaw, JointForce, compiled_laws
from femrom.inference import galerkin
from femrom.integrators import (Newmark, Newton, Shaker, SteadyStateCriterion, SteppedSine, StepResult, march,
                                march_batch)
from femrom.scene import SecondOrderSystem

RESULTS = Path(__file__).resolve().parent / "results" / "batch_march.json"
DT, MODES, FREQUENCY = 2e-4, 5, 400.0
BATCHES = (1, 4, 16)


def lap_joint(pairs: int):
    """``(reduced system with one input column, rest state)``: ``tests/test_fused_step.py``'s model at ``pairs``."""
    S = pairs
    n = 6 * S
    a = np.arange(3 * S).reshape(S, 3)
    b = 3 * S + a
    rows, cols, values = [], [], []
    for side in (a, b):
        for m in range(S - 1):
            for c in range(3):
                i, j = side[m, c], side[m + 1, c]
                rows += [i, j, i, j]
                cols += [i, j, j, i]
                values += [5e8, 5e8, -5e8, -5e8]
    ground = np.full(n, 1e6)
    ground[a[0]] = 1e10
    K = sp.coo_matrix((values, (rows, cols)), shape=(n, n)).tocsr() + sp.diags(ground)
    M = sp.diags(np.full(n, 0.01))
    law = ClampedIwanLaw(1e9, 2e8, chi=-0.5, beta=0.5, n_sliders=12)
    joint = JointForce(law, a, b, np.tile([0.0, 0.0, 1.0], (S, 1)), np.full(S, 1e-4), n, initial_gap=-1e-6)
    z0 = law.initial_state(S)
    z0[:, -1, 0] = np.linspace(2e4, 2e5, S)
    z0[:, -1, 1] = 1.0
    z0[0, -1, 1] = 0.0
    B = np.zeros((n, 1))
    B[b[-1, 0], 0] = 1.0
    system = SecondOrderSystem(mass=M, stiffness=K, input_matrix=B, nonlinear=joint)
    stuck = (K + joint.tangent(np.zeros(n), None, z0)[0]).toarray()
    V = sla.eigh(stuck, M.toarray())[1][:, :MODES]
    q0 = 1e-7 * np.sin(np.arange(n))
    model = galerkin(system, V, reference=q0, reference_state=z0, damping_ratios=0.005)
    return model.system, z0


def inputs(B: int, times) -> np.ndarray:
    levels = np.geomspace(300.0, 8000.0, B) if B > 1 else np.array([2000.0])
    return np.array([[F * np.sin(2 * np.pi * FREQUENCY * times)] for F in levels])


def single(system, scheme, times, U, z0):
    r = system.n_dofs
    return [march(system, scheme, times, np.zeros(r), np.zeros(r), inputs=u, state0=z0) for u in U]


def check(system, scheme, times, z0) -> dict:
    U = inputs(max(BATCHES), times)
    batch = march_batch(system, scheme, times, inputs=U, state0=z0)
    runs = single(system, scheme, times, U, z0)
    return {"q_max_relative_difference": max(float(np.abs(batch["q"][b] - run["q"]).max() / np.abs(run["q"]).max())
                                             for b, run in enumerate(runs)),
            "state_max_difference": max(float(np.abs(batch["state"][b] - run["state"]).max())
                                        for b, run in enumerate(runs)),
            "same_iterations": all(int(batch["newton_iterations"][b].sum()) == run["newton_iterations"]
                                   for b, run in enumerate(runs)),
            "newton_iterations_per_step": [float(batch["newton_iterations"][b].mean()) for b in range(len(runs))]}


def stepped_sines(repeats: int, steps_per_period: int) -> dict:
    """Seconds per level of ``run`` and ``run_batched`` at each ``B``, and their largest phasor difference."""
    system, z0 = lap_joint(10)
    r = system.n_dofs
    f1 = np.sqrt(sla.eigh(np.asarray(system.stiffness), np.asarray(system.mass), eigvals_only=True)[0]) / (2 * np.pi)
    system = dataclasses.replace(system, output_matrix=np.eye(r)[:2], output_names=("y0", "y1"),
                                 damping=10.0 * np.asarray(system.damping))
    plant = Shaker(system, 0, rest=StepResult.at_rest(r, state=z0))
    sweep = SteppedSine(f1 * np.array([0.9, 1.0, 1.1]), steps_per_period=steps_per_period,
                        steady_state=SteadyStateCriterion(tolerance=1e-3, max_periods=200))
    out = {}
    for B in BATCHES:
        levels = list(np.geomspace(300.0, 8000.0, B)) if B > 1 else [2000.0]
        seconds = {"run": [], "run_batched": []}
        for _ in range(repeats):
            for name in seconds:
                plant.reset()
                tic = time.perf_counter()
                result = getattr(sweep, name)(plant, levels)
                seconds[name].append((time.perf_counter() - tic) / B)
                if name == "run":
                    reference = result
        difference = max(float(np.abs(a.phasors - b.phasors).max() / np.abs(b.phasors).max())
                         for a, b in zip(result.levels, reference.levels))
        periods = [int(level.periods.sum()) for level in reference.levels]
        out[str(B)] = {"ms_per_level": {k: 1e3 * statistics.median(v) for k, v in seconds.items()},
                       "spread_ms": {k: [1e3 * min(v), 1e3 * max(v)] for k, v in seconds.items()},
                       "ratio": statistics.median(seconds["run"]) / statistics.median(seconds["run_batched"]),
                       "ratio_per_repeat": [x / y for x, y in zip(seconds["run"], seconds["run_batched"])],
                       "periods_per_level": periods, "phasor_max_relative_difference": difference}
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--pairs", type=int, nargs="+", default=[10, 40])
    parser.add_argument("--steps-per-period", type=int, default=64)
    args = parser.parse_args()
    assert compiled_laws(), "the batch path needs numba"
    scheme = Newmark(newton=Newton(rtol=1e-12))
    times = DT * np.arange(args.steps + 1)
    load = os.getloadavg()
    result = {"date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="minutes"),
              "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                       cwd=Path(__file__).resolve().parents[1]).stdout.strip(),
              "machine": platform.platform(), "cpus": os.cpu_count(), "load_average_start": load,
              "steps": args.steps, "repeats": args.repeats, "dt": DT, "modes": MODES, "sliders": 12,
              "batches": list(BATCHES), "models": {}}
    for pairs in args.pairs:
        system, z0 = lap_joint(pairs)
        march_batch(system, scheme, times[:3], inputs=inputs(2, times[:3]), state0=z0)      # compile / load
        entry = {"check": check(system, scheme, times, z0), "us_per_run_step": {}}
        seconds = {(path, B): [] for B in BATCHES for path in ("single", "batch")}
        for _ in range(args.repeats):
            for B in BATCHES:
                U = inputs(B, times)
                tic = time.perf_counter()
                single(system, scheme, times, U, z0)
                seconds["single", B].append((time.perf_counter() - tic) / (B * args.steps))
                tic = time.perf_counter()
                march_batch(system, scheme, times, inputs=U, state0=z0)
                seconds["batch", B].append((time.perf_counter() - tic) / (B * args.steps))
        for B in BATCHES:
            s, b = seconds["single", B], seconds["batch", B]
            entry["us_per_run_step"][str(B)] = {
                "single": 1e6 * statistics.median(s), "single_spread": [1e6 * min(s), 1e6 * max(s)],
                "batch": 1e6 * statistics.median(b), "batch_spread": [1e6 * min(b), 1e6 * max(b)],
                "ratio": statistics.median(s) / statistics.median(b),
                "ratio_per_repeat": [x / y for x, y in zip(s, b)],
                "all_single": [1e6 * x for x in s], "all_batch": [1e6 * x for x in b]}
        result["models"][str(pairs)] = entry
    result["stepped_sine"] = stepped_sines(args.repeats, args.steps_per_period)
    result["steps_per_period"] = args.steps_per_period
    result["load_average_end"] = os.getloadavg()
    print(f"{result['date']}, commit {result['commit']}, load {load[0]:.1f} -> {result['load_average_end'][0]:.1f}")
    print("| pairs | B | single [us / run-step] | batch [us / run-step] | single / batch | same repeat (min-max) |\n"
          "|---|---|---|---|---|---|")
    for pairs, entry in result["models"].items():
        for B, x in entry["us_per_run_step"].items():
            print(f"| {pairs} | {B} | {x['single']:.1f} ({x['single_spread'][0]:.1f}-{x['single_spread'][1]:.1f}) "
                  f"| {x['batch']:.1f} ({x['batch_spread'][0]:.1f}-{x['batch_spread'][1]:.1f}) | {x['ratio']:.2f} "
                  f"| {min(x['ratio_per_repeat']):.2f}-{max(x['ratio_per_repeat']):.2f} |")
    for pairs, entry in result["models"].items():
        print(f"{pairs} pairs, check: {entry['check']}")
    print("\n| stepped sine, B levels | run [ms / level] | run_batched [ms / level] | run / run_batched "
          "| same repeat (min-max) | periods per level | phasor difference |\n|---|---|---|---|---|---|---|")
    for B, x in result["stepped_sine"].items():
        a, b = x["spread_ms"]["run"], x["spread_ms"]["run_batched"]
        print(f"| {B} | {x['ms_per_level']['run']:.0f} ({a[0]:.0f}-{a[1]:.0f}) "
              f"| {x['ms_per_level']['run_batched']:.0f} ({b[0]:.0f}-{b[1]:.0f}) | {x['ratio']:.2f} "
              f"| {min(x['ratio_per_repeat']):.2f}-{max(x['ratio_per_repeat']):.2f} "
              f"| {min(x['periods_per_level'])}-{max(x['periods_per_level'])} | {x['phasor_max_relative_difference']:.1e} |")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=1))
    print(f"written: {RESULTS}")


if __name__ == "__main__":
    main()
