r"""Potentials of the known nonlinear terms.

- :class:`LocalPotential`: a nodal potential ``U(x) = sum_i w_i phi(x_i)`` on a
  force's local coordinates (all dofs of a chain, or the normal displacements
  of a boundary layer), with its gradient ``w phi'(x)`` and diagonal Hessian
  ``w phi''(x)``; the densities are named (:data:`DENSITIES`), so a potential
  saves to arrays and numbers and rebuilds from them.
- :class:`QuarticPotential`: the cubic NLS term of a canonical Hamiltonian,
  ``H_nl(q, p) = -(gamma / 4) sum_j (q_j^2 + p_j^2)^2``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from femrom._errors import FemromValueError
from femrom.fem._nonlinear import NonlinearForce, register_force


def _sine_gordon():
    return (lambda x: 1.0 - np.cos(x)), np.sin, np.cos


def _quartic(coefficient: float):
    c = float(coefficient)
    return (lambda x: 0.25 * c * x**4), (lambda x: c * x**3), (lambda x: 3.0 * c * x**2)


def _duffing(linear: float, cubic: float):
    k1, k3 = float(linear), float(cubic)
    return (lambda x: 0.5 * k1 * x**2 + 0.25 * k3 * x**4), (lambda x: k1 * x + k3 * x**3), \
        (lambda x: k1 + 3.0 * k3 * x**2)


#: Named densities ``phi``: name -> (builder of ``(phi, phi', phi'')`` from keyword parameters).
DENSITIES: dict[str, Callable] = {
    "sine_gordon": _sine_gordon,   # phi = 1 - cos x: the sine-Gordon chain, f = w sin x
    "quartic": _quartic,           # phi = c x^4 / 4: a hardening cubic spring, f = w c x^3
    "duffing": _duffing,           # phi = k1 x^2 / 2 + k3 x^4 / 4: a Duffing (Winkler + cubic) layer
}


@register_force
class LocalPotential(NonlinearForce):
    r"""``U(x) = sum_i w_i phi(x_i)`` on local coordinates ``x = L q``; ``g = w phi'(x)``.

    With ``w`` the lumped quadrature weights of a grid this is the standard
    discretisation of ``int phi(u) dx`` (a chain) or ``int_Gamma phi(u . n) dA``
    (a boundary layer); e.g. sine-Gordon takes ``phi(x) = 1 - cos x``.

    Parameters
    ----------
    weights : (s,) ndarray
        Quadrature weights of the local coordinates.
    phi, dphi, ddphi : callables
        The density and its first two derivatives, vectorised.
    dofs : (s,) int array, optional
        The dofs the coordinates are (default: all ``s`` dofs, ``n = s``).
    n_dofs : int, optional
        Size of the system (default ``s``; needed with ``dofs``).
    density : str, optional
        The :data:`DENSITIES` name ``phi`` came from, with its ``density_parameters``:
        what :meth:`parameters` saves.
    name : str, optional
    """

    kind = "local_potential"
    conservative = True
    columns = True

    def __init__(self, weights: np.ndarray, phi: Callable, dphi: Callable, ddphi: Callable, *,
                 dofs=None, n_dofs: int | None = None, density: str | None = None,
                 density_parameters: dict | None = None, name: str | None = None):
        self.weights = np.asarray(weights, dtype=float)
        if self.weights.ndim != 1:
            raise FemromValueError(f"weights must be (s,), got shape {self.weights.shape}")
        if dofs is not None and np.size(dofs) != self.weights.size:
            raise FemromValueError(f"{np.size(dofs)} dofs but {self.weights.size} weights")
        if n_dofs is None:
            if dofs is not None:
                raise FemromValueError("a potential on some dofs needs n_dofs, the system's size")
            n_dofs = self.weights.size
        super().__init__(n_dofs, dofs=dofs, name=name)
        self.phi, self.dphi, self.ddphi = phi, dphi, ddphi
        self.density = density
        self.density_parameters = dict(density_parameters or {})

    @classmethod
    def of_density(cls, density: str, weights: np.ndarray, *, dofs=None, n_dofs=None,
                   name: str | None = None, **parameters) -> "LocalPotential":
        """A potential with a named density of :data:`DENSITIES` (e.g. ``"duffing", linear=, cubic=``)."""
        if density not in DENSITIES:
            raise FemromValueError(f"unknown potential density {density!r}; valid: {', '.join(DENSITIES)}")
        phi, dphi, ddphi = DENSITIES[density](**parameters)
        return cls(weights, phi, dphi, ddphi, dofs=dofs, n_dofs=n_dofs, density=density,
                   density_parameters=parameters, name=name)

    @classmethod
    def sine_gordon(cls, weights: np.ndarray, **placement) -> "LocalPotential":
        """``phi(x) = 1 - cos x``: the sine-Gordon potential, ``g = w sin x``."""
        return cls.of_density("sine_gordon", weights, **placement)

    @classmethod
    def cubic(cls, weights: np.ndarray, coefficient: float, **placement) -> "LocalPotential":
        """``phi(x) = c x^4 / 4``: a hardening (c > 0) Duffing-type spring, ``g = w c x^3``."""
        return cls.of_density("quartic", weights, coefficient=coefficient, **placement)

    def local_force(self, x, xdot=None, state=None):
        w = self.weights if np.ndim(x) == 1 else self.weights[:, None]
        return w * self.dphi(x)

    def local_tangent(self, x, xdot=None, state=None):
        return self.weights * self.ddphi(x), None

    def local_potential(self, x) -> float:
        return float(self.weights @ self.phi(x))

    def parameters(self):
        if self.density is None:
            return None
        return {"kind": self.kind, "density": self.density, "weights": self.weights, "name": self.name,
                **{f"density.{k}": v for k, v in self.density_parameters.items()}, **self._placement()}

    @classmethod
    def from_parameters(cls, parameters):
        placement = cls._placement_from(parameters)
        if "local_map" in placement:
            raise FemromValueError("a LocalPotential is placed on dofs, not through a general map")
        density = {k.split(".", 1)[1]: float(v) for k, v in parameters.items() if k.startswith("density.")}
        dofs = placement["dofs"]
        full = dofs.size == placement["n_dofs"] and np.array_equal(dofs, np.arange(dofs.size))
        return cls.of_density(str(parameters["density"]), np.asarray(parameters["weights"], dtype=float),
                              dofs=None if full else dofs, n_dofs=None if full else placement["n_dofs"],
                              name=str(parameters.get("name", "local_potential")), **density)


@dataclass(frozen=True)
class QuarticPotential:
    r"""``H_nl = -(gamma / 4) sum_j (q_j^2 + p_j^2)^2``: the cubic NLS term.

    With ``psi = q + i p`` and ``D_q = D_p = -Laplacian``, Hamilton's equations
    are ``i psi_t + psi_xx + gamma |psi|^2 psi = 0`` on the grid. A potential
    of a canonical system (:class:`femrom.integrators.CanonicalSystem`):
    ``value``, ``gradient`` and ``hessian`` (diagonal blocks ``H_qq, H_qp, H_pp``).
    """

    gamma: float

    def value(self, q: np.ndarray, p: np.ndarray):
        w = q * q + p * p
        return -0.25 * self.gamma * np.sum(w * w, axis=0)

    def gradient(self, q: np.ndarray, p: np.ndarray):
        w = q * q + p * p
        return -self.gamma * w * q, -self.gamma * w * p

    def hessian(self, q: np.ndarray, p: np.ndarray):
        w = q * q + p * p
        g = -self.gamma
        return g * (w + 2 * q * q), g * (2 * q * p), g * (w + 2 * p * p)
