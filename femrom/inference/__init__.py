"""Learning reduced operators from snapshots, next to their intrusive Galerkin projection.

- Reduced terms (:mod:`._terms`): every term of ``M^ q'' + C^ q' + K^ q +
  f^(q, q'; s) = B^ u + f^_0``, ``y = E^ q`` is one registered class that
  knows its Galerkin projection, its data block, its structure, its value and
  tangent in a reduced step and its HDF5 form (:class:`Mass`,
  :class:`Damping`, :class:`Stiffness`, :class:`Input`, :class:`Output`,
  :class:`ConstantLoad`, :class:`ProjectedNonlinearForce`; :func:`register_term` for more);
  :class:`ReducedOperators` holds a model's terms, :func:`galerkin` projects
  every registered term;
- data: :func:`finite_difference`, :func:`reduce_snapshots` /
  :class:`SecondOrderData`, denoised before a fit by :class:`Smoothing` (every second-order
  learner's ``smoothing=`` option), :func:`reduce_canonical_snapshots` /
  :class:`CanonicalData`; snapshots every k-th step refined between by the model
  (:func:`alternating_fill`);
- learners (``fit(data, *, validation=None) -> self``, ``operators_``; :func:`registered_learners`
  by name), each built for a study by ``for_training(training, r, **options)`` from one
  :class:`TrainingSet` (the reduced runs, the system, Markov parameters: what it ``needs``):
  :class:`LagrangianOpInf` (structure-preserving, a semidefinite program solved by
  its ``solver=`` object: :class:`FastSolver` (default, :func:`solve_fast`) or
  :class:`ConicSolver`, the cvxpy reference, :func:`solve_conic`),
  :class:`SecondOrderOpInf` (plain least squares, the baseline),
  :class:`HamiltonianOpInf` (symmetric ``D^_q``, ``D^_p`` by Lyapunov
  equations), :class:`CanonicalOpInf` (an unconstrained first-order ``A^`` on
  canonical data, H-OpInf's baseline), :class:`GalerkinProjection` (the intrusive reference);
- identified first-order models (``model = "state_space"``, ``operators_`` a
  :class:`StateSpaceOperators` ``z+ = A z + B u``, ``y = C z + D u``) from
  :class:`InputOutputData` (sampled inputs, outputs and optionally states of
  several trajectories; :meth:`InputOutputData.from_second_order` reads the data
  L-OpInf learns from) and :class:`MarkovParameters`: :class:`DMDc` (DMD with
  control on the states), :class:`ERA` (balanced realisation of Markov
  parameters, :func:`era_realization`, :func:`block_hankel`), :class:`OKID`
  (observer Markov parameters by least squares, :func:`okid_markov_parameters`,
  then ERA, and the identified observer's gain, :func:`okid_observer_gain`);
  Markov parameters of a model (:func:`markov_parameters`), a stepper
  (:func:`impulse_response`) or a full-order system (:func:`system_impulse_response`);
- :class:`SpML` (L-OpInf, then a learned mass, potential and dissipation function on top,
  structure by construction; fitting needs torch, the ``ml`` extra, and says so in one
  line without it: :data:`TORCH_MISSING`; settings :class:`SpMLConfig`);
- learned nonlinear terms (numpy, no torch): :class:`LearnedPotential` (a scalar
  ``U^(q^)`` of monomials of degree 3 and 4 and an MLP, force ``dU^/dq^``) and
  :class:`LearnedDissipation` (a convex ``F^(q^') >= 0``, force ``dF^/dq^'``), built
  from :class:`SymmetricPolynomial`, :class:`ConvexPowers` and :class:`ScalarNetwork` (of :class:`NetworkLayer`; monomials by
  :func:`multi_indices`)
  (value, exact gradient and Hessian);
- :class:`ErrorSplit`, :class:`HamiltonianErrorSplit`: projection, derivative
  and optimisation errors of a fit.
"""

