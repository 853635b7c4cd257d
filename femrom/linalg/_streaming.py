r"""Single-pass streaming sketch, updated column by column while the integrator runs.

Tropp, Yurtsever, Udell & Cevher, "Streaming low-rank matrix approximation
with an application to scientific simulation", SISC 41(4), A2430-A2463,
2019 (TYUC2019), three-sketch method, for A (n, K) whose columns a_j arrive
one at a time (K need not be known):

- range sketch     Y = A Omega^T       (n, k),  Y += a_j omega_j^T
- co-range sketch  X = Upsilon A       (k, K),  column j = Upsilon a_j
- core sketch      Z = Phi A Psi^T     (s, s),  Z += (Phi a_j) psi_j^T

with Upsilon (k, n), Phi (s, n) drawn once and kept, and the per-column
columns omega_j (k,), psi_j (s,) of Omega, Psi regenerated from the seed
(:mod:`._test_matrices`). Reconstruction (TYUC2019 Sec. 4): Q = orth(Y),
P = orth(X^T), C = (Phi Q)^+ Z ((Psi P)^+)^T, A_hat = Q C P^T, and the
rank-r answer is the truncated SVD of C: U = Q U_C[:, :r],
Vt = (P V_C[:, :r])^T.

Sketch sizes: the defaults k = 4r + 1, s = 2k + 1 are TYUC2019's choice
(Eq. 5.3, real field alpha = 1) when nothing is known about the spectrum.

Weighted product W: a diagonal W is exact (columns scaled by W^{1/2} before
sketching, U scaled back by W^{-1/2}). For a general sparse W, Q is made
W-orthonormal (Q^T W Q = I) and the same formula is used; this is the method
applied to R A (R^T R = W) with left test matrices Upsilon R^{-1}, Phi R^{-1},
which are Gaussian with covariance W^{-1} instead of I, so the a priori
bound holds only approximately (up to cond(W)).

Memory (numbers of float64): Y n k, Upsilon n k (or about 9 n for
``test_matrix="sparse"``), Phi n s (same), X k K -- the co-range sketch grows
with the number of columns K --, Z s^2, and a buffer of ``buffer_columns``
columns (updates are applied in blocks so the products are matrix-matrix).
With the defaults and Gaussian maps that is n (16 r + 5) + (4 r + 1) K.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from femrom._errors import FemromValueError, positive_integer
from femrom.linalg._blocks import as_block_source, as_column_block
from femrom.linalg._lowrank import LowRankSVD
from femrom.linalg._product import InnerProduct, householder_qr
from femrom.linalg._test_matrices import (
    LEFT_STREAM,
    STREAMING_STREAM,
    LeftTestMatrix,
    column_rows,
)

_FIELDS = ("q", "v", "a")


class StreamingSketch:
    """Single-pass randomized sketch of A (n, K) fed one column (or block) at a time.

    Parameters
    ----------
    n : int
        Length of a column (number of free dofs).
    rank : int
        Target rank r (default of :meth:`finalize`; sets the default sizes).
    range_size : int, optional
        k, columns of the range sketch and rows of the co-range sketch
        (default 4 r + 1).
    core_size : int, optional
        s, size of the core sketch (default 2 k + 1; must be >= k).
    seed : int
        Seed of all test matrices.
    product : None, (n,) array or (n, n) sparse matrix
        SPD inner product W; the returned U satisfies U^T W U = I.
    test_matrix : {"gaussian", "sparse"}
        Kind of the stored maps Upsilon, Phi (sparse sign maps store about
        9 n numbers each instead of k n and s n).
    buffer_columns : int
        Columns gathered before the sketches are updated.

    Attributes
    ----------
    n_columns : int
        Columns received so far.
    total_energy : float
        ||A||_W^2 of the columns received so far.
    """

    def __init__(self, n: int, rank: int, *, range_size: int | None = None,
                 core_size: int | None = None, seed: int = 0, product: Any = None,
                 test_matrix: str = "gaussian", buffer_columns: int = 32):
        self.n, self.rank = positive_integer(n, "n"), positive_integer(rank, "rank")
        self.range_size = 4 * self.rank + 1 if range_size is None else positive_integer(range_size, "range_size")
        self.core_size = 2 * self.range_size + 1 if core_size is None else positive_integer(core_size, "core_size")
        if self.range_size < self.rank + 2:
            raise FemromValueError(f"range_size must be >= rank + 2 = {self.rank + 2} "
                                   f"(TYUC2019 needs k > r + 1 for real data), got {self.range_size}")
        if self.core_size < self.range_size:
            raise FemromValueError(f"core_size must be >= range_size = {self.range_size}, got {self.core_size}")
        if self.range_size > self.n:
            raise FemromValueError(f"range_size {self.range_size} exceeds n = {self.n}")
        self.seed = int(seed)
        self.product = InnerProduct(product)
        self.product.check_dimension(self.n)
        rng = np.random.default_rng([self.seed, LEFT_STREAM])
        self._upsilon = LeftTestMatrix(rng, self.range_size, self.n, test_matrix)
        self._phi = LeftTestMatrix(rng, self.core_size, self.n, test_matrix)
        self.test_matrix = test_matrix
        self._range = np.zeros((self.n, self.range_size))
        self._core = np.zeros((self.core_size, self.core_size))
        self._corange: list[np.ndarray] = []
        self.buffer_columns = max(1, int(buffer_columns))
        self._buffer = np.empty((self.n, self.buffer_columns))
        self._filled = 0
        self.n_columns = 0
        self.total_energy = 0.0

    # -- feeding -------------------------------------------------------------

    def update(self, columns: np.ndarray) -> None:
        """Add columns a_j: (n,) or (n, b) array, in order."""
        columns = as_column_block(columns, self.n)
        start = 0
        b = columns.shape[1]
        if self._filled == 0 and b >= self.buffer_columns:
            self._absorb(columns)
            return
        while start < b:
            take = min(b - start, self.buffer_columns - self._filled)
            self._buffer[:, self._filled:self._filled + take] = columns[:, start:start + take]
            self._filled += take
            start += take
            if self._filled == self.buffer_columns:
                self.flush()

    def update_from(self, data: Any) -> "StreamingSketch":
        """Add every column of an array or block source (one pass); returns self."""
        for block in as_block_source(data).blocks():
            self.update(block)
        return self

    def __call__(self, result: Any) -> None:
        """Integrator consumer: add ``result.q`` (see :meth:`consumer` for other fields)."""
        self.update(result.q)

    def consumer(self, field: str = "q", every: int = 1) -> "SketchConsumer":
        """An integrator consumer adding ``getattr(result, field)`` every ``every`` steps."""
        return SketchConsumer(self, field, every)

    def close(self) -> None:
        """Apply the buffered columns (called by ``integrate`` at the end of a run)."""
        self.flush()

    def flush(self) -> None:
        """Apply the buffered columns to the sketches."""
        if self._filled:
            self._absorb(self._buffer[:, :self._filled])
            self._filled = 0

    def _absorb(self, block: np.ndarray) -> None:
        inner = self.product
        if inner.kind == "diagonal":
            block = inner.sqrt_weights[:, None] * block
            self.total_energy += float(np.vdot(block, block))
        else:
            self.total_energy += inner.squared_norm(block)
        k = self.range_size
        rows = column_rows(self.seed, STREAMING_STREAM, self.n_columns, block.shape[1],
                           k + self.core_size)
        self._range += block @ rows[:, :k]
        self._corange.append(self._upsilon.apply(block))
        self._core += self._phi.apply(block) @ rows[:, k:]
        self.n_columns += block.shape[1]

    # -- reading -------------------------------------------------------------

    @property
    def memory_bytes(self) -> int:
        """Bytes held by the sketches, the stored test matrices and the buffer."""
        return (self._range.nbytes + self._core.nbytes + self._buffer.nbytes
                + sum(x.nbytes for x in self._corange) + self._upsilon.nbytes + self._phi.nbytes)

    def finalize(self, rank: int | None = None) -> LowRankSVD:
        """Rank-r approximation A ~ U diag(s) Vt from the sketches (TYUC2019 Alg. 4.3-4.4).

        Can be called again after more updates.

        Returns
        -------
        LowRankSVD
            ``U`` (n, r) with U^T W U = I, ``s`` (r,), ``Vt`` (r, K), ``passes = 1``.
        """
        rank = self.rank if rank is None else positive_integer(rank, "rank")
        self.flush()
        n_columns = self.n_columns
        if n_columns == 0:
            raise FemromValueError("the sketch has received no columns")
        if len(self._corange) > 1:
            self._corange = [np.concatenate(self._corange, axis=1)]
        corange = self._corange[0]
        k = self.range_size
        if rank > min(k, n_columns):
            raise FemromValueError(f"rank {rank} exceeds min(range_size, columns) = "
                                   f"min({k}, {n_columns})")
        if self.product.kind == "matrix":
            q, _ = self.product.orthonormalize(self._range)
        else:
            q, _ = householder_qr(self._range)
        p, _ = np.linalg.qr(corange.T)  # (K, min(k, K))
        psi_p = np.zeros((self.core_size, p.shape[1]))
        for start in range(0, n_columns, 256):
            count = min(256, n_columns - start)
            rows = column_rows(self.seed, STREAMING_STREAM, start, count, k + self.core_size)
            psi_p += rows[:, k:].T @ p[start:start + count]
        phi_q = self._phi.apply(q)
        core = np.linalg.lstsq(phi_q, self._core, rcond=None)[0]           # (Phi Q)^+ Z
        core = np.linalg.lstsq(psi_p, core.T, rcond=None)[0].T             # ... ((Psi P)^+)^T
        u_c, s, vt_c = np.linalg.svd(core, full_matrices=False)
        u = q @ u_c[:, :rank]
        if self.product.kind == "diagonal":
            u = u / self.product.sqrt_weights[:, None]
        return LowRankSVD(U=u, s=s[:rank], Vt=vt_c[:rank] @ p.T, passes=1,
                          total_energy=self.total_energy, n_columns=n_columns,
                          sketch_size=k, method="streaming")


class SketchConsumer:
    """Integrator consumer feeding one field of every ``every``-th step to a sketch."""

    def __init__(self, sketch: StreamingSketch, field: str = "q", every: int = 1):
        if field not in _FIELDS:
            raise FemromValueError(f"unknown field {field!r}; valid: {', '.join(_FIELDS)}")
        if int(every) < 1:
            raise FemromValueError(f"every must be >= 1, got {every}")
        self.sketch, self.field, self.every = sketch, field, int(every)

    def __call__(self, result: Any) -> None:
        if getattr(result, "step", 0) % self.every:
            return
        value = getattr(result, self.field)
        if value is None:
            raise FemromValueError(f"step {getattr(result, 'step', '?')} has no {self.field!r} to sketch")
        self.sketch.update(value)

    def close(self) -> None:
        self.sketch.flush()
