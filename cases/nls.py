"""Cubic nonlinear Schroedinger: H-OpInf with a known quartic Hamiltonian, 400 % outside training.

The FOM ``i psi_t + psi_xx + gamma |psi|^2 psi = 0`` with ``psi = q + i p`` on a
periodic grid (central differences, ``n`` points, 2n real unknowns) is the
canonical Hamiltonian system

    H(q, p) = q^T K q / 2 + p^T K p / 2 - (gamma / 4) sum_j (q_j^2 + p_j^2)^2,
    q' = dH/dp = K p - gamma |psi|^2 p,   p' = -dH/dq = -K q + gamma |psi|^2 q,

``K = -Laplacian`` (circulant, symmetric positive semidefinite), integrated
with the implicit midpoint rule (Newton on the symmetric tangent). The ROMs
live on a cotangent-lift basis ``Phi`` of the training snapshots:

- **H-OpInf** (Sharma, Wang & Kramer, Physica D 431, 2022): symmetric
  ``D^_q``, ``D^_p`` learned from projected snapshots, finite-difference
  derivatives and the projected known gradient of the quartic term; implicit
  midpoint (symplectic) on ``H^``;
- **OpInf** (the non-structure-preserving baseline): an unconstrained
  ``(2r, 2r)`` linear operator ``A^`` learned by least squares from the same
  data and the same known nonlinear term, integrated with the *same* implicit
  midpoint rule as H-OpInf (so a difference in the invariants is the learned
  operator's, not the integrator's); ``OpInf-RK4`` is the same model under RK4;
  ``OpInf-Tikhonov`` adds a Tikhonov weight chosen from ``baseline_regularizations``
  by the smallest training-window error of its midpoint prediction (training
  data only), which keeps it finite over the whole window;
- **Galerkin** (intrusive reference): ``D~ = Phi^T K Phi``, same integrator as H-OpInf.

With the phase-invariant quartic term, the reduced mass ``|y^|^2`` of any of
these ROMs changes only through the symmetric part of its linear operator,
``d|y^|^2/dt = y^T (A^ + A^^T) y`` (``A^ = [[0, D^_p], [-D^_q, 0]]`` for
H-OpInf: zero when ``D^_q = D^_p``), and the midpoint rule keeps every
quadratic invariant of the ODE it steps: ``mass_generator`` =
``||A^ + A^^T|| / (2 ||A^||)`` is reported for every ROM.

The report (``out_dir``): ``metrics.json``, ``report.md`` (accuracy-vs-cost
table, the baseline table and, unless ``quick``, the Tikhonov sweep at the
headline r), ``nls_state_error.png``, ``nls_invariants.png``,
``nls_accuracy_cost.png``, ``nls_solution.png``, ``scene.toml``.

Run ``python -m femrom run nls [--out DIR] [--quick]``; tests import :func:`run`.
"""

# no `from __future__ import annotations`: the CLI loads cases without registering them
# in sys.modules, and dataclasses then cannot resolve string annotations
import argparse
import dataclasses
import time
import types
import tomllib
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from femrom.basis import CotangentLiftPSD
from femrom.inference import HamiltonianOperators, HamiltonianOpInf, finite_difference
from femrom.inference import ProjectedPotential, project_potential_gradient
from femrom.fem import QuarticPotential
from femrom.integrators import CanonicalSystem, ConvergenceError, Newton, integrate_canonical, solve_newton
from femrom.post import accuracy_cost_table, machine_description, plot_accuracy_cost, write_metrics
from femrom.rom import HamiltonianROM

SCENE = Path(__file__).with_suffix(".toml")


