r"""Reference solver: the regression as a conic program in cvxpy (Clarabel or SCS).

With ``G = L L^T`` and ``Z = H^T L^{-T}`` (see :meth:`GramProblem.factor`),

.. math::

    \min_{X}\; \| X L + Z \|_F^2
    \quad \text{s.t.} \quad X_j = X_j^\top,\; X_j - \varepsilon_j I \succeq 0
    \text{ for the "psd" blocks},

which differs from ``f(X)`` by the constant ``c - ||Z||_F^2``. ``L`` is
(p, k) with ``k = rank G <= p``: the program has ``r p`` unknowns and ``r k``
residuals whatever the number of snapshots. The problem is first scaled
(:meth:`GramProblem.scaled`) so that the solver's tolerances mean the same
thing for every data set.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from femrom._errors import FemromRuntimeError, FemromValueError
from femrom.inference._problem import GramProblem

#: cvxpy solvers this reference accepts.
CONIC_SOLVERS = ("CLARABEL", "SCS")


@dataclass(frozen=True)
class ConicSolver:
    """A cvxpy conic solver and its settings: for a learner's ``solver=``, the regression as a
    conic program (the reference of :func:`solve_conic`, ``"clarabel"`` or ``"scs"``); for
    :class:`~femrom.inference.IwanLOpInf`, its second-order cone program (any cvxpy solver
    that takes one).

    Attributes
    ----------
    name : str
        The cvxpy solver, any case (``"clarabel"``, ``"scs"``, ...); kept lower-case.
    options : dict
        Keyword arguments of ``cvxpy.Problem.solve`` (e.g. ``{"eps": 1e-10}`` for SCS).
    """

    name: str = "clarabel"
    options: dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise FemromValueError(f"a conic solver needs a cvxpy solver name, got {self.name!r}")
        object.__setattr__(self, "name", self.name.lower())
        object.__setattr__(self, "options", dict(self.options))

    @property
    def keywords(self) -> dict:
        """The keyword arguments of ``cvxpy.Problem.solve``: ``solver`` and :attr:`options`."""
        return {"solver": self.name.upper(), **self.options}

    def solve(self, problem: GramProblem):
        """:func:`solve_conic` with this solver and options: ``(X, info)``."""
        return solve_conic(problem, self.name, **self.options)


def solve_conic(problem: GramProblem, solver: str = "CLARABEL", **options):
    """Solve ``problem`` with cvxpy; returns ``(X, info)``.

    Parameters
    ----------
    problem : GramProblem
    solver : {"CLARABEL", "SCS"}
    **options
        Passed to ``cvxpy.Problem.solve`` (e.g. ``eps=1e-9`` for SCS).

    Returns
    -------
    X : (r, p) ndarray
        The operators, in the problem's (unscaled) units, with the symmetric
        blocks symmetrized exactly and their eigenvalues clipped at the bounds
        (the solver meets the cone only to its tolerance).
    info : dict
        ``solver``, ``status``, ``seconds`` (the whole call),
        ``solve_seconds`` (inside the conic solver) and ``objective``.
    """
    import cvxpy as cp

    solver = solver.upper()
    if solver not in CONIC_SOLVERS:
        raise FemromValueError(f"unknown conic solver {solver!r}; valid: {CONIC_SOLVERS}")
    tic = time.perf_counter()
    scaled, unscale, _ = problem.scaled()
    L, Z, _ = scaled.factor()
    r = scaled.r
    parts, constraints = [], []
    for b in scaled.blocks:
        if b.structure == "free":
            var = cp.Variable((r, b.size))
        else:
            var = cp.Variable((r, r), symmetric=True)
            if b.structure == "psd":
                constraints.append(var - b.shift * np.eye(r) >> 0)
        parts.append(var)
    X = cp.hstack(parts) if len(parts) > 1 else parts[0]
    program = cp.Problem(cp.Minimize(cp.sum_squares(X @ L + Z)), constraints)
    if solver == "SCS":
        options.setdefault("eps", 1e-9)
        options.setdefault("max_iters", 100_000)
    program.solve(solver=solver, **options)
    if X.value is None:
        raise FemromRuntimeError(f"{solver} returned no solution (status {program.status!r})")
    Xs = np.asarray(X.value, dtype=float)
    # interior-point iterates meet the cone only to the solver's tolerance:
    # clip onto it so every returned model satisfies its constraints exactly
    Xs = scaled.project(_symmetrize(Xs, scaled))
    out = _symmetrize(unscale(Xs), problem)
    stats = program.solver_stats
    info = {
        "solver": solver,
        "status": program.status,
        "seconds": time.perf_counter() - tic,
        "solve_seconds": float(stats.solve_time) if stats.solve_time is not None else None,
        "objective": problem.objective(out),
    }
    return out, info


def _symmetrize(X: np.ndarray, problem: GramProblem) -> np.ndarray:
    out = X.copy()
    for b, s in zip(problem.blocks, problem.slices()):
        if b.square:
            out[:, s] = 0.5 * (X[:, s] + X[:, s].T)
    return out
