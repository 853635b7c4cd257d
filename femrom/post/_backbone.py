r"""Backbone and damping-vs-amplitude curves from free-decay (ring-down) signals.

A weakly damped mode of a nonlinear structure rings down as

.. math::

    x(t) \approx a(t) \cos\varphi(t), \qquad
    \dot a = -\sigma(a)\, a, \qquad \dot\varphi = \omega_d(a),

so the instantaneous decay rate ``sigma`` and damped circular frequency ``omega_d``
are functions of the amplitude ``a``: the *backbone* ``omega_d(a)`` and the damping
curve. Two estimators, which share only the band-pass filter:

* :func:`hilbert_backbone`: zero-phase band-pass around the mode
  (:func:`scipy.signal.sosfiltfilt`), analytic signal ``y + i H[y] = A e^{i phi}``
  (:func:`scipy.signal.hilbert`), then in each window a least-squares line through
  the unwrapped phase (slope ``omega_d``) and through ``ln A`` (slope ``-sigma``).
* :func:`peak_backbone`: zero crossings and extrema of the filtered signal; in
  each group of cycles a least-squares line through the zero-crossing times
  (half period) and through ``ln |extremum|`` (the log decrement
  ``delta = sigma T_d`` of the group).

Damping ratio, both estimators (the definition that makes a linear oscillator's
``zeta`` exact: poles ``-sigma +- i omega_d``, ``omega_n^2 = sigma^2 + omega_d^2``):

.. math::

    \zeta = \frac{\sigma}{\sqrt{\sigma^2 + \omega_d^2}}
          = \frac{\delta}{\sqrt{4\pi^2 + \delta^2}}, \qquad \delta = \sigma T_d = 2\pi\sigma/\omega_d.

End effects. The forward-backward filter starts (and, running backwards, ends) on a
transient of the band-pass filter, which decays like ``exp(-p t)`` with ``p`` the
smallest ``|Re|`` of the filter's poles; the FFT-based Hilbert transform treats the
record as periodic and is wrong near both ends by a slowly (algebraically) decaying
amount (about ``J / (pi omega d)`` at a distance ``d`` from a wrap-around jump ``J``;
for a decaying record the jump is the large start, felt at the small end). So the
Hilbert estimator multiplies the filtered signal by a raised-cosine ramp over
``trim`` seconds at each end (the extension is then smooth and the edge error decays
fast), zero-pads it to twice its length before the FFT (the periodic image of the
large start then lies a record length away from the small end, not next to it), and
both estimators drop those ``trim`` seconds. The default (:func:`default_trim`) is
the time the slowest filter pole ``p`` takes to decay by ``TRIM_DECAY = 1e-4``
(``ln(1e4) / p``), at least ten periods of the band's centre: 0.25 s for a 4th-order
Butterworth band 60-100 Hz at 12.8 kHz (``p = 36.9 / s``).

Measured on a linear decay 30 -> 0.2 over 5.12 s at 80.5 Hz in that band (the case of
the measured beam), largest relative errors in the kept part, start half / end half
(end relative to the 150x smaller end amplitude):

=========================  ===================  ===================
processing                 envelope             inst. frequency
=========================  ===================  ===================
no ramp, circular FFT      1.5e-3 / 1.3e-1      1.9e-3 / 2.0e-1
ramp, circular FFT         3.7e-5 / 1.1e-4      3.1e-5 / 9.4e-5
ramp, zero-padded (used)   3.7e-5 / 3.0e-5      3.1e-5 / 2.7e-5
=========================  ===================  ===================

and the 0.2 s window fits then recover ``f`` to 2e-8 and ``zeta`` to 1e-5 (relative).
On a 535x decay (10 Hz, ``zeta = 0.005``, band 5-20 Hz, 20 s at 500 Hz) the padding
took the end windows' ``zeta`` error from 3e-3 to 6e-5.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.fft as scipy_fft
import scipy.signal as signal_tools

from femrom._errors import FemromValueError

#: Relative decay of the slowest filter pole over the default trim (see :func:`default_trim`).
TRIM_DECAY = 1e-4
#: The default trim is at least this many periods of the band centre (Hilbert edge error).
TRIM_MIN_PERIODS = 10


@dataclass(frozen=True)
class Backbone:
    r"""Amplitude-dependent frequency and damping of one mode, one entry per window.

    Attributes
    ----------
    time : (w,) ndarray
        Window centre times [s].
    amplitude : (w,) ndarray
        Envelope of the band-passed signal at the window centre (units of the signal):
        the mode's amplitude when it lies well inside the pass band (the zero-phase
        filter's gain ``|H(f)|^2`` is 1 - 2.4e-7 at 80.5 Hz in a 4th-order 60-100 Hz band).
    frequency_hz : (w,) ndarray
        Damped frequency ``omega_d / 2 pi`` [Hz].
    damping_ratio : (w,) ndarray
        ``zeta = sigma / sqrt(sigma^2 + omega_d^2)`` (a fraction, not %).
    method : str
        Which estimator produced it ("hilbert", "peaks", ...).
    """

    time: np.ndarray
    amplitude: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    method: str = field(default="")

    def __post_init__(self):
        arrays = {}
        for name in ("time", "amplitude", "frequency_hz", "damping_ratio"):
            value = np.array(getattr(self, name), dtype=float).reshape(-1)
            value.setflags(write=False)
            arrays[name] = value
        sizes = {name: value.size for name, value in arrays.items()}
        if len(set(sizes.values())) != 1:
            raise FemromValueError(f"Backbone arrays need one length, got {sizes}")
        for name, value in arrays.items():
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return self.time.size

    @property
    def decay_rate(self) -> np.ndarray:
        r"""(w,) ``sigma = zeta omega_d / sqrt(1 - zeta^2)`` [1/s] (inverse of the ``zeta`` definition)."""
        omega_d = 2 * np.pi * self.frequency_hz
        return self.damping_ratio * omega_d / np.sqrt(1.0 - self.damping_ratio ** 2)

    def rows(self) -> list[dict]:
        """One ``{"amplitude", "frequency_hz", "damping_ratio"}`` dict per window (for metrics.json)."""
        return [{"amplitude": float(a), "frequency_hz": float(f), "damping_ratio": float(z)}
                for a, f, z in zip(self.amplitude, self.frequency_hz, self.damping_ratio)]

    def at_amplitude(self, amplitude):
        """Frequency [Hz] and damping ratio at ``amplitude`` (scalar or array), linear in
        ``log(amplitude)`` between windows.

        Raises
        ------
        FemromValueError
            An amplitude outside the range the backbone covers (no extrapolation), or
            a backbone whose amplitudes are not all positive.
        """
        amplitude = np.asarray(amplitude, dtype=float)
        if len(self) == 0 or not np.all(self.amplitude > 0):
            raise FemromValueError("at_amplitude needs a backbone with positive amplitudes")
        lo, hi = self.amplitude.min(), self.amplitude.max()
        if not np.all((amplitude >= lo) & (amplitude <= hi)):
            raise FemromValueError(f"amplitude must lie in the backbone's range [{lo:.6g}, {hi:.6g}], "
                                   f"got {np.min(amplitude):.6g}..{np.max(amplitude):.6g}")
        order = np.argsort(self.amplitude)
        log_a = np.log(self.amplitude[order])
        x = np.log(amplitude)
        return (np.interp(x, log_a, self.frequency_hz[order]),
                np.interp(x, log_a, self.damping_ratio[order]))


# ----------------------------------------------------------------------------- input checks


def _check_signal(signal) -> np.ndarray:
    x = np.asarray(signal, dtype=float)
    if x.ndim != 1:
        raise FemromValueError(f"signal must be a 1-D array of samples, got shape {x.shape}")
    if x.size < 16:
        raise FemromValueError(f"signal must have at least 16 samples, got {x.size}")
    if not np.all(np.isfinite(x)):
        bad = np.flatnonzero(~np.isfinite(x))
        raise FemromValueError(f"signal has {bad.size} non-finite samples (first at index {bad[0]}); "
                               "all samples must be finite")
    return x


def _check_rate(sample_rate) -> float:
    try:
        rate = float(sample_rate)
    except (TypeError, ValueError):
        raise FemromValueError(f"sample_rate must be a positive finite number [Hz], got {sample_rate!r}") from None
    if not (np.isfinite(rate) and rate > 0):
        raise FemromValueError(f"sample_rate must be a positive finite number [Hz], got {sample_rate!r}")
    return rate


def _check_band(band, rate: float) -> tuple[float, float]:
    try:
        low, high = (float(b) for b in band)
    except (TypeError, ValueError):
        raise FemromValueError(f"band must be a pair (low, high) in Hz, got {band!r}") from None
    nyquist = rate / 2
    if not (0 < low < high < nyquist):
        raise FemromValueError(f"band must satisfy 0 < low < high < Nyquist = {nyquist:g} Hz, got ({low:g}, {high:g})")
    return low, high


def _is_positive_integer(value) -> bool:
    return (isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= 1)


def _check_order(filter_order) -> int:
    if not _is_positive_integer(filter_order):
        raise FemromValueError(f"filter_order must be a positive integer, got {filter_order!r}")
    return int(filter_order)


def _band_pass(x, rate, band, order):
    sos = signal_tools.butter(order, band, btype="bandpass", fs=rate, output="sos")
    return sos, signal_tools.sosfiltfilt(sos, x)


def default_trim(sample_rate: float, band, filter_order: int = 4) -> float:
    r"""Seconds cut from each end of a band-passed record by default.

    ``max(ln(1 / TRIM_DECAY) / p, TRIM_MIN_PERIODS / f_c)``: ``p`` the smallest
    ``|Re s|`` of the Butterworth band-pass poles (continuous time, from the
    discrete poles ``z`` as ``|Re s| = -ln|z| f_s``), so the filter's start and end
    transients have decayed by ``TRIM_DECAY``; ``f_c = sqrt(low high)`` the band
    centre, so that a ramp over the trimmed length (:func:`hilbert_backbone`) spans
    many cycles and the Hilbert transform's edge error has died out.
    """
    rate = _check_rate(sample_rate)
    band = _check_band(band, rate)
    order = _check_order(filter_order)
    _, poles, _ = signal_tools.butter(order, band, btype="bandpass", fs=rate, output="zpk")
    slowest = np.min(-np.log(np.abs(poles)) * rate)
    centre = np.sqrt(band[0] * band[1])
    return float(max(np.log(1 / TRIM_DECAY) / slowest, TRIM_MIN_PERIODS / centre))


def _trim_samples(trim, rate, band, order, n) -> int:
    if trim is None:
        trim = default_trim(rate, band, order)
    trim = float(trim)
    if not (np.isfinite(trim) and trim >= 0):
        raise FemromValueError(f"trim must be a non-negative number of seconds, got {trim!r}")
    k = int(round(trim * rate))
    if 2 * k >= n:
        raise FemromValueError(f"trim = {trim:g} s from each end leaves nothing of a {n / rate:g} s signal")
    return k


def _end_ramps(n: int, k: int) -> np.ndarray:
    """(n,) raised-cosine ramps 0 -> 1 over the first and 1 -> 0 over the last k samples."""
    ramp = np.ones(n)
    if k > 0:
        rise = 0.5 - 0.5 * np.cos(np.pi * (np.arange(k) + 0.5) / k)
        ramp[:k] = rise
        ramp[n - k:] = rise[::-1]
    return ramp


def _line_slopes(t, *ys):
    """Least-squares slopes (and intercepts at the mean of t) of the ys against t."""
    tc = t - t.mean()
    denom = tc @ tc
    return [((tc @ y) / denom, y.mean()) for y in ys]


# ----------------------------------------------------------------------------- estimators


def hilbert_backbone(signal, sample_rate: float, band, *, window: float, overlap: float = 0.5,
                     filter_order: int = 4, trim: float | None = None, start_time: float = 0.0) -> Backbone:
    r"""Backbone of the mode inside ``band`` by the Hilbert transform, window by window.

    With ``y`` the zero-phase band-passed signal and ``y + i H[y] = A e^{i phi}``, each
    window ``[t_0, t_0 + T_w]`` fits, in the least-squares sense,

    .. math::

        \varphi(t) \approx \varphi_0 + \omega_d t, \qquad
        \ln A(t) \approx c - \sigma t,

    and reports ``f = omega_d / 2 pi``, ``zeta = sigma / sqrt(sigma^2 + omega_d^2)``
    and the amplitude ``exp(c - sigma t_c)``, the fitted envelope at the window centre
    ``t_c`` (the geometric mean of ``A`` over the window).

    Parameters
    ----------
    signal : (k,) ndarray
        Uniformly sampled free decay (any unit: displacement, acceleration, ...).
    sample_rate : float
        Samples per second [Hz].
    band : (float, float)
        Pass band ``(low, high)`` [Hz] around the mode, ``0 < low < high < sample_rate / 2``.
    window : float
        Window length [s]; at least 4 samples and at most the trimmed record.
    overlap : float
        Fraction ``[0, 1)`` by which consecutive windows overlap.
    filter_order : int
        Butterworth order of the band-pass (doubled by the forward-backward pass).
    trim : float, optional
        Seconds dropped at each end after filtering; default :func:`default_trim`.
    start_time : float
        Time of the first sample (the reported window times are offset by it).

    Returns
    -------
    Backbone
        One entry per window, ``method="hilbert"``.
    """
    x = _check_signal(signal)
    rate = _check_rate(sample_rate)
    band = _check_band(band, rate)
    order = _check_order(filter_order)
    overlap = float(overlap)
    if not (0 <= overlap < 1):
        raise FemromValueError(f"overlap must be a fraction in [0, 1), got {overlap!r}")
    window = float(window)
    n_window = int(round(window * rate)) if np.isfinite(window) else -1
    if n_window < 4:
        raise FemromValueError(f"window must be a positive length of at least 4 samples (4 / sample_rate = "
                               f"{4 / rate:g} s), got {window!r}")
    cut = _trim_samples(trim, rate, band, order, x.size)
    usable = x.size - 2 * cut
    if n_window > usable:
        raise FemromValueError(f"window = {window:g} s is longer than the signal after trimming "
                               f"({usable / rate:g} s of {x.size / rate:g} s; trim {cut / rate:g} s each end)")

    _, y = _band_pass(x, rate, band, order)
    # zero-padded to twice the length: the FFT's periodic image of the (large) start then
    # lies a record length away from the (small) end instead of right next to it
    padded = scipy_fft.next_fast_len(2 * x.size, real=True)
    analytic = signal_tools.hilbert(y * _end_ramps(x.size, cut), N=padded)[:x.size]
    log_envelope = np.log(np.maximum(np.abs(analytic), np.finfo(float).tiny))
    phase = np.unwrap(np.angle(analytic))

    step = max(1, int(round(n_window * (1 - overlap))))
    starts = np.arange(cut, x.size - cut - n_window + 1, step)
    t_local = np.arange(n_window) / rate
    out = np.empty((4, starts.size))
    for j, s in enumerate(starts):
        (omega_d, _), (slope, mean_log) = _line_slopes(t_local, phase[s:s + n_window], log_envelope[s:s + n_window])
        sigma = -slope
        out[:, j] = (start_time + (s + (n_window - 1) / 2) / rate, np.exp(mean_log),
                     omega_d / (2 * np.pi), sigma / np.hypot(sigma, omega_d))
    return Backbone(*out, method="hilbert")


def peak_backbone(signal, sample_rate: float, band, *, cycles: int = 8, filter_order: int = 4,
                  trim: float | None = None, start_time: float = 0.0) -> Backbone:
    r"""Backbone of the mode inside ``band`` from zero crossings and peaks (log decrement).

    The band-passed signal ``y`` (as in :func:`hilbert_backbone`) is cut into groups of
    ``cycles`` whole cycles. Zero crossings ``t_k`` (linear interpolation between
    samples) and extrema ``|y_j|`` at ``tau_j`` (parabola through three samples),
    one per half cycle, give by least squares in each group

    .. math::

        t_k \approx t_0 + k\,\frac{T_d}{2}, \qquad
        \ln|y_j| \approx c - \sigma \tau_j,

    so ``f = 1 / T_d`` and the log decrement per cycle ``delta = sigma T_d``;
    ``zeta = delta / sqrt(4 pi^2 + delta^2)`` (the same definition as the Hilbert
    estimator) and the amplitude is ``exp(c - sigma t_c)`` at the group's centre.
    Independent of the Hilbert transform; consecutive groups do not overlap.

    Parameters
    ----------
    signal, sample_rate, band, filter_order, trim, start_time
        As in :func:`hilbert_backbone`.
    cycles : int
        Cycles per group (at least 1).

    Returns
    -------
    Backbone
        One entry per group, ``method="peaks"``.
    """
    x = _check_signal(signal)
    rate = _check_rate(sample_rate)
    band = _check_band(band, rate)
    order = _check_order(filter_order)
    if not _is_positive_integer(cycles):
        raise FemromValueError(f"cycles must be a positive integer, got {cycles!r}")
    cycles = int(cycles)
    cut = _trim_samples(trim, rate, band, order, x.size)
    _, y = _band_pass(x, rate, band, order)
    y = y[cut:x.size - cut]

    sign = np.signbit(y)
    i = np.flatnonzero(sign[1:] != sign[:-1])                   # y[i], y[i+1] straddle zero
    crossings = i + y[i] / (y[i] - y[i + 1])                    # fractional sample index
    half_cycles = crossings.size - 1
    if half_cycles < 2 * cycles:
        raise FemromValueError(f"cycles = {cycles}: the trimmed signal has only {half_cycles // 2} whole cycles "
                               f"in band {band} Hz")
    # one extremum between consecutive crossings
    peak_time = np.empty(half_cycles)
    peak_value = np.empty(half_cycles)
    for j in range(half_cycles):
        a, b = i[j] + 1, i[j + 1] + 1
        m = a + int(np.argmax(np.abs(y[a:b])))
        if 0 < m < y.size - 1:
            ym, y0, yp = np.abs(y[m - 1:m + 2])
            curvature = ym - 2 * y0 + yp
            shift = 0.5 * (ym - yp) / curvature if curvature < 0 else 0.0
            peak_time[j] = m + shift
            peak_value[j] = y0 - 0.25 * (ym - yp) * shift
        else:
            peak_time[j], peak_value[j] = m, abs(y[m])

    n_groups = half_cycles // (2 * cycles)
    out = np.empty((4, n_groups))
    for g in range(n_groups):
        k = slice(2 * cycles * g, 2 * cycles * (g + 1) + 1)     # 2 * cycles + 1 crossings
        p = slice(2 * cycles * g, 2 * cycles * (g + 1))         # the extrema between them
        tk = crossings[k] / rate
        (half_period, _), = _line_slopes(np.arange(tk.size, dtype=float), tk)
        tau = peak_time[p] / rate
        (slope, mean_log), = _line_slopes(tau, np.log(np.maximum(peak_value[p], np.finfo(float).tiny)))
        period = 2 * half_period
        delta = -slope * period
        t_centre = tau.mean()
        out[:, g] = (start_time + (cut / rate) + t_centre, np.exp(mean_log), 1 / period,
                     delta / np.hypot(delta, 2 * np.pi))
    return Backbone(*out, method="peaks")


def spectral_peaks(signal, sample_rate: float, *, min_frequency: float = 0.0, max_frequency: float | None = None,
                   floor_db: float = 60.0, prominence_db: float = 15.0, window: str = "hann") -> np.ndarray:
    r"""Frequencies [Hz] of the peaks of a record's periodogram.

    ``P(f) = |FFT(w x)|^2`` of the whole record (``w`` the taper ``window``, bin
    ``sample_rate / k``); a peak is a local maximum of ``10 log10 P`` that stands
    ``prominence_db`` above its surroundings (:func:`scipy.signal.find_peaks`
    prominence) and lies less than ``floor_db`` below the highest peak in
    ``[min_frequency, max_frequency]``. Its frequency is refined by a parabola through
    the three bins around it (in dB).

    Parameters
    ----------
    signal : (k,) ndarray
    sample_rate : float
    min_frequency, max_frequency : float
        Search range [Hz]; default the whole band up to Nyquist.
    floor_db, prominence_db : float
        Positive thresholds [dB].
    window : str
        Taper, any name :func:`scipy.signal.get_window` knows ("hann", "boxcar", ...).

    Returns
    -------
    (p,) ndarray
        Peak frequencies, ascending.
    """
    x = _check_signal(signal)
    rate = _check_rate(sample_rate)
    nyquist = rate / 2
    max_frequency = nyquist if max_frequency is None else float(max_frequency)
    min_frequency = float(min_frequency)
    if not (0 <= min_frequency < max_frequency <= nyquist):
        raise FemromValueError(f"need 0 <= min_frequency < max_frequency <= Nyquist = {nyquist:g} Hz, "
                               f"got ({min_frequency:g}, {max_frequency:g})")
    if not (floor_db > 0 and prominence_db > 0):
        raise FemromValueError(f"floor_db and prominence_db must be positive, got {floor_db!r}, {prominence_db!r}")
    frequencies, power = signal_tools.periodogram(x, rate, window=window, detrend="constant")
    level = 10 * np.log10(np.maximum(power, np.finfo(float).tiny))
    found, _ = signal_tools.find_peaks(level, prominence=prominence_db)
    found = found[(frequencies[found] >= min_frequency) & (frequencies[found] <= max_frequency)
                  & (found > 0) & (found < level.size - 1)]
    if found.size == 0:
        return np.empty(0)
    found = found[level[found] >= level[found].max() - floor_db]
    lm, l0, lp = level[found - 1], level[found], level[found + 1]
    curvature = lm - 2 * l0 + lp
    shift = np.where(curvature < 0, 0.5 * (lm - lp) / np.where(curvature < 0, curvature, -1.0), 0.0)
    return np.sort(frequencies[found] + shift * (frequencies[1] - frequencies[0]))
