"""QP seconds per MPC step at horizon 50: m = 6 inputs, p = 40 outputs, r = 2, 6, 10, 20.

The controller's model: a modal second-order ROM with r modes (natural frequencies
1 to 40 Hz spread over the modes, 1 % modal damping, M^ = I), six random input columns and
40 outputs sampled from beam-like mode shapes sin(i pi x) at x = 0.025 .. 1
(``ReducedOperators.from_matrices``), exported by ``SecondOrderROM.to_state_space(0.01)``
(Newmark, n = 2 r states, a feedthrough D). A closed loop runs it against itself
(``StateSpacePlant``, Kalman observer with an output-disturbance model) tracking a feasible
reference: its response to six sines of amplitude 0.05 (1-3 Hz), inside the bound
|u| <= 0.1. Weights: Q = I / rms(reference)^2, R = 0, S = 1e-4 I / b^2 (input moves);
tolerance 1e-6.

Per configuration (r, formulation, solver) and repeat: ``--steps`` closed-loop steps, each
timed as the wall time of ``LinearMPC.control`` (gradient or parameters, cvxpy's solve
with its canonicalisation and the solver, unpacking), the median over the steps after the
first (the first solve compiles the QP) and the solver's own median time. Reported: the
median over ``--repeats`` repeats, the tracking error (a check that the QP was solved), and
the ratio to the baseline measured in the same run: the unconstrained condensed QP solved
by a precomputed Cholesky factor (``scipy.linalg.cho_solve``) for the same gradient, the
cheapest possible step of the same problem. The target is <= 10 ms per step at r <= 20
(faster than real time at dt = 0.01 s).

BLAS runs on one thread (``OMP_NUM_THREADS`` etc. set to 1 unless already set): a controller
process on a core of its own; on two shared cores, threaded BLAS made the same small products
several times slower.

Run ``python -m benchmarks.mpc_solve [--sizes 2 6 10 20] [--repeats 3]``; it
prints a table and writes ``benchmarks/results/mpc_solve.json``.
"""

from __future__ import annotations

import argparse
import json
import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
import platform
import statistics
import time
import warnings
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import scipy.linalg as sla

from femrom.control import KalmanObserver, LinearMPC, StateSpacePlant, closed_loop, open_loop
from femrom.inference import ReducedOperators
from femrom.rom import SecondOrderROM

SIZES = (2, 6, 10, 20)
FORMULATIONS = ("condensed", "sparse", "condensed_osqp")
SOLVERS = ("OSQP", "CLARABEL")
HORIZON, N_INPUTS, N_OUTPUTS, DT, BOUND = 50, 6, 40, 0.01, 0.1


def modal_model(r: int, seed: int = 0):
    """The Newmark state space of a modal ROM with r modes, 6 inputs and 40 outputs."""
    rng = np.random.default_rng(seed)
    omega = 2 * np.pi * np.geomspace(1.0, 40.0, r)
    x = np.linspace(0.025, 1.0, N_OUTPUTS)
    shapes = np.sin(np.outer(x, np.arange(1, r + 1)) * np.pi)                  # (p, r)
    ops = ReducedOperators.from_matrices(np.diag(omega ** 2), mass=np.eye(r), damping=np.diag(0.02 * omega),
                                         input_matrix=rng.standard_normal((r, N_INPUTS)) * omega[:, None] ** 2 / 50,
                                         output_matrix=shapes)
    return SecondOrderROM(ops).to_state_space(DT)


