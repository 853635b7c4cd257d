r"""Backbones against each other: one evaluation at common amplitudes, and what is read from it.

A backbone (:class:`~femrom.post.Backbone`) is frequency ``f(A)`` and damping ratio ``zeta(A)``
against amplitude ``A``, linear in ``log A`` between its windows (:meth:`Backbone.at_amplitude`).
:func:`compare_backbones` evaluates a model's and a reference's backbone at the same amplitudes
``A_1 < ... < A_k`` inside ``[lo, hi]``, the overlap of an amplitude range with both backbones'
ranges: ``n`` log-spaced amplitudes over it (the ROM studies), one backbone's own windows inside
it (a measured backbone's, a prediction's), or given ones. What the studies read from it:

- :func:`backbone_errors`: the relative error of the total frequency shift
  ``|Delta f_m - Delta f_r| / |Delta f_r|`` (``Delta f = f(A_1) - f(A_k)``, the softening over the
  range), the largest frequency difference and the worst relative damping error
  ``max_i |zeta_m(A_i) / zeta_r(A_i) - 1|``;
- :func:`backbone_shift`: one backbone's frequency shift and damping ratios between two amplitudes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError
from femrom.post import Backbone


@dataclass(frozen=True)
class BackboneComparison:
    """Two backbones at common amplitudes (:func:`compare_backbones`).

    Attributes
    ----------
    bounds : (lo, hi)
        The overlap of the amplitude range with both backbones' ranges (``hi <= lo``: none).
    amplitude : (k,) ndarray
        Increasing amplitudes inside ``bounds``, where both curves are evaluated.
    frequency_model, damping_model, frequency_reference, damping_reference : (k,) ndarray
        ``f`` [Hz] and ``zeta`` of each backbone there.
    """

    bounds: tuple
    amplitude: np.ndarray
    frequency_model: np.ndarray
    damping_model: np.ndarray
    frequency_reference: np.ndarray
    damping_reference: np.ndarray

    def __len__(self) -> int:
        return int(self.amplitude.size)

    @property
    def shift_model(self) -> float:
        """``f_m(A_1) - f_m(A_k)`` [Hz]: the model's softening from the lowest to the highest amplitude."""
        return float(self.frequency_model[0] - self.frequency_model[-1])

    @property
    def shift_reference(self) -> float:
        """``f_r(A_1) - f_r(A_k)`` [Hz]."""
        return float(self.frequency_reference[0] - self.frequency_reference[-1])

    @property
    def damping_relative_errors(self) -> np.ndarray:
        """(k,) ``|zeta_m / zeta_r - 1|``."""
        return np.abs(self.damping_model / self.damping_reference - 1)


def _own(backbone: Backbone, lo: float, hi: float):
    """A backbone's own windows with amplitudes inside ``[lo, hi]``, by increasing amplitude."""
    amplitude = np.asarray(backbone.amplitude, dtype=float)
    keep = np.flatnonzero((amplitude >= lo) & (amplitude <= hi))
    keep = keep[np.argsort(amplitude[keep], kind="stable")]
    return amplitude[keep], np.asarray(backbone.frequency_hz)[keep], np.asarray(backbone.damping_ratio)[keep]