@dataclasses.dataclass(frozen=True)
class NLSConfig:
    """The case's settings (``nls.toml``)."""

    n: int = 64
    length: float = 2 * np.pi
    gamma: float = 2.0
    amplitude: float = 1.0
    modulation: float = 0.1
    carrier: int = 1
    dt: float = 1e-3
    t_train: float = 2.0
    t_end: float = 10.0
    rank: int = 12
    ranks: tuple = (4, 6, 8, 10, 12, 16, 20)
    derivative_order: int = 4
    gradient_data: str = "snapshots"
    scheme: str = "midpoint"
    regularization: float = 0.0
    baseline_regularizations: tuple = (1e-14, 1e-12, 1e-10, 1e-8, 1e-6, 1e-4, 1e-2, 1.0)
    name: str = "nls"
    description: str = ""

    @classmethod
    def from_toml(cls, path) -> "NLSConfig":
        data = tomllib.loads(Path(path).read_text())
        flat = {"name": data.get("name", "nls"), "description": data.get("description", "")}
        for section in ("model", "initial_condition", "time", "rom"):
            flat |= data.get(section, {})
        for key in ("ranks", "baseline_regularizations"):
            if key in flat:
                flat[key] = tuple(flat[key])
        return cls(**flat)

    @property
    def dx(self) -> float:
        return self.length / self.n

    @property
    def grid(self) -> np.ndarray:
        return -0.5 * self.length + self.dx * np.arange(self.n)


# -- the full model -----------------------------------------------------------
def periodic_difference(n: int, dx: float, derivative: int) -> sp.csr_matrix:
    """Central periodic differences: ``(u_{j+1} - u_{j-1}) / 2dx`` or ``(u_{j+1} - 2u_j + u_{j-1}) / dx^2``."""
    shift = sp.eye(n, k=1, format="csr") + sp.eye(n, k=-(n - 1), format="csr")   # (S u)_j = u_{j+1}
    if derivative == 1:
        return ((shift - shift.T) / (2 * dx)).tocsr()
    return ((shift + shift.T - 2 * sp.eye(n)) / dx**2).tocsr()


def full_model(cfg: NLSConfig) -> CanonicalSystem:
    """``H = q^T K q / 2 + p^T K p / 2 - gamma/4 sum (q^2 + p^2)^2`` with ``K = -Laplacian`` (dense, n is small)."""
    K = -periodic_difference(cfg.n, cfg.dx, 2).toarray()
    return CanonicalSystem(K, K, QuarticPotential(cfg.gamma))


def initial_condition(cfg: NLSConfig) -> tuple[np.ndarray, np.ndarray]:
    x = cfg.grid
    psi = cfg.amplitude * (1 + cfg.modulation * np.cos(x)) * np.exp(1j * cfg.carrier * x)
    return psi.real.copy(), psi.imag.copy()


def invariants(cfg: NLSConfig, Q: np.ndarray, P: np.ndarray) -> dict:
    """Mass ``int (p^2 + q^2) dx`` and momentum ``int (p_x q - q_x p) dx`` (seed's formulas), (k,) each."""
    D = periodic_difference(cfg.n, cfg.dx, 1)
    mass = cfg.dx * np.sum(Q * Q + P * P, axis=0)
    momentum = cfg.dx * (np.sum((D @ P) * Q, axis=0) - np.sum((D @ Q) * P, axis=0))
    return {"mass": mass, "momentum": momentum}


def drift(values: np.ndarray, window: slice) -> float:
    """``max |I(t) - I(0)| / |I(0)|`` over ``window``."""
    values = np.asarray(values)
    return float(np.max(np.abs(values[window] - values[0])) / abs(values[0]))


# -- the non-structure-preserving baseline -----------------------------------
def fit_plain_opinf(Qh, Ph, dQ, dP, Fq, Fp, regularization: float = 0.0) -> np.ndarray:
    """(2r, 2r) ``A^`` minimising ``||Y^' - F^ - A^ Y^||_F^2 + lambda ||A^||_F^2``, no structure.

    ``F^ = [F^_q; -F^_p]``; ``lambda = regularization * ||Y^||_F^2 / (2r)`` (relative,
    the mean eigenvalue of the data Gram matrix, as in :mod:`femrom.inference`);
    ``regularization = 0`` is ordinary least squares.
    """
    Y = np.vstack([Qh, Ph])
    R = np.vstack([dQ - Fq, dP + Fp])
    if regularization == 0.0:
        return np.linalg.lstsq(Y.T, R.T, rcond=None)[0].T
    lam = regularization * np.sum(Y * Y) / Y.shape[0]
    return np.linalg.solve(Y @ Y.T + lam * np.eye(Y.shape[0]), Y @ R.T).T


def mass_generator(A: np.ndarray) -> float:
    """``||A + A^T||_F / (2 ||A||_F)``: the part of ``y' = A y`` that changes ``|y|^2``."""
    return float(np.linalg.norm(A + A.T) / (2 * np.linalg.norm(A)))


