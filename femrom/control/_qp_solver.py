"""The QP solver of an MPC and its settings, as one small object (:class:`QPSolver`).

A formulation asks it for its solver's arguments: the keyword arguments of
``cvxpy.Problem.solve`` (:meth:`QPSolver.cvxpy_keywords`, the cvxpy formulations) or
OSQP's own settings (:meth:`QPSolver.osqp_settings`, ``"condensed_osqp"``). The
tolerance means the same for both solvers it maps: OSQP ``eps_abs = eps_rel``,
Clarabel ``tol_gap_abs = tol_gap_rel = tol_feas``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from femrom._errors import FemromValueError


@dataclass(frozen=True)
class QPSolver:
    """A QP solver for :class:`~femrom.control.LinearMPC` (its config's ``solver``).

    Attributes
    ----------
    name : str
        A cvxpy QP solver, any case, kept lower-case: ``"osqp"`` (warm-started ADMM;
        the default, with the ``"condensed_osqp"`` formulation) or ``"clarabel"``
        (interior point); another installed cvxpy solver takes ``options`` only.
    tolerance : float
        OSQP ``eps_abs = eps_rel``; Clarabel ``tol_gap_abs = tol_gap_rel = tol_feas``.
        OSQP stops when the bound residual is at most ``tolerance * (1 + max|u|)``: the
        largest bound violation an accepted solve can have (a polished solve has none).
    max_iterations : int
        The solver's iteration limit.
    options : dict
        Further settings, which win over the ones above: keyword arguments of
        ``cvxpy.Problem.solve`` (e.g. ``{"polish": True}``), or OSQP's settings for
        ``"condensed_osqp"`` (e.g. ``{"polishing": True}``).
    """

    name: str = "osqp"
    tolerance: float = 1e-6
    max_iterations: int = 10_000
    options: dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise FemromValueError(f"a QP solver needs a cvxpy solver name, got {self.name!r}")
        if not (self.tolerance > 0):
            raise FemromValueError(f"tolerance must be positive, got {self.tolerance!r}")
        if not (isinstance(self.max_iterations, (int, np.integer)) and self.max_iterations >= 1):
            raise FemromValueError(f"max_iterations must be a positive integer, got {self.max_iterations!r}")
        object.__setattr__(self, "name", self.name.lower())
        object.__setattr__(self, "options", dict(self.options))

    def cvxpy_keywords(self) -> dict:
        """Keyword arguments of ``cvxpy.Problem.solve``: the solver, warm start, the mapped
        tolerance and iteration limit (OSQP, Clarabel), then :attr:`options`."""
        tol, iterations = float(self.tolerance), int(self.max_iterations)
        if self.name == "osqp":
            options = dict(eps_abs=tol, eps_rel=tol, max_iter=iterations, polish=False)
        elif self.name == "clarabel":
            options = dict(tol_gap_abs=tol, tol_gap_rel=tol, tol_feas=tol, max_iter=iterations)
        else:
            options = {}
        options.update(self.options)
        return dict(solver=self.name.upper(), warm_start=True, **options)

    def osqp_settings(self) -> dict:
        """The settings of an ``osqp.OSQP`` solver object (``setup(**settings)``)."""
        if self.name != "osqp":
            raise FemromValueError(f"OSQP settings asked of the {self.name!r} solver")
        settings = dict(eps_abs=float(self.tolerance), eps_rel=float(self.tolerance),
                        max_iter=int(self.max_iterations), polishing=False, warm_starting=True, verbose=False)
        settings.update(self.options)
        return settings

    def describe(self) -> dict:
        """The settings as plain JSON values, under the keys a config has always reported."""
        return {"solver": self.name.upper(), "tolerance": self.tolerance, "max_iterations": self.max_iterations,
                "solver_options": dict(self.options)}
