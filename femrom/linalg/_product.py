r"""Inner products <x, y>_W = x^T W y for an SPD W (a mass matrix, lumped or consistent).

Three kinds, each with the orthonormalisation that suits it:

- Euclidean (W = I): Householder QR (as a tall-skinny QR, :func:`householder_qr`).
- Diagonal (lumped mass, given as a 1-D array w > 0): Householder QR of
  W^{1/2} Y, then Q = W^{-1/2} Q_B. Exact change of variables, as stable as
  the Euclidean case.
- General sparse (or small dense) SPD matrix: Householder QR Y = Q_0 R_0 in
  the Euclidean product, then two Cholesky-QR passes in the W product
  (CholQR2): G = Q^T W Q = L L^T, Q <- Q L^{-T}. Because Q_0 is Euclidean
  orthonormal, cond(Q_0^T W Q_0) <= cond(W), so the Cholesky factorisation
  is safe while cond(W) << 1/eps (mass matrices: cond(W) is mesh-grading
  bound, typically 1e1 - 1e4); the second pass restores W-orthonormality to
  machine precision (Yamamoto, Nakatsukasa, Yanagisawa & Fukaya, ETNA 44,
  2015, CholeskyQR2). No square root or Cholesky factor of W is formed.
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from femrom._errors import FemromValueError


_TSQR_ROWS = 4096  # rows per leaf of the tall-skinny QR (a leaf of 30 columns is ~1 MB)
_CONTROLLER: list = []  # threadpoolctl's controller, made once (it scans the loaded libraries)


def single_threaded_blas():
    """A context in which BLAS/LAPACK run on one thread (threadpoolctl; no-op without it).

    For many small factorisations: a LAPACK QR of a 4096 x 30 leaf with
    OpenBLAS's two threads was 6x slower than with one on this 2-core machine
    under load (threads spinning at every panel's barrier), and 17x for the
    whole TSQR of a 2e4 x 30 block (benchmarks/snapshot_ladder.py, docs/benchmarks_snapshots.md).
    """
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency of the env
        return contextlib.nullcontext()
    if not _CONTROLLER:
        _CONTROLLER.append(ThreadpoolController())
    return _CONTROLLER[0].limit(limits=1, user_api="blas")


def householder_qr(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reduced QR of a tall (n, k) ``y`` by a two-level tall-skinny QR (TSQR).

    Leaves of 4096 rows are factorised in cache, their stacked R factors once
    more, and Q is assembled leaf by leaf (Demmel, Grigori, Hoemmen & Langou,
    SISC 34(1), 2012). As stable as Householder QR of the whole block, and about
    4x faster than ``numpy.linalg.qr`` at n = 2e5, k = 30 (whose panel
    factorisation streams the full block from memory once per column).
    """
    n, k = y.shape
    with single_threaded_blas():
        return _tsqr(y, n, k)


def _tsqr(y, n, k):
    if n < 4 * _TSQR_ROWS or n < 4 * k:
        return np.linalg.qr(y)
    starts = range(0, n, _TSQR_ROWS)
    leaves = [np.linalg.qr(y[i:i + _TSQR_ROWS]) for i in starts]
    q_top, r = np.linalg.qr(np.vstack([leaf_r for _, leaf_r in leaves]))
    q = np.empty((n, r.shape[0]))
    offset = 0
    for i, (leaf_q, leaf_r) in zip(starts, leaves):
        q[i:i + leaf_q.shape[0]] = leaf_q @ q_top[offset:offset + leaf_r.shape[0]]
        offset += leaf_r.shape[0]
    return q, r


class InnerProduct:
    """The SPD inner product x^T W y, with W = I, diag(w) or a sparse matrix.

    Parameters
    ----------
    product : None, (n,) array or (n, n) sparse/dense SPD matrix
        ``None`` for the Euclidean product, a positive 1-D array for a
        lumped (diagonal) mass, a symmetric matrix otherwise.

    Attributes
    ----------
    kind : str
        ``"euclidean"``, ``"diagonal"`` or ``"matrix"``.
    n : int or None
        Dimension (``None`` for the Euclidean product).
    matrix : the ``product`` as given (``None``, array or matrix).
    """

    def __init__(self, product: Any = None):
        self.matrix = product
        self._weights = self._sqrt_weights = None
        if isinstance(product, InnerProduct):
            product = product.matrix
            self.matrix = product
        if product is None:
            self.kind, self.n = "euclidean", None
        elif sp.issparse(product) or (isinstance(product, np.ndarray) and product.ndim == 2):
            shape = product.shape
            if shape[0] != shape[1]:
                raise FemromValueError(f"inner-product matrix must be square, got shape {shape}")
            asym = abs(product - product.T).max()
            scale = abs(product).max()
            if not scale > 0 or asym > 1e-10 * scale:
                raise FemromValueError(f"inner-product matrix must be symmetric positive definite "
                                       f"(max |W - W^T| = {asym:.3g}, max |W| = {scale:.3g})")
            self.kind, self.n = "matrix", shape[0]
            self.matrix = product.tocsr() if sp.issparse(product) else np.asarray(product, float)
        else:
            weights = np.asarray(product, dtype=np.float64)
            if weights.ndim != 1:
                raise FemromValueError(f"a lumped (diagonal) product is a 1-D array, got shape {weights.shape}")
            if not np.all(weights > 0):
                raise FemromValueError(f"lumped product weights must all be > 0 "
                                       f"(min = {weights.min():.3g})")
            self.kind, self.n = "diagonal", weights.size
            self._weights = weights
            self._sqrt_weights = np.sqrt(weights)

    @property
    def is_euclidean(self) -> bool:
        return self.kind == "euclidean"

    @property
    def sqrt_weights(self) -> np.ndarray:
        """(n,) square roots of a diagonal product's weights."""
        if self.kind != "diagonal":
            raise FemromValueError(f"only a diagonal product has square-root weights, this one is {self.kind}")
        return self._sqrt_weights

    def check_dimension(self, n: int) -> None:
        """Raise if the product's dimension differs from ``n``."""
        if self.n is not None and self.n != n:
            raise FemromValueError(f"inner product has dimension {self.n} but the data have n = {n} rows")

    def apply(self, x: np.ndarray) -> np.ndarray:
        """W x for (n,) or (n, k) ``x``."""
        if self.kind == "euclidean":
            return x
        if self.kind == "diagonal":
            return self._weights * x if x.ndim == 1 else self._weights[:, None] * x
        return np.asarray(self.matrix @ x)

    def gram(self, x: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        """x^T W y (``y = x`` when omitted)."""
        y = x if y is None else y
        return x.T @ self.apply(y)

    def squared_norm(self, x: np.ndarray) -> float:
        """||x||_W^2 = trace(x^T W x) for (n,) or (n, k) ``x`` (Frobenius in the W product)."""
        if self.kind == "euclidean":
            flat = x.ravel(order="K")  # no copy for C- or F-contiguous blocks
            return float(flat @ flat)
        wx = self.apply(x)
        return float(np.dot(x, wx) if x.ndim == 1 else np.einsum("ij,ij->", x, wx))

    def orthonormalize(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Q (n, k) with Q^T W Q = I and R (k, k) upper triangular with Y = Q R.

        Y (n, k) with n >= k. See the module doc for the method per kind.
        """
        if self.kind == "euclidean":
            return householder_qr(y)
        if self.kind == "diagonal":
            q, r = householder_qr(self._sqrt_weights[:, None] * y)
            return q / self._sqrt_weights[:, None], r
        q, r = householder_qr(y)
        for _ in range(2):  # CholQR2 in the W product
            lower = np.linalg.cholesky(self.gram(q))
            q = sla.solve_triangular(lower, q.T, lower=True).T
            r = lower.T @ r
        return q, r

    def __repr__(self) -> str:
        return f"InnerProduct(kind={self.kind!r}, n={self.n})"
