"""What a step of the jointed-beam case's reduced model costs: the joint in Newton against its tangent.

The model is the one ``femrom/cases/jointed_beam.py`` rings down: the ``--modes`` lowest elastic
modes of the prestressed, calibrated beam (default mesh, 24,522 dofs, 592 interface pairs),
Galerkin about the preload, modal damping 0.139 %, the hammer (300 N, 0.3 ms half-sine), the
``clamped_iwan`` joint at the case's default chi and beta. Three versions of it step the same
blow from the preloaded rest state, ``--steps`` steps of ``dt = 1 / (128 f1)`` per block,
Newmark average acceleration (dense Newton: 10 dofs), in one process:

- ``linear``: the joint replaced by its tangent at the preload (every pair stuck),
  ``K^ + (L V)^T D_0 (L V)``: one factorisation, one solve per step;
- ``hyper``: the joint sampled by ECSW on a few weighted pairs (what the case runs; trained
  as the case trains it, on 0.15 s all-pair ring-downs at 300 and 1500 N);
- ``all_pairs``: the joint on all 592 pairs.

The blocks alternate ``--repeats`` times; the medians of their mean step times give the
ratios against ``linear`` (the issue's target: a nonlinear step within 3x).

Run ``python -m benchmarks.jointed_beam_step`` (about 5 minutes); it prints a
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

from femrom.cases.jointed_beam import SCENE
from femrom.integrators import Newmark, StepResult, integrate
from femrom.study import JointedBeamModel

RESULTS = Path(__file__).resolve().parent / "results" / "jointed_beam_step.json"


def block(system, state, dt: float, n_steps: int) -> tuple[float, int]:
    """Mean seconds per step over ``n_steps`` from rest, and the Newton iterations."""
    r = system.n_dofs
    rest = StepResult.at_rest(r, state=state)
    tic = time.perf_counter()
    summary = integrate(system, Newmark(), None, None, dt, n_steps, start=rest, progress=False)
    return (time.perf_counter() - tic) / n_steps, summary.newton_iterations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--modes", type=int, default=10)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    config = JointedBeamModel(n_modes=args.modes)
    setup = config.calibrated(config.scene(SCENE))
    model, q0, z0 = config.iwan_joint(setup)
    damping = 0.00139
    all_pairs = config.reduced(setup, model, q0, z0, damping)
    dt = config.dt(setup)
    _, sampling, hyper, z_hyper = config.hyper_reduced(all_pairs, z0, dt)
    D0 = all_pairs.nonlinear.tangent(np.zeros(all_pairs.n_dofs), None, z0)[0]
    linear = dataclasses.replace(all_pairs, stiffness=sp.csr_matrix(all_pairs.stiffness + D0), nonlinear=None,
                                 load=None)
    models = (("linear", linear, None), ("hyper", hyper, z_hyper), ("all_pairs", all_pairs, z0))
    seconds = {name: [] for name, *_ in models}
    iterations = {}
    for _ in range(args.repeats):
        for name, system, state in models:
            per_step, newton = block(system, state, dt, args.steps)
            seconds[name].append(per_step)
            iterations[name] = newton / args.steps
    medians = {name: statistics.median(values) for name, values in seconds.items()}
    result = {"machine": platform.platform(), "modes": args.modes, "pairs": int(sampling.n_pairs),
              "sampled_pairs": int(sampling.pairs.size), "law": "clamped_iwan",
              "steps_per_block": args.steps, "repeats": args.repeats, "dt": dt,
              "ms_per_step": {name: 1e3 * value for name, value in medians.items()},
              "all_ms_per_step": {name: [1e3 * v for v in values] for name, values in seconds.items()},
              "newton_iterations_per_step": iterations,
              "ratio_to_linear": {name: medians[name] / medians["linear"] for name in ("hyper", "all_pairs")}}
    print("| step | ms (median of blocks) | / linear | Newton iterations per step |\n|---|---|---|---|")
    for name, value in medians.items():
        print(f"| {name} | {1e3 * value:.3f} | {value / medians['linear']:.1f} | {iterations[name]:.2f} |")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=1))
    print(f"written: {RESULTS}")


if __name__ == "__main__":
    main()
