"""The classical fourth-order Runge-Kutta method for first-order models (no structure kept)."""

from __future__ import annotations

from femrom.integrators._scheme import Scheme, register_scheme


@register_scheme
class RungeKutta4(Scheme):
    r"""Classical Runge-Kutta, order 4, explicit, for ``y' = f(y)``:

    .. math::

        y_{k+1} = y_k + \tfrac h6 (k_1 + 2 k_2 + 2 k_3 + k_4), \quad k_1 = f(y_k),\
        k_2 = f(y_k + \tfrac h2 k_1),\ k_3 = f(y_k + \tfrac h2 k_2),\ k_4 = f(y_k + h k_3).

    Neither symplectic nor energy-conserving: the unstructured baseline of the Hamiltonian ROMs.
    """

    name = "rk4"
    order = 4
    models = ("first_order",)

    def first_order_step(self, rhs, jacobian, y, h, newton):
        k1 = rhs(y)
        k2 = rhs(y + 0.5 * h * k1)
        k3 = rhs(y + 0.5 * h * k2)
        k4 = rhs(y + h * k3)
        return y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
