r"""A closed loop on the full-order model: MPC with a model as the controller's model, tracking one reference."""

from __future__ import annotations

import time

import numpy as np

from femrom.control import FullOrderPlant, KalmanObserver, LinearMPC, closed_loop
from femrom.post import relative_error
from femrom.study._experiment import Experiment, register_experiment


def open_loop_error(model, result) -> float:
    """``||y_model - y||_F / ||y||_F``: ``model`` (a discrete state space) run from rest on the inputs the
    closed loop ``result`` applied, against the plant's outputs."""
    predicted = model.simulate(result.inputs, np.zeros(model.n_states))[0]
    return relative_error(result.outputs, predicted)


@register_experiment("closed_loop")
class ClosedLoopTest(Experiment):
    r"""The FOM (:class:`~femrom.control.FullOrderPlant`, its own integrator) tracking ``reference`` (p, K) over
    ``n_steps`` samples under :class:`~femrom.control.LinearMPC` of the model under test and a
    :class:`~femrom.control.KalmanObserver` (``docs/control.md``): output weight ``1 / s^2`` with
    ``s = rms(y_ref)``, no input weight, rate weight ``rate_weight / b^2``, ``|u| <= b``; measurement
    noise ``measurement_noise s^2``, optionally a constant ``disturbance`` per output.

    ``run(model)`` takes a :class:`~femrom.rom.DiscreteStateSpace` at the plant's ``dt`` (or a model
    with ``to_state_space(dt)``) and returns the loop's metrics
    (:meth:`~femrom.control.ClosedLoopResult.metrics`), ``model_error_on_applied_inputs``
    (:func:`open_loop_error`: what feedback had to correct), ``reference_rms``, ``loop_seconds`` and
    the :class:`~femrom.control.ClosedLoopResult` under ``_result`` (with the FOM's displacements
    when ``record_state``).

    Parameters
    ----------
    fom : FullOrderModel or SecondOrderSystem
    dt : float
    reference : (p, K) ndarray
        ``K >= n_steps + 1 + horizon`` (the MPC looks ``horizon`` samples ahead).
    n_steps : int
    solver : callable, optional
        The plant's linear solver factory (one cached factorisation shared by several loops).
    """

    def __init__(self, fom, dt: float, reference, n_steps: int, *, horizon: int, input_bound: float,
                 rate_weight: float = 1e-3, measurement_noise: float = 1e-2, disturbance: str | None = "output",
                 solver=None, label: str = "reference"):
        self.system = getattr(fom, "system", fom)
        self.dt, self.reference, self.n_steps = float(dt), np.asarray(reference, dtype=float), int(n_steps)
        self.horizon, self.input_bound, self.rate_weight = int(horizon), float(input_bound), float(rate_weight)
        self.measurement_noise, self.disturbance, self.solver, self.label = measurement_noise, disturbance, solver, label

    def run(self, model, *, record_state: bool = False) -> dict:
        model = model if hasattr(model, "simulate") else model.to_state_space(self.dt)
        size = float(np.sqrt(np.mean(self.reference ** 2)))
        mpc = LinearMPC(model, horizon=self.horizon, output_weight=1.0 / size ** 2, input_weight=0.0,
                        input_rate_weight=self.rate_weight / self.input_bound ** 2, input_bound=self.input_bound)
        observer = KalmanObserver(model, measurement_noise=self.measurement_noise * size ** 2,
                                  disturbance=self.disturbance)
        plant = FullOrderPlant(self.system, self.dt, solver=self.solver)
        tic = time.perf_counter()
        result = closed_loop(plant, mpc, observer, self.reference, self.n_steps,
                             record_state=(lambda p: p.last.q) if record_state else None, progress=False)
        seconds = time.perf_counter() - tic
        return {**result.metrics(), "model_error_on_applied_inputs": open_loop_error(model, result),
                "reference_rms": size, "loop_seconds": seconds, "_result": result}
