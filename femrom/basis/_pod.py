r"""Proper orthogonal decomposition in an SPD inner product (mass-weighted POD).

For snapshots A = [a_1 ... a_K] (n, K) and an SPD product W (identity,
lumped or consistent mass), the rank-r POD basis V (n, r) solves

.. math::
    \min_{V^T W V = I_r} \|A - V V^T W A\|_W^2, \qquad \|X\|_W^2 = \operatorname{tr}(X^T W X),

and is given by the r leading left singular vectors of W^{1/2} A mapped back
by W^{-1/2}; the minimum is the tail energy sum_{i > r} sigma_i^2. The
retained energy is sum_{i <= r} sigma_i^2 / ||A||_W^2 and the relative
projection error sqrt(1 - retained energy).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg as sla

from femrom._errors import FemromTypeError, FemromValueError, positive_integer
from femrom.linalg import (
    InnerProduct,
    LowRankSVD,
    StreamingSketch,
    as_block_source,
    randomized_svd,
    randomized_svd_dask,
)

METHODS = ("auto", "svd", "randomized", "streaming", "dask")


def _is_dask_array(data: Any) -> bool:
    return type(data).__module__.split(".")[0] == "dask"


def _choose_method(data: Any) -> str:
    if isinstance(data, StreamingSketch):
        return "streaming"
    if _is_dask_array(data) or isinstance(data, (str, Path)):
        return "dask"
    if isinstance(data, np.ndarray):
        return "svd"
    return "randomized"


def exact_svd(data: np.ndarray, inner: InnerProduct) -> LowRankSVD:
    r"""Thin SVD of W^{1/2} A for an in-memory A (n, K), as A = U diag(s) Vt with U^T W U = I.

    Euclidean and diagonal W: LAPACK SVD (of W^{1/2} A). Sparse W with n >= K:
    A = Q R with Q^T W Q = I (Householder + CholQR2, :class:`InnerProduct`),
    then the SVD of R (K, K). Sparse W with n < K (small n): dense Cholesky
    W = L L^T and the SVD of L^T A.
    """
    a = np.asarray(data, dtype=np.float64)
    if a.ndim != 2:
        raise FemromValueError(f"snapshot matrix must be 2-D (n, K), got shape {a.shape}")
    inner.check_dimension(a.shape[0])
    if inner.kind == "euclidean":
        u, s, vt = np.linalg.svd(a, full_matrices=False)
    elif inner.kind == "diagonal":
        sqrt_w = inner.sqrt_weights[:, None]
        u, s, vt = np.linalg.svd(sqrt_w * a, full_matrices=False)
        u = u / sqrt_w
    elif a.shape[0] >= a.shape[1]:
        q, r = inner.orthonormalize(a)
        u_r, s, vt = np.linalg.svd(r)
        u = q @ u_r
    else:
        matrix = inner.matrix.toarray() if hasattr(inner.matrix, "toarray") else inner.matrix
        lower = np.linalg.cholesky(matrix)
        u, s, vt = np.linalg.svd(lower.T @ a, full_matrices=False)
        u = sla.solve_triangular(lower.T, u, lower=False)
    return LowRankSVD(U=u, s=s, Vt=vt, passes=1, total_energy=inner.squared_norm(a),
                      n_columns=a.shape[1], sketch_size=s.size, method="svd")


def truncation_rank(singular_values: np.ndarray, total_energy: float, *, rank: int | None = None,
                    energy: float | None = None, tolerance: float | None = None) -> int:
    r"""The rank r picked by exactly one criterion.

    ``rank``: r itself. ``energy``: the smallest r with
    sum_{i<=r} s_i^2 / total >= energy. ``tolerance``: the smallest r with
    relative projection error sqrt(1 - sum_{i<=r} s_i^2 / total) <= tolerance.
    When the available singular values do not reach the criterion, warns
    and returns their number.
    """
    given = [name for name, value in (("rank", rank), ("energy", energy), ("tolerance", tolerance))
             if value is not None]
    if len(given) != 1:
        raise FemromValueError(f"give exactly one of rank, energy, tolerance (got {given or 'none'})")
    available = singular_values.size
    if rank is not None:
        rank = positive_integer(rank, "rank")
        if not rank <= available:
            raise FemromValueError(f"rank {rank} is not in 1..{available} (singular values available)")
        return int(rank)
    if energy is not None:
        if not 0 < energy <= 1:
            raise FemromValueError(f"energy must be in (0, 1], got {energy}")
        target, label = float(energy), f"energy {energy}"
    else:
        if not 0 <= tolerance < 1:
            raise FemromValueError(f"tolerance must be in [0, 1), got {tolerance}")
        target, label = 1.0 - float(tolerance) ** 2, f"tolerance {tolerance}"
    retained = np.cumsum(singular_values**2) / total_energy if total_energy > 0 else np.ones(available)
    # Round-off: the cumulative energy of a full SVD reaches 1 only to ~1e-15.
    reached = np.flatnonzero(retained >= target * (1 - 1e-13))
    if reached.size == 0:
        warnings.warn(f"{label} not reached with {available} singular values (retained energy "
                      f"{retained[-1]:.12g}); increase max_rank", RuntimeWarning, stacklevel=3)
        return available
    return int(reached[0]) + 1


class POD:
    r"""Proper orthogonal decomposition, optionally in a mass inner product.

    Parameters
    ----------
    rank : int, optional
        Basis size r. Give exactly one of ``rank``, ``energy``, ``tolerance``.
    energy : float, optional
        Smallest r retaining this fraction of sum sigma_i^2 = ||A||_W^2.
    tolerance : float, optional
        Smallest r whose relative projection error of the training snapshots,
        ||A - V V^T W A||_W / ||A||_W, is at most this.
    product : None, (n,) array or (n, n) sparse matrix
        SPD inner product W (lumped or consistent mass); V^T W V = I.
    method : {"auto", "svd", "randomized", "streaming", "dask"}
        ``"svd"``: exact, in-memory array. ``"randomized"``: multi-pass
        out-of-core (:func:`~femrom.linalg.randomized_svd`). ``"streaming"``:
        single pass (:class:`~femrom.linalg.StreamingSketch`; ``fit`` also
        takes an already fed sketch). ``"dask"``:
        :func:`~femrom.linalg.randomized_svd_dask`. ``"auto"``: streaming for
        a sketch, dask for a dask array or an HDF5 path, svd for an ndarray,
        randomized otherwise.
    max_rank : int, optional
        Rank computed by the randomized methods when truncating by energy or
        tolerance (required then).
    oversampling, power_iterations, seed, block_columns
        Passed to the randomized methods.
    scheme : {"pass_efficient", "classical"}, optional
        Last-pass scheme of the multi-pass ``"randomized"`` method (see
        :func:`~femrom.linalg.randomized_svd`; ``None``: its default). Only
        that method has it: giving it with another method raises.
    options : dict, optional
        Extra keyword arguments for the chosen method (e.g. ``dataset``,
        ``scheduler`` for dask; ``range_size``, ``test_matrix`` for streaming).

    Attributes
    ----------
    basis_ : (n, r) ndarray
        V, with V^T W V = I.
    singular_values_ : (m,) ndarray
        All singular values computed (m >= r), decreasing.
    rank_ : int
        r.
    total_energy_ : float
        ||A||_W^2 (exact for every method: accumulated in the first pass).
    retained_energy_ : float
        sum_{i<=r} sigma_i^2 / ||A||_W^2.
    projection_error_ : float
        sqrt(1 - retained_energy_): the relative W-Frobenius projection error
        of the training snapshots (exact for "svd" and for "randomized" with
        scheme "classical", whose sigma_i are those of V^T W A; an upper bound
        for scheme "pass_efficient", whose sigma_i are those of
        W^{1/2} A P_Z with ||V^T W A||_F >= ||V^T W A P_Z||_F, equal once the
        iteration has converged; an estimate for "streaming").
    svd_ : LowRankSVD
        The decomposition (with ``passes`` and ``method``).
    inner_product_ : InnerProduct
        The product the basis is orthonormal in.
    """

    def __init__(self, rank: int | None = None, *, energy: float | None = None,
                 tolerance: float | None = None, product: Any = None, method: str = "auto",
                 max_rank: int | None = None, oversampling: int = 10, power_iterations: int = 2,
                 seed: int = 0, block_columns: int | None = None, scheme: str | None = None,
                 options: dict | None = None):
        if method not in METHODS:
            raise FemromValueError(f"unknown POD method {method!r}; valid: {', '.join(METHODS)}")
        given = [v for v in (rank, energy, tolerance) if v is not None]
        if len(given) != 1:
            raise FemromValueError("give exactly one of rank, energy, tolerance")
        positive_integer(rank, "rank", optional=True)
        for name, value in (("energy", energy), ("tolerance", tolerance)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))
                                      or not np.isfinite(value)):
                raise FemromValueError(f"{name} must be a finite number, got {value!r}")
        self.rank, self.energy, self.tolerance = rank, energy, tolerance
        self.product = product
        self.method = method
        self.max_rank = max_rank
        self.oversampling, self.power_iterations = oversampling, power_iterations
        self.seed, self.block_columns = seed, block_columns
        self.scheme = scheme
        self.options = dict(options or {})

    # -- fitting -------------------------------------------------------------

    def _computed_rank(self, method: str) -> int:
        if self.rank is not None:
            return int(self.rank) if self.max_rank is None else max(int(self.rank), int(self.max_rank))
        if self.max_rank is None:
            raise FemromValueError(f"method {method!r} with energy/tolerance truncation needs max_rank "
                                   "(the largest rank it may pick)")
        return int(self.max_rank)

    def _decompose(self, data: Any, method: str, inner: InnerProduct) -> LowRankSVD:
        if self.scheme is not None and method != "randomized":
            raise FemromValueError(f"scheme={self.scheme!r} applies to method 'randomized' only, "
                                   f"this POD uses {method!r}")
        if method == "svd":
            if not isinstance(data, np.ndarray):
                raise FemromTypeError(f"method 'svd' needs an in-memory ndarray, got {type(data).__name__}; "
                                      "use method='randomized' for block sources")
            # the one path that reads no blocks (those are checked as they are read)
            if data.dtype.kind not in "fiu":
                raise FemromValueError(f"POD: snapshots must be real numbers, got dtype {data.dtype}")
            if not np.all(np.isfinite(data)):
                bad = np.argwhere(~np.isfinite(data))[0]
                raise FemromValueError(f"POD: snapshot column {bad[1]} is not finite (row {bad[0]})")
            return exact_svd(data, inner)
        if method == "randomized":
            scheme = {} if self.scheme is None else {"scheme": self.scheme}
            return randomized_svd(data, self._computed_rank(method), oversampling=self.oversampling,
                                  power_iterations=self.power_iterations, product=inner.matrix,
                                  seed=self.seed, block_columns=self.block_columns, **scheme,
                                  **self.options)
        if method == "dask":
            return randomized_svd_dask(data, self._computed_rank(method), oversampling=self.oversampling,
                                       power_iterations=self.power_iterations, product=inner.matrix,
                                       seed=self.seed, **self.options)
        rank = self._computed_rank(method)
        if isinstance(data, StreamingSketch):
            sketch = data
            if (inner.kind, inner.n) != (sketch.product.kind, sketch.product.n):
                raise FemromValueError(f"the sketch was built with product {sketch.product}, "
                                       f"this POD has {inner}")
        else:
            opts = dict(self.options)
            sketch = None
            for block in as_block_source(data, block_columns=self.block_columns).blocks():
                if sketch is None:
                    sketch = StreamingSketch(block.shape[0], rank, seed=self.seed,
                                             product=inner.matrix, **opts)
                sketch.update(block)
            if sketch is None:
                raise FemromValueError("the snapshot source yielded no columns")
        return sketch.finalize(rank)

    def fit(self, data: Any) -> "POD":
        """Compute the basis from snapshots.

        Parameters
        ----------
        data : (n, K) array, block source, StreamingSketch, dask array or HDF5 path
            The snapshot matrix, or a way to read it (see ``method``).

        Returns
        -------
        self
        """
        method = _choose_method(data) if self.method == "auto" else self.method
        product = self.product
        if product is None and isinstance(data, StreamingSketch):
            product = data.product.matrix
        inner = InnerProduct(product)
        svd = self._decompose(data, method, inner)
        if not svd.total_energy > 0:
            raise FemromValueError("POD: every snapshot is zero; there is nothing to build a basis from")
        rank = truncation_rank(svd.s, svd.total_energy, rank=self.rank, energy=self.energy,
                               tolerance=self.tolerance)
        self.svd_ = svd
        self.inner_product_ = inner
        self.basis_ = svd.U[:, :rank]
        self.singular_values_ = svd.s
        self.rank_ = rank
        self.total_energy_ = svd.total_energy
        retained = float(np.sum(svd.s[:rank] ** 2) / svd.total_energy) if svd.total_energy > 0 else 1.0
        self.retained_energy_ = min(retained, 1.0)
        self.projection_error_ = float(np.sqrt(max(0.0, 1.0 - retained)))
        return self

    # -- using ---------------------------------------------------------------

    def _check_fitted(self) -> None:
        if not hasattr(self, "basis_"):
            raise AttributeError("POD is not fitted: call fit(snapshots) first")

    def _check_rows(self, states: np.ndarray) -> np.ndarray:
        states = np.asarray(states, dtype=np.float64)
        if states.shape[0] != self.basis_.shape[0]:
            raise FemromValueError(f"states have {states.shape[0]} rows, the basis {self.basis_.shape[0]}")
        return states

    def compress(self, states: np.ndarray) -> np.ndarray:
        r"""Reduced coordinates V^T W q: (n,) -> (r,), (n, k) -> (r, k)."""
        self._check_fitted()
        states = self._check_rows(states)
        return self.basis_.T @ self.inner_product_.apply(states)

    def decompress(self, reduced: np.ndarray) -> np.ndarray:
        r"""Full states V q_r: (r,) -> (n,), (r, k) -> (n, k)."""
        self._check_fitted()
        reduced = np.asarray(reduced, dtype=np.float64)
        if reduced.shape[0] != self.rank_:
            raise FemromValueError(f"reduced states have {reduced.shape[0]} rows, the basis rank is {self.rank_}")
        return self.basis_ @ reduced

    def projection_error(self, states: np.ndarray) -> float:
        r"""Relative projection error ||Q - V V^T W Q||_W / ||Q||_W (Frobenius in the W product)."""
        states = self._check_rows(states)
        residual = states - self.decompress(self.compress(states))
        inner = self.inner_product_
        norm2 = inner.squared_norm(states)
        return float(np.sqrt(inner.squared_norm(residual) / norm2)) if norm2 > 0 else 0.0
