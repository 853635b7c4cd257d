r"""Stepped-sine forced response: the test engineer's sweep, run on a model.

For each force amplitude ``F`` (one *level*) the model starts at rest; then for each
frequency ``f_k`` of the sweep, in order, it is driven by ``F sin(2 pi f_k (t - t_k))``
from the state the previous frequency ended in (no restart, so a hysteretic joint or a
Duffing oscillator follows its branch and jumps where a test would), whole periods at a
time with ``N`` steps each, until the first-harmonic phasors of the outputs are steady
(:class:`SteadyStateCriterion`). The last period gives each output's amplitude and phase
relative to the force (:func:`first_harmonic`). The force is zero at every period
boundary, so it stays continuous when the frequency changes.

Time discretisation and prewarping
----------------------------------
Newmark average acceleration is the trapezoidal rule: at step ``h`` its periodic steady
state under ``F sin(omega t_n)`` is *exactly* the continuous one at the warped frequency
``Omega = (2 / h) tan(omega h / 2)`` (for a linear system of any size: ``Q = (K - Omega^2 M
+ i Omega C)^{-1} F``, ``A = -Omega^2 Q``), a relative shift ``tan(pi/N)/(pi/N) - 1 ~
pi^2 / (3 N^2)``: 2.0e-4 at ``N = 128``, i.e. 0.016 Hz at 80 Hz, an eighth of the
half-power bandwidth of a 0.13 %-damped mode. With ``prewarp`` (the default) the model is
driven where the scheme's own frequency map (:meth:`~femrom.integrators.Scheme.frequency`)
puts the requested frequency: for average acceleration at ``omega_s = omega (pi/N) /
tan(pi/N)`` with ``h = 2 pi / (N omega_s)``, so that ``Omega`` equals the requested ``omega``: a linear model's phasors are then exact up to the steady-
state tolerance for any ``N`` (bilinear-transform prewarping; Franklin, Powell & Workman,
*Digital Control of Dynamic Systems*, 3rd ed., sec. 6.3). For a nonlinear force the first
harmonic obeys the same harmonic balance at ``Omega`` (the force acts on the sampled
displacements); its higher harmonics ``h omega`` are warped by ``~ (h pi)^2 / (3 N^2)``.
``N = 128`` (the default) keeps the third harmonic within 0.2 % and resolves a stick-slip
transition to 1/128 of a period; without prewarping it is the frequency shift above that
sets ``N``.

Accelerations are the scheme's (``E a_n``, which balance the equation of motion at every
step), not ``-omega^2`` times the displacement phasor: for average acceleration the two
agree exactly at the prewarped frequency (``A = -Omega^2 Q``), and the scheme's are what
an accelerometer model of a nonlinear system should see, higher harmonics included.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from femrom._errors import FemromValueError
from femrom.integrators._march import march_batch
from femrom.integrators._newton import ConvergenceError
from femrom.integrators._steady_state import SteadyStateCriterion, first_harmonic

#: Key of the amplitude in :meth:`FrequencyResponse.rows`, by quantity (SI units assumed).
AMPLITUDE_KEYS = {"acceleration": "amplitude_m_s2", "displacement": "amplitude_m"}


class SteadyStateWarning(RuntimeWarning):
    """A frequency reached ``max_periods`` before its response was steady."""


def prewarped_frequency(frequency_hz, steps_per_period: int, scheme=None):
    r"""The frequency to drive a scheme at so that it responds as at ``frequency_hz``.

    A scheme steps a mode of frequency ``omega`` at ``Omega(omega h) / h`` (its
    :meth:`~femrom.integrators.Scheme.frequency`); driven at ``f_s`` with ``N`` steps a
    period (``Omega h = 2 pi / N``) a linear model responds as the continuous one at
    ``omega = continuous_frequency(2 pi / N, 1) N f_s``. Hence ``f_s = 2 pi f / (N
    continuous_frequency(2 pi / N, 1))``; for average acceleration (``scheme=None``, the
    trapezoidal rule) ``f_s = f (pi / N) / tan(pi / N)``. Float or ndarray alike.
    """
    N = int(steps_per_period)
    if scheme is None:
        x = math.pi / N
        return np.asarray(frequency_hz, dtype=float) * (x / math.tan(x))
    g = float(scheme.continuous_frequency(2.0 * math.pi / N, 1.0))
    return np.asarray(frequency_hz, dtype=float) * (2.0 * math.pi / (N * g))


def parabolic_peak(x, y) -> tuple[float, float, int, bool]:
    r"""The maximum of sampled ``y(x)``, refined by the parabola through the top three points.

    Returns ``(x_peak, y_peak, index, interpolated)``: ``index`` of the discrete maximum;
    when it is interior the vertex of the parabola through ``(x_{i-1}, x_i, x_{i+1})``
    (any spacing, either order), else the end point itself (``interpolated = False``).
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    i = int(np.argmax(y))
    if i == 0 or i == y.size - 1:
        return float(x[i]), float(y[i]), i, False
    xs, ys = x[i - 1:i + 2] - x[i], y[i - 1:i + 2]
    a, b, c = np.polyfit(xs, ys, 2)
    if not a < 0:  # three collinear points with a flat top: keep the sample
        return float(x[i]), float(y[i]), i, False
    return float(x[i] - b / (2 * a)), float(c - b * b / (4 * a)), i, True


