"""Nonlinear internal forces ``f_nl(q, v)`` with their tangent and internal state.

A nonlinear effect enters the equations of motion as

    M q'' + C q' + K q + f_nl(q, q'; s) = B u,

where ``s`` is an optional internal state (e.g. the slider positions of a
stick-slip joint) that is *frozen* during the Newton iterations of a step and
*committed* once the step has converged. A checkpoint is a dict of arrays, so a
snapshot store can save it next to (q, v, a) and a run can resume bit-exactly.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import scipy.sparse as sp


class NonlinearForce:
    """Interface of a nonlinear internal force on the free dofs (size n).

    Subclasses implement :meth:`force` and :meth:`tangent`; stateful forces
    also override :meth:`initial_state`, :meth:`commit`, :meth:`checkpoint` and
    :meth:`restore`; conservative forces implement :meth:`potential` so that
    ``f_nl = dU/dq`` and the system energy includes ``U(q)``.
    """

    #: ``True`` when ``f_nl = grad U(q)`` (no velocity dependence, no state).
    conservative: bool = False
    #: ``True`` when ``f_nl`` depends on the velocity (its tangent has a dv block).
    velocity_dependent: bool = False

    def initial_state(self) -> Any:
        """Internal state at t = 0 (``None`` for a stateless force)."""
        return None

    def force(self, q: np.ndarray, v: np.ndarray, state: Any = None) -> np.ndarray:
        """(n,) ndarray: ``f_nl(q, v; state)``."""
        raise NotImplementedError

    def tangent(self, q: np.ndarray, v: np.ndarray, state: Any = None):
        """``(df/dq, df/dv)``: (n, n) sparse matrices; ``df/dv`` may be ``None``."""
        raise NotImplementedError

    def potential(self, q: np.ndarray) -> float:
        """Potential ``U(q)`` with ``grad U = f_nl`` (conservative forces only)."""
        raise NotImplementedError(f"{type(self).__name__} has no potential")

    def commit(self, q: np.ndarray, v: np.ndarray, state: Any) -> Any:
        """State after a converged step ending at (q, v)."""
        return state

    def checkpoint(self, state: Any) -> dict[str, np.ndarray]:
        """Arrays that restore ``state`` exactly."""
        return {}

    def restore(self, data: dict[str, np.ndarray]) -> Any:
        """Inverse of :meth:`checkpoint`."""
        return self.initial_state()


class LocalPotential(NonlinearForce):
    """Nodal potential ``U(q) = sum_i w_i phi(q_i)`` with its gradient and Hessian.

    With ``w`` the lumped-mass weights of a P1 (or finite-difference) grid this is
    the standard discretisation of ``int phi(q) dx``; e.g. sine-Gordon takes
    ``phi(q) = 1 - cos q`` so that ``f_nl = w * sin q``.

    Parameters
    ----------
    weights : (n,) ndarray
        Quadrature weights on the free dofs.
    phi, dphi, ddphi : callables
        The potential density and its first two derivatives, vectorised.
    """

    conservative = True

    def __init__(self, weights: np.ndarray, phi: Callable, dphi: Callable, ddphi: Callable):
        self.weights = np.asarray(weights, dtype=float)
        self.phi, self.dphi, self.ddphi = phi, dphi, ddphi

    @classmethod
    def sine_gordon(cls, weights: np.ndarray) -> "LocalPotential":
        """``phi(q) = 1 - cos q``: the sine-Gordon potential, ``f_nl = w sin q``."""
        return cls(weights, lambda q: 1.0 - np.cos(q), np.sin, np.cos)

    @classmethod
    def cubic(cls, weights: np.ndarray, coefficient: float) -> "LocalPotential":
        """``phi(q) = c q^4 / 4``: a hardening (c > 0) Duffing-type spring."""
        c = float(coefficient)
        return cls(weights, lambda q: 0.25 * c * q**4, lambda q: c * q**3,
                   lambda q: 3.0 * c * q**2)

    def force(self, q, v=None, state=None):
        return self.weights * self.dphi(q)

    def tangent(self, q, v=None, state=None):
        # a DIA matrix: cheap to build every Newton iteration (csr costs ~0.2 ms at n = 40)
        return sp.dia_matrix((self.weights * self.ddphi(q), 0), shape=(q.size, q.size)), None

    def potential(self, q) -> float:
        return float(self.weights @ self.phi(q))
