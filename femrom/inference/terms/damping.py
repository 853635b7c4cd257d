"""``C^ q'``: linear viscous damping."""

from femrom.inference._terms import LinearTerm, register_term
from femrom.inference.terms._projection import symmetric_projection


@register_term
class Damping(LinearTerm):
    r"""``C^ q^'``: symmetric positive semidefinite (``V^T C V``); data block ``Q^'``."""

    name = "damping"
    effect = "damping"
    structure = "psd"
    learnable = True
    variable = "v"
    order = 10

    @classmethod
    def galerkin(cls, system, basis):
        return None if system.damping is None else cls(symmetric_projection(system.damping, basis))
