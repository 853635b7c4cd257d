r"""MPC closed loops on a full-order model: each controller model on each reference, one row per loop.

For every controller model (a discrete state space, e.g. a ROM or an identified model of size
``r``) and every reference ``y_ref`` (p, K), :func:`closed_loop_rows` runs
:func:`femrom.control.closed_loop` on the FOM (:class:`~femrom.control.FullOrderPlant`, its own
Newmark integrator, one factorisation for all loops) with

- :class:`~femrom.control.LinearMPC` of horizon ``N``, the weights scaled to the reference and the
  input bound ``b``: output weight ``1 / s^2`` with ``s = rms(y_ref)``, no input weight, rate
  weight ``w_rate / b^2``, ``|u| <= b``;
- :class:`~femrom.control.KalmanObserver` with process noise ``I`` and measurement noise
  ``w_meas s^2 I`` (optionally a constant output disturbance per output: offset-free tracking).

Each row: the loop's metrics (:meth:`~femrom.control.ClosedLoopResult.metrics`), the controller
model's open-loop error on the inputs the loop applied (:func:`open_loop_error`: what feedback
had to correct), ``s`` and the loop's wall time.
"""

from __future__ import annotations

import time

import numpy as np

from femrom.control import FullOrderPlant, KalmanObserver, LinearMPC, closed_loop
from femrom.post import accuracy_cost_table, plot_closed_loops, render_closed_loop
from femrom.study._metrics import relative_error
from femrom.snapshots import solver_factory

#: Columns of a report table of :func:`closed_loop_rows`.
CLOSED_LOOP_COLUMNS = ["controller", "r", "reference", "tracking_error", "model_error_on_applied_inputs",
                       "input_effort", "max_constraint_violation", "qp_seconds_per_step", "qp_seconds_max",
                       "n_fallbacks"]


def open_loop_error(model, result) -> float:
    """``||y_model - y||_F / ||y||_F``: ``model`` (a discrete state space) run from rest on the inputs the
    closed loop ``result`` applied, against the plant's outputs."""
    predicted = model.simulate(result.inputs, np.zeros(model.n_states))[0]
    return relative_error(result.outputs, predicted)


def closed_loop_rows(fom, dt: float, models: dict, controllers, references: dict, n_steps: int, *, horizon: int,
                     input_bound: float, rate_weight: float = 1e-3, measurement_noise: float = 1e-2,
                     disturbance: str | None = "output", record=None, progress=None) -> tuple[list[dict], dict]:
    """Closed loops on the FOM (module docstring): ``(rows, results)``.

    Parameters
    ----------
    fom : FullOrderModel
        The plant (:func:`femrom.scene.build`'s result): its system steps with one cached factorisation
        (:func:`solver_factory`, freed at the end).
    dt : float
        The sample time (the controller models' and the plant's step).
    models : dict
        ``{(label, r): DiscreteStateSpace}``.
    controllers : sequence of (label, r)
        The loops' controller models; one missing from ``models`` (its fit failed) gets a row
        ``{"controller", "r", "reference": "-", "failed"}``.
    references : dict
        ``{name: (p, K) ndarray}`` with ``K >= n_steps + 1 + horizon`` (the MPC looks ``horizon`` samples ahead).
    n_steps : int
        Samples of each loop.
    horizon, input_bound, rate_weight, measurement_noise, disturbance
        The MPC and the observer (module docstring).
    record : (label, r, name), optional
        The loop whose FOM displacements are kept (``result.plant_states``, e.g. for a render).
    progress : callable, optional
        One line per loop.

    Returns
    -------
    rows : list of dict
    results : dict
        ``{(label, r, name): ClosedLoopResult}``.
    """
    system = fom.system
    solver = solver_factory(fom)
    rows, results = [], {}
    try:
        for label, r in controllers:
            if (label, r) not in models:
                rows.append({"controller": label, "r": r, "reference": "-", "failed": "the model did not fit"})
                continue
            model = models[(label, r)]
            for name, reference in references.items():
                if progress is not None:
                    progress(f"closed loop on the FOM: {label} r = {r}, {name} reference ({n_steps} steps)")
                size = float(np.sqrt(np.mean(reference ** 2)))
                mpc = LinearMPC(model, horizon=horizon, output_weight=1.0 / size ** 2, input_weight=0.0,
                                input_rate_weight=rate_weight / input_bound ** 2, input_bound=input_bound)
                observer = KalmanObserver(model, measurement_noise=measurement_noise * size ** 2,
                                          disturbance=disturbance)
                plant = FullOrderPlant(system, dt, solver=solver)
                keep = (lambda p: p.last.q) if (label, r, name) == record else None
                tic = time.perf_counter()
                result = closed_loop(plant, mpc, observer, reference, n_steps, record_state=keep, progress=False)
                seconds = time.perf_counter() - tic
                rows.append({"controller": label, "r": r, "reference": name, **result.metrics(),
                             "model_error_on_applied_inputs": open_loop_error(model, result),
                             "reference_rms": size, "loop_seconds": seconds})
                results[(label, r, name)] = result
    finally:
        solver.cache.clear()
    return rows, results


def closed_loop_section(out_dir, rows: list[dict], results: dict, fom, dt: float, *, bound: float, horizon: int,
                        shown=None, render: bool = True, **figure) -> tuple[str, dict]:
    """``(section, renders)``: the report section of :func:`closed_loop_rows` (``control.png``: outputs and
    applied inputs of every loop, :func:`~femrom.post.plot_closed_loops` with ``figure``'s labels and
    scale; the table), and with ``render`` a render of the loop ``shown`` (``(label, r, reference)``,
    recorded with its FOM displacements) as ``control_render.png``."""
    from pathlib import Path

    out_dir = Path(out_dir)
    plot_closed_loops(out_dir / "control.png", results, dt, bound, title=f"MPC on the FOM, horizon {horizon}",
                      **figure)
    section = ("## MPC closed loops on the FOM\n\n" + accuracy_cost_table(rows, CLOSED_LOOP_COLUMNS)
               + "\n\n![control](control.png)")
    renders = {"control_render": None}
    result = None if shown is None else results.get(shown)
    if render and result is not None:
        renders = render_closed_loop(out_dir / "control_render.png", fom, result,
                                     f"{shown[0]} r={shown[1]}, {shown[2].replace('_', ' ')}", dt)
        if renders["control_render"]:
            section += "\n\n![controlled motion](control_render.png)"
    return section, renders
