r"""The comparison engine: every model spec at every size through every experiment.

``compare_models(specs, training, ranks, experiments)`` fits each
:class:`~femrom.study.ModelSpec` at each ``r`` from one
:class:`~femrom.inference.TrainingSet` and runs each :class:`~femrom.study.Experiment`
on it: one row per (model, r, experiment) with the experiment's metrics. A case
is its reference, its training runs, its specs and its experiments; what a
learner or an experiment is never appears here by name.
"""

from __future__ import annotations

import numpy as np


def compare_models(specs, training, ranks, experiments, *, progress=None, describe=None) -> tuple[list[dict], dict]:
    """``(rows, outcomes)``: every spec fitted at every ``r`` and run through every experiment.

    Parameters
    ----------
    specs : sequence of ModelSpec
    training : TrainingSet
    ranks : sequence of int
    experiments : sequence of Experiment
    progress : callable, optional
        Told each row (``describe(row) -> str`` formats it; default: model, r, experiment).

    Returns
    -------
    rows : list of dict
        ``model`` (the spec's label), ``r``, ``experiment`` (its label), ``fit_seconds`` and the
        experiment's metrics (keys starting with ``_`` left out), or ``failed`` (the message) when
        the model could not be run through it (a Newton iteration that did not converge).
    outcomes : dict
        ``{(label, r): model}`` under ``"models"`` and ``{(label, r, experiment): outcome}`` (whole,
        arrays included) under ``"runs"``.
    """
    rows, models, runs = [], {}, {}
    for r in ranks:
        for spec in specs:
            model = spec.fit(training, r)
            models[(spec.label, r)] = model
            for experiment in experiments:
                row = {"model": spec.label, "r": r, "experiment": experiment.label, "fit_seconds": model.fit_seconds_}
                try:
                    outcome = experiment.run(model)
                except (RuntimeError, np.linalg.LinAlgError) as exc:    # a nonlinear model's Newton failed
                    row["failed"] = str(exc)
                    rows.append(row)
                    if progress is not None:
                        progress(f"  {spec.label} r={r} {experiment.label}: failed: {exc}")
                    continue
                runs[(spec.label, r, experiment.label)] = outcome
                row.update({k: v for k, v in outcome.items() if not k.startswith("_")})
                rows.append(row)
                if progress is not None:
                    progress(describe(row) if describe else f"  {spec.label} r={r} {experiment.label}")
    return rows, {"models": models, "runs": runs}
