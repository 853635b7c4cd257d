r"""What a closed loop drives: a *plant* is anything with

- ``step(u) -> y``: advance one sample with the input ``u_{k+1}`` (m,) at the new
  time and return the outputs ``y_{k+1}`` (p,) there (the stepper convention of
  :class:`~femrom.rom.StateSpaceStepper` and :class:`~femrom.rom.ReducedStepper`);
- ``output``: (p,) the outputs at the current sample (``y_0`` before any step).

The controller sees only these outputs. Three adapters:

- :class:`StateSpacePlant`: a :class:`~femrom.rom.DiscreteStateSpace` (a ROM's
  or an identified model; the plant of tests and of "ROM on ROM" loops);
- :class:`ReducedPlant`: a reduced model's own stepper (``model.stepper(...)``,
  any scheme, nonlinear terms included);
- :class:`FullOrderPlant`: a :class:`~femrom.scene.SecondOrderSystem` stepped by its
  own integrator (:func:`~femrom.integrators.iterate`, any scheme, Newton for a
  nonlinear force): the FOM as the plant.

Between two samples the full-order plant's input is the straight line from
``u_k`` to ``u_{k+1}`` (what a scheme that evaluates the force mid-step sees),
the same piecewise-linear input with which a ROM's ``predict`` and
``to_state_space`` treat sampled inputs.
"""

from __future__ import annotations

import dataclasses
from typing import Protocol, runtime_checkable

import numpy as np

from femrom._errors import FemromValueError
from femrom.control._problem import vector
from femrom.integrators import Newmark, iterate
from femrom.rom import DiscreteStateSpace


@runtime_checkable
class Plant(Protocol):
    """``step(u) -> y`` and ``output`` (module docstring)."""

    @property
    def output(self) -> np.ndarray: ...

    def step(self, u) -> np.ndarray: ...


class StateSpacePlant:
    """A :class:`~femrom.rom.DiscreteStateSpace` as a plant.

    Parameters
    ----------
    model : DiscreteStateSpace
    initial_state : (n,) array_like, optional
        ``z_0`` (zeros by default).
    u0 : (m,) array_like, optional
        The input sample at ``t_0`` (zeros by default).

    Attributes
    ----------
    state : (n,) ndarray
        The current ``z_k``.
    """

    def __init__(self, model: DiscreteStateSpace, initial_state=None, u0=None):
        if not isinstance(model, DiscreteStateSpace):
            raise FemromValueError(f"model must be a DiscreteStateSpace, got a {type(model).__name__}")
        self.model = model
        self.n_inputs, self.n_outputs = model.n_inputs, model.n_outputs
        self._stepper = model.stepper(initial=vector(initial_state, model.n_states, "initial_state"),
                                      u0=vector(u0, model.n_inputs, "u0"))

    @property
    def state(self) -> np.ndarray:
        return self._stepper.z.copy()

    @property
    def output(self) -> np.ndarray:
        return self._stepper.output

    def step(self, u) -> np.ndarray:
        return self._stepper.step(vector(u, self.n_inputs, "u"))


class ReducedPlant:
    """A reduced model stepped one sample at a time through its own ``stepper``.

    Parameters
    ----------
    model : object with ``stepper(q0, v0, *, dt, u0, scheme)``
        E.g. a :class:`~femrom.rom.SecondOrderROM` (linear or not).
    dt : float
    q0, v0 : array_like, optional
        Initial reduced (or full) displacements and velocities (zeros by default).
    u0 : (m,) array_like, optional
    scheme : str
        A registered reduced scheme.
    """

    def __init__(self, model, dt: float, *, q0=None, v0=None, u0=None, scheme: str = "newmark"):
        if not callable(getattr(model, "stepper", None)):
            raise FemromValueError(f"model must have a stepper(dt, initial=, u0=, scheme=) method; "
                                   f"got a {type(model).__name__}")
        initial = None if q0 is None and v0 is None else (q0, v0)
        if initial is not None and q0 is None:
            initial = (np.zeros_like(np.asarray(v0, dtype=float)), v0)
        elif initial is not None and v0 is None:
            initial = q0
        self.stepper = model.stepper(float(dt), initial=initial, u0=u0, scheme=scheme)
        B = self.stepper.input_matrix
        self.n_inputs = 0 if B is None else B.shape[1]
        self.n_outputs = self.output.size

    @property
    def output(self) -> np.ndarray:
        return np.asarray(self.stepper.outputs, dtype=float)

    def step(self, u) -> np.ndarray:
        return np.asarray(self.stepper.step(vector(u, self.n_inputs, "u")), dtype=float)