def compare_backbones(model: Backbone, reference: Backbone, amplitude_range=(0.0, np.inf), *, at="log",
                      n: int = 24) -> BackboneComparison:
    """Both backbones at common amplitudes inside ``[lo, hi]`` (module docstring).

    Parameters
    ----------
    model, reference : Backbone
    amplitude_range : (2,)
        Clipped to both backbones' ranges: ``lo = max(range[0], min A_m, min A_r)``,
        ``hi = min(range[1], max A_m, max A_r)`` (non-finite amplitudes ignored).
    at : "log", "model", "reference" or (s,) array
        Where to compare: ``"log"``, ``n`` log-spaced amplitudes from ``lo`` to ``hi`` (none if
        ``hi <= lo``); ``"model"`` (``"reference"``), that backbone's own windows inside ``[lo, hi]``,
        its values as they are and the other's interpolated; an array, those of its amplitudes inside
        ``[lo, hi]``, both interpolated (:meth:`Backbone.at_amplitude`). Amplitudes increase.
    """
    lo = max(amplitude_range[0], np.nanmin(model.amplitude), np.nanmin(reference.amplitude))
    hi = min(amplitude_range[1], np.nanmax(model.amplitude), np.nanmax(reference.amplitude))
    if isinstance(at, str) and at in ("model", "reference"):
        own, other = (model, reference) if at == "model" else (reference, model)
        a, f_own, z_own = _own(own, lo, hi)
        f_other, z_other = other.at_amplitude(a) if a.size else (np.empty(0), np.empty(0))
        f_m, z_m, f_r, z_r = (f_own, z_own, f_other, z_other) if at == "model" else (f_other, z_other, f_own, z_own)
        return BackboneComparison((float(lo), float(hi)), a, f_m, z_m, f_r, z_r)
    if isinstance(at, str):
        if at != "log":
            raise FemromValueError(f"at must be 'log', 'model', 'reference' or an array of amplitudes, got {at!r}")
        a = np.geomspace(lo, hi, n) if hi > lo else np.empty(0)
    else:
        a = np.asarray(at, dtype=float)
        a = np.sort(a[(a >= lo) & (a <= hi)])
    if a.size:
        f_m, z_m = model.at_amplitude(a)
        f_r, z_r = reference.at_amplitude(a)
    else:
        f_m = z_m = f_r = z_r = np.empty(0)
    return BackboneComparison((float(lo), float(hi)), a, f_m, z_m, f_r, z_r)


def backbone_errors(model: Backbone, reference: Backbone, amplitude_range, n: int = 24, *, at="log") -> dict:
    """The model's backbone against the reference's (:func:`compare_backbones`; by default at ``n``
    log-spaced amplitudes over ``amplitude_range`` clipped to both ranges): the amplitudes compared
    (first and last), both frequency shifts over them and the shift's relative error, the largest
    frequency difference, and the worst relative damping error. ``None`` errors when the ranges do
    not overlap (fewer than two amplitudes)."""
    c = compare_backbones(model, reference, amplitude_range, at=at, n=n)
    if len(c) < 2:
        return {"amplitude_range": [float(c.bounds[0]), float(c.bounds[1])], "frequency_shift_error": None,
                "damping_max_error": None}
    shift_m, shift_r = c.shift_model, c.shift_reference
    return {"amplitude_range": [float(c.amplitude[0]), float(c.amplitude[-1])], "frequency_shift_hz": shift_m,
            "reference_shift_hz": shift_r,
            "frequency_shift_error": abs(shift_m - shift_r) / abs(shift_r) if shift_r else None,
            "frequency_max_difference_hz": float(np.max(np.abs(c.frequency_model - c.frequency_reference))),
            "damping_max_error": float(np.max(c.damping_relative_errors))}


def backbone_shift(backbone: Backbone, low: float, high: float) -> dict:
    """Frequency shift ``f(A_lo) - f(A_hi)`` [Hz] and the damping ratios at both ends, between the
    amplitudes ``low`` and ``high`` clipped to the backbone's range (``A_lo = max(low, min A)``,
    ``A_hi = min(high, max A)``): ``{"from_amplitude", "to_amplitude", "frequency_shift_hz", "damping_low",
    "damping_high"}``; the shift is ``None`` (and no damping) when they do not bracket a range."""
    amplitude = np.asarray(backbone.amplitude)
    lo, hi = max(low, amplitude.min()), min(high, amplitude.max())
    if not hi > lo:
        return {"from_amplitude": lo, "to_amplitude": hi, "frequency_shift_hz": None}
    f_lo, z_lo = backbone.at_amplitude(lo)
    f_hi, z_hi = backbone.at_amplitude(hi)
    return {"from_amplitude": float(lo), "to_amplitude": float(hi), "frequency_shift_hz": float(f_lo - f_hi),
            "damping_low": float(z_lo), "damping_high": float(z_hi)}
