r"""Nonlinear modes of damped models by the extended periodic motion concept (EPMC).

Krack (2015, "Nonlinear modal analysis of nonconservative systems: extension of the periodic
motion concept", Computers & Structures 154:59-71) defines a nonlinear mode of a damped
system as the family of periodic motions of the *autonomous* system with an artificial
negative mass-proportional damping ``-xi M q'`` that just compensates the dissipation,

.. math::

    M q'' + (C - \xi M) q' + K q + f_{nl}(q, q'; s) = f_0,

with the motion's frequency ``Omega`` and ``xi`` unknown. The modal frequency is ``Omega``
and the modal damping ratio ``D = xi / (2 Omega)`` (his definition: exact for a linear system
with modal damping, where ``Omega`` is the undamped natural frequency ``omega_n`` and
``xi = 2 zeta omega_n``; a ring-down's damped frequency is ``omega_n sqrt(1 - zeta^2)``).

Harmonic balance (:class:`HarmonicBalance`, ``xi`` in ``A(Omega)``) gives ``(2H+1) n``
equations for the coefficients ``Z``, ``Omega`` and ``xi``; two more close the system:

- *amplitude*: the fundamental harmonic has modal amplitude ``a`` in the mass norm,
  ``a_1^T M a_1 + b_1^T M b_1 = a^2`` (``|Q_1|_M = a``, ``Q_1 = a_1 - i b_1``); for a single
  dof of unit mass ``a`` is the fundamental displacement amplitude;
- *phase*: the motion's time origin is fixed by ``phi^T M b_1 = 0`` (no ``sin`` component
  along the linear mode ``phi``).

The unknowns are solved in the scaled form ``Psi = Z / a`` (the residual divided by ``a``), so
that they stay of order one over decades of amplitude, and followed in ``log a`` over the
requested amplitudes: each point is predicted by linear extrapolation in ``log a`` from the
two before it and corrected by Newton; a failed corrector inserts the geometric mean of the
two amplitudes (up to ``max_halvings`` times).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femrom._errors import FemromValueError
from femrom.integrators._harmonic_balance import HB_NEWTON, HarmonicBalance, HarmonicBalanceError, newton_solve
from femrom.integrators._newton import Newton


@dataclass(frozen=True)
class NonlinearModes:
    r"""A nonlinear mode by EPMC: frequency and damping against modal amplitude.

    Attributes
    ----------
    modal_amplitude : (k,) ndarray
        ``a`` (fundamental harmonic in the mass norm).
    omega : (k,) ndarray
        ``Omega`` [rad/s].
    xi : (k,) ndarray
        The self-excitation ``xi`` [1/s].
    coefficients : (k, 2H+1, n) ndarray
        ``Z`` of each periodic motion.
    outputs : (k, 2H+1, p) ndarray
        The outputs' coefficients.
    iterations : (k,) int ndarray
    linear_frequency_hz : float
        The mode's frequency linearised at rest (the start).
    harmonics, samples : int
    seconds : float
    """

    modal_amplitude: np.ndarray
    omega: np.ndarray
    xi: np.ndarray
    coefficients: np.ndarray
    outputs: np.ndarray
    iterations: np.ndarray
    linear_frequency_hz: float
    harmonics: int
    samples: int
    seconds: float = 0.0

    def __len__(self) -> int:
        return self.omega.size

    @property
    def frequency_hz(self) -> np.ndarray:
        return self.omega / (2 * np.pi)

    @property
    def damping_ratio(self) -> np.ndarray:
        """(k,) ``D = xi / (2 Omega)`` (Krack 2015)."""
        return self.xi / (2 * self.omega)

    @property
    def output_amplitude(self) -> np.ndarray:
        """(k, p) fundamental displacement amplitude of each output."""
        return np.hypot(self.outputs[:, 1], self.outputs[:, 2])

    def rows(self) -> list[dict]:
        return [{"modal_amplitude": float(a), "frequency_hz": float(f), "damping_ratio": float(d),
                 "iterations": int(i)}
                for a, f, d, i in zip(self.modal_amplitude, self.frequency_hz, self.damping_ratio, self.iterations)]


def linear_mode(hb: HarmonicBalance, mode=0):
    r"""``(omega, phi)`` of the model linearised at rest (``K + df/dq``), ``phi^T M phi = 1``.

    ``mode``: the index of the mode in ascending frequency, or a shape ``(n,)`` (its Rayleigh
    quotient is the frequency).
    """
    K, M = hb.rest_tangent(), hb.mass
    if not np.isscalar(mode):
        phi = np.asarray(mode, dtype=float).reshape(-1)
        if phi.shape != (hb.n_dofs,):
            raise FemromValueError(f"mode must be an index or a ({hb.n_dofs},) shape, got shape {phi.shape}")
        omega2 = float(phi @ (K @ phi)) / float(phi @ (M @ phi))
    else:
        index = int(mode)
        if not 0 <= index < hb.n_dofs:
            raise FemromValueError(f"mode must lie in [0, {hb.n_dofs}), got {mode}")
        if sp.issparse(K):
            values, vectors = spla.eigsh(sp.csc_matrix(K), k=index + 1, M=sp.csc_matrix(M), sigma=0.0, which="LM")
            order = np.argsort(values)
            omega2, phi = values[order[index]], vectors[:, order[index]]
        else:
            values, vectors = la.eigh(K, M)
            omega2, phi = values[index], vectors[:, index]
    phi = phi / np.sqrt(float(phi @ (M @ phi)))
    if not omega2 > 0:
        raise FemromValueError(f"the linearised mode has omega^2 = {omega2:.3g}: not an oscillating mode")
    return float(np.sqrt(omega2)), phi


def epmc(system, amplitudes, *, mode=0, harmonics: int = 5, samples: int | None = None, state=None,
         output=None, newton: Newton | None = None, max_halvings: int = 4) -> NonlinearModes:
    r"""The nonlinear mode ``mode`` of ``system`` at the modal amplitudes ``amplitudes`` (module docstring).

    Parameters
    ----------
    system : SecondOrderSystem or SecondOrderROM
    amplitudes : (k,) array
        Positive modal amplitudes, monotonic (increasing from the linear range is the usual way).
    mode : int or (n,) array
        Which mode of the model linearised at rest (index, ascending), or its shape.
    harmonics, samples, state, output
        As :class:`HarmonicBalance`.
    newton : Newton, optional
        Tolerances of each corrector (default 1e-10 relative, 40 iterations).
    max_halvings : int
        Intermediate amplitudes a failed step may insert.
    """
    tic = time.perf_counter()
    a_list = np.asarray(amplitudes, dtype=float).reshape(-1)
    if a_list.size == 0 or not np.all(a_list > 0) or not np.all(np.isfinite(a_list)):
        raise FemromValueError("amplitudes must be positive and finite")
    d = np.diff(a_list)
    if not (np.all(d > 0) or np.all(d < 0)):
        raise FemromValueError("amplitudes must be strictly monotonic")
    newton = newton or HB_NEWTON
    hb = HarmonicBalance(system, None, harmonics=harmonics, samples=samples, state=state, output=output)
    if hb.basis.harmonics < 1:
        raise FemromValueError("EPMC needs at least one harmonic")
    size, n = hb.basis.size, hb.n_dofs
    nz = hb.n_unknowns
    omega0, phi = linear_mode(hb, mode)
    M = hb.mass
    m_phi = np.asarray(M @ phi).reshape(-1)
    xi0 = 0.0 if hb.damping is None else float(phi @ (hb.damping @ phi))
    a1, b1 = slice(n, 2 * n), slice(2 * n, 3 * n)
    weight = omega0 ** 2                 # constraints in the residual's units (force per unit amplitude)

    def fun_at(a):
        def fun(u):
            psi, omega, xi = u[:nz], u[nz], u[nz + 1]
            r = hb.residual(a * psi, omega, 0.0, xi=xi)
            Ma, Mb = np.asarray(M @ psi[a1]).reshape(-1), np.asarray(M @ psi[b1]).reshape(-1)
            g = np.array([psi[a1] @ Ma + psi[b1] @ Mb - 1.0, m_phi @ psi[b1]]) * weight
            R = np.concatenate([r["residual"] / a, g])
            rows = np.zeros((2, nz))
            rows[0, a1], rows[0, b1] = 2 * Ma, 2 * Mb
            rows[1, b1] = m_phi
            rows *= weight
            columns = np.column_stack([r["d_omega"] / a, r["d_xi"] / a])
            J = r["jacobian"]
            if sp.issparse(J):
                J = sp.bmat([[J, sp.csr_matrix(columns)], [sp.csr_matrix(rows), None]], format="csc")
            else:
                J = np.block([[J, columns], [rows, np.zeros((2, 2))]])
            return R, J, r["scale"] / a + weight
        return fun

    psi0 = np.zeros((size, n))
    psi0[1] = phi
    u = np.concatenate([psi0.reshape(-1), [omega0, xi0]])
    solutions, its_list = [], []
    log_a = np.log(a_list)
    history: list[tuple[float, np.ndarray]] = []    # (log a, u) of converged points, for the predictor

    def predict(target):
        if len(history) < 2:
            return history[-1][1] if history else u
        (l1, u1), (l2, u2) = history[-2], history[-1]
        return u2 + (u2 - u1) * (target - l2) / (l2 - l1)

    def correct(target, depth):
        guess = predict(target)
        try:
            return newton_solve(fun_at(np.exp(target)), guess, newton)[:2]
        except HarmonicBalanceError:
            if depth >= max_halvings or not history:
                raise
        middle = 0.5 * (history[-1][0] + target)
        u_mid, _ = correct(middle, depth + 1)
        history.append((middle, u_mid))
        return correct(target, depth + 1)

    for target in log_a:
        u_new, its = correct(target, 0)
        history.append((target, u_new))
        solutions.append(u_new)
        its_list.append(its)
    U = np.array(solutions)
    Z = U[:, :nz].reshape(-1, size, n) * a_list[:, None, None]
    return NonlinearModes(a_list, U[:, nz], U[:, nz + 1], Z, Z @ hb.output_matrix.T, np.array(its_list, dtype=int),
                          omega0 / (2 * np.pi), hb.basis.harmonics, hb.basis.samples, time.perf_counter() - tic)
