r"""Proper symplectic decomposition by cotangent lift (Peng & Mohseni, SISC 38(1), A1-A27, 2016).

For Hamiltonian snapshots z = [q; p] (2n,), with the canonical structure
J_{2n} = [[0, I_n], [-I_n, 0]], the cotangent lift takes Phi (n, r) as the
rank-r POD basis of the horizontally stacked [Q, P] (n, 2K) and the
block-diagonal basis

.. math::
    A = \begin{bmatrix} \Phi & 0 \\ 0 & \Phi \end{bmatrix} \in \mathbb{R}^{2n \times 2r},
    \qquad A^T J_{2n} A = J_{2r} \iff \Phi^T \Phi = I_r,

so A is symplectic. Reduction uses the symplectic inverse
A^+ = J_{2r}^T A^T J_{2n} (equal to A^T here), and the Galerkin projection
A^+ J_{2n} grad H(A z_r) = J_{2r} grad_{z_r} H(A z_r) is again Hamiltonian.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from femrom._errors import FemromValueError
from femrom.basis._pod import POD
from femrom.linalg import as_block_source


def apply_j(z: np.ndarray) -> np.ndarray:
    r"""J_{2m} z = [z_p; -z_q] for z = [z_q; z_p] of shape (2m,) or (2m, k)."""
    half = z.shape[0] // 2
    if 2 * half != z.shape[0]:
        raise FemromValueError(f"a phase-space array has an even number of rows, got {z.shape[0]}")
    return np.concatenate([z[half:], -z[:half]], axis=0)


def apply_j_transpose(z: np.ndarray) -> np.ndarray:
    r"""J_{2m}^T z = [-z_p; z_q] for z = [z_q; z_p]."""
    return -apply_j(z)


def _stacked_source(positions: Any, momenta: Any):
    """Blocks of [Q, P]: all blocks of Q, then all blocks of P (arrays are stacked directly)."""
    if isinstance(positions, np.ndarray) and isinstance(momenta, np.ndarray):
        if positions.shape[0] != momenta.shape[0]:
            raise FemromValueError(f"Q has {positions.shape[0]} rows but P has {momenta.shape[0]}")
        return np.hstack([positions, momenta])
    sources = [as_block_source(positions), as_block_source(momenta)]

    def open_pass():
        for source in sources:
            yield from source.blocks()

    return open_pass


class CotangentLiftPSD:
    r"""Symplectic basis A = blkdiag(Phi, Phi) from position and momentum snapshots.

    Parameters
    ----------
    rank : int, optional
        r (the basis has 2 r columns). Or ``energy`` / ``tolerance`` (exactly
        one), applied to the POD of [Q, P].
    energy, tolerance : float, optional
        As :class:`POD`.
    method : str
        POD method (:class:`POD`): "auto", "svd", "randomized", "streaming", "dask".
    **pod_options
        Other :class:`POD` keyword arguments (``max_rank``, ``oversampling``, ...).

    Attributes
    ----------
    basis_ : (2n, 2r) ndarray
        A.
    phi_ : (n, r) ndarray
        Phi, Phi^T Phi = I.
    pod_ : POD
        The POD of [Q, P] (singular values, retained energy, ...).
    rank_ : int
        r.
    symplecticity_error_ : float
        ||A^T J_{2n} A - J_{2r}||_F.
    """

    def __init__(self, rank: int | None = None, *, energy: float | None = None,
                 tolerance: float | None = None, method: str = "auto", **pod_options: Any):
        if "product" in pod_options:
            raise FemromValueError("CotangentLiftPSD is Euclidean (A^T J A = J needs Phi^T Phi = I); "
                                   "a product is not supported")
        self.rank, self.energy, self.tolerance = rank, energy, tolerance
        self.method = method
        self.pod_options = pod_options

    def fit(self, positions: Any, momenta: Any) -> "CotangentLiftPSD":
        """Fit from Q (n, K) and P (n, K) (arrays or block sources).

        Returns
        -------
        self
        """
        pod = POD(self.rank, energy=self.energy, tolerance=self.tolerance, method=self.method,
                  **self.pod_options)
        self.pod_ = pod.fit(_stacked_source(positions, momenta))
        phi = pod.basis_
        n, r = phi.shape
        basis = np.zeros((2 * n, 2 * r))
        basis[:n, :r] = phi
        basis[n:, r:] = phi
        self.phi_, self.basis_, self.rank_ = phi, basis, r
        j_2r = apply_j(np.eye(2 * r))
        self.symplecticity_error_ = float(np.linalg.norm(basis.T @ apply_j(basis) - j_2r))
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "basis_"):
            raise AttributeError("CotangentLiftPSD is not fitted: call fit(Q, P) first")

    @property
    def symplectic_inverse_(self) -> np.ndarray:
        r"""A^+ = J_{2r}^T A^T J_{2n} (2r, 2n)."""
        self._check_fitted()
        return apply_j_transpose(apply_j_transpose(self.basis_).T)  # J^T (J^T A)^T = J^T A^T J

    def compress(self, states: np.ndarray) -> np.ndarray:
        r"""z_r = A^+ z: (2n,) -> (2r,), (2n, k) -> (2r, k)."""
        self._check_fitted()
        states = np.asarray(states, dtype=np.float64)
        if states.shape[0] != self.basis_.shape[0]:
            raise FemromValueError(f"states have {states.shape[0]} rows, the basis {self.basis_.shape[0]}")
        return apply_j_transpose(self.basis_.T @ apply_j(states))

    def decompress(self, reduced: np.ndarray) -> np.ndarray:
        r"""z = A z_r: (2r,) -> (2n,), (2r, k) -> (2n, k)."""
        self._check_fitted()
        reduced = np.asarray(reduced, dtype=np.float64)
        if reduced.shape[0] != self.basis_.shape[1]:
            raise FemromValueError(f"reduced states have {reduced.shape[0]} rows, expected {self.basis_.shape[1]}")
        return self.basis_ @ reduced

    def projection_error(self, states: np.ndarray) -> float:
        r"""Relative error ||z - A A^+ z||_F / ||z||_F."""
        states = np.asarray(states, dtype=np.float64)
        residual = states - self.decompress(self.compress(states))
        norm = np.linalg.norm(states)
        return float(np.linalg.norm(residual) / norm) if norm > 0 else 0.0
