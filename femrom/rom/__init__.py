"""Reduced models: fit, predict, step, export, save.

- :class:`SecondOrderROM`: intrusive (:meth:`SecondOrderROM.galerkin`) or
  learned (``SecondOrderROM(learner=LagrangianOpInf()).fit(data)``) models of
  any :class:`~femrom.inference.ReducedOperators` with ``predict``, a
  ``stepper`` (one input at a time), ``to_state_space(dt)`` for linear models,
  outputs, reduced energy, lazy full-field reconstruction and HDF5
  ``save``/``load`` (term by term);
- :class:`ReducedSolution`: what ``predict`` returns;
- reduced models step with the time schemes of :mod:`femrom.integrators` (one
  registry for the full and the reduced models: Newmark average acceleration, the
  implicit midpoint rule, Stoermer-Verlet, and ``discrete_gradient``, implicit
  midpoint with the average-vector-field discrete gradient of every conservative
  force: the energy never increases without input, the scheme of learned SpML models);
- :class:`DiscreteStateSpace`: ``z+ = A z + B u``, ``y = C z + D u``, with
  ``simulate``, a stepper and HDF5 (the form of identified first-order models);
- :class:`StateSpaceROM`: an identified first-order model
  (``StateSpaceROM(learner=DMDc(...) | ERA(...) | OKID(...)).fit(data)``) with
  ``predict`` (:class:`StateSpaceSolution`), a stepper, ``to_state_space`` at its
  identified ``dt``, OKID's observer (``estimate_states``) and HDF5 ``save``/``load``
  (a DiscreteStateSpace file plus the state basis and observer gain);
- :class:`HamiltonianROM`: canonical Hamiltonian ROMs, intrusive
  (:meth:`HamiltonianROM.galerkin`) or learned (``fit`` on
  :class:`~femrom.inference.CanonicalData` through
  :class:`~femrom.inference.HamiltonianOpInf`), with symplectic Euler A/B,
  Stoermer-Verlet, the implicit midpoint rule and AVF, outputs, the reduced
  Hamiltonian, lazy full fields (:class:`HamiltonianSolution`), a stepper and
  HDF5 ``save``/``load``;
- :class:`FirstOrderROM`: ``y' = A^ y + F^(y)`` on a cotangent lift without structure
  (plain OpInf, :class:`~femrom.inference.CanonicalOpInf`), implicit midpoint or RK4, a
  blow-up ends the run with NaN: the baseline of the Hamiltonian ROMs;
- :func:`select_regularization`: a grid of regularization weights scored by
  training fit and by energy over an extended window;
- :class:`HyperReducedPotential`, :func:`ecsw_weights`, :func:`sparse_nnls`:
  structure-preserving hyper-reduction of a nodal potential (sampled nodes
  and non-negative weights; the reduced force stays an exact gradient);
- :func:`ecsw_joint`, :func:`hyper_reduced_system`, :class:`JointSampling`: a projected
  joint sampled on a few weighted interface pairs (the stuck joint kept exact, the
  slip remainder sampled by ECSW; each sampled pair stays an interface element).
"""

from femrom.rom._base import LazyFields, ReducedModel, Solution
from femrom.rom._first_order import FirstOrderROM
from femrom.rom._hamiltonian import (
    HamiltonianROM,
    HamiltonianSolution,
    HamiltonianStepper,
)
from femrom.rom._identified import StateSpaceROM, StateSpaceSolution
from femrom.rom._hyper import HyperReducedPotential, ecsw_weights, sparse_nnls
from femrom.rom._hyper_joint import JointSampling, ecsw_joint, hyper_reduced_system
from femrom.rom._model import ReducedSolution, SecondOrderROM
from femrom.rom._selection import RegularizationScore, select_regularization
from femrom.rom._statespace import DiscreteStateSpace, StateSpaceStepper

__all__ = [
    "DiscreteStateSpace", "FirstOrderROM", "HamiltonianROM", "HamiltonianSolution", "HamiltonianStepper",
    "HyperReducedPotential", "JointSampling", "LazyFields", "ReducedModel",
    "ReducedSolution", "RegularizationScore", "SecondOrderROM", "StateSpaceROM",
    "StateSpaceSolution", "StateSpaceStepper",
    "ecsw_joint", "ecsw_weights", "hyper_reduced_system",
    "select_regularization", "sparse_nnls", "Solution",
]
