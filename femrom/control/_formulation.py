r"""How the MPC's tracking problem becomes a cvxpy QP: registered formulations.

A formulation builds one parametrised ``cvxpy.Problem`` from an
:class:`~femrom.control.MPCProblem` once (disciplined parametrised
programming: ``problem.is_dcp(dpp=True)``, so cvxpy compiles it on the first
solve and afterwards only maps new parameter values into the solver's data),
and on every step writes the new state, reference window, previous input and
offsets into its parameters. Each is one class in one module of
``femrom/control/formulations``, registered by name
(:func:`register_formulation`), with

- ``name`` (str);
- ``__init__(problem)``: build ``self.problem`` (a DPP ``cvxpy.Problem``);
- ``set_parameters(state, reference, u_previous, state_offset, output_offset,
  terminal_state)``: (n,), (p, N), (m,), (n,), (p,), (n,) ndarrays;
- ``plan()``: the solution as an (m, N) ndarray (``None`` before a solve).
"""

from __future__ import annotations

import numpy as np

from femrom._registry import Registry

#: The QP formulations by name (sorted).
QP_FORMULATIONS = Registry("QP formulation", "femrom.control.formulations", order=lambda name, cls: name)


class QPFormulation:
    """Base class of a formulation (module docstring); ``problem`` is the parametrised cvxpy problem."""

    name = ""

    def __init__(self, problem):
        self.mpc_problem = problem
        self.problem = None

    def set_parameters(self, state, reference, u_previous, state_offset, output_offset, terminal_state):
        raise NotImplementedError

    def plan(self) -> np.ndarray | None:
        raise NotImplementedError


def register_formulation(cls: type[QPFormulation]) -> type[QPFormulation]:
    """Class decorator: ``LinearMPC(..., formulation=cls.name)`` builds its QP with ``cls``."""
    if not cls.name:
        raise ValueError(f"formulation class {cls.__name__} has no name")
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
