r"""Pseudo-arclength continuation of harmonic-balance solutions in frequency or in force.

A branch of solutions of ``R(z, lambda) = 0`` (``lambda`` the excitation frequency ``Omega``
or the force amplitude ``F``) is followed through turning points (Keller 1977; Krack & Gross
2019, ch. 4): with ``y = (z, lambda)`` scaled component-wise by ``w`` (typical size of the
coefficients, and of ``lambda``),

- *predictor*: ``y_pred = y_i + ds t_i``, ``t_i`` the unit tangent, the null vector of
  ``[dR/dz, dR/dlambda]`` (in scaled variables) oriented along ``t_{i-1}``;
- *corrector*: Newton on ``R(y) = 0`` together with ``t_i . (y - y_pred) = 0`` (the
  hyperplane through the prediction normal to the tangent);
- *scaling*: ``lambda`` by its starting value, the coefficients by the largest one of the
  last accepted point, so that ``ds`` is a relative change of the motion whatever its size;
- *step control*: ``ds <- ds * clip(target / iterations, 0.5, 2)`` after a converged
  corrector, within ``[ds_min, ds_max]``; a failed corrector halves ``ds`` and tries again.

The branch ends when ``lambda`` leaves ``[start, end]``, after ``max_steps`` points, or
when ``ds`` falls below ``ds_min``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.integrators._harmonic_balance import (
    HB_NEWTON,
    HarmonicBalance,
    HarmonicBalanceError,
    newton_solve,
    solve_linear,
)
from femrom.integrators._newton import Newton


@dataclass(frozen=True)
class HarmonicBalanceCurve:
    r"""A branch of periodic solutions: frequency response (``parameter = "frequency"``) or
    force response (``"force"``).

    Attributes
    ----------
    omega : (k,) ndarray
        Excitation frequency ``Omega`` [rad/s] of each point.
    force : (k,) ndarray
        Force amplitude ``F`` of each point (``F b sin(Omega t)``).
    coefficients : (k, 2H+1, n) ndarray
        ``Z`` of each point (rows ``a_0, a_1, b_1, ...``).
    outputs : (k, 2H+1, p) ndarray
        The outputs' coefficients ``Z E^T``.
    iterations : (k,) int ndarray
        Newton iterations of each point (its corrector).
    state_change : (k,) ndarray
        Relative change of the force state over the second march (0 for a periodic loop).
    harmonics, samples : int
        ``H`` and ``N``.
    parameter : str
    seconds : float
        Wall time of the continuation.
    """

    omega: np.ndarray
    force: np.ndarray
    coefficients: np.ndarray
    outputs: np.ndarray
    iterations: np.ndarray
    state_change: np.ndarray
    harmonics: int
    samples: int
    parameter: str
    seconds: float = 0.0

    def __len__(self) -> int:
        return self.omega.size

    @property
    def frequency_hz(self) -> np.ndarray:
        return self.omega / (2 * np.pi)

    @property
    def phasor(self) -> np.ndarray:
        """(k, p) fundamentals ``Y = b_1 + i a_1`` of the outputs: ``y_1 = |Y| sin(Omega t + arg Y)``
        (the force is ``F sin(Omega t)``: the phase is relative to it, as in :class:`SteppedSine`)."""
        if self.harmonics < 1:
            return np.zeros(self.outputs.shape[::2], dtype=complex)
        return self.outputs[:, 2] + 1j * self.outputs[:, 1]

    @property
    def amplitude(self) -> np.ndarray:
        """(k, p) ``|Y|``: the outputs' fundamental amplitudes."""
        return np.abs(self.phasor)

    @property
    def phase_rad(self) -> np.ndarray:
        """(k, p) ``arg Y`` in (-pi, pi]."""
        return np.angle(self.phasor)

    def harmonic_amplitudes(self) -> np.ndarray:
        """(k, H+1, p) amplitude of each harmonic of the outputs (``|a_0|``, ``sqrt(a_k^2 + b_k^2)``)."""
        Y = self.outputs
        out = np.empty((Y.shape[0], self.harmonics + 1, Y.shape[2]))
        out[:, 0] = np.abs(Y[:, 0])
        out[:, 1:] = np.hypot(Y[:, 1::2], Y[:, 2::2])
        return out

    def rows(self, output: int = 0) -> list[dict]:
        """One dict per point for metrics.json (displacement amplitude and phase of one output)."""
        return [{"frequency_hz": float(f), "force": float(F), "amplitude": float(a), "phase_rad": float(p),
                 "iterations": int(i)}
                for f, F, a, p, i in zip(self.frequency_hz, self.force, self.amplitude[:, output],
                                         self.phase_rad[:, output], self.iterations)]


