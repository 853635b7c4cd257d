r"""Output-error refinement of a learned second-order model: its parameters fitted through its own trajectories.

An equation-error fit (L-OpInf, SpML's least squares and L-BFGS) regresses the measured
accelerations on the measured states; with noise on the states that is an errors-in-variables
problem, and smoothing first removes only the noise outside the signal's band. The output-error
fit instead simulates every measured trajectory from an estimated initial state and minimises

.. math::

    \sum_{\text{trajectories } i} \sum_{x \in \{q,\, q',\, q''\}}
        \frac{\| x^{\text{model}}_i(\theta, y_{0,i}) - x^{\text{data}}_i \|_F^2}{\sigma_{x,i}^2}

over the model's parameters ``theta`` that enter its balance linearly (the mass up to its gauge
``tr M^`` fixed, the learned linear terms ``K^, C^, B^, f^_0``, the potential's monomial
coefficients) and the initial states ``y_0,i = (q_0, q'_0)``; networks, convex powers and every
other term stay as they are. ``q''`` is the model's acceleration at the simulated state (its
equation of motion), ``sigma`` each field's noise estimated from the data (robust sixth
differences, :func:`noise_level`). With white Gaussian noise of those levels this is the
maximum-likelihood estimate of ``theta``; its cost ends near the noise's expectation, half the
number of residuals.

The trajectories are the model's discrete-gradient march (:mod:`femrom.integrators`, compiled when
the terms allow) at ``substeps`` steps per sample, so the scheme's own error (``O(h^2)``) stays
well below the noise. The Jacobian is the march's exact forward sensitivity (one linear
recursion per trajectory, all parameters as columns): with ``v_m = (v_k + v_{k+1}) / 2`` the step
solves

.. math::

    R = \tfrac{2}{h} M (v_m - v_k) + C v_m + K q_m + \bar\nabla U(q_k, q_{k+1}) + f(q_m, v_m) - F_m = 0,

so ``delta v_m = -J^{-1} (A_q delta q_k - (2/h) M delta v_k + dR/dtheta)``, ``J`` the step's Newton
matrix, ``A_q = K + int_0^1 grad^2 U + df/dq`` (two-point Gauss, exact for quartic potentials;
Gonzalez's correction of a network potential is left out of the derivative only).
Levenberg-Marquardt on the normal equations, a Jacobian per accepted step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromError, FemromValueError
from femrom.inference._data import SecondOrderData, sampling_step
from femrom.inference._networks import SymmetricPolynomial, derivative_map, monomials
from femrom.inference._operators import ReducedOperators
from femrom.inference._smoothing import _DERIVED as DERIVED_SOURCES
from femrom.inference._smoothing import noise_level
from femrom.inference._terms import LinearTerm
from femrom.inference.terms.learned_potential import LearnedPotential

#: Gauss-Legendre on [0, 1], two points (the discrete gradient's quadrature).
_NODES = 0.5 + 0.5 * np.array([-1.0, 1.0]) / np.sqrt(3.0)
_WEIGHTS = np.array([0.5, 0.5])

#: Steps whose parameter forcing is formed at once in the sensitivity recursion.
_CHUNK = 128

#: A field's noise is floored at this fraction of its RMS (a field at round-off would otherwise
#: take all the weight).
NOISE_FLOOR = 1e-6


@dataclass(frozen=True)
class OutputError:
    """Settings of the output-error refinement (module docstring).

    Attributes
    ----------
    iterations : int
        Levenberg-Marquardt steps at most (each: one Jacobian, one or more trial simulations).
    substeps : int
        Discrete-gradient steps per sampling interval (8: the scheme's error about 1e-2 of its
        error at the data's step).
    tolerance : float
        The fit stops when an accepted step lowers the cost by less than this fraction.
    """

    iterations: int = 20
    substeps: int = 8
    tolerance: float = 1e-7

    def __post_init__(self):
        for name in ("iterations", "substeps"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 1:
                raise FemromValueError(f"OutputError.{name} must be an integer >= 1, got {value!r}")
        if not (np.isfinite(self.tolerance) and self.tolerance >= 0):
            raise FemromValueError(f"OutputError.tolerance must be finite and >= 0, got {self.tolerance!r}")


# -- the parameters ------------------------------------------------------------------------------
class _Linear:
    """A free linear term: ``sign * (A_0 + sum_j theta_j E_j) z``."""

    def __init__(self, term: LinearTerm, gauge: bool):
        self.term, self.name, self.variable, self.sign = term, term.name, term.variable, float(term.sign)
        A = term.matrix
        rows, cols = A.shape
        basis = []
        if term.structure in ("spd", "psd", "symmetric"):
            for a in range(rows):
                for b in range(a, cols):
                    E = np.zeros((rows, cols))
                    E[a, b] = E[b, a] = 1.0
                    basis.append(E)
            if gauge:                 # tr M^ fixed: the diagonal moves by differences only
                basis = [E for E in basis if not (np.count_nonzero(E) == 1 and E[0, 0] == 1.0)]
                for E in basis:
                    if np.count_nonzero(E) == 1:
                        E[0, 0] = -1.0
        else:
            for a in range(rows):
                for b in range(cols):
                    E = np.zeros((rows, cols))
                    E[a, b] = 1.0
                    basis.append(E)
        self.basis = np.array(basis).reshape(len(basis), rows, cols)

    @property
    def size(self) -> int:
        return self.basis.shape[0]

    def matrix(self, theta) -> np.ndarray:
        return self.term.matrix + np.tensordot(theta, self.basis, axes=1)

    def columns(self, Z: np.ndarray) -> np.ndarray:
        """(K, r, size): ``sign E_j z`` at the columns of ``Z`` (p, K)."""
        return self.sign * np.einsum("jab,bk->kaj", self.basis, Z)


class _Polynomial:
    """The free monomial coefficients of a learned potential (its network fixed)."""

    def __init__(self, term: LearnedPotential):
        import scipy.sparse as sp

        self.term, self.r = term, term.r
        self.degrees = sorted(term.polynomial.terms)
        self.counts = [term.polynomial.terms[d][0].shape[0] for d in self.degrees]
        self.size = int(sum(self.counts))
        # d x^m / d x_i = e x^p: one sparse map from the monomials of degree d - 1 to the (i, m) pairs
        self.maps = []
        for d, n in zip(self.degrees, self.counts):
            m, p, i, e = derivative_map(self.r, d)
            lower = int(p.max()) + 1 if p.size else 0
            self.maps.append(sp.csr_matrix((e.astype(float), (i * n + m, p)), shape=(self.r * n, lower)))

    def potential(self, theta) -> LearnedPotential:
        terms, at = {}, 0
        for d in self.degrees:
            index, coefficients = self.term.polynomial.terms[d]
            terms[d] = (index, coefficients + theta[at:at + coefficients.size])
            at += coefficients.size
        return LearnedPotential(self.r, SymmetricPolynomial(self.r, terms), self.term.network)

    def columns(self, X: np.ndarray) -> np.ndarray:
        """(K, r, size): the monomials' gradients at the columns of ``X`` (r, K)."""
        K = X.shape[1]
        blocks = []
        for d, n, S in zip(self.degrees, self.counts, self.maps):
            lower = monomials(X.T, d - 1)                       # (K, n_{d-1})
            blocks.append(np.asarray(S @ lower.T).reshape(self.r, n, K).transpose(2, 0, 1))
        return np.concatenate(blocks, axis=2) if blocks else np.zeros((K, self.r, 0))


def _hessians(term, X: np.ndarray) -> np.ndarray:
    """(K, r, r) the Hessians of a learned potential at the columns of ``X``: the polynomial's by
    contractions, a network's point by point."""
    K, r = X.shape[1], X.shape[0]
    H = np.zeros((K, r, r))
    poly = getattr(term, "polynomial", None)
    if poly is not None:
        H += 6.0 * np.einsum("ijk,kn->nij", poly.T3, X) + 12.0 * np.einsum("ijkl,kn,ln->nij", poly.T4, X, X)
    network = getattr(term, "network", None)
    if network is not None:
        H += network.hessians(X)
    if poly is None and network is None:
        for k in range(K):
            H[k] = term.tangent(X[:, k])[0]
    return H


def _tangents(terms, Q: np.ndarray, V: np.ndarray):
    """``(df/dq, df/dv)``, each (K, r, r): the summed tangents of ``terms`` at the columns of ``(Q, V)``."""
    K, r = Q.shape[1], Q.shape[0]
    Tq, Tv = np.zeros((K, r, r)), np.zeros((K, r, r))
    for t in terms:
        for k in range(K):
            Jq, Jv = t.tangent(Q[:, k], V[:, k])
            if Jq is not None:
                Tq[k] += Jq
            if Jv is not None:
                Tv[k] += Jv
    return Tq, Tv


class _Model:
    """The operators as a function of ``theta`` and what the sensitivities need of them."""

    def __init__(self, operators: ReducedOperators, free: tuple):
        self.operators, self.r = operators, operators.r
        self.linear, self.polynomial = [], None
        for t in operators.terms:
            if isinstance(t, LinearTerm):
                if t.name in free and t.role == "balance" and t.variable in ("q", "v", "a", "u", "1"):
                    self.linear.append(_Linear(t, gauge=t.variable == "a"))
            elif isinstance(t, LearnedPotential) and "learned_potential" in free and t.polynomial is not None:
                self.polynomial = _Polynomial(t)
        others = [t for t in operators.terms if not isinstance(t, LinearTerm)]
        stateful = [t.name for t in others if t.stateful]
        if stateful:
            raise FemromValueError(f"output error: the terms {stateful} carry a state, which the sensitivities "
                                   "do not follow")
        self.sizes = [b.size for b in self.linear] + [0 if self.polynomial is None else self.polynomial.size]
        self.size = int(sum(self.sizes))

    def split(self, theta):
        out, at = [], 0
        for n in self.sizes:
            out.append(theta[at:at + n])
            at += n
        return out

    def at(self, theta) -> ReducedOperators:
        parts = self.split(theta)
        replaced = [type(b.term)(b.matrix(p)) for b, p in zip(self.linear, parts)]
        if self.polynomial is not None:
            replaced.append(self.polynomial.potential(parts[-1]))
        return self.operators.with_terms(*replaced)

    def columns(self, Z: dict, gauss=None, X=None) -> np.ndarray:
        """(K, r, size) ``dR/dtheta``: the linear blocks at ``Z`` (variable -> (p, K)), the monomials
        by the quadrature over ``gauss`` (list of (r, K)) or at ``X``."""
        K = next(iter(Z.values())).shape[1]
        blocks = [b.columns(Z[b.variable]) for b in self.linear]
        if self.polynomial is not None:
            if gauss is not None:
                blocks.append(sum(w * self.polynomial.columns(G) for w, G in zip(_WEIGHTS, gauss)))
            else:
                blocks.append(self.polynomial.columns(X))
        return np.concatenate(blocks, axis=2) if blocks else np.zeros((K, self.r, 0))


# -- one trajectory ------------------------------------------------------------------------------
@dataclass
class _Trajectory:
    data: SecondOrderData          # one measured trajectory
    fields: tuple                  # which of (q, v, a) enter
    sigma: tuple                   # their noise levels
    dt: float

    @property
    def n_residuals(self) -> int:
        return len(self.fields) * self.data.states.size


def _trajectories(datasets) -> list[SecondOrderData]:
    """Every trajectory of ``datasets`` (split at their ``starts``) with its sample times (from the
    sampling step where concatenated data carry none)."""
    out = []
    for d in datasets:
        bounds = list(d.starts) + [d.n_samples]
        dt = sampling_step(d)
        if dt is None:
            raise FemromValueError("output error needs uniformly sampled trajectories (times, or the sampling step "
                                   "of concatenated data)")
        for a, b in zip(bounds[:-1], bounds[1:]):
            times = dt * np.arange(b - a) if d.times is None else d.times[a:b]
            out.append(SecondOrderData(d.states[:, a:b], d.velocities[:, a:b], d.accelerations[:, a:b],
                                       inputs=None if d.inputs is None else d.inputs[:, a:b],
                                       times=times, diagnostics=dict(d.diagnostics)))
    return out


def measured_fields(data: SecondOrderData) -> tuple:
    """The fields of ``data`` that are measurements: the states, and the velocities and accelerations
    unless they are finite differences or an integrator's (``diagnostics["derivative_source"]``) or
    placeholders (all zero)."""
    derived = data.diagnostics.get("derivative_source") in DERIVED_SOURCES
    if derived or not (np.any(data.velocities) and np.any(data.accelerations)):
        return (0,)
    return (0, 1, 2)


def field_noise(data: SecondOrderData, field: int) -> float:
    """The noise level of one field of one trajectory: the RMS over its coordinates of their robust
    sixth-difference estimates (:func:`noise_level`), floored at :data:`NOISE_FLOOR` of the field's RMS."""
    y = (data.states, data.velocities, data.accelerations)[field]
    levels = np.array([noise_level(row, 6, robust=True) for row in y])
    rms = float(np.sqrt(np.mean(y * y)))
    return max(float(np.sqrt(np.mean(levels ** 2))), NOISE_FLOOR * rms, np.finfo(float).tiny)


class _Problem:
    """The weighted residuals and their Jacobian for given trajectories (the model's ``theta`` free
    or not; every trajectory's initial state free)."""

    def __init__(self, model: _Model, trajectories: list, settings: OutputError, free_theta: bool = True):
        from femrom.integrators import march

        self.model, self.settings, self.march = model, settings, march
        self.trajectories = trajectories
        self.n_theta = model.size if free_theta else 0
        self.r = model.r

    def _simulate(self, operators, y0, traj: _Trajectory):
        s, d = self.settings.substeps, traj.data
        h = traj.dt / s
        n = d.n_samples - 1
        times = float(d.times[0]) + h * np.arange(n * s + 1)
        inputs = None
        if d.inputs is not None:
            fine = np.arange(n * s + 1) / s
            inputs = np.array([np.interp(fine, np.arange(n + 1), row) for row in d.inputs])
        r = self.r
        out = self.march(operators.system, "discrete_gradient", times, y0[:r], y0[r:], inputs=inputs)
        return out["q"], out["v"], inputs, h

    @staticmethod
    def _acceleration(operators, Q, V, U):
        """(r, K) the model's acceleration at the columns ``(Q, V)`` with inputs ``U``."""
        lhs = np.zeros_like(Q)
        for t in operators.terms:
            if isinstance(t, LinearTerm):
                if t.role != "balance" or t.variable == "a":
                    continue
                z = {"q": Q, "v": V, "u": U, "1": np.ones((1, Q.shape[1]))}[t.variable]
                lhs += t.sign * (t.matrix @ z)
            else:
                lhs += t.forces(Q, V)
        return np.linalg.solve(operators.mass_matrix, -lhs)

    def evaluate(self, theta, y0s, jacobian: bool = False):
        """The weighted residual vector (and its Jacobian: columns ``theta`` then each trajectory's
        ``(q_0, q'_0)``); ``None`` when a simulation fails."""
        operators = self.model.at(theta) if self.n_theta else self.model.operators
        residuals, blocks = [], []
        for i, (traj, y0) in enumerate(zip(self.trajectories, y0s)):
            try:
                with np.errstate(all="ignore"):
                    Qf, Vf, Uf, h = self._simulate(operators, y0, traj)
            except (FemromError, ArithmeticError, np.linalg.LinAlgError):
                return None
            if not (np.all(np.isfinite(Qf)) and np.all(np.isfinite(Vf))):
                return None
            s = self.settings.substeps
            Q, V = Qf[:, ::s], Vf[:, ::s]
            d = traj.data
            A = self._acceleration(operators, Q, V, d.inputs)
            sim = (Q, V, A)
            data = (d.states, d.velocities, d.accelerations)
            residuals.append(np.concatenate([((sim[f] - data[f]) / sg).ravel()
                                             for f, sg in zip(traj.fields, traj.sigma)]))
            if jacobian:
                blocks.append(self._sensitivity(operators, traj, Qf, Vf, Uf, h, A))
        r = np.concatenate(residuals)
        if not jacobian:
            return r
        n_cols = self.n_theta + 2 * self.r * len(self.trajectories)
        J = np.zeros((r.size, n_cols))
        row = 0
        for i, (Jt, Jy) in enumerate(blocks):
            rows = Jy.shape[0]
            J[row:row + rows, :self.n_theta] = Jt
            c = self.n_theta + 2 * self.r * i
            J[row:row + rows, c:c + 2 * self.r] = Jy
            row += rows
        return r, J

    def _sensitivity(self, operators, traj: _Trajectory, Qf, Vf, Uf, h, A):
        """``(J_theta, J_y0)``: the weighted residual's derivatives for one trajectory."""
        model, r, s = self.model, self.r, self.settings.substeps
        M, K = operators.mass_matrix, operators.stiffness
        C = operators.damping if operators.damping is not None else np.zeros((r, r))
        potentials = [t for t in operators.terms if isinstance(t, LearnedPotential)]
        others = [t for t in operators.terms if not isinstance(t, (LinearTerm, LearnedPotential))]
        q0, q1, v0 = Qf[:, :-1], Qf[:, 1:], Vf[:, :-1]
        X = 0.5 * (Vf[:, :-1] + Vf[:, 1:])
        Qm = 0.5 * (q0 + q1)
        N = X.shape[1]
        gauss = [q0 + c * (q1 - q0) for c in _NODES]
        Jx = np.broadcast_to((2.0 / h) * M + C + 0.5 * h * K, (N, r, r)).copy()
        Aq = np.broadcast_to(K, (N, r, r)).copy()
        for t in potentials:
            for c, w, G in zip(_NODES, _WEIGHTS, gauss):
                H = _hessians(t, G)
                Jx += (h * w * c) * H
                Aq += w * H
        Tq, Tv = _tangents(others, Qm, X)
        Jx += Tv + (0.5 * h) * Tq
        Aq += Tq
        n_theta = self.n_theta
        width = n_theta + 2 * r
        Jinv = np.linalg.inv(Jx)
        Gq, Gv = -Jinv @ Aq, Jinv @ ((2.0 / h) * M)
        # (dq, dv)_{k+1} = Phi_k (dq, dv)_k + Gamma_k: dx = Gq dq + Gv dv + Gt, dq_{k+1} = dq_k + h dx,
        # dv_{k+1} = 2 dx - dv_k
        Phi = np.empty((N, 2 * r, 2 * r))
        Phi[:, :r, :r] = np.eye(r) + h * Gq
        Phi[:, :r, r:] = h * Gv
        Phi[:, r:, :r] = 2.0 * Gq
        Phi[:, r:, r:] = 2.0 * Gv - np.eye(r)
        S = np.zeros((2 * r, width))
        S[:, n_theta:] = np.eye(2 * r)
        n_samples = traj.data.n_samples
        SS = np.empty((n_samples, 2 * r, width))
        SS[0] = S
        U = None if Uf is None else 0.5 * (Uf[:, :-1] + Uf[:, 1:])
        lift = np.concatenate([h * np.eye(r), 2.0 * np.eye(r)])          # dx -> (dq, dv) of the next step
        # the parameters' forcing (h, 2) (x) -J^-1 dR/dtheta in chunks of steps (its (N, 2r, n_theta) whole
        # would be hundreds of MB at r = 8)
        for a in range(0, N, _CHUNK):
            b = min(N, a + _CHUNK)
            if n_theta:
                Z = {"q": Qm[:, a:b], "v": X[:, a:b], "a": (2.0 / h) * (X[:, a:b] - v0[:, a:b]),
                     "1": np.ones((1, b - a)), "u": None if U is None else U[:, a:b]}
                Gamma = -((lift @ Jinv[a:b]) @ model.columns(Z, gauss=[g[:, a:b] for g in gauss]))
            for k in range(a, b):
                S = Phi[k] @ S
                if n_theta:
                    S[:, :n_theta] += Gamma[k - a]
                if (k + 1) % s == 0:
                    SS[(k + 1) // s] = S
        SQ, SV = SS[:, :r], SS[:, r:]
        # the acceleration's: M delta a = -(delta(lhs)/dtheta + (K + H + df/dq) delta q + (C + df/dv) delta v + delta M a)
        d = traj.data
        Q, V = Qf[:, ::s], Vf[:, ::s]
        Tq, Tv = _tangents(others, Q, V)
        Tq += K
        Tv += C
        for t in potentials:
            Tq += _hessians(t, Q)
        dlhs = Tq @ SQ + Tv @ SV
        if n_theta:
            Z = {"q": Q, "v": V, "a": A, "u": d.inputs, "1": np.ones((1, n_samples))}
            dlhs[:, :, :n_theta] += model.columns(Z, X=Q)
        SA = -np.linalg.solve(M, dlhs)               # (n, r, width) broadcast over the samples
        sens = (SQ, SV, SA)
        rows = [np.transpose(sens[f], (1, 0, 2)).reshape(r * n_samples, width) / sg
                for f, sg in zip(traj.fields, traj.sigma)]
        J = np.concatenate(rows, axis=0)
        return J[:, :n_theta], J[:, n_theta:]


def _levenberg_marquardt(problem: _Problem, theta, y0s, settings: OutputError, progress=None):
    """Levenberg-Marquardt on ``(theta, y0s)``; returns ``(theta, y0s, cost, cost_0, steps)``."""
    n_theta, r = problem.n_theta, problem.r
    x = np.concatenate([theta] + list(y0s))

    def unpack(x):
        return x[:n_theta], [x[n_theta + 2 * r * i:n_theta + 2 * r * (i + 1)] for i in range(len(y0s))]

    out = problem.evaluate(*unpack(x), jacobian=True)
    if out is None:
        raise FemromValueError("output error: the model's simulation of the training trajectories fails at the start")
    res, J = out
    cost = cost0 = 0.5 * float(res @ res)
    mu, steps = 1e-3, 0                      # the damping, relative to the diagonal (Marquardt's scaling)
    for _ in range(settings.iterations):
        g = J.T @ res
        JTJ = J.T @ J
        diag = np.maximum(np.diag(JTJ), 1e-300)
        accepted = False
        for _ in range(12):
            try:
                step = np.linalg.solve(JTJ + mu * np.diag(diag), -g)
            except np.linalg.LinAlgError:
                mu *= 10.0
                continue
            trial = problem.evaluate(*unpack(x + step))
            trial_cost = np.inf if trial is None else 0.5 * float(trial @ trial)
            predicted = -(g @ step + 0.5 * step @ (JTJ @ step))
            if trial_cost < cost:
                rho = (cost - trial_cost) / max(predicted, np.finfo(float).tiny)
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3) if rho > 0 else 2.0
                accepted = True
                break
            mu *= 4.0
        if not accepted:
            break
        x = x + step
        decrease = (cost - trial_cost) / cost
        cost = trial_cost
        steps += 1
        if progress is not None:
            progress(steps, cost)
        if decrease < settings.tolerance:
            break
        res, J = problem.evaluate(*unpack(x), jacobian=True)
    theta, y0s = unpack(x)
    return theta, y0s, cost, cost0, steps


def output_error_refinement(operators: ReducedOperators, data, free, *, start_from=None, initial_states=None,
                            validation=None, validation_start_from=None, settings: OutputError = OutputError(),
                            progress=None) -> dict:
    """Refine ``operators`` by output error on the measured trajectories ``data`` (module docstring).

    Parameters
    ----------
    operators : ReducedOperators
        The model to refine (no stateful terms).
    data : SecondOrderData or list
        The measured (noisy, not smoothed) trajectories, uniformly sampled, with times.
    free : iterable of str
        Names of the terms whose parameters are fitted: linear terms (``"mass"``: with ``tr M^``
        fixed) and ``"learned_potential"`` (its monomials).
    start_from, validation_start_from : SecondOrderData or list, optional
        Data of the same trajectories whose first samples start the initial states (e.g. the smoothed
        data); default the measured first samples.
    initial_states : list of (2r,) arrays, optional
        The initial states themselves (e.g. a previous refinement's ``initial_states``), in place of
        ``start_from``'s.
    validation : SecondOrderData or list, optional
        Held-out trajectories: their cost, with only their initial states fitted, before and after.

    Returns
    -------
    dict
        ``operators``, ``cost``, ``cost_before``, ``expected`` (half the number of residuals),
        ``steps``, ``seconds``, ``initial_states`` and, with ``validation``, ``validation_cost``
        and ``validation_cost_before``.
    """
    tic = time.perf_counter()
    datasets = _trajectories(list(data) if isinstance(data, (list, tuple)) else [data])
    model = _Model(operators, tuple(free))
    trajectories = [_prepare(d) for d in datasets]
    y0s = _starts(datasets, start_from)
    if initial_states is not None:
        if len(initial_states) != len(y0s) or any(np.shape(a) != b.shape for a, b in zip(initial_states, y0s)):
            raise FemromValueError(f"output error: {len(initial_states)} initial states for {len(y0s)} trajectories "
                                   f"of (2r,) = {y0s[0].shape}")
        y0s = [np.asarray(a, dtype=float).copy() for a in initial_states]
    problem = _Problem(model, trajectories, settings)
    theta, y0s, cost, cost0, steps = _levenberg_marquardt(problem, np.zeros(model.size), y0s, settings, progress)
    refined = model.at(theta)
    out = {"operators": refined, "cost": cost, "cost_before": cost0, "steps": steps,
           "expected": 0.5 * sum(t.n_residuals for t in trajectories), "initial_states": y0s,
           "parameters": model.size}
    if validation is not None:
        held = _trajectories(list(validation) if isinstance(validation, (list, tuple)) else [validation])
        held_traj = [_prepare(d) for d in held]
        held_y0 = _starts(held, validation_start_from)
        for key, ops in (("validation_cost_before", operators), ("validation_cost", refined)):
            fixed = _Problem(_Model(ops, ()), held_traj, settings, free_theta=False)
            out[key] = _levenberg_marquardt(fixed, np.zeros(0), [y.copy() for y in held_y0], settings)[2]
    out["seconds"] = time.perf_counter() - tic
    return out


def _prepare(d: SecondOrderData) -> _Trajectory:
    dt = sampling_step(d)
    if dt is None or d.times is None:
        raise FemromValueError("output error needs uniformly sampled trajectories (times, or the sampling step "
                               "of concatenated data)")
    fields = measured_fields(d)
    return _Trajectory(d, fields, tuple(field_noise(d, f) for f in fields), float(dt))


def _starts(datasets, start_from) -> list:
    """The first ``(q, q')`` of every trajectory of ``start_from`` (default ``datasets``)."""
    if start_from is not None:
        source = _trajectories(list(start_from) if isinstance(start_from, (list, tuple)) else [start_from])
        if len(source) != len(datasets) or any(a.states.shape != b.states.shape for a, b in zip(source, datasets)):
            raise FemromValueError(f"output error: the start data have {len(source)} trajectories of shapes "
                                   f"{[a.states.shape for a in source]}, the data {len(datasets)} of "
                                   f"{[b.states.shape for b in datasets]}")
        datasets = source
    return [np.concatenate([d.states[:, 0], d.velocities[:, 0]]) for d in datasets]
