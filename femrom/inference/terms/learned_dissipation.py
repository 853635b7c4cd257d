r"""``dF^/dq^'``: a learned convex dissipation function's force (SpML)."""

from __future__ import annotations

import numpy as np

from femrom._errors import FemromValueError
from femrom.fem import CompiledScalar
from femrom.inference._networks import ConvexPowers, ScalarNetwork, ScalarSum
from femrom.inference._terms import ReducedTerm, register_term
from femrom.inference.terms.learned_potential import _PointCache


@register_term
class LearnedDissipation(ReducedTerm):
    r"""The force ``dF^/dq^'`` of a learned dissipation function ``F^ >= 0``, with tangent ``d^2F^/dq^'^2``.

    .. math::

        \hat{\mathcal F}(v) = \sum_k \tfrac13 |a_k \cdot v|^3 + \sum_k \tfrac14 (b_k \cdot v)^4
            + \big(N(v) - N(0) - \nabla N(0) \cdot v\big),

    ``N`` an input-convex network (:class:`ScalarNetwork` with non-negative
    hidden-to-hidden and output weights and a convex non-decreasing
    activation, Amos, Xu & Kolter, ICML 2017). Every part is convex with
    value and gradient zero at ``v = 0``, so ``F^`` is convex with its minimum
    ``0`` at ``v = 0``, and convexity gives

    .. math::

        0 = \hat{\mathcal F}(0) \ge \hat{\mathcal F}(v) + \nabla\hat{\mathcal F}(v) \cdot (0 - v)
        \;\Rightarrow\; v \cdot \nabla\hat{\mathcal F}(v) \ge \hat{\mathcal F}(v) \ge 0 :

    the power the force takes out is never negative, for any weights. The
    linear viscous part ``C^ v`` (the quadratic ``v^T C^ v / 2``) is the
    :class:`Damping` term's. Evaluated in numpy (no torch).

    Parameters
    ----------
    r : int
    powers : ConvexPowers, optional
    network : ScalarNetwork, optional
        Input-convex (checked: hidden-to-hidden and output weights >= 0, softplus).
    """

    name = "learned_dissipation"
    structure = "dissipative"
    order = 33

    def __init__(self, r: int, powers: ConvexPowers | None = None, network: ScalarNetwork | None = None):
        self._r = int(r)
        if network is not None:
            negative = [i for i, layer in enumerate(network.layers)
                        if layer.weight is not None and np.any(layer.weight < 0)]
            if negative or np.any(network.output < 0) or network.activation != "softplus":
                raise FemromValueError("learned dissipation: the network is not input-convex (negative hidden or "
                                 "output weights, or an activation other than softplus)")
        self.powers, self.network = powers, network
        self.function = ScalarSum((powers, network), self._r)
        self._at = _PointCache(self.function, "v")

    @property
    def r(self) -> int:
        return self._r

    @property
    def velocity_dependent(self) -> bool:
        return True

    def dissipation(self, v) -> float | np.ndarray:
        """``F^(v)`` for (r,) or at the columns of (r, K)."""
        v = np.asarray(v, dtype=float)
        return self._at.value(v) if v.ndim == 1 else self.function.value_gradient(v)[0]

    def force(self, q, v=None, state=None) -> np.ndarray:
        """(r,) ``dF^/dv`` (zero without a velocity)."""
        if v is None:
            return np.zeros(self._r)
        return self._at(np.asarray(v, dtype=float))[1].copy()

    def forces(self, Q: np.ndarray, Vel=None, starts=(0,)) -> np.ndarray:
        """(r, K) ``dF^/dv`` at the columns of ``Vel``."""
        if Vel is None:
            raise FemromValueError("learned dissipation: the forces need the velocities")
        return self.function.value_gradient(np.asarray(Vel, dtype=float))[1]

    def lhs(self, q, v=None, a=None, u=None, state=None):
        return self.force(q, v)

    def tangent(self, q, v=None, state=None):
        if v is None:
            return None, None
        return None, self._at(np.asarray(v, dtype=float))[2].copy()

    def target(self, data) -> np.ndarray:
        return self.forces(data.states, data.velocities)

    def compiled_scalar(self) -> CompiledScalar | None:
        """``F^`` as compiled kernels take it (:class:`femrom.fem.CompiledScalar`, argument ``"v"``), or ``None``
        when the compiled laws are off (:meth:`LearnedPotential.compiled_scalar`)."""
        return self._at.compiled()

    # -- storage ------------------------------------------------------------------------
    def save(self, group) -> None:
        group.attrs["r"] = self._r
        if self.powers is not None:
            group.create_dataset("cubic", data=self.powers.cubic)
            group.create_dataset("quartic", data=self.powers.quartic)
        if self.network is not None:
            self.network.save(group.create_group("network"))

    @classmethod
    def load(cls, group, **context) -> "LearnedDissipation":
        powers = ConvexPowers(group["cubic"][()], group["quartic"][()]) if "cubic" in group else None
        network = ScalarNetwork.load(group["network"]) if "network" in group else None
        return cls(int(group.attrs["r"]), powers, network)

    def describe(self) -> dict:
        return {"term": self.name, "structure": self.structure,
                "powers": None if self.powers is None else [int(self.powers.cubic.shape[0]),
                                                            int(self.powers.quartic.shape[0])],
                "network": None if self.network is None else
                [int(layer.bias.size) for layer in self.network.layers]}
