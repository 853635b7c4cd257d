r"""A model on a shaker: driven by ``F sin(omega t) f_hat`` a whole forcing period at a time.

:class:`~femrom.integrators.SteppedSine` sweeps a :class:`Shaker` frequency by frequency
without restarting (a hysteretic joint follows its branch). The shaker holds the model's
state between frequencies and offers

- ``output_names`` (tuple of p str), ``quantity`` (``"acceleration"`` or ``"displacement"``)
  and ``scheme`` (the time scheme, whose frequency map the sweep prewarps with);
- ``reset()``: back to rest (the ``rest`` state given, else ``q = v = 0`` and the nonlinear
  force's initial state);
- ``periods(amplitude, frequency_hz, steps_per_period, max_periods)``: an iterator that
  drives ``F sin(2 pi f (t - t_0))`` from the current time ``t_0`` with ``dt = 1 / (f N)``,
  sampled at the steps (``u_j = F sin(2 pi j / N)``), and yields each whole period's (p, N)
  output samples at steps ``1 .. N``; the state is the end of the last period handed out.

Any model steps on it, the full one (sparse) and every reduced one (dense), with any
registered scheme: a :class:`~femrom.integrators.Stepper` per frequency (its ``dt``
changes), started from the previous period's end with its force state and acceleration.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Iterator

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.integrators._driver import StepResult
from femrom.integrators._march import Stepper
from femrom.integrators._scheme import time_scheme
from femrom.solvers import make_solver

QUANTITIES = ("acceleration", "displacement")


def model_of(model):
    """The :class:`~femrom.scene.SecondOrderSystem` of a model given as one, as a reduced model offering
    it (``model.model``) or as a built scene (``model.system``)."""
    for system in (model, getattr(model, "model", None), getattr(model, "system", None)):
        if system is not None and all(hasattr(system, name) for name in ("mass", "stiffness", "nonlinear", "n_dofs")):
            return system
    raise FemromValueError(f"model must be a SecondOrderSystem or have one as .model or .system; got a "
                           f"{type(model).__name__}")


class Shaker:
    r"""A second-order model shaken by ``F sin(omega t) f_hat`` (module docstring).

    The model's own inputs are replaced by the one harmonic input ``f_hat``; its constant
    load ``f_0`` (a bolt preload) and its nonlinear forces stay. Outputs are ``E a`` (the
    scheme's accelerations, which balance the equation of motion at every step) or ``E q``.

    Parameters
    ----------
    model : SecondOrderSystem, or a reduced model with ``.model``
        With an output map (the accelerometers).
    force : int or (n,) array_like
        Where the unit force acts: the index of one of the model's input columns, or the
        vector ``f_hat`` (e.g. :func:`~femrom.fem.point_load` at the shaker's attachment).
    scheme : str or Scheme
        A registered time scheme (default Newmark average acceleration).
    quantity : {"acceleration", "displacement"}
    rest : StepResult, optional
        The state each force level starts from (default rest: zeros and the force's initial
        state): a preloaded equilibrium with its committed joint state,
        ``StepResult.at_rest(n, state=...)``.
    solver : str or callable, optional
        Linear-solver strategy or factory of the scheme's set-up (default by the matrix).
    output_names : sequence of str, optional
        Default the model's, else ``y0, y1, ...``.
    """

    def __init__(self, model, force=0, *, scheme="newmark", quantity: str = "acceleration",
                 rest: StepResult | None = None, solver=None, output_names=None):
        system = model_of(model)
        if system.output_matrix is None:
            raise FemromValueError("the model has no outputs (output_matrix is None): a stepped sine reports "
                                   "outputs such as accelerometers")
        if quantity not in QUANTITIES:
            raise FemromValueError(f"quantity must be one of {', '.join(QUANTITIES)}, got {quantity!r}")
        n = system.n_dofs
        if isinstance(force, (int, np.integer)) and not isinstance(force, bool):
            m = 0 if system.input_matrix is None else system.input_matrix.shape[1]
            if not 0 <= force < m:
                raise FemromValueError(f"force must be an input index in [0, {m}) or an ({n},) vector, got {force!r}")
            B = system.input_matrix
            column = B[:, [force]]
            f_hat = np.asarray(column.toarray() if sp.issparse(column) else column, dtype=float).ravel()
        else:
            f_hat = np.asarray(force.toarray() if hasattr(force, "toarray") else force, dtype=float).ravel()
            if f_hat.shape != (n,) or not np.all(np.isfinite(f_hat)) or not np.any(f_hat):
                raise FemromValueError(f"force must be a finite, nonzero ({n},) vector, got shape {f_hat.shape}")
        self.force_vector = f_hat
        self.system = dataclasses.replace(system, input_matrix=f_hat[:, None], inputs=None)
        self.scheme = time_scheme(scheme)
        self.scheme.check(self.system)
        self.quantity = quantity
        names = output_names if output_names is not None else system.output_names
        p = system.output_matrix.shape[0]
        self.output_names = tuple(names) if names else tuple(f"y{i}" for i in range(p))
        if len(self.output_names) != p:
            raise FemromValueError(f"output_names has {len(self.output_names)} names for {p} outputs")
        if rest is not None and (np.shape(rest.q) != (n,) or rest.t != 0.0):
            raise FemromValueError(f"rest must be a StepResult at t = 0 on the model's {n} dofs")
        self.rest = rest
        self.solver = (functools.partial(make_solver, strategy=solver) if isinstance(solver, str) else solver)
        self._last: StepResult | None = rest

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
        last = self._last
        if last is None:
            stepper = Stepper(self.system, self.scheme, dt, u0=np.zeros(1), solver=self.solver)
        else:
            stepper = Stepper(self.system, self.scheme, dt, last.q, last.v, t0=last.t, u0=np.zeros(1),
                              state=last.state, a0=last.a, solver=self.solver)
        sines = float(amplitude) * np.sin(2.0 * np.pi * np.arange(1, N + 1) / N)
        E = self.system.output_matrix
        acceleration = self.quantity == "acceleration"
        u = np.zeros(1)
        for _ in range(max_periods):
            columns = []
            for j in range(N):
                u[0] = sines[j]
                stepper.step(u)
                columns.append(stepper.acceleration if acceleration else stepper.q)
            self._last = StepResult(step=0, t=stepper.t, q=stepper.q.copy(), v=stepper.v.copy(),
                                    a=None if stepper.a is None else np.array(stepper.a), state=stepper.state)
            yield np.asarray(E @ np.column_stack(columns))