def hamiltonian_matrix(ops: HamiltonianOperators) -> np.ndarray:
    """(2r, 2r) ``[[0, D^_p], [-D^_q, 0]]``: the linear part of ``y' = J grad H^``."""
    Z = np.zeros_like(ops.position)
    return np.block([[Z, ops.momentum], [-ops.position, Z]])


def midpoint_plain(A, potential, basis, y0, dt, n_steps, newton: Newton = Newton(rtol=1e-12)):
    """Implicit midpoint on ``y' = A y + [Phi^T dH_nl/dp; -Phi^T dH_nl/dq](Phi y)``, as H-OpInf's ROM.

    The scheme and Newton tolerance of :func:`femrom.integrators.integrate_canonical`
    (``y_1 = y_0 + h f((y_0 + y_1) / 2)``, Newton from the explicit Euler predictor),
    for a right-hand side that is not ``J grad H``. A step whose Newton iteration
    does not converge, or a state beyond ``1e3 ||y_0||``, ends the run: the rest is NaN.
    Returns the (2r, n_steps + 1) states and the stepping seconds.
    """
    pot = ProjectedPotential(potential, basis)
    r = basis.shape[1]
    identity = np.eye(2 * r)

    def f(y):
        gq, gp = pot.gradient(y[:r], y[r:])
        return A @ y + np.concatenate([gp, -gq])

    def jacobian(y):
        hqq, hqp, hpp = pot.hessian(y[:r], y[r:])
        return A + np.block([[hqp.T, hpp], [-hqq, -hqp]])

    def residual(y_new, y):
        fm = f(0.5 * (y + y_new))
        return y_new - y - dt * fm, np.linalg.norm(y) + dt * np.linalg.norm(fm)

    def dense_solver(J, spd=False):
        return types.SimpleNamespace(solve=lambda b: np.linalg.solve(J, b))

    Y = np.full((2 * r, n_steps + 1), np.nan)
    Y[:, 0] = y0
    y = np.asarray(y0, dtype=float).copy()
    limit = 1e3 * max(np.linalg.norm(y0), 1.0)
    tic = time.perf_counter()
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(n_steps):
            try:
                y1, _ = solve_newton(lambda x: residual(x, y),
                                     lambda x: identity - 0.5 * dt * jacobian(0.5 * (y + x)),
                                     y + dt * f(y), dense_solver, newton)
            except ConvergenceError:
                break
            if not np.linalg.norm(y1) < limit:
                break
            y = y1
            Y[:, k + 1] = y
    return Y, time.perf_counter() - tic


def rk4_plain(A, potential, basis, y0, dt, n_steps):
    """RK4 on ``y' = A y + [Phi^T dH_nl/dp; -Phi^T dH_nl/dq](Phi y)`` (y = [q^; p^])."""
    r = basis.shape[1]

    def f(y):
        gq, gp = potential.gradient(basis @ y[:r], basis @ y[r:])
        return A @ y + np.concatenate([basis.T @ gp, -(basis.T @ gq)])

    Y = np.empty((2 * r, n_steps + 1))
    Y[:, 0] = y0
    y = y0.copy()
    limit = 1e3 * max(np.linalg.norm(y0), 1.0)    # a blow-up: stop before overflow
    with np.errstate(over="ignore", invalid="ignore"):
        _rk4_loop(f, Y, y, dt, n_steps, limit)
    return Y


def _rk4_loop(f, Y, y, dt, n_steps, limit):
    for k in range(n_steps):
        k1 = f(y)
        k2 = f(y + 0.5 * dt * k1)
        k3 = f(y + 0.5 * dt * k2)
        k4 = f(y + dt * k3)
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not (np.linalg.norm(y) < limit):
            Y[:, k + 1:] = np.nan
            break
        Y[:, k + 1] = y


# -- one ROM of each kind at one r --------------------------------------------
def relative_error(Qr, Pr, Q, P, window: slice) -> float:
    num = np.linalg.norm(Qr[:, window] - Q[:, window]) ** 2 + np.linalg.norm(Pr[:, window] - P[:, window]) ** 2
    den = np.linalg.norm(Q[:, window]) ** 2 + np.linalg.norm(P[:, window]) ** 2
    return float(np.sqrt(num / den)) if np.isfinite(num) else float("inf")


