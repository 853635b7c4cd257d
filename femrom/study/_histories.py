r"""Reduced models judged over time on one run: the FOM energy of the reconstructed state,
a table of errors and costs per (learner, r), and the error histories drawn per r.

A ROM's own energy (of ``M^``, ``K^``) says whether the ROM is stable; the FOM energy
of its reconstructed state ``(V q^, V q^')`` says whether it is right: for a
conservative structure released from ``(q_0, v_0)``

.. math::

    e_E(t) = |E(V q^(t), V q^'(t)) - E_0| / |E_0|,
    \qquad E(q, q') = \tfrac12 q'^T M q' + \tfrac12 q^T K q + U(q) - f_0^T q,

stays at the level of the energy the basis misses and grows only with the ROM's
error. The functions here work on a study's rows and evaluations
(:func:`~femrom.study.study_rows`), so a case adds its own models (e.g. a
hyper-reduced one) as rows of the same form.
"""

from __future__ import annotations

import numpy as np

from femrom.post import plot_accuracy_cost_groups, plot_time_series
from femrom.study._figures import plot_error_history
from femrom.study._metrics import invariant_drift
from femrom.study._study import study_costs
from femrom.study.experiments.unseen_input import evaluate, scored_columns


def state_energy(system, Q: np.ndarray, Qdot: np.ndarray) -> np.ndarray:
    r"""(k,) ndarray: the FOM energy ``E(q_j, q'_j)`` of full states, column by column.

    ``E = q'^T M q' / 2 + q^T K q / 2 + U(q) - f_0^T q`` (as
    :meth:`~femrom.scene.SecondOrderSystem.energy`), with ``Q``, ``Qdot`` (n, k)
    ndarrays of displacements and velocities; ``U`` is the potential of the
    system's nonlinear force (a conservative one), evaluated per column.
    """
    energy = 0.5 * np.sum(Qdot * (system.mass @ Qdot) + Q * (system.stiffness @ Q), axis=0)
    if system.nonlinear is not None:
        energy = energy + np.array([system.nonlinear.potential(q) for q in Q.T])
    if system.load is not None:
        energy = energy - np.asarray(system.load) @ Q
    return energy


def reconstructed_energy_error(system, basis: np.ndarray, solution, energy0: float) -> np.ndarray:
    """(k,) ndarray ``|E(V q^, V q^') - E_0| / |E_0|`` of a reduced solution (``solution.q``,
    ``solution.v``: (r, k)) in the first r columns of ``basis`` (n, R); non-finite where the
    ROM blew up (the overflow on the way is not reported)."""
    r = solution.q.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):
        Q, Qdot = basis[:, :r] @ solution.q, basis[:, :r] @ solution.v
        return np.abs(state_energy(system, Q, Qdot) - energy0) / abs(energy0)


def _peak(values: np.ndarray) -> float:
    """The largest value; ``inf`` if any is not finite (a ROM that blew up)."""
    return float(np.max(values)) if np.all(np.isfinite(values)) else float("inf")


