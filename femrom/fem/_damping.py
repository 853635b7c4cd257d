"""Damping operators."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError


def rayleigh_damping(mass: sp.spmatrix, stiffness: sp.spmatrix, alpha: float, beta: float) -> sp.csr_matrix:
    """Rayleigh damping ``C = alpha M + beta K`` (symmetric positive semidefinite).

    Modal damping ratio ``zeta_i = alpha / (2 omega_i) + beta omega_i / 2``.
    """
    for name, value in (("alpha", alpha), ("beta", beta)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
                or not np.isfinite(value):
            raise FemromValueError(f"Rayleigh {name} must be a finite number, got {value!r}")
    if alpha < 0 or beta < 0:
        raise FemromValueError(f"Rayleigh coefficients must be non-negative, got alpha={alpha}, beta={beta}")
    if alpha == 0 and beta == 0:
        raise FemromValueError("Rayleigh damping with alpha = beta = 0: remove the damping effect instead")
    return (alpha * sp.csr_matrix(mass) + beta * sp.csr_matrix(stiffness)).tocsr()


def rayleigh_from_damping_ratios(omega_1: float, omega_2: float, zeta_1: float, zeta_2: float):
    """(alpha, beta) giving damping ratios ``zeta_1, zeta_2`` at ``omega_1, omega_2`` (rad/s)."""
    det = omega_2 / omega_1 - omega_1 / omega_2
    alpha = 2.0 * (zeta_1 * omega_2 - zeta_2 * omega_1) / det
    beta = 2.0 * (zeta_2 / omega_1 - zeta_1 / omega_2) / det
    return alpha, beta