def pointwise_error(Qr, Pr, Q, P) -> np.ndarray:
    num = np.sum((Qr - Q) ** 2 + (Pr - P) ** 2, axis=0)
    return np.sqrt(num / np.sum(Q * Q + P * P, axis=0))


def rom_ladder(cfg: NLSConfig, fom, Q, P, ranks, fom_seconds: float, keep: int | None = None,
               sweep: bool = False) -> tuple[list, dict, list]:
    """Fit and run H-OpInf, the plain OpInf baselines and Galerkin at every ``r``.

    Returns the rows, the trajectories at ``r = keep`` and, with ``sweep``, one row per
    Tikhonov weight of ``cfg.baseline_regularizations`` at ``r = keep`` (each run over
    the whole window; without ``sweep`` the weights are only run over the training
    window, which is all the selection needs).
    """
    dt = cfg.dt
    k_train = int(round(cfg.t_train / dt)) + 1
    n_steps = Q.shape[1] - 1
    train, test = slice(0, k_train), slice(k_train, None)
    times = dt * np.arange(n_steps + 1)
    Qt, Pt = Q[:, train], P[:, train]
    potential = fom.potential
    rows, kept, sweep_rows = [], {}, []
    for r in ranks:
        tic = time.perf_counter()
        psd = CotangentLiftPSD(r, method="svd").fit(Qt, Pt)
        basis_seconds = time.perf_counter() - tic
        V = psd.phi_
        projection = psd.projection_error(np.vstack([Q[:, test], P[:, test]]))
        learners = {}
        for name, shared in (("H-OpInf", False), ("H-OpInf-shared", True)):
            tic = time.perf_counter()
            learners[name] = HamiltonianOpInf(cfg.regularization, shared=shared).fit_snapshots(
                V, Qt, Pt, dt, potential=potential, order=cfg.derivative_order, gradient_data=cfg.gradient_data)
            learners[name].seconds_ = time.perf_counter() - tic
        tic = time.perf_counter()
        Qh, Ph = V.T @ Qt, V.T @ Pt
        dQ, dP = finite_difference(Qh, dt, cfg.derivative_order), finite_difference(Ph, dt, cfg.derivative_order)
        at = (Qt, Pt) if cfg.gradient_data == "snapshots" else (V @ Qh, V @ Ph)
        Fq, Fp = project_potential_gradient(V, potential, *at)
        A = fit_plain_opinf(Qh, Ph, dQ, dP, Fq, Fp)
        opinf_fit = time.perf_counter() - tic
        q0, p0 = V.T @ Q[:, 0], V.T @ P[:, 0]
        y0 = np.concatenate([q0, p0])
        galerkin_ops = HamiltonianOperators(V.T @ fom.position @ V, V.T @ fom.momentum @ V)
        # results[name] = (Q^, P^, H^ or None, online seconds, fit seconds, linear operator, extra row fields)
        results = {}
        for name, ops, fit_seconds in [(name, l.operators_, l.seconds_) for name, l in learners.items()] + [
                ("Galerkin", galerkin_ops, None)]:
            rom = HamiltonianROM(ops, V, potential)
            tic = time.perf_counter()
            Qr, Pr, Hr = rom.predict(q0, p0, times, scheme=cfg.scheme)
            extra = {"integrator": cfg.scheme} | ({} if name == "Galerkin" else {"regularization": cfg.regularization})
            results[name] = (Qr, Pr, Hr, time.perf_counter() - tic, fit_seconds, hamiltonian_matrix(ops), extra)
        # the unstructured baseline under the same implicit midpoint rule, and under RK4
        Y, online = midpoint_plain(A, potential, V, y0, dt, n_steps)
        results["OpInf"] = (Y[:r], Y[r:], None, online, opinf_fit, A,
                            {"integrator": "midpoint", "regularization": 0.0})
        tic = time.perf_counter()
        Y = rk4_plain(A, potential, V, y0, dt, n_steps)
        results["OpInf-RK4"] = (Y[:r], Y[r:], None, time.perf_counter() - tic, opinf_fit, A,
                                {"integrator": "rk4", "regularization": 0.0})
        # Tikhonov: the weight whose midpoint prediction fits the training window best
        tic = time.perf_counter()
        candidates = []
        for rho in cfg.baseline_regularizations:
            A_rho = fit_plain_opinf(Qh, Ph, dQ, dP, Fq, Fp, rho)
            full = sweep and r == keep
            Y, seconds = midpoint_plain(A_rho, potential, V, y0, dt, n_steps if full else k_train - 1)
            Yt = Y[:, :k_train]
            train_error = relative_error(V @ Yt[:r], V @ Yt[r:], Qt, Pt, slice(None)) if \
                np.all(np.isfinite(Yt)) else float("inf")
            candidates.append((train_error, rho, A_rho, Y if full else None, seconds))
            if full:
                sweep_rows.append({"r": r, "regularization": rho, "train_error": train_error,
                                   **_window_metrics(cfg, V, Y[:r], Y[r:], Q, P, train, test),
                                   "mass_generator": mass_generator(A_rho),
                                   "max_real_eigenvalue": float(np.max(np.linalg.eigvals(A_rho).real))})
        train_error, rho, A_rho, Y, seconds = min(candidates, key=lambda c: c[0])
        selection_seconds = time.perf_counter() - tic
        if Y is None:
            Y, seconds = midpoint_plain(A_rho, potential, V, y0, dt, n_steps)
        results["OpInf-Tikhonov"] = (Y[:r], Y[r:], None, seconds, opinf_fit + selection_seconds, A_rho,
                                     {"integrator": "midpoint", "regularization": rho})
        for name, (Qr, Pr, Hr, online, fit_seconds, A_lin, extra) in results.items():
            Qf, Pf = V @ Qr, V @ Pr
            row = {"method": name, "r": r, **extra, "basis_seconds": basis_seconds,
                   "fit_seconds": fit_seconds if fit_seconds is not None else float("nan"),
                   "offline_seconds": basis_seconds + (fit_seconds or 0.0),
                   "online_seconds": online, "speedup": fom_seconds / online,
                   **_window_metrics(cfg, V, Qr, Pr, Q, P, train, test, fom),
                   "projection_error_test": projection,
                   "mass_generator": mass_generator(A_lin),
                   "max_real_eigenvalue": float(np.max(np.linalg.eigvals(A_lin).real))}
            if name in learners:
                ops = learners[name].operators_
                row["residual"] = learners[name].residual_
                row["operator_error"] = float(np.linalg.norm(ops.position - galerkin_ops.position)
                                              / np.linalg.norm(galerkin_ops.position))
                row["operator_asymmetry"] = float(np.linalg.norm(ops.position - ops.momentum)
                                                  / np.linalg.norm(ops.momentum))
                row["reduced_hamiltonian_drift_test"] = drift(Hr, test)
                row["gram_condition_q"] = float(np.linalg.cond(Qh @ Qh.T))
                row["gram_condition_p"] = float(np.linalg.cond(Ph @ Ph.T))
                row["gram_condition_shared"] = float(np.linalg.cond(Qh @ Qh.T + Ph @ Ph.T))
            rows.append(row)
            if r == keep:
                with np.errstate(all="ignore"):
                    kept[name] = {"Q": Qf, "P": Pf, "H": fom.hamiltonian(Qf, Pf), "H_reduced": Hr,
                                  **invariants(cfg, Qf, Pf), "error": pointwise_error(Qf, Pf, Q, P)}
    return rows, kept, sweep_rows


