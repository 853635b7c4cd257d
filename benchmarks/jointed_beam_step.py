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

The two nonlinear models step three times: with the interface law in numpy (``_numpy``), with
its compiled kernels inside the numpy step (``_compiled``: the force's compiled joint hidden
from the scheme) and with the whole step as one compiled call (``_fused``: the default with
the compiled laws on, :func:`femrom.fem.use_compiled_laws`). The blocks alternate
``--repeats`` times; the medians of their mean step times, and their spread
(min-max), give the ratios against ``linear`` (the issue's target: a nonlinear step within
3x). An untimed run of the hyper-reduced model counts the law's calls per step and keeps
the sampled pairs' last gaps and states, on which ``--calls`` evaluations (with the
tangent) and commits are timed the same way, numpy against compiled: law time per step =
calls x time per call, and the rest of the step is what is left outside the law.

The first fused step of a fresh process (``--processes`` of them, each cold: a new numba
cache folder, then warm: the same folder again) is timed on a small joint model, the
kernel's compile (or cache load) against a second step.

Run ``python -m benchmarks.jointed_beam_step`` (about 5 minutes); it prints
tables and writes ``benchmarks/results/jointed_beam_step.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from femrom.cases.jointed_beam import SCENE
from femrom.fem import compiled_laws, use_compiled_laws
from femrom.integrators import Newmark, StepResult, integrate
from femrom.study import JointedBeamModel

RESULTS = Path(__file__).resolve().parent / "results" / "jointed_beam_step.json"

FIRST_STEP = r"""
import json, time
tic = time.perf_counter()
import numpy as np
from femrom.fem import ClampedIwanLaw, JointForce, compiled_laws, transform_force
from femrom.integrators import Newmark, StepResult, integrate
from femrom.scene import SecondOrderSystem
out = {"import_femrom": time.perf_counter() - tic}
tic = time.perf_counter()
assert compiled_laws()
out["import_numba"] = time.perf_counter() - tic
s, n, r = 6, 36, 4                       # 6 pairs between two 6-node sides, 4 coordinates
law = ClampedIwanLaw(1e12, 1e11, -0.5, 0.4)
a = np.arange(3 * s).reshape(s, 3)
joint = JointForce(law, a, a + 3 * s, np.tile([0.0, 0.0, 1.0], (s, 1)), np.full(s, 1e-4), n)
V = np.random.default_rng(0).normal(size=(n, r))
state = law.initial_state(s)
state[:, -1] = (1e6, 1.0)
system = SecondOrderSystem(mass=np.eye(r), stiffness=1e8 * np.eye(r), nonlinear=transform_force(joint, V))
q0 = np.full(r, 1e-7)
for key in ("first_step", "second_step"):
    tic = time.perf_counter()
    summary = integrate(system, Newmark(), None, None, 1e-4, 1, start=StepResult.at_rest(r, state=state, q=q0),
                        progress=False)
    out[key] = time.perf_counter() - tic
    assert summary.details.get("compiled_step")
print(json.dumps(out))
"""


def first_steps(processes: int) -> dict:
    """Seconds of the first fused steps in fresh processes, cold and warm cache (lists, one per process)."""
    runs = {"cold": [], "warm": []}
    root = Path(__file__).resolve().parents[1]
    for _ in range(processes):
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "NUMBA_CACHE_DIR": cache, "FEMROM_COMPILED_LAWS": "1",
                   "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
            for kind in ("cold", "warm"):
                out = subprocess.run([sys.executable, "-c", FIRST_STEP], env=env, capture_output=True, text=True,
                                     check=True, cwd=root)
                runs[kind].append(json.loads(out.stdout))
    return {kind: {key: [run[key] for run in values] for key in values[0]} for kind, values in runs.items()}


def fused_step(system, fused: bool) -> None:
    """Let the scheme take the force's compiled joint (the default) or hide it: the numpy step with the compiled law."""
    force = system.nonlinear
    if fused:
        force.__dict__.pop("compiled_joint", None)
    else:
        force.compiled_joint = lambda: None


