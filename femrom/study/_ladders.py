"""The FOM's accuracy against its cost: coarser time steps against the scene's."""

from __future__ import annotations

import numpy as np

from femrom.study._metrics import relative_error
from femrom.study._runs import FOMRun, run_fom


def time_step_ladder(model, reference: FOMRun, factors=(10, 5, 2), *, min_block_seconds: float = 0.1) -> list[dict]:
    """Output error of runs at ``factor * dt`` against ``reference`` (a run at the scene's ``dt``),
    their stepping time and per-step cost, and the observed order of convergence.

    The runs use the reference's signals and window; every coarse step must divide
    the window (all are compared on the coarsest grid, at the same final time).
    """
    dt0, t_end = reference.dt, float(reference.times[-1])
    factors = tuple(sorted(factors, reverse=True))
    for factor in factors:
        steps = t_end / (factor * dt0)
        if abs(steps - round(steps)) > 1e-9 * steps:
            raise ValueError(f"time step {factor * dt0:g} does not divide the window {t_end:g} s")
    coarse = factors[0] * dt0
    t_common = coarse * np.arange(int(round(t_end / coarse)) + 1)

    def on_grid(run):
        return np.vstack([np.interp(t_common, run.times, y) for y in run.outputs])

    ref = on_grid(reference)
    rows = []
    for factor in factors:
        run = run_fom(model, reference.inputs.signals, name=f"dt/{factor}", dt=factor * dt0, t_end=t_end,
                      min_block_seconds=min_block_seconds)
        rows.append(_row(run, relative_error(ref, on_grid(run))))
    rows.append(_row(reference, 0.0))
    if len(factors) >= 2:
        order = float(np.polyfit(np.log([r["dt"] for r in rows[:-1]]),
                                 np.log([r["output_error"] for r in rows[:-1]]), 1)[0])
        for r in rows:
            r["observed_order"] = order
    return rows


def _row(run: FOMRun, error: float) -> dict:
    s = run.summary
    return {"dt": run.dt, "steps": s["n_steps"], "output_error": error, "stepping_seconds": s["stepping_seconds"],
            "seconds_per_step": run.cost.median, "cost": run.cost.to_dict()}
