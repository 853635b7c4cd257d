r"""A stepped sine at a shaker: a model's first-harmonic response against the reference's."""

from __future__ import annotations

import time

import numpy as np

from femrom.inference import Output
from femrom.integrators import Shaker, StepResult
from femrom.rom import SecondOrderROM
from femrom.study._experiment import Experiment, dense, register_experiment, rest_start



def peak_rows(result, reference, output: int = 0) -> list[dict]:
    """Per force level: the peak (frequency, amplitude) of ``result`` beside the ``reference``'s, their
    differences, and ``amplitude_max_error`` (max over frequencies of ``|A / A_ref - 1|``)."""
    rows = []
    for level, reference_level in zip(result.levels, reference.levels):
        peak, peak_ref = level.peaks()[output], reference_level.peaks()[output]
        A, A_ref = level.amplitude[output], reference_level.amplitude[output]
        rows.append({"force_n": level.force_n, "peak_frequency_hz": peak.frequency_hz,
                     "peak_amplitude": peak.amplitude, "reference_peak_frequency_hz": peak_ref.frequency_hz,
                     "reference_peak_amplitude": peak_ref.amplitude,
                     "peak_frequency_difference_hz": peak.frequency_hz - peak_ref.frequency_hz,
                     "peak_amplitude_error": peak.amplitude / peak_ref.amplitude - 1.0,
                     "amplitude_max_error": float(np.max(np.abs(A / A_ref - 1.0))),
                     "all_converged": bool(np.all(level.converged))})
    return rows


@register_experiment("stepped_sine")
class SteppedSineTest(Experiment):
    r"""The reference and every model on a :class:`~femrom.integrators.Shaker` through the same
    :class:`~femrom.integrators.SteppedSine` at the same force levels.

    Each model is driven through its own input column ``input`` (the reference's ``B[:, input]``
    projected, ``V^T B[:, input]``, for a Galerkin model; the learned column for a learned one) and
    seen through the reference's sensors on its basis, ``E V q^''``; a projection of the reference
    starts each level in the reference's committed rest state. ``run(model)`` returns one entry per
    level (:func:`peak_rows`) under ``levels`` and the model's :class:`SteppedSineResult` under ``_result``.

    Parameters
    ----------
    reference : SecondOrderSystem
        With inputs (the shaker one of them) and outputs (the sensors).
    sweep : SteppedSine
    levels : sequence of float [N]
    input : int
        The shaker's input column.
    rest_state : optional
        The reference's committed force state at rest.
    output : int
        The output whose peaks are compared.
    scheme : str
        The time scheme of every run.
    """

    def __init__(self, reference, sweep, levels, *, input: int = 0, rest_state=None, output: int = 0,
                 scheme: str = "newmark", label: str = "stepped_sine"):
        self.reference, self.sweep, self.levels = reference, sweep, tuple(float(F) for F in levels)
        self.input, self.rest_state, self.output, self.scheme = int(input), rest_state, int(output), scheme
        self.label = label
        self._reference_result = None
        self.reference_seconds = None

    @property
    def reference_result(self):
        """The reference's stepped sine (run on first use)."""
        if self._reference_result is None:
            n = self.reference.n_dofs
            rest = None if self.rest_state is None else StepResult.at_rest(n, state=self.rest_state)
            shaker = Shaker(self.reference, self.input, rest=rest, scheme=self.scheme)
            tic = time.perf_counter()
            self._reference_result = self.sweep.run(shaker, list(self.levels))
            self.reference_seconds = time.perf_counter() - tic
        return self._reference_result

    def plant(self, model) -> Shaker:
        """``model`` on the shaker, seen through the reference's sensors on its basis."""
        E = dense(self.reference.output_matrix)
        sensed = SecondOrderROM(model.operators_.with_terms(Output(E @ model.basis)), model.basis)
        return Shaker(sensed, self.input, rest=rest_start(model, self.rest_state), scheme=self.scheme,
                      output_names=self.reference.output_names)

    def run(self, model) -> dict:
        reference = self.reference_result
        tic = time.perf_counter()
        result = self.sweep.run(self.plant(model), list(self.levels))
        seconds = time.perf_counter() - tic
        return {"levels": peak_rows(result, reference, self.output), "seconds": seconds, "_result": result}

    def compare(self, models: dict, *, progress=None) -> dict:
        """Every model of ``models`` (name -> model) through :meth:`run`: ``results`` (the reference's
        under ``"reference"``), ``seconds`` and ``rows`` (one per model and level, :func:`peak_rows`)."""
        results, seconds = {"reference": self.reference_result}, {"reference": self.reference_seconds}
        rows = []
        for name, model in models.items():
            outcome = self.run(model)
            results[name], seconds[name] = outcome["_result"], outcome["seconds"]
            rows += [{"model": name, **level, "seconds": outcome["seconds"]} for level in outcome["levels"]]
            if progress is not None:
                progress(f"  stepped sine {name}: " + ", ".join(
                    f"{level['force_n']:g} N: {level['peak_frequency_hz']:.3f} Hz" for level in outcome["levels"]))
        return {"results": results, "rows": rows, "seconds": seconds}
