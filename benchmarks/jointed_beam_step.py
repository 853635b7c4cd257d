"""What a step of the jointed-beam case's reduced model costs: the joint in Newton against its tangent.

The model is the one ``cases/jointed_beam.py`` rings down: the ``--modes`` lowest elastic
modes of the prestressed, calibrated beam (default mesh, 24,522 dofs, 592 interface pairs),
Galerkin about the preload, modal damping 0.139 %, the hammer (300 N, 0.3 ms half-sine).
Two versions of it step the same blow from the preloaded rest state, ``--steps`` steps of
``dt = 1 / (128 f1)`` per block, Newmark average acceleration, in one process:

- ``linear``: the joint replaced by its tangent at the preload (every closed pair stuck),
  ``K^ + (L V)^T D_0 (L V)``: one factorisation, one solve per step;
- ``nonlinear``: the ``clamped_friction`` joint on all 592 pairs in Newton through the
  projected local map (what the case runs).

The blocks alternate ``--repeats`` times; the medians of their mean step times give the
ratio ``nonlinear / linear`` (the issue's target: within 3x).

Run ``PYTHONPATH=. python benchmarks/jointed_beam_step.py`` (about 2 minutes); it prints a
table and writes ``benchmarks/results/jointed_beam_step.json``.
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
import scipy.sparse as sp

from femrom.cli import load_case
from femrom.integrators import Newmark, StepResult, integrate

RESULTS = Path(__file__).resolve().parent / "results" / "jointed_beam_step.json"


def block(system, state, dt: float, n_steps: int) -> tuple[float, int]:
    """Mean seconds per step over ``n_steps`` from rest, and the Newton iterations."""
    r = system.n_dofs
    rest = StepResult(step=0, t=0.0, q=np.zeros(r), v=np.zeros(r), a=np.zeros(r), state=state)
    tic = time.perf_counter()
    summary = integrate(system, Newmark(), None, None, dt, n_steps, start=rest, progress=False)
    return (time.perf_counter() - tic) / n_steps, summary.newton_iterations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--modes", type=int, default=10)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    case = load_case("jointed_beam")
    config = case.JointedBeamCase(n_modes=args.modes)
    setup = case.prestressed(config)
    nonlinear, z0 = case.reduced_model(setup, config, 0.00139)
    D0 = nonlinear.nonlinear.tangent(np.zeros(nonlinear.n_dofs), None, z0)[0]
    linear = dataclasses.replace(nonlinear, stiffness=sp.csr_matrix(nonlinear.stiffness + D0), nonlinear=None,
                                 load=None)
    f1 = float(setup["modes"].frequencies[6])
    dt = 1.0 / (128 * f1)
    seconds = {"linear": [], "nonlinear": []}
    iterations = {}
    for _ in range(args.repeats):
        for name, system, state in (("linear", linear, None), ("nonlinear", nonlinear, z0)):
            per_step, newton = block(system, state, dt, args.steps)
            seconds[name].append(per_step)
            iterations[name] = newton
    medians = {name: statistics.median(values) for name, values in seconds.items()}
    result = {"machine": platform.platform(), "modes": args.modes, "pairs": int(nonlinear.nonlinear.force_model.n_pairs),
              "steps_per_block": args.steps, "repeats": args.repeats, "dt": dt,
              "ms_per_step": {name: 1e3 * value for name, value in medians.items()},
              "all_ms_per_step": {name: [1e3 * v for v in values] for name, values in seconds.items()},
              "newton_iterations_per_step": iterations["nonlinear"] / args.steps,
              "ratio_nonlinear_to_linear": medians["nonlinear"] / medians["linear"]}
    print("| step | ms (median of blocks) |\n|---|---|")
    for name, value in medians.items():
        print(f"| {name} | {1e3 * value:.3f} |")
    print(f"\nnonlinear / linear = {result['ratio_nonlinear_to_linear']:.1f}x "
          f"({result['newton_iterations_per_step']:.2f} Newton iterations per step)")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=1))
    print(f"written: {RESULTS}")


if __name__ == "__main__":
    main()
