"""Consumers of a run: each keeps only what it was asked for.

A consumer is called with every :class:`StepResult` and may have ``close()``.
Values are gathered in lists and stacked into arrays when read, so nothing is
stored that was not requested (``Trajectory(fields=("q",))`` holds no
velocities; ``OutputRecorder`` holds ``p`` numbers per kept step, not ``n``).
"""

from __future__ import annotations

import time

import numpy as np

from femrom._errors import FemromValueError

_FIELDS = ("q", "v", "a")


def _check_every(every: int) -> int:
    every = int(every)
    if every < 1:
        raise FemromValueError(f"every must be >= 1, got {every}")
    return every


class Trajectory:
    """Full states every ``every`` steps, as (n, k) arrays ``q``, ``v``, ``a``.

    Parameters
    ----------
    every : int
        Keep steps whose index is a multiple of ``every`` (step 0 included).
    fields : tuple of str
        Which of ``"q"``, ``"v"``, ``"a"`` to keep.

    Attributes
    ----------
    t : (k,) ndarray
        Times of the kept steps.
    steps : (k,) int ndarray
        Their indices.
    q, v, a : (n, k) ndarray
        The kept fields (only those in ``fields``).
    """

    def __init__(self, every: int = 1, fields: tuple[str, ...] = _FIELDS):
        unknown = [f for f in fields if f not in _FIELDS]
        if unknown or not fields:
            raise FemromValueError(f"unknown trajectory fields {unknown}; valid: {', '.join(_FIELDS)}")
        self.every = _check_every(every)
        self.fields = tuple(fields)
        self._t: list[float] = []
        self._steps: list[int] = []
        self._columns: dict[str, list[np.ndarray]] = {f: [] for f in self.fields}

    def __call__(self, result) -> None:
        if result.step % self.every:
            return
        for name in self.fields:
            value = getattr(result, name)
            if value is None:
                raise FemromValueError(f"step {result.step} has no {name!r} (e.g. ImplicitMidpoint "
                                 "with accelerations=False); drop it from fields")
            self._columns[name].append(value)  # read-only arrays: no copy needed
        self._t.append(result.t)
        self._steps.append(result.step)

    def __len__(self) -> int:
        return len(self._t)

    @property
    def t(self) -> np.ndarray:
        return np.asarray(self._t, dtype=float)

    @property
    def steps(self) -> np.ndarray:
        return np.asarray(self._steps, dtype=int)

    def _stack(self, name: str) -> np.ndarray:
        if name not in self._columns:
            raise AttributeError(f"this trajectory keeps {self.fields}, not {name!r}")
        columns = self._columns[name]
        if not columns:
            return np.empty((0, 0))
        return np.column_stack(columns)

    @property
    def q(self) -> np.ndarray:
        return self._stack("q")

    @property
    def v(self) -> np.ndarray:
        return self._stack("v")

    @property
    def a(self) -> np.ndarray:
        return self._stack("a")


class OutputRecorder:
    """Outputs ``y = E q`` every ``every`` steps: (p, k) ``outputs`` and (k,) ``t``.

    Parameters
    ----------
    system : SecondOrderSystem
        Must have an ``output_matrix``.
    every : int
        Keep steps whose index is a multiple of ``every``.
    """

    def __init__(self, system, every: int = 1):
        if system.output_matrix is None:
            raise FemromValueError("system has no outputs (output_matrix is None)")
        self.system = system
        self.every = _check_every(every)
        self.names = tuple(system.output_names)
        self._t: list[float] = []
        self._y: list[np.ndarray] = []

    def __call__(self, result) -> None:
        if result.step % self.every == 0:
            self._t.append(result.t)
            self._y.append(np.asarray(self.system.outputs(result.q)).ravel())

    def __len__(self) -> int:
        return len(self._t)

    @property
    def t(self) -> np.ndarray:
        return np.asarray(self._t, dtype=float)

    @property
    def outputs(self) -> np.ndarray:
        if not self._y:
            return np.empty((self.system.n_outputs, 0))
        return np.column_stack(self._y)


class EnergyRecorder:
    """Kinetic, potential and total energy every ``every`` steps, as (k,) arrays.

    ``kinetic = v^T M v / 2``, ``potential = q^T K q / 2 + U_nl(q)``,
    ``total = kinetic + potential`` (needs a conservative nonlinear force).
    """

    def __init__(self, system, every: int = 1):
        nl = system.nonlinear
        if nl is not None and not nl.conservative:
            raise FemromValueError(f"{type(nl).__name__} is not conservative: the system has no "
                             "potential energy to record")
        self.system = system
        self.every = _check_every(every)
        self._t: list[float] = []
        self._kinetic: list[float] = []
        self._potential: list[float] = []

    def __call__(self, result) -> None:
        if result.step % self.every == 0:
            self._t.append(result.t)
            self._kinetic.append(self.system.kinetic_energy(result.v))
            self._potential.append(self.system.potential_energy(result.q))

    def __len__(self) -> int:
        return len(self._t)

    @property
    def t(self) -> np.ndarray:
        return np.asarray(self._t, dtype=float)

    @property
    def kinetic(self) -> np.ndarray:
        return np.asarray(self._kinetic, dtype=float)

    @property
    def potential(self) -> np.ndarray:
        return np.asarray(self._potential, dtype=float)

    @property
    def total(self) -> np.ndarray:
        return self.kinetic + self.potential


class StepClock:
    """Wall time of each step, the consumers' work excluded.

    :func:`~femrom.integrators.simulate` (``clock=``) hands :attr:`arrival` the
    step before any other consumer and :attr:`departure` after all of them, so
    step ``k + 1`` took ``arrival[k + 1] - departure[k]``: the scheme's work only,
    not recording outputs and energy or streaming fields to a store.
    """

    def __init__(self):
        self._arrivals: list[float] = []
        self._departures: list[float] = []

    def arrival(self, result) -> None:
        self._arrivals.append(time.perf_counter())

    def departure(self, result) -> None:
        self._departures.append(time.perf_counter())

    @property
    def step_seconds(self) -> np.ndarray:
        """(n_steps,) ndarray: the wall time of steps 1, 2, ..."""
        a, d = np.asarray(self._arrivals), np.asarray(self._departures)
        n = min(a.size - 1, d.size)
        return a[1:n + 1] - d[:n]
