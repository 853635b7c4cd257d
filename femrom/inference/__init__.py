"""Learning reduced second-order operators from snapshots.

- :func:`finite_difference`: time derivatives of snapshots (orders 2, 4, 6);
- :func:`reduce_snapshots` / :class:`SecondOrderData`: projected training data;
- :func:`galerkin` / :class:`ReducedOperators`: the intrusive reference ROM;
- :class:`LagrangianOpInf`: structure-preserving inference
  (``K^ = K^^T >= eps I``, ``C^ = C^^T >= 0``) as a semidefinite program, with
  the fast dedicated solver :func:`solve_fast` and the cvxpy reference
  :func:`solve_conic`;
- :class:`SecondOrderOpInf`: plain least-squares inference (the baseline);
- :class:`HamiltonianOpInf`: symmetric ``D^_q``, ``D^_p`` of a canonical
  Hamiltonian ROM from Lyapunov equations (Bartels-Stewart);
- :class:`ErrorSplit`, :class:`HamiltonianErrorSplit`: projection, derivative
  and optimisation errors of a second-order or Hamiltonian fit.
"""

from femrom.inference._data import (
    DERIVATIVE_SOURCES,
    SecondOrderData,
    concatenate,
    reduce_snapshots,
    reduced_coordinates,
)
from femrom.inference._derivatives import finite_difference, stencil_weights
from femrom.inference._fast import FastOptions, solve_fast
from femrom.inference._hamiltonian import (
    GRADIENT_DATA,
    HAMILTONIAN_DERIVATIVE_SOURCES,
    HamiltonianErrorSplit,
    HamiltonianOperators,
    HamiltonianOpInf,
    ProjectedPotential,
    project_potential_gradient,
    symmetric_lyapunov_fit,
)
from femrom.inference._learners import (
    SOLVERS,
    ErrorSplit,
    LagrangianOpInf,
    Regularization,
    SecondOrderOpInf,
)
from femrom.inference._operators import (
    Damping,
    Input,
    Mass,
    Output,
    ProjectedNonlinearForce,
    ReducedOperators,
    Stiffness,
    galerkin,
)
from femrom.inference._problem import Block, GramProblem
from femrom.inference._sdp import CONIC_SOLVERS, solve_conic

__all__ = [
    "CONIC_SOLVERS", "DERIVATIVE_SOURCES", "SOLVERS", "Block", "Damping", "ErrorSplit",
    "FastOptions", "GramProblem", "HamiltonianOperators", "HamiltonianOpInf", "Input", "LagrangianOpInf", "Mass", "Output",
    "ProjectedNonlinearForce", "ReducedOperators", "Regularization", "SecondOrderData",
    "SecondOrderOpInf", "Stiffness", "concatenate", "finite_difference", "galerkin",
    "reduce_snapshots", "reduced_coordinates", "solve_conic", "solve_fast", "stencil_weights",
    "symmetric_lyapunov_fit",
    "GRADIENT_DATA", "HAMILTONIAN_DERIVATIVE_SOURCES", "HamiltonianErrorSplit",
    "ProjectedPotential", "project_potential_gradient",
]
