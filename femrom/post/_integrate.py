r"""Velocity and displacement from a measured acceleration: integration in a frequency band.

Integrating an accelerometer signal in time amplifies whatever it holds at low
frequency (an offset, the sensor's drift, a suspension mode): a constant ``c`` grows
into ``c t^2 / 2``. Inside a band ``[f_lo, f_hi]`` that excludes zero, integration is
a division in the frequency domain, exact for every harmonic:

.. math::

    \hat v(\omega) = \frac{\hat a(\omega)}{i \omega}, \qquad
    \hat q(\omega) = -\frac{\hat a(\omega)}{\omega^2}, \qquad
    \omega = 2 \pi f, \ f \in [f_{lo}, f_{hi}],

and zero outside the band, with raised-cosine flanks of width ``roll`` (a fraction of
each band edge) so that the band's edges do not ring. The signal is zero-padded to at
least twice its length before the FFT, so that a ring-down that has decayed at its end
does not wrap around onto its start. The three returned signals are consistent:
``a_band`` is the acceleration filtered by the same band, and ``v``, ``q`` are its
exact integrals in the band (``v' = a_band``, ``q' = v`` up to the FFT's round-off).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference import SecondOrderData


@dataclass(frozen=True)
class BandIntegrals:
    """Acceleration, velocity and displacement of one signal in one band.

    Attributes
    ----------
    acceleration, velocity, displacement : (k,) or (c, k) ndarray
        ``a_band``, ``v``, ``q`` on the input's time grid.
    sample_rate : float
    band : (float, float)
    """

    acceleration: np.ndarray
    velocity: np.ndarray
    displacement: np.ndarray
    sample_rate: float
    band: tuple[float, float]


def band_weights(frequencies: np.ndarray, band, roll: float) -> np.ndarray:
    """(f,) weights in [0, 1]: 1 inside ``band``, raised-cosine flanks of relative width ``roll`` outside it."""
    lo, hi = band
    f = np.abs(np.asarray(frequencies, dtype=float))
    w = ((f >= lo) & (f <= hi)).astype(float)
    if roll > 0:
        lower = (f < lo) & (f > lo * (1 - roll))
        w[lower] = 0.5 * (1 + np.cos(np.pi * (lo - f[lower]) / (lo * roll)))
        upper = (f > hi) & (f < hi * (1 + roll))
        w[upper] = 0.5 * (1 + np.cos(np.pi * (f[upper] - hi) / (hi * roll)))
    return w


def band_limited_integrals(acceleration, sample_rate: float, band, *, roll: float = 0.2) -> BandIntegrals:
    r"""Velocity and displacement of ``acceleration`` in ``band`` (module docstring).

    Parameters
    ----------
    acceleration : (k,) or (c, k) array_like
        Samples (one row per channel).
    sample_rate : float
        [Hz].
    band : (float, float)
        ``0 < f_lo < f_hi`` [Hz], below the Nyquist frequency (including the flank).
    roll : float
        Relative width of the raised-cosine flanks, in [0, 1) (default 0.2).
    """
    a = np.asarray(acceleration, dtype=float)
    if a.ndim not in (1, 2) or a.shape[-1] < 8 or not np.all(np.isfinite(a)):
        raise FemromValueError(f"acceleration must be a finite (k,) or (c, k) array with k >= 8, got shape {a.shape}")
    rate = float(sample_rate)
    if not (np.isfinite(rate) and rate > 0):
        raise FemromValueError(f"sample_rate must be a positive number, got {sample_rate!r}")
    if not 0 <= roll < 1:
        raise FemromValueError(f"roll must lie in [0, 1), got {roll!r}")
    try:
        lo, hi = (float(b) for b in band)
    except (TypeError, ValueError):
        raise FemromValueError(f"band must be two frequencies (f_lo, f_hi), got {band!r}") from None
    if not (0 < lo < hi and hi * (1 + roll) < rate / 2):
        raise FemromValueError(f"band must satisfy 0 < f_lo < f_hi and f_hi (1 + roll) < {rate / 2:g} Hz "
                               f"(Nyquist), got {band!r}")
    k = a.shape[-1]
    n = 1 << int(np.ceil(np.log2(2 * k)))            # zero-padded: no wrap-around of the ring-down
    spectrum = np.fft.rfft(a, n=n, axis=-1)
    f = np.fft.rfftfreq(n, d=1.0 / rate)
    w = band_weights(f, (lo, hi), roll)
    omega = 2 * np.pi * f
    safe = np.where(w > 0, omega, 1.0)
    filtered = spectrum * w
    velocity = np.fft.irfft(filtered / (1j * safe), n=n, axis=-1)[..., :k]
    displacement = np.fft.irfft(-filtered / safe**2, n=n, axis=-1)[..., :k]
    band_acceleration = np.fft.irfft(filtered, n=n, axis=-1)[..., :k]
    return BandIntegrals(band_acceleration, velocity, displacement, rate, (lo, hi))


@dataclass(frozen=True)
class ModalRecord:
    r"""Dominant modal coordinates of a band-limited multi-channel record.

    Attributes
    ----------
    data : SecondOrderData
        ``q``, ``q'``, ``q''`` (r, K) of the kept samples (no input), ``times`` (K,).
    shapes : (c, r) ndarray
        Orthonormal channel shapes (the displacements' leading left singular vectors,
        signed so that each column's largest entry is positive): channels ``x = shapes q``.
    singular_values : (min(c, K),) ndarray
        All singular values of the band-passed displacements (kept samples), largest first.
    band : (float, float)
    sample_rate : float
    """

    data: SecondOrderData
    shapes: np.ndarray
    singular_values: np.ndarray
    band: tuple[float, float]
    sample_rate: float

    def channel_acceleration(self, accelerations, channel: int) -> np.ndarray:
        """(k,) acceleration of one channel from modal accelerations (r, k): ``shapes[channel] @ a``."""
        return self.shapes[channel] @ np.atleast_2d(np.asarray(accelerations, dtype=float))


def modal_record(acceleration, sample_rate: float, band, *, rank: int = 1, trim: float = 0.0,
                 every: int = 1, roll: float = 0.2, start_time: float = 0.0) -> ModalRecord:
    r"""Band-limited multi-channel accelerations -> the ``rank`` dominant modal coordinates.

    Each channel is integrated in ``band`` (:func:`band_limited_integrals`), giving
    consistent ``(a, v, x)`` (c, k). The displacements of the kept samples (``trim``
    seconds dropped at each end: the band's transients) are decomposed,
    ``X = W S Z^T``; the modal coordinates are the projections ``q = W_r^T x``,
    ``q' = W_r^T v``, ``q'' = W_r^T a`` on the ``rank`` leading shapes (the same
    linear map for all three, so ``q'`` and ``q''`` stay the exact band derivatives of
    ``q``). The singular values say how many coordinates the sensors support.

    Parameters
    ----------
    acceleration : (c, k) array_like
        One row per channel, uniformly sampled.
    sample_rate : float
        [Hz].
    band : (float, float)
        [Hz], as in :func:`band_limited_integrals`.
    rank : int
        Number of coordinates, ``1 <= rank <= c``.
    trim : float
        Seconds dropped at each end, ``>= 0``.
    every : int
        Keep every ``every``-th sample of the trimmed record (after the integration at the full rate).
    roll : float
        Flank width of the band (:func:`band_weights`).
    start_time : float
        Time of the record's first sample [s].
    """
    a = np.atleast_2d(np.asarray(acceleration, dtype=float))
    if a.ndim != 2:
        raise FemromValueError(f"acceleration must be (c, k), got shape {a.shape}")
    c, k = a.shape
    if not (isinstance(rank, (int, np.integer)) and 1 <= rank <= c):
        raise FemromValueError(f"rank must be an integer in [1, {c}] (the channels), got {rank!r}")
    if not (isinstance(every, (int, np.integer)) and every >= 1):
        raise FemromValueError(f"every must be a positive integer, got {every!r}")
    integrals = band_limited_integrals(a, sample_rate, band, roll=roll)
    rate = integrals.sample_rate
    cut = int(round(float(trim) * rate)) if trim else 0
    if trim < 0 or k - 2 * cut < 2 * rank:
        raise FemromValueError(f"trim must be >= 0 and leave samples: {trim!r} s of {k / rate:g} s")
    kept = slice(cut, k - cut)
    W, S, _ = np.linalg.svd(integrals.displacement[:, kept], full_matrices=False)
    W = W[:, :rank]
    W = W * np.where(np.abs(W.max(axis=0)) >= np.abs(W.min(axis=0)), 1.0, -1.0)
    taken = slice(cut, k - cut, every)
    q, v, acc = (W.T @ X[:, taken] for X in (integrals.displacement, integrals.velocity,
                                              integrals.acceleration))
    times = float(start_time) + np.arange(k)[taken] / rate
    data = SecondOrderData(q, v, acc, times=times,
                           diagnostics={"derivative_source": "band_limited_integrals", "dt": every / rate,
                                        "band": integrals.band, "n_trajectories": 1})
    return ModalRecord(data, W, S, integrals.band, rate)