@dataclass(frozen=True)
class Peak:
    """The resonance peak of one output at one force level.

    Attributes
    ----------
    output : str
    frequency_hz, amplitude : float
        Parabolic interpolation around the discrete maximum (the sample itself at an end).
    index : int
        Index of the discrete maximum in the sweep.
    interpolated : bool
        Whether the maximum was interior (if not, the sweep may have missed the peak).

    At a jump (a hardening Duffing stepped up) the response drops off a cliff after the
    maximum and the parabola is no peak shape: read the discrete maximum ``index`` there.
    """

    output: str
    frequency_hz: float
    amplitude: float
    index: int
    interpolated: bool


@dataclass(frozen=True, eq=False)
class FrequencyResponse:
    r"""One force level of a stepped sine: the phasors of p outputs at k frequencies.

    Attributes
    ----------
    force_n : float
        Force amplitude ``F``.
    frequencies_hz : (k,) ndarray
        In sweep order.
    phasors : (p, k) complex ndarray
        ``Y``: output ``~ |Y| sin(omega t + arg Y)`` for the force ``F sin(omega t)``.
    output_names : tuple of str
    quantity : str
        ``"acceleration"`` or ``"displacement"``.
    periods : (k,) int ndarray
        Periods run at each frequency.
    converged : (k,) bool ndarray
        Whether each frequency met the steady-state criterion before the cap.
    remaining : (k,) ndarray
        Estimated relative transient left in the reported phasors.
    """

    force_n: float
    frequencies_hz: np.ndarray
    phasors: np.ndarray
    output_names: tuple
    quantity: str
    periods: np.ndarray
    converged: np.ndarray
    remaining: np.ndarray

    @property
    def amplitude(self) -> np.ndarray:
        """(p, k) ndarray ``|Y|``."""
        return np.abs(self.phasors)

    @property
    def phase_rad(self) -> np.ndarray:
        """(p, k) ndarray ``arg Y`` in (-pi, pi], relative to the force."""
        return np.angle(self.phasors)

    @property
    def receptance(self) -> np.ndarray:
        """(p, k) complex ndarray ``Y / F``: the first-harmonic frequency response."""
        return self.phasors / self.force_n

    def peaks(self) -> tuple[Peak, ...]:
        """Per output, the :class:`Peak` (parabolic interpolation around the discrete maximum)."""
        return tuple(Peak(name, *parabolic_peak(self.frequencies_hz, amplitude))
                     for name, amplitude in zip(self.output_names, self.amplitude))

    def rows(self) -> dict:
        """A JSON-ready dict: ``force_n``, per output ``[{frequency_hz, amplitude_*, phase_rad}]``,
        the peaks, and the steady-state bookkeeping."""
        key = AMPLITUDE_KEYS[self.quantity]
        amplitude, phase = self.amplitude, self.phase_rad
        outputs = {name: [{"frequency_hz": float(f), key: float(a), "phase_rad": float(ph)}
                          for f, a, ph in zip(self.frequencies_hz, amplitude[i], phase[i])]
                   for i, name in enumerate(self.output_names)}
        peaks = {p.output: {"frequency_hz": p.frequency_hz, key: p.amplitude, "interpolated": p.interpolated}
                 for p in self.peaks()}
        return {"force_n": float(self.force_n), "quantity": self.quantity, "outputs": outputs,
                "peaks": peaks, "all_converged": bool(np.all(self.converged)),
                "periods": [int(n) for n in self.periods]}