def _dense(J):
    return J.toarray() if sp.issparse(J) else np.asarray(J)


def _augmented(J, column, row):
    """``[[J, column], [row]]`` with ``row`` (m+1,) the bordering row."""
    row, corner = row[:-1], row[-1]
    if sp.issparse(J):
        return sp.bmat([[J, sp.csr_matrix(column.reshape(-1, 1))],
                        [sp.csr_matrix(row.reshape(1, -1)), sp.csr_matrix([[corner]])]], format="csc")
    return np.block([[J, column.reshape(-1, 1)], [row.reshape(1, -1), np.array([[corner]])]])


def arclength(fun, y0: np.ndarray, scale: np.ndarray, *, ds: float, direction: float, bounds, ds_min: float,
              ds_max: float, max_steps: int, newton: Newton, target_iterations: int = 5, solve_at=None):
    r"""Continue ``fun(y) -> (R (m,), J (m, m+1) as (J_z, dR/dlambda), scale)`` from the solution ``y0``.

    ``y = (z, lambda)`` of length ``m + 1``; ``scale`` (m+1,) the typical size of each
    component at the start (the coefficients' is then the largest coefficient of each accepted
    point, at least 1e-6 of the starting one); ``bounds`` the range of ``lambda``. Returns the accepted points (the start
    included) and their iteration counts (module docstring). ``solve_at(lambda, z) -> (z, iterations)``
    solves at a fixed ``lambda``: the branch then ends exactly at the bound it crosses.
    """
    w = np.array(scale, dtype=float)
    floor = 1e-6 * np.max(w[:-1])
    lo, hi = min(bounds), max(bounds)

    def tangent(y, previous):
        _, (Jz, Jl), _ = fun(y)
        # scaled variables u = y / w: dR/du = dR/dy diag(w)
        Jz_s = Jz @ sp.diags(w[:-1]) if sp.issparse(Jz) else Jz * w[:-1]
        A = _augmented(Jz_s, Jl * w[-1], previous)
        rhs = np.zeros(y.size)
        rhs[-1] = 1.0
        t = solve_linear(A, rhs)
        t /= np.linalg.norm(t)
        return t if t @ previous >= 0 else -t

    points, iterations = [np.array(y0, dtype=float)], [0]
    start = np.zeros(y0.size)
    start[-1] = np.sign(direction) or 1.0
    t = tangent(points[0], start)
    step = ds
    while len(points) < max_steps:
        y = points[-1]
        u_pred = y / w + step * t

        def corrector(u, t=t, u_pred=u_pred):
            R, (Jz, Jl), res_scale = fun(u * w)
            Jz_s = Jz @ sp.diags(w[:-1]) if sp.issparse(Jz) else Jz * w[:-1]
            J = _augmented(Jz_s, Jl * w[-1], t)
            return np.append(R, t @ (u - u_pred)), J, res_scale

        try:
            u, its, _, _ = newton_solve(corrector, u_pred, newton)
        except HarmonicBalanceError:
            step *= 0.5
            if step < ds_min:
                break
            continue
        y_new = u * w
        if not lo <= y_new[-1] <= hi:
            bound = hi if y_new[-1] > hi else lo
            if solve_at is not None and y_new[-1] != y[-1]:
                theta = (bound - y[-1]) / (y_new[-1] - y[-1])
                try:
                    z_end, its_end = solve_at(bound, y[:-1] + theta * (y_new[:-1] - y[:-1]))
                    points.append(np.append(z_end, bound))
                    iterations.append(its_end)
                except HarmonicBalanceError:
                    pass
            break
        secant = y_new - y
        # the coefficients' scale follows the motion (a resonance peak is many times the start)
        w[:-1] = max(np.max(np.abs(y_new[:-1])), floor)
        secant = secant / w
        t = tangent(y_new, secant / max(np.linalg.norm(secant), 1e-300))
        points.append(y_new)
        iterations.append(its)
        step = float(np.clip(step * np.clip(target_iterations / max(its, 1), 0.5, 2.0), ds_min, ds_max))
    return np.array(points), np.array(iterations)


