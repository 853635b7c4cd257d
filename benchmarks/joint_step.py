"""What a step of the jointed beam costs once the linear part is Craig-Bampton reduced: the joint
in Newton against the linearised (stuck) joint, and the full FE model for reference.

The model: the free-free jointed beam (``meshes/jointed_beam.geo``, P2, 25.4 / 12.7 mm, no
holes: 7,908 dofs, 149 interface pairs), Rayleigh damping (alpha = 0.5 1/s, beta = 2e-7 s),
an Iwan JointForce on the pairs (F_S = 1e7 Pa, K_T = 1e12 Pa/m, chi = -0.5, beta = 0.1, a
linear normal spring 1e13 Pa/m, 60 sliders: plausible, not calibrated), the hammer (300 N
half-sine, 0.3 ms) on the ``impact`` patch, acc3 read on its patch. Craig-Bampton onto the
joint's, the hammer's and acc3's dofs plus ``--modes`` fixed-interface modes.

Measured in one process (Newmark average acceleration, dt = 50 us, each block from rest through
the blow, ``--steps`` steps):

- ``linear``: the reduced model with the joint replaced by its tangent at rest, ``K^ + (L T)^T
  D_0 (L T)``: one factorisation, one solve per step;
- ``nonlinear``: the reduced model with the joint in Newton on its own 447 coordinates
  (``Newton(method="condensed", rtol=1e-10)``);

alternating ``--repeats`` times (medians of the blocks' mean step times), so that a change of
load on the shared machine hits both. Reported: ``nonlinear / linear`` (the issue's target:
within 3x). Then, once each, the full FE model's linear and nonlinear steps
(``--full-steps``, 0 to skip), and with ``--ring-down SECONDS`` a ring-down of the reduced
model with its energy balance (:class:`femrom.integrators.EnergyBalance`).

Run ``python -m benchmarks.joint_step`` (about 2-3 minutes; ``--ring-down 1``
adds about 8 minutes); it prints a table and writes ``benchmarks/results/joint_step.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

import femrom.mesh as fm
from femrom.fem import JointForce, interface_law
from femrom.integrators import EnergyBalance, Newmark, Newton, OutputRecorder, integrate
from femrom.scene import Scene, build, craig_bampton

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "joint_step.json"
PARAMETERS = {"mesh_size": 0.0254, "joint_mesh_size": 0.0127, "bonded": 0, "holes": 0}
PATCH, PEAK, WIDTH, DT = 0.00635, 300.0, 3e-4, 5e-5
LAW = {"slip_traction": 1e7, "tangential_stiffness": 1e12, "chi": -0.5, "beta": 0.1, "normal_stiffness": 1e13}


def jointed_beam():
    """The free-free jointed beam with the Iwan joint on its P2 interface pairs (a SecondOrderSystem)."""
    scene = Scene.from_dict({
        "name": "jointed_brb",
        "structure": {"geometry": "jointed_beam", "element": "p2", "parameters": PARAMETERS},
        "material": {"youngs_modulus": 2.0e11, "poisson_ratio": 0.29, "density": 7800.0},
        "effects": {"inertia": {}, "elasticity": {}, "damping": {"alpha": 0.5, "beta": 2e-7}, "actuation": {}},
        "inputs": [{"name": "hammer", "load": {"kind": "surface_traction", "at": "impact", "direction": [0, -1, 0],
                                              "magnitude": 1 / PATCH**2},
                    "signal": {"kind": "impulse", "amplitude": PEAK, "duration": WIDTH, "start": 1e-4}}],
        "outputs": {"averages": [{"name": "acc3", "over": "acc3", "component": "y"}]},
        "time": {"t_end": 0.01, "dt": DT}})
    mesh = fm.build_mesh("jointed_beam", PARAMETERS)
    linear = build(scene, mesh=mesh).system
    pairs = fm.interface_pairs(mesh, "interface_left", "interface_right", order=2)
    dofs = pairs.dofs()
    joint = JointForce(interface_law("iwan", **LAW), dofs[:, 0], dofs[:, 1], pairs.normals, pairs.areas,
                       linear.n_dofs, name="joint")
    return dataclasses.replace(linear, nonlinear=joint)


def linearised(system):
    """The system with the joint replaced by its tangent at rest (stuck and closed)."""
    joint = system.nonlinear
    D0 = joint.local_tangent(np.zeros(joint.n_local), None, joint.initial_state())[0]
    stiffness = (system.stiffness + joint.local_map.T @ D0 @ joint.local_map).tocsr()
    return dataclasses.replace(system, stiffness=stiffness, nonlinear=None)


NEWMARK = Newmark(newton=Newton(rtol=1e-10, method="condensed"))


def block(system, n_steps: int) -> dict:
    """One run from rest through the blow: mean step time and Newton counts."""
    zero = np.zeros(system.n_dofs)
    summary = integrate(system, NEWMARK, zero, zero, DT, n_steps, progress=False)
    return {"step_seconds": summary.stepping_seconds / n_steps, "setup_seconds": summary.setup_seconds,
            "newton_iterations_per_step": summary.newton_iterations / n_steps,
            "local_factorizations": summary.details.get("local_factorizations", 0)}


def ring_down(system, cb, seconds: float) -> dict:
    ledger, acc3 = EnergyBalance(system), OutputRecorder(system)
    n_steps = int(round(seconds / DT))
    tic = time.perf_counter()
    zero = np.zeros(system.n_dofs)
    summary = integrate(system, NEWMARK, zero, zero, DT, n_steps, consumers=[ledger, acc3], progress=False)
    wall = time.perf_counter() - tic
    work = float(ledger.external_work[-1])
    y = np.asarray(acc3.outputs)[0] if np.ndim(acc3.outputs) == 2 else np.asarray(acc3.outputs)
    windows = int(seconds / 0.1)
    peaks = [float(np.abs(y[int(k * 0.1 / DT) + 1:int((k + 1) * 0.1 / DT) + 1]).max()) for k in range(windows)]
    return {"seconds": seconds, "n_steps": n_steps, "wall_seconds": wall,
            "step_seconds": summary.stepping_seconds / n_steps,
            "newton_iterations_per_step": summary.newton_iterations / n_steps,
            "external_work": work, "rayleigh": float(ledger.rayleigh[-1]), "friction": float(ledger.friction[-1]),
            "left": float(ledger.kinetic[-1] + ledger.strain[-1] + ledger.joint_energy[-1]),
            "worst_scheme_residual": float(np.abs(ledger.scheme_residual).max() / work),
            "worst_step_residual": float(np.abs(ledger.residual).max() / work),
            "acc3_displacement_peak_per_100ms": peaks}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--modes", type=int, default=30)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--full-steps", type=int, default=40)
    parser.add_argument("--ring-down", type=float, default=0.0, help="seconds of reduced ring-down (0: none)")
    parser.add_argument("--solver", default="superlu", help="K_ii factorisation strategy of craig_bampton")
    args = parser.parse_args(argv)

    load_before = os.getloadavg()
    tic = time.perf_counter()
    system = jointed_beam()
    build_seconds = time.perf_counter() - tic
    tic = time.perf_counter()
    cb = craig_bampton(system, args.modes, solver=args.solver)
    cb_seconds = time.perf_counter() - tic
    reduced, reduced_linear = cb.system, linearised(cb.system)
    blocks = {"linear": [], "nonlinear": []}
    for _ in range(args.repeats):
        blocks["linear"].append(block(reduced_linear, args.steps))
        blocks["nonlinear"].append(block(reduced, args.steps))
    median = {name: statistics.median(b["step_seconds"] for b in runs) for name, runs in blocks.items()}
    result = {
        "n_dofs": system.n_dofs, "n_pairs": system.nonlinear.n_pairs, "n_boundary": cb.n_boundary,
        "n_modes": cb.n_modes, "n_reduced": reduced.n_dofs, "joint_coordinates": system.nonlinear.n_local,
        "build_seconds": build_seconds, "craig_bampton_seconds": cb_seconds, "craig_bampton_stages": cb.seconds,
        "interior_frequencies_hz": cb.interior_frequencies[:5].tolist(), "law": {"kind": "iwan", **LAW},
        "dt": DT, "steps": args.steps, "repeats": args.repeats, "blocks": blocks,
        "median_step_seconds": median, "nonlinear_over_linear": median["nonlinear"] / median["linear"],
    }
    if args.full_steps:
        result["full"] = {"linear": block(linearised(system), args.full_steps),
                          "nonlinear": block(system, args.full_steps)}
    if args.ring_down > 0:
        result["ring_down"] = ring_down(reduced, cb, args.ring_down)
    result["load_average"] = {"before": load_before, "after": os.getloadavg()}
    payload = {"benchmark": "joint_step", "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
               "description": __doc__.split("\n\n")[1], "cpu_count": os.cpu_count(), "result": result}
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(payload, indent=2, default=float))

    print(f"jointed beam: {system.n_dofs} dofs, {result['n_pairs']} pairs -> Craig-Bampton "
          f"{cb.n_boundary} + {cb.n_modes} = {reduced.n_dofs} coordinates in {cb_seconds:.1f} s")
    print(f"{'model':<28}{'step [ms]':>12}{'Newton it/step':>16}")
    for name in ("linear", "nonlinear"):
        iterations = statistics.median(b["newton_iterations_per_step"] for b in blocks[name])
        print(f"{'reduced, ' + name:<28}{1e3 * median[name]:>12.2f}{iterations:>16.2f}")
    if "full" in result:
        for name, values in result["full"].items():
            print(f"{'full FE, ' + name:<28}{1e3 * values['step_seconds']:>12.2f}"
                  f"{values['newton_iterations_per_step']:>16.2f}")
    print(f"nonlinear / linear (reduced): {result['nonlinear_over_linear']:.2f} (target <= 3)")
    if "ring_down" in result:
        r = result["ring_down"]
        print(f"ring-down {r['seconds']} s: work {r['external_work']:.4g} J, Rayleigh {r['rayleigh']:.4g}, "
              f"friction {r['friction']:.4g}, left {r['left']:.4g}; worst step residual "
              f"{r['worst_step_residual']:.2g} of the work (scheme {r['worst_scheme_residual']:.2g})")
    print(f"written {RESULTS.relative_to(ROOT)}")
    return result


if __name__ == "__main__":
    main()