class _SampledInput:
    """``u(t)`` on ``[t_k, t_{k+1}]``: the straight line between the last two samples."""

    def __init__(self, t: float, u: np.ndarray):
        self.t0, self.t1, self.u0, self.u1 = t, t, u, u

    def advance(self, t: float, u: np.ndarray) -> None:
        self.t0, self.u0 = self.t1, self.u1
        self.t1, self.u1 = t, u

    def __call__(self, t) -> np.ndarray:
        if self.t1 <= self.t0:
            return self.u1
        s = min(max((float(t) - self.t0) / (self.t1 - self.t0), 0.0), 1.0)
        return (1.0 - s) * self.u0 + s * self.u1


class FullOrderPlant:
    r"""A :class:`~femrom.scene.SecondOrderSystem` stepped by its own integrator, one sample at a time.

    The system's inputs (its ``input_matrix`` columns) are driven by the
    controller's samples, linear in between (module docstring); its constant
    load and nonlinear forces stay. The outputs are ``y = E q`` (the system's
    ``output_matrix``), the displacement outputs a ROM's ``to_state_space`` has.
    One factorisation for a linear system, reused every step.

    Parameters
    ----------
    system : SecondOrderSystem
        With ``input_matrix`` and ``output_matrix``.
    dt : float
        The controller's sampling time.
    scheme : optional
        A full-order scheme (default ``Newmark()``, average acceleration).
    q0, v0 : (n,) array_like, optional
        Initial state (zeros by default).
    u0 : (m,) array_like, optional
        The input sample at ``t_0 = 0``.
    solver : str or callable
        Linear-solver strategy, as in :func:`~femrom.integrators.iterate`.

    Attributes
    ----------
    last : StepResult
        The current state (``q``, ``v``, ``a``, the nonlinear state).
    """

    #: Steps the underlying integration is opened for (it is advanced lazily).
    MAX_STEPS = 10 ** 12

    def __init__(self, system, dt: float, *, scheme=None, q0=None, v0=None, u0=None, solver="auto"):
        if system.input_matrix is None or system.output_matrix is None:
            raise FemromValueError("system needs inputs and outputs to be a plant "
                                   f"(input_matrix is {'set' if system.input_matrix is not None else 'None'}, "
                                   f"output_matrix is {'set' if system.output_matrix is not None else 'None'})")
        n = system.n_dofs
        self.system, self.dt = system, float(dt)
        self.n_inputs, self.n_outputs = system.n_inputs, system.n_outputs
        self.scheme = Newmark() if scheme is None else scheme
        self._input = _SampledInput(0.0, vector(u0, self.n_inputs, "u0"))
        driven = dataclasses.replace(system, inputs=self._input)
        self._run = iterate(driven, self.scheme, vector(q0, n, "q0"), vector(v0, n, "v0"), self.dt,
                            self.MAX_STEPS, solver=solver, progress=False)
        self.last = next(self._run)

    @property
    def output(self) -> np.ndarray:
        return np.asarray(self.system.output_matrix @ self.last.q, dtype=float).ravel()

    def step(self, u) -> np.ndarray:
        self._input.advance(self.last.t + self.dt, vector(u, self.n_inputs, "u").copy())
        self.last = next(self._run)
        return self.output

    def summary(self):
        """The integrator's :class:`~femrom.integrators.IntegrationSummary` so far (timings, factorisations)."""
        return self._run.summary()
