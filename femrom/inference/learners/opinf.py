"""Plain second-order operator inference (the baseline)."""

from femrom.inference._learner import register_learner
from femrom.inference._second_order import SecondOrderLearner


@register_learner("opinf")
class SecondOrderOpInf(SecondOrderLearner):
    r"""Plain second-order operator inference: ordinary (Tikhonov) least squares.

    .. math::

        \min_{\hat K, \hat C, \hat B}
        \big\| \hat M \ddot{\hat Q} + \hat F + \hat C \dot{\hat Q}
              + \hat K \hat Q - \hat B U \big\|_F^2 + \text{Tikhonov},

    no symmetry or definiteness: the baseline structure preservation must
    beat. Parameters and attributes: :class:`SecondOrderLearner`.
    """

    structured = False
    method = "plain_opinf"