def rom_table(system, basis: np.ndarray, run, rows: list[dict], evaluations: dict, *, train: str | None = None,
              score_after: float | None = None, carry=()) -> tuple[list[dict], dict]:
    """One row per study row on ``run`` (a :class:`~femrom.study.FOMRun` with its energy), and the
    energy-error histories.

    ``rows`` are rows of :func:`~femrom.study.study_rows` (``learner``, ``r``, ``_rom``,
    ``seconds_per_step``, ``speedup``, or ``failed``) or a case's rows of that form;
    ``evaluations`` by ``(r, learner, run name)``. Each table row has ``method`` (the
    learner's label), ``r``, ``train_error`` and ``projection_error_train`` (field and projection
    error on the run ``train``), ``test_error``, ``projection_error`` and their ratio
    ``error_over_projection`` (on ``run``, scored after ``score_after``), ``energy_error_max`` (:func:`reconstructed_energy_error`, largest over
    the run), ``energy_error_train_max`` (over the steps up to ``score_after``; only with it),
    ``energy_error_test_max`` (over the scored steps), ``rom_energy_drift`` (the ROM's own
    energy, :func:`energy_drift`), ``rom_energy_growth`` and ``blowup_time`` (of the
    :class:`Evaluation`), ``seconds_per_step``, ``online_seconds`` (the run's
    steps), ``speedup``, ``cost`` (the row's, with its spread), ``stiffness_asymmetry`` ``||K^ - K^T||_F / ||K^||_F``
    and the smallest eigenvalues of the symmetric parts of ``K^`` and ``C^`` (``stiffness_min_eig``,
    ``damping_min_eig``; ``None`` without a damping). A failed model
    has ``method``, ``r``, ``failed`` and an infinite ``test_error``. The keys ``carry`` of a
    source row that has them (a case's own columns) close its table row, failed rows aside.

    Returns
    -------
    table : list of dict
    histories : dict
        ``(r, learner) -> (k,) ndarray`` energy error over the run.
    """
    energy0 = run.energy[0]
    window = scored_columns(run, score_after)
    table, histories = [], {}
    for row in rows:
        label, r = row["learner"], row["r"]
        ev = evaluations.get((r, label, run.name))
        if ev is None:
            table.append({"method": label, "r": r, "failed": row.get("failed"), "test_error": float("inf")})
            continue
        error = histories[(r, label)] = reconstructed_energy_error(system, basis, ev.solution, energy0)
        trained = evaluations.get((r, label, train))         # None: no training run, or it failed there
        out = {"method": label, "r": r, "train_error": trained and trained.field_error,
               "projection_error_train": trained and trained.projection_error,
               "test_error": ev.field_error, "projection_error": ev.projection_error,
               "error_over_projection": ev.field_error / ev.projection_error, "energy_error_max": _peak(error)}
        if score_after is not None:
            out["energy_error_train_max"] = _peak(error[:window.start])
        out |= {"energy_error_test_max": _peak(error[window]), "rom_energy_drift": invariant_drift(ev.solution.energy),
                "rom_energy_growth": ev.energy_growth, "blowup_time": ev.blowup_time,
                "seconds_per_step": row["seconds_per_step"],
                "online_seconds": row["seconds_per_step"] * (run.times.size - 1), "speedup": row["speedup"],
                "cost": row.get("cost")}
        K, C = row["_rom"].operators_.stiffness, getattr(row["_rom"].operators_, "damping", None)
        if K is not None:
            out["stiffness_asymmetry"] = float(np.linalg.norm(K - K.T) / np.linalg.norm(K))
            out["stiffness_min_eig"] = float(np.linalg.eigvalsh(0.5 * (K + K.T))[0])
            out["damping_min_eig"] = None if C is None else float(np.linalg.eigvalsh(0.5 * (C + C.T))[0])
        table.append(out | {key: row[key] for key in carry if key in row})
    return table, histories


def plot_energy_error_history(path, run, histories: dict, r: int, labels: dict, *, fom: bool = True,
                              shade=None, envelope: int | None = 400, title: str = ""):
    """The energy error over time (:func:`reconstructed_energy_error`) of each learner's ROM at
    rank ``r`` (``labels``: learner -> legend name; those without a history are left out), and
    with ``fom`` the FOM's own ``|E(t) - E_0| / |E_0|``. Log scale, clipped at 10 (a blow-up
    runs along the top); ``shade``: the training window; ``envelope``: bin maxima."""
    energy0 = run.energy[0]
    series = {"FOM": np.abs(run.energy - energy0) / abs(energy0)} if fom else {}
    series |= {f"{name} (r={r})": histories[(r, key)] for key, name in labels.items() if (r, key) in histories}
    return plot_time_series(path, run.times, series, logy=True, envelope=envelope, ymax=10.0, shade=shade,
                            ylabel="|E(V q^, V q^') - E0| / E0", title=title)


def plot_output_history(path, run, evaluations: dict, r: int, labels: dict, *, output: int = 0, last=None,
                        shade=None, ylabel: str = "", title: str = ""):
    """Output ``output`` of the FOM (``run``) and of each learner's ROM at rank ``r`` over time
    (``labels``: learner -> legend name; those not evaluated are left out); ``last``: only the
    last that many seconds of the run."""
    times = run.times
    keep = slice(None) if last is None else times >= times[-1] - last
    series = {"FOM": run.outputs[output]}
    series |= {name: evaluations[(r, key, run.name)].solution.outputs[output] for key, name in labels.items()
               if (r, key, run.name) in evaluations}
    return plot_time_series(path, times[keep], {name: y[keep] for name, y in series.items()}, shade=shade,
                            ylabel=ylabel, title=title)


