"""Euler-Bernoulli cantilever FOM: tip response, energy, and what accuracy costs in time.

A steel cantilever (Hermite elements on a Gmsh line) is released from its
static deflection under a tip load (``beam.toml``). The case writes, into its
output folder:

- ``response.png``: tip and midspan deflection and the relative energy change;
- ``accuracy_cost_dt.png`` and the table in ``report.md``: tip error against
  stepping time for a ladder of time steps (reference: dt / 8 on the same mesh);
- ``accuracy_cost_mesh.png``: error of the first four natural frequencies
  against the analytic cantilever roots, for a ladder of mesh sizes, against
  assembly + eigen-solve time;
- ``metrics.json`` (every number above, timings of each stage) and ``scene.toml``.

Run ``python -m femrom run beam [--out DIR] [--quick]``; tests import :func:`run`.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from femrom.integrators import simulate
from femrom.post import accuracy_cost_table, plot_accuracy_cost, plot_response, write_metrics
from femrom.post._report import machine_description
from femrom.scene import Scene, build

SCENE = Path(__file__).with_suffix(".toml")

# beta_n L of a cantilever (Blevins 1979, table 8-1; ../shared/DESIGN.md)
CANTILEVER_ROOTS = np.array([1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349])


def with_time_step(scene: Scene, dt: float) -> Scene:
    return dataclasses.replace(scene, time=dataclasses.replace(scene.time, dt=dt))


def with_mesh_size(scene: Scene, mesh_size: float) -> Scene:
    params = dict(scene.structure.parameters) | {"mesh_size": mesh_size}
    structure = dataclasses.replace(scene.structure, parameters=tuple(sorted(params.items())))
    return dataclasses.replace(scene, structure=structure)


def analytic_frequencies(scene: Scene, count: int = 4) -> np.ndarray:
    """Cantilever omega_n = (beta_n L)^2 sqrt(E I / (rho A L^4)) [rad/s]."""
    m = scene.material
    length = dict(scene.structure.parameters)["length"]
    return CANTILEVER_ROOTS[:count] ** 2 * np.sqrt(
        m.youngs_modulus * m.second_moment / (m.density * m.area * length**4))


def fe_frequencies(model, count: int = 4) -> np.ndarray:
    from scipy.sparse.linalg import eigsh

    s = model.system
    values = eigsh(s.stiffness.tocsc(), k=count, M=s.mass.tocsc(), sigma=0.0, which="LM")[0]
    return np.sqrt(np.sort(values))


def time_step_ladder(scene: Scene, factors=(8, 4, 2, 1), reference_divisor=8) -> list[dict]:
    """Tip error (max over time, relative to the peak tip deflection) against stepping cost."""
    model = build(scene)
    dt0 = scene.time.dt
    reference = simulate(model, dt=dt0 / reference_divisor)
    coarse = max(factors) * dt0
    t_common = np.arange(0.0, scene.time.t_end + 0.5 * coarse, coarse)
    ref_tip = np.interp(t_common, reference.times, reference.outputs[0])
    scale = np.max(np.abs(ref_tip))
    rows = []
    for factor in factors:
        result = simulate(model, dt=factor * dt0)
        tip = np.interp(t_common, result.times, result.outputs[0])
        rows.append({"dt": factor * dt0, "steps": result.summary["n_steps"],
                     "tip_error": float(np.max(np.abs(tip - ref_tip)) / scale),
                     "stepping_seconds": result.summary["stepping_seconds"]})
    dts = np.array([r["dt"] for r in rows])
    errors = np.array([r["tip_error"] for r in rows])
    order = float(np.polyfit(np.log(dts), np.log(errors), 1)[0])
    for r in rows:
        r["observed_order"] = order
    return rows


def mesh_ladder(scene: Scene, mesh_sizes=(0.2, 0.1, 0.05, 0.025)) -> list[dict]:
    exact = analytic_frequencies(scene)
    rows = []
    for h in mesh_sizes:
        tic = time.perf_counter()
        model = build(with_mesh_size(scene, h))
        omega = fe_frequencies(model)
        seconds = time.perf_counter() - tic
        rows.append({"mesh_size": h, "dofs": model.system.n_dofs,
                     "frequency_error": float(np.max(np.abs(omega / exact - 1))),
                     "f1_hz": float(omega[0] / (2 * np.pi)), "seconds": seconds})
    return rows


def run(out_dir, *, quick: bool = False, scene_path=SCENE) -> dict:
    """Run the case; return its metrics (also written to ``out_dir/metrics.json``)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    scene = Scene.from_toml(scene_path)
    if quick:
        scene = with_time_step(dataclasses.replace(
            scene, time=dataclasses.replace(scene.time, t_end=0.5)), 4 * scene.time.dt)

    tic = time.perf_counter()
    model = build(scene)
    build_seconds = time.perf_counter() - tic
    result = simulate(model)
    energy = result.energy
    drift = float(np.max(np.abs(energy - energy[0])) / energy[0])

    plot_response(out_dir / "response.png", result.times, result.outputs, model.system.output_names,
                  energy, title=f"cantilever FOM, {model.system.n_dofs} dofs, {result.summary['scheme']}")
    (out_dir / "scene.toml").write_text(scene.source_text)

    dt_rows = time_step_ladder(scene, factors=(8, 4, 2, 1) if not quick else (4, 2, 1))
    mesh_rows = mesh_ladder(scene, (0.1, 0.05, 0.025) if quick else (0.2, 0.1, 0.05, 0.025, 0.0125))
    plot_accuracy_cost(out_dir / "accuracy_cost_dt.png", dt_rows, "stepping_seconds", "tip_error", "dt",
                       title="FOM time step: tip error vs stepping time")
    plot_accuracy_cost(out_dir / "accuracy_cost_mesh.png", mesh_rows, "seconds", "frequency_error", "dofs",
                       title="FOM mesh: frequency error vs build + eigensolve time")

    omega = fe_frequencies(model)
    exact = analytic_frequencies(scene)
    metrics = {
        "case": "beam", "scene": scene.name, "n_dofs": model.system.n_dofs,
        "machine": machine_description(),
        "build_seconds": build_seconds, "build_timings": model.timings,
        "simulation": result.summary,
        "energy_relative_drift": drift,
        "frequencies_hz": omega / (2 * np.pi), "analytic_frequencies_hz": exact / (2 * np.pi),
        "time_step_ladder": dt_rows, "mesh_ladder": mesh_rows,
    }
    write_metrics(out_dir / "metrics.json", metrics)
    report = [
        f"# {scene.description}", "",
        f"{model.system.n_dofs} free dofs, {result.summary['n_steps']} steps of {scene.time.dt:g} s "
        f"with {result.summary['scheme']} in {result.summary['stepping_seconds']:.2f} s; "
        f"relative energy drift {drift:.2e}.", "",
        "## Time step: tip error (vs dt/8) against stepping time", "",
        accuracy_cost_table(dt_rows, ["dt", "steps", "tip_error", "stepping_seconds"]), "",
        f"Observed order {dt_rows[0]['observed_order']:.2f}; Newmark average acceleration is second "
        "order once every excited mode is resolved (omega dt << 1). The release from a static tip "
        "load excites the whole spectrum (modal amplitudes fall only as 1/omega^2), so at these steps "
        "the phase errors of the higher modes, which grow with their frequency, keep the observed "
        "tip-error order below 2 (pre-asymptotic); the energy stays conserved at every step size.", "",
        "## Mesh: first four natural frequencies against the analytic roots", "",
        accuracy_cost_table(mesh_rows, ["mesh_size", "dofs", "frequency_error", "f1_hz", "seconds"]), "",
    ]
    (out_dir / "report.md").write_text("\n".join(report))
    return metrics


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="femrom run beam", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results") / "beam")
    parser.add_argument("--quick", action="store_true", help="short window and ladders (tests)")
    args = parser.parse_args(argv)
    metrics = run(args.out, quick=args.quick)
    print(f"beam: {metrics['n_dofs']} dofs, {metrics['simulation']['n_steps']} steps in "
          f"{metrics['simulation']['stepping_seconds']:.2f} s, energy drift {metrics['energy_relative_drift']:.1e}, "
          f"f1 = {metrics['frequencies_hz'][0]:.3f} Hz (analytic {metrics['analytic_frequencies_hz'][0]:.3f}); "
          f"report in {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