def reference(model, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """(inputs (m, K), outputs (p, K)): six sines of amplitude 0.05 and the model's response."""
    t = DT * np.arange(n_samples)
    frequencies = np.linspace(1.0, 3.0, N_INPUTS)
    U = 0.05 * np.sin(2 * np.pi * frequencies[:, None] * t + np.arange(N_INPUTS)[:, None])
    U[:, 0] = 0.0
    return U, open_loop(StateSpacePlant(model), U)


def baseline_seconds(controller: LinearMPC, model, windows: list, repeats: int = 200) -> float:
    """Median seconds of the unconstrained condensed solve: gradient map + two triangular solves."""
    from femrom.control import CondensedQP

    qp = CondensedQP.from_problem(controller.qp)
    factor = sla.cho_factor(qp.hessian)
    n, p = model.n_states, model.n_outputs
    z, u, zeros_n, zeros_p = np.zeros(n), np.zeros(model.n_inputs), np.zeros(n), np.zeros(p)
    times = []
    for k in range(repeats):
        window = windows[k % len(windows)]
        tic = time.perf_counter()
        sla.cho_solve(factor, -qp.gradient(z, window, u, zeros_n, zeros_p, zeros_n))
        times.append(time.perf_counter() - tic)
    return statistics.median(times)


def run_one(model, U, Y, formulation: str, solver: str, steps: int) -> dict:
    rms = float(np.sqrt(np.mean(Y ** 2)))
    controller = LinearMPC(model, horizon=HORIZON, output_weight=1.0 / rms ** 2, input_weight=0.0,
                           input_rate_weight=1e-4 / BOUND ** 2, input_bound=BOUND, formulation=formulation,
                           solver=solver, tolerance=1e-6)
    observer = KalmanObserver(model, disturbance="output")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = closed_loop(StateSpacePlant(model), controller, observer, Y, n_steps=steps, progress=False)
    qp = result.qp_seconds[1:]
    solver_seconds = result.solver_seconds[1:]
    return {"qp_seconds_per_step": float(np.median(qp)), "qp_seconds_max": float(np.max(qp)),
            "first_solve_seconds": float(result.qp_seconds[0]),
            "solver_seconds_per_step": float(np.nanmedian(solver_seconds)),
            "iterations": float(np.median(controller.iterations[1:])),
            "tracking_error": result.tracking_error(), "max_constraint_violation": result.max_constraint_violation(),
            "n_fallbacks": result.n_fallbacks, "controller": controller}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    parser.add_argument("--formulations", nargs="+", default=list(FORMULATIONS))
    parser.add_argument("--solvers", nargs="+", default=list(SOLVERS))
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "mpc_solve.json"))
    args = parser.parse_args(argv)
    rows = []
    for r in args.sizes:
        model = modal_model(r)
        U, Y = reference(model, args.steps + HORIZON + 1)
        windows = [Y[:, k:k + HORIZON] for k in range(args.steps)]
        for formulation in args.formulations:
            for solver in args.solvers:
                if formulation == "condensed_osqp" and solver != "OSQP":
                    continue
                runs, baselines = [], []
                for _ in range(args.repeats):
                    run = run_one(model, U, Y, formulation, solver, args.steps)
                    baselines.append(baseline_seconds(run.pop("controller"), model, windows))
                    runs.append(run)
                row = {"r": r, "n_states": model.n_states, "formulation": formulation, "solver": solver}
                for key in runs[0]:
                    row[key] = statistics.median(run[key] for run in runs)
                row["baseline_seconds"] = statistics.median(baselines)
                row["ratio_to_baseline"] = row["qp_seconds_per_step"] / row["baseline_seconds"]
                row["meets_10ms"] = row["qp_seconds_per_step"] <= 0.010
                row["repeats_qp_seconds"] = [run["qp_seconds_per_step"] for run in runs]
                rows.append(row)
                print(f"r={r:2d} {formulation:9s} {solver:8s} step {row['qp_seconds_per_step'] * 1e3:7.2f} ms "
                      f"(solver {row['solver_seconds_per_step'] * 1e3:6.2f} ms, {row['iterations']:.0f} it) "
                      f"max {row['qp_seconds_max'] * 1e3:7.2f} ms  x{row['ratio_to_baseline']:.0f} baseline  "
                      f"tracking {row['tracking_error']:.1e}", flush=True)
    header = "| r | formulation | solver | ms per step (median) | solver ms | max ms | x baseline | tracking error |"
    lines = [header, "|---|---|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['r']} | {row['formulation']} | {row['solver']} | {row['qp_seconds_per_step'] * 1e3:.2f} "
                     f"| {row['solver_seconds_per_step'] * 1e3:.2f} | {row['qp_seconds_max'] * 1e3:.1f} "
                     f"| {row['ratio_to_baseline']:.0f} | {row['tracking_error']:.1e} |")
    table = "\n".join(lines)
    print(table)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({
        "benchmark": "mpc_solve", "horizon": HORIZON, "n_inputs": N_INPUTS, "n_outputs": N_OUTPUTS, "dt": DT,
        "input_bound": BOUND, "steps": args.steps, "repeats": args.repeats, "rows": rows, "table": table,
        "machine": {"platform": platform.platform(), "processor": platform.processor(),
                    "cpu_count": os.cpu_count(), "load_average": os.getloadavg(),
                    "blas_threads": os.environ.get("OMP_NUM_THREADS")},
        "timestamp": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }, indent=1))


if __name__ == "__main__":
    main()
