"""Time integrators for ``M q'' + C q' + K q + f_nl(q, q'; s) = B u(t) + f_0``.

Three separate pieces:

- a *scheme* takes one step of any second-order model, full (sparse) or reduced
  (dense), and declares its ``order``, its input time, the models it supports and
  its frequency map: :class:`Newmark` (average acceleration by default; its discrete
  frequencies :func:`newmark_frequencies`), :class:`GeneralizedAlpha`,
  :class:`CentralDifference` (explicit Stoermer-Verlet), :class:`ImplicitMidpoint`,
  :class:`DiscreteGradient` (the energy of conservative forces kept exactly); each is
  one class in one module of ``femrom.integrators.schemes``, registered by the name a
  scene's ``[time] integrator`` and ``predict(scheme=...)`` use (:class:`Scheme`,
  :data:`SCHEMES`, :func:`register_scheme`, :func:`time_scheme`, :func:`scheme_for`);
  a linear model with dense operators also steps by the scheme's precomputed
  step map (:func:`run_linear`);
- the *driver* :func:`iterate` loops and yields :class:`StepResult`;
  :func:`integrate` feeds them to *consumers* (:class:`Trajectory`,
  :class:`OutputRecorder`, :class:`EnergyRecorder`, or any callable);
  :func:`march` steps a model over a grid with sampled inputs into arrays (:func:`march_batch`
  many runs of one model at once, in one compiled call on a reduced joint model), and a
  :class:`Stepper` one input at a time;
- a *stepped sine* (:class:`SteppedSine`) drives any model on a :class:`Shaker`
  frequency by frequency without restarting, whole periods at
  a time to a tested steady state (:class:`SteadyStateCriterion`), and reports the
  first-harmonic amplitude and phase of each output (:class:`SteppedSineResult`);
  ``run_batched`` steps its force levels together;
- *harmonic balance* (:class:`HarmonicBalance`) writes any model's periodic steady state under
  ``F b sin(Omega t)`` as Fourier coefficients, with the nonlinear force (memory included)
  evaluated by alternating frequency-time marches over the period; :func:`frequency_response`
  and :func:`force_response` continue it by pseudo-arclength, and :func:`epmc` gives a damped
  nonlinear mode (frequency and damping against amplitude, :class:`NonlinearModes`);
- a *linear-solver strategy* (:func:`femrom.solvers.make_solver`) factorises
  (or preconditions) an effective matrix once and solves with it every step.

Linear systems take the linear path (one factorisation per ``dt``); Newton
runs only when the system has a nonlinear force, and only on that force's own
coordinates when it acts on a few dofs (:class:`Newton`, ``method``).
"""

from femrom.integrators._conditioning import (
    ConditioningError,
    ConditioningWarning,
    check_conditioning,
)
from femrom.integrators._consumers import EnergyRecorder, OutputRecorder, StepClock, Trajectory
from femrom.integrators._energy_balance import EnergyBalance
from femrom.integrators._driver import (
    Integration,
    IntegrationError,
    IntegrationSummary,
    StepResult,
    integrate,
    iterate,
)
from femrom.integrators._hamiltonian import (
    CanonicalSystem,
    CanonicalTrajectory,
    integrate_canonical,
)
from femrom.integrators._epmc import NonlinearModes, epmc, linear_mode
from femrom.integrators._harmonic_balance import (
    AFTResult,
    FourierBasis,
    HarmonicBalance,
    HarmonicBalanceError,
    HarmonicBalanceSolution,
    default_samples,
)
from femrom.integrators._hb_continuation import HarmonicBalanceCurve, force_response, frequency_response
from femrom.integrators._implicit import ImplicitSolve
from femrom.integrators._march import (
    Stepper,
    input_sample,
    input_samples,
    march,
    march_batch,
    run_linear,
    uniform_step,
)
from femrom.integrators._newton import ConvergenceError, Newton, newton_loop
from femrom.integrators._scheme import (
    LinearParts,
    Scheme,
    register_scheme,
    registered_schemes,
    scheme_for,
    time_scheme,
)
from femrom.integrators.schemes.central_difference import CentralDifference
from femrom.integrators.schemes.discrete_gradient import DiscreteGradient
from femrom.integrators.schemes.generalized_alpha import GeneralizedAlpha
from femrom.integrators.schemes.implicit_midpoint import ImplicitMidpoint
from femrom.integrators.schemes.newmark import Newmark, newmark_frequencies
from femrom.integrators._simulate import SimulationResult, simulate
from femrom.integrators._shaker import Shaker
from femrom.integrators._stability import bound_max_frequency, estimate_max_frequency
from femrom.integrators._steady_state import SteadyStateCriterion, first_harmonic
from femrom.integrators._stepped_sine import (
    FrequencyResponse,
    Peak,
    SteadyStateWarning,
    SteppedSine,
    SteppedSineResult,
    parabolic_peak,
    prewarped_frequency,
)

__all__ = [
        "ConditioningError",
    "ConditioningWarning",
    "check_conditioning",
    "CanonicalSystem", "CanonicalTrajectory",
    "CentralDifference", "ConvergenceError", "DiscreteGradient", "EnergyBalance", "EnergyRecorder", "GeneralizedAlpha", "ImplicitMidpoint",
    "ImplicitSolve", "Integration", "IntegrationError", "IntegrationSummary", "Newmark",
    "Newton", "OutputRecorder", "SimulationResult", "StepClock", "StepResult",
    "Trajectory", "bound_max_frequency", "estimate_max_frequency", "integrate", "integrate_canonical",
    "iterate", "newmark_frequencies", "register_scheme", "scheme_for", "simulate",     "LinearParts", "Scheme", "Stepper", "march", "march_batch", "newton_loop", "registered_schemes", "run_linear",
    "Shaker", "input_sample", "input_samples", "time_scheme", "uniform_step",     "FrequencyResponse", "Peak", "SteadyStateCriterion", "SteadyStateWarning",
    "SteppedSine", "SteppedSineResult", "first_harmonic", "parabolic_peak",
    "prewarped_frequency",
    "AFTResult", "FourierBasis", "HarmonicBalance", "HarmonicBalanceCurve", "HarmonicBalanceError",
    "HarmonicBalanceSolution", "NonlinearModes", "default_samples", "epmc", "force_response", "linear_mode",
    "frequency_response",
]
