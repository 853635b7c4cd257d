"""Sparse linear-solver back-ends: set up once, solve many times.

The foundation under :mod:`femrom.fem`, :mod:`femrom.scene` and
:mod:`femrom.integrators` (it imports nothing else of femrom). A strategy is
one :class:`LinearSolver` subclass registered by name with
:func:`register_strategy`; :func:`make_solver` builds one by name, or picks
one by size and installed packages (``"auto"``, :func:`choose_strategy`).
"""

from femrom.solvers._base import (
    STRATEGY_CLASSES,
    LinearSolver,
    LinearSolverError,
    is_available,
    is_diagonal,
    register_strategy,
)
from femrom.solvers import _dense, _direct, _krylov, _pardiso  # noqa: F401  (register the strategies)
from femrom.solvers._direct import SUPERLU_MAX_DOFS
from femrom.solvers._factory import (
    AUTO_DIRECT_THRESHOLD,
    AUTO_SMALL,
    SolverCache,
    SolverFactory,
    choose_strategy,
    make_solver,
    matrix_digest,
    strategies,
)

#: Strategy names accepted by :func:`make_solver` when femrom was imported
#: (``"auto"`` first; :func:`strategies` also lists strategies registered later).
STRATEGIES = strategies()

__all__ = [
    "AUTO_DIRECT_THRESHOLD", "AUTO_SMALL", "STRATEGIES", "STRATEGY_CLASSES", "SUPERLU_MAX_DOFS",
    "LinearSolver", "LinearSolverError", "SolverCache", "SolverFactory", "choose_strategy",
    "is_available", "is_diagonal", "make_solver", "matrix_digest", "register_strategy", "strategies",
]
