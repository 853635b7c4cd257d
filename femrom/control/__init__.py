"""Control on a reduced model's discrete state-space form: observers, linear MPC, closed loops.

The layer above :mod:`femrom.rom` (and below :mod:`femrom.post`): a controller is
designed on any :class:`~femrom.rom.DiscreteStateSpace` (a ROM's
``to_state_space(dt)``, an identified model) and run against any plant, the
full-order model included.

- :class:`LinearMPC` (:class:`MPCConfig`, its :class:`QPSolver`): output tracking with input bounds, a
  horizon of ``N`` inputs, weights on outputs, inputs and input moves, an optional
  terminal cost (``"dare"``: the LQR cost-to-go); the QP is built once as a
  parametrised cvxpy problem and re-solved each step (OSQP warm-started, or
  Clarabel); ``control(state, reference_window, u_previous) -> u`` logs the time
  and status of every solve; a failed solve raises or falls back by a stated
  policy (:class:`MPCError`, :class:`MPCWarning`);
- QP formulations, registered (:func:`registered_formulations`,
  :func:`register_formulation`; :class:`QPFormulation`, :class:`CvxpyFormulation`,
  :class:`QPSolution`): ``"condensed"`` (inputs only, :class:`CondensedQP`) and
  ``"sparse"`` (states and inputs) as parametrised cvxpy problems, and
  ``"condensed_osqp"`` (the condensed QP in OSQP directly, without cvxpy's
  per-solve work: the default with OSQP, 7 ms a step at m = 6, p = 40, N = 50
  in ``benchmarks/mpc_solve.py``); :class:`MPCProblem` is the math all are built from;
- observers: :class:`KalmanObserver` (steady-state Kalman filter from the
  discrete Riccati equation), :class:`PolePlacementObserver`, both
  :class:`LinearObserver` filters that handle the feedthrough ``D`` and the
  input offset of a Newmark state;
- offset-free tracking: :class:`DisturbanceModel` (``"output"`` or ``"input"``
  constant disturbances augmented to the observer's model, fed to the MPC as
  offsets);
- plants (:class:`Plant`: ``step(u) -> y``, ``output``): :class:`StateSpacePlant`,
  :class:`ReducedPlant` (a reduced model's stepper), :class:`FullOrderPlant`
  (a :class:`~femrom.scene.SecondOrderSystem` stepped by its own integrator);
- :func:`closed_loop` -> :class:`ClosedLoopResult` (outputs, inputs, estimates,
  QP times; ``metrics()``: tracking error, input effort, constraint violation,
  QP seconds per step; HDF5 ``save``/``load``); :func:`open_loop` (a feasible reference: a plant's
  response to a known input) and :func:`travelling_wave` (``a(x) sin(k x - omega t)``).
"""

from femrom.control._closed_loop import ClosedLoopResult, closed_loop, open_loop, travelling_wave
from femrom.control._disturbance import DisturbanceModel
from femrom.control._formulation import (
    QP_FORMULATIONS,
    CvxpyFormulation,
    QPFormulation,
    QPSolution,
    register_formulation,
    registered_formulations,
)
from femrom.control._mpc import LinearMPC, MPCError, MPCWarning
from femrom.control._observers import KalmanObserver, LinearObserver, PolePlacementObserver
from femrom.control._plants import FullOrderPlant, Plant, ReducedPlant, StateSpacePlant
from femrom.control._problem import CondensedQP, MPCConfig, MPCProblem
from femrom.control._qp_solver import QPSolver

__all__ = [
    "QP_FORMULATIONS", "ClosedLoopResult", "CondensedQP", "CvxpyFormulation", "DisturbanceModel", "FullOrderPlant",
    "KalmanObserver", "LinearMPC", "LinearObserver", "MPCConfig", "MPCError", "MPCProblem", "MPCWarning",
    "Plant", "PolePlacementObserver", "QPFormulation", "QPSolution", "QPSolver", "ReducedPlant", "StateSpacePlant", "closed_loop",
    "open_loop", "register_formulation", "registered_formulations", "travelling_wave",
]
