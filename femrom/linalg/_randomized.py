r"""Out-of-core multi-pass randomized SVD of a snapshot matrix read in column blocks.

The randomized range finder with q power iterations and re-orthonormalisation
(Halko, Martinsson & Tropp, SIAM Review 53(2), 2011, "HMT", Alg. 4.4 followed
by Alg. 5.1) on A (n, K), in the W inner product:

1. Y_0 = A Omega, Omega (K, k) standard normal, k = rank + oversampling;
   Q_0 R_0 = Y_0 with Q_0^T W Q_0 = I.
2. For i = 1..q:  Z_i = A^T W Q_{i-1} orthonormalised, Y_i = A Z_i,
   Q_i R_i = Y_i.
3. The last pass, by ``scheme``:

   - ``"classical"``: B = Q_q^T W A (k, K), B = U_B diag(s) V^T,
     U = Q_q U_B[:, :rank]. The rank-k approximation is Q_q Q_q^T W A.
   - ``"pass_efficient"``: one more half power step in the same pass,
     Z = A^T W Q_q (K, k) and Y = A Z (n, k), and the approximation
     A P_Z = Y Z^+ = (A U_Z) U_Z^T (P_Z the Euclidean projector on span(Z)
     in R^K), from the SVD Z = U_Z Sigma_Z V_Z^T: C = A U_Z = Y V_Z Sigma_Z^{-1},
     C = Q_C R_C with Q_C^T W Q_C = I, R_C = U_M diag(s) V_M^T, U = Q_C U_M,
     Vt = V_M^T U_Z^T. This is the idea of Bjarkason's pass-efficient
     randomized SVD (E. K. Bjarkason, "Pass-efficient randomized algorithms
     for low-rank matrix approximation using any number of views", SIAM J.
     Sci. Comput. 41(4), A2355-A2383, 2019), derived here for column blocks
     and a W product.

Both schemes read the data ``power_iterations + 2`` times. With the same
passes the pass-efficient scheme applies one more half power step:
span(Z) = range((A^T W A)^{q+1} Omega), so its error behaves like HMT's with
the exponent 2q + 2 instead of 2q + 1 (classical q = 1, 3 passes: exponent 3;
pass-efficient, 3 passes: exponent 4). It is never worse with the same Omega:
Q Q^T W A = Q Z^T has its rows in span(Z), and A P_Z is the best
approximation of A with rows in span(Z) in every unitarily invariant W-norm,
so ||A - A P_Z||_W <= ||A - Q Q^T W A||_W and, since Q Q^T W A = Q Q^T W A P_Z,
sigma_i(Q^T W A) <= sigma_i(W^{1/2} A P_Z) <= sigma_i(W^{1/2} A) for every i.
Its last pass costs two block products instead of one (A_j^T S and A_j Z_j)
and a second (n, k) orthonormalisation.

U minimises ||A - U U^T W A||_W over W-orthonormal rank-k bases up to the
randomized error: this is the Euclidean algorithm applied to W^{1/2} A, with
W^{1/2} never formed (see :class:`InnerProduct` for how each kind of W is
orthonormalised). In the pass-efficient scheme the right factor lives in R^K
with the Euclidean product, exactly as for W = I: Z = A^T W Q = (W^{1/2} A)^T
(W^{1/2} Q) with W^{1/2} Q Euclidean orthonormal, and W^{1/2} A P_Z has the
singular values of W^{1/2} A U_Z, i.e. of R_C.

**Passes.** A literal Alg. 4.4 reads A twice per power iteration (once for
A^T Q, once for A Z). Here each power iteration is one pass: block A_j gives
its rows Z_j = A_j^T S of Z and, at once, its contribution A_j Z_j to Y.
The orthonormalisation of Z that Alg. 4.4 does between the two products is
folded into S: if the previous iterate satisfies A Z~ = Q R' with Z~
orthonormal, then Q^T W A Z~ = R', so Z = A^T W Q R'^{-T} has Z~^T Z = I;
with the SVD R' = U_R Sigma V_R^T we use S = W Q U_R Sigma^{-1} (the factor
V_R^T only rotates Z). The spans are those of Alg. 4.4 in exact arithmetic,
and Z is orthonormal up to the part of A^T W Q outside span(Z~), which
vanishes as the iteration converges (precisely: Z^T Z = I + (that part)^T
(that part) >= I). R' is tracked from the Gram matrices Omega^T Omega and
Z^T Z accumulated in each pass (k x k), so neither Omega nor Z (K x k) is
kept, except Z of the pass-efficient last pass. Total: q + 2 passes (sketch,
q power iterations, last pass).

On every spectrum of the tests the simpler Y = A (A^T W Q) without this
scaling was as accurate; the scaling is a conditioning safeguard that costs
one k x k SVD per pass. For the pass-efficient last pass it matters more:
C = Y V_Z Sigma_Z^{-1} divides by the singular values of Z, and because
Z^T Z >= I with nearly orthogonal columns, the round-off of Y is not
amplified (directions of Q that A^T W annihilates, where Sigma was floored,
give short columns of Z whose Y columns are divided by their own length).

**Memory.** Y, Q, S (n, k) and B or Z (k, K), plus one block (two while the
next one is read ahead, see :class:`BlockSource`): O((n + K) k).
Omega's rows are regenerated from the seed per column (see
:mod:`._test_matrices`), so K need not be known in advance.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from femrom._errors import FemromValueError, nonnegative_integer, positive_integer
from femrom._progress import Progress
from femrom.linalg._blocks import as_block_source
from femrom.linalg._lowrank import LowRankSVD
from femrom.linalg._product import InnerProduct
from femrom.linalg._test_matrices import RANGE_STREAM, column_rows

# Singular values of R' below this fraction of the largest are treated as this
# fraction when scaling S = W Q U_R Sigma^{-1}: they belong to directions already
# below round-off, and the floor keeps exactly rank-deficient data finite.
_SCALE_FLOOR = 1e-13

#: Last-pass schemes of :func:`randomized_svd` (module doc).
SCHEMES = ("classical", "pass_efficient")

# Rows per tile of the accumulation Y += A_j Z_j: an (8192, k) tile of Y and of
# the block stay in cache between the product and the sum.
_TILE_ROWS = 8192


def _add_product(y: np.ndarray, block: np.ndarray, z: np.ndarray) -> None:
    """Y += A_j Z_j in row tiles, without an (n, k) temporary.

    ``y += block @ z`` writes an (n, k) product and reads it back: with blocks
    of about as many columns as k, that traffic is larger than the block
    itself. In row tiles it stays in cache: 0.17-0.19 s instead of 0.24-0.29 s
    per (1e6 x 32) block with k = 30 while a reader thread copies the next
    block (docs/benchmarks_snapshots.md). Same products row by row.
    """
    n = y.shape[0]
    if n <= 2 * _TILE_ROWS:
        y += block @ z
        return
    for start in range(0, n, _TILE_ROWS):
        stop = start + _TILE_ROWS
        y[start:stop] += block[start:stop] @ z


def _inverse_sqrt_factor(gram: np.ndarray) -> np.ndarray:
    """F (k, k) with F^T G F = I for an SPD Gram G (eigenvalues floored at 1e-28 max).

    A zero Gram (all-zero data) gives a finite F (floor: the smallest normal float).
    """
    values, vectors = np.linalg.eigh(gram)
    floor = max(values.max() * 1e-28, np.finfo(float).tiny)
    return vectors / np.sqrt(np.maximum(values, floor))


def _next_scaling(weighted_q: np.ndarray, coupling: np.ndarray) -> np.ndarray:
    """S = W Q U_R Sigma^{-1} (n, k) from W Q and R' = U_R Sigma V_R^T."""
    u_r, sigma, _ = np.linalg.svd(coupling)
    sigma = np.maximum(sigma, sigma[0] * _SCALE_FLOOR) if sigma[0] > 0 else np.ones_like(sigma)
    return weighted_q @ (u_r / sigma)


