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

Each loop is a :class:`~femrom.study.ClosedLoopTest` (a registered experiment) run on the controller
model; each row: the loop's metrics (:meth:`~femrom.control.ClosedLoopResult.metrics`), the controller
model's open-loop error on the inputs the loop applied (:func:`open_loop_error`: what feedback
had to correct), ``s`` and the loop's wall time.
"""

from __future__ import annotations

from femrom.post import accuracy_cost_table, plot_closed_loops, render_closed_loop
from femrom.snapshots import solver_factory
from femrom.study.experiments.closed_loop import ClosedLoopTest, open_loop_error  # noqa: F401 (open_loop_error: here too)

#: Columns of a report table of :func:`closed_loop_rows`.
CLOSED_LOOP_COLUMNS = ["controller", "r", "reference", "tracking_error", "model_error_on_applied_inputs",
                       "input_effort", "max_constraint_violation", "qp_seconds_per_step", "qp_seconds_max",
                       "n_fallbacks", "n_repaired"]


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
    solver = solver_factory(fom)
    tests = {name: ClosedLoopTest(fom, dt, reference, n_steps, horizon=horizon, input_bound=input_bound,
                                  rate_weight=rate_weight, measurement_noise=measurement_noise,
                                  disturbance=disturbance, solver=solver, label=name)
             for name, reference in references.items()}
    rows, results = [], {}
    try:
        for label, r in controllers:
            if (label, r) not in models:
                rows.append({"controller": label, "r": r, "reference": "-", "failed": "the model did not fit"})
                continue
            for name, test in tests.items():
                if progress is not None:
                    progress(f"closed loop on the FOM: {label} r = {r}, {name} reference ({n_steps} steps)")
                outcome = test.run(models[(label, r)], record_state=(label, r, name) == record)
                results[(label, r, name)] = outcome.pop("_result")
                rows.append({"controller": label, "r": r, "reference": name, **outcome})
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
