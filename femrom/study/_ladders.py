"""The FOM's accuracy against its cost: coarser time steps, finer meshes."""

from __future__ import annotations

import time

import numpy as np

from femrom._errors import FemromValueError
from femrom.study._metrics import relative_error
from femrom.snapshots import FOMRun, run_fom

ERRORS = ("frobenius", "max")


def time_step_ladder(model, reference: FOMRun | None = None, factors=(10, 5, 2), *, reference_divisor: int = 1,
                     error: str = "frobenius", outputs=None, min_block_seconds: float = 0.1) -> list[dict]:
    """Output error of runs at ``factor * dt`` against a reference run, with their stepping time and
    per-step cost, and the observed order of convergence (slope of log error against log dt).

    Parameters
    ----------
    model : FullOrderModel
    reference : FOMRun, optional
        A run at the scene's ``dt`` (its signals and window are the ladder's); ``None``:
        the scene's signals and window, run here at ``dt / reference_divisor``.
    factors : sequence of int
        Steps of the ladder, ``factor * dt``; all runs are compared on the coarsest
        step's grid inside the window (each run covers ``round(t_end / dt)`` steps).
    error : {"frobenius", "max"}
        ``||Y - Y_ref||_F / ||Y_ref||_F``, or ``max |Y - Y_ref| / max |Y_ref|``.
    outputs : sequence of int, optional
        Which outputs count (all by default).

    Returns
    -------
    list of dict
        One row per factor (coarsest first), then the reference itself when it is a
        given run at the scene's ``dt`` (error 0).
    """
    if error not in ERRORS:
        raise FemromValueError(f"unknown error {error!r}; valid: {', '.join(ERRORS)}")
    signals = None if reference is None else reference.inputs.signals
    dt0 = model.scene.time.dt if reference is None else reference.dt / reference.every
    t_end = model.scene.time.t_end if reference is None else float(reference.times[-1])
    factors = tuple(sorted(factors, reverse=True))
    given = reference is not None
    if not given:
        reference = run_fom(model, signals, name="reference", dt=dt0 / reference_divisor, t_end=t_end,
                            min_block_seconds=min_block_seconds)
    coarse = factors[0] * dt0
    t_common = coarse * np.arange(int(np.floor(t_end / coarse + 1e-9)) + 1)
    pick = slice(None) if outputs is None else list(outputs)

    def on_grid(run):
        return np.vstack([np.interp(t_common, run.times, y) for y in run.outputs[pick]])

    ref = on_grid(reference)

    def distance(Y):
        if error == "max":
            return float(np.max(np.abs(Y - ref)) / np.max(np.abs(ref)))
        return relative_error(ref, Y)

    rows = []
    for factor in factors:
        run = run_fom(model, signals, name=f"dt/{factor}", dt=factor * dt0, t_end=t_end,
                      min_block_seconds=min_block_seconds)
        rows.append(_row(run, distance(on_grid(run))))
    if given:
        rows.append(_row(reference, 0.0))
    fitted = [r for r in rows if r["output_error"] > 0]
    if len(fitted) >= 2:
        order = observed_order([r["dt"] for r in fitted], [r["output_error"] for r in fitted])
        for r in rows:
            r["observed_order"] = order
    return rows


def _row(run: FOMRun, error: float) -> dict:
    s = run.summary
    return {"dt": run.dt / run.every, "steps": s["n_steps"], "output_error": error, "stepping_seconds": s["stepping_seconds"],
            "seconds_per_step": run.cost.seconds, "cost": run.cost.to_dict()}


def natural_frequencies(system, count: int = 4) -> np.ndarray:
    """(count,) ndarray: the lowest ``omega`` of ``K phi = omega^2 M phi`` [rad/s] (shift-invert Lanczos)."""
    from scipy.sparse.linalg import eigsh

    return np.sqrt(np.sort(eigsh(system.stiffness.tocsc(), k=count, M=system.mass.tocsc(), sigma=0.0,
                                 which="LM")[0]))


