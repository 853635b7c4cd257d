"""Time integrators for ``M q'' + C q' + K q + f_nl(q, q') = B u(t)``.

Three separate pieces:

- a *scheme* takes one step and declares its ``order``: :class:`Newmark`
  (average acceleration by default), :class:`GeneralizedAlpha`,
  :class:`CentralDifference` (explicit Stoermer-Verlet), :class:`ImplicitMidpoint`;
- the *driver* :func:`iterate` loops and yields :class:`StepResult`;
  :func:`integrate` feeds them to *consumers* (:class:`Trajectory`,
  :class:`OutputRecorder`, :class:`EnergyRecorder`, or any callable);
- a *linear-solver strategy* (:func:`make_solver`) factorises (or
  preconditions) an effective matrix once and solves with it every step.

Linear systems take the linear path (one factorisation per ``dt``); Newton
runs only when the system has a nonlinear force.
"""

from femrom.integrators._central_difference import CentralDifference
from femrom.integrators._consumers import EnergyRecorder, OutputRecorder, Trajectory
from femrom.integrators._driver import (
    Integration,
    IntegrationError,
    IntegrationSummary,
    StepResult,
    integrate,
    iterate,
)
from femrom.integrators._midpoint import ImplicitMidpoint
from femrom.integrators._hamiltonian import (
    CANONICAL_SCHEMES,
    CanonicalSystem,
    CanonicalTrajectory,
    QuarticPotential,
    integrate_canonical,
)
from femrom.integrators._newmark import GeneralizedAlpha, Newmark, NewmarkAverageAcceleration
from femrom.integrators._newton import ConvergenceError, Newton, solve_newton
from femrom.fem import (
    STRATEGIES,
    LinearSolver,
    LinearSolverError,
    choose_strategy,
    make_solver,
)
from femrom.integrators._simulate import SimulationResult, scheme_for, simulate
from femrom.integrators._stability import MaxFrequency, bound_max_frequency, estimate_max_frequency

__all__ = [
    "CANONICAL_SCHEMES",
    "CanonicalSystem",
    "CanonicalTrajectory",
    "QuarticPotential",
    "integrate_canonical",
    "STRATEGIES",
    "CentralDifference",
    "ConvergenceError", "solve_newton",
    "EnergyRecorder",
    "GeneralizedAlpha",
    "ImplicitMidpoint",
    "Integration",
    "IntegrationError",
    "IntegrationSummary",
    "LinearSolver",
    "LinearSolverError",
    "MaxFrequency",
    "Newmark",
    "NewmarkAverageAcceleration",
    "Newton",
    "OutputRecorder",
    "SimulationResult",
    "StepResult",
    "Trajectory",
    "bound_max_frequency",
    "choose_strategy",
    "estimate_max_frequency",
    "integrate",
    "iterate",
    "make_solver",
    "scheme_for",
    "simulate",
]
