"""Cubic nonlinear Schroedinger: H-OpInf with a known quartic Hamiltonian, 400 % outside training.

The FOM ``i psi_t + psi_xx + gamma |psi|^2 psi = 0`` with ``psi = q + i p`` on a
periodic grid (central differences, ``n`` points, 2n real unknowns) is canonical
Hamiltonian, ``H(q, p) = q^T K q / 2 + p^T K p / 2 - (gamma / 4) sum_j (q_j^2 + p_j^2)^2``
with ``K = -Laplacian``, integrated with the implicit midpoint rule. The study runs on
:func:`femrom.study.canonical_rows`: a cotangent-lift basis of the training window,
H-OpInf (the paper's separate fits and femrom's shared ``D^``), the intrusive Galerkin
ROM and the unstructured baseline ``A^`` (plain OpInf under the same midpoint rule,
under RK4, and with the Tikhonov weight of ``baseline_regularizations`` that fits the
training window best), all with the same projected quartic term, scored on the
training window and 400 % beyond it with the drifts of the NLS's mass and momentum
(``mass_generator = ||A^ + A^^T|| / (2 ||A^||)``: what changes ``|y^|^2``). What is the
case's own: the grid, the plane wave, the two invariants, the space-time plot of ``|psi|``.

The report (``out_dir``): ``metrics.json``, ``report.md``, ``nls_state_error.png``,
``nls_invariants.png``, ``nls_accuracy_cost.png``, ``nls_solution.png``,
``nls_fom_time_step.png`` (not with ``quick``), ``scene.toml``.

Run ``python -m femrom run nls [--out DIR] [--quick]``; tests import :func:`run`.
"""

# no `from __future__ import annotations`: the CLI loads cases without registering them
# in sys.modules, and dataclasses then cannot resolve string annotations
import dataclasses
import functools
import os
import tomllib
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from threadpoolctl import threadpool_limits

from femrom.cases import case_parser
from femrom.fem import QuarticPotential
from femrom.integrators import CanonicalSystem
from femrom.post import accuracy_cost_table, machine_description, plot_accuracy_cost as plot_points, \
    plot_space_time, plot_time_series, staged_output, write_metrics
from femrom.study import CanonicalSpec, canonical_rows, canonical_time_step_ladder, invariant_drift, \
    plot_accuracy_cost, plot_invariant_drifts, run_canonical

SCENE = Path(__file__).with_suffix(".toml")
HEADLINE = ("Galerkin", "H-OpInf-shared", "H-OpInf", "OpInf", "OpInf-RK4", "OpInf-Tikhonov")


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

    def specs(self) -> tuple[CanonicalSpec, ...]:
        """The ROMs: H-OpInf (separate and shared fits), Galerkin, and the unstructured baselines."""
        return (CanonicalSpec("H-OpInf", "hopinf", self.scheme, regularization=self.regularization),
                CanonicalSpec("H-OpInf-shared", "hopinf", self.scheme, shared=True,
                              regularization=self.regularization),
                CanonicalSpec("Galerkin", "galerkin", self.scheme),
                CanonicalSpec("OpInf", "canonical_opinf", "midpoint"),
                CanonicalSpec("OpInf-RK4", "canonical_opinf", "rk4"),
                CanonicalSpec("OpInf-Tikhonov", "canonical_opinf", "midpoint",
                              regularization=tuple(self.baseline_regularizations)))


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
    n_steps = int(round(cfg.t_end / cfg.dt))
    k_train = int(round(cfg.t_train / cfg.dt)) + 1
    test = slice(k_train, None)

    fom_run = run_canonical(fom, *initial_condition(cfg), cfg.dt, n_steps)
    with threadpool_limits(1):   # r x r algebra: one thread
        rows, kept, sweep_rows = canonical_rows(
            fom, fom_run, cfg.specs(), ranks=cfg.ranks, train_window=cfg.t_train, order=cfg.derivative_order,
            gradient_data=cfg.gradient_data, invariants=functools.partial(invariants, cfg), keep=cfg.rank, sweep=not quick)
    dt_rows = [] if quick else canonical_time_step_ladder(fom, *initial_condition(cfg), cfg.dt, cfg.t_train)
    Q, P, times = fom_run.q, fom_run.p, fom_run.times
    fom_inv = invariants(cfg, Q, P) | {"H": fom_run.hamiltonian}
    shade = (0.0, cfg.t_train)
    plot_time_series(out_dir / "nls_state_error.png", times, {name: kept[name]["error"] for name in HEADLINE},
                     logy=True, shade=shade, ymax=1e2, ylabel="relative state error",
                     title=f"NLS, r = {cfg.rank}: state error over training and test windows")
    plot_invariant_drifts(out_dir / "nls_invariants.png", times, fom_inv, kept,
                          {"mass": "mass", "momentum": "momentum", "H": "Hamiltonian H(Phi y^)"}, shade=shade,
                          title=f"NLS invariants, r = {cfg.rank}")
    # |psi(x, t)| of the FOM and of three ROMs at r (white line: the end of training)
    panels = {"FOM": (Q, P), **{f"{name}, r = {cfg.rank}": (kept[name]["Q"], kept[name]["P"])
                                for name in ("H-OpInf-shared", "H-OpInf", "OpInf-Tikhonov") if name in kept}}
    plot_space_time(out_dir / "nls_solution.png", cfg.grid, times,
                    {name: np.sqrt(Qx**2 + Px**2) for name, (Qx, Px) in panels.items()}, mark=cfg.t_train, label="|psi|: ")
    plot_accuracy_cost(out_dir / "nls_accuracy_cost.png", rows, fom_run.cost.to_dict(),
                       "NLS: test-window state error vs cost per step", error="test_error")
    if dt_rows:
        plot_points(out_dir / "nls_fom_time_step.png", dt_rows, "stepping_seconds", "error_at_end", "dt",
                    title="NLS FOM (implicit midpoint): error at t_train vs stepping time")
    (out_dir / "scene.toml").write_text(Path(scene_path).read_text())

    headline = {name: next(r for r in rows if r["method"] == name and r["r"] == cfg.rank) for name in HEADLINE}
    fom_metrics = {"dofs": 2 * cfg.n, "steps": n_steps, "stepping_seconds": fom_run.seconds,
                   "seconds_per_step": fom_run.cost.seconds, "cost": fom_run.cost.to_dict(),
                   "newton_iterations_mean": float(fom_run.iterations.mean()),
                   **{f"{k}_drift_test": invariant_drift(fom_inv[k], test) for k in ("mass", "momentum")},
                   "hamiltonian_drift_test": invariant_drift(fom_inv["H"], test),
                   "mass0": float(fom_inv["mass"][0]), "momentum0": float(fom_inv["momentum"][0]),
                   "hamiltonian0": float(fom_inv["H"][0])}
    metrics = {"case": "nls", "config": dataclasses.asdict(cfg), "machine": machine_description(), "quick": quick,
               "load_average": list(os.getloadavg()), "fom": fom_metrics, "rank": cfg.rank, "headline": headline,
               "ladder": rows, "fom_time_step_ladder": dt_rows, "baseline_regularization_sweep": sweep_rows}
    write_metrics(out_dir / "metrics.json", metrics)
    (out_dir / "report.md").write_text("\n".join(report(cfg, metrics)))
    return metrics


