r"""``dU^/dq^``: a learned potential's force (SpML)."""

from __future__ import annotations

import numpy as np

from femrom._errors import FemromValueError
from femrom.fem import CompiledScalar, compiled_scalar_kernels
from femrom.inference._networks import ScalarNetwork, ScalarSum, SymmetricPolynomial, packed_parts
from femrom.inference._terms import ReducedTerm, register_term


class _PointCache:
    """The last point's ``(value, gradient, hessian)``: a scheme asks for the force and then
    the tangent at the same point, which is one evaluation. With the compiled laws on
    (:func:`femrom.fem.use_compiled_laws`) it is the compiled kernel's (``scalar_vgh`` of
    :func:`femrom.fem.compiled_scalar_kernels`), else the numpy reference's."""

    def __init__(self, function, argument: str):
        self.function, self.argument = function, argument
        self.x, self.result, self.kernels, self._compiled = None, None, None, None

    def compiled(self) -> CompiledScalar | None:
        """The function as compiled kernels take it, or ``None`` with the compiled laws off."""
        if compiled_scalar_kernels() is None:
            return None
        if self._compiled is None:
            self._compiled = CompiledScalar(self.function.r, self.argument, packed_parts(self.function))
        return self._compiled

    def _hit(self, x, kernels) -> bool:
        return self.x is not None and kernels is self.kernels and np.array_equal(self.x, x)

    def __call__(self, x):
        kernels = compiled_scalar_kernels()
        if not self._hit(x, kernels):
            if kernels is None:
                self.result = self.function.value_gradient_hessian(x)
            else:
                r = self.function.r
                grad, hess = np.empty(r), np.empty((r, r))
                value = kernels.scalar_vgh(np.ascontiguousarray(x, dtype=float), self.compiled().parts, True,
                                           grad, hess)
                self.result = (value, grad, hess)
            self.x, self.kernels = np.array(x, dtype=float), kernels
        return self.result

    def value(self, x) -> float:
        """``phi(x)`` (from the cache at its point, else the value alone)."""
        kernels = compiled_scalar_kernels()
        if self._hit(x, kernels):
            return self.result[0]
        if kernels is None:
            return self.function.value(x)
        grad = np.empty(self.function.r)
        return kernels.scalar_vgh(np.ascontiguousarray(x, dtype=float), self.compiled().parts, False, grad,
                                  np.empty((0, 0)))


@register_term
class LearnedPotential(ReducedTerm):
    r"""The force ``dU^/dq^`` of a learned nonlinear reduced potential, with tangent ``d^2U^/dq^2``.

    .. math::

        \hat U(\hat q) = \sum_{|m| \in \{3, 4\}} \alpha_m \hat q^m
            + \big(N(\hat q) - N(0) - \nabla N(0) \cdot \hat q\big),

    monomials of degree 3 and 4 (:class:`SymmetricPolynomial`) and a network
    ``N`` (:class:`ScalarNetwork`, the weighted sum ``sum_i lambda_i U_i`` of
    the seed's MLP outputs is its last layer). Degree 2 is ``K^ q^``'s (a
    separate term); the shift keeps ``U^(0) = 0`` and ``dU^/dq^(0) = 0``, so
    ``q^ = 0`` stays an equilibrium. The force is an exact gradient
    (``conservative``): ``v^T M^ v / 2 + q^T K^ q / 2 + U^(q)`` is the energy a
    discrete-gradient scheme keeps (:mod:`femrom.rom.schemes.discrete_gradient`).
    Fitted by :class:`~femrom.inference.SpML`; evaluated without torch: compiled (numba,
    :meth:`compiled_scalar`) with the compiled laws on, else in numpy (the reference).

    Parameters
    ----------
    r : int
    polynomial : SymmetricPolynomial, optional
    network : ScalarNetwork, optional
    """

    name = "learned_potential"
    structure = "gradient"
    order = 32

    def __init__(self, r: int, polynomial: SymmetricPolynomial | None = None,
                 network: ScalarNetwork | None = None):
        self._r = int(r)
        self.polynomial, self.network = polynomial, network
        for part in (polynomial, network):
            if part is not None and part.r != self._r:
                raise FemromValueError(f"learned potential: a part has r = {part.r}, expected {self._r}")
        self.function = ScalarSum((polynomial, network), self._r)
        self._at = _PointCache(self.function, "q")

    @property
    def r(self) -> int:
        return self._r

    @property
    def conservative(self) -> bool:
        return True

    def potential(self, q) -> float | np.ndarray:
        """``U^(q)`` for (r,) or at the columns of (r, K)."""
        q = np.asarray(q, dtype=float)
        return self._at.value(q) if q.ndim == 1 else self.function.value_gradient(q)[0]

    def force(self, q, v=None, state=None) -> np.ndarray:
        """(r,) ``dU^/dq^``."""
        return self._at(np.asarray(q, dtype=float))[1].copy()

    def forces(self, Q: np.ndarray, Vel=None, starts=(0,)) -> np.ndarray:
        """(r, K) ``dU^/dq^`` at the columns of ``Q``."""
        return self.function.value_gradient(np.asarray(Q, dtype=float))[1]

    def lhs(self, q, v=None, a=None, u=None, state=None):
        return self.force(q)

    def tangent(self, q, v=None, state=None):
        return self._at(np.asarray(q, dtype=float))[2].copy(), None

    def target(self, data) -> np.ndarray:
        return self.forces(data.states)

    def compiled_scalar(self) -> CompiledScalar | None:
        """``U^`` as compiled kernels take it (:class:`femrom.fem.CompiledScalar`, argument ``"q"``), or ``None``
        when the compiled laws are off: a discrete-gradient step of a model whose nonlinear terms all offer
        one runs in one compiled call (:mod:`femrom.integrators`)."""
        return self._at.compiled()

    # -- storage ------------------------------------------------------------------------
    def save(self, group) -> None:
        group.attrs["r"] = self._r
        if self.polynomial is not None:
            sub = group.create_group("polynomial")
            for degree, (indices, coefficients) in self.polynomial.terms.items():
                sub.create_dataset(f"indices_{degree}", data=indices)
                sub.create_dataset(f"coefficients_{degree}", data=coefficients)
        if self.network is not None:
            self.network.save(group.create_group("network"))

    @classmethod
    def load(cls, group, **context) -> "LearnedPotential":
        r = int(group.attrs["r"])
        polynomial = None
        if "polynomial" in group:
            sub = group["polynomial"]
            polynomial = SymmetricPolynomial(r, {d: (sub[f"indices_{d}"][()], sub[f"coefficients_{d}"][()])
                                                 for d in SymmetricPolynomial.DEGREES if f"indices_{d}" in sub})
        network = ScalarNetwork.load(group["network"]) if "network" in group else None
        return cls(r, polynomial, network)

    def describe(self) -> dict:
        return {"term": self.name, "structure": self.structure,
                "monomials": {str(d): int(i.shape[0]) for d, (i, _) in
                              (self.polynomial.terms.items() if self.polynomial else [])},
                "network": None if self.network is None else
                [int(layer.bias.size) for layer in self.network.layers]}
