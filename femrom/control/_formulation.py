r"""How the MPC's tracking problem becomes a QP and is solved: registered formulations.

A formulation builds its QP once from an :class:`~femrom.control.MPCProblem` and
the :class:`~femrom.control.MPCConfig` (its :class:`~femrom.control.QPSolver`), and on every step
writes the new state, reference window, previous input and offsets into it and
solves. Each is one class in one module of ``femrom/control/formulations``,
registered by name (:func:`register_formulation`), with

- ``name`` (str);
- ``__init__(problem, config)``: the one-off work;
- ``set_parameters(state, reference, u_previous, state_offset, output_offset,
  terminal_state)``: (n,), (p, N), (m,), (n,), (p,), (n,) ndarrays;
- ``solve() -> QPSolution``: status, the plan (m, N), the solver's seconds and iterations.

:class:`CvxpyFormulation` is the base of those that write a parametrised
``cvxpy.Problem`` (``self.problem``, checked to be DPP: cvxpy compiles it on the
first solve and afterwards only maps new parameter values into the solver's
data; OSQP is warm-started from the last solution).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from femrom._errors import FemromRuntimeError, FemromValueError
from femrom._registry import Registry

#: The QP formulations by name (sorted).
QP_FORMULATIONS = Registry("QP formulation", "femrom.control.formulations", order=lambda name, cls: name)

#: Statuses whose solution is used as it is (cvxpy's names).
ACCEPTED_STATUSES = (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


@dataclass(frozen=True)
class QPSolution:
    """One solve: ``status`` (cvxpy's names, ``"error"`` when the solver raised), ``plan``
    (m, N) ndarray or ``None``, ``solver_seconds`` (``nan`` if unknown), ``iterations`` (-1 if unknown)."""

    status: str
    plan: np.ndarray | None
    solver_seconds: float
    iterations: int


class QPFormulation:
    """Base class of a formulation (module docstring)."""

    name = ""
    #: (m N,) the condensed QP's gradient term ``g`` of the last :meth:`set_parameters`, for a
    #: formulation that computes it (the MPC's accuracy certificate reuses it); ``None`` otherwise.
    gradient_ = None

    def __init__(self, problem, config):
        self.mpc_problem, self.config = problem, config

    def set_parameters(self, state, reference, u_previous, state_offset, output_offset, terminal_state):
        raise NotImplementedError

    def solve(self) -> QPSolution:
        raise NotImplementedError


class CvxpyFormulation(QPFormulation):
    """A formulation that writes a DPP ``cvxpy.Problem`` (``self.problem``) and its ``plan()``.

    A subclass builds ``self.problem`` in ``__init__`` and then calls :meth:`compiled`.
    """

    def compiled(self) -> None:
        """Check that the problem is DPP (compiled once) and that the solver is there."""
        if not self.problem.is_dcp(dpp=True):
            raise FemromRuntimeError(f"formulation {self.name!r} is not DPP: cvxpy would recompile the QP every solve")
        if self.config.solver.name.upper() not in cp.installed_solvers():
            raise FemromValueError(f"solver {self.config.solver.name!r} is not installed for cvxpy; "
                                   f"installed: {', '.join(cp.installed_solvers())}")
        self._options = self.config.solver.cvxpy_keywords()

    def plan(self) -> np.ndarray | None:
        raise NotImplementedError

    def solve(self) -> QPSolution:
        try:
            with warnings.catch_warnings():
                # cvxpy hands OSQP 1.x the old setting name "polish" (a DeprecationWarning per solve)
                warnings.simplefilter("ignore", DeprecationWarning)
                warnings.simplefilter("ignore", PendingDeprecationWarning)
                self.problem.solve(**self._options)
            status = self.problem.status
        except cp.error.SolverError:
            return QPSolution("error", None, float("nan"), -1)
        stats = self.problem.solver_stats
        seconds = float(stats.solve_time) if stats.solve_time is not None else float("nan")
        iterations = int(stats.num_iters) if stats.num_iters is not None else -1
        return QPSolution(status, self.plan() if status in ACCEPTED_STATUSES else None, seconds, iterations)


def register_formulation(cls: type[QPFormulation]) -> type[QPFormulation]:
    """Class decorator: ``LinearMPC(..., formulation=cls.name)`` builds its QP with ``cls``."""
    if not cls.name:
        raise FemromValueError(f"formulation class {cls.__name__} has no name")
    QP_FORMULATIONS.add(cls.name, cls)
    return cls


def registered_formulations() -> dict[str, type[QPFormulation]]:
    """The registered QP formulations by name (the built-in modules imported once)."""
    return QP_FORMULATIONS.items()


def box_constraints(variable, bound: np.ndarray, horizon: int) -> list:
    """``-b <= u <= b`` on the bounded inputs of a stacked (m N,) input variable ``[u_0; ...; u_{N-1}]``."""
    bounded = np.flatnonzero(np.isfinite(np.tile(bound, horizon)))
    if bounded.size == 0:
        return []
    limits = np.tile(bound, horizon)[bounded]
    selected = variable if bounded.size == variable.size else variable[bounded]
    return [selected <= limits, selected >= -limits]