def report(cfg: NLSConfig, m: dict) -> list[str]:
    f, rows = m["fom"], m["ladder"]
    columns = ["method", "r", "train_error", "test_error", "projection_error_test", "mass_drift_test",
               "momentum_drift_test", "hamiltonian_drift_test", "offline_seconds", "seconds_per_step", "speedup"]
    lines = [
        f"# {cfg.description}", "",
        f"FOM: 2n = {2 * cfg.n}, {f['steps']} implicit-midpoint steps of {cfg.dt:g}, {f['seconds_per_step']:.3g} s "
        f"per step (fastest timed block); training [0, {cfg.t_train:g}], test ({cfg.t_train:g}, {cfg.t_end:g}]. "
        f"FOM drift over the test window: mass {f['mass_drift_test']:.1e}, momentum {f['momentum_drift_test']:.1e}, "
        f"H {f['hamiltonian_drift_test']:.1e}.", "",
        "## Accuracy against cost (errors relative, in the Frobenius norm over each window; seconds per step: "
        "the fastest of timed blocks, all ROMs interleaved; a ROM that blew up is not timed)", "",
        accuracy_cost_table(sorted(rows, key=lambda r: (r["method"], r["r"])), columns), "",
        f"## Invariants of the structure-preserving and the plain ROMs (r = {cfg.rank})", "",
        "OpInf: the unconstrained A^ (ordinary least squares) under the same implicit midpoint rule as H-OpInf; "
        "OpInf-RK4: the same A^ under RK4; OpInf-Tikhonov: the weight of `baseline_regularizations` whose midpoint "
        "prediction fits the training window best, then the whole window. Same basis, data and known quartic term "
        "for all. Drifts are max |I(t) - I(0)| / |I(0)| over each window; mass_generator = ||A^ + A^^T|| / "
        "(2 ||A^||), the part of the linear operator that changes the reduced mass (the quartic term cannot: it "
        "is phase-invariant).", "",
        accuracy_cost_table([m["headline"][name] for name in HEADLINE],
                            ["method", "integrator", "regularization", "train_error", "test_error", "blowup_time",
                             "mass_drift_train", "mass_drift_test", "momentum_drift_test", "mass_generator",
                             "max_real_eigenvalue"]), ""]
    if m["baseline_regularization_sweep"]:
        lines += [f"### Plain OpInf under implicit midpoint: every Tikhonov weight (r = {cfg.rank}, whole window)",
                  "", accuracy_cost_table(m["baseline_regularization_sweep"], [
                      "regularization", "train_error", "test_error", "blowup_time", "mass_drift_train",
                      "mass_drift_test", "momentum_drift_test", "mass_generator", "max_real_eigenvalue"]), ""]
    if m["fom_time_step_ladder"]:
        lines += ["## FOM time step: state error at t_train (vs dt/4) against its cost", "",
                  accuracy_cost_table(m["fom_time_step_ladder"], ["dt", "steps", "error_at_end", "seconds_per_step",
                                                                  "stepping_seconds", "newton_iterations_mean",
                                                                  "observed_order"]), ""]
    return lines


def main(argv=None) -> int:
    parser = case_parser("nls", __doc__, quick="same windows, 2x coarser step (dt = 4e-3), headline rank only, no Tikhonov "
                             "sweep or FOM time-step ladder (tests)")
    args = parser.parse_args(argv)
    with staged_output(args.out) as out:    # the results appear whole, or the old ones stay
        m = run(out, quick=args.quick)
    print(f"nls: r = {m['rank']}, drifts over the test window; report in {args.out}")
    for name, row in m["headline"].items():
        blowup = "" if row["blowup_time"] is None else f", blows up at t = {row['blowup_time']:.3g}"
        print(f"  {name:>15s} ({row['integrator']}): test error {row['test_error']:.2e}, mass drift "
              f"{row['mass_drift_test']:.1e}, momentum drift {row['momentum_drift_test']:.1e}{blowup}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
