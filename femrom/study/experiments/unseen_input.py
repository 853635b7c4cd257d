r"""A full-order run the model was not trained on (or its window beyond training): predicted from its initial state."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from femrom.post import relative_error
from femrom.snapshots import FOMRun
from femrom.study._experiment import Experiment, register_experiment
from femrom.study._metrics import Projection, energy_ratio

#: a ROM has blown up once its energy exceeds this multiple of its initial energy
BLOWUP = 1e6


@dataclass(frozen=True, eq=False)
class Evaluation:
    """A ROM on one run: errors, its solution on the run's grid, its energy over the extended window."""

    output_error: float
    field_error: float
    projection_error: float
    energy_ratio: float
    energy_final_ratio: float
    energy_growth: float
    blowup_time: float | None
    solution: object
    long_times: np.ndarray
    long_energy: np.ndarray

    ERRORS = ("output_error", "field_error", "projection_error", "energy_ratio", "energy_final_ratio",
              "energy_growth", "blowup_time")

    def errors(self) -> dict:
        return {"output_error": self.output_error, "field_error": self.field_error,
                "projection_error": self.projection_error, "energy_ratio": self.energy_ratio,
                "energy_final_ratio": self.energy_final_ratio, "energy_growth": self.energy_growth,
                "blowup_time": self.blowup_time}


def _first_steps(solution, k: int):
    """The first ``k`` time steps of a reduced solution (its arrays sliced, the rest shared)."""
    if solution.t.size == k:
        return solution
    head = {f.name: getattr(solution, f.name)[..., :k] for f in fields(solution)
            if isinstance(getattr(solution, f.name), np.ndarray) and f.name != "basis"}
    return replace(solution, **head)


def scored_columns(run: FOMRun, score_after: float | None) -> slice:
    """The columns of ``run`` its errors are scored over: all, or the steps after ``score_after``."""
    if score_after is None:
        return slice(None)
    return slice(int(np.searchsorted(run.times, score_after * (1 + 1e-12), side="right")), None)


def energy_scale(energy, reference=None) -> float:
    """What a model's energy history (k,) is measured against: its initial value, or for a run from
    rest (initial energy 0) the largest ``|E|`` of the ``reference`` (the FOM's, (k,)); 0 without either."""
    if energy[0] and np.isfinite(energy[0]):
        return abs(float(energy[0]))
    if reference is not None and np.size(reference) and np.all(np.isfinite(reference)):
        return float(np.max(np.abs(reference)))
    return 0.0


def evaluate(rom, run: FOMRun, projection: Projection, *, extension: float,
             score_after: float | None = None) -> Evaluation:
    """Errors of ``rom`` on ``run`` and its reduced energy over ``extension`` times the run's window.

    The ROM runs over the whole window from the run's initial state; its output and
    field errors (and the projection error of its basis, the floor of the field error)
    are scored over the steps after ``score_after`` (all steps by
    default; a training window's end for a test of extrapolation in time). A ROM
    that blows up (plain OpInf can) gets infinite errors; the overflow on the way is
    expected and not reported as a warning. ``energy_growth`` is the ROM's largest
    energy on the run's window over its energy scale, ``blowup_time`` the first time, over the
    extended window, its energy exceeds :data:`BLOWUP` times that scale (``None``: never) or stops
    being finite.
    The scale is the ROM's initial energy, or, for a run from rest (initial energy 0: a
    driven structure), the FOM's largest energy on the run (:func:`energy_scale`); without
    either, ``energy_growth`` is ``nan`` and only a non-finite energy counts as a blow-up.
    """
    times = run.times
    columns = scored_columns(run, score_after)
    long_times = times[0] + run.dt * np.arange(int(round(extension * (times.size - 1))) + 1)
    with np.errstate(all="ignore"):
        # one integration over the extended window; the run's window is its first steps
        long = rom.predict(long_times, run.inputs.sampled(long_times), initial=(run.q0, run.v0))
        solution = _first_steps(long, times.size)
        output_error = float("nan") if run.outputs is None else relative_error(
            run.outputs[:, columns], solution.outputs[:, columns])
        ratio, final = energy_ratio(long.energy, run.energy)
        energy = solution.energy
        scale = energy_scale(energy, run.energy)
        growth = float(np.nanmax(np.abs(energy)) / scale) if scale else float("nan")
        big = ~np.isfinite(long.energy) | ((np.abs(long.energy) > BLOWUP * scale) if scale else False)
        return Evaluation(output_error, projection.field_error(solution.q, columns),
                          projection.projection_error(rom.r, columns), ratio, final, growth,
                          float(long_times[np.argmax(big)]) if big.any() else None, solution, long_times,
                          long.energy)




@register_experiment("unseen_input")
class UnseenInput(Experiment):
    r"""A model predicted from the run's initial state with the run's inputs over ``extension`` times its
    window (:func:`~femrom.study.evaluate`): output and exact field errors (after ``score_after``,
    the end of a training window for extrapolation in time), the projection floor, the energy over
    the extended window, when it blew up.

    Parameters
    ----------
    run : FOMRun
    projection : Projection
        The run's displacements in the study's basis (exact field errors at every r).
    extension : float
    score_after : float, optional
    """

    def __init__(self, run, projection, *, extension: float = 1.0, score_after: float | None = None):
        self.reference, self.projection = run, projection
        self.extension, self.score_after = float(extension), score_after
        self.label = run.name

    def run(self, model) -> dict:
        evaluation = evaluate(model, self.reference, self.projection, extension=self.extension,
                              score_after=self.score_after)
        return {**evaluation.errors(), "_evaluation": evaluation}

    @classmethod
    def for_study(cls, state, *, runs=None, extension=None) -> list["UnseenInput"]:
        """One per run of the study (``runs``: their names, default every test run)."""
        config = state.config
        names = [spec.name for spec in config.test] if runs is None else list(runs)
        score_after = {spec.name: spec.score_after for spec in (*config.train, *config.test)}
        return [cls(state.runs[name], state.projections[name],
                    extension=config.extension if extension is None else extension,
                    score_after=score_after.get(name)) for name in names]
