r"""Denoising sampled trajectories before a fit: one smooth curve per coordinate, fitted to the states
and (when they are measured) the velocities and accelerations at once.

Noise in the states is noise in the regressors of every learner that fits ``M^ q'' + f(q, q') = B u``
by least squares (errors in variables): it biases the learned stiffness by about ``sigma^2 / var``
of the weakly excited coordinates, however well the fit is solved. The snapshots of a trajectory
are densely sampled values of one smooth curve, so most of the noise can be removed before the fit.
For each coordinate ``j`` of each trajectory :class:`Smoothing` fits a B-spline ``x(t)`` of degree
``k`` (knots at the samples, uniform) by penalised weighted least squares,

.. math::

    \min_c\; \frac{\|x(t) - q\|^2}{\hat\sigma_q^2} + \frac{\|x'(t) - v\|^2}{\hat\sigma_v^2}
        + \frac{\|x''(t) - a\|^2}{\hat\sigma_a^2}
        + \lambda \int \big(x^{(m)}(t)\big)^2\, dt ,
    \qquad x(t) = \sum_i c_i B_i(t),

and returns ``x, x', x''`` at the samples: states, velocities and accelerations that are exact
derivatives of one curve. The three measurements constrain the curve at different frequencies:
the accelerations determine its fast content far better than the states (noise ``sigma_a /
omega^2``), the states its slow content. Without measured derivatives (finite differences of the
states, which carry the states' noise) only the states' term is used.

- ``sigma_hat`` of each field and coordinate comes from the data (the noise dominates the
  ``p``-th differences of densely sampled smooth data: ``sigma^2 ~ mean((Delta^p y)^2) / C(2p, p)``,
  Gasser, Sroka & Jennen-Steinmetz 1986), never from a known noise level;
- ``lambda`` minimises the unbiased risk estimate (Mallows' C_p, Craven & Wahba 1979)
  ``RSS_w - n + 2 tr H`` with those weights (``RSS_w`` the weighted residual, ``H`` the hat matrix,
  ``n`` the weighted observations) over a log grid, then refined; its trace ``tr((N + lambda P)^-1
  N)`` uses the band of the inverse of the banded normal matrix (Hutchinson & de Hoog 1985), so
  the cost is linear in the samples. (Generalised cross-validation, which needs no ``sigma``, picks
  the interpolating curve when only the states are fitted: the spline has a knot at every sample.)

On exact data the estimated noise is the smooth part's own differences, ``lambda`` comes out tiny
and, fitting all three fields, the curve stays within the spline's approximation error (relative
1e-8 in the states, 1e-6 in the accelerations on the systems of ``benchmarks/spml_systems.py``);
from the states alone it costs 1e-3 in the accelerations there. :meth:`Smoothing.auto` therefore
smooths only the trajectories whose regressors' estimated noise is at least :data:`AUTO_THRESHOLD`
of their RMS; it is :class:`~femrom.inference.SpML`'s default. The other learners take the data as
given unless asked (``smoothing=None``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from math import comb

import numpy as np

from femrom._errors import FemromTypeError, FemromValueError, nonnegative_integer, positive_integer

#: :meth:`Smoothing.auto`'s threshold on the estimated relative noise. Noise ``sigma`` in the states
#: biases a least-squares stiffness by about ``sigma^2`` (relative); the smoothing's own error on exact
#: data is about 2e-6 in the learned force (benchmarks/spml_convergence.py): below 1e-3 relative noise
#: (a bias below 1e-6) smoothing costs more than it removes.
AUTO_THRESHOLD = 1e-3

#: Which fields a smoothing fits: the states with the measured derivatives, or the states alone.
SMOOTHING_FIELDS = ("auto", "all", "states")
_DERIVED = ("finite_difference", "integrator")


@dataclass(frozen=True)
class Smoothing:
    """How trajectories are denoised before a fit (module docstring).

    Attributes
    ----------
    degree : int
        ``k``: the B-spline's degree (odd, >= 3; 5: the accelerations are a C^2 cubic).
    penalty_order : int
        ``m``: the derivative whose squared integral is penalised, ``2 <= m < degree`` (4 by
        default: the filter falls as ``omega^-8`` on the states' noise beyond its corner).
    fields : {"auto", "all", "states"}
        ``"all"``: fit the states, velocities and accelerations together (they must be independent
        measurements); ``"states"``: the states alone (derivatives from the curve); ``"auto"``: the
        states alone when the data's derivatives are finite differences of the states
        (``diagnostics["derivative_source"]``) or placeholders (all zero), else all three.
    noise_order : int
        ``p``: the order of the differences that estimate each field's noise.
    log_lambda : float or None
        ``log10`` of ``lambda`` relative to ``tr N / tr P`` (given: no search).
    threshold : float
        A trajectory whose regressors' estimated noise (:meth:`noise`) is below ``threshold`` is kept
        as measured (0: always smooth).
        :meth:`auto` sets it to :data:`AUTO_THRESHOLD`.
    """

    degree: int = 5
    penalty_order: int = 4
    fields: str = "auto"
    noise_order: int = 6
    log_lambda: float | None = None
    threshold: float = 0.0

    def __post_init__(self):
        k = positive_integer(self.degree, "Smoothing.degree")
        if k < 3 or k % 2 == 0:
            raise FemromValueError(f"Smoothing.degree must be odd and >= 3, got {self.degree!r}")
        m = nonnegative_integer(self.penalty_order, "Smoothing.penalty_order")
        if not 2 <= m < k:
            raise FemromValueError(f"Smoothing.penalty_order must be in 2 .. degree - 1 = {k - 1}, got {m}")
        if self.fields not in SMOOTHING_FIELDS:
            raise FemromValueError(f"Smoothing.fields must be one of {SMOOTHING_FIELDS}, got {self.fields!r}")
        p = positive_integer(self.noise_order, "Smoothing.noise_order")
        if self.log_lambda is not None and not np.isfinite(float(self.log_lambda)):
            raise FemromValueError(f"Smoothing.log_lambda must be finite or None, got {self.log_lambda!r}")
        if not float(self.threshold) >= 0.0 or not np.isfinite(float(self.threshold)):
            raise FemromValueError(f"Smoothing.threshold must be finite and >= 0, got {self.threshold!r}")
        object.__setattr__(self, "threshold", float(self.threshold))
        object.__setattr__(self, "degree", k)
        object.__setattr__(self, "penalty_order", m)
        object.__setattr__(self, "noise_order", p)

    @classmethod
    def auto(cls) -> "Smoothing":
        """Smooth only the trajectories whose estimated noise exceeds :data:`AUTO_THRESHOLD`."""
        return cls(threshold=AUTO_THRESHOLD)

    @classmethod
    def of(cls, value) -> "Smoothing | None":
        """``None``/``False``: no smoothing; ``True``: the defaults (always smooth); ``"auto"``:
        :meth:`auto`; a :class:`Smoothing` as is."""
        if value is None or value is False:
            return None
        if value is True:
            return cls()
        if isinstance(value, str) and value == "auto":
            return cls.auto()
        if isinstance(value, cls):
            return value
        raise FemromTypeError(f"smoothing must be a Smoothing, True, 'auto' or None, got {value!r}")

    def noise(self, data) -> list[float]:
        """Per trajectory of ``data``, the largest estimated noise of a regressor over the coordinates,
        relative to its RMS: the states' and, when they are measured (``fields`` "all"), the
        velocities' (what :attr:`threshold` is compared with). The noise that biases a fit is the
        regressors' (errors in variables); the accelerations are its target, and integrator data
        carry their under-resolved fast content there (the jointed beam's Newmark runs: 1e-3 in
        the accelerations, 1e-5 .. 1e-4 in the states and velocities). The estimate is the robust one
        of :func:`noise_level`, blind to a stick-slip kink or a blow's end."""
        use = (0,) if self._fields(data) == "states" else (0, 1)
        bounds = list(data.starts) + [data.n_samples]
        fields = (data.states, data.velocities, data.accelerations)
        out = []
        for a, b in zip(bounds[:-1], bounds[1:]):
            worst = 0.0
            for i in use:
                y = fields[i][:, a:b]
                rms = np.sqrt(np.mean(y * y, axis=1))
                # a coordinate at round-off against the largest one (a POD tail) is not judged by its own
                # scale: relative to 1e-6 of the largest
                rms = np.maximum(rms, 1e-6 * rms.max(initial=0.0))
                for j in range(data.r):
                    if rms[j] > 0.0:
                        worst = max(worst, noise_level(y[j], self.noise_order, robust=True) / rms[j])
            out.append(worst)
        return out

    def _fields(self, data) -> str:
        if self.fields != "auto":
            return self.fields
        placeholders = not (np.any(data.velocities) and np.any(data.accelerations))
        return "states" if placeholders or data.diagnostics.get("derivative_source") in _DERIVED else "all"

    def apply(self, data):
        """``data`` (a :class:`SecondOrderData`, or a list of them) with each trajectory (split at its
        ``starts``) replaced by the smooth curve's states, velocities and accelerations; inputs,
        outputs and forces unchanged. ``diagnostics["smoothing"]`` records, per trajectory, the
        estimated noise of each field (relative to its RMS), ``log_lambda`` and the curve's degrees of
        freedom."""
        if isinstance(data, (list, tuple)):
            return [self.apply(d) for d in data]
        fields = self._fields(data)
        use = (0,) if fields == "states" else (0, 1, 2)
        bounds = list(data.starts) + [data.n_samples]
        # a threshold keeps data it cannot judge (differences need a uniform grid); without one, they are refused
        step = _step(data, required=self.threshold == 0.0)
        noise = [np.inf] * (len(bounds) - 1) if self.threshold == 0.0 else \
            [None] * (len(bounds) - 1) if step is None else self.noise(data)
        summary = {"fields": fields, "threshold": self.threshold}
        if step is None or all(level < self.threshold for level in noise):       # every trajectory kept: no copies
            if step is None:
                summary["note"] = "not uniformly sampled: kept as given"
            report = [{"kept": True, "noise": None if level is None else float(level)} for level in noise]
            return replace(data, diagnostics=dict(data.diagnostics, smoothing={**summary, "trajectories": report}))
        report = []
        out = [data.states.copy(), data.velocities.copy(), data.accelerations.copy()]
        for (a, b), level in zip(zip(bounds[:-1], bounds[1:]), noise):
            if level < self.threshold:
                report.append({"kept": True, "noise": float(level)})
                continue
            if b - a < self.degree + 2 * self.noise_order:
                raise FemromValueError(f"smoothing needs at least {self.degree + 2 * self.noise_order} samples a "
                                       f"trajectory, got {b - a} (columns {a}..{b - 1})")
            basis = _SplineBasis(b - a, step, self.degree, self.penalty_order)
            rows = []
            for j in range(data.r):
                fields_j = [data.states[j, a:b], data.velocities[j, a:b], data.accelerations[j, a:b]]
                curve, info = basis.fit([fields_j[i] for i in use], use, self.noise_order, self.log_lambda)
                for i in range(3):
                    out[i][j, a:b] = curve[i]
                rows.append(info)
            report.append(rows)
        diagnostics = dict(data.diagnostics, smoothing={**summary, "trajectories": report})
        return replace(data, states=out[0], velocities=out[1], accelerations=out[2], diagnostics=diagnostics)


def noise_level(y: np.ndarray, order: int = 6, *, robust: bool = False) -> float:
    r"""The standard deviation of white noise on a densely sampled smooth signal ``y`` (K,):
    ``sqrt(mean((Delta^p y)^2) / C(2p, p))`` (the ``p``-th differences of the smooth part are
    ``O((omega dt)^p)`` of it, the noise's have variance ``C(2p, p) sigma^2``). ``robust``: from the
    median absolute difference instead, ``1.4826 median|Delta^p y| / sqrt(C(2p, p))`` (the same for
    Gaussian noise, and blind to isolated kinks and jumps of a piecewise smooth signal: a stick-slip
    transition, a blow's end)."""
    d = np.diff(np.asarray(y, dtype=float), order)
    if not d.size:
        return 0.0
    if robust:
        return float(1.482602218505602 * np.median(np.abs(d)) / np.sqrt(comb(2 * order, order)))
    return float(np.sqrt(np.mean(d * d) / comb(2 * order, order)))


def _step(data, *, required: bool = True) -> float | None:
    """The uniform sampling step of ``data``; without one, an error (``required``) or ``None``."""
    from femrom.inference._data import sampling_step

    h = sampling_step(data)
    if h is None:
        h = data.diagnostics.get("dt") if data.diagnostics.get("n_trajectories", 1) == 1 else None
    if h is None or not h > 0:
        if not required:
            return None
        raise FemromValueError("smoothing needs uniformly sampled trajectories (times, or diagnostics dt)")
    return float(h)


class _SplineBasis:
    """B-splines of degree ``k`` on uniform knots at ``K`` samples ``h`` apart (extended by ``k`` knots
    each side): sparse design matrices of the value and the first two derivatives at the samples,
    and the banded penalty ``P_il = int B_i^(m) B_l^(m) dt`` (Gauss-Legendre, exact)."""

    def __init__(self, K: int, h: float, k: int, m: int):
        from scipy.interpolate import BSpline

        t = h * np.arange(K)
        knots = np.concatenate([t[0] - h * np.arange(k, 0, -1), t, t[-1] + h * np.arange(1, k + 1)])
        self.n, self.k = len(knots) - k - 1, k
        # the basis functions are translates: evaluate one on its support at the needed offsets
        unit = BSpline.basis_element(np.arange(k + 2, dtype=float), extrapolate=False)

        def values(x_offsets, derivative):
            f = unit.derivative(derivative) if derivative else unit
            return np.nan_to_num(f(x_offsets)) / h ** derivative

        # at sample s (knot index s + k) the basis functions i = s .. s + k - 1 (B_i on knots i .. i + k + 1)
        # can be nonzero: the sample sits at offset k - (i - s) of B_i's support (B_{s+k} starts there,
        # with value and derivatives below k zero)
        offsets = k - np.arange(k, dtype=float)
        self.design = [values(offsets, d) for d in range(3)]            # (k,) weights of B_s .. B_{s+k-1}
        self.K = K
        g, w = np.polynomial.legendre.leggauss(k - m + 1)
        x = 0.5 * (g + 1.0)                                              # points in one knot interval
        # on interval [t_s, t_{s+1}] the nonzero functions are B_s .. B_{s+k} at offsets k - (i - s) + x
        local = np.array([values(k - j + x, m) for j in range(k + 1)])   # (k + 1, points)
        block = (local * (0.5 * w * h)) @ local.T                        # (k + 1, k + 1) per interval
        P = np.zeros((k + 1, self.n))                                    # upper banded storage
        for s in range(K - 1):
            for j in range(k + 1):
                for l in range(j, k + 1):
                    P[k - (l - j), s + l] += block[j, l]
        self.penalty = P

    def _normal(self, weights):
        """Upper banded ``N = sum_f w_f A_f^T A_f`` and the row map (each sample touches k + 1 functions)."""
        k = self.k
        N = np.zeros((k + 1, self.n))
        for w, d in weights:
            outer = np.outer(d, d) * w
            for j in range(k):
                for l in range(j, k):
                    N[k - (l - j), l:l + self.K] += outer[j, l]
        return N

    def _apply(self, d, c):
        """``A_d c`` at the samples: (K,)."""
        return sum(d[j] * c[j:j + self.K] for j in range(self.k))

    def _transpose(self, d, y):
        out = np.zeros(self.n)
        for j in range(self.k):
            out[j:j + self.K] += d[j] * y
        return out

    def fit(self, fields, use, noise_order, log_lambda):
        from scipy.linalg import cholesky_banded, cho_solve_banded

        k = self.k
        sigma = []
        for y in fields:
            rms = float(np.sqrt(np.mean(y * y)))
            sigma.append(max(noise_level(y, noise_order), 1e-12 * rms, np.finfo(float).tiny))
        weights = [(1.0 / s ** 2, self.design[i]) for s, i in zip(sigma, use)]
        N = self._normal(weights)
        rhs = sum(self._transpose(d, y) * w for (w, d), y in zip(weights, fields))
        n_obs = self.K * len(use)
        P = self.penalty
        scale = float(np.sum(N[k]) / max(np.sum(P[k]), np.finfo(float).tiny))

        def solve(ll):
            S = N + (scale * 10.0 ** ll) * P
            U = cholesky_banded(S, lower=False)
            c = cho_solve_banded((U, False), rhs)
            rss = sum(w * float(np.sum((self._apply(d, c) - y) ** 2)) for (w, d), y in zip(weights, fields))
            return c, rss, U

        def risk(ll):
            c, rss, U = solve(ll)
            trace = float(np.sum(_inverse_band(U) * N * _band_multiplicity(k, self.n)))
            return rss - n_obs + 2.0 * trace, trace

        if log_lambda is None:
            grid = np.arange(-14.0, 8.01, 1.0)
            scores = [risk(ll)[0] for ll in grid]
            i = int(np.argmin(scores))
            lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
            from scipy.optimize import minimize_scalar

            best = minimize_scalar(lambda ll: risk(ll)[0], bounds=(lo, hi), method="bounded",
                                   options={"xatol": 0.02})
            log_lambda = float(best.x) if best.fun <= scores[i] else float(grid[i])
        c, _, _ = solve(log_lambda)
        dof = risk(log_lambda)[1]
        curve = [self._apply(self.design[d], c) for d in range(3)]
        names = ("states", "velocities", "accelerations")
        rms = [max(float(np.sqrt(np.mean(y * y))), np.finfo(float).tiny) for y in fields]
        return curve, {"noise": {names[i]: s / r for s, r, i in zip(sigma, rms, use)},
                       "log_lambda": float(log_lambda), "dof": dof}


def _band_multiplicity(k: int, n: int) -> np.ndarray:
    """Weights of the upper band storage in ``tr(Z N) = sum_ij Z_ij N_ij`` (off-diagonals twice)."""
    w = np.full((k + 1, n), 2.0)
    w[k] = 1.0
    return w


def _inverse_band(U: np.ndarray) -> np.ndarray:
    """The band (upper storage, as ``U``) of ``S^-1`` for ``S = U^T U``, ``U`` upper banded Cholesky
    (scipy's ``cholesky_banded`` storage): the recurrence ``Z = U^-1 U^-T``, from the last row up,
    ``Z_ij = delta_ij / U_ii^2 - sum_{l > i} (U_il / U_ii) Z_lj`` for ``j >= i`` in the band."""
    b, n = U.shape[0] - 1, U.shape[1]
    diag = U[b]
    # R[i, d] = U[i, i + d] / U[i, i], d = 1..b
    R = np.zeros((n, b + 1))
    for d in range(1, b + 1):
        R[:n - d, d] = U[b - d, d:] / diag[:n - d]
    Z = np.zeros((n, b + 1))              # Z[i, d] = Z_{i, i+d}
    block = np.zeros((b, b))              # Z at rows and columns i+1 .. i+b (zero beyond n)
    for i in range(n - 1, -1, -1):
        r = R[i, 1:]
        off = -(block @ r)                # Z_{i, i+d}, d = 1..b
        Z[i, 0] = 1.0 / diag[i] ** 2 - float(r @ off)
        Z[i, 1:] = off
        block[1:, 1:] = block[:-1, :-1].copy()
        block[0, 0] = Z[i, 0]
        block[0, 1:] = block[1:, 0] = off[:-1]
    band = np.zeros_like(U)
    for d in range(b + 1):
        band[b - d, d:] = Z[:n - d, d]
    return band
