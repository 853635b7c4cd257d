r"""Scalar functions of reduced coordinates with exact gradients and Hessians, in numpy.

The learned potential and dissipation of :class:`~femrom.inference.SpML` are
scalar functions ``phi(x)`` of ``x in R^r`` (``q^`` or ``q^'``); a reduced
scheme needs ``phi``, ``grad phi`` (the force) and ``hess phi`` (the Newton
tangent) at one point per Newton iteration, and a learner's diagnostics need
the forces at many columns. The weights are trained elsewhere (torch, only
when fitting) and evaluated here, so a fitted model steps and loads without
torch.

- :class:`SymmetricPolynomial`: ``sum_m alpha_m x^m`` over an explicit list
  of multi-indices of degree 3 and 4, held as symmetric tensors ``T3``, ``T4``:
  ``phi = T3[x,x,x] + T4[x,x,x,x]``, ``grad = 3 T3[x,x,.] + 4 T4[x,x,x,.]``,
  ``hess = 6 T3[x,.,.] + 12 T4[x,x,.,.]``;
- :class:`ConvexPowers`: ``sum_k |a_k . x|^3 / 3 + sum_k (b_k . x)^4 / 4``,
  convex, zero with zero gradient at ``x = 0``;
- :class:`ScalarNetwork`: a multilayer perceptron ``x -> c . h_L`` with
  ``h_l = sigma(W_l h_{l-1} + U_l x + b_l)`` (``U_l``: input skips, as in an
  input-convex network), shifted by its value and gradient at 0.

The Hessian of a network is exact: the affine maps have none, so
``hess = sum_l J_l^T diag(delta_l * sigma''(z_l)) J_l`` with ``J_l = dz_l/dx``
(forward) and ``delta_l = d phi / d h_l`` (backward).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations_with_replacement, permutations

import numpy as np

from femrom._errors import FemromValueError

#: Columns evaluated together by the batched methods (bounds the r^3 x chunk buffers).
CHUNK = 1024


def multi_indices(r: int, degree: int) -> np.ndarray:
    """(n, degree) int ndarray: the monomials ``x_i x_j ... `` of one degree, ``i <= j <= ...``."""
    return np.array(list(combinations_with_replacement(range(r), degree)), dtype=np.int64).reshape(-1, degree)


def monomials(X: np.ndarray, degree: int) -> np.ndarray:
    """(K, n) ndarray: the monomials of one degree (:func:`multi_indices` order) at the rows of ``X`` (K, r)."""
    index = multi_indices(X.shape[1], degree)
    out = np.ones((X.shape[0], index.shape[0]))
    for j in range(degree):
        out *= X[:, index[:, j]]
    return out


def derivative_map(r: int, degree: int):
    """``(m, p, i, e)`` int arrays: monomial ``m`` of ``degree`` differentiated in ``x_i`` is ``e``
    times monomial ``p`` of ``degree - 1`` (:func:`multi_indices` orders), one row per pair."""
    lower = {tuple(p): k for k, p in enumerate(multi_indices(r, degree - 1).tolist())}
    rows = []
    for m, index in enumerate(multi_indices(r, degree).tolist()):
        for i in sorted(set(index)):
            reduced = list(index)
            reduced.remove(i)
            rows.append((m, lower[tuple(reduced)], i, index.count(i)))
    return tuple(np.array(c, dtype=np.int64) for c in zip(*rows))


def symmetric_tensor(r: int, indices: np.ndarray, coefficients: np.ndarray) -> np.ndarray:
    """The symmetric tensor ``T`` with ``T[x, ..., x] = sum_m c_m prod_j x_{i_mj}``."""
    degree = indices.shape[1]
    T = np.zeros((r,) * degree)
    for index, c in zip(indices, coefficients):
        perms = set(permutations(index.tolist()))
        for p in perms:
            T[p] = c / len(perms)
    return T


class SymmetricPolynomial:
    r"""``phi(x) = sum_m alpha_m prod_j x_{i_mj}`` over monomials of degree 3 and 4.

    Parameters
    ----------
    r : int
    terms : dict
        ``{degree: (indices (n, degree) int ndarray, coefficients (n,) ndarray)}``
        for degrees in (3, 4).
    """

    DEGREES = (3, 4)

    def __init__(self, r: int, terms: dict):
        self.r = int(r)
        self.terms = {}
        for degree, (indices, coefficients) in sorted(terms.items()):
            if degree not in self.DEGREES:
                raise FemromValueError(f"polynomial degree {degree} is not one of {self.DEGREES}")
            indices = np.asarray(indices, dtype=np.int64).reshape(-1, degree)
            coefficients = np.asarray(coefficients, dtype=float).ravel()
            if indices.shape[0] != coefficients.size or (indices.size and indices.max() >= self.r):
                raise FemromValueError(f"degree-{degree} monomials: {indices.shape[0]} index rows for "
                                       f"{coefficients.size} coefficients in r = {self.r}")
            self.terms[int(degree)] = (indices, coefficients)
        zero = np.zeros((self.r,) * 3), np.zeros((self.r,) * 4)
        self.T3 = symmetric_tensor(self.r, *self.terms[3]) if 3 in self.terms else zero[0]
        self.T4 = symmetric_tensor(self.r, *self.terms[4]) if 4 in self.terms else zero[1]

    def value_gradient_hessian(self, x: np.ndarray):
        """``(phi, grad (r,), hess (r, r))`` at one point ``x`` (r,)."""
        B4 = (self.T4 @ x) @ x                 # T4[x, x, ., .]
        B3 = self.T3 @ x                       # T3[x, ., .]
        c4, c3 = B4 @ x, B3 @ x
        return float(c3 @ x + c4 @ x), 3.0 * c3 + 4.0 * c4, 6.0 * B3 + 12.0 * B4

    def value(self, x: np.ndarray) -> float:
        """``phi`` at one point ``x`` (r,)."""
        c3 = (self.T3 @ x) @ x
        return float(c3 @ x + (((self.T4 @ x) @ x) @ x) @ x)

    def value_gradient(self, X: np.ndarray):
        """``(phi (K,), grad (r, K))`` at the columns of ``X`` (r, K)."""
        r, K = X.shape
        values, grads = np.empty(K), np.empty((r, K))
        T3, T4 = self.T3.reshape(r * r, r), self.T4.reshape(r * r * r, r)
        for s in range(0, K, CHUNK):
            Xc = X[:, s:s + CHUNK]
            k = Xc.shape[1]
            c3 = np.einsum("ijk,jk->ik", (T3 @ Xc).reshape(r, r, k), Xc)
            c4 = np.einsum("ijk,jk->ik", np.einsum("ijk,jk->ik", (T4 @ Xc).reshape(r * r, r, k), Xc)
                           .reshape(r, r, k), Xc)
            values[s:s + k] = np.sum((c3 + c4) * Xc, axis=0)
            grads[:, s:s + k] = 3.0 * c3 + 4.0 * c4
        return values, grads


class ConvexPowers:
    r"""``phi(x) = sum_k |a_k . x|^3 / 3 + sum_k (b_k . x)^4 / 4``: convex, ``phi(0) = 0``, ``grad phi(0) = 0``.

    Parameters
    ----------
    cubic : (n3, r) ndarray
        Rows ``a_k``.
    quartic : (n4, r) ndarray
        Rows ``b_k``.
    """

    def __init__(self, cubic: np.ndarray, quartic: np.ndarray):
        self.cubic = np.atleast_2d(np.asarray(cubic, dtype=float))
        self.quartic = np.atleast_2d(np.asarray(quartic, dtype=float))
        if self.cubic.shape[1] != self.quartic.shape[1]:
            raise FemromValueError(f"convex powers: cubic rows have {self.cubic.shape[1]} entries, quartic "
                                   f"{self.quartic.shape[1]}")
        self.r = self.cubic.shape[1]

    def value_gradient_hessian(self, x: np.ndarray):
        A, B = self.cubic, self.quartic
        s, t = A @ x, B @ x
        value = float(np.sum(np.abs(s) ** 3) / 3.0 + np.sum(t ** 4) / 4.0)
        grad = A.T @ (np.abs(s) * s) + B.T @ t ** 3
        hess = A.T @ ((2.0 * np.abs(s))[:, None] * A) + B.T @ ((3.0 * t * t)[:, None] * B)
        return value, grad, hess

    def value(self, x: np.ndarray) -> float:
        s, t = self.cubic @ x, self.quartic @ x
        return float(np.sum(np.abs(s) ** 3) / 3.0 + np.sum(t ** 4) / 4.0)

    def value_gradient(self, X: np.ndarray):
        S, T = self.cubic @ X, self.quartic @ X
        values = np.sum(np.abs(S) ** 3, axis=0) / 3.0 + np.sum(T ** 4, axis=0) / 4.0
        return values, self.cubic.T @ (np.abs(S) * S) + self.quartic.T @ T ** 3


def _tanh(z):
    t = np.tanh(z)
    d = 1.0 - t * t
    return t, d, -2.0 * t * d


def _softplus(z):
    s = 0.5 * (1.0 + np.tanh(0.5 * z))          # the logistic function, without overflow
    return np.logaddexp(0.0, z), s, s * (1.0 - s)


#: Activations by name: ``z -> (sigma, sigma', sigma'')``.
ACTIVATIONS = {"tanh": _tanh, "softplus": _softplus}


@dataclass(frozen=True, eq=False)
class NetworkLayer:
    """``z = W h_prev + U x + b`` (``W`` absent in the first layer, ``U`` optional after it)."""

    bias: np.ndarray
    weight: np.ndarray | None = None
    input_weight: np.ndarray | None = None


class ScalarNetwork:
    r"""``phi(x) = N(x) - N(0) - grad N(0) . x`` with ``N(x) = c . h_L``, ``h_l = sigma(W_l h_{l-1} + U_l x + b_l)``.

    The shift makes ``phi(0) = 0`` and ``grad phi(0) = 0``: a learned
    potential keeps the equilibrium at ``q^ = 0``, a learned dissipation
    function its minimum at ``q^' = 0``.

    Parameters
    ----------
    layers : sequence of NetworkLayer
    output : (w_L,) ndarray
        ``c``.
    activation : {"tanh", "softplus"}
    """

    def __init__(self, layers, output: np.ndarray, activation: str):
        if activation not in ACTIVATIONS:
            raise FemromValueError(f"unknown activation {activation!r}; valid: {', '.join(ACTIVATIONS)}")
        self.layers = tuple(layers)
        if not self.layers or self.layers[0].input_weight is None or self.layers[0].weight is not None:
            raise FemromValueError("a network's first layer takes the input only (input_weight, no weight)")
        self.output = np.asarray(output, dtype=float).ravel()
        self.activation = activation
        self._sigma = ACTIVATIONS[activation]
        self.r = self.layers[0].input_weight.shape[1]
        zero = np.zeros(self.r)
        self.value0, self.gradient0, _ = self._raw(zero, hessian=False)

    def _raw(self, x: np.ndarray, hessian: bool = True):
        sigma = self._sigma
        derivatives, Js, h, Jh = [], [], None, None
        for layer in self.layers:
            if layer.weight is None:
                z = layer.bias + layer.input_weight @ x
                J = layer.input_weight
            else:
                z = layer.bias + layer.weight @ h
                J = layer.weight @ Jh
                if layer.input_weight is not None:
                    z = z + layer.input_weight @ x
                    J = J + layer.input_weight
            s, ds, dds = sigma(z)
            derivatives.append((ds, dds))
            Js.append(J)
            h, Jh = s, ds[:, None] * J
        value = float(self.output @ h)
        grad, H = np.zeros(self.r), np.zeros((self.r, self.r)) if hessian else None
        delta = self.output
        for layer, (ds, dds), J in zip(reversed(self.layers), reversed(derivatives), reversed(Js)):
            dz = delta * ds
            if hessian:
                H += J.T @ ((delta * dds)[:, None] * J)
            if layer.input_weight is not None:
                grad += layer.input_weight.T @ dz
            if layer.weight is not None:
                delta = layer.weight.T @ dz
        return value, grad, H

    def value(self, x: np.ndarray) -> float:
        h = None
        for layer in self.layers:
            z = layer.bias.copy()
            if layer.weight is not None:
                z += layer.weight @ h
            if layer.input_weight is not None:
                z += layer.input_weight @ x
            h = self._sigma(z)[0]
        return float(self.output @ h) - self.value0 - float(self.gradient0 @ x)

    def value_gradient_hessian(self, x: np.ndarray):
        value, grad, H = self._raw(np.asarray(x, dtype=float))
        return value - self.value0 - float(self.gradient0 @ x), grad - self.gradient0, H

    def value_gradient(self, X: np.ndarray):
        """``(phi (K,), grad (r, K))`` at the columns of ``X`` (r, K)."""
        sigma = self._sigma
        zs, h = [], None
        for layer in self.layers:
            z = layer.bias[:, None] + 0.0
            if layer.weight is not None:
                z = z + layer.weight @ h
            if layer.input_weight is not None:
                z = z + layer.input_weight @ X
            zs.append(z)
            h = sigma(z)[0]
        values = self.output @ h
        grad = np.zeros_like(X)
        delta = np.broadcast_to(self.output[:, None], h.shape)
        for layer, z in zip(reversed(self.layers), reversed(zs)):
            dz = delta * sigma(z)[1]
            if layer.input_weight is not None:
                grad += layer.input_weight.T @ dz
            if layer.weight is not None:
                delta = layer.weight.T @ dz
        return values - self.value0 - self.gradient0 @ X, grad - self.gradient0[:, None]

    def hessians(self, X: np.ndarray) -> np.ndarray:
        """(K, r, r) the Hessians at the columns of ``X`` (r, K), all at once (``value_gradient_hessian``'s
        third output, column by column)."""
        sigma = self._sigma
        K = X.shape[1]
        derivatives, Js, h, Jh = [], [], None, None
        for layer in self.layers:
            if layer.weight is None:
                z = layer.bias[:, None] + layer.input_weight @ X
                J = np.broadcast_to(layer.input_weight, (K,) + layer.input_weight.shape)
            else:
                z = layer.bias[:, None] + layer.weight @ h
                J = np.matmul(layer.weight, Jh)
                if layer.input_weight is not None:
                    z = z + layer.input_weight @ X
                    J = J + layer.input_weight
            s, ds, dds = sigma(z)
            derivatives.append((ds, dds))
            Js.append(J)
            h, Jh = s, ds.T[:, :, None] * J               # (K, w, r)
        H = np.zeros((K, self.r, self.r))
        delta = np.broadcast_to(self.output[:, None], h.shape)
        for layer, (ds, dds), J in zip(reversed(self.layers), reversed(derivatives), reversed(Js)):
            H += np.matmul(np.swapaxes(J, 1, 2), (delta * dds).T[:, :, None] * J)
            if layer.weight is not None:
                delta = layer.weight.T @ (delta * ds)
        return H

    # -- storage ------------------------------------------------------------------------
    def save(self, group) -> None:
        group.attrs["activation"] = self.activation
        group.attrs["n_layers"] = len(self.layers)
        group.create_dataset("output", data=self.output)
        for i, layer in enumerate(self.layers):
            sub = group.create_group(f"layer_{i}")
            sub.create_dataset("bias", data=layer.bias)
            for name in ("weight", "input_weight"):
                if getattr(layer, name) is not None:
                    sub.create_dataset(name, data=getattr(layer, name))

    @classmethod
    def load(cls, group) -> "ScalarNetwork":
        layers = []
        for i in range(int(group.attrs["n_layers"])):
            sub = group[f"layer_{i}"]
            layers.append(NetworkLayer(sub["bias"][()], *(sub[name][()] if name in sub else None
                                                   for name in ("weight", "input_weight"))))
        return cls(layers, group["output"][()], str(group.attrs["activation"]))


class ScalarSum:
    """The sum of scalar functions (each with ``value_gradient_hessian`` and ``value_gradient``)."""

    def __init__(self, parts, r: int):
        self.parts = tuple(p for p in parts if p is not None)
        self.r = int(r)

    def value_gradient_hessian(self, x: np.ndarray):
        value, grad, hess = 0.0, np.zeros(self.r), np.zeros((self.r, self.r))
        for part in self.parts:
            v, g, h = part.value_gradient_hessian(x)
            value, grad, hess = value + v, grad + g, hess + h
        return value, grad, hess

    def value(self, x: np.ndarray) -> float:
        return float(sum(part.value(x) for part in self.parts))

    def value_gradient(self, X: np.ndarray):
        values, grads = np.zeros(X.shape[1]), np.zeros(X.shape)
        for part in self.parts:
            v, g = part.value_gradient(X)
            values, grads = values + v, grads + g
        return values, grads


def packed_parts(function: ScalarSum) -> tuple:
    """``function``'s parts as the arrays :class:`femrom.fem.CompiledScalar` holds (empty for an absent part)."""
    r = function.r
    T3, T4 = np.zeros((0, 0, 0)), np.zeros((0, 0, 0, 0))
    A, B = np.zeros((0, r)), np.zeros((0, r))
    network = None
    for part in function.parts:
        if isinstance(part, SymmetricPolynomial) and T3.size == 0:
            T3, T4 = part.T3, part.T4
        elif isinstance(part, ConvexPowers) and A.size == 0:
            A, B = part.cubic, part.quartic
        elif isinstance(part, ScalarNetwork) and network is None:
            network = part
        else:
            raise FemromValueError(f"no compiled form for a sum with {type(part).__name__} twice or unknown")
    ints = np.zeros(0, dtype=np.int64)
    widths, has_w, has_u, b_off, w_off, u_off = ints, ints, ints, np.zeros(1, dtype=np.int64), ints, ints
    bias, W, U, output, activation, value0, grad0 = (np.zeros(0),) * 4 + (0, 0.0, np.zeros(r))
    if network is not None:
        layers = network.layers
        widths = np.array([layer.bias.size for layer in layers], dtype=np.int64)
        has_w = np.array([layer.weight is not None for layer in layers], dtype=np.int64)
        has_u = np.array([layer.input_weight is not None for layer in layers], dtype=np.int64)
        b_off = np.concatenate([[0], np.cumsum(widths)]).astype(np.int64)
        w_sizes = [0 if layer.weight is None else layer.weight.size for layer in layers]
        u_sizes = [0 if layer.input_weight is None else layer.input_weight.size for layer in layers]
        w_off = np.concatenate([[0], np.cumsum(w_sizes)[:-1]]).astype(np.int64)
        u_off = np.concatenate([[0], np.cumsum(u_sizes)[:-1]]).astype(np.int64)
        flat = lambda name: np.concatenate([np.zeros(0)] + [np.asarray(getattr(layer, name), dtype=float).ravel()
                                                            for layer in layers if getattr(layer, name) is not None])
        bias, W, U = flat("bias"), flat("weight"), flat("input_weight")
        output, activation = network.output, ("tanh", "softplus").index(network.activation)
        value0, grad0 = float(network.value0), network.gradient0
    arrays = [np.ascontiguousarray(a, dtype=float) for a in (T3, T4, A, B)]
    ints = [np.ascontiguousarray(a, dtype=np.int64) for a in (widths, has_w, has_u, b_off, w_off, u_off)]
    floats = [np.ascontiguousarray(a, dtype=float) for a in (bias, W, U, output)]
    return (*arrays, *ints, *floats, int(activation), float(value0), np.ascontiguousarray(grad0, dtype=float))
