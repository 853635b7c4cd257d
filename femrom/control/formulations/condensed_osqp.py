r"""The condensed QP handed to OSQP directly: the same problem, without cvxpy's per-solve work.

The QP is the ``"condensed"`` one (:class:`~femrom.control.CondensedQP`,
``sigma (U^T H U + 2 g^T U)`` with ``-b <= u_j <= b``), set up once in OSQP as
``P = 2 sigma H`` (upper triangle), ``A`` the rows of the identity of the bounded
inputs; a step writes only the new linear term ``q = 2 sigma g`` (``update(q=)``)
and solves, warm-started from the last solution. One factorisation of the KKT
matrix, at set-up, unless OSQP's adaptive step size asks for another.

cvxpy solves the same QP (the ``"condensed"`` formulation) but, on every solve,
rebuilds the solver's data from its parameter map and compares the dense
Hessian entry by entry with the previous one: at m N = 300 that is several
milliseconds a step (``benchmarks/mpc_solve.py``), more than OSQP's own solve.
Only OSQP (``solver=QPSolver("osqp")``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.control._formulation import QPFormulation, QPSolution, register_formulation
from femrom.control._problem import CondensedQP

_STATUSES = {"solved": "optimal", "solved inaccurate": "optimal_inaccurate",
             "primal infeasible": "infeasible", "primal infeasible inaccurate": "infeasible_inaccurate",
             "dual infeasible": "unbounded", "dual infeasible inaccurate": "unbounded_inaccurate",
             "maximum iterations reached": "user_limit", "run time limit reached": "user_limit"}


@register_formulation
class CondensedOSQPFormulation(QPFormulation):
    """The condensed QP in an ``osqp.OSQP`` solver object, updated in place each step."""

    name = "condensed_osqp"

    def __init__(self, problem, config):
        super().__init__(problem, config)
        if config.solver.name != "osqp":
            raise FemromValueError(f"formulation 'condensed_osqp' solves with OSQP only, got solver "
                                   f"{config.solver.name!r}")
        import osqp

        self.qp = CondensedQP.from_problem(problem)
        self.scale = self.qp.cost_scale()
        m, N = problem.n_inputs, problem.horizon
        limits = np.tile(problem.bound, N)
        bounded = np.flatnonzero(np.isfinite(limits))
        P = sp.triu(sp.csc_matrix(2.0 * self.scale * self.qp.hessian), format="csc")
        A = sp.identity(m * N, format="csc")[bounded]
        self.solver = osqp.OSQP()
        self.solver.setup(P=P, q=np.zeros(m * N), A=sp.csc_matrix(A), l=-limits[bounded], u=limits[bounded],
                          **config.solver.osqp_settings())
        self._q = np.zeros(m * N)

    def set_parameters(self, state, reference, u_previous, state_offset, output_offset, terminal_state):
        self.gradient_ = self.qp.gradient(state, reference, u_previous, state_offset, output_offset, terminal_state)
        self._q = 2.0 * self.scale * self.gradient_

    def solve(self) -> QPSolution:
        self.solver.update(q=self._q)
        try:
            result = self.solver.solve(raise_error=False)
        except Exception as err:  # an OSQP error is a failed solve for the controller's policy
            return QPSolution(f"error: {err}", None, float("nan"), -1)
        status = _STATUSES.get(result.info.status, result.info.status)
        plan = None
        if status in ("optimal", "optimal_inaccurate") and result.x is not None:
            N, m = self.mpc_problem.horizon, self.mpc_problem.n_inputs
            plan = np.asarray(result.x, dtype=float).reshape(N, m).T
        return QPSolution(status, plan, float(result.info.solve_time), int(result.info.iter))
