r"""Linear reduced and identified models compared in one form: their discrete state spaces on every run.

A second-order ROM (the intrusive Galerkin one, L-OpInf, ...) is fitted in the
study's basis and exported by :meth:`~femrom.rom.SecondOrderROM.to_state_space`;
an identified model (DMDc, ERA, OKID) is fitted on the same reduced training data
(or, for ERA, on Markov parameters) and is a state space already. Every model is then

.. math::

    z_{k+1} = A z_k + B u_k, \qquad y_k = C z_k + D u_k,

run from rest (``z_0 = 0``: the runs start at rest with ``u_0 = 0``) on each run's
input samples, and scored by the relative output error, its spectral radius, its
free response over a long window (``extension`` times the run's, the input zero after
the run's end) and its cost per step, all models timed together (interleaved blocks).
A model is *stable* when its spectral radius is at most 1 (to round-off) and its
largest output over the second half of the long window, long after the input has
stopped, is no larger than its largest output while driven.

"Size" ``r`` is the number of basis coordinates of a second-order model (state
``[q^; q^']``, ``2 r`` entries); an identified model of size ``r`` has ``2 r``
states too, so that models of one size cost the same per step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference import DMDc, ERA, OKID, InputOutputData
from femrom.rom import StateSpaceROM
from femrom.scene import Derivatives, LearnerSpec
from femrom.study._metrics import relative_error
from femrom.study._study import fit_rom
from femrom._timing import repeated_costs

#: a free response may exceed the driven peak by this relative margin (round-off of a marginal mode)
GROWTH_TOLERANCE = 1e-6
#: spectral radii up to ``1 + RADIUS_TOLERANCE`` count as stable (an undamped direction sits at 1 to round-off)
RADIUS_TOLERANCE = 1e-9
@dataclass(frozen=True)
class LinearModelSpec:
    """One kind of linear model of the comparison.

    ``learner``: ``"galerkin"`` or a registered second-order learner (fitted by
    :func:`~femrom.study.fit_rom` with stored derivatives), or ``"dmdc"`` (on the
    phase states ``[q^; q^']``, inputs at both ends of a step: Newmark's form),
    ``"era"`` (on the Markov parameters given to :func:`linear_model_rows`), ``"okid"``
    (on inputs and outputs only). ``options``: keyword options of the learner as
    ``(name, value)`` pairs (e.g. ``(("observer_order", 10),)`` for OKID).
    """

    label: str
    learner: str
    options: tuple = ()

    def __post_init__(self):
        if self.learner in IDENTIFIED:
            return
        from femrom.study._study import study_learners

        if self.learner not in study_learners():
            raise FemromValueError(f"linear model {self.label!r}: unknown learner {self.learner!r}; valid: "
                                   f"{', '.join((*study_learners(), *IDENTIFIED))}")


def state_space_data(data: dict, r: int, states: str = "phase") -> InputOutputData:
    """The training runs' reduced data (by name, in the largest basis) at size ``r`` as one input-output data set."""
    return InputOutputData.stack([InputOutputData.from_second_order(d.truncated(r), states=states)
                                  for d in data.values()])


def _dmdc(r, options, data, markov):
    return DMDc(input_samples="both", **options), state_space_data(data, r)


def _okid(r, options, data, markov):
    return OKID(order=2 * r, **options), state_space_data(data, r, "none")


def _era(r, options, data, markov):
    if markov is None:
        raise FemromValueError("ERA needs Markov parameters: pass markov=")
    return ERA(order=2 * r, **options), markov


#: how an identified learner is made at size ``r`` (2 r states) and what it is fitted on:
#: ``name -> make(r, options, data, markov) -> (learner, its data)``; a new identified learner is one entry
IDENTIFIED = {"dmdc": _dmdc, "era": _era, "okid": _okid}


def fit_linear_model(spec: LinearModelSpec, r: int, *, system, basis, product, data: dict, dt: float,
                     markov=None):
    """The :class:`~femrom.rom.DiscreteStateSpace` of ``spec`` at size ``r``, and the fitted model."""
    options = dict(spec.options)
    if spec.learner in IDENTIFIED:
        learner, training = IDENTIFIED[spec.learner](r, options, data, markov)
        rom = StateSpaceROM(learner=learner).fit(training)
        return rom.to_state_space(), rom
    rom = fit_rom(system, basis, product, r, LearnerSpec(spec.label, spec.learner, Derivatives("stored"), **options),
                  data)
    return rom.to_state_space(dt), rom


def _simulate(model, inputs: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        return model.simulate(inputs, np.zeros(model.n_states))[0]


def linear_model_rows(specs, ranks, runs: dict, *, system, basis, product, data: dict, markov=None,
                      extension: float = 10.0, repeats: int = 5, min_block_seconds: float = 0.05,
                      progress=None) -> tuple[list[dict], dict]:
    """One row per (model, r, run): fit every spec at every r, run it on every run, time all together.

    Parameters
    ----------
    specs : sequence of LinearModelSpec
    ranks : sequence of int
    runs : dict of name -> FOMRun
        Each starting at rest with ``u_0 = 0`` (else ``z_0 = 0`` is not its initial state).
    system, basis, product, data
        The study's FOM system, basis (n, R), basis product and training data by run.
    markov : MarkovParameters, optional
        For ERA.
    extension : float
        The long window in multiples of each run's.

    Returns
    -------
    rows : list of dict
        ``model``, ``r``, ``state_order``, ``run``, ``test_output_error``, ``spectral_radius``,
        ``long_output_ratio`` (the model's largest output over the second half of the long window
        over its largest output on the run's window),
        ``stable``, ``fit_seconds``, ``seconds_per_step`` (the fastest timed block), ``cost``.
    models : dict of (label, r) -> DiscreteStateSpace
    """
    dt = float(next(iter(runs.values())).dt)
    for name, run in runs.items():
        if np.any(run.q0) or np.any(run.v0) or np.any(run.U[:, 0]):
            raise FemromValueError(f"run {name!r} does not start at rest with u_0 = 0: a model started from z_0 = 0 "
                                   "would not start where it does")
    rows, models, fits = [], {}, {}
    for r in ranks:
        for spec in specs:
            if progress:
                progress(f"r = {r}: {spec.label}")
            tic = time.perf_counter()
            try:
                with np.errstate(over="ignore", invalid="ignore"):   # a diverging fit fails by a ValueError below
                    model, _ = fit_linear_model(spec, r, system=system, basis=basis, product=product, data=data,
                                                dt=dt, markov=markov)
            except (ValueError, np.linalg.LinAlgError) as exc:
                rows.append({"model": spec.label, "r": r, "failed": str(exc)})
                continue
            fits[(spec.label, r)] = time.perf_counter() - tic
            models[(spec.label, r)] = model
    costs = repeated_costs({key: _stepping_block(model, next(iter(runs.values())))
                            for key, model in models.items()}, 200, repeats=repeats,
                           min_block_seconds=min_block_seconds)
    for (label, r), model in models.items():
        radius = float(np.max(np.abs(model.poles())))
        for name, run in runs.items():
            long_times = run.times[0] + dt * np.arange(int(round(extension * (run.times.size - 1))) + 1)
            outputs = _simulate(model, run.inputs.sampled(long_times))
            driven = float(np.max(np.abs(outputs[:, :run.times.size])))
            late = outputs[:, long_times.size // 2:]
            ratio = float(np.max(np.abs(late))) / driven if np.all(np.isfinite(outputs)) and driven > 0 \
                else float("inf")
            rows.append({"model": label, "r": r, "state_order": model.n_states, "run": name,
                         "test_output_error": relative_error(run.outputs, outputs[:, :run.times.size]),
                         "spectral_radius": radius, "long_output_ratio": ratio,
                         "stable": bool(radius <= 1 + RADIUS_TOLERANCE and ratio <= 1 + GROWTH_TOLERANCE),
                         "fit_seconds": fits[(label, r)], "seconds_per_step": costs[(label, r)].seconds,
                         "cost": costs[(label, r)].to_dict()})
    return rows, models


def _stepping_block(model, run):
    """``block(n) -> seconds`` of ``n`` state-space steps on ``run``'s inputs (what a ROM step costs online)."""
    def block(n: int) -> float:
        times = run.times[0] + run.dt * np.arange(n + 1)
        U = run.inputs.sampled(times)
        tic = time.perf_counter()
        _simulate(model, U)
        return time.perf_counter() - tic
    return block