def block(system, state, dt: float, n_steps: int) -> tuple[float, int]:
    """Mean seconds per step over ``n_steps`` from rest, and the Newton iterations."""
    r = system.n_dofs
    rest = StepResult.at_rest(r, state=state)
    tic = time.perf_counter()
    summary = integrate(system, Newmark(), None, None, dt, n_steps, start=rest, progress=False)
    return (time.perf_counter() - tic) / n_steps, summary.newton_iterations


def law_calls(system, state, dt: float, n_steps: int):
    """Untimed: ``({"evaluate": calls per step, "commit": ...}, law, last gap, last state)`` of a joint model."""
    law = system.nonlinear.transformed.force_model.law
    cls = type(law)
    counts = {"evaluate": 0, "commit": 0}
    last = {}
    original = cls.evaluate, cls.commit

    def evaluate(self, gap, state, tangent=True):
        counts["evaluate"] += 1
        last["gap"], last["state"] = np.array(gap), np.array(state)
        return original[0](self, gap, state, tangent)

    def commit(self, gap, state):
        counts["commit"] += 1
        return original[1](self, gap, state)

    cls.evaluate, cls.commit = evaluate, commit
    try:
        integrate(system, Newmark(), None, None, dt, n_steps, start=StepResult.at_rest(system.n_dofs, state=state),
                  progress=False)
    finally:
        cls.evaluate, cls.commit = original
    return {key: value / n_steps for key, value in counts.items()}, law, last["gap"], last["state"]