def plot_histories(out_dir, run, projection, evaluations: dict, table: list[dict], histories: dict, r: int,
                   labels: dict, *, prefix: str = "", title: str = "", shade=None, envelope: int | None = 400,
                   fom_energy: bool = True) -> None:
    """The pictures of a :func:`rom_table` on ``run``, into ``out_dir``, names starting with ``prefix``:

    - ``rom_state_error.png``: each learner's field error over time at rank ``r`` and the
      basis's projection error (:func:`plot_error_history`; ``projection`` the run's);
    - ``rom_energy_error.png``: their energy errors (:func:`plot_energy_error_history`, the FOM's
      own with ``fom_energy``);
    - ``accuracy_cost_rom.png``: test error against online seconds, one line per learner, points
      labelled with r.

    ``labels``: learner -> legend name; ``shade``: the training window; ``title`` heads each plot.
    """
    plot_error_history(out_dir / f"{prefix}rom_state_error.png", run, projection, evaluations, r, list(labels),
                       shade=shade, envelope=envelope, title=f"{title}: state error")
    plot_energy_error_history(out_dir / f"{prefix}rom_energy_error.png", run, histories, r, labels, fom=fom_energy,
                              shade=shade, envelope=envelope,
                              title=f"{title}: energy error (FOM energy of the reconstructed state)")
    plot_accuracy_cost_groups(out_dir / f"{prefix}accuracy_cost_rom.png", table, "online_seconds", "test_error", "r",
                              "method", title=f"{title}: test error vs online time (labels: r)")


def evaluate_runs(rom, state) -> dict:
    """``{run name: Evaluation}`` of a case's own ROM on every run of a study (a
    :class:`~femrom.study.StudyState`), as the study evaluates its ROMs: over each run's
    window (extended by the study's ``extension``), scored after the run's ``score_after``."""
    specs = (*state.config.train, *state.config.test)
    return {spec.name: evaluate(rom, state.runs[spec.name], state.projections[spec.name],
                                extension=state.config.extension, score_after=spec.score_after)
            for spec in specs}


def extra_rom_rows(state, roms: dict, *, alongside=()) -> tuple[list[dict], dict]:
    """Rows of the study's form for a case's own ROMs (e.g. hyper-reduced ones), so that
    :func:`rom_table` treats them like the study's.

    ``roms``: ``(r, label) -> ROM`` (labels other than the study's learners). Each ROM is
    evaluated on every run (:func:`evaluate_runs`) and timed on the first test run
    (:func:`study_costs`), interleaved with the study's ROMs of the learners
    ``alongside`` at the same r, timed anew in the same rounds: ``{learner}_seconds_per_step``
    and ``speedup_over_{learner}`` (that ROM's step over this one's) compare models measured
    side by side.

    Returns
    -------
    rows : list of dict
        ``learner``, ``r``, ``_rom``, ``seconds_per_step``, ``cost``, ``speedup``,
        ``speedup_range``, and per learner alongside the two columns above; in the order of ``roms``.
    evaluations : dict
        ``(r, label, run name) -> Evaluation``.
    """
    study = {(row["r"], row["learner"]): row["_rom"] for row in state.rows if "failed" not in row}
    timed = {("own", key): rom for key, rom in roms.items()}
    timed |= {("study", (r, learner)): study[(r, learner)] for r, _ in roms for learner in alongside
              if (r, learner) in study}
    costs = study_costs(timed, state.runs, state.config)
    rows, evaluations = [], {}
    for (r, label), rom in roms.items():
        row = {"learner": label, "r": r, "_rom": rom, **costs[("own", (r, label))]}
        for learner in alongside:
            other = costs.get(("study", (r, learner)))
            if other is not None:
                row[f"{learner}_seconds_per_step"] = other["seconds_per_step"]
                row[f"speedup_over_{learner}"] = other["seconds_per_step"] / row["seconds_per_step"]
        rows.append(row)
        evaluations |= {(r, label, name): ev for name, ev in evaluate_runs(rom, state).items()}
    return rows, evaluations
