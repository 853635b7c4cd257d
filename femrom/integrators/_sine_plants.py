r"""What a stepped-sine test drives: a model advanced whole forcing periods at a time.

A *plant* holds the state of one run between frequencies (the test engineer's stepped
sine never restarts: a hysteretic joint follows its branch) and has

- ``output_names`` (tuple of p str) and ``quantity`` (``"acceleration"`` or ``"displacement"``);
- ``tustin`` (bool): its scheme maps frequencies like the trapezoidal rule (Newmark
  average acceleration), so :class:`~femrom.integrators.SteppedSine` may prewarp;
- ``reset()``: back to rest (``q = v = 0``, the nonlinear state initial);
- ``periods(amplitude, frequency_hz, steps_per_period, max_periods)``: an iterator that
  drives ``F sin(2 pi f (t - t_0))`` from the current time ``t_0`` with
  ``dt = 1 / (f N)`` and yields each whole period's (p, N) output samples at steps
  ``1 .. N``; the plant's state is the end of the last period handed out.

Two plants are here: :class:`SystemPlant` (a :class:`~femrom.scene.SecondOrderSystem`
stepped by :func:`~femrom.integrators.iterate` with any scheme and nonlinear force, stateful
ones included) and :class:`StepperPlant` (any reduced model with
``stepper(q0, v0, dt=, t0=, u0=, scheme=)``, e.g. :class:`~femrom.rom.SecondOrderROM`,
duck-typed so that this layer imports nothing above it).
"""

from __future__ import annotations

import dataclasses
from typing import Iterator

import numpy as np

from femrom._errors import FemromValueError
from femrom.integrators._driver import StepResult, iterate
from femrom.integrators.schemes.newmark import Newmark
from femrom.scene import Signal, SignalVector

QUANTITIES = ("acceleration", "displacement")


def _quantity(quantity: str) -> str:
    if quantity not in QUANTITIES:
        raise FemromValueError(f"quantity must be one of {', '.join(QUANTITIES)}, got {quantity!r}")
    return quantity


def _sine(amplitude: float, frequency_hz: float, start: float) -> SignalVector:
    """``u(t) = [F sin(2 pi f (t - start))]`` (zero before ``start``): a scene's ``sine`` signal."""
    return SignalVector([Signal.from_dict({"kind": "sine", "amplitude": float(amplitude),
                                           "frequency": float(frequency_hz), "phase": 0.0,
                                           "start": float(start)})])


class SystemPlant:
    r"""A :class:`~femrom.scene.SecondOrderSystem` shaken by ``F sin(omega t) f_hat``.

    The system's own inputs are replaced by the one harmonic input ``f_hat``; its
    constant load ``f_0`` (a bolt preload) and its nonlinear forces stay. Outputs are
    ``E a`` (the scheme's accelerations, which balance the equation of motion at every
    step) or ``E q``.

    Parameters
    ----------
    system : SecondOrderSystem
        With an ``output_matrix`` (the accelerometers).
    force_vector : (n,) array_like
        ``f_hat``: where the unit force acts (e.g. a column of ``system.input_matrix``,
        or :func:`~femrom.fem.point_load` at the shaker attachment).
    scheme : optional
        A scheme of :mod:`femrom.integrators` (default ``Newmark()``, average acceleration).
    solver : str or callable
        Linear-solver strategy or factory, as in :func:`~femrom.integrators.iterate`.
    quantity : {"acceleration", "displacement"}
    rest : StepResult, optional
        The state each force level starts from (default zero ``q``, ``v``, ``a`` and the
        force's initial state): a preloaded equilibrium with its committed joint state,
        at ``t = 0`` with zero acceleration.
    """

    def __init__(self, system, force_vector, *, scheme=None, solver="auto", quantity: str = "acceleration",
                 rest: StepResult | None = None):
        if system.output_matrix is None:
            raise FemromValueError("system has no outputs (output_matrix is None): "
                             "a stepped sine reports outputs such as accelerometers")
        n = system.n_dofs
        f_hat = np.asarray(force_vector.toarray() if hasattr(force_vector, "toarray") else force_vector,
                           dtype=float).ravel()
        if f_hat.shape != (n,) or not np.all(np.isfinite(f_hat)) or not np.any(f_hat):
            raise FemromValueError(f"force_vector must be a finite, nonzero ({n},) vector, got shape {f_hat.shape}")
        self.system = system
        self.force_vector = f_hat
        self.scheme = Newmark() if scheme is None else scheme
        self.solver = solver
        self.quantity = _quantity(quantity)
        self.output_names = tuple(system.output_names) or tuple(f"y{i}" for i in range(system.n_outputs))
        if rest is not None and (rest.q.shape != (n,) or rest.t != 0.0):
            raise FemromValueError(f"rest must be a StepResult at t = 0 on the system's {n} dofs")
        self.rest = rest
        self._last: StepResult | None = rest

    @property
    def tustin(self) -> bool:
        """Whether the scheme is Newmark average acceleration (the trapezoidal frequency map)."""
        return (isinstance(self.scheme, Newmark) and self.scheme.beta == 0.25 and self.scheme.gamma == 0.5)

    @property
    def last(self) -> StepResult | None:
        """The state at the end of the last period handed out (``None`` at rest)."""
        return self._last

    def reset(self) -> None:
        self._last = self.rest

    def periods(self, amplitude: float, frequency_hz: float, steps_per_period: int,
                max_periods: int) -> Iterator[np.ndarray]:
        N = int(steps_per_period)
        dt = 1.0 / (float(frequency_hz) * N)
        t0 = 0.0 if self._last is None else self._last.t
        driven = dataclasses.replace(self.system, input_matrix=self.force_vector[:, None],
                                     inputs=_sine(amplitude, frequency_hz, t0))
        n = self.system.n_dofs
        if self._last is None:
            run = iterate(driven, self.scheme, np.zeros(n), np.zeros(n), dt, N * max_periods, t0=t0,
                          solver=self.solver, progress=False)
            next(run)  # step 0, the rest state
        else:
            # the force is zero at a period's end and at the next one's start: the
            # stored acceleration stays consistent across the change of frequency
            run = iterate(driven, self.scheme, None, None, dt, N * max_periods, solver=self.solver,
                          progress=False, start=self._last)
        E = self.system.output_matrix
        use_acceleration = self.quantity == "acceleration"
        for _ in range(max_periods):
            columns = []
            for _ in range(N):
                result = next(run)
                x = result.a if use_acceleration else result.q
                if x is None:
                    raise FemromValueError(f"scheme {getattr(self.scheme, 'name', self.scheme)!r} gives no "
                                     "accelerations: use quantity='displacement'")
                columns.append(x)
            self._last = result
            yield np.asarray(E @ np.column_stack(columns))


