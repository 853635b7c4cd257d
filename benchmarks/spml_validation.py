"""SpML on full-order models whose nonlinear potential is known: learned force and predictions.

Two FOMs with a known nonlinear potential, each released from a family of
initial states (the amplitude scaled), Newmark average acceleration, stored
displacements, velocities and accelerations:

- ``sine_gordon``: ``femrom/cases/sine_gordon.toml`` at n = 200 interior nodes, dt = 0.02, the
  breather's initial velocity scaled by the amplitude; trained on [0, 5] s, predicted to
  25 s (400 % outside the training window, as in the seed);
- ``cubic_beam``: ``femrom/cases/beam.toml`` (Hermite cantilever, 100 dofs) with a cubic spring
  at the tip (``spring_layer``, k3 = 1e7 N/m^3: at the 9.5 mm static deflection of 10 N the
  cubic force is about the beam's tip stiffness) and Rayleigh damping (alpha = 1 /s),
  released from the static deflection under a tip load scaled by the amplitude; trained on
  [0, 0.03] s, predicted to 0.15 s.

The basis is the mass-orthonormal POD (r modes) of all training trajectories. For a
growing number of training trajectories, SpML's conservative acceleration
``M^^-1 (K^ q + dU^/dq)`` is compared with Galerkin's on the states of an unseen test
trajectory (:func:`femrom.study.force_error`, relative to the projected nonlinear force).
With the most data, the test trajectory is predicted by Galerkin, L-OpInf with the known
force projected (the route the sine-Gordon case takes), L-OpInf alone (linear) and SpML,
all with the discrete-gradient scheme at the FOM's dt; errors are ``||Q^ - Q^_FOM||_F /
||Q^_FOM||_F`` of the reduced coordinates inside and outside the training window. Costs:
SpML's training time, seconds per ROM step (fastest of ``--repeats`` runs) and per FOM step.

Run ``python -m benchmarks.spml_validation [--fom sine_gordon cubic_beam]``;
it prints a table and writes ``benchmarks/results/spml_validation.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
import tomllib
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from femrom.basis import POD
from femrom.cases import scene_file
from femrom.inference import (LagrangianOpInf, ProjectedNonlinearForce, SpML, SpMLConfig, galerkin,
                              reduce_snapshots)
from femrom.integrators import Trajectory, simulate
from femrom.rom import SecondOrderROM
from femrom.scene import Scene, build
from femrom.study import force_error

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Family:
    """A FOM released from scaled initial states: what the validation trains and tests on."""

    name: str
    text: str           # the scene file, with {amplitude} where the initial state scales
    dt: float
    train_window: float
    t_end: float
    train_amplitudes: tuple
    test_amplitude: float
    rank: int
    damping: bool

    def model(self, amplitude: float, t_end: float):
        scene = Scene.from_dict(tomllib.loads(self.text.replace("{amplitude}", repr(float(amplitude)))))
        return build(scene.with_time(dt=self.dt, t_end=t_end))


def sine_gordon(n: int = 200, rank: int = 8, amplitudes=(1.0, 0.6, 0.8, 0.9, 0.7, 0.65, 0.75, 0.85)) -> Family:
    text = scene_file("sine_gordon").read_text()
    text = text.replace('velocity = "4.0 * 0.6', 'velocity = "{amplitude} * 4.0 * 0.6')
    elements = n + 1
    text = text.replace("mesh_size = 0.019990004997501248, probe_position = 0.49975012493753124",
                        f"mesh_size = {40.0 / elements!r}, probe_position = {(elements // 2) / elements!r}")
    return Family("sine_gordon", text, 0.02, 5.0, 25.0, tuple(amplitudes), 0.95, rank, False)


def cubic_beam(rank: int = 8, amplitudes=(1.0, 0.6, 0.8, 0.9, 0.7, 0.65, 0.75, 0.85)) -> Family:
    text = scene_file("beam").read_text()
    text = text.replace("bending = {}", 'bending = {}\nspring_layer = { at = "right", component = "w", cubic = 1.0e7 }\n'
                                        'damping = { kind = "rayleigh", alpha = 1.0, beta = 0.0 }')
    text = text.replace("magnitude = 10.0", "magnitude = {amplitude}")
    return Family("cubic_beam", text, 2.0e-4, 0.03, 0.15, tuple(10.0 * a for a in amplitudes), 9.5, rank, True)


def fom_run(family: Family, amplitude: float, t_end: float):
    """``(model, trajectory, seconds per step)``: the FOM from one initial state, q, v, a kept."""
    model = family.model(amplitude, t_end)
    trajectory = Trajectory(fields=("q", "v", "a"))
    tic = time.perf_counter()
    simulate(model, consumers=[trajectory], progress=False)
    return model, trajectory, (time.perf_counter() - tic) / (trajectory.t.size - 1)


def reduced(trajectory, basis, mass, dt):
    return reduce_snapshots(basis, trajectory.q, dt, product=mass, velocities=trajectory.v,
                            accelerations=trajectory.a, derivatives="stored")


def window_errors(Q, reference, split: int) -> dict:
    def error(columns):
        return float(np.linalg.norm(Q[:, columns] - reference[:, columns]) / np.linalg.norm(reference[:, columns]))
    return {"train_window_error": error(slice(0, split + 1)), "extrapolation_error": error(slice(split + 1, None))}


def validate(family: Family, sizes=(1, 2, 4, 8), config: SpMLConfig = SpMLConfig(), repeats: int = 3) -> dict:
    train = [fom_run(family, a, family.train_window) for a in family.train_amplitudes[:max(sizes)]]
    model, test, fom_step = fom_run(family, family.test_amplitude, family.t_end)
    system, M, dt = model.system, model.system.mass, family.dt
    V = POD(rank=family.rank, product=M).fit(np.hstack([t.q for _, t, _ in train])).basis_
    data = [reduced(t, V, M, dt) for _, t, _ in train]
    test_data = reduced(test, V, M, dt)
    reference = galerkin(system, V, mass_orthonormal=True)
    known = ProjectedNonlinearForce.galerkin(system, V)
    split = int(round(family.train_window / dt))
    terms = ["damping"] if family.damping else []
    states = test_data.states

    growth = []
    for size in sizes:
        learner = SpML(terms, config=config, progress=False).fit(data[:size])
        growth.append({"trajectories": size, "snapshots": int(sum(d.n_samples for d in data[:size])),
                       "force_error": force_error(learner.operators_, reference, states),
                       "linear_force_error": force_error(learner.linear_.operators_, reference, states),
                       "loss": learner.loss_, "linear_loss": learner.linear_loss_,
                       "training_seconds": learner.training_seconds_, "iterations": learner.iterations_})
        print(f"{family.name}: {size} trajectories, force error {growth[-1]['force_error']:.3e} "
              f"(L-OpInf alone {growth[-1]['linear_force_error']:.3e}), fit {learner.training_seconds_:.1f} s",
              flush=True)
    models = {"galerkin": reference,
              "lopinf_known": LagrangianOpInf([*terms, known]).fit(data).operators_,
              "lopinf": LagrangianOpInf(terms).fit(data).operators_,
              "spml": learner.operators_}
    times = test_data.times - test_data.times[0]
    rows = []
    for name, operators in models.items():
        rom = SecondOrderROM(operators, V, product=M)
        best, solution = np.inf, None
        for _ in range(repeats):
            solution = rom.predict(times, initial=(states[:, 0], test_data.velocities[:, 0]), scheme="discrete_gradient")
            best = min(best, solution.info["seconds_per_step"])
        energy = solution.energy
        rows.append({"method": name, "r": family.rank, **window_errors(solution.q, states, split),
                     "force_error": force_error(operators, reference, states),
                     "energy_change": float((energy[-1] - energy[0]) / abs(energy[0])),
                     "energy_increase_max": float(np.max(np.diff(energy)) / abs(energy[0])),
                     "seconds_per_step": best, "speedup_over_fom": fom_step / best})
    return {"fom": family.name, "n_dofs": system.n_dofs, "r": family.rank, "dt": dt,
            "train_window": family.train_window, "t_end": family.t_end,
            "fom_seconds_per_step": fom_step, "config": asdict(config), "growth": growth, "rows": rows}


def table(result: dict) -> str:
    lines = [f"{result['fom']} (n = {result['n_dofs']}, r = {result['r']}, trained on [0, {result['train_window']:g}], "
             f"predicted to {result['t_end']:g}; FOM step {result['fom_seconds_per_step'] * 1e3:.3f} ms)",
             "| trajectories | snapshots | SpML force error | L-OpInf force error | loss | fit s |",
             "|---|---|---|---|---|---|"]
    for g in result["growth"]:
        lines.append(f"| {g['trajectories']} | {g['snapshots']} | {g['force_error']:.2e} | {g['linear_force_error']:.2e} "
                     f"| {g['loss']:.1e} | {g['training_seconds']:.1f} |")
    lines += ["", "| method | error in window | error outside (400 %) | force error | energy change | ms/step | FOM/ROM |",
              "|---|---|---|---|---|---|---|"]
    for row in result["rows"]:
        lines.append(f"| {row['method']} | {row['train_window_error']:.2e} | {row['extrapolation_error']:.2e} | "
                     f"{row['force_error']:.2e} | {row['energy_change']:.1e} | {row['seconds_per_step'] * 1e3:.3f} | "
                     f"{row['speedup_over_fom']:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--fom", nargs="+", default=["sine_gordon", "cubic_beam"])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 2, 4, 8])
    parser.add_argument("--rank", type=int, default=8)
    parser.add_argument("--max-iterations", type=int, default=2000)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "spml_validation.json")
    args = parser.parse_args(argv)
    config = SpMLConfig(max_iterations=args.max_iterations)
    families = {"sine_gordon": sine_gordon(rank=args.rank), "cubic_beam": cubic_beam(rank=args.rank)}
    results = []
    for name in args.fom:
        result = validate(families[name], tuple(args.sizes), config)
        print(table(result), flush=True)
        results.append(result)
    payload = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                           "load_average": os.getloadavg()}, "results": results}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(payload, indent=1, default=float))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
