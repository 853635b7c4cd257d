"""Newton on a nonlinear force's own coordinates against Newton on every dof, at 1e5 dofs.

The FOM: a unit elastic cube (``beam_solid`` with ``length = width = height =
1 m``, P1 tetrahedra, about 1e5 free dofs, E = 10 MPa, nu = 0.3, rho = 1000
kg/m^3) clamped on its ``left`` face, its opposite ``right`` face on a Duffing
foundation (the ``spring_layer`` effect: ``k_1 = 1e6 N/m^3``, ``k_3 = 1e12
N/m^5`` on the normal displacement, the cubic term stiffening the layer
tenfold at 3 mm), driven by a sine pressure on its ``top`` face (amplitude
1e5 Pa at 8 Hz). The layer's dofs are about 1 % of the dofs. Newmark average
acceleration, dt = 2e-3 s, PARDISO.

Measured in one process, one after the other on the same machine:

- ``linear``: the same system without the layer (the linear path: one
  factorisation, one solve per step): median step time;
- ``condensed``: Newton on the layer's coordinates
  (:class:`femrom.integrators.ImplicitSolve`, ``Newton(method="condensed")``):
  ``S`` factorised once, ``G = L S^-1 L^T`` and its inverse once per dt, each
  iteration a dense (s, s) solve; median step time and seconds per local
  iteration; once with ``Z = S^-1 L^T`` stored, once with a second solve
  instead (``condense_memory=0``);
- ``full``: Newton on all dofs (``method="full"``): the effective tangent
  factorised afresh every iteration (PARDISO, nonsymmetric); seconds per
  iteration, over fewer steps.

The linear and condensed runs alternate ``--repeats`` times (medians of the
steps of all repeats), so a load change hits both. Both Newton runs converge
to ``rtol = 1e-12``; the condensed trajectory is compared with the full one
over the full run's steps. Reported: ``full iteration / condensed iteration``
(target >= 20), ``condensed step / linear step`` (target <= 2), the largest
relative trajectory difference (target <= 1e-10).

Run ``python -m benchmarks.nonlinear_subset [--mesh-size 0.03]``;
it prints a table and writes ``benchmarks/results/nonlinear_subset.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import json
import os
import statistics
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).parent / "results" / "nonlinear_subset.json"


def scene_dict(mesh_size: float, with_layer: bool = True) -> dict:
    effects = {"inertia": {"mass": "consistent"}, "elasticity": {}, "actuation": {}}
    if with_layer:
        effects["spring_layer"] = {"at": "right", "component": "x", "linear": 1e6, "cubic": 1e12}
    return {
        "name": "cube_on_duffing_layer",
        "structure": {"geometry": "beam_solid", "element": "p1",
                      "parameters": {"length": 1.0, "width": 1.0, "height": 1.0, "mesh_size": mesh_size}},
        "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3, "density": 1000.0},
        "effects": effects,
        "boundary": {"clamped": ["left"]},
        "inputs": [{"name": "pressure", "load": {"kind": "surface_pressure", "at": "top", "magnitude": 1e5},
                    "signal": {"kind": "sine", "frequency": 8.0}}],
        "time": {"t_end": 1.0, "dt": 2e-3, "solver": "pardiso"},
    }


class StepClock:
    """A consumer that keeps the wall time between consecutive steps (and the states, optionally)."""

    def __init__(self, keep: bool = False):
        self.times, self.keep, self.q = [], keep, []

    def __call__(self, result):
        self.times.append(time.perf_counter())
        if self.keep:
            self.q.append(result.q)

    @property
    def steps(self) -> list[float]:
        return list(np.diff(self.times[1:]))   # step 0 is the initial state: no step before it


def run_once(system, scheme, n_steps: int, dt: float, keep: bool = False):
    from femrom.integrators import integrate

    gc.collect()
    clock = StepClock(keep)
    n = system.n_dofs
    summary = integrate(system, scheme, np.zeros(n), np.zeros(n), dt, n_steps, consumers=[clock],
                        solver="pardiso", progress=False)
    return clock, summary


def run(mesh_size: float = 0.03, steps: int = 30, full_steps: int = 6, repeats: int = 3,
        out: Path | None = RESULTS) -> dict:
    from femrom.integrators import Newmark, Newton
    from femrom.scene import Scene, build

    tic = time.perf_counter()
    model = build(Scene.from_dict(scene_dict(mesh_size)))
    system = model.system
    dt = model.scene.time.dt
    layer = system.nonlinear
    linear = dataclasses.replace(system, nonlinear=None)
    n, s = system.n_dofs, layer.n_local
    print(f"cube: {n} free dofs (P1), spring layer on {s} of them ({100 * s / n:.2f} %), "
          f"assembly {time.perf_counter() - tic:.1f} s", flush=True)
    tight = dict(rtol=1e-12, condense_max=10**6, condense_fraction=1.0)
    variants = {"linear": (linear, Newmark()),
                "condensed": (system, Newmark(newton=Newton(method="condensed", **tight))),
                "condensed_no_z": (system, Newmark(newton=Newton(method="condensed", condense_memory=0,
                                                                   **tight)))}
    step_times = {name: [] for name in variants}
    summaries = {name: [] for name in variants}
    for repeat in range(repeats):
        for name, (sys_, scheme) in variants.items():
            clock, summary = run_once(sys_, scheme, steps, dt)
            step_times[name] += clock.steps
            summaries[name].append(dataclasses.asdict(summary))
            print(f"  repeat {repeat}: {name:15s} median step {statistics.median(clock.steps):.4f} s, "
                  f"setup {summary.setup_seconds:.1f} s, Newton iterations {summary.newton_iterations}",
                  flush=True)
    # the reference: Newton on every dof, refactorising the tangent every iteration
    condensed_ref, condensed_summary = run_once(system, variants["condensed"][1], full_steps, dt, keep=True)
    full_clock, full_summary = run_once(system, Newmark(newton=Newton(method="full", rtol=1e-12)),
                                        full_steps, dt, keep=True)
    Qc, Qf = np.array(condensed_ref.q), np.array(full_clock.q)
    norms = np.maximum(np.linalg.norm(Qf, axis=1), np.finfo(float).tiny)
    difference = float(np.max(np.linalg.norm(Qc - Qf, axis=1)[1:] / norms[1:]))
    medians = {name: statistics.median(times) for name, times in step_times.items()}
    details = [sm["details"] for sm in summaries["condensed"]]
    local_iteration = sum(d["local_newton_seconds"] for d in details) / max(sum(d["local_iterations"]
                                                                                for d in details), 1)
    full_iteration = full_summary.stepping_seconds / max(full_summary.newton_iterations, 1)
    refactorisation = full_summary.factorization_seconds / max(full_summary.n_factorizations, 1)
    payload = {
        "benchmark": "nonlinear_subset", "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "description": __doc__.split("\n\n")[1], "cpu_count": os.cpu_count(), "load_average": os.getloadavg(),
        "n_dofs": int(n), "layer_coordinates": int(s), "layer_fraction": s / n, "dt": dt,
        "steps": steps, "full_steps": full_steps, "repeats": repeats, "mesh_size": mesh_size,
        "median_step_seconds": medians,
        "condensed_iteration_seconds": local_iteration,
        "full_iteration_seconds": full_iteration,
        "full_refactorisation_seconds": refactorisation,
        "condensation_setup_seconds": details[0]["condensation_seconds"],
        "newton_iterations_per_step": {"condensed": summaries["condensed"][0]["newton_iterations"] / steps,
                                       "full": full_summary.newton_iterations / full_steps},
        "ratios": {"full_iteration_over_condensed_iteration": full_iteration / local_iteration,
                   "refactorisation_over_condensed_iteration": refactorisation / local_iteration,
                   "condensed_step_over_linear_step": medians["condensed"] / medians["linear"],
                   "condensed_no_z_step_over_linear_step": medians["condensed_no_z"] / medians["linear"]},
        "trajectory_max_relative_difference": difference,
        "summaries": summaries, "full_summary": dataclasses.asdict(full_summary),
        "seconds": time.perf_counter() - tic,
    }
    print(table(payload))
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(payload, indent=2, default=float))
    return payload


def table(p: dict) -> str:
    r = p["ratios"]
    m = p["median_step_seconds"]
    rows = [
        "| quantity | measured | target |",
        "|---|---:|---|",
        f"| free dofs / layer coordinates | {p['n_dofs']:,} / {p['layer_coordinates']:,} "
        f"({100 * p['layer_fraction']:.2f} %) | about 1e5 / 1 % |",
        f"| linear step (median) [s] | {m['linear']:.4f} | |",
        f"| condensed step, Z stored / second solve [s] | {m['condensed']:.4f} / {m['condensed_no_z']:.4f} | |",
        f"| condensed step / linear step | {r['condensed_step_over_linear_step']:.2f} "
        f"({r['condensed_no_z_step_over_linear_step']:.2f} with a second solve) | <= 2 |",
        f"| condensed iteration [s] | {p['condensed_iteration_seconds']:.4f} | |",
        f"| full iteration [s] (refactorisation alone) | {p['full_iteration_seconds']:.2f} "
        f"({p['full_refactorisation_seconds']:.2f}) | |",
        f"| full iteration / condensed iteration | {r['full_iteration_over_condensed_iteration']:.0f} | >= 20 |",
        f"| Newton iterations per step, condensed / full | {p['newton_iterations_per_step']['condensed']:.2f} / "
        f"{p['newton_iterations_per_step']['full']:.2f} | |",
        f"| condensation set-up per dt [s] | {p['condensation_setup_seconds']:.1f} | |",
        f"| largest relative trajectory difference | {p['trajectory_max_relative_difference']:.1e} | <= 1e-10 |",
    ]
    return "\n".join(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mesh-size", type=float, default=0.03)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--full-steps", type=int, default=6)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    run(args.mesh_size, args.steps, args.full_steps, args.repeats, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