def frequency_ladder(scene, values, *, parameter: str = "mesh_size", count: int = 4, exact=None) -> list[dict]:
    r"""The first ``count`` natural frequencies (``K phi = omega^2 M phi``, shift-invert Lanczos) per
    value of a geometry parameter, with the build + eigensolve time.

    ``frequency_error`` is ``max_k |omega_k / omega_k^* - 1|`` against ``exact`` (rad/s, e.g.
    analytic) or, without it, against the last value of the ladder (the finest mesh).
    """
    from femrom.scene import build

    rows = []
    for value in values:
        tic = time.perf_counter()
        model = build(scene.with_geometry(**{parameter: float(value)}))
        omega = natural_frequencies(model.system, count)
        rows.append({parameter: float(value), "dofs": model.system.n_dofs, "omega": omega, "f1_hz": float(omega[0] / (2 * np.pi)),
                     "seconds": time.perf_counter() - tic})
    reference = np.asarray(exact, dtype=float)[:count] if exact is not None else rows[-1]["omega"]
    for row in rows:
        row["frequency_error"] = float(np.max(np.abs(row["omega"] / reference - 1)))
    return rows


def observed_order(steps, errors) -> float:
    """The slope of ``log error`` against ``log step`` (least squares): the order ``p`` of
    ``error ~ C step^p`` along a ladder (a mesh ladder in node counts gives ``-p``)."""
    return float(np.polyfit(np.log(np.asarray(steps, dtype=float)), np.log(np.asarray(errors, dtype=float)), 1)[0])


def final_state(model, dt: float, t_end: float) -> tuple[np.ndarray, dict]:
    """The model's displacement at ``t_end``, released from its initial state and stepped at ``dt``
    with the scene's scheme (only the last state kept), and the run's cost.

    Returns
    -------
    q : (n,) ndarray
        ``q(t_end)``.
    row : dict
        ``n`` (dofs), ``dt``, ``steps``, ``stepping_seconds``, ``seconds_per_step``.

    Raises ``ValueError`` if ``dt`` does not divide ``t_end`` (the state would be at another time).
    """
    from femrom.integrators import Trajectory, simulate

    steps = int(round(t_end / dt))
    if abs(steps * dt - t_end) > 1e-9 * t_end:
        raise FemromValueError(f"time step {dt:g} does not divide the window {t_end:g}")
    last = Trajectory(every=steps, fields=("q",))
    summary = simulate(model, dt=dt, t_end=steps * dt, consumers=[last], progress=False).summary
    return last.q[:, -1], {"n": model.system.n_dofs, "dt": dt, "steps": steps,
                           "stepping_seconds": summary["stepping_seconds"],
                           "seconds_per_step": summary["stepping_seconds"] / steps}


def final_state_ladders(model, t_end: float, time_steps, fine_dt: float, meshes, exact, *,
                        exact_name: str = "exact solution", dimension: int = 1) -> list[dict]:
    r"""The FOM's error at ``t_end`` against its cost, over time steps and over meshes.

    Every error is the relative mass norm of a final state (:func:`final_state`: the
    scene's scheme from the initial state, only the last state kept),

    .. math::

        e = \|q_h(T) - q_{ref}\|_M / \|q_{ref}\|_M, \qquad \|x\|_M = \sqrt{x^T M x},

    on two ladders:

    - ``"time step"``: ``model`` stepped at each of ``time_steps`` against the same model at
      ``fine_dt`` (the time error alone);
    - ``"mesh"``: each model of ``meshes`` stepped at ``fine_dt`` against ``exact(model, t)``
      (the space error, when ``fine_dt`` makes the time part negligible).

    Parameters
    ----------
    model : FullOrderModel
        The time ladder's model.
    t_end : float
        The final time ``T``; every step must divide it.
    time_steps : sequence of float
    fine_dt : float
    meshes : iterable of FullOrderModel
        The mesh ladder, coarsest first (a generator builds each model when its turn comes).
    exact : callable ``(model, t) -> (n,) ndarray``
        The exact displacement at the model's free dofs at time ``t``.
    exact_name : str
        What ``exact`` is, for the rows' ``reference``.
    dimension : int
        The mesh's dimension ``d``: the mesh ladder's order is fitted against the dofs ``n ~ h^-d``,
        ``p = -d * slope(log e, log n)``.

    Returns
    -------
    list of dict
        Per run, the time ladder's first: ``ladder``, ``label`` (``dt=...``, ``n=...``),
        :func:`final_state`'s row (``n``, ``dt``, ``steps``, ``stepping_seconds``,
        ``seconds_per_step``), ``error``, ``reference`` and ``observed_order`` (of its
        ladder, :func:`observed_order`).
    """
    from femrom.study._metrics import mass_norm

    def relative(M, q, reference):
        return mass_norm(M, q - reference) / mass_norm(M, reference)

    reference, _ = final_state(model, fine_dt, t_end)
    rows = []
    for dt in time_steps:
        q, row = final_state(model, dt, t_end)
        rows.append({"ladder": "time step", "label": f"dt={dt:g}", **row,
                     "error": relative(model.system.mass, q, reference),
                     "reference": f"dt = {fine_dt:g}, same mesh"})
    for mesh in meshes:
        q, row = final_state(mesh, fine_dt, t_end)
        exact_q = exact(mesh, row["steps"] * fine_dt)
        rows.append({"ladder": "mesh", "label": f"n={row['n']}", **row,
                     "error": relative(mesh.system.mass, q, exact_q), "reference": exact_name})
    for name, key, sign in (("time step", "dt", 1.0), ("mesh", "n", -float(dimension))):
        ladder = [row for row in rows if row["ladder"] == name]
        if len(ladder) >= 2:
            order = sign * observed_order([row[key] for row in ladder], [row["error"] for row in ladder])
            for row in ladder:
                row["observed_order"] = order
    return rows


