r"""How far a QP solver's plan can be from the MPC problem's optimum, and a repair when it is too far.

Every formulation solves the same strictly convex, box-constrained QP in the inputs
(:class:`~femrom.control.CondensedQP`)

.. math::

    \min_U f(U) = \tfrac12 U^T H U + g^T U \quad \text{s.t.} \quad l \le U \le h,

(``U^T H U + 2 g^T U`` halved: the same minimiser). Its optimum ``U*`` is unique, and
a plan ``U`` that satisfies the bounds is certified by its projected-gradient step
``G(U) = L (U - \Pi(U - \nabla f(U) / L))``: for ``f`` ``mu``-strongly convex and
``L``-smooth (``mu``, ``L`` the extreme eigenvalues of ``H``),

.. math::

    \|U - U^*\|_2 \le \frac{2}{\mu} \|G(U)\|_2

(from ``<G(U), U - U*> >= |G|^2 / (2L) + mu |U - U*|^2 / 2``; Beck, *First-Order Methods
in Optimization*, 2017, Thm. 10.29 with Lemma 10.4). The bound uses the problem's own
matrices, so it holds whatever the solver's scaling and stopping rule. A solver that
stops on residuals of its own scaled problem can return, on a badly conditioned QP
(``cond H`` of 1e9 and more), a plan whose first move is 100 % off while it reports
``optimal`` (``tests/test_mpc_accuracy.py``).

A plan that fails the certificate is repaired by the primal-dual active-set method
(Hintermüller, Ito and Kunisch, SIAM J. Optim. 13 (2002) 865-888) started from it: guess
the active bounds from ``U`` and the multipliers, solve the equality-constrained QP on the
free inputs by Cholesky, repeat until the active set repeats (a few iterations from a
plan near the optimum); the result is certified again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

#: Active-set iterations of a repair before it gives up.
REPAIR_ITERATIONS = 50


@dataclass(frozen=True, eq=False)
class PlanCertificate:
    r"""The certificate and the repair of plans of one condensed QP (module docstring).

    Attributes
    ----------
    hessian : (M, M) ndarray
        ``H`` of ``f`` (``M = m N``).
    lower, upper : (M,) ndarray
        ``l``, ``h`` (``-inf``, ``inf`` for unbounded inputs).
    smallest, largest : float
        ``mu`` and ``L``: the extreme eigenvalues of ``H``.
    """

    hessian: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    smallest: float
    largest: float

    @classmethod
    def from_hessian(cls, hessian: np.ndarray, bound: np.ndarray, horizon: int) -> "PlanCertificate":
        """For ``H`` (m N, m N) and the per-input bounds ``b`` (m,): ``|u_{j,i}| <= b_i``."""
        limits = np.tile(np.asarray(bound, dtype=float), int(horizon))
        values = np.linalg.eigvalsh(hessian)
        return cls(hessian=hessian, lower=-limits, upper=limits, smallest=float(values[0]),
                   largest=float(values[-1]))

    @property
    def condition(self) -> float:
        """``L / mu`` (``inf`` if ``H`` is not definite)."""
        return self.largest / self.smallest if self.smallest > 0 else float("inf")

    def round_off_bound(self) -> float:
        """The relative bound that round-off alone leaves a computed optimum: ``||H U + g||`` of
        about ``eps L ||U||`` gives ``2 eps cond(H)`` (and a multiple of ``M``, summed rows)."""
        return 2.0 * np.finfo(float).eps * self.condition * np.sqrt(self.hessian.shape[0])

    def error_bound(self, plan: np.ndarray, gradient: np.ndarray) -> float:
        r"""An upper bound of ``||U - U*||_2`` (``inf`` if ``U`` leaves the bounds or ``H`` is not definite).

        Parameters
        ----------
        plan : (M,) ndarray
            ``U``.
        gradient : (M,) ndarray
            ``g``.
        """
        if not self.smallest > 0 or np.any(plan < self.lower) or np.any(plan > self.upper):
            return float("inf")
        slope = self.hessian @ plan + gradient
        step = plan - np.clip(plan - slope / self.largest, self.lower, self.upper)
        return 2.0 * self.largest * float(np.linalg.norm(step)) / self.smallest

    def repair(self, plan: np.ndarray, gradient: np.ndarray) -> np.ndarray | None:
        """The optimum by the primal-dual active-set method from ``plan``; ``None`` if it does not settle."""
        H, g, lo, hi = self.hessian, gradient, self.lower, self.upper
        u = np.clip(plan, lo, hi)
        weight = np.diag(H)                          # c of the active-set rule, per input: H's scale
        previous = None
        for _ in range(REPAIR_ITERATIONS):
            multiplier = -(H @ u + g)                # lambda with grad f + lambda = 0 on the active set
            at_upper = multiplier + weight * (u - hi) > 0
            at_lower = multiplier + weight * (u - lo) < 0
            active = (at_upper.tobytes(), at_lower.tobytes())
            if active == previous:
                return u
            previous = active
            u = np.where(at_upper, hi, np.where(at_lower, lo, 0.0))
            free = ~(at_upper | at_lower)
            if free.any():
                fixed = ~free
                rhs = -(g[free] + H[np.ix_(free, fixed)] @ u[fixed])
                try:
                    u[free] = sla.cho_solve(sla.cho_factor(H[np.ix_(free, free)]), rhs)
                except np.linalg.LinAlgError:
                    return None
        return None
