r"""Symplectic time stepping of linear canonical Hamiltonian ROMs.

``q' = D_p p``, ``p' = -D_q q`` (``H = q^T D_q q / 2 + p^T D_p p / 2``), with
``h = dt``:

- ``"symplectic_euler_a"``: ``q_{k+1} = q_k + h D_p p_k``, ``p_{k+1} = p_k - h D_q q_{k+1}``;
- ``"symplectic_euler_b"``: ``p_{k+1} = p_k - h D_q q_k``, ``q_{k+1} = q_k + h D_p p_{k+1}``;
- ``"verlet"``: half a step of ``p``, a full step of ``q``, half a step of ``p``;
- ``"midpoint"``: the implicit midpoint rule, ``(I - h A / 2) y_{k+1} = (I + h A / 2) y_k``.

All four are symplectic (Hairer, Lubich & Wanner, Geometric Numerical
Integration, 2006, VI.3); the midpoint rule also conserves the quadratic ``H``
exactly, the others a modified Hamiltonian (no drift). Each becomes one
precomputed (2r, 2r) step matrix.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl

from femrom.inference._hamiltonian import HamiltonianOperators
from femrom.rom._steppers import run_linear

#: Symplectic schemes for Hamiltonian ROMs.
HAMILTONIAN_SCHEMES = ("symplectic_euler_a", "symplectic_euler_b", "verlet", "midpoint")


def hamiltonian_step_matrix(ops: HamiltonianOperators, dt: float, scheme: str) -> np.ndarray:
    """(2r, 2r) ndarray ``S`` with ``[q; p]_{k+1} = S [q; p]_k``."""
    r, h = ops.r, float(dt)
    I, Z = np.eye(r), np.zeros((r, r))
    Dq, Dp = ops.position, ops.momentum
    kick = lambda c: np.block([[I, Z], [-c * h * Dq, I]])   # noqa: E731  p -= c h Dq q
    drift = lambda c: np.block([[I, c * h * Dp], [Z, I]])   # noqa: E731  q += c h Dp p
    if scheme == "symplectic_euler_a":
        return kick(1.0) @ drift(1.0)
    if scheme == "symplectic_euler_b":
        return drift(1.0) @ kick(1.0)
    if scheme == "verlet":
        return kick(0.5) @ drift(1.0) @ kick(0.5)
    if scheme == "midpoint":
        A = np.block([[Z, Dp], [-Dq, Z]])
        return sl.solve(np.eye(2 * r) - 0.5 * h * A, np.eye(2 * r) + 0.5 * h * A)
    raise ValueError(f"unknown Hamiltonian scheme {scheme!r}; valid: {HAMILTONIAN_SCHEMES}")


class HamiltonianROM:
    """A linear canonical Hamiltonian ROM with symplectic integrators.

    Parameters
    ----------
    operators : HamiltonianOperators
    basis : (n, r) ndarray, optional
        The cotangent-lift ``Phi``: ``q ~ Phi q^``, ``p ~ Phi p^``.
    """

    def __init__(self, operators: HamiltonianOperators, basis: np.ndarray | None = None):
        self.operators_ = operators
        self.basis = basis

    def predict(self, q0: np.ndarray, p0: np.ndarray, times: np.ndarray,
                scheme: str = "midpoint"):
        """``(Q, P, H)``: (r, k), (r, k) and the reduced Hamiltonian (k,) on ``times``."""
        times = np.asarray(times, dtype=float)
        h = float(times[1] - times[0])
        S = hamiltonian_step_matrix(self.operators_, h, scheme)
        X = run_linear(S, np.concatenate([q0, p0]), times.size - 1, None)
        r = self.operators_.r
        Q, P = X[:r], X[r:]
        return Q, P, self.operators_.hamiltonian(Q, P)
