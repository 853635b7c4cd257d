r"""The sparse QP: states and inputs are variables, the dynamics equality constraints.

.. math::

    \min_{Z, U} \; \sigma \sum_{j=0}^{N-1} \Big[ \| L_Q (C z_j + D u_j + w_y - r_j) \|^2
        + \| L_R u_j \|^2 + \| L_S (u_j - u_{j-1}) \|^2 \Big] + \sigma \| L_P (z_N - z_T) \|^2

    \text{s.t.}\quad z_0 = \hat z, \quad z_{j+1} = A z_j + B u_j + w_z, \quad -b \le u_j \le b,

with ``L^T L`` the weights and ``sigma`` the condensed form's scale (so both
formulations stop on the same tests). The state ``z_0``, the reference window
(p, N), the previous input and the offsets are cvxpy Parameters of a DPP
problem: compiled once, re-solved with new values. n (N + 1) + m N variables
and a banded KKT system: the size grows with the state dimension n.
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np

from femrom.control._formulation import CvxpyFormulation, box_constraints, register_formulation
from femrom.control._problem import CondensedQP, square_root


@register_formulation
class SparseFormulation(CvxpyFormulation):
    """States and inputs, the dynamics as constraints; every datum a cvxpy Parameter."""

    name = "sparse"

    def __init__(self, problem, config):
        super().__init__(problem, config)
        A, B, C, D, N = problem.A, problem.B, problem.C, problem.D, problem.horizon
        n, m, p = problem.n_states, problem.n_inputs, problem.n_outputs
        self.scale = CondensedQP.from_problem(problem).cost_scale()
        root = np.sqrt(self.scale)
        self.states = cp.Variable((n, N + 1), name="states")
        self.inputs = cp.Variable((m, N), name="inputs")
        self.state = cp.Parameter(n, name="state")
        self.reference = cp.Parameter((p, N), name="reference")
        self.u_previous = cp.Parameter((m, 1), name="u_previous")
        self.state_offset = cp.Parameter((n, 1), name="state_offset")
        self.output_offset = cp.Parameter((p, 1), name="output_offset")
        ones = np.ones((1, N))
        Z, U = self.states, self.inputs
        outputs = C @ Z[:, :N] + D @ U + self.output_offset @ ones
        cost = cp.sum_squares(root * square_root(problem.Q) @ (outputs - self.reference))
        if np.any(problem.R):
            cost += cp.sum_squares(root * square_root(problem.R) @ U)
        if problem.S is not None:
            moves = U - cp.hstack([self.u_previous, U[:, :N - 1]]) if N > 1 else U - self.u_previous
            cost += cp.sum_squares(root * square_root(problem.S) @ moves)
        self.terminal_state = None
        if problem.P is not None:
            self.terminal_state = cp.Parameter(n, name="terminal_state")
            cost += cp.sum_squares(root * square_root(problem.P) @ (Z[:, N] - self.terminal_state))
        constraints = [Z[:, 0] == self.state,
                       Z[:, 1:] == A @ Z[:, :N] + B @ U + self.state_offset @ ones]
        constraints += box_constraints(cp.vec(U, order="F"), problem.bound, N)
        self.problem = cp.Problem(cp.Minimize(cost), constraints)
        self.compiled()

    def set_parameters(self, state, reference, u_previous, state_offset, output_offset, terminal_state):
        self.state.value = state
        self.reference.value = reference
        self.u_previous.value = u_previous[:, None]
        self.state_offset.value = state_offset[:, None]
        self.output_offset.value = output_offset[:, None]
        if self.terminal_state is not None:
            self.terminal_state.value = terminal_state

    def plan(self) -> np.ndarray | None:
        value = self.inputs.value
        return None if value is None else np.asarray(value)
