"""L-OpInf fit time against the reduced dimension r, for every solver.

The problem: a damped, forced elastic string (P1 elements, n = 600 free dofs,
Rayleigh damping, one point force ``u(t)``, released from a static deflection)
integrated with Newmark average acceleration; mass-orthonormal POD bases of
r = 10, 30, 60, 100, 150, 200 from its snapshots; fourth-order finite-difference
derivatives; L-OpInf with damping and input terms and a relative Tikhonov
weight of 1e-8. Solvers:

- ``fast``: :func:`femrom.inference.solve_fast` (its ``method`` column says which
  path ran: the interior-point method on ill-conditioned data, the first-order
  path on well-conditioned data);
- ``clarabel``, ``scs``: the cvxpy reference (:func:`femrom.inference.solve_conic`);
- a solver is skipped where its time, extrapolated from the largest size it
  ran as ``t ~ r^6`` (Clarabel, and fast on its interior-point path: dense
  Newton systems of ~r^2 unknowns) or ``t ~ r^4`` (SCS, fast on its first-order
  path), would exceed ``--limit`` (two minutes by default; said so in the table);
- ``least_squares``: plain second-order OpInf (no structure), for scale.

The objective column is ``||M^ Q'' + C^ Q' + K^ Q - B^ U||^2 + Tikhonov``; the
gap column is ``(f - f_best) / f_best`` against the lowest objective any
structure-preserving solver reached at that r (plain least squares solves an
unconstrained problem, so its objective is a lower bound, shown for scale).

``--problem random`` runs the same ladder on random data with many active
constraints (``random_data``) instead.

``--fast-method interior_point`` (or ``first_order``) forces one path of the fast
solver (``FastSolver(method=...)``); the interior point is then taken even above
``ipm_max_unknowns`` (r = 200: a 13 GB Newton matrix, docs/inference.md).

Run ``python -m benchmarks.fit_ladder [--sizes 10 30 60] [--problem string|random]
[--fast-method auto|interior_point|first_order] [--out benchmarks/results]``; it
prints a table and writes ``fit_ladder.json`` (``fit_ladder_random.json``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from skfem import MeshLine

from femrom.fem import Condensation, axial_stiffness, line_basis, line_mass, rayleigh_damping
from femrom.inference import (FastSolver, LagrangianOpInf, SecondOrderData, SecondOrderOpInf,
                              reduce_snapshots, solve_conic, solve_fast)
from femrom.integrators import Newmark, Trajectory, integrate
from femrom.scene import SecondOrderSystem

SIZES = (10, 30, 60, 100, 150, 200)
SOLVERS = ("fast", "clarabel", "scs")
#: The conic solvers' own wall-clock limits (seconds), set to ``--limit``.
TIME_LIMIT_OPTION = {"clarabel": "time_limit", "scs": "time_limit_secs"}
LIMIT_SECONDS = 120.0
#: Assumed growth of a solver's time with r when predicting whether to skip it
#: (Clarabel and the interior-point path of fast: dense systems with ~r^2
#: unknowns; the others: r^4 covers what was measured).
GROWTH = {"clarabel": 6, "scs": 4, "fast": 4, "fast/interior_point": 6}


def string_data(n_elements: int = 601, dt: float = 2e-4, steps: int = 4000):
    """Newmark snapshots of a damped, forced string; returns (M, q, U, dt)."""
    mesh = MeshLine(np.linspace(0.0, 1.0, n_elements + 1))
    basis = line_basis(mesh, "p1")
    fixed = basis.get_dofs(np.array([0, n_elements])).all()
    c = Condensation.from_fixed(basis.N, fixed)
    M, K = c.matrix(line_mass(basis, 1.0)), c.matrix(axial_stiffness(basis, 1.0))
    n = M.shape[0]
    B = np.zeros((n, 1))
    B[n // 3, 0] = 1.0 / n
    inputs = lambda t: np.array([np.sin(40.0 * t) + 0.5 * np.sin(170.0 * t)])  # noqa: E731
    system = SecondOrderSystem(mass=M, stiffness=K, damping=rayleigh_damping(M, K, 0.5, 1e-5),
                               input_matrix=B, inputs=inputs)
    x = c.vector(mesh.p[0])
    q0 = np.minimum(x, 1 - x) * 0.01                 # triangular pluck: every mode excited
    trajectory = Trajectory(fields=("q",))
    integrate(system, Newmark(), q0, np.zeros(n), dt, steps, consumers=[trajectory])
    U = np.column_stack([inputs(t) for t in trajectory.t])
    return M, trajectory.q, U, dt


def mass_pod(M, Q, r):
    R = np.linalg.cholesky(M.toarray()).T              # M = R^T R
    U = np.linalg.svd(R @ Q, full_matrices=False)[0]
    return np.linalg.solve(R, U[:, :r])                 # V^T M V = I


def random_data(r: int, seed: int = 0) -> SecondOrderData:
    """Random reduced data (10 r snapshots) whose unconstrained fit is indefinite:
    about half of the eigenvalues of K^ and C^ end on their bounds."""
    rng = np.random.default_rng(seed)
    K = 10 * r
    Q, Qd, U = rng.standard_normal((r, K)), rng.standard_normal((r, K)), rng.standard_normal((2, K))
    A = rng.standard_normal((r, r))
    Y = -((A + A.T) @ Q + (0.5 * (A - A.T) - np.eye(r)) @ Qd - rng.standard_normal((r, 2)) @ U)
    return SecondOrderData(states=Q, velocities=Qd, accelerations=Y + 0.1 * rng.standard_normal((r, K)),
                           inputs=U)


def run(sizes=SIZES, out_dir: Path | None = None, problem_kind: str = "string",
        limit: float = LIMIT_SECONDS, solvers=None, fast_method: str = "auto") -> list[dict]:
    solvers = SOLVERS if solvers is None else tuple(solvers)
    if problem_kind == "string":
        M, Q, U, dt = string_data()
    rows = []
    times = {"fast": {}, "clarabel": {}, "scs": {}}
    growth = dict(GROWTH)
    for r in sizes:
        if problem_kind == "string":
            V = mass_pod(M, Q, r)
            data = reduce_snapshots(V, Q, dt, product=M, inputs=U, order=4)
        else:
            data = random_data(r)
        problem = LagrangianOpInf(["damping"], regularization=1e-8).regression(data)
        results = {}
        for name in solvers:
            predicted = None
            if times[name]:
                r0 = max(times[name])
                predicted = times[name][r0] * (r / r0) ** growth[name]
            if predicted is not None and predicted > limit:
                results[name] = {"skipped": f"predicted {predicted:.0f} s > {limit:.0f} s"}
                continue
            if name == "fast":
                _, info = solve_fast(problem, FastSolver(method=fast_method))
            else:   # a run that would overshoot the prediction stops at the limit, said so
                tic = time.perf_counter()
                try:
                    _, info = solve_conic(problem, name.upper(), **{TIME_LIMIT_OPTION[name]: limit})
                except Exception as exc:       # noqa: BLE001 - reported in the table
                    results[name] = {"skipped": f"no solution within {limit:.0f} s ({exc})",
                                     "stopped_after": time.perf_counter() - tic}
                    continue
            results[name] = info
            times[name][r] = info["seconds"]
            if name == "fast":
                growth["fast"] = GROWTH.get(f"fast/{info.get('method')}", GROWTH["fast"])
        plain = SecondOrderOpInf(["damping"], regularization=1e-8)
        tic = time.perf_counter()
        plain.fit(data)
        results["least_squares"] = {"seconds": time.perf_counter() - tic,
                                    "objective": plain.objective_, "status": "unconstrained"}
        reached = [v["objective"] for k, v in results.items()
                   if k != "least_squares" and "objective" in v]
        best = min(reached) if reached else None
        for name, info in results.items():
            row = {"r": r, "solver": name, "n_samples": data.n_samples, "problem": problem_kind,
                   "date": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
            if "skipped" in info:
                row.update(seconds=None, objective=None, gap=None, status=info["skipped"],
                           stopped_after=info.get("stopped_after"))
            else:
                row.update(seconds=float(info["seconds"]), objective=float(info["objective"]),
                           gap=None if best is None else float((info["objective"] - best) / best),
                           status=str(info.get("status")),
                           gap_estimate=info.get("gap_estimate"))
                if name == "fast":
                    row.update(method=info.get("method"), condition=info.get("condition"),
                               ipm_iterations=info.get("ipm_iterations"),
                               admm_iterations=info.get("iterations"),
                               certificate=info.get("certificate"), active=info.get("active"))
            rows.append(row)
            print(_format(row), flush=True)
        if out_dir is not None:
            _write(out_dir, problem_kind, rows)
    return rows


def _write(out_dir, problem_kind, rows):
    """Write the rows, merged into the existing file: a (r, solver) this run measured
    replaces the old row, the others stay (each row keeps its own ``date``)."""
    if out_dir is not None:
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        name = "fit_ladder.json" if problem_kind == "string" else f"fit_ladder_{problem_kind}.json"
        ran = {(row["r"], row["solver"]) for row in rows}
        kept = []
        if (out_dir / name).is_file():
            old = json.loads((out_dir / name).read_text())
            kept = [dict(row, date=row.get("date", old.get("date"))) for row in old.get("rows", [])
                    if (row["r"], row["solver"]) not in ran]
        order = SOLVERS + ("least_squares",)
        rows = sorted(kept + rows, key=lambda row: (row["r"], order.index(row["solver"])))
        payload = {"benchmark": "fit_ladder", "machine": platform.platform(),
                   "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "load_average": os.getloadavg(),
                   "load_average_at_start": _LOAD_AT_START,
                   "processor": platform.processor(), "problem": problem_kind,
                   "description": __doc__.split("\n\n")[1], "rows": rows}
        (out_dir / name).write_text(json.dumps(payload, indent=2))


_LOAD_AT_START = os.getloadavg()


def _format(row) -> str:
    seconds = "skipped" if row["seconds"] is None else f"{row['seconds']:9.3f}"
    objective = "" if row["objective"] is None else f"{row['objective']:.9e}"
    gap = "" if row["gap"] is None else f"{row['gap']:+.1e}"
    extra = ""
    if row.get("method"):
        extra = f"  [{row['method']}, kappa {row['condition']:.1e}, certified gap {row['gap_estimate']:.1e}]"
    return (f"r={row['r']:4d}  {row['solver']:14s} {seconds:>9s} s  f={objective:17s} gap={gap:9s} "
            f"{row['status']}{extra}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--problem", choices=("string", "random"), default="string")
    parser.add_argument("--limit", "--max-seconds", dest="limit", type=float, default=LIMIT_SECONDS,
                        help="skip a solver whose predicted time exceeds this (seconds)")
    parser.add_argument("--solvers", nargs="+", choices=SOLVERS, default=list(SOLVERS),
                        help="a subset to (re)measure; the file keeps the other rows")
    parser.add_argument("--fast-method", choices=("auto", "interior_point", "first_order"), default="auto",
                        help="FastSolver(method=...) of the fast column (interior_point is taken even "
                             "above ipm_max_unknowns)")
    args = parser.parse_args(argv)
    run(args.sizes, args.out, args.problem, args.limit, args.solvers, args.fast_method)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