def _window_metrics(cfg, V, Qr, Pr, Q, P, train, test, fom=None) -> dict:
    """Errors, blow-up time and invariant drifts of a reduced trajectory (inf where it is not finite)."""
    Qf, Pf = V @ Qr, V @ Pr
    with np.errstate(all="ignore"):
        inv = invariants(cfg, Qf, Pf)
        H_full = fom.hamiltonian(Qf, Pf) if fom is not None else None
    finite_at = np.all(np.isfinite(Qr), axis=0) & np.all(np.isfinite(Pr), axis=0)
    finite = bool(np.all(finite_at))
    bad = np.flatnonzero(~finite_at)
    out = {"train_error": relative_error(Qf, Pf, Q, P, train) if np.all(finite_at[train]) else float("inf"),
           "test_error": relative_error(Qf, Pf, Q, P, test) if finite else float("inf"),
           "finite": finite, "blowup_time": float(cfg.dt * bad[0]) if bad.size else None,
           "mass_drift_train": drift(inv["mass"], train) if np.all(finite_at[train]) else float("inf"),
           "mass_drift_test": drift(inv["mass"], test) if finite else float("inf"),
           "momentum_drift_train": drift(inv["momentum"], train) if np.all(finite_at[train]) else float("inf"),
           "momentum_drift_test": drift(inv["momentum"], test) if finite else float("inf")}
    if H_full is not None:
        out["hamiltonian_drift_test"] = drift(H_full, test) if finite else float("inf")
    return out