@dataclass(frozen=True, eq=False)
class SteppedSineResult:
    """All force levels of a stepped sine and how they were run.

    Attributes
    ----------
    levels : tuple of FrequencyResponse
        One per force amplitude, in the order given.
    steps_per_period : int
    prewarp : bool
    criterion : SteadyStateCriterion
    direction : str
        ``"up"`` or ``"down"`` (``"single"`` for one frequency).
    """

    levels: tuple
    steps_per_period: int
    prewarp: bool
    criterion: SteadyStateCriterion
    direction: str

    @property
    def all_converged(self) -> bool:
        return all(bool(np.all(level.converged)) for level in self.levels)

    def rows(self) -> list[dict]:
        """One :meth:`FrequencyResponse.rows` per level, each with the sweep settings."""
        settings = {"steps_per_period": self.steps_per_period, "prewarp": self.prewarp,
                    "direction": self.direction, "steady_state_tolerance": self.criterion.tolerance,
                    "max_periods": self.criterion.max_periods}
        return [{**level.rows(), **settings} for level in self.levels]


def _frequencies(values) -> tuple[float, ...]:
    try:
        f = np.asarray(values, dtype=float).ravel()
    except (TypeError, ValueError):
        raise FemromValueError(f"frequencies_hz must be numbers, got {values!r}") from None
    if f.size == 0 or not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise FemromValueError(f"frequencies_hz must be a non-empty list of positive finite numbers, got {values!r}")
    steps = np.diff(f)
    if f.size > 1 and not (np.all(steps > 0) or np.all(steps < 0)):
        raise FemromValueError("frequencies_hz must be strictly increasing (step up) or strictly decreasing "
                         "(step down)")
    return tuple(float(x) for x in f)


def _force_amplitudes(values) -> tuple[float, ...]:
    try:
        F = np.atleast_1d(np.asarray(values, dtype=float)).ravel()
    except (TypeError, ValueError):
        raise FemromValueError(f"force_amplitudes must be numbers, got {values!r}") from None
    if F.size == 0 or not np.all(np.isfinite(F)) or np.any(F <= 0):
        raise FemromValueError(f"force_amplitudes must be positive finite numbers, got {values!r}")
    return tuple(float(x) for x in F)



class _LevelRecord:
    """One force level's steady states as a stepped sine goes through its frequencies: each frequency's
    phasors, periods, convergence and estimated transient, a warning where it did not settle."""

    def __init__(self):
        self.columns, self.periods, self.converged, self.remaining = [], [], [], []

    def add(self, monitor, F: float, f: float, criterion, progress) -> None:
        self.columns.append(monitor.phasors)
        self.periods.append(monitor.periods)
        self.converged.append(monitor.converged)
        self.remaining.append(monitor.remaining)
        if not monitor.converged:
            warnings.warn(f"stepped sine F = {F:g}, f = {f:g} Hz: not steady after "
                          f"{monitor.periods} periods (estimated transient left "
                          f"{monitor.remaining:.2e} > tolerance {criterion.tolerance:g})",
                          SteadyStateWarning, stacklevel=3)
        if progress is not None:
            amplitude = float(np.max(np.abs(monitor.phasors)))
            status = "steady" if monitor.converged else "NOT STEADY"
            progress(f"F = {F:g} N  f = {f:.4f} Hz  periods = {monitor.periods:4d}  {status}  "
                     f"max |Y| = {amplitude:.4g}")

    def response(self, F: float, frequencies_hz, plant) -> "FrequencyResponse":
        return FrequencyResponse(
            force_n=F, frequencies_hz=np.asarray(frequencies_hz), phasors=np.column_stack(self.columns),
            output_names=tuple(plant.output_names), quantity=plant.quantity,
            periods=np.asarray(self.periods, dtype=int), converged=np.asarray(self.converged, dtype=bool),
            remaining=np.asarray(self.remaining, dtype=float))

