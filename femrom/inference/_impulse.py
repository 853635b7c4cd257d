r"""Markov parameters from impulse responses: of a stepping model, or of a full-order system.

The Markov parameters ``Y_0 = D``, ``Y_k = C A^{k-1} B`` of a sampled linear
model are its response to a unit sample. A model stepped with the input at the
step's end (Newmark: ``x_{k+1}`` depends on ``u_k`` and ``u_{k+1}``) is written
as ``z+ = A z + B u``, ``y = C z + D u`` only with the shifted state ``z = x - E u``
(:meth:`~femrom.rom.SecondOrderROM.to_state_space`), so a run from rest
(``x_0 = 0``) with ``u_0 != 0`` is not the state-space model from ``z_0 = 0``.
The unit sample is therefore applied at ``t_1``, after a zero sample at ``t_0``:
then ``z_0 = x_0 = 0`` and the outputs are ``y_{k+1} = Y_k e_j`` exactly, for every
scheme.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from femrom._errors import FemromValueError
from femrom._progress import Progress
from femrom.inference._io_data import MarkovParameters
from femrom.integrators import Newmark, iterate
from femrom.solvers import SolverCache


def impulse_response(make_stepper: Callable[[], object], n_inputs: int, count: int, *, dt: float,
                     progress: bool | None = None) -> MarkovParameters:
    r"""``Y_0 ... Y_{count-1}`` of a model stepped one input sample at a time.

    Parameters
    ----------
    make_stepper : callable
        ``make_stepper()`` returns a fresh stepper at rest whose input sample at
        ``t_0`` is zero, with ``y_{k+1} = stepper.step(u_{k+1})`` (a
        :class:`~femrom.rom.StateSpaceStepper`, a
        :class:`~femrom.rom.ReducedStepper`, ...).
    n_inputs : int
        ``m``: one run per input.
    count : int
        ``N >= 2`` parameters, ``N`` steps per run.
    dt : float
        The stepper's step.
    """
    m, count = int(n_inputs), int(count)
    if m < 1 or count < 2:
        raise FemromValueError(f"an impulse response needs n_inputs >= 1 and count >= 2, got {n_inputs}, {count}")
    columns = []
    bar = Progress(m * count, "impulse response", enabled=progress)
    for j in range(m):
        stepper = make_stepper()
        unit = np.zeros(m)
        unit[j] = 1.0
        response = [np.atleast_1d(np.asarray(stepper.step(unit), dtype=float))]
        zero = np.zeros(m)
        for _ in range(count - 1):
            response.append(np.atleast_1d(np.asarray(stepper.step(zero), dtype=float)))
        bar.update(count)
        columns.append(np.stack(response))               # (count, p)
    bar.close()
    return MarkovParameters(np.stack(columns, axis=2), dt=dt, layout="npm",
                            metadata={"source": "impulse response (stepper)"})


def _unit_sample(j: int, m: int, dt: float) -> Callable[[float], np.ndarray]:
    """``u(t) = e_j max(0, 1 - |t - dt| / dt)``: the unit sample at ``t_1`` on the grid, linear between."""

    def u(t: float) -> np.ndarray:
        value = np.zeros(m)
        value[j] = max(0.0, 1.0 - abs(float(t) - dt) / dt)
        return value

    return u


def system_impulse_response(system, dt: float, count: int, *, scheme=None, solver="auto",
                            progress: bool | None = None) -> MarkovParameters:
    r"""``Y_0 ... Y_{count-1}`` of a linear full-order system ``M q'' + C q' + K q = B u``, ``y = E q``.

    One run per input from rest, the unit sample at ``t_1`` (module doc): the
    sampled impulse response of the scheme, the same as
    :meth:`~femrom.rom.SecondOrderROM.to_state_space` of the Galerkin ROM with
    the identity basis. Between samples the input is linear (a scheme that
    evaluates it mid-step sees the average of the samples, as a ROM does).
    With a solver strategy name the ``m`` runs share one factorisation.

    Parameters
    ----------
    system : SecondOrderSystem
        Linear (no nonlinear force, no constant load), with inputs and outputs.
    dt : float
    count : int
        ``N >= 2``: ``N`` steps per run.
    scheme : optional
        A scheme of :mod:`femrom.integrators` (default ``Newmark()``, average acceleration).
    solver : str or callable
        As in :func:`femrom.integrators.iterate`.
    """
    if system.nonlinear is not None:
        raise FemromValueError("the system has a nonlinear force: Markov parameters describe linear systems only")
    if system.load is not None:
        raise FemromValueError("the system has a constant load: remove it (the impulse response is about u alone)")
    if system.input_matrix is None or system.output_matrix is None:
        raise FemromValueError("an impulse response needs the system's input_matrix and output_matrix")
    dt, count = float(dt), int(count)
    if not dt > 0 or count < 2:
        raise FemromValueError(f"an impulse response needs dt > 0 and count >= 2, got dt = {dt}, count = {count}")
    scheme = Newmark() if scheme is None else scheme
    if isinstance(solver, str):
        solver = SolverCache(solver, size=2)
    m, n = system.input_matrix.shape[1], system.n_dofs
    E = system.output_matrix
    columns = []
    for j in range(m):
        driven = dataclasses.replace(system, inputs=_unit_sample(j, m, dt))
        run = iterate(driven, scheme, np.zeros(n), np.zeros(n), dt, count, solver=solver, progress=progress)
        next(run)                                         # t_0: rest, zero input
        columns.append(np.stack([np.asarray(E @ result.q).ravel() for result in run]))
    return MarkovParameters(np.stack(columns, axis=2), dt=dt, layout="npm",
                            metadata={"source": f"impulse response ({getattr(scheme, 'name', type(scheme).__name__)})"})
