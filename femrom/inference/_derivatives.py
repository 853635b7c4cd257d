r"""Time derivatives of snapshot data by finite differences.

For a uniform grid ``t_k = t_0 + k dt`` the ``d``-th derivative at ``t_k`` is

.. math::

    \frac{d^d q}{dt^d}(t_k) \approx \frac{1}{dt^d} \sum_{j} w_j \, q_{k + s_j},

with integer offsets ``s_j`` and weights from the Taylor conditions
``sum_j w_j s_j^i / i! = delta_{i d}`` for ``i = 0, ..., len(s) - 1``.
Interior points use the symmetric central stencil of ``order + 1`` points
(for ``d = 1`` and ``d = 2`` alike);
the first and last few points use a one-sided window of ``order + d`` points,
which is of the same order ``order`` (a stencil of ``s`` points is exact on
polynomials of degree ``s - 1`` and so has error ``O(dt^{s - d})``).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from femrom._errors import FemromValueError

#: Orders of accuracy :func:`finite_difference` offers.
ORDERS = (2, 4, 6)
#: Derivatives it offers: first (velocity) and second (acceleration).
DERIVATIVES = (1, 2)


@functools.cache
def stencil_weights(offsets: tuple[int, ...], derivative: int) -> np.ndarray:
    """(s,) ndarray: weights of the ``derivative``-th derivative on integer ``offsets``.

    Solves the Taylor (Vandermonde) conditions
    ``sum_j w_j s_j^i / i! = delta_{i, derivative}`` for ``i = 0, ..., s - 1``
    in exact rational arithmetic (the systems are tiny and their floating-point
    Vandermonde matrices are ill-conditioned at eight points).
    """
    from fractions import Fraction

    s = len(offsets)
    if derivative >= s:
        raise FemromValueError(f"a {derivative}-th derivative needs more than {s} points")
    rows = [[Fraction(o) ** i / math.factorial(i) for o in offsets] for i in range(s)]
    rhs = [Fraction(int(i == derivative)) for i in range(s)]
    # Gauss-Jordan elimination with exact fractions
    for col in range(s):
        pivot = next(r for r in range(col, s) if rows[r][col] != 0)
        rows[col], rows[pivot] = rows[pivot], rows[col]
        rhs[col], rhs[pivot] = rhs[pivot], rhs[col]
        for r in range(s):
            if r != col and rows[r][col] != 0:
                factor = rows[r][col] / rows[col][col]
                rows[r] = [a - factor * b for a, b in zip(rows[r], rows[col])]
                rhs[r] -= factor * rhs[col]
    weights = np.array([float(rhs[i] / rows[i][i]) for i in range(s)])
    weights.setflags(write=False)
    return weights


def _central_offsets(order: int) -> tuple[int, ...]:
    # symmetric stencils of order p: p/2 points each side for d = 1 and d = 2 alike
    # (symmetry cancels the odd Taylor term, so 2 (p/2) + 1 points reach order p)
    half = order // 2
    return tuple(range(-half, half + 1))


def finite_difference(Q: np.ndarray, dt: float, order: int = 4, derivative: int = 1) -> np.ndarray:
    r"""Time derivative of snapshots ``Q`` (columns at uniform times) by finite differences.

    Central stencils of ``order`` inside; at the ``order/2`` first and last
    columns, one-sided windows of ``order + derivative`` points with the same
    order of accuracy.

    Parameters
    ----------
    Q : (r, K) ndarray (or (K,) for a single signal)
        Snapshots ``q(t_0), ..., q(t_{K-1})`` as columns.
    dt : float
        Uniform time step between columns.
    order : {2, 4, 6}
        Order of accuracy: the error is ``O(dt^order)`` at every column.
    derivative : {1, 2}
        ``1`` for ``q'``, ``2`` for ``q''``.

    Returns
    -------
    (r, K) ndarray (same shape as ``Q``)
        The derivative at every column.
    """
    if order not in ORDERS:
        raise FemromValueError(f"unknown finite-difference order {order}; valid: {ORDERS}")
    if derivative not in DERIVATIVES:
        raise FemromValueError(f"unknown derivative {derivative}; valid: {DERIVATIVES}")
    dt = float(dt)
    if not (dt > 0.0 and math.isfinite(dt)):
        raise FemromValueError(f"dt must be positive and finite, got {dt}")
    Q = np.asarray(Q, dtype=float)
    K = Q.shape[-1]
    width = order + derivative
    if K < width:
        raise FemromValueError(f"{K} snapshots are too few for an order-{order} derivative "
                               f"{derivative} (needs at least {width})")
    half = order // 2
    scale = dt ** derivative
    out = np.empty_like(Q)

    central = _central_offsets(order)
    weights = stencil_weights(central, derivative)
    interior = slice(half, K - half)
    acc = np.zeros(Q.shape[:-1] + (K - 2 * half,))
    for w, s in zip(weights, central):
        if w != 0.0:
            acc += w * Q[..., half + s: K - half + s]
    out[..., interior] = acc / scale

    # one-sided windows at both ends: the first `width` and last `width` columns
    for k in range(half):
        offsets = tuple(range(-k, width - k))
        w = stencil_weights(offsets, derivative)
        out[..., k] = Q[..., :width] @ w / scale
        # mirrored at the end: offsets -(width-1-k) .. k
        offsets_end = tuple(range(-(width - 1 - k), k + 1))
        w_end = stencil_weights(offsets_end, derivative)
        out[..., K - 1 - k] = Q[..., K - width:] @ w_end / scale
    return out
