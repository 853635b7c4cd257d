"""What a step of an Iwan-L-OpInf ROM costs: the learned sliders in numpy, fused per step, marched in one call.

The model has the structure ``IwanLOpInf`` fits (``femrom/inference/learners/iwan_lopinf.py``):
``q'' + C q' + K q + a sum_i k_i e_i = B u`` with ``--sliders`` learned Jenkins sliders (the
learner's default 32, thresholds spread geometrically over three decades) along one direction
``a``, at r = 1 and 3; random SPD ``K`` (first frequency 80 Hz), 0.14 % modal damping, one input.
The operators' values do not change what a step costs, only how many Newton iterations it
takes: the blow (a 0.3 ms half-sine) is sized so that most sliders slip, as in the jointed
beam's ROMs. ``dt = 1 / (128 * 80 Hz)``, Newmark average acceleration, ``--steps`` steps from
rest per block. Rows:

- ``linear``: the sliders replaced by their stuck stiffness (``march``'s linear map, the baseline);
- ``march_numpy``: :func:`femrom.integrators.march` with the compiled laws off (the term's numpy
  force and tangent, dense Newton, one scheme step a Python call);
- ``march_fused``: the same call with them on: the whole trajectory in one compiled call;
- ``driver_numpy`` and ``driver_fused``: :func:`femrom.integrators.integrate` (the streaming driver,
  a Python step each), numpy step and fused step.

``--potential`` adds a learned quartic potential beside the sliders (all degree-4 monomials, scaled so
that its force is about a tenth of ``K q`` at the blow's largest linear motion): the shape of SpML with
sliders and its monomials (``SpML([..., "hysteresis"])``, the jointed-beam ROM study's ``spml_hyst``),
whose fused step evaluates the potential's gradient and Hessian beside the sliders
(``newmark_sliders_step`` of the scalar kernels); it writes ``iwan_rom_step_potential.json``.

``march`` rows report its ``stepping_seconds`` (the loop alone), ``driver`` rows the whole call.
The blocks alternate ``--repeats`` times; medians of the blocks' mean step times and their spread
(min-max), and ratios against ``linear`` and ``march_numpy``. Run ``python -m benchmarks.iwan_rom_step``
(about 1 minute); writes ``benchmarks/results/iwan_rom_step.json``.
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

from femrom.fem import compiled_laws, use_compiled_laws
from femrom.inference import LearnedHysteresis, ReducedOperators
from femrom.integrators import Newmark, StepResult, integrate, march
from femrom.scene import Signal, SignalVector

RESULTS = Path(__file__).resolve().parent / "results" / "iwan_rom_step.json"
F1 = 80.0


def models(r: int, sliders: int):
    """``(nonlinear system, linear system)`` of an Iwan-L-OpInf-shaped ROM with ``r`` coordinates."""
    rng = np.random.default_rng(r)
    X = rng.normal(size=(r, r))
    K = X @ X.T + r * np.eye(r)
    K *= (2 * np.pi * F1) ** 2 / np.linalg.eigvalsh(K)[0]
    omega = np.sqrt(np.linalg.eigvalsh(K))
    C = 2 * 0.0014 * np.diag(omega)
    a = rng.normal(size=r)
    a /= np.linalg.norm(a)
    thresholds = np.geomspace(1e-6, 1e-3, sliders)
    weights = 0.3 * K[0, 0] / sliders * np.ones(sliders)
    term = LearnedHysteresis(a, thresholds, weights)
    blow = SignalVector([Signal.from_dict({"kind": "impulse", "amplitude": 2000.0, "start": 0.0, "duration": 3e-4})])
    B = np.ones((r, 1)) / np.sqrt(r)
    nonlinear = ReducedOperators.from_matrices(K, damping=C, input_matrix=B, nonlinear=term).system
    linear = ReducedOperators.from_matrices(K + term.stuck_stiffness * np.outer(a, a), damping=C,
                                            input_matrix=B).system
    return dataclasses.replace(nonlinear, inputs=blow), dataclasses.replace(linear, inputs=blow), term


def with_potential(system, linear, dt: float, steps: int):
    """``system`` with a quartic potential over all degree-4 monomials beside its sliders, its force a tenth of
    ``K q`` at the linear model's largest motion under the blow."""
    from femrom.inference import LearnedPotential, SymmetricPolynomial, multi_indices

    r = system.n_dofs
    zero = np.zeros(r)
    peak = float(np.abs(march(linear, Newmark(), dt * np.arange(steps + 1), zero, zero, inputs=linear.inputs)["q"]).max())
    index = multi_indices(r, 4)
    coefficients = np.random.default_rng(7).uniform(0.5, 1.0, len(index))
    coefficients *= 0.1 * float(np.max(np.diag(linear.stiffness))) / (4.0 * len(index) * peak ** 2)
    potential = LearnedPotential(r, SymmetricPolynomial(r, {4: (index, coefficients)}))
    ops = ReducedOperators.from_matrices(system.stiffness, damping=system.damping, input_matrix=system.input_matrix,
                                         nonlinear=potential)
    sliders = system.nonlinear
    return dataclasses.replace(ops.with_terms(sliders).system, inputs=system.inputs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--sliders", type=int, default=32)
    parser.add_argument("--potential", action="store_true", help="a learned quartic potential beside the sliders")
    args = parser.parse_args()
    if not compiled_laws():
        raise SystemExit("the compiled kernels are off (numba missing or FEMROM_COMPILED_LAWS=0)")
    dt = 1.0 / (128 * F1)
    times = dt * np.arange(args.steps + 1)
    result = {"machine": platform.platform(), "python": platform.python_version(), "steps": args.steps,
              "repeats": args.repeats, "sliders": args.sliders, "potential": args.potential, "dt": dt, "rows": {}}
    for r in (1, 3):
        system, linear, term = models(r, args.sliders)
        if args.potential:
            system = with_potential(system, linear, dt, args.steps)
        zero = np.zeros(r)

        def marched(model, compiled):
            use_compiled_laws(compiled)
            run = march(model, Newmark(), times, zero, zero, inputs=model.inputs)
            return run["stepping_seconds"] / args.steps, run["newton_iterations"] / args.steps, run

        def driven(compiled):
            use_compiled_laws(compiled)
            tic = time.perf_counter()
            summary = integrate(system, Newmark(), None, None, dt, args.steps, start=StepResult.at_rest(r),
                                progress=False)
            return (time.perf_counter() - tic) / args.steps, summary.newton_iterations / args.steps, None

        blocks = {"linear": lambda: marched(linear, True), "march_numpy": lambda: marched(system, False),
                  "march_fused": lambda: marched(system, True), "driver_numpy": lambda: driven(False),
                  "driver_fused": lambda: driven(True)}
        for block in blocks.values():                                     # compile or load outside the blocks
            block()
        seconds = {name: [] for name in blocks}
        iterations = {}
        for _ in range(args.repeats):
            for name, block in blocks.items():
                per_step, its, run = block()
                seconds[name].append(per_step)
                iterations[name] = its
                if name == "march_numpy":
                    state = run["state"] if not args.potential else run["state"][-1]
        use_compiled_laws(True)
        slipped = int(np.count_nonzero(np.abs(state.stretch) >= term.thresholds))
        medians = {name: statistics.median(v) for name, v in seconds.items()}
        rows = {name: {"us_per_step": 1e6 * medians[name], "spread_us": [1e6 * min(v), 1e6 * max(v)],
                       "all_us": [1e6 * x for x in v], "newton_iterations_per_step": iterations[name],
                       "over_linear": medians[name] / medians["linear"],
                       "march_numpy_over": medians["march_numpy"] / medians[name]}
                for name, v in seconds.items()}
        result["rows"][f"r={r}"] = {"sliders_at_their_limit_at_the_end": slipped, **rows}
        print(f"\nr = {r}, {args.sliders} sliders ({slipped} at their limit at the end):")
        print("| path | us per step (median) | spread | / linear | march_numpy / this | Newton it./step |\n"
              "|---|---|---|---|---|---|")
        for name, row in rows.items():
            print(f"| {name} | {row['us_per_step']:.2f} | {row['spread_us'][0]:.2f}-{row['spread_us'][1]:.2f} "
                  f"| {row['over_linear']:.2f} | {row['march_numpy_over']:.1f} | "
                  f"{row['newton_iterations_per_step']:.3f} |")
    out = RESULTS.with_name("iwan_rom_step_potential.json") if args.potential else RESULTS
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))
    print(f"written: {out}")


if __name__ == "__main__":
    main()
