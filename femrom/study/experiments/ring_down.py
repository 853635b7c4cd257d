r"""A ring-down after a blow: a model from rest against the reference's run, in time and by backbones."""

from __future__ import annotations

import time

import numpy as np

from femrom.post import hilbert_backbone
from femrom.study._backbone_metrics import backbone_errors
from femrom.study._experiment import Experiment, dense, finite, register_experiment, rest_start



def decays(signal: np.ndarray) -> bool:
    """Finite, and the last tenth's peak no larger than the first tenth's (a ring-down decays)."""
    if not finite(signal):
        return False
    k = max(signal.size // 10, 1)
    return bool(np.max(np.abs(signal[-k:])) <= np.max(np.abs(signal[:k])))


@register_experiment("ring_down")
class RingDownTest(Experiment):
    r"""A model predicted from rest under the reference run's input, on the run's time grid.

    The compared signal is output ``output`` of the sensors ``E`` through the model's basis,
    ``E V q^''`` (the reference's own accelerations ``E q''``): the time-domain error
    ``||y - y_ref|| / ||y_ref||`` and the Hilbert backbones (``band``, ``window``) compared
    over ``amplitude_range`` (:func:`~femrom.study.backbone_errors`: frequency shift and
    damping errors); ``stable`` when the prediction decays (:func:`decays`). ``seconds_per_step``: the
    prediction's stepping time per step (its ``stepping_seconds`` where it reports them; the whole
    ``predict`` call is ``predict_seconds``), after a one-step prediction that loads any compiled kernel.

    Parameters
    ----------
    reference : RingDown
        The reference's run (:func:`~femrom.study.reference_ring_down`): times, outputs.
    inputs : SignalVector
        The blow, ``u(t)`` (the model's input map applies it).
    sensors : (p, n) matrix
        ``E`` of the reference (what ``outputs`` are, of its accelerations).
    amplitude_range : (2,) floats
    band : (2,) floats [Hz]
    window : float [s]
    output : int
    correction : callable, optional
        ``Backbone -> Backbone`` applied to every backbone (the scheme's period error).
    rest_state : optional
        The reference's committed force state at rest, where a projection of it starts.
    scheme, stateful_scheme : str
        The time scheme of a smooth model and of one with a stateful force (a return mapping).
    """

    def __init__(self, reference, inputs, sensors, amplitude_range, *, band, window, output: int = 0,
                 correction=None, rest_state=None, scheme: str = "discrete_gradient",
                 stateful_scheme: str = "newmark"):
        self.reference, self.inputs, self.E = reference, inputs, dense(sensors)
        self.amplitude_range = tuple(float(a) for a in amplitude_range)
        self.band, self.window, self.output = band, window, int(output)
        self.correction = correction or (lambda backbone: backbone)
        self.rest_state, self.scheme, self.stateful_scheme = rest_state, scheme, stateful_scheme
        self.label = reference.label
        self.reference_backbone = self.backbone(reference.outputs[self.output])

    def backbone(self, signal):
        """The (corrected) Hilbert backbone of one output history on the reference's grid."""
        return self.correction(hilbert_backbone(signal, 1.0 / self.reference.dt, self.band, window=self.window))

    def run(self, model) -> dict:
        times = self.reference.times
        scheme = self.stateful_scheme if model.operators_.stateful else self.scheme
        # one step first: loading a compiled kernel (once per process) is not the model's step cost
        model.predict(times[:2], self.inputs, initial=rest_start(model, self.rest_state), scheme=scheme)
        tic = time.perf_counter()
        solution = model.predict(times, self.inputs, initial=rest_start(model, self.rest_state), scheme=scheme)
        seconds = time.perf_counter() - tic
        signal = self.E @ (model.basis @ np.asarray(solution.a))
        o, y_ref = self.output, self.reference.outputs
        ok = finite(signal)
        # the stepping alone when the solution reports it (set-up and a compiled kernel's loading left out)
        stepping = getattr(solution, "info", {}).get("stepping_seconds", seconds)
        row = {"time_domain_error": (float(np.linalg.norm(signal[o] - y_ref[o]) / np.linalg.norm(y_ref[o]))
                                     if ok else float("inf")),
               "seconds_per_step": stepping / max(times.size - 1, 1), "predict_seconds": seconds,
               "stable": decays(signal[o]),
               "frequency_shift_error": None, "damping_max_error": None, "_signal": signal}
        if ok:
            try:
                curve = self.backbone(signal[o])
                row["_backbone"] = curve
                row.update(backbone_errors(curve, self.reference_backbone, self.amplitude_range))
            except ValueError as exc:      # a signal without the mode in the band
                row["note"] = f"no backbone: {exc}"
        return row
