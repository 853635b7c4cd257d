"""Input signals ``u(t)``: step, sigmoid, sine, impulse and user-given arrays."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from femrom.scene._errors import SceneError

SIGNAL_KEYS = {
    "step": {"amplitude": 1.0, "start": 0.0},
    "sigmoid": {"amplitude": 1.0, "midpoint": 0.0, "width": 1.0},
    "sine": {"amplitude": 1.0, "frequency": 1.0, "phase": 0.0, "start": 0.0},
    "impulse": {"amplitude": 1.0, "start": 0.0, "duration": 1.0},
    "array": {"times": None, "values": None, "file": None},
}


@dataclass(frozen=True)
class Signal:
    r"""A scalar input signal ``u(t)``.

    Kinds and parameters (SI units, frequency in Hz):

    - ``step``: ``a H(t - start)``
    - ``sigmoid``: ``a / (1 + exp(-(t - midpoint) / width))``
    - ``sine``: ``a sin(2 pi f (t - start) + phase) H(t - start)``
    - ``impulse``: half-sine pulse of peak ``a`` on ``[start, start + duration]``
      (a smooth hammer blow; impulse ``2 a duration / pi``). Its spectrum is flat
      within 3 dB up to ``0.594 / duration`` and first vanishes at ``1.5 / duration``
      (:func:`half_sine_spectrum`): the duration, set by the hammer tip, sets the
      excited band.
    - ``array``: piecewise-linear through ``times``/``values`` (or an ``.npz``
      ``file`` with arrays ``t`` and ``u``), zero outside.
    """

    kind: str
    parameters: tuple = field(default=())

    @classmethod
    def from_dict(cls, data: dict, where: str = "signal") -> "Signal":
        data = dict(data)
        kind = data.pop("kind", None)
        if kind not in SIGNAL_KEYS:
            raise SceneError(f"{where}: unknown signal kind {kind!r}; valid: {', '.join(SIGNAL_KEYS)}")
        defaults = SIGNAL_KEYS[kind]
        unknown = sorted(set(data) - set(defaults))
        if unknown:
            raise SceneError(f"{where}: unknown key {unknown[0]!r} for a {kind} signal; "
                             f"valid: kind, {', '.join(defaults)}")
        params = {**defaults, **data}
        if kind == "array":
            params = _array_parameters(params, where)
        else:
            for key, value in params.items():
                if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                    raise SceneError(f"{where}: {key} must be a finite number, got {value!r}")
            params = {key: float(value) for key, value in params.items()}
        if kind == "sine" and not params["frequency"] > 0:
            raise SceneError(f"{where}: frequency must be positive (Hz), got {params['frequency']}")
        if kind in ("sigmoid", "impulse"):
            positive = "width" if kind == "sigmoid" else "duration"
            if not params[positive] > 0:
                raise SceneError(f"{where}: {positive} must be positive, got {params[positive]}")
        return cls(kind, tuple(sorted(params.items())))

    def scaled(self, factor: float) -> "Signal":
        """The same signal times ``factor`` (its amplitude, or an array's values)."""
        p = dict(self.parameters)
        if self.kind == "array":
            p["values"] = tuple(float(factor) * v for v in p["values"])
        else:
            p["amplitude"] = float(factor) * p["amplitude"]
        return Signal(self.kind, tuple(sorted(p.items())))

    def __call__(self, t):
        p = dict(self.parameters)
        t = np.asarray(t, dtype=float)
        if self.kind == "step":
            return p["amplitude"] * (t >= p["start"])
        if self.kind == "sigmoid":
            return p["amplitude"] / (1.0 + np.exp(-(t - p["midpoint"]) / p["width"]))
        if self.kind == "sine":
            s = t - p["start"]
            return p["amplitude"] * np.sin(2 * np.pi * p["frequency"] * s + p["phase"]) * (s >= 0)
        if self.kind == "impulse":
            s = (t - p["start"]) / p["duration"]
            return p["amplitude"] * np.sin(np.pi * s) * ((s >= 0) & (s <= 1))
        times, values = np.asarray(p["times"]), np.asarray(p["values"])
        return np.interp(t, times, values, left=0.0, right=0.0)


def half_sine_spectrum(frequency, amplitude: float, duration: float):
    r"""Magnitude of the Fourier transform of the half-sine pulse (``impulse`` signal), [N s] for a force in N.

    For ``u(t) = a sin(pi t / tau)`` on ``[0, tau]`` (zero elsewhere),

    .. math::

        |U(f)| = \left|\int u(t)\, e^{-2 \pi i f t}\, dt\right|
               = \frac{2 a \tau}{\pi} \left|\frac{\cos(\pi f \tau)}{1 - (2 f \tau)^2}\right|,

    ``2 a tau / pi`` at ``f = 0`` (the impulse), ``a tau / 2`` at ``f tau = 1/2``
    (the removable 0/0), 3 dB down at ``f tau = 0.594`` and zero first at
    ``f tau = 3/2``, then lobes falling as ``f^-2``. ``frequency`` [Hz]: float or
    ndarray; returns the same shape.
    """
    x = np.asarray(frequency, dtype=float) * float(duration)
    denominator = 1.0 - (2.0 * x) ** 2
    near = np.abs(denominator) < 1e-8
    safe = np.where(near, 1.0, denominator)
    ratio = np.where(near, np.pi / 4.0, np.cos(np.pi * x) / safe)
    return 2.0 * float(amplitude) * float(duration) / np.pi * np.abs(ratio)


class SignalVector:
    """``u(t) = [s_1(t), ..., s_m(t)]``: a scene's inputs, callable at one time or sampled on a grid."""

    def __init__(self, signals):
        self.signals = tuple(signals)

    def __call__(self, t) -> np.ndarray:
        return np.array([float(s(t)) for s in self.signals])

    def sampled(self, times) -> np.ndarray | None:
        """(m, k) ndarray of ``u`` on ``times`` (``None`` without inputs)."""
        times = np.asarray(times, dtype=float)
        if not self.signals:
            return None
        return np.vstack([np.broadcast_to(np.asarray(s(times), dtype=float), times.shape)
                          for s in self.signals])


def _array_parameters(params, where):
    if params["file"] is not None:
        path = Path(params["file"])
        try:
            with np.load(path) as data:
                times, values = data["t"], data["u"]
        except (OSError, KeyError, ValueError) as exc:
            raise SceneError(f"{where}: cannot read signal file {path} (needs arrays 't' and 'u'): {exc}") from None
    else:
        times, values = params["times"], params["values"]
    if times is None or values is None:
        raise SceneError(f"{where}: an array signal needs 'times' and 'values' (or 'file')")
    times = np.asarray(times, dtype=float)
    values = np.asarray(values, dtype=float)
    if times.ndim != 1 or times.shape != values.shape or times.size < 2 or np.any(np.diff(times) <= 0):
        raise SceneError(f"{where}: array signal needs increasing 'times' and 'values' of the same length >= 2")
    return {"times": tuple(times), "values": tuple(values), "file": params["file"]}
