r"""Test and training inputs sampled on a time grid: phased multi-sines, linear chirps, band-limited noise.

Each function returns an ``array`` :class:`~femrom.scene.Signal` through the
samples ``u(t_k)`` on ``t_k = k dt``, ``k = 0 .. K`` (piecewise linear in
between, as a reduced model sees sampled inputs), multiplied by the raised-cosine
onset

.. math::

    w(t) = \tfrac12 \big(1 - \cos(\pi t / t_r)\big) \ (t < t_r), \qquad w(t) = 1 \ (t \ge t_r),

so that a run starts at rest with ``u(0) = 0`` (``ramp = t_r = 0``: no onset).
A state-space model started from rest then starts where the full-order run does.
"""

from __future__ import annotations

import numpy as np

from femrom._errors import FemromValueError
from femrom.scene._signals import Signal


def sample_times(t_end: float, dt: float) -> np.ndarray:
    """(K + 1,) ndarray ``k dt``, ``K = round(t_end / dt)`` (one error naming a bad value)."""
    if not (np.isfinite(t_end) and t_end > 0 and np.isfinite(dt) and dt > 0):
        raise FemromValueError(f"t_end and dt must be positive and finite, got t_end = {t_end}, dt = {dt}")
    n = int(round(t_end / dt))
    if n < 1:
        raise FemromValueError(f"t_end = {t_end} is shorter than one step dt = {dt}")
    return dt * np.arange(n + 1)


def onset(times, ramp: float) -> np.ndarray:
    """(K,) ndarray of the raised-cosine onset ``w(t)`` (module doc); ones for ``ramp = 0``."""
    t = np.asarray(times, dtype=float)
    if ramp < 0:
        raise FemromValueError(f"ramp must be >= 0, got {ramp}")
    if ramp == 0:
        return np.ones_like(t)
    return np.where(t < ramp, 0.5 * (1.0 - np.cos(np.pi * np.clip(t, 0.0, ramp) / ramp)), 1.0)


def sampled_signal(times, values) -> Signal:
    """An ``array`` signal through ``(times, values)`` (zero outside)."""
    return Signal("array", tuple(sorted({"times": tuple(map(float, times)), "values": tuple(map(float, values)),
                                         "file": None}.items())))


def multisine(amplitudes, frequencies, phases, t_end: float, dt: float, *, ramp: float = 0.0) -> Signal:
    r"""``u(t) = w(t) sum_j a_j sin(2 pi f_j t + phi_j)``.

    Parameters
    ----------
    amplitudes, frequencies, phases : (J,) array_like
        ``a_j``, ``f_j`` [Hz] (positive), ``phi_j`` [rad]; scalars broadcast.
    t_end, dt : float
        The sampled window ``[0, t_end]`` and its step.
    ramp : float
        The onset ``t_r`` [s].
    """
    a, f, phi = np.broadcast_arrays(*(np.atleast_1d(np.asarray(x, dtype=float)) for x in
                                      (amplitudes, frequencies, phases)))
    if not np.all(f > 0):
        raise FemromValueError(f"frequencies must be positive, got {f.tolist()}")
    t = sample_times(t_end, dt)
    u = np.sin(2 * np.pi * f[:, None] * t[None, :] + phi[:, None]).T @ a
    return sampled_signal(t, onset(t, ramp) * u)


def chirp(amplitude: float, f_start: float, f_end: float, t_end: float, dt: float, *, phase: float = 0.0,
          ramp: float = 0.0) -> Signal:
    r"""Linear chirp ``u(t) = w(t) a sin(2 pi (f_0 t + (f_1 - f_0) t^2 / (2 T)) + phi)``, ``T = t_end``.

    The instantaneous frequency ``f_0 + (f_1 - f_0) t / T`` sweeps ``f_start``
    to ``f_end`` [Hz] over the window.
    """
    if not (f_start > 0 and f_end > 0):
        raise FemromValueError(f"chirp frequencies must be positive, got {f_start}, {f_end}")
    t = sample_times(t_end, dt)
    u = amplitude * np.sin(2 * np.pi * (f_start * t + (f_end - f_start) * t ** 2 / (2 * t_end)) + phase)
    return sampled_signal(t, onset(t, ramp) * u)


def band_limited_noise(rms: float, band, t_end: float, dt: float, *, seed: int = 0,
                       ramp: float = 0.0) -> Signal:
    r"""Gaussian white noise filtered to ``band = (f_low, f_high)`` [Hz], scaled to RMS ``rms``.

    The discrete Fourier transform of ``K + 1`` samples of white noise
    (``numpy.random.default_rng(seed)``) is zeroed outside ``f_low <= |f| <= f_high``
    and transformed back: the samples have no content outside the band (up to
    round-off), and are scaled so that ``sqrt(mean(u^2)) = rms`` before the onset
    is applied.
    """
    f_low, f_high = (float(x) for x in band)
    if not 0 <= f_low < f_high:
        raise FemromValueError(f"band must be (f_low, f_high) with 0 <= f_low < f_high, got {band}")
    if f_high > 0.5 / dt:
        raise FemromValueError(f"band's upper edge {f_high} Hz is above the Nyquist frequency "
                               f"{0.5 / dt:g} Hz of dt = {dt}")
    t = sample_times(t_end, dt)
    spectrum = np.fft.rfft(np.random.default_rng(seed).standard_normal(t.size))
    f = np.fft.rfftfreq(t.size, dt)
    spectrum[(f < f_low) | (f > f_high)] = 0.0
    u = np.fft.irfft(spectrum, n=t.size)
    size = np.sqrt(np.mean(u ** 2))
    if size == 0:
        raise FemromValueError(f"band {band} Hz holds no frequency of a {t_end} s window "
                               f"(resolution {1 / (t.size * dt):g} Hz)")
    return sampled_signal(t, onset(t, ramp) * u * (rms / size))