def fom_time_step_ladder(cfg: NLSConfig, factors=(4, 2, 1), reference_divisor=4) -> list[dict]:
    """FOM state error at ``t_train`` (vs a run at ``dt / reference_divisor``) against stepping time."""
    fom = full_model(cfg)
    q0, p0 = initial_condition(cfg)
    ref_dt = cfg.dt / reference_divisor
    ref = integrate_canonical(fom, q0, p0, ref_dt, int(round(cfg.t_train / ref_dt)))
    yref = np.concatenate([ref.q[:, -1], ref.p[:, -1]])
    rows = []
    for factor in factors:
        dt = factor * cfg.dt
        run = integrate_canonical(fom, q0, p0, dt, int(round(cfg.t_train / dt)))
        y = np.concatenate([run.q[:, -1], run.p[:, -1]])
        rows.append({"dt": dt, "steps": run.iterations.size, "error_at_t_train": float(np.linalg.norm(y - yref) / np.linalg.norm(yref)),
                     "stepping_seconds": run.seconds, "newton_iterations_mean": float(run.iterations.mean())})
    order = float(np.polyfit(np.log([r["dt"] for r in rows]), np.log([r["error_at_t_train"] for r in rows]), 1)[0])
    for r in rows:
        r["observed_order"] = order
    return rows


# -- plots --------------------------------------------------------------------
METHOD_STYLES = (("H-OpInf", "-"), ("H-OpInf-shared", "-."), ("OpInf", "--"),
                 ("OpInf-Tikhonov", (0, (5, 1, 1, 1, 1, 1))), ("Galerkin", ":"))

