"""``- f^_0``: a constant load (gravity, a preload), projected or learned."""

from femrom.inference._terms import LinearTerm, register_term


@register_term
class ConstantLoad(LinearTerm):
    r"""``- f^_0``: a constant force on the right side, ``V^T f_0`` intrusively; data block ``-1``.

    A model about a reference state ``q_0`` (:meth:`femrom.scene.SecondOrderSystem.about`)
    carries ``f_0 - K q_0`` here: zero when the reference is an equilibrium of the linear part.
    """

    name = "constant_load"
    effect = "load"
    structure = "free"
    learnable = True
    variable = "1"
    sign = -1.0
    order = 50

    @classmethod
    def galerkin(cls, system, basis):
        return None if system.load is None else cls(basis.T @ system.load)
