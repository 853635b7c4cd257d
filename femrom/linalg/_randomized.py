r"""Out-of-core multi-pass randomized SVD of a snapshot matrix read in column blocks.

The randomized range finder with q power iterations and re-orthonormalisation
(Halko, Martinsson & Tropp, SIAM Review 53(2), 2011, Alg. 4.4 followed by
Alg. 5.1) on A (n, K), in the W inner product:

1. Y_0 = A Omega, Omega (K, k) standard normal, k = rank + oversampling;
   Q_0 R_0 = Y_0 with Q_0^T W Q_0 = I.
2. For i = 1..q:  Z_i = A^T W Q_{i-1} orthonormalised, Y_i = A Z_i,
   Q_i R_i = Y_i.
3. B = Q_q^T W A (k, K), B = U_B diag(s) V^T, U = Q_q U_B[:, :rank].

U minimises ||A - U U^T W A||_W over W-orthonormal rank-k bases up to the
randomized error: this is the Euclidean algorithm applied to W^{1/2} A, with
W^{1/2} never formed (see :class:`InnerProduct` for how each kind of W is
orthonormalised).

**Passes.** A literal Alg. 4.4 reads A twice per power iteration (once for
A^T Q, once for A Z). Here each power iteration is one pass: block A_j gives
its rows Z_j = A_j^T S of Z and, at once, its contribution A_j Z_j to Y.
The orthonormalisation of Z that Alg. 4.4 does between the two products is
folded into S: if the previous iterate satisfies A Z~ = Q R' with Z~
orthonormal, then Q^T W A Z~ = R', so Z = A^T W Q R'^{-T} has Z~^T Z = I;
with the SVD R' = U_R Sigma V_R^T we use S = W Q U_R Sigma^{-1} (the factor
V_R^T only rotates Z). The spans are those of Alg. 4.4 in exact arithmetic,
and Z is orthonormal up to the part of A^T W Q outside span(Z~), which
vanishes as the iteration converges. R' is tracked from the Gram matrices
Omega^T Omega and Z^T Z accumulated in each pass (k x k), so neither Omega nor
Z (K x k) is kept. Total: q + 2 passes (sketch, q power iterations, B).

On every spectrum of the tests the simpler Y = A (A^T W Q) without this
scaling was as accurate; the scaling is a conditioning safeguard that costs
one k x k SVD per pass.

**Memory.** Y, Q, S (n, k) and B (k, K), plus one block (two while the next
one is read ahead, see :class:`BlockSource`): O((n + K) k).
Omega's rows are regenerated from the seed per column (see
:mod:`._test_matrices`), so K need not be known in advance.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from femrom._progress import Progress
from femrom.linalg._blocks import as_block_source
from femrom.linalg._lowrank import LowRankSVD
from femrom.linalg._product import InnerProduct
from femrom.linalg._test_matrices import RANGE_STREAM, column_rows

# Singular values of R' below this fraction of the largest are treated as this
# fraction when scaling S = W Q U_R Sigma^{-1}: they belong to directions already
# below round-off, and the floor keeps exactly rank-deficient data finite.
_SCALE_FLOOR = 1e-13


def _inverse_sqrt_factor(gram: np.ndarray) -> np.ndarray:
    """F (k, k) with F^T G F = I for an SPD Gram G (eigenvalues floored at 1e-28 max)."""
    values, vectors = np.linalg.eigh(gram)
    floor = max(values.max(), np.finfo(float).tiny) * 1e-28
    return vectors / np.sqrt(np.maximum(values, floor))


def _next_scaling(weighted_q: np.ndarray, coupling: np.ndarray) -> np.ndarray:
    """S = W Q U_R Sigma^{-1} (n, k) from W Q and R' = U_R Sigma V_R^T."""
    u_r, sigma, _ = np.linalg.svd(coupling)
    sigma = np.maximum(sigma, sigma[0] * _SCALE_FLOOR) if sigma[0] > 0 else np.ones_like(sigma)
    return weighted_q @ (u_r / sigma)


def _check_same_columns(source, seen: int, expected: int) -> None:
    if seen != expected:
        raise ValueError(f"{source.description} gave {seen} columns in pass {source.passes} "
                         f"but {expected} in the first: the data changed between passes")


def _check_rank(rank: int, oversampling: int, power_iterations: int) -> None:
    if int(rank) < 1:
        raise ValueError(f"rank must be >= 1, got {rank}")
    if int(oversampling) < 0:
        raise ValueError(f"oversampling must be >= 0, got {oversampling}")
    if int(power_iterations) < 0:
        raise ValueError(f"power_iterations must be >= 0, got {power_iterations}")


def randomized_svd(data: Any, rank: int, *, oversampling: int = 10, power_iterations: int = 2,
                   product: Any = None, seed: int = 0, block_columns: int | None = None,
                   progress: bool | None = None) -> LowRankSVD:
    r"""Rank-``rank`` SVD of A (n, K) read in column blocks, A ~ U diag(s) Vt.

    Multi-pass randomized range finder with power iterations (module doc):
    ``power_iterations + 2`` passes over the data, memory O((n + K) k) with
    k = rank + oversampling.

    Parameters
    ----------
    data : (n, K) array-like or block source
        See :func:`as_block_source`; must be readable more than once.
    rank : int
        Number r of singular triplets returned.
    oversampling : int
        Extra sketch columns p (k = r + p).
    power_iterations : int
        Number q of power iterations (A A^T W)^q.
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
        ``passes`` and ``total_energy`` = ||A||_W^2.
    """
    _check_rank(rank, oversampling, power_iterations)
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
            y += block @ omega
            gram += omega.T @ omega
            energy += inner.squared_norm(block)
            n_columns += block.shape[1]
        bar.update()
        if y is None:
            raise ValueError(f"{source.description} yielded no columns")
        if rank > min(n_columns, y.shape[0]):
            raise ValueError(f"rank {rank} exceeds min(n, K) = min({y.shape[0]}, {n_columns})")
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
                y += block @ z
                gram += z.T @ z
                seen += block.shape[1]
            _check_same_columns(source, seen, n_columns)
            bar.update()
            basis, r_factor = inner.orthonormalize(y)
            coupling = r_factor @ _inverse_sqrt_factor(gram)

        # Last pass: B = Q^T W A.
        weighted = inner.apply(basis)
        b = np.concatenate([(block.T @ weighted).T for block in source.blocks()], axis=1)
        bar.update()

    _check_same_columns(source, b.shape[1], n_columns)
    u_b, s, vt = np.linalg.svd(b, full_matrices=False)
    return LowRankSVD(U=basis @ u_b[:, :rank], s=s[:rank], Vt=vt[:rank], passes=passes,
                      total_energy=energy, n_columns=n_columns, sketch_size=width,
                      method="randomized")