class StepperPlant:
    r"""A reduced model with a ``stepper`` (e.g. :class:`~femrom.rom.SecondOrderROM`), shaken
    through one of its inputs: ``u = F sin(omega t) e_j``.

    A stepper is made per frequency (its ``dt`` changes) at the previous period's end
    ``(q, v)``; a nonlinear model's committed state and acceleration are carried over
    into it (the attributes ``state`` and ``a`` a :class:`~femrom.rom.ReducedStepper`
    documents). Outputs are ``E^ a`` or ``E^ q`` (``a`` or ``q`` without an output map).

    Parameters
    ----------
    model : object with ``stepper(dt, *, initial, t0, u0, scheme)``
    input_index : int
        The input ``j`` that is the shaker force.
    scheme : str
        Reduced scheme name (``"newmark"``, average acceleration, is the one that may prewarp).
    quantity : {"acceleration", "displacement"}
    output_names : sequence of str, optional
        Default ``model.output_names`` if it has them, else ``y0, y1, ...``.
    """

    def __init__(self, model, input_index: int = 0, *, scheme: str = "newmark",
                 quantity: str = "acceleration", output_names=None):
        if not callable(getattr(model, "stepper", None)):
            raise FemromValueError(f"model must have a stepper(dt, initial=, t0=, u0=, scheme=) method; "
                             f"got a {type(model).__name__}")
        self.model, self.scheme = model, str(scheme)
        self.quantity = _quantity(quantity)
        probe = model.stepper(1.0, scheme=self.scheme)
        m = 0 if probe.input_matrix is None else probe.input_matrix.shape[1]
        if not (isinstance(input_index, (int, np.integer)) and 0 <= input_index < m):
            raise FemromValueError(f"input_index must be an integer in [0, {m}), got {input_index!r}")
        if self.quantity == "acceleration" and probe.a is None:
            raise FemromValueError(f"scheme {self.scheme!r} carries no acceleration: use quantity='displacement'")
        self.input_index, self.n_inputs = int(input_index), m
        p = probe.outputs.size
        names = output_names if output_names is not None else getattr(model, "output_names", None)
        self.output_names = tuple(names) if names else tuple(f"y{i}" for i in range(p))
        if len(self.output_names) != p:
            raise FemromValueError(f"output_names has {len(self.output_names)} names for {p} outputs")
        self._r = probe.q.size
        self.reset()

    @property
    def tustin(self) -> bool:
        return self.scheme == "newmark"

    def reset(self) -> None:
        self._t, self._q, self._v = 0.0, np.zeros(self._r), np.zeros(self._r)
        self._a = self._state = None

    def periods(self, amplitude: float, frequency_hz: float, steps_per_period: int,
                max_periods: int) -> Iterator[np.ndarray]:
        N = int(steps_per_period)
        dt = 1.0 / (float(frequency_hz) * N)
        u_zero = np.zeros(self.n_inputs)
        start = StepResult(step=0, t=self._t, q=self._q, v=self._v, a=self._a, state=self._state)
        stepper = self.model.stepper(dt, initial=start, t0=self._t, u0=u_zero, scheme=self.scheme)
        sines = float(amplitude) * np.sin(2.0 * np.pi * np.arange(1, N + 1) / N)
        u = u_zero.copy()
        E = stepper.output_matrix
        for _ in range(max_periods):
            samples = np.empty((len(self.output_names), N))
            for j in range(N):
                u[self.input_index] = sines[j]
                y = stepper.step(u)
                if self.quantity == "acceleration":
                    y = stepper.a if E is None else E @ stepper.a
                samples[:, j] = y
            self._t, self._q, self._v = stepper.t, stepper.q.copy(), stepper.v.copy()
            self._a = None if stepper.a is None else np.array(stepper.a)
            self._state = stepper.state
            yield samples
