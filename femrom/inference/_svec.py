r"""Symmetric matrices in orthonormal coordinates (``svec``), for the structured regression.

Every symmetric (k, k) block is written in the orthonormal basis
``E_ii = e_i e_i^T``, ``E_il = (e_i e_l^T + e_l e_i^T) / sqrt 2`` (``i < l``), so a
block has ``k (k + 1) / 2`` coordinates ``svec(A)_a = <E_a, A>`` and
``smat(svec(A)) = A``. For the regression of :mod:`._problem` with square blocks
only, ``x`` collects the coordinates of all ``b`` blocks (``m = b r (r + 1) / 2``
entries) and

.. math::

    f = x^\top P x + 2 q^\top x + c, \qquad P_{jl}[a, b] = \langle E_a, G_{jl} E_b\rangle,

whose Hessian blocks are sparse (``O(r)`` entries a row: a Lyapunov operator),
assembled once from ``kron(I, G_jl)`` (:func:`hessian`). The symmetrised Kronecker
product :func:`sym_kron` gives the cone terms of the interior-point Newton matrix
(:mod:`._interior_point`); :func:`sym_basis` the same basis as dense arrays for the
dense face solves (:mod:`._face_lstsq`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from femrom.inference._problem import GramProblem


def sym(A: np.ndarray) -> np.ndarray:
    """``(A + A^T) / 2``."""
    return 0.5 * (A + A.T)


def svec_index(k: int):
    """``(i, l, c)``: the upper-triangle pairs of a (k, k) symmetric matrix and the
    coefficients ``c`` of ``E = c (e_i e_l^T + e_l e_i^T)`` (1/2 on the diagonal,
    ``1/sqrt 2`` off it), so that the ``E`` are orthonormal."""
    i, l = np.triu_indices(k)
    return i, l, np.where(i == l, 0.5, np.sqrt(0.5))


def svec(A: np.ndarray, index) -> np.ndarray:
    """``<E_a, A>`` for every basis matrix ``E_a`` (``A`` need not be symmetric)."""
    i, l, c = index
    return c * (A[i, l] + A[l, i])


def smat(v: np.ndarray, index, k: int) -> np.ndarray:
    """``sum_a v_a E_a``: exactly symmetric (k, k)."""
    i, l, c = index
    A = np.zeros((k, k))
    A[i, l] = c * v
    A[l, i] += c * v
    return A


def sym_kron(A: np.ndarray, index, out: np.ndarray | None = None,
             rows: int | None = None) -> np.ndarray:
    r"""Dense ``M[a, b] = <E_a, A E_b A>`` for symmetric ``A``: the symmetrised
    Kronecker product ``A (x)_s A`` of Todd, Toh & Tutuncu (1998) in svec coordinates.

    With ``E_a = c_a (e_i e_l^T + e_l e_i^T)`` and ``E_b = c_b (e_p e_q^T + e_q e_p^T)``,
    ``M[a, b] = 2 c_a c_b (A_ip A_lq + A_iq A_lp)``: four gathers of ``A``, ``rows``
    rows of ``M`` at a time (default: about 32 MB a gather, so that the temporaries
    stay small next to ``M``, which is 3.2 GB at r = 200). Written into ``out`` if given.
    """
    i, l, c = index
    n = i.size
    M = np.empty((n, n)) if out is None else out
    step = max(1, (1 << 22) // max(n, 1)) if rows is None else rows
    for start in range(0, n, step):
        b = slice(start, min(start + step, n))
        block = A[np.ix_(i[b], i)] * A[np.ix_(l[b], l)]
        block += A[np.ix_(i[b], l)] * A[np.ix_(l[b], i)]
        block *= 2.0 * c[b, None]
        block *= c[None, :]
        M[b] = block
    return M


def _svec_matrix(k: int) -> sp.csr_matrix:
    """(k^2, k (k+1)/2) sparse ``vec(E_a)`` (column-major ``vec``)."""
    i, l, c = svec_index(k)
    a = np.arange(i.size)
    rows = np.concatenate([i + l * k, l + i * k])
    data = np.concatenate([c, c])
    return sp.csr_matrix((data, (rows, np.concatenate([a, a]))), shape=(k * k, i.size))


def lyapunov_block(A: np.ndarray, k: int) -> sp.csr_matrix:
    """Sparse ``[<E_a, A E_b>]_{ab}`` for (k, k) ``A``: ``S^T kron(I, A) S``."""
    S = _svec_matrix(k)
    return (S.T @ sp.kron(sp.identity(k, format="csr"), sp.csr_matrix(A)) @ S).tocsr()


def hessian(problem: GramProblem) -> sp.csr_matrix:
    """(m, m) sparse Hessian ``2 P`` of ``f`` in svec coordinates (square blocks only)."""
    r, nb = problem.r, len(problem.blocks)
    slices = problem.slices()
    rows = []
    for j in range(nb):
        rows.append([2.0 * lyapunov_block(problem.gram[slices[j], slices[l]], r)
                     for l in range(nb)])
    return sp.bmat(rows, format="csr")


def sym_basis(k: int) -> np.ndarray:
    """(k (k+1)/2, k, k) orthonormal basis of symmetric matrices: ``E_ii``, ``(E_il + E_li)/sqrt 2``."""
    i, l = np.triu_indices(k)
    E = np.zeros((i.size, k, k))
    idx = np.arange(i.size)
    value = np.where(i == l, 1.0, np.sqrt(0.5))
    E[idx, i, l] = value
    E[idx, l, i] = value
    return E
