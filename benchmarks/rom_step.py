"""Online cost: one ROM time step against one FOM time step at n >= 1e5 dofs.

The FOM: the clamped steel cantilever of ``benchmarks/fom_ladder.py``
(``beam_solid``, P2 tetrahedra at the "medium" mesh size, about 1.05e5 free
dofs), a tip traction switched on at t = 0, Newmark average acceleration with
dt = 2e-4 s through ``femrom.integrators.integrate`` with PARDISO (factor of
``M + dt^2/4 K`` computed once and reused, as in the FOM ladder). Its time per
step is the median of the steps' wall times (``--fom-steps`` steps).

The ROMs: mass-orthonormal POD bases (method of snapshots, ``V^T M V = I``)
of the FOM displacements and velocities (completed by random M-orthonormal
vectors where the short run has fewer independent directions), r = 5, 10, 20, 40, with the intrusive Galerkin
operators (the step cost does not depend on how the operators were found:
an L-OpInf model has the same (r, r) matrices). Each ROM is stepped with
Newmark over ``--rom-steps`` steps in three ways:

- ``generic``: the reduced matrices wrapped as a ``SecondOrderSystem`` and
  stepped by the same FOM driver (``integrate``, solver "auto"): what a ROM
  step costs without a dedicated path (the "before");
- ``predict``: ``SecondOrderROM.predict`` (precomputed one-step map
  ``x_{k+1} = A x_k + F u_{k+1}``, preallocated C-ordered output, one
  ``dot(out=)`` per step; the "after"), ``info["seconds_per_step"]``;
- ``kernel``: the bare loop of that path (``femrom.integrators.run_linear``).

Reported per r: median over ``--repeats`` repeats of the seconds per step,
and the ratios FOM step / ROM step (target: >= 1e4 at r = 20). The FOM and
the ROMs run in the same process, right after each other, so they see the
same machine load (recorded in the JSON as the load average).

Run ``python -m benchmarks.rom_step [--sizes 5 10 20 40] [--fom-steps 40]``;
it prints a table and writes ``benchmarks/results/rom_step.json``.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import statistics
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from benchmarks import fom_ladder  # the FOM problem and its constants
from femrom.integrators import Newmark, Trajectory, integrate
from femrom.rom import SecondOrderROM
from femrom.integrators import LinearParts, run_linear, time_scheme
from femrom.scene import SecondOrderSystem

SIZES = (5, 10, 20, 40)


class _Clock:
    def __init__(self):
        self.stamps = []

    def __call__(self, result):
        self.stamps.append(time.perf_counter())


def fom_run(size: str, element: str, n_steps: int):
    """(system, snapshots (n, 2 n_steps): displacements and velocities, per-step seconds, summary)."""
    system, _, _ = fom_ladder._cantilever(size, element)
    fom_ladder._warm_up("pardiso")
    trajectory, clock = Trajectory(fields=("q", "v")), _Clock()
    summary = integrate(system, Newmark(), np.zeros(system.n_dofs), np.zeros(system.n_dofs),
                        fom_ladder.DT, n_steps, consumers=[trajectory, clock], solver="pardiso",
                        progress=False)
    steps = list(np.diff(clock.stamps))
    Q, V = np.asarray(trajectory.q)[:, 1:], np.asarray(trajectory.v)[:, 1:]
    # a step response of a few dozen steps has fewer independent displacements
    # than r = 40: the basis is the POD of displacements and velocities together
    return system, np.hstack([Q / np.linalg.norm(Q), V / np.linalg.norm(V)]), steps, summary


def mass_pod(M, Q: np.ndarray, r: int, seed: int = 0) -> tuple[np.ndarray, int]:
    """(n, r) basis with ``V^T M V = I``, and how many of its columns are POD modes.

    Method of snapshots on ``Q^T M Q``; a short step response excites fewer
    independent directions than r = 40 above round-off (17 of 60 snapshots
    at 1e-7 relative amplitude here), so the basis is completed with random
    vectors: the cost of a reduced step depends on r only.
    """
    MQ = M @ Q
    g, W = np.linalg.eigh(Q.T @ MQ)
    order = np.argsort(g)[::-1]
    order = order[g[order] > 1e-12 * g[order[0]]][:r]
    V = Q @ (W[:, order] / np.sqrt(g[order]))
    if V.shape[1] < r:
        rng = np.random.default_rng(seed)
        V = np.hstack([V, rng.standard_normal((Q.shape[0], r - V.shape[1]))])
    # M-orthonormalize (Cholesky of the M-Gram matrix), twice against round-off
    for _ in range(2):
        R = np.linalg.cholesky(V.T @ (M @ V))
        V = np.linalg.solve(R, V.T).T
    return V, int(order.size)


def _time_rom(rom: SecondOrderROM, n_steps: int, repeats: int, generic_steps: int):
    ops = rom.operators_
    r = ops.r
    times = np.arange(n_steps + 1) * fom_ladder.DT
    inputs = np.ones((1, n_steps + 1))
    out = {"predict": [], "kernel": [], "generic": []}
    for _ in range(repeats):
        gc.collect()
        sol = rom.predict(times, inputs, scheme="newmark")
        out["predict"].append(sol.info["seconds_per_step"])
        A, F = time_scheme("newmark").step_map(LinearParts(ops.mass_matrix, ops.damping, ops.stiffness),
                                                  fom_ladder.DT, ops.input_matrix)
        forcing = F @ inputs[:, 1:]
        tic = time.perf_counter()
        run_linear(A, np.zeros(A.shape[0]), n_steps, forcing)
        out["kernel"].append((time.perf_counter() - tic) / n_steps)
    # the generic FOM driver on the reduced matrices (slow: fewer steps)
    import scipy.sparse as sp
    reduced = SecondOrderSystem(mass=sp.csr_matrix(ops.mass_matrix),
                                stiffness=sp.csr_matrix(ops.stiffness),
                                input_matrix=ops.input_matrix, inputs=lambda t: np.ones(1))
    for _ in range(repeats):
        summary = integrate(reduced, Newmark(), np.zeros(r), np.zeros(r), fom_ladder.DT,
                            generic_steps, progress=False)
        out["generic"].append(summary.stepping_seconds / generic_steps)
    # the same trajectory from both ROM paths (checks that the timings compare like with like)
    check = Trajectory(fields=("q",))
    integrate(reduced, Newmark(), np.zeros(r), np.zeros(r), fom_ladder.DT, 50,
              consumers=[check], progress=False)
    lean = rom.predict(times[:51], inputs[:, :51], scheme="newmark").q
    generic_q = np.asarray(check.q)
    agreement = float(np.max(np.abs(lean - generic_q)) / max(np.max(np.abs(generic_q)), 1e-300))
    return {k: statistics.median(v) for k, v in out.items()}, out, agreement


def run(sizes=SIZES, fom_steps: int = 40, rom_steps: int = 100_000, repeats: int = 5,
        generic_steps: int = 2000, mesh_size: str = "medium", element: str = "p2",
        out: Path | None = None) -> dict:
    tic = time.perf_counter()
    system, Q, steps, summary = fom_run(mesh_size, element, fom_steps)
    fom_step = statistics.median(steps)
    print(f"FOM: {system.n_dofs} free dofs ({element.upper()}, {mesh_size}), PARDISO, Newmark, "
          f"{fom_steps} steps: median step {fom_step * 1e3:.2f} ms "
          f"(mean {summary.stepping_seconds / fom_steps * 1e3:.2f} ms), "
          f"setup {summary.setup_seconds:.1f} s", flush=True)
    rows = []
    for r in sizes:
        V, n_pod = mass_pod(system.mass, Q, r)
        rom = SecondOrderROM.galerkin(system, V, product=system.mass, mass_orthonormal=True)
        med, raw, agreement = _time_rom(rom, rom_steps, repeats, generic_steps)
        row = {"r": r, "pod_columns": n_pod, "fom_step_seconds": fom_step,
               **{f"{k}_step_seconds": v for k, v in med.items()},
               **{f"fom_over_{k}": fom_step / v for k, v in med.items()},
               "generic_over_predict": med["generic"] / med["predict"],
               "lean_vs_generic_max_rel_diff": agreement, "raw": raw}
        rows.append(row)
        print(f"r={r:3d}  generic {med['generic'] * 1e6:8.2f} us  predict {med['predict'] * 1e6:7.3f} us"
              f"  kernel {med['kernel'] * 1e6:7.3f} us   FOM/predict {fom_step / med['predict']:9.3g}"
              f"  FOM/generic {fom_step / med['generic']:8.3g}  (paths agree to {agreement:.1e})",
              flush=True)
    payload = {
        "benchmark": "rom_step", "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "machine": platform.platform(), "processor": platform.processor(),
        "cpu_count": os.cpu_count(), "load_average": os.getloadavg(),
        "description": __doc__.split("\n\n")[1],
        "fom": {"n_free": int(system.n_dofs), "element": element, "mesh_size": mesh_size,
                "dt": fom_ladder.DT, "n_steps": fom_steps, "step_seconds_median": fom_step,
                "step_seconds": steps, "setup_seconds": summary.setup_seconds,
                "solver": summary.solver},
        "rom_steps": rom_steps, "generic_steps": generic_steps, "repeats": repeats,
        "rows": rows, "seconds": time.perf_counter() - tic,
    }
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(payload, indent=2, default=float))
    return payload


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    parser.add_argument("--fom-steps", type=int, default=40)
    parser.add_argument("--rom-steps", type=int, default=100_000)
    parser.add_argument("--generic-steps", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--mesh-size", default="medium", choices=tuple(fom_ladder.MESH_SIZES))
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).parent / "results" / "rom_step.json")
    args = parser.parse_args(argv)
    run(args.sizes, args.fom_steps, args.rom_steps, args.repeats, args.generic_steps,
        args.mesh_size, "p2", args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
