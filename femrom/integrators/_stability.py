r"""The highest natural frequency ``omega_max`` and the explicit stability bound.

An explicit (central-difference) step is stable for ``dt <= 2 / omega_max``,
where ``omega_max^2 = lambda_max`` is the largest eigenvalue of
``K phi = lambda M phi``.

Lanczos approaches ``lambda_max`` from below: its Ritz value ``theta`` is a
Rayleigh quotient, so ``theta <= lambda_max``, and ``2 / sqrt(theta)`` is a
step bound that may be slightly too generous. :func:`bound_max_frequency`
therefore also returns an upper bound, the one :class:`CentralDifference`
checks against:

- the residual of the Ritz pair: for a unit Ritz vector ``x``, some eigenvalue
  lies in ``[theta - ||r||, theta + ||r||]``, ``r = A x - theta x`` (Bauer-Fike
  for a symmetric matrix; for a general mass in the ``M^{-1}`` norm). That
  eigenvalue is ``lambda_max`` once Lanczos has found the top of the spectrum,
  which it does from a random start unless the start is almost orthogonal to
  the top eigenvectors: so ``theta + ||r||`` is an upper bound in practice, not
  a proof. ARPACK stops when ``||r|| <= rtol theta``, so the margin costs at
  most a factor ``1 / sqrt(1 + rtol)`` (5e-4 at the default ``rtol = 1e-3``)
  of the step;
- for a diagonal (lumped) mass, Gershgorin's bound (the largest absolute row
  sum of ``M^{-1/2} K M^{-1/2}``), which is a proof but usually loose (1.1-1.2
  times ``lambda_max`` on a spring chain with random coefficients). The
  smaller of the two is used.

Systems below 64 dofs use a dense eigensolver (exact to rounding).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femrom._errors import FemromValueError
from femrom.solvers import is_diagonal, make_solver

#: Below this size the dense eigensolver is cheaper and exact.
_DENSE_LIMIT = 64


@dataclass(frozen=True)
class MaxFrequency:
    """The highest natural frequency of ``(K, M)``, from below and from above (rad/s).

    Attributes
    ----------
    estimate : float
        ``sqrt(theta)``, the Lanczos (or dense) estimate: ``<= omega_max``.
    upper : float
        An upper bound of ``omega_max`` (module docstring): the dense value, or
        ``sqrt(min(theta + ||r||, Gershgorin))``.
    method : str
        ``"dense"``, ``"ritz residual"`` or ``"gershgorin"``: what gave ``upper``.
    """

    estimate: float
    upper: float
    method: str


def _sqrt(lam: float) -> float:
    return float(np.sqrt(max(float(lam), 0.0)))


def bound_max_frequency(stiffness, mass, *, rtol: float = 1e-3, seed: int = 0) -> MaxFrequency:
    r"""``omega_max`` of ``K phi = omega^2 M phi``: Lanczos estimate and upper bound.

    For a diagonal (lumped) mass ``M = D`` Lanczos (ARPACK ``eigsh``, largest
    algebraic eigenvalue) runs on ``A = D^{-1/2} K D^{-1/2}``; for a general
    SPD mass, on the generalized problem with a factorised ``M``. The upper
    bound is ``theta + ||r||`` from the Ritz pair's residual, capped by
    Gershgorin's bound for a diagonal mass (module docstring). If ARPACK stops
    early, its best Ritz pair is used the same way; without one, Gershgorin's
    bound stands alone (a diagonal mass) or the error is raised.

    Parameters
    ----------
    stiffness, mass : (n, n) sparse matrices
        ``K`` (symmetric) and ``M`` (SPD).
    rtol : float
        ARPACK's relative tolerance on ``lambda_max``: the residual is at most
        about ``rtol * theta``, so the upper bound is at most a factor
        ``sqrt(1 + rtol)`` above the estimate.
    seed : int
        Seed of the Lanczos start vector.

    Returns
    -------
    MaxFrequency
    """
    K = sp.csr_matrix(stiffness, dtype=float)
    n = K.shape[0]
    diagonal_mass = is_diagonal(mass)
    if diagonal_mass:
        d = np.asarray(mass.diagonal(), dtype=float)
        if np.any(d <= 0.0):
            raise FemromValueError(f"mass has {np.count_nonzero(d <= 0)} non-positive diagonal entries")
        scale = sp.diags(1.0 / np.sqrt(d))
        A = sp.csr_matrix(scale @ K @ scale)
    if n <= _DENSE_LIMIT:
        if diagonal_mass:
            lam = sla.eigvalsh(A.toarray())[-1]
        else:
            lam = sla.eigh(K.toarray(), sp.csr_matrix(mass).toarray(), eigvals_only=True)[-1]
        return MaxFrequency(_sqrt(lam), _sqrt(lam), "dense")
    gershgorin = float(np.max(abs(A).sum(axis=1))) if diagonal_mass else np.inf
    v0 = np.random.default_rng(seed).standard_normal(n)
    mass_solver = None if diagonal_mass else make_solver(mass, "auto", spd=True)
    try:
        if diagonal_mass:
            values, vectors = spla.eigsh(A, k=1, which="LA", tol=rtol, v0=v0, maxiter=20 * n)
        else:
            Minv = spla.LinearOperator((n, n), matvec=mass_solver.solve, dtype=float)
            values, vectors = spla.eigsh(K, k=1, M=mass, Minv=Minv, which="LA", tol=rtol,
                                         v0=v0, maxiter=20 * n)
    except spla.ArpackNoConvergence as err:
        values, vectors = err.eigenvalues, err.eigenvectors
        if not len(values):
            if not diagonal_mass:
                raise
            return MaxFrequency(_sqrt(gershgorin), _sqrt(gershgorin), "gershgorin")
    j = int(np.argmax(values))
    theta, x = float(values[j]), vectors[:, j]
    if diagonal_mass:
        x = x / np.linalg.norm(x)
        residual = float(np.linalg.norm(A @ x - theta * x))
    else:  # ||r||_{M^-1} for x with x' M x = 1
        x = x / np.sqrt(float(x @ (mass @ x)))
        r = K @ x - theta * (mass @ x)
        residual = float(np.sqrt(max(float(r @ mass_solver.solve(r)), 0.0)))
    ritz = theta + residual
    if ritz <= gershgorin:
        return MaxFrequency(_sqrt(theta), _sqrt(ritz), "ritz residual")
    return MaxFrequency(_sqrt(theta), _sqrt(gershgorin), "gershgorin")


def estimate_max_frequency(stiffness, mass, *, rtol: float = 1e-3, seed: int = 0) -> float:
    r"""``omega_max = sqrt(lambda_max)`` of ``K phi = lambda M phi`` (rad/s), from below.

    The Lanczos (or, below 64 dofs, dense) estimate of
    :func:`bound_max_frequency`: at most ``omega_max``, to relative accuracy
    about ``rtol / 2``. For a step-size bound use ``bound_max_frequency(...).upper``.

    Parameters
    ----------
    stiffness, mass : (n, n) sparse matrices
        ``K`` (symmetric) and ``M`` (SPD).
    rtol : float
        Relative tolerance on ``lambda_max``.
    seed : int
        Seed of the Lanczos start vector.

    Returns
    -------
    float
    """
    return bound_max_frequency(stiffness, mass, rtol=rtol, seed=seed).estimate


def central_difference_bound(omega_max: float) -> float:
    """``2 / omega_max``: the largest stable central-difference step (undamped)."""
    return 2.0 / omega_max if omega_max > 0 else float("inf")
