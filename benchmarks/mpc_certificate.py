"""What the MPC's accuracy certificate costs a step: ``LinearMPC(accuracy=1e-4)`` (the default)
against ``accuracy=None`` on the closed loop of ``benchmarks/mpc_solve.py``.

The same modal model, weights, bound, OSQP at tolerance 1e-6 (``condensed_osqp``) and feasible
reference as ``mpc_solve.py``; per size r and setting, ``--steps`` closed-loop steps, the median
QP seconds over the steps after the first; the settings alternate in ``--repeats`` blocks, and
the table gives the median over the blocks, the spread, the ratio, and how many plans the
certificate repaired or refused (and the tracking error of both: the same loop).

Run ``python -m benchmarks.mpc_certificate [--sizes 6 20] [--repeats 3]``; it prints a table and
writes ``benchmarks/results/mpc_certificate.json``.
"""

from __future__ import annotations

import argparse
import json
import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
import platform
import statistics
import warnings
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from benchmarks.mpc_solve import BOUND, HORIZON, modal_model, reference
from femrom.control import KalmanObserver, LinearMPC, QPSolver, StateSpacePlant, closed_loop

SETTINGS = {"off": None, "1e-4": 1e-4}


def run_one(model, Y, accuracy, steps: int) -> dict:
    rms = float(np.sqrt(np.mean(Y ** 2)))
    controller = LinearMPC(model, horizon=HORIZON, output_weight=1.0 / rms ** 2, input_weight=0.0,
                           input_rate_weight=1e-4 / BOUND ** 2, input_bound=BOUND,
                           solver=QPSolver("osqp", tolerance=1e-6), accuracy=accuracy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = closed_loop(StateSpacePlant(model), controller, KalmanObserver(model, disturbance="output"), Y,
                             n_steps=steps, progress=False)
    return {"seconds": float(np.median(result.qp_seconds[1:])), "repaired": controller.n_repaired,
            "fallbacks": result.n_fallbacks, "tracking_error": result.tracking_error()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[6, 20])
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "mpc_certificate.json"))
    args = parser.parse_args(argv)
    rows = []
    for r in args.sizes:
        model = modal_model(r)
        _, Y = reference(model, args.steps + HORIZON + 10)
        runs = {name: [] for name in SETTINGS}
        for _ in range(args.repeats):                       # alternating blocks
            for name, accuracy in SETTINGS.items():
                runs[name].append(run_one(model, Y, accuracy, args.steps))
        row = {"r": r, "qp_unknowns": HORIZON * model.n_inputs}
        for name, results in runs.items():
            seconds = [x["seconds"] for x in results]
            row[name] = {"ms_per_step": 1e3 * statistics.median(seconds),
                         "ms_spread": [1e3 * min(seconds), 1e3 * max(seconds)],
                         "repaired": results[-1]["repaired"], "fallbacks": results[-1]["fallbacks"],
                         "tracking_error": results[-1]["tracking_error"]}
        row["ratio"] = row["1e-4"]["ms_per_step"] / row["off"]["ms_per_step"]
        rows.append(row)
        print(f"r = {r:2d} (m N = {row['qp_unknowns']}): off {row['off']['ms_per_step']:.2f} ms, "
              f"certified {row['1e-4']['ms_per_step']:.2f} ms ({row['1e-4']['ms_spread'][0]:.2f}-"
              f"{row['1e-4']['ms_spread'][1]:.2f}), ratio {row['ratio']:.2f}; repaired "
              f"{row['1e-4']['repaired']} of {args.steps} plans, fallbacks {row['1e-4']['fallbacks']}; tracking "
              f"{row['off']['tracking_error']:.3e} / {row['1e-4']['tracking_error']:.3e}")
    out = {"benchmark": "mpc_certificate", "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
           "machine": platform.processor() or platform.machine(), "steps": args.steps, "repeats": args.repeats,
           "rows": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
