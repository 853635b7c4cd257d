r"""The condensed QP: the inputs are the only variables.

.. math::

    \min_U \; \sigma \left( U^T H U + 2 g^T U \right) \quad \text{s.t.} \quad -b \le u_j \le b,

with ``H`` and the maps that give ``g`` from the state, the reference window,
the previous input and the offsets computed once (:class:`~femrom.control.CondensedQP`);
``sigma = 1 / max(diag H)`` keeps the solver's stopping tests independent of the
units of the outputs. The state, reference, previous input and offsets enter
only the gradient ``g``, which is affine in them: the cvxpy problem has one
Parameter, ``g``, set from them in numpy each step. (Making each of them a
Parameter gives the same QP, but cvxpy then rebuilds ``g`` through a sparse
(m N, p N + ...) tensor on every solve, which measured slower.)

m N variables and a dense (m N, m N) Hessian: 300 variables at m = 6, N = 50,
whatever the state dimension.
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np

from femrom.control._formulation import CvxpyFormulation, box_constraints, register_formulation
from femrom.control._problem import CondensedQP


@register_formulation
class CondensedFormulation(CvxpyFormulation):
    """Inputs only, dense Hessian, the parameters folded into one gradient Parameter."""

    name = "condensed"

    def __init__(self, problem, config):
        super().__init__(problem, config)
        self.qp = CondensedQP.from_problem(problem)
        self.scale = self.qp.cost_scale()
        m, N = problem.n_inputs, problem.horizon
        self.inputs = cp.Variable(m * N, name="inputs")
        self.gradient = cp.Parameter(m * N, name="gradient")
        hessian = cp.psd_wrap(self.scale * self.qp.hessian)
        objective = cp.quad_form(self.inputs, hessian) + 2.0 * self.scale * (self.gradient @ self.inputs)
        self.problem = cp.Problem(cp.Minimize(objective), box_constraints(self.inputs, problem.bound, N))
        self.compiled()

    def set_parameters(self, state, reference, u_previous, state_offset, output_offset, terminal_state):
        self.gradient_ = self.qp.gradient(state, reference, u_previous, state_offset, output_offset, terminal_state)
        self.gradient.value = self.gradient_

    def plan(self) -> np.ndarray | None:
        value = self.inputs.value
        if value is None:
            return None
        return np.asarray(value).reshape(self.mpc_problem.horizon, self.mpc_problem.n_inputs).T