from femrom.inference._data import (
    DERIVATIVE_SOURCES,
    SecondOrderData,
    concatenate,
    project_columns,
    reduce_snapshots,
    reduced_coordinates,
)
from femrom.inference._derivatives import finite_difference, stencil_weights
from femrom.inference._impulse import impulse_response, system_impulse_response
from femrom.inference._io_data import STATE_LAYOUTS, InputOutputData, MarkovParameters
from femrom.inference._every_kth_snapshot import FillSweep, alternating_fill, fill_between_snapshots, newmark_residual_matrix
from femrom.inference._structured_lstsq import FastSolver, solve_fast
from femrom.inference._hamiltonian import (
    GRADIENT_DATA,
    HAMILTONIAN_DERIVATIVE_SOURCES,
    CanonicalData,
    ForcePotential,
    HamiltonianErrorSplit,
    HamiltonianOperators,
    ProjectedPotential,
    canonical_from_second_order,
    project_potential_gradient,
    reduce_canonical_snapshots,
    symmetric_lyapunov_fit,
)
from femrom.inference._learner import (
    LEARNERS,
    Learner,
    Regularization,
    learner_class,
    register_learner,
    registered_learners,
)
from femrom.inference._operators import ReducedForces, ReducedOperators, galerkin
from femrom.inference._training import TrainingSet
from femrom.inference._problem import Block, GramProblem
from femrom.inference._realization import (
    LargeHankelWarning,
    block_hankel,
    era_realization,
    markov_from_observer,
    observer_markov_parameters,
    okid_markov_parameters,
    okid_observer_gain,
    system_markov_from_observer,
)
from femrom.inference._sdp import ConicSolver, solve_conic
from femrom.inference._smoothing import SMOOTHING_FIELDS, Smoothing, noise_level
from femrom.inference._second_order import ErrorSplit, SecondOrderLearner
from femrom.inference._state_space import StateSpaceOperators, markov_parameters
from femrom.inference._terms import (
    TERMS,
    VARIABLES,
    LinearTerm,
    ReducedTerm,
    register_term,
    registered_terms,
    term_class,
)
from femrom.inference.learners.dmdc import DMDc
from femrom.inference.learners.era import ERA
from femrom.inference.learners.galerkin import GalerkinProjection
from femrom.inference.learners.hopinf import HamiltonianOpInf
from femrom.inference.learners.iwan_lopinf import IwanLOpInf
from femrom.inference.learners.canonical_opinf import CanonicalOpInf
from femrom.inference.learners.lopinf import LagrangianOpInf
from femrom.inference.learners.okid import OKID
from femrom.inference.learners.opinf import SecondOrderOpInf
from femrom.inference.learners.spml import TORCH_MISSING, SpML, SpMLConfig, spml_module, torch_available
from femrom.inference._networks import ConvexPowers, NetworkLayer, ScalarNetwork, SymmetricPolynomial, multi_indices
from femrom.inference.terms.constant_load import ConstantLoad
from femrom.inference.terms.damping import Damping
from femrom.inference.terms.input import Input
from femrom.inference.terms.learned_dissipation import LearnedDissipation
from femrom.inference.terms.learned_hysteresis import LearnedHysteresis, SliderState, slider_stretches
from femrom.inference.terms.learned_potential import LearnedPotential
from femrom.inference.terms.mass import Mass
from femrom.inference.terms.output import Output
from femrom.inference.terms.projected_force import ProjectedNonlinearForce
from femrom.inference.terms.stiffness import Stiffness

__all__ = [
    "DERIVATIVE_SOURCES", "GRADIENT_DATA", "HAMILTONIAN_DERIVATIVE_SOURCES", "LEARNERS",
    "TERMS", "TORCH_MISSING", "VARIABLES", "ConstantLoad", "ConvexPowers", "LearnedDissipation", "LearnedPotential",
    "NetworkLayer", "ScalarNetwork", "multi_indices", "SpML", "SpMLConfig", "SymmetricPolynomial", "torch_available", "Block", "CanonicalData", "CanonicalOpInf", "Damping", "ErrorSplit", "ConicSolver", "FastSolver", "ForcePotential",
    "GalerkinProjection", "canonical_from_second_order",
    "GramProblem", "HamiltonianErrorSplit", "HamiltonianOperators", "HamiltonianOpInf", "Input",
    "LagrangianOpInf", "Learner", "LinearTerm", "Mass", "Output", "ProjectedNonlinearForce",
    "ProjectedPotential", "ReducedForces", "ReducedOperators", "ReducedTerm", "Regularization",
    "SecondOrderData", "SecondOrderLearner", "SecondOrderOpInf", "Stiffness", "concatenate",
    "FillSweep", "alternating_fill", "fill_between_snapshots", "newmark_residual_matrix",
    "finite_difference", "galerkin", "learner_class", "project_columns",
    "project_potential_gradient", "reduce_canonical_snapshots", "reduce_snapshots", "reduced_coordinates",
    "register_learner", "register_term", "registered_learners", "registered_terms", "solve_conic", "solve_fast", "stencil_weights",
    "symmetric_lyapunov_fit", "term_class",
    "DMDc", "ERA", "InputOutputData", "MarkovParameters", "OKID", "STATE_LAYOUTS", "StateSpaceOperators",
    "LargeHankelWarning", "block_hankel", "era_realization", "impulse_response", "markov_parameters", "observer_markov_parameters",
    "markov_from_observer", "okid_markov_parameters", "okid_observer_gain", "system_impulse_response",
    "system_markov_from_observer",
    "IwanLOpInf", "TrainingSet", "SMOOTHING_FIELDS", "Smoothing", "noise_level", "LearnedHysteresis", "SliderState", "slider_stretches", "spml_module",
]
