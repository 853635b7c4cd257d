r"""The highest natural frequency ``omega_max`` and the explicit stability bound.

An explicit (central-difference) step is stable for ``dt <= 2 / omega_max``,
where ``omega_max^2`` is the largest eigenvalue of ``K phi = omega^2 M phi``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femrom.fem._solvers import _is_diagonal, make_solver

#: Below this size the dense eigensolver is cheaper and exact.
_DENSE_LIMIT = 64


def estimate_max_frequency(stiffness, mass, *, rtol: float = 1e-3, seed: int = 0) -> float:
    r"""``omega_max = sqrt(lambda_max)`` of ``K phi = lambda M phi`` (rad/s).

    For a diagonal (lumped) mass ``M = D`` this runs Lanczos (ARPACK ``eigsh``,
    largest algebraic eigenvalue) on ``D^{-1/2} K D^{-1/2}``; for a general SPD
    mass, on the generalized problem with a factorised ``M``. Lanczos
    approaches ``lambda_max`` from below, to relative accuracy ``rtol`` on
    ``lambda``; if ARPACK stops early the best Ritz value is used, and if it
    has none, the Gershgorin upper bound. Systems below 64 dofs use a dense
    eigensolver.

    Parameters
    ----------
    stiffness, mass : (n, n) sparse matrices
        ``K`` (symmetric) and ``M`` (SPD).
    rtol : float
        Relative tolerance on ``lambda_max`` (a loose one is enough for a
        time-step bound).
    seed : int
        Seed of the Lanczos start vector.

    Returns
    -------
    float
    """
    K = sp.csr_matrix(stiffness, dtype=float)
    n = K.shape[0]
    diagonal_mass = _is_diagonal(mass)
    if diagonal_mass:
        d = np.asarray(mass.diagonal(), dtype=float)
        if np.any(d <= 0.0):
            raise ValueError(f"mass has {np.count_nonzero(d <= 0)} non-positive diagonal entries")
        scale = sp.diags(1.0 / np.sqrt(d))
        A = sp.csr_matrix(scale @ K @ scale)
    if n <= _DENSE_LIMIT:
        if diagonal_mass:
            lam = sla.eigvalsh(A.toarray())[-1]
        else:
            lam = sla.eigh(K.toarray(), sp.csr_matrix(mass).toarray(), eigvals_only=True)[-1]
        return float(np.sqrt(max(lam, 0.0)))
    v0 = np.random.default_rng(seed).standard_normal(n)
    try:
        if diagonal_mass:
            lam = spla.eigsh(A, k=1, which="LA", tol=rtol, v0=v0, maxiter=20 * n,
                             return_eigenvectors=False)[0]
        else:
            solver = make_solver(mass, "auto", spd=True)
            Minv = spla.LinearOperator((n, n), matvec=solver.solve, dtype=float)
            lam = spla.eigsh(K, k=1, M=mass, Minv=Minv, which="LA", tol=rtol, v0=v0,
                             maxiter=20 * n, return_eigenvectors=False)[0]
    except spla.ArpackNoConvergence as err:
        if len(err.eigenvalues):
            lam = float(np.max(err.eigenvalues))
        elif diagonal_mass:
            lam = float(np.max(abs(A).sum(axis=1)))  # Gershgorin: an upper bound
        else:
            raise
    return float(np.sqrt(max(lam, 0.0)))


def central_difference_bound(omega_max: float) -> float:
    """``2 / omega_max``: the largest stable central-difference step (undamped)."""
    return 2.0 / omega_max if omega_max > 0 else float("inf")
