"""Random test matrices, seeded so that nothing of size K has to be stored.

Test matrices that multiply A (n, K) from the right (Omega (K, k) in
Y = A Omega) have one row per snapshot column. Row j is drawn from its own
generator ``default_rng([seed, stream, j])``, so any block of rows can be
regenerated on demand, the number of columns K need not be known in
advance, and the result does not depend on how the columns were grouped
into blocks (one at a time from an integrator or 500 at a time from a file).

Test matrices that multiply from the left (Upsilon (k, n) in X = Upsilon A)
are drawn once and kept: they are needed for every column.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError

# Streams of per-column rows, so that different sketches of one seed are independent.
RANGE_STREAM = 0        # Omega of the multi-pass range finder
STREAMING_STREAM = 1    # [Omega | Psi] rows of the single-pass sketch
LEFT_STREAM = 2         # Upsilon and Phi of the single-pass sketch


def column_rows(seed: int, stream: int, start: int, count: int, width: int) -> np.ndarray:
    """Rows ``start .. start + count - 1`` of a standard normal (K, width) test matrix.

    Returns
    -------
    (count, width) ndarray
        Row j comes from ``default_rng([seed, stream, j])``: the same j gives
        the same row, whatever the block it is drawn in.
    """
    rows = np.empty((count, width))
    for i in range(count):
        rows[i] = np.random.default_rng([seed, stream, start + i]).standard_normal(width)
    return rows


class LeftTestMatrix:
    """A (rows, n) test matrix applied to every column: ``apply(B)`` = Upsilon B.

    ``kind="gaussian"``: dense standard normal (rows * n floats).
    ``kind="sparse"``: sparse sign map, ``nonzeros_per_column`` entries +-1 per
    column at distinct random rows, scaled by 1/sqrt(nonzeros) (Tropp, Yurtsever,
    Udell & Cevher, SISC 41(4), 2019, Sec. 3.3): about (2 zeta + 1) n numbers
    stored instead of rows * n. It is kept transposed, (n, rows) CSR, because
    ``B^T @ Upsilon^T`` is 3-5x faster in scipy than ``Upsilon @ B``.
    """

    def __init__(self, rng: np.random.Generator, rows: int, n: int, kind: str,
                 nonzeros_per_column: int = 8):
        self.kind, self.shape = kind, (rows, n)
        if kind == "gaussian":
            self._dense = rng.standard_normal((rows, n))
            self._transposed = None
        elif kind == "sparse":
            zeta = min(int(nonzeros_per_column), rows)
            # zeta distinct rows per column: the first zeta of a random ordering,
            # drawn in chunks of columns to keep the temporary small.
            chunk = max(1, 2**22 // rows)
            row_index = np.concatenate([
                np.argsort(rng.random((min(chunk, n - start), rows)), axis=1)[:, :zeta].ravel()
                for start in range(0, n, chunk)])
            col_index = np.repeat(np.arange(n), zeta)
            signs = rng.choice([-1.0, 1.0], size=n * zeta) / np.sqrt(zeta)
            self._dense = None
            self._transposed = sp.csr_matrix((signs, (col_index, row_index)), shape=(n, rows))
        else:
            raise FemromValueError(f"unknown test matrix {kind!r}; valid: gaussian, sparse")

    def apply(self, block: np.ndarray) -> np.ndarray:
        """Upsilon B for (n, b) ``B``: (rows, b)."""
        if self._dense is not None:
            return self._dense @ block
        return np.asarray(block.T @ self._transposed).T

    @property
    def nbytes(self) -> int:
        if self._dense is not None:
            return self._dense.nbytes
        m = self._transposed
        return m.data.nbytes + m.indices.nbytes + m.indptr.nbytes
