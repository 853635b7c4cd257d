"""Symplectic Euler A for canonical models: ``p`` kicked with the old ``q``, then ``q`` drifted."""

from __future__ import annotations

from femrom.integrators._scheme import Scheme, register_scheme
from femrom.integrators.schemes._canonical import drift, kick


@register_scheme
class SymplecticEulerA(Scheme):
    r"""Symplectic Euler (variant A) of ``H = q^T D_q q / 2 + p^T D_p p / 2``, first order, explicit.

    ``p_{k+1} = p_k - h D_q q_k``, ``q_{k+1} = q_k + h D_p p_{k+1}``: conserves a modified
    Hamiltonian (an ``O(h)`` oscillation of ``H``, no drift; Hairer, Lubich & Wanner, Geometric
    Numerical Integration, VI.3).
    """

    name = "symplectic_euler_a"
    order = 1
    models = ("canonical",)

    def canonical_step_matrix(self, position, momentum, dt):
        h = float(dt)
        return kick(position, h, 1.0) @ drift(momentum, h, 1.0)
