"""Reduced second-order models and their structure-preserving time stepping.

- :class:`SecondOrderROM`: intrusive (:meth:`SecondOrderROM.galerkin`) or
  learned (``SecondOrderROM(learner=LagrangianOpInf()).fit(data)``) models with
  ``predict``, outputs, reduced energy, lazy full-field reconstruction and
  HDF5 ``save``/``load``;
- :class:`ReducedSolution`: what ``predict`` returns;
- reduced schemes (:data:`SCHEMES`): Newmark average acceleration, the
  implicit midpoint rule, Stoermer-Verlet, as precomputed linear step maps;
- :class:`HamiltonianROM`: canonical Hamiltonian ROMs, intrusive
  (:meth:`HamiltonianROM.galerkin`) or learned (``fit`` through
  :class:`~femrom.inference.HamiltonianOpInf`), with symplectic Euler A/B,
  Stoermer-Verlet, the implicit midpoint rule and AVF, outputs, the reduced
  Hamiltonian, lazy full fields (:class:`HamiltonianSolution`) and HDF5
  ``save``/``load``;
- :func:`select_regularization`: a grid of regularization weights scored by
  training fit and by energy over an extended window;
- :class:`HyperReducedPotential`, :func:`ecsw_weights`, :func:`sparse_nnls`:
  structure-preserving hyper-reduction of a nodal potential (sampled nodes
  and non-negative weights; the reduced force stays an exact gradient).
"""

from femrom.rom._hamiltonian import (
    HAMILTONIAN_SCHEMES,
    HamiltonianROM,
    HamiltonianSolution,
    hamiltonian_step_matrix,
)
from femrom.rom._hyper import HyperReducedPotential, ecsw_weights, sparse_nnls
from femrom.rom._model import ReducedSolution, SecondOrderROM
from femrom.rom._selection import RegularizationScore, select_regularization
from femrom.rom._steppers import SCHEMES, linear_step_map, verlet_bound

__all__ = [
    "HAMILTONIAN_SCHEMES", "HamiltonianROM", "HamiltonianSolution", "SCHEMES", "hamiltonian_step_matrix", "ReducedSolution", "RegularizationScore", "SecondOrderROM", "linear_step_map",
    "select_regularization", "verlet_bound",
    "HyperReducedPotential", "ecsw_weights", "sparse_nnls",
]
