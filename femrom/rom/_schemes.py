r"""Reduced time schemes: a registry of one-step methods for small dense models.

A scheme integrates ``M q'' + C q' + K q + f(q, q'; s) = F(t)`` (``F = B u +
f_0``) with (r, r) dense operators. It is one :class:`ReducedScheme` subclass
in one module of the package ``femrom.rom.schemes`` (found by
:func:`registered_schemes`), or anywhere else decorated with
:func:`register_reduced_scheme`. It provides

- :meth:`~ReducedScheme.step_map`: for a linear model, the precomputed map
  ``x_{k+1} = A x_k + G F_{k+theta}`` on the state ``x = [q; v; a]`` (or ``[q; v]``);
- :meth:`~ReducedScheme.step`: one step with a nonlinear force (Newton on the
  reduced unknown, or explicit);
- ``input_time``: where a step from ``t_k`` samples the forcing, ``"end"``
  (``t_{k+1}``) or ``"mid"`` (``t_k + h/2``; from samples on the grid, the
  average of the two ends).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import scipy.linalg as sl

from femrom._registry import Registry

#: The reduced schemes by name (sorted).
REDUCED_SCHEMES = Registry("reduced scheme", "femrom.rom.schemes", order=lambda name, cls: name)


@dataclass(frozen=True, eq=False)
class LinearParts:
    """The linear operators of a reduced model for stepping: ``M``, ``C`` (or zeros), ``K``."""

    mass: np.ndarray
    damping: np.ndarray | None
    stiffness: np.ndarray

    @property
    def r(self) -> int:
        return self.stiffness.shape[0]

    @property
    def damping_matrix(self) -> np.ndarray:
        return np.zeros_like(self.stiffness) if self.damping is None else self.damping

    def acceleration(self, force: np.ndarray, q: np.ndarray, v: np.ndarray, nonlinear=None, state=None):
        """``a = M^-1 (F - C v - K q - f(q, v; s))``."""
        rhs = force - self.damping_matrix @ v - self.stiffness @ q
        if nonlinear is not None:
            rhs = rhs - nonlinear.force(q, v, state)
        return np.linalg.solve(self.mass, rhs)


def solve_matrix(S: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    return sl.lu_solve(sl.lu_factor(S), rhs)


class ReducedScheme:
    """A one-step method for a reduced second-order model (module docstring).

    Class attributes
    ----------------
    name : str
        Registry key (``predict(scheme=name)``).
    order : int
    input_time : {"end", "mid"}
    carries_acceleration : bool
        Whether the linear state is ``[q; v; a]`` (else ``[q; v]``).
    """

    name: ClassVar[str] = ""
    order: ClassVar[int] = 2
    input_time: ClassVar[str] = "end"
    carries_acceleration: ClassVar[bool] = True

    def check(self, parts: LinearParts, dt: float) -> None:
        """Raise if ``dt`` is not allowed (an explicit scheme's stability bound)."""

    def step_map(self, parts: LinearParts, dt: float, forcing: np.ndarray | None):
        """``(A, G)``: ``x_{k+1} = A x_k + G F`` for the (r, m) forcing columns ``forcing``
        (``G`` is ``None`` without forcing)."""
        raise NotImplementedError

    def step(self, parts: LinearParts, nonlinear, dt: float, t: float, q, v, a, state, force,
             newton: "ReducedNewton") -> tuple:
        """One step with a nonlinear force from ``t``: ``(q1, v1, a1, iterations)``.

        ``force`` is ``F`` at the scheme's input time; the state is frozen.
        ``a1`` may be ``None``: the caller then takes it from the equation of
        motion at ``t + dt``.
        """
        raise NotImplementedError


@dataclass(frozen=True)
class ReducedNewton:
    """Tolerances of the reduced Newton iterations: stop when ``||dx|| <= tol ||x||``."""

    tol: float = 1e-10
    max_iterations: int = 25


def newton_solve(residual_and_jacobian, x: np.ndarray, options: ReducedNewton, t: float):
    """Dense Newton: ``x <- x + dx`` with ``J dx = -R`` until ``||dx|| <= tol ||x||``."""
    for iteration in range(1, options.max_iterations + 1):
        R, J = residual_and_jacobian(x)
        dx = np.linalg.solve(J, -R)
        x = x + dx
        if np.linalg.norm(dx) <= options.tol * max(np.linalg.norm(x), 1e-300):
            return x, iteration
    raise RuntimeError(f"reduced Newton did not converge at t = {t:.6g}")


def register_reduced_scheme(cls: type[ReducedScheme]) -> type[ReducedScheme]:
    """Class decorator: ``predict(scheme=cls.name)`` integrates with ``cls``."""
    if not cls.name:
        raise ValueError(f"scheme class {cls.__name__} has no name")
    if cls.input_time not in ("end", "mid"):
        raise ValueError(f"scheme {cls.name!r}: input_time must be 'end' or 'mid'")
    REDUCED_SCHEMES.add(cls.name, cls)
    return cls


def registered_schemes() -> dict[str, type[ReducedScheme]]:
    """The registered reduced schemes by name (the built-in modules imported once)."""
    return REDUCED_SCHEMES.items()


def reduced_scheme(name: str) -> ReducedScheme:
    """An instance of the scheme registered as ``name``; a clear error otherwise."""
    return REDUCED_SCHEMES.get(name)()
