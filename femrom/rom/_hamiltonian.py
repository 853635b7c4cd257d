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

With a known nonlinear term, ``H^ = q^T D_q q / 2 + p^T D_p p / 2 + H_nl(Phi q, Phi p)``
(:class:`femrom.inference.ProjectedPotential`), the ROM steps
``y' = J_{2r} grad H^`` with :func:`femrom.integrators.integrate_canonical`:
``"midpoint"`` (implicit midpoint with Newton on the symmetric tangent
``grad^2 H^``: symplectic, exact for quadratic invariants, ``H^`` oscillates
by ``O(h^2)`` without drift) or ``"avf"`` (average vector field: ``H^``
conserved to the Newton tolerance, not symplectic). The explicit symplectic
Euler and Stoermer-Verlet splittings need a separable ``H^ = T(p) + V(q)``;
a potential coupling ``q`` and ``p`` (the NLS) is not, so they are refused.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl

from femrom.inference._hamiltonian import HamiltonianOperators, ProjectedPotential
from femrom.integrators._hamiltonian import CANONICAL_SCHEMES, CanonicalSystem, integrate_canonical
from femrom.integrators._newton import Newton
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
    """A canonical Hamiltonian ROM (linear, or with a known projected potential).

    Parameters
    ----------
    operators : HamiltonianOperators
    basis : (n, r) ndarray, optional
        The cotangent-lift ``Phi``: ``q ~ Phi q^``, ``p ~ Phi p^``.
    potential : object, optional
        The known full-order ``H_nl`` (``value``, ``gradient``, ``hessian``);
        needs ``basis``. The ROM uses ``H_nl(Phi q^, Phi p^)``.
    newton : Newton
        Tolerances of the implicit steps with a potential.

    Attributes
    ----------
    last_trajectory_ : CanonicalTrajectory
        Newton iterations and stepping time of the last nonlinear ``predict``.
    """

    def __init__(self, operators: HamiltonianOperators, basis: np.ndarray | None = None,
                 potential=None, newton: Newton = Newton(rtol=1e-12)):
        if potential is not None and basis is None:
            raise ValueError("a known potential is evaluated through the basis: give basis")
        self.operators_ = operators
        self.basis = basis
        self.newton = newton
        self.potential_ = None if potential is None else ProjectedPotential(potential, basis)

    @property
    def system_(self) -> CanonicalSystem:
        ops = self.operators_
        return CanonicalSystem(ops.position, ops.momentum, self.potential_)

    def hamiltonian(self, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Reduced ``H^`` of (r, k) columns: quadratic part plus ``H_nl(Phi q^, Phi p^)``."""
        return np.atleast_1d(self.system_.hamiltonian(q, p))

    def reconstruct(self, q: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Full ``(Phi q^, Phi p^)``."""
        return self.basis @ q, self.basis @ p

    def predict(self, q0: np.ndarray, p0: np.ndarray, times: np.ndarray,
                scheme: str = "midpoint"):
        """``(Q, P, H)``: (r, k), (r, k) and the reduced Hamiltonian (k,) on uniform ``times``."""
        times = np.asarray(times, dtype=float)
        h = float(times[1] - times[0])
        r = self.operators_.r
        if self.potential_ is not None:
            if scheme not in CANONICAL_SCHEMES:
                raise ValueError(f"scheme {scheme!r} needs a separable Hamiltonian; with a potential "
                                 f"coupling q and p use one of {CANONICAL_SCHEMES}")
            tr = integrate_canonical(self.system_, q0, p0, h, times.size - 1, scheme, self.newton)
            self.last_trajectory_ = tr
            return tr.q, tr.p, tr.hamiltonian
        S = hamiltonian_step_matrix(self.operators_, h, scheme)
        X = run_linear(S, np.concatenate([q0, p0]), times.size - 1, None)
        Q, P = X[:r], X[r:]
        return Q, P, self.operators_.hamiltonian(Q, P)