@dataclass(frozen=True)
class SteppedSine:
    r"""A stepped-sine sweep: frequencies, steps per period, steady-state criterion, prewarping.

    Attributes
    ----------
    frequencies_hz : sequence of float
        Strictly increasing (step up) or decreasing (step down).
    steps_per_period : int
        ``N >= 16`` steps per forcing period (see the module docstring for the choice of 128).
    steady_state : SteadyStateCriterion
    prewarp : bool
        Drive at ``f (pi/N) / tan(pi/N)`` so that average acceleration responds as at ``f``
        (:func:`prewarped_frequency` with the shaker's scheme).

    Examples
    --------
    >>> sweep = SteppedSine(np.arange(79.0, 81.5 + 1e-9, 0.05))          # doctest: +SKIP
    >>> result = sweep.run(Shaker(model, shaker), [0.2, 0.5, 1.5])  # doctest: +SKIP
    >>> metrics["forced_response"] = result.rows()                        # doctest: +SKIP
    """

    frequencies_hz: Sequence[float]
    steps_per_period: int = 128
    steady_state: SteadyStateCriterion = field(default_factory=SteadyStateCriterion)
    prewarp: bool = True

    def __post_init__(self):
        object.__setattr__(self, "frequencies_hz", _frequencies(self.frequencies_hz))
        N = self.steps_per_period
        if not (isinstance(N, (int, np.integer)) and not isinstance(N, bool) and N >= 16):
            raise FemromValueError(f"steps_per_period must be an integer >= 16, got {N!r}")
        if not isinstance(self.steady_state, SteadyStateCriterion):
            raise FemromValueError(f"steady_state must be a SteadyStateCriterion, got {type(self.steady_state).__name__}")

    @property
    def direction(self) -> str:
        f = self.frequencies_hz
        return "single" if len(f) == 1 else ("up" if f[1] > f[0] else "down")

    def run(self, plant, force_amplitudes, *, progress: Callable[[str], None] | None = None
            ) -> SteppedSineResult:
        """Sweep every force level, each from rest; see the module docstring.

        Parameters
        ----------
        plant : Shaker
            Or any object with its ``periods``, ``reset``, ``output_names``, ``quantity`` and
            ``scheme`` (:mod:`._shaker`).
        force_amplitudes : float or sequence of float
            ``F > 0`` per level.
        progress : callable, optional
            Called with one line per frequency (level, frequency, periods, status, amplitude).

        Returns
        -------
        SteppedSineResult

        Warns
        -----
        SteadyStateWarning
            For each frequency that reached ``steady_state.max_periods`` unsettled
            (its ``converged`` entry is False; the last period is still reported).
        """
        amplitudes = _force_amplitudes(force_amplitudes)
        scheme = getattr(plant, "scheme", None)
        if self.prewarp and not hasattr(scheme, "continuous_frequency"):
            raise FemromValueError("prewarp=True needs a plant whose scheme has a frequency map (plant.scheme); "
                                   "pass prewarp=False")
        N, criterion = int(self.steps_per_period), self.steady_state
        driven = (prewarped_frequency(self.frequencies_hz, N, scheme) if self.prewarp
                  else np.asarray(self.frequencies_hz))
        levels = []
        for F in amplitudes:
            plant.reset()
            record = _LevelRecord()
            for f, f_drive in zip(self.frequencies_hz, driven):
                monitor = criterion.monitor()
                for samples in plant.periods(F, float(f_drive), N, criterion.max_periods):
                    if monitor.update(first_harmonic(samples)):
                        break
                record.add(monitor, F, f, criterion, progress)
            levels.append(record.response(F, self.frequencies_hz, plant))
        return SteppedSineResult(levels=tuple(levels), steps_per_period=N, prewarp=bool(self.prewarp),
                                 criterion=criterion, direction=self.direction)

    def run_batched(self, plant, force_amplitudes, *, progress: Callable[[str], None] | None = None
                    ) -> SteppedSineResult:
        """:meth:`run` with all force levels stepped together: the same result, levels as a batch.

        Every level marches on its own branch exactly as in :meth:`run` (from the plant's rest, a
        period at a time, each frequency until that level is steady or reaches ``max_periods``, the
        next frequency from where it stopped), but each period of all the levels still running at a
        frequency is one :func:`~femrom.integrators.march_batch` call: on a reduced model with a
        compiled joint, one compiled call for all their steps. A level that is steady waits at the
        end of its period while the others go on. Warnings and progress lines come frequency by
        frequency (all levels), not level by level; the plant's own state is left as it was.

        Parameters
        ----------
        plant : Shaker
            (its ``system``, ``scheme``, ``quantity``, ``rest`` and ``solver``).
        force_amplitudes, progress
            As for :meth:`run`.
        """
        amplitudes = _force_amplitudes(force_amplitudes)
        scheme = plant.scheme
        if self.prewarp and not hasattr(scheme, "continuous_frequency"):
            raise FemromValueError("prewarp=True needs a plant whose scheme has a frequency map (plant.scheme); "
                                   "pass prewarp=False")
        N, criterion = int(self.steps_per_period), self.steady_state
        driven = (prewarped_frequency(self.frequencies_hz, N, scheme) if self.prewarp
                  else np.asarray(self.frequencies_hz))
        system, rest = plant.system, plant.rest
        n, L = system.n_dofs, len(amplitudes)
        E = system.output_matrix
        field_ = "a" if plant.quantity == "acceleration" else "q"
        q = np.zeros((L, n)) if rest is None else np.tile(rest.q, (L, 1))
        v = np.zeros((L, n)) if rest is None else np.tile(rest.v, (L, 1))
        a = None if rest is None or rest.a is None else np.tile(rest.a, (L, 1))
        if system.nonlinear is None:
            states = [None] * L
        else:
            start = system.nonlinear.initial_state() if rest is None or rest.state is None else rest.state
            states = [np.array(start) if isinstance(start, np.ndarray) else start for _ in range(L)]
        F = np.asarray(amplitudes)
        results = [_LevelRecord() for _ in range(L)]
        for f, f_drive in zip(self.frequencies_hz, driven):
            dt = 1.0 / (float(f_drive) * N)
            sines = np.sin(2.0 * np.pi * np.arange(1, N + 1) / N)
            monitors = [criterion.monitor() for _ in range(L)]
            active = list(range(L))
            while active:
                U = np.zeros((len(active), 1, N + 1))
                for j, i in enumerate(active):
                    U[j, 0, 1:] = float(F[i]) * sines
                batch_states = (np.array([states[i] for i in active]) if isinstance(states[0], np.ndarray)
                                else [states[i] for i in active])
                try:                  # the grid from 0 so that its step is dt itself, as the shaker's
                    out = march_batch(system, scheme, dt * np.arange(N + 1), q[active], v[active], inputs=U,
                                      state0=batch_states, a0=None if a is None else a[active], solver=plant.solver)
                except ConvergenceError as err:
                    raise ConvergenceError(f"stepped sine at f = {f:g} Hz, levels {F[active].tolist()} "
                                           f"(run = index among them; t from the period's start): {err}") from None
                if a is None:
                    a = np.empty((L, n))
                still = []
                for j, i in enumerate(active):
                    q[i], v[i], a[i] = out["q"][j, :, -1], out["v"][j, :, -1], out["a"][j, :, -1]
                    if system.nonlinear is not None:
                        states[i] = out["state"][j]
                    samples = np.asarray(E @ out[field_][j, :, 1:])
                    monitor = monitors[i]
                    if not monitor.update(first_harmonic(samples)) and monitor.periods < criterion.max_periods:
                        still.append(i)
                active = still
            for i, monitor in enumerate(monitors):
                results[i].add(monitor, float(F[i]), f, criterion, progress)
        levels = tuple(record.response(float(F[i]), self.frequencies_hz, plant) for i, record in enumerate(results))
        return SteppedSineResult(levels=levels, steps_per_period=N, prewarp=bool(self.prewarp),
                                 criterion=criterion, direction=self.direction)