def law_timings(law, gap, state, n_calls: int, repeats: int) -> dict:
    """Medians and spread [us] of ``evaluate`` (with the tangent) and ``commit``, numpy and compiled, alternating."""
    seconds = {}
    for _ in range(repeats):
        for compiled in (False, True):
            use_compiled_laws(compiled)
            for what, call in (("evaluate", lambda: law.evaluate(gap, state)), ("commit", lambda: law.commit(gap, state))):
                tic = time.perf_counter()
                for _ in range(n_calls):
                    call()
                seconds.setdefault(what, {}).setdefault("compiled" if compiled else "numpy", []).append(
                    (time.perf_counter() - tic) / n_calls)
    use_compiled_laws(True)
    return {what: {path: {"median_us": 1e6 * statistics.median(v), "min_us": 1e6 * min(v), "max_us": 1e6 * max(v)}
                   for path, v in paths.items()} for what, paths in seconds.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--modes", type=int, default=10)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--calls", type=int, default=1000)
    parser.add_argument("--processes", type=int, default=3)
    args = parser.parse_args()
    if not compiled_laws():
        raise SystemExit("the compiled kernels are off (numba missing or FEMROM_COMPILED_LAWS=0)")
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
    fused_step(hyper, False)
    calls, law, gap, state = law_calls(hyper, z_hyper, dt, min(args.steps, 1000))
    models = (("linear", linear, None, True, False),
              ("hyper_numpy", hyper, z_hyper, False, False), ("hyper_compiled", hyper, z_hyper, True, False),
              ("hyper_fused", hyper, z_hyper, True, True),
              ("all_pairs_numpy", all_pairs, z0, False, False), ("all_pairs_compiled", all_pairs, z0, True, False),
              ("all_pairs_fused", all_pairs, z0, True, True))
    for _, system, state0, _, fused in models[1:4]:                  # compile (or load) outside the blocks
        fused_step(system, fused)
        block(system, state0, dt, 2)
    seconds = {name: [] for name, *_ in models}
    iterations = {}
    for _ in range(args.repeats):
        for name, system, state0, compiled, fused in models:
            use_compiled_laws(compiled)
            if system.nonlinear is not None:
                fused_step(system, fused)
            per_step, newton = block(system, state0, dt, args.steps)
            seconds[name].append(per_step)
            iterations[name] = newton / args.steps
    use_compiled_laws(True)
    for system in (hyper, all_pairs):
        fused_step(system, True)
    first = first_steps(args.processes)
    medians = {name: statistics.median(values) for name, values in seconds.items()}
    laws = law_timings(law, gap, state, args.calls, args.repeats)
    law_ms = {path: 1e-3 * (calls["evaluate"] * laws["evaluate"][path]["median_us"]
                            + calls["commit"] * laws["commit"][path]["median_us"]) for path in ("numpy", "compiled")}
    result = {"machine": platform.platform(), "modes": args.modes, "pairs": int(sampling.n_pairs),
              "sampled_pairs": int(sampling.pairs.size), "law": "clamped_iwan",
              "sliders": int(law.n_elements), "steps_per_block": args.steps, "repeats": args.repeats, "dt": dt,
              "ms_per_step": {name: 1e3 * value for name, value in medians.items()},
              "spread_ms_per_step": {name: [1e3 * min(v), 1e3 * max(v)] for name, v in seconds.items()},
              "all_ms_per_step": {name: [1e3 * v for v in values] for name, values in seconds.items()},
              "newton_iterations_per_step": iterations,
              "ratio_to_linear": {name: medians[name] / medians["linear"] for name in medians if name != "linear"},
              "ratio_to_linear_per_repeat": {name: [x / y for x, y in zip(seconds[name], seconds["linear"])]
                                             for name in medians if name != "linear"},
              "speedup_compiled": {kind: medians[f"{kind}_numpy"] / medians[f"{kind}_compiled"]
                                   for kind in ("hyper", "all_pairs")},
              "speedup_fused_over_compiled": {kind: medians[f"{kind}_compiled"] / medians[f"{kind}_fused"]
                                              for kind in ("hyper", "all_pairs")},
              "first_fused_step_seconds": first,
              "hyper_law_calls_per_step": calls, "hyper_law_call_us": laws,
              "hyper_law_ms_per_step": law_ms,
              "hyper_outside_law_ms_per_step": {path: 1e3 * medians[f"hyper_{path}"] - law_ms[path]
                                                for path in ("numpy", "compiled")}}
    print("| step | ms (median of blocks) | spread (min-max) | / linear | / linear, same repeat (min-max) "
          "| Newton iterations per step |\n|---|---|---|---|---|---|")
    for name, value in medians.items():
        low, high = result["spread_ms_per_step"][name]
        paired = result["ratio_to_linear_per_repeat"].get(name, [1.0])
        print(f"| {name} | {1e3 * value:.3f} | {low:.3f}-{high:.3f} | {value / medians['linear']:.2f} "
              f"| {min(paired):.2f}-{max(paired):.2f} | {iterations[name]:.2f} |")
    print(f"\nhyper-reduced law ({sampling.pairs.size} pairs x {law.n_elements} sliders), "
          f"{calls['evaluate']:.2f} evaluations + {calls['commit']:.2f} commits per step:")
    print("| call | numpy [us] | compiled [us] | speed-up |\n|---|---|---|---|")
    for what, paths in laws.items():
        n, c = paths["numpy"], paths["compiled"]
        print(f"| {what} | {n['median_us']:.1f} ({n['min_us']:.1f}-{n['max_us']:.1f}) "
              f"| {c['median_us']:.1f} ({c['min_us']:.1f}-{c['max_us']:.1f}) | {n['median_us'] / c['median_us']:.1f} |")
    for path in ("numpy", "compiled"):
        print(f"{path}: law {law_ms[path]:.3f} ms a step, outside the law "
              f"{result['hyper_outside_law_ms_per_step'][path]:.3f} ms")
    print("\n| first fused step (fresh process) | cold cache [s] | warm cache [s] |\n|---|---|---|")
    for key in first["cold"]:
        cold, warm = first["cold"][key], first["warm"][key]
        print(f"| {key} | {statistics.median(cold):.3f} ({min(cold):.3f}-{max(cold):.3f}) "
              f"| {statistics.median(warm):.3f} ({min(warm):.3f}-{max(warm):.3f}) |")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=1))
    print(f"written: {RESULTS}")


if __name__ == "__main__":
    main()
