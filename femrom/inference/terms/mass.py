"""``M^ q''``: the reduced mass."""

from femrom.inference._terms import LinearTerm, register_term
from femrom.inference.terms._projection import symmetric_projection


@register_term
class Mass(LinearTerm):
    r"""``M^ q^''`` with ``M^ = V^T M V`` (symmetric positive definite).

    A mass-orthonormal basis has ``M^ = I``: a model without a mass term has
    the identity. Learners take the mass as known (the identity, or a given
    ``V^T M V`` for a Euclidean basis): it moves to the regression's target.
    """

    name = "mass"
    effect = "inertia"
    structure = "spd"
    variable = "a"
    order = 0

    @classmethod
    def galerkin(cls, system, basis):
        return cls(symmetric_projection(system.mass, basis))
