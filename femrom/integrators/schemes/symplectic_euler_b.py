"""Symplectic Euler B for canonical models: ``q`` drifted with the old ``p``, then ``p`` kicked."""

from __future__ import annotations

from femrom.integrators._scheme import Scheme, register_scheme
from femrom.integrators.schemes._canonical import drift, kick


@register_scheme
class SymplecticEulerB(Scheme):
    r"""Symplectic Euler (variant B) of ``H = q^T D_q q / 2 + p^T D_p p / 2``, first order, explicit:
    the adjoint of variant A (``q_{k+1} = q_k + h D_p p_k``, ``p_{k+1} = p_k - h D_q q_{k+1}``)."""

    name = "symplectic_euler_b"
    order = 1
    models = ("canonical",)

    def canonical_step_matrix(self, position, momentum, dt):
        h = float(dt)
        return drift(momentum, h, 1.0) @ kick(position, h, 1.0)