def _curve(hb: HarmonicBalance, points, iterations, parameter, fixed, seconds, first_iterations):
    size, n = hb.basis.size, hb.n_dofs
    Z = points[:, :-1].reshape(-1, size, n)
    lam = points[:, -1]
    omega = lam if parameter == "frequency" else np.full(lam.size, fixed)
    force = lam if parameter == "force" else np.full(lam.size, fixed)
    change = np.array([hb.aft(z.reshape(-1), w, jacobian=False).state_change for z, w in zip(Z, omega)]) \
        if hb.stateful else np.zeros(lam.size)
    its = np.asarray(iterations, dtype=int).copy()
    its[0] = first_iterations
    return HarmonicBalanceCurve(omega, force, Z, Z @ hb.output_matrix.T, its, change, hb.basis.harmonics,
                                hb.basis.samples, parameter, seconds)


def _z_scale(z, hb):
    typical = np.max(np.abs(z)) if z.size else 1.0
    return np.full(z.size, typical if typical > 0 else 1.0)


def frequency_response(hb: HarmonicBalance, force: float, start: float, end: float, *, ds: float = 0.02,
                       ds_min: float = 1e-6, ds_max: float = 0.1, max_steps: int = 2000, initial=None,
                       newton: Newton | None = None, target_iterations: int = 5) -> HarmonicBalanceCurve:
    r"""The frequency response at force ``force`` from ``Omega = start`` to ``end`` [rad/s].

    The first point is solved by Newton from ``initial`` (nz,) (default the model linearised at
    rest); the branch is then continued by pseudo-arclength (module docstring) with the
    coefficients scaled by their largest magnitude at the start and ``Omega`` by ``start``;
    ``ds`` is the arclength in those scaled variables (0.02: about 2 % of the starting
    frequency per step away from resonance).
    """
    import time

    if not (start > 0 and end > 0 and start != end):
        raise FemromValueError(f"start and end must be distinct positive frequencies [rad/s], got {start}, {end}")
    newton = newton or HB_NEWTON
    tic = time.perf_counter()
    first = hb.solve(start, force, initial=initial, newton=newton)
    z0 = first.coefficients.reshape(-1)

    def fun(y):
        r = hb.residual(y[:-1], y[-1], force)
        return r["residual"], (r["jacobian"], r["d_omega"]), r["scale"]

    def solve_at(omega, z):
        sol = hb.solve(omega, force, initial=z, newton=newton)
        return sol.coefficients.reshape(-1), sol.iterations

    scale = np.append(_z_scale(z0, hb), abs(start))
    points, its = arclength(fun, np.append(z0, start), scale, ds=ds, direction=np.sign(end - start),
                            bounds=(start, end), ds_min=ds_min, ds_max=ds_max, max_steps=max_steps,
                            newton=newton, target_iterations=target_iterations, solve_at=solve_at)
    return _curve(hb, points, its, "frequency", force, time.perf_counter() - tic, first.iterations)


def force_response(hb: HarmonicBalance, omega: float, start: float, end: float, *, ds: float = 0.05,
                   ds_min: float = 1e-6, ds_max: float = 0.5, max_steps: int = 2000, initial=None,
                   newton: Newton | None = None, target_iterations: int = 5) -> HarmonicBalanceCurve:
    r"""The response at ``Omega = omega`` [rad/s] as the force goes from ``start`` to ``end`` (> 0),
    by pseudo-arclength in ``F`` (scaled by ``end``) and the coefficients (as
    :func:`frequency_response`)."""
    import time

    if not (start > 0 and end > 0 and start != end):
        raise FemromValueError(f"start and end must be distinct positive forces, got {start}, {end}")
    newton = newton or HB_NEWTON
    tic = time.perf_counter()
    first = hb.solve(omega, start, initial=initial, newton=newton)
    z0 = first.coefficients.reshape(-1)

    def fun(y):
        r = hb.residual(y[:-1], omega, y[-1])
        return r["residual"], (r["jacobian"], r["d_force"]), r["scale"]

    # the coefficients grow with F: scale them as at the larger end (linear estimate)
    ratio = max(abs(end), abs(start)) / abs(start)
    def solve_at(force, z):
        sol = hb.solve(omega, force, initial=z, newton=newton)
        return sol.coefficients.reshape(-1), sol.iterations

    scale = np.append(_z_scale(z0, hb) * ratio, max(abs(start), abs(end)))
    points, its = arclength(fun, np.append(z0, start), scale, ds=ds, direction=np.sign(end - start),
                            bounds=(start, end), ds_min=ds_min, ds_max=ds_max, max_steps=max_steps,
                            newton=newton, target_iterations=target_iterations, solve_at=solve_at)
    return _curve(hb, points, its, "force", omega, time.perf_counter() - tic, first.iterations)
