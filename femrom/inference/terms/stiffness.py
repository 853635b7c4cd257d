"""``K^ q``: linear stiffness."""

from femrom.inference._terms import LinearTerm, register_term
from femrom.inference.terms._projection import symmetric_projection


@register_term
class Stiffness(LinearTerm):
    r"""``K^ q^``: symmetric positive definite (``V^T K V``; ``K^ >= eps I`` when learned); data block ``Q^``."""

    name = "stiffness"
    effect = "stiffness"
    structure = "spd"
    learnable = True
    variable = "q"
    order = 20

    @classmethod
    def galerkin(cls, system, basis):
        return cls(symmetric_projection(system.stiffness, basis))
