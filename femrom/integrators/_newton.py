r"""Newton iterations for the implicit step of a nonlinear system.

An implicit scheme reduces one step to ``R(x) = 0`` for an unknown ``x`` (the
new acceleration for Newmark, the midpoint velocity for implicit midpoint),
with a sparse Jacobian assembled from ``K + df/dq`` and ``C + df/dv``. Newton
updates ``x <- x - J(x)^{-1} R(x)`` until

    ||R(x)|| <= atol + rtol * scale(x),

where ``scale`` is the sum of the norms of the force terms that make up ``R``
(inertia, elastic, damping, nonlinear, external): the residual is small
*relative to the forces it balances*. Once an update no longer changes ``x``
in floating point (``||dx|| <= 4 eps ||x||``) the residual is at its roundoff
floor and the step is accepted as well.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromRuntimeError, FemromValueError


class ConvergenceError(FemromRuntimeError):
    """Newton did not converge (the driver adds the step and time)."""


#: How an implicit step's nonlinear equation is solved (:mod:`._implicit`).
NEWTON_METHODS = ("auto", "full", "condensed", "dense")


@dataclass(frozen=True)
class Newton:
    """Tolerances of the Newton iterations of a step, and where they run.

    Attributes
    ----------
    rtol : float
        Residual tolerance relative to the size of the balanced force terms.
    atol : float
        Absolute residual tolerance (in the units of the residual).
    max_iterations : int
        Jacobian solves allowed per step before :class:`ConvergenceError`.
    method : {"auto", "full", "condensed", "dense"}
        ``"full"``: Newton on all dofs, the tangent refactorised every
        iteration; ``"condensed"``: Newton on the nonlinear force's own
        coordinates with the linear part condensed once per ``dt``
        (:mod:`femrom.integrators._implicit`); ``"dense"``: Newton on all
        dofs with dense arrays (a small system: a reduced model);
        ``"auto"``: dense up to ``dense_max`` dofs, else condensed when the
        force has at most ``condense_max`` coordinates and at most
        ``condense_fraction`` of the dofs, else full.
    dense_max : int
        Largest system ``"auto"`` solves with dense arrays.
    condense_max : int
        Largest number of condensed coordinates ``"auto"`` takes (a dense
        (s, s) factorisation per iteration: 0.1-0.2 s at 4000).
    condense_fraction : float
        Largest share of the dofs ``"auto"`` condenses.
    condense_memory : float
        Bytes the condensed step may keep for ``Z = S^-1 L^T`` (n x s); above
        it, each step solves once more with ``S`` instead.
    refactor_ratio : float
        A condensed step iterates with the (s, s) tangent at rest, factorised
        once per ``dt``, while every iteration reduces the residual at least
        by this factor, and refactorises at the current iterate otherwise;
        ``0`` refactorises at every iteration (plain Newton).
    """

    rtol: float = 1e-10
    atol: float = 0.0
    max_iterations: int = 20
    method: str = "auto"
    condense_max: int = 4000
    condense_fraction: float = 0.25
    condense_memory: float = 2.0**31
    refactor_ratio: float = 0.1
    dense_max: int = 64

    def __post_init__(self):
        if self.rtol < 0 or self.atol < 0 or (self.rtol == 0 and self.atol == 0):
            raise FemromValueError(f"Newton needs rtol, atol >= 0 and not both 0, "
                             f"got {self.rtol}, {self.atol}")
        if self.max_iterations < 1:
            raise FemromValueError(f"Newton max_iterations must be >= 1, got {self.max_iterations}")
        if self.method not in NEWTON_METHODS:
            raise FemromValueError(f"unknown Newton method {self.method!r}; valid: {', '.join(NEWTON_METHODS)}")
        if not (self.condense_max >= 1 and 0 < self.condense_fraction <= 1 and self.condense_memory >= 0
                and 0 <= self.refactor_ratio < 1 and self.dense_max >= 0):
            raise FemromValueError("Newton needs condense_max >= 1, 0 < condense_fraction <= 1, "
                             "condense_memory >= 0, 0 <= refactor_ratio < 1, dense_max >= 0")


def newton_loop(evaluate: Callable, x0: np.ndarray, options: Newton, *, update_scale: float | None = None,
                stagnation: bool = False, where: str = "") -> tuple[np.ndarray, int]:
    r"""The one Newton iteration of femrom: ``x <- x - J(x)^{-1} R(x)`` from ``x0``.

    Parameters
    ----------
    evaluate : callable
        ``x -> (R, scale, solve)``: the (n,) residual, the positive float it is measured
        against (the norms of the force terms it balances) and ``solve(R) = J(x)^{-1} R``.
    x0 : (n,) ndarray
        The predictor.
    options : Newton
        ``rtol``, ``atol``, ``max_iterations``.
    update_scale : float, optional
        Judge convergence by the update instead of the residual: stop when
        ``||dx|| <= rtol max(||x||, update_scale)`` (``update_scale``: the size the unknown
        has in this step, when ``||x||`` itself can vanish at a turning point).
    stagnation : bool
        Also stop when, from the third iteration on, an update fails to halve the previous
        one: with an exact Jacobian that is the round-off floor.
    where : str
        Appended to the error message (e.g. ``" at t = 0.3"``).

    Returns
    -------
    x : (n,) ndarray
    iterations : int
        Jacobian solves (0 when ``x0`` already satisfies the residual test).

    By default the residual test ``||R|| <= atol + rtol scale``; once an update no
    longer changes ``x`` in floating point (``||dx|| <= 4 eps ||x||``) the residual is
    at its round-off floor and the iterate is accepted as well.
    """
    x = np.array(x0, dtype=float)
    eps = np.finfo(float).eps
    previous = np.inf
    norm = tolerance = float("nan")
    for iteration in range(options.max_iterations + 1):
        R, scale, solve = evaluate(x)
        norm = float(np.linalg.norm(R))
        if not np.isfinite(norm):
            raise ConvergenceError(f"Newton residual is not finite at iteration {iteration}{where}")
        tolerance = options.atol + options.rtol * scale
        if update_scale is None and norm <= tolerance:
            return x, iteration
        if iteration == options.max_iterations:
            break
        dx = solve(R)
        x = x - dx
        size = float(np.linalg.norm(dx))
        if update_scale is not None:
            if size <= options.rtol * max(float(np.linalg.norm(x)), update_scale, 1e-300) or (
                    stagnation and iteration >= 2 and size >= 0.5 * previous):
                return x, iteration + 1
        elif size <= 4.0 * eps * np.linalg.norm(x) or (stagnation and iteration >= 2 and size >= 0.5 * previous):
            return x, iteration + 1
        previous = size
    if update_scale is not None:
        raise ConvergenceError(f"Newton did not converge in {options.max_iterations} iterations{where}")
    raise ConvergenceError(
        f"Newton did not converge in {options.max_iterations} iterations{where}: residual "
        f"{norm:.3g} > tolerance {tolerance:.3g} (atol={options.atol:g}, rtol={options.rtol:g})")


def solve_newton(residual: Callable, jacobian: Callable, x0: np.ndarray, make_solver: Callable,
                 options: Newton) -> tuple[np.ndarray, int]:
    r"""Solve ``R(x) = 0`` from ``x0`` with a sparse Jacobian (:func:`newton_loop`).

    Parameters
    ----------
    residual : callable
        ``x -> (R, scale)``: the (n,) residual and the positive float it is
        measured against.
    jacobian : callable
        ``x -> J``: the (n, n) sparse ``dR/dx``.
    x0 : (n,) ndarray
        Initial guess (a predictor).
    make_solver : callable
        ``(J, spd=...) -> LinearSolver``; called once per iteration (the
        tangent changes every iteration).
    options : Newton
        Tolerances.

    Returns
    -------
    x : (n,) ndarray
    iterations : int
        Number of Jacobian solves (0 when ``x0`` already satisfies the test).
    """
    def evaluate(x):
        R, scale = residual(x)
        return R, scale, lambda r: make_solver(jacobian(x), spd=False).solve(r)

    return newton_loop(evaluate, x0, options)


def _diagonal_values(D) -> np.ndarray | None:
    """The diagonal of ``D`` if ``D`` is stored as a diagonal matrix, else ``None``."""
    if D.format == "dia":
        return D.diagonal() if list(D.offsets) == [0] else None
    if D.format == "csr" and D.nnz == D.shape[0] and np.all(np.diff(D.indptr) == 1) \
            and np.array_equal(D.indices, np.arange(D.shape[0])):
        return D.data
    return None


class TangentMatrix:
    r"""Builds the step Jacobian ``J = S + c_q df/dq + c_v df/dv`` around a fixed ``S``.

    ``S`` is the scheme's effective matrix (e.g. ``M + gamma h C + beta h^2 K``).
    Diagonal tangents (local potentials such as sine-Gordon or cubic springs)
    are added straight onto the stored diagonal of ``S``, which avoids a
    sparse-matrix sum per Newton iteration; any other tangent is summed.

    Parameters
    ----------
    effective_matrix : (n, n) sparse
        ``S``.
    c_q, c_v : float
        Weights of ``df/dq`` and ``df/dv`` in ``J``.
    """

    def __init__(self, effective_matrix, c_q: float, c_v: float):
        S = sp.csr_matrix(effective_matrix, dtype=float, copy=True)
        S.sum_duplicates()
        S.sort_indices()
        self.S, self.c_q, self.c_v = S, float(c_q), float(c_v)
        n = S.shape[0]
        rows = np.repeat(np.arange(n), np.diff(S.indptr))
        positions = np.flatnonzero(S.indices == rows)
        self._diagonal = positions if positions.size == n else None

    def __call__(self, dfdq, dfdv) -> sp.csr_matrix:
        data = self.S.data.copy()
        others = []
        for c, D in ((self.c_q, dfdq), (self.c_v, dfdv)):
            if D is None:
                continue
            d = _diagonal_values(D) if self._diagonal is not None else None
            if d is None:
                others.append(c * D)
            else:
                data[self._diagonal] += c * d
        J = sp.csr_matrix((data, self.S.indices, self.S.indptr), shape=self.S.shape)
        for X in others:
            J = J + X
        return J.tocsr()