def ladder_table(rows: list[dict], *, heading: str, columns: list[str], group: str | None = None,
                 note: str = "") -> str:
    """A ladder's report section: ``heading``, the table of ``columns``, the observed order when
    the rows carry one (``observed_order``; with ``group``, that of each group's first row), ``note``."""
    from femrom.post import table_section

    orders = {}
    for row in rows:
        if "observed_order" in row:
            orders.setdefault(None if group is None else row[group], row["observed_order"])
    if group is None:
        order = f"Observed order {orders[None]:.2f}." if orders else ""
    else:
        order = "Observed order: " + ", ".join(f"{name} {p:.2f}" for name, p in orders.items()) + "." if orders else ""
    return table_section(heading, rows, columns, note=" ".join(part for part in (order, note) if part))


def ladder_section(path, rows: list[dict], cost: str, error: str, label: str, *, heading: str, columns: list[str],
                   group: str | None = None, note: str = "") -> str:
    """Plot a ladder's ``error`` against ``cost`` (log-log, points annotated with ``label``; one
    line per value of ``group`` if given; titled ``heading``; rows with a zero error, a reference
    against itself, left out) into ``path``, and return its report section (:func:`ladder_table`)."""
    from femrom.post import plot_accuracy_cost, plot_accuracy_cost_groups

    shown = [row for row in rows if row[error] > 0]
    if group is None:
        plot_accuracy_cost(path, shown, cost, error, label, title=heading)
    else:
        plot_accuracy_cost_groups(path, shown, cost, error, label, group, title=heading)
    return ladder_table(rows, heading=heading, columns=columns, group=group, note=note)


#: the report's columns of :func:`time_step_ladder` rows
TIME_STEP_COLUMNS = ["dt", "steps", "output_error", "stepping_seconds", "seconds_per_step"]
#: the report's columns of :func:`frequency_ladder` rows
FREQUENCY_COLUMNS = ["mesh_size", "dofs", "frequency_error", "f1_hz", "seconds"]


def time_step_section(path, rows: list[dict], *, heading: str, note: str = "") -> str:
    """:func:`ladder_section` of :func:`time_step_ladder` rows: output error against stepping time,
    points labelled with dt, the columns :data:`TIME_STEP_COLUMNS`."""
    return ladder_section(path, rows, "stepping_seconds", "output_error", "dt", heading=heading,
                          columns=TIME_STEP_COLUMNS, note=note)


def frequency_section(path, rows: list[dict], *, heading: str, note: str = "") -> str:
    """:func:`ladder_section` of :func:`frequency_ladder` rows: frequency error against build +
    eigensolve time, points labelled with the dofs, the columns :data:`FREQUENCY_COLUMNS`."""
    return ladder_section(path, rows, "seconds", "frequency_error", "dofs", heading=heading,
                          columns=FREQUENCY_COLUMNS, note=note)


#: the report's columns of :func:`final_state_ladders` rows
FINAL_STATE_COLUMNS = ["ladder", "n", "dt", "steps", "error", "reference", "stepping_seconds", "seconds_per_step",
                       "observed_order"]


def final_state_section(path, rows: list[dict], *, note: str = "") -> str:
    """The plot (error against stepping time, one line per ladder, points labelled ``dt=`` / ``n=``)
    into ``path`` and the report section of :func:`final_state_ladders` rows (:func:`ladder_section`):
    their table, the observed order of each ladder, ``note``."""
    t_end = rows[0]["steps"] * rows[0]["dt"]
    return ladder_section(path, rows, "stepping_seconds", "error", "label", group="ladder", columns=FINAL_STATE_COLUMNS,
                          heading=f"FOM accuracy against cost (relative error in the mass norm at t = {t_end:g} s)",
                          note=note)
