r"""Hamiltonian operator inference for canonical Hamiltonian systems.

For ``y = [q; p]`` with ``q' = dH/dp``, ``p' = -dH/dq`` and a cotangent-lift
basis ``V_q = V_p = Phi`` (Peng & Mohseni, SIAM J. Sci. Comput. 38, 2016), the
reduced Hamiltonian ``H^ = q^T D^_q q / 2 + p^T D^_p p / 2 + H^_nl`` gives

.. math::

    \dot{\hat q} = \hat D_p \hat p + \hat f_q, \qquad
    \dot{\hat p} = -\hat D_q \hat q - \hat f_p ,

and Sharma, Wang & Kramer (Physica D 431, 2022) fit the symmetric operators by

.. math::

    \min_{\hat D_p = \hat D_p^\top} \| R_p - \hat D_p \hat P \|_F, \quad
    R_p = \dot{\hat Q} - \hat F_q ;\qquad
    \min_{\hat D_q = \hat D_q^\top} \| R_q - \hat D_q \hat Q \|_F, \quad
    R_q = -\dot{\hat P} - \hat F_p ,

whose optimality conditions are Lyapunov equations

.. math::

    (\hat P \hat P^\top) \hat D_p + \hat D_p (\hat P \hat P^\top)
        = \hat P R_p^\top + R_p \hat P^\top

(and likewise for ``D^_q``), solved by Bartels-Stewart
(:func:`scipy.linalg.solve_continuous_lyapunov`) in ``O(r^3)``, never as an
``r^2 x r^2`` Kronecker system. A Tikhonov weight ``lambda`` adds
``lambda I`` to the Gram matrix (``2 lambda`` on the left's diagonal).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sl


def symmetric_lyapunov_fit(X: np.ndarray, R: np.ndarray, regularization: float = 0.0) -> np.ndarray:
    r"""(r, r) symmetric ``D`` minimising ``||R - D X||_F^2 + lambda ||D||_F^2``.

    Solves ``(G + lambda I) D + D (G + lambda I) = X R^T + R X^T`` with
    ``G = X X^T``.

    Parameters
    ----------
    X : (r, K) ndarray
    R : (r, K) ndarray
    regularization : float
        Absolute ``lambda >= 0``.
    """
    G = X @ X.T + regularization * np.eye(X.shape[0])
    S = X @ R.T
    D = sl.solve_continuous_lyapunov(G, S + S.T)
    return 0.5 * (D + D.T)


@dataclass(frozen=True, eq=False)
class HamiltonianOperators:
    r"""``q' = D_p p + f_q``, ``p' = -D_q q - f_p`` with symmetric ``D_q``, ``D_p`` (r, r)."""

    position: np.ndarray     # D_q
    momentum: np.ndarray     # D_p

    @property
    def r(self) -> int:
        return self.position.shape[0]

    def hamiltonian(self, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``q^T D_q q / 2 + p^T D_p p / 2`` column by column."""
        return 0.5 * (np.sum(q * (self.position @ q), axis=0) + np.sum(p * (self.momentum @ p), axis=0))


class HamiltonianOpInf:
    r"""Learn ``D^_q``, ``D^_p`` (symmetric) from reduced canonical data.

    Parameters
    ----------
    regularization : float
        Relative Tikhonov weight: ``lambda = rho * trace(X X^T) / r``.

    Attributes
    ----------
    operators_ : HamiltonianOperators
    residual_ : float
        Relative residual of both regressions together.
    """

    def __init__(self, regularization: float = 0.0):
        if not regularization >= 0:
            raise ValueError(f"regularization must be >= 0, got {regularization}")
        self.regularization = float(regularization)

    def fit(self, states_q: np.ndarray, states_p: np.ndarray, ddt_q: np.ndarray,
            ddt_p: np.ndarray, forces_q: np.ndarray | None = None,
            forces_p: np.ndarray | None = None) -> "HamiltonianOpInf":
        """Fit from reduced (r, K) data ``Q^, P^, Q^', P^'`` and known ``F^_q, F^_p``."""
        Rp = ddt_q - (0.0 if forces_q is None else forces_q)
        Rq = -ddt_p - (0.0 if forces_p is None else forces_p)
        lam_p = self.regularization * np.sum(states_p**2) / states_p.shape[0]
        lam_q = self.regularization * np.sum(states_q**2) / states_q.shape[0]
        Dp = symmetric_lyapunov_fit(states_p, Rp, lam_p)
        Dq = symmetric_lyapunov_fit(states_q, Rq, lam_q)
        self.operators_ = HamiltonianOperators(position=Dq, momentum=Dp)
        num = np.linalg.norm(Rp - Dp @ states_p) ** 2 + np.linalg.norm(Rq - Dq @ states_q) ** 2
        den = np.linalg.norm(Rp) ** 2 + np.linalg.norm(Rq) ** 2
        self.residual_ = float(np.sqrt(num / den)) if den > 0 else 0.0
        return self
