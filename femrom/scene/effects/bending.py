"""``bending``: Euler-Bernoulli bending of a line (Hermite elements)."""

from femrom.scene._effects import register_effect
from femrom.scene.effects.elasticity import Elasticity


@register_effect
class Bending(Elasticity):
    """``K q`` of Euler-Bernoulli bending, ``int E I w'' v'' dx`` (element ``hermite``).

    The same assembly as :class:`Elasticity` (the space knows both operators by name).
    """

    name = "bending"