def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_errors(path, times, kept, t_train, r):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 3.4))
    for name, style in METHOD_STYLES:
        if name in kept:
            ax.semilogy(times, kept[name]["error"], linestyle=style, lw=1.2, label=name)
    ax.axvspan(0, t_train, color="0.9", label="training")
    ax.set_xlabel("t")
    ax.set_ylabel("relative state error")
    ax.set_title(f"NLS, r = {r}: state error over training and test windows")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_invariants(path, times, fom_inv, kept, t_train, r):
    plt = _plt()
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    for ax, key, label in zip(axes, ("mass", "momentum", "H"), ("mass", "momentum", "Hamiltonian H(Phi y^)")):
        ref = fom_inv[key]
        floor = 1e-16     # |I(t) - I(0)| / |I(0)| on a log axis; exact invariants sit at round-off
        ax.semilogy(times, np.maximum(np.abs(ref - ref[0]) / abs(ref[0]), floor), "k-", lw=1.0, label="FOM")
        for name, style in METHOD_STYLES:
            if name in kept:
                v = kept[name][key]
                ax.semilogy(times, np.maximum(np.abs(v - v[0]) / abs(v[0]), floor), linestyle=style, lw=1.0,
                            label=name)
        ax.axvspan(0, t_train, color="0.92")
        ax.set_ylim(1e-16, 1e2)
        ax.set_ylabel(f"|change| of {label}", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, ncol=4)
    axes[0].set_title(f"NLS invariants, r = {r}")
    axes[-1].set_xlabel("t")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_solution(path, cfg, times, Q, P, kept, r):
    plt = _plt()
    panels = [("FOM", Q, P)] + [(name, kept[name]["Q"], kept[name]["P"]) for name in ("H-OpInf-shared", "H-OpInf", "OpInf-Tikhonov")
                                     if name in kept]
    fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 3.2), sharey=True)
    stride = max(1, times.size // 400)
    for ax, (name, Qx, Px) in zip(np.atleast_1d(axes), panels):
        amp = np.sqrt(Qx[:, ::stride] ** 2 + Px[:, ::stride] ** 2)
        ax.pcolormesh(cfg.grid, times[::stride], np.nan_to_num(amp.T), shading="auto", vmin=0, vmax=np.max(np.sqrt(Q**2 + P**2)))
        ax.axhline(cfg.t_train, color="w", lw=0.8)
        ax.set_title(f"|psi|: {name}" + ("" if name == "FOM" else f", r = {r}"), fontsize=9)
        ax.set_xlabel("x")
    np.atleast_1d(axes)[0].set_ylabel("t")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_cost(path, rows):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, marker in (("H-OpInf", "o-"), ("H-OpInf-shared", "D-"), ("OpInf", "s--"), ("OpInf-Tikhonov", "v--"),
                         ("Galerkin", "^:")):
        sub = [r for r in rows if r["method"] == name and np.isfinite(r["test_error"])]
        if not sub:
            continue
        ax.loglog([r["online_seconds"] for r in sub], [r["test_error"] for r in sub], marker, label=name)
        for r in sub:
            ax.annotate(str(r["r"]), (r["online_seconds"], r["test_error"]), textcoords="offset points",
                        xytext=(3, 3), fontsize=7)
    ax.set_xlabel("online seconds (whole window)")
    ax.set_ylabel("relative state error, test window")
    ax.set_title("NLS: test error against online time (labels: r)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# -- the case -----------------------------------------------------------------
def run(out_dir, *, quick: bool = False, scene_path=SCENE, ranks=None) -> dict:
    """Run the case; return its metrics (also written to ``out_dir/metrics.json``)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cfg = NLSConfig.from_toml(scene_path)
    if quick:   # the same physics and windows with a 2x coarser step; the headline rank only
        cfg = dataclasses.replace(cfg, dt=2 * cfg.dt, ranks=(cfg.rank,))
    if ranks is not None:
        cfg = dataclasses.replace(cfg, ranks=tuple(ranks), rank=max(ranks) if cfg.rank not in ranks else cfg.rank)
    fom = full_model(cfg)
    q0, p0 = initial_condition(cfg)
    n_steps = int(round(cfg.t_end / cfg.dt))
    fom_run = integrate_canonical(fom, q0, p0, cfg.dt, n_steps, "midpoint")
    Q, P = fom_run.q, fom_run.p
    times = cfg.dt * np.arange(n_steps + 1)
    k_train = int(round(cfg.t_train / cfg.dt)) + 1
    test = slice(k_train, None)
    fom_inv = invariants(cfg, Q, P) | {"H": fom_run.hamiltonian}

    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):   # r x r algebra: one thread, like the FOM's stepping
        rows, kept, sweep_rows = rom_ladder(cfg, fom, Q, P, cfg.ranks, fom_run.seconds, keep=cfg.rank,
                                            sweep=not quick)
    plot_errors(out_dir / "nls_state_error.png", times, kept, cfg.t_train, cfg.rank)
    plot_invariants(out_dir / "nls_invariants.png", times, fom_inv, kept, cfg.t_train, cfg.rank)
    plot_solution(out_dir / "nls_solution.png", cfg, times, Q, P, kept, cfg.rank)
    plot_cost(out_dir / "nls_accuracy_cost.png", rows)
    hopinf_rows = [r for r in rows if r["method"] == "H-OpInf"]
    plot_accuracy_cost(out_dir / "nls_accuracy_cost_hopinf.png", hopinf_rows, "online_seconds", "test_error", "r",
                       title="H-OpInf: test error vs online time (labels: r)")
    (out_dir / "scene.toml").write_text(Path(scene_path).read_text())
    dt_rows = [] if quick else fom_time_step_ladder(cfg)
    if dt_rows:
        plot_accuracy_cost(out_dir / "nls_fom_time_step.png", dt_rows, "stepping_seconds", "error_at_t_train", "dt",
                           title="NLS FOM (implicit midpoint): error at t_train vs stepping time")

    headline = {name: next(r for r in rows if r["method"] == name and r["r"] == cfg.rank)
                for name in ("H-OpInf", "H-OpInf-shared", "OpInf", "OpInf-RK4", "OpInf-Tikhonov", "Galerkin")}
    metrics = {
        "case": "nls", "config": dataclasses.asdict(cfg), "machine": machine_description(),
        "quick": quick, "load_average": list(__import__("os").getloadavg()),
        "fom": {"dofs": 2 * cfg.n, "steps": n_steps, "stepping_seconds": fom_run.seconds,
                "newton_iterations_mean": float(fom_run.iterations.mean()),
                "mass_drift_test": drift(fom_inv["mass"], test),
                "momentum_drift_test": drift(fom_inv["momentum"], test),
                "hamiltonian_drift_test": drift(fom_inv["H"], test),
                "mass0": float(fom_inv["mass"][0]), "momentum0": float(fom_inv["momentum"][0]),
                "hamiltonian0": float(fom_inv["H"][0])},
        "rank": cfg.rank, "headline": headline, "ladder": rows, "fom_time_step_ladder": dt_rows,
        "baseline_regularization_sweep": sweep_rows,
    }
    write_metrics(out_dir / "metrics.json", metrics)
    columns = ["method", "r", "train_error", "test_error", "projection_error_test", "mass_drift_test",
               "momentum_drift_test", "hamiltonian_drift_test", "offline_seconds", "online_seconds", "speedup"]
    f = metrics["fom"]
    report = [
        f"# {cfg.description}", "",
        f"FOM: 2n = {2 * cfg.n}, {n_steps} implicit-midpoint steps of {cfg.dt:g} in {f['stepping_seconds']:.2f} s; "
        f"training [0, {cfg.t_train:g}], test ({cfg.t_train:g}, {cfg.t_end:g}]. FOM drift over the test window: "
        f"mass {f['mass_drift_test']:.1e}, momentum {f['momentum_drift_test']:.1e}, H {f['hamiltonian_drift_test']:.1e}.", "",
        "## Accuracy against cost (errors relative, in the Frobenius norm over each window)", "",
        accuracy_cost_table(sorted(rows, key=lambda r: (r["method"], r["r"])), columns), "",
        f"## Invariants of the structure-preserving and the plain ROMs (r = {cfg.rank})", "",
        "OpInf: the unconstrained A^ (ordinary least squares) under the same implicit midpoint rule as "
        "H-OpInf; OpInf-RK4: the same A^ under RK4; OpInf-Tikhonov: the weight of "
        "`baseline_regularizations` whose midpoint prediction fits the training window best, then the "
        "whole window. Same basis, data and known quartic term for all. Drifts are max |I(t) - I(0)| / |I(0)| "
        "over each window; mass_generator = ||A^ + A^^T|| / (2 ||A^||), the part of the linear operator that "
        "changes the reduced mass (the quartic term cannot change it: it is phase-invariant).", "",
        accuracy_cost_table([headline[name] for name in ("Galerkin", "H-OpInf-shared", "H-OpInf", "OpInf",
                                                           "OpInf-RK4", "OpInf-Tikhonov")],
                            ["method", "integrator", "regularization", "train_error", "test_error", "blowup_time",
                             "mass_drift_train",
                             "mass_drift_test", "momentum_drift_test", "mass_generator", "max_real_eigenvalue"]), "",
    ]
    if sweep_rows:
        report += [f"### Plain OpInf under implicit midpoint: every Tikhonov weight (r = {cfg.rank}, whole window)", "",
                   accuracy_cost_table(sweep_rows, ["regularization", "train_error", "test_error", "blowup_time",
                                                    "mass_drift_train", "mass_drift_test", "momentum_drift_test",
                                                    "mass_generator", "max_real_eigenvalue"]), ""]
    if dt_rows:
        report += ["## FOM time step: state error at t_train (vs dt/4) against stepping time", "",
                   accuracy_cost_table(dt_rows, ["dt", "steps", "error_at_t_train", "stepping_seconds",
                                                 "newton_iterations_mean", "observed_order"]), ""]
    (out_dir / "report.md").write_text("\n".join(report))
    return metrics


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="femrom run nls", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results") / "nls")
    parser.add_argument("--quick", action="store_true",
                        help="same windows, 2x coarser step (dt = 4e-3), headline rank only, no Tikhonov "
                             "sweep or FOM time-step ladder (tests)")
    args = parser.parse_args(argv)
    m = run(args.out, quick=args.quick)
    print(f"nls: r = {m['rank']}, drifts over the test window; report in {args.out}")
    for name, row in m["headline"].items():
        blowup = "" if row["blowup_time"] is None else f", blows up at t = {row['blowup_time']:.3g}"
        print(f"  {name:>15s} ({row['integrator']}): test error {row['test_error']:.2e}, mass drift "
              f"{row['mass_drift_test']:.1e}, momentum drift {row['momentum_drift_test']:.1e}{blowup}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
