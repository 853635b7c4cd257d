r"""Stepped-sine forced responses: one model's beside its linearisation, several models against a reference.

:func:`stepped_sine_response` runs a model with a stateful force from its committed rest state at
force levels ``F`` and lists, beside each first-harmonic output amplitude, the amplitude ``F H(f)``
of the model linearised there (:func:`femrom.post.linear_accelerance`: a stuck joint), the
small-force limit the nonlinear response tends to.

For :func:`compare_stepped_sines`, every model on its :class:`~femrom.integrators.Shaker` (the full model,
a Galerkin or a learned ROM alike) runs the same :class:`~femrom.integrators.SteppedSine` at the same
force levels. Per model and level, the
first-harmonic amplitude of one output is compared with the reference's: the peak (parabolic
interpolation around the discrete maximum) in frequency and in amplitude, and the worst relative
amplitude difference over the frequencies.
"""

from __future__ import annotations

import time

import numpy as np

from femrom.integrators import Shaker, SteadyStateCriterion, SteppedSine, StepResult
from femrom.post import linear_accelerance
from femrom.study.experiments.stepped_sine import peak_rows


def stepped_sine_response(system, rest_state, input: int, frequencies, levels, *, steps_per_period: int,
                          tolerance: float, linear_key: str = "linear_amplitude", progress=None):
    """``(result, rows)``: the stepped sine of ``system`` driven through input column ``input`` at the force
    ``levels`` [N] over ``frequencies`` [Hz], from rest in the committed force state ``rest_state``
    (:class:`~femrom.integrators.Shaker`, :class:`~femrom.integrators.SteppedSine` with
    ``steps_per_period`` steps per period and :class:`~femrom.integrators.SteadyStateCriterion` at
    ``tolerance``).

    ``rows``: ``result.rows()`` with, in every point of every output, ``linear_key``: ``F |H(f)|`` of the
    model linearised at rest (:func:`femrom.post.linear_accelerance`), in the outputs' acceleration units."""
    force = np.asarray(system.input_matrix[:, input]).ravel()
    plant = Shaker(system, force, rest=StepResult.at_rest(system.n_dofs, state=rest_state))
    sweep = SteppedSine(np.asarray(frequencies), steps_per_period=steps_per_period,
                        steady_state=SteadyStateCriterion(tolerance=tolerance))
    result = sweep.run(plant, list(levels), progress=progress)
    per_newton = linear_accelerance(system, rest_state, force, frequencies)
    rows = result.rows()
    for level in rows:
        for i, name in enumerate(system.output_names):
            for j, point in enumerate(level["outputs"][name]):
                point[linear_key] = float(level["force_n"] * per_newton[i, j])
    return result, rows




def compare_stepped_sines(reference, plants: dict, sweep: SteppedSine, levels, *, output: int = 0,
                          progress=None) -> dict:
    """Run ``sweep`` on ``reference`` and on every plant of ``plants`` (by name) at the force ``levels``.

    Returns
    -------
    dict with ``results`` (``{name: SteppedSineResult}``, the reference under ``"reference"``),
    ``seconds`` (per plant) and ``rows``: one per model and level (:func:`peak_rows`: ``peak_frequency_hz``,
    ``peak_amplitude``, ``peak_frequency_difference_hz`` (model - reference), ``peak_amplitude_error``
    (relative, signed), ``amplitude_max_error`` (max over frequencies of ``|A_model / A_reference - 1|``)).
    """
    results, seconds = {}, {}
    for name, plant in {"reference": reference, **plants}.items():
        tic = time.perf_counter()
        results[name] = sweep.run(plant, list(levels))
        seconds[name] = time.perf_counter() - tic
        if progress is not None:
            peaks = ", ".join(f"{level.force_n:g} N: {level.peaks()[output].frequency_hz:.3f} Hz / "
                              f"{level.peaks()[output].amplitude:.4g}" for level in results[name].levels)
            progress(f"  stepped sine {name}: {peaks} ({seconds[name]:.1f} s)")
    rows = [{"model": name, **row, "seconds": seconds[name]}
            for name in plants for row in peak_rows(results[name], results["reference"], output)]
    return {"results": results, "rows": rows, "seconds": seconds}
