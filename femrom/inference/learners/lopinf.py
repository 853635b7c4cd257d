"""Lagrangian operator inference."""

from femrom.inference._learner import register_learner
from femrom.inference._second_order import SecondOrderLearner


@register_learner("lopinf")
class LagrangianOpInf(SecondOrderLearner):
    r"""Lagrangian operator inference: every term keeps its structure (``K^ = K^^T >= eps I``, ``C^ = C^^T >= 0``).

    .. math::

        \min_{\hat K \succeq \varepsilon I,\; \hat C \succeq 0,\; \hat B}
        \big\| \hat M \ddot{\hat Q} + \hat F + \hat C \dot{\hat Q}
              + \hat K \hat Q - \hat B U \big\|_F^2 + \text{Tikhonov}

    (Sharma & Kramer, Physica D 462, 134128, 2024), with ``C^`` only when the
    caller names ``"damping"`` (or the system has it: :meth:`for_system`). A
    semidefinite program: ``solver=FastSolver()`` (default,
    :class:`~femrom.inference.FastSolver`) or the cvxpy reference
    ``ConicSolver("clarabel")`` / ``ConicSolver("scs")``. Parameters and attributes:
    :class:`SecondOrderLearner`.
    """

    structured = True
    method = "lagrangian_opinf"
