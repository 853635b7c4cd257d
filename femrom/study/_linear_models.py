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

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference import TrainingSet, learner_class, system_impulse_response
from femrom.scene import Derivatives
from femrom.study._metrics import relative_error
from femrom.study._models import ModelSpec
from femrom._timing import repeated_costs

#: a free response may exceed the driven peak by this relative margin (round-off of a marginal mode)
GROWTH_TOLERANCE = 1e-6
#: spectral radii up to ``1 + RADIUS_TOLERANCE`` count as stable (an undamped direction sits at 1 to round-off)
RADIUS_TOLERANCE = 1e-9
def _state_space(spec: ModelSpec, training: TrainingSet, r: int, dt: float):
    """The :class:`~femrom.rom.DiscreteStateSpace` of ``spec`` at size ``r`` (a second-order ROM exported
    at ``dt``, an identified model as it is)."""
    rom = spec.fit(training, r)
    return rom.to_state_space(dt) if spec.kind == "second_order" else rom.to_state_space()


def _simulate(model, inputs: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        return model.simulate(inputs, np.zeros(model.n_states))[0]


def linear_model_rows(specs, ranks, runs: dict, *, system, basis, product, data: dict, markov=None,
                      markov_samples: int | None = None, extension: float = 10.0, repeats: int = 5,
                      min_block_seconds: float = 0.05, progress=None) -> tuple[list[dict], dict]:
    """One row per (model, r, run): fit every spec at every r, run it on every run, time all together.

    Parameters
    ----------
    specs : sequence of ModelSpec
        Registered learners of second-order models (fitted with stored derivatives and exported
        by ``to_state_space(dt)``) or of state spaces (DMDc, ERA, OKID: 2 r states).
    ranks : sequence of int
    runs : dict of name -> FOMRun
        Each starting at rest with ``u_0 = 0`` (else ``z_0 = 0`` is not its initial state).
    system, basis, product, data
        The study's FOM system, basis (n, R), basis product and training data by run.
    markov : MarkovParameters, optional
        For a learner that needs them (ERA); without them, ``markov_samples`` of the system's own
        impulse response (:func:`~femrom.inference.system_impulse_response`, one run per input, timed:
        ``markov_seconds`` in those learners' rows).
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
    markov_seconds = None
    if markov is None and any("markov" in learner_class(spec.learner).needs for spec in specs):
        if markov_samples is None:
            raise FemromValueError("a model needs Markov parameters: give markov= or markov_samples=")
        if progress:
            progress(f"Markov parameters: the system's impulse response, {system.n_inputs} runs of "
                     f"{markov_samples} steps")
        tic = time.perf_counter()
        markov = system_impulse_response(system, dt, markov_samples, progress=False)
        markov_seconds = time.perf_counter() - tic
    training = TrainingSet(system, basis, data, product=product, markov=markov, derivatives=Derivatives("stored"))
    rows, models, fits = [], {}, {}
    by_label = {spec.label: spec for spec in specs}
    for r in ranks:
        for spec in specs:
            if progress:
                progress(f"r = {r}: {spec.label}")
            tic = time.perf_counter()
            try:
                with np.errstate(over="ignore", invalid="ignore"):   # a diverging fit fails by a ValueError below
                    model = _state_space(spec, training, r, dt)
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
                         **({"markov_seconds": markov_seconds} if markov_seconds is not None
                            and "markov" in learner_class(by_label[label].learner).needs else {}),
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