def _check_same_columns(source, seen: int, expected: int) -> None:
    if seen != expected:
        raise FemromValueError(f"{source.description} gave {seen} columns in pass {source.passes} "
                               f"but {expected} in the first: the data changed between passes")


def _check_rank(rank: int, oversampling: int, power_iterations: int, scheme: str) -> None:
    positive_integer(rank, "rank")
    nonnegative_integer(oversampling, "oversampling")
    nonnegative_integer(power_iterations, "power_iterations")
    if scheme not in SCHEMES:
        raise FemromValueError(f"unknown randomized SVD scheme {scheme!r}; valid: {', '.join(SCHEMES)}")


def _right_factor(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""U_Z (K, k) and M (k, k) with A U_Z = (A Z) M, from Z = U_Z Sigma_Z V_Z^T.

    M = V_Z Sigma_Z^{-1}, except that columns whose sigma_Z is below round-off
    relative to the largest are left zero: Z carries no direction there, and
    A P_Z = (A U_Z) U_Z^T only loses what is not in span(Z).
    """
    u_z, sigma_z, vt_z = np.linalg.svd(z, full_matrices=False)
    tolerance = sigma_z[0] * max(z.shape) * np.finfo(float).eps if sigma_z.size else 0.0
    kept = sigma_z > tolerance
    coefficients = np.zeros((z.shape[1], z.shape[1]))
    coefficients[:, kept] = vt_z[kept].T / sigma_z[kept]
    return u_z, coefficients


def randomized_svd(data: Any, rank: int, *, oversampling: int = 10, power_iterations: int = 2,
                   scheme: str = "pass_efficient", product: Any = None, seed: int = 0,
                   block_columns: int | None = None, progress: bool | None = None) -> LowRankSVD:
    r"""Rank-``rank`` SVD of A (n, K) read in column blocks, A ~ U diag(s) Vt.

    Multi-pass randomized range finder with power iterations (module doc):
    ``power_iterations + 2`` passes over the data in either scheme, memory
    O((n + K) k) with k = rank + oversampling.

    Parameters
    ----------
    data : (n, K) array-like or block source
        See :func:`as_block_source`; must be readable more than once.
    rank : int
        Number r of singular triplets returned.
    oversampling : int
        Extra sketch columns p (k = r + p).
    power_iterations : int
        Number q of passes that apply A A^T W between the sketch and the
        last pass.
    scheme : {"pass_efficient", "classical"}
        What the last pass computes. ``"pass_efficient"`` (default): Z = A^T W Q
        and A Z in the same pass, the approximation A P_Z (Bjarkason 2019),
        error like HMT's bound with exponent 2q + 2, never less accurate than
        ``"classical"`` with the same seed and passes (module doc); its last
        pass does two block products instead of one. ``"classical"``:
        B = Q^T W A, the approximation Q Q^T W A (HMT Alg. 4.4 + 5.1),
        exponent 2q + 1. The default was chosen from accuracy per pass
        (docs/benchmarks_snapshots.md): reading the data is the cost that
        grows with the problem.
    product : None, (n,) array or (n, n) sparse matrix
        SPD inner product W; U^T W U = I and the approximation is optimal in
        the W-norm ||x||_W^2 = x^T W x.
    seed : int
        Seed of Omega.
    block_columns : int, optional
        Columns per block for array input.
    progress : bool, optional
        Show a progress line (passes); ``None`` decides from the terminal.

    Returns
    -------
    LowRankSVD
        ``U`` (n, r) with U^T W U = I, ``s`` (r,), ``Vt`` (r, K); also
        ``passes`` (= q + 2), ``total_energy`` = ||A||_W^2 and ``method``
        (``"randomized"`` or ``"randomized-pass-efficient"``).
    """
    _check_rank(rank, oversampling, power_iterations, scheme)
    rank, q = int(rank), int(power_iterations)
    source = as_block_source(data, block_columns=block_columns)
    passes = q + 2
    source.require_passes(passes, "randomized_svd")
    inner = InnerProduct(product)
    width = rank + int(oversampling)

    with Progress(passes, "randomized SVD passes", enabled=progress) as bar:
        # Pass 1: Y = A Omega, Omega^T Omega, ||A||_W^2.
        y = gram = None
        energy, n_columns = 0.0, 0
        for block in source.blocks():
            if y is None:
                inner.check_dimension(block.shape[0])
                y = np.zeros((block.shape[0], width))
                gram = np.zeros((width, width))
            omega = column_rows(seed, RANGE_STREAM, n_columns, block.shape[1], width)
            _add_product(y, block, omega)
            gram += omega.T @ omega
            energy += inner.squared_norm(block)
            n_columns += block.shape[1]
        bar.update()
        if y is None:
            raise FemromValueError(f"{source.description} yielded no columns")
        if rank > min(n_columns, y.shape[0]):
            raise FemromValueError(f"rank {rank} exceeds min(n, K) = min({y.shape[0]}, {n_columns})")
        width = min(width, n_columns, y.shape[0])
        y, gram = y[:, :width], gram[:width, :width]  # fewer snapshots than k: Y spans range(A)
        basis, r_factor = inner.orthonormalize(y)
        coupling = r_factor @ _inverse_sqrt_factor(gram)  # A Omega~ = Q R'

        # Passes 2 .. q+1: one power iteration each (Z and A Z in the same pass).
        for _ in range(q):
            scaling = _next_scaling(inner.apply(basis), coupling)
            y = np.zeros_like(y)
            gram = np.zeros((width, width))
            seen = 0
            for block in source.blocks():
                z = block.T @ scaling
                _add_product(y, block, z)
                gram += z.T @ z
                seen += block.shape[1]
            _check_same_columns(source, seen, n_columns)
            bar.update()
            del scaling
            basis, r_factor = inner.orthonormalize(y)
            coupling = r_factor @ _inverse_sqrt_factor(gram)

        if scheme == "classical":
            # Last pass: B = Q^T W A.
            weighted = inner.apply(basis)
            b = np.concatenate([(block.T @ weighted).T for block in source.blocks()], axis=1)
            bar.update()
        else:
            # Last pass: Z = A^T W Q (scaled as in a power iteration) and Y = A Z.
            scaling = _next_scaling(inner.apply(basis), coupling)
            del basis
            y = np.zeros_like(y)
            rows, block = [], None
            for block in source.blocks():
                z = block.T @ scaling
                _add_product(y, block, z)
                rows.append(z)
            bar.update()
            del scaling, block
            z = np.concatenate(rows, axis=0)
            del rows

    if scheme == "classical":
        _check_same_columns(source, b.shape[1], n_columns)
        u_b, s, vt = np.linalg.svd(b, full_matrices=False)
        u, s, vt = basis @ u_b[:, :rank], s[:rank], vt[:rank]
        method = "randomized"
    else:
        # A P_Z = (A U_Z) U_Z^T with A U_Z = Y M = Q_C R_C (Q_C^T W Q_C = I), R_C = U_M S V_M^T.
        _check_same_columns(source, z.shape[0], n_columns)
        u_z, coefficients = _right_factor(z)
        y = y @ coefficients
        basis, r_factor = inner.orthonormalize(y)
        del y
        u_m, s, vt_m = np.linalg.svd(r_factor)
        u, s, vt = basis @ u_m[:, :rank], s[:rank], vt_m[:rank] @ u_z.T
        method = "randomized-pass-efficient"
    return LowRankSVD(U=u, s=s, Vt=vt, passes=passes, total_energy=energy, n_columns=n_columns,
                      sketch_size=width, method=method)
