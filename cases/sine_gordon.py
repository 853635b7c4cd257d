"""Sine-Gordon breather, n = 2000: L-OpInf with a known nonlinear force, then hyper-reduction.

``q_tt = q_xx - sin(q)`` on [0, 40] with fixed ends, P1 elements with a lumped
mass (the symmetric finite-difference discretization of the seed), released
as the exact breather of frequency 0.8 (``sine_gordon.toml``). The seed
(``../shared/seeds/000_*.txt``, "Sine-Gordon equation (n = 2000)") trains on
[0, 5] s and predicts to 25 s (400 % outside the training interval) with
bounded energy error. Here, for several basis sizes r:

- FOM (Newmark average acceleration, Newton) over [0, 25] s; its first 5 s
  are the training snapshots, the rest the test reference;
- mass-orthonormal POD of the training snapshots (``V^T M V = I``);
- L-OpInf: ``min_{K^ = K^^T > 0} ||Q^'' + F^ + K^ Q^||_F`` with the projected
  forcing data ``F^ = V^T f_nl(Q)`` (the seed's formulation), finite-difference
  accelerations; online the known force ``V^T f_nl(V q^)`` (O(n) per call);
- the intrusive Galerkin ROM (reference) and, at the main r, plain OpInf;
- hyper-reduction: the learned K^ with the reduced potential sampled on a few
  nodes with non-negative ECSW weights (:mod:`femrom.rom._hyper`), so the
  reduced force stays the exact gradient of a reduced potential.

The case writes ``metrics.json``, ``report.md`` (accuracy-vs-cost table),
``rom_state_error.png``, ``rom_energy_error.png``, ``rom_outputs.png``,
``rom_profiles.png`` (q(x) at t = 5, 15, 25 s), ``accuracy_cost_rom.png``,
``accuracy_cost_fom.png`` (the FOM's time-step and mesh ladders against the exact
breather, :func:`fom_ladder`) and ``scene.toml``.

Run ``python -m femrom run sine_gordon [--out DIR] [--quick]``; tests import :func:`run`.
"""

import argparse
import dataclasses
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from femrom.post import (accuracy_cost_table, machine_description, plot_accuracy_cost_groups,
                         plot_time_series, write_metrics)
from femrom.scene import Scene, build

SCENE = Path(__file__).with_suffix(".toml")


@dataclass(frozen=True)
class SineGordonStudy:
    """Settings of the case.

    Attributes
    ----------
    n : int or None
        Interior nodes (``None``: the scene's 2000).
    dt : float or None
        FOM and ROM step (``None``: the scene's 0.01 s).
    train_window, t_end : float
        Training window [0, T] and prediction end [s] (seed: 5 and 25).
    ranks : tuple of int
        Basis sizes of the accuracy-vs-cost ladder.
    ladder_time_steps, ladder_nodes, ladder_fine_dt : tuple, tuple, float
        The FOM's accuracy-vs-cost ladders (:func:`fom_ladder`): time steps at the
        study's n (against ``ladder_fine_dt``), and node counts at ``ladder_fine_dt``
        (against the exact breather).
    main_rank : int
        The r of the time-history plots and of plain OpInf.
    derivative_order : int
        Finite-difference order of the reduced accelerations.
    hyper_tolerance : float
        Relative residual of the ECSW fit (:func:`femrom.rom.ecsw_weights`).
    hyper_stride : int
        Every how many training snapshots the ECSW fit uses.
    """

    n: int | None = None
    dt: float | None = None
    train_window: float = 5.0
    t_end: float = 25.0
    ranks: tuple[int, ...] = (2, 3, 4, 6, 8)
    main_rank: int = 4
    derivative_order: int = 4
    hyper_tolerance: float = 1e-4
    hyper_stride: int = 2
    ladder_time_steps: tuple[float, ...] = (0.1, 0.05, 0.025, 0.0125)
    ladder_nodes: tuple[int, ...] = (250, 500, 1000, 2000)
    ladder_fine_dt: float = 0.0025


QUICK = SineGordonStudy(n=400, dt=0.02, ranks=(3, 4), main_rank=4, ladder_time_steps=(0.1, 0.05, 0.025),
                        ladder_nodes=(100, 200, 400), ladder_fine_dt=0.005)

#: Frequency and centre of the breather that ``sine_gordon.toml`` releases (its initial
#: velocity is ``4 sqrt(1 - w^2) / cosh(sqrt(1 - w^2) (x - centre))``; checked in :func:`fom_ladder`).
BREATHER_FREQUENCY = 0.8
BREATHER_CENTRE = 20.0
PAPER = SineGordonStudy(dt=0.005, ranks=(2, 3, 4, 6, 8, 12), main_rank=4)


def with_nodes(scene: Scene, n: int) -> Scene:
    """The scene with ``n`` interior nodes: ``n + 1`` elements split ``floor`` / ``ceil`` at the probe."""
    params = dict(scene.structure.parameters)
    length = params["length"]
    elements = n + 1
    params |= {"mesh_size": length / elements, "probe_position": (elements // 2) / elements}
    structure = dataclasses.replace(scene.structure, parameters=tuple(sorted(params.items())))
    return dataclasses.replace(scene, structure=structure)


def _m_norms(X, M) -> np.ndarray:
    return np.sqrt(np.maximum(np.sum(X * np.asarray(M @ X), axis=0), 0.0))


def fom_energy(system, Q, Vel) -> np.ndarray:
    """(k,) ndarray ``q'^T M q' / 2 + q^T K q / 2 + U(q)`` of full (n, k) states."""
    nl = system.nonlinear
    U = np.sum(nl.weights[:, None] * nl.phi(Q), axis=0)
    return 0.5 * np.sum(Vel * np.asarray(system.mass @ Vel), axis=0) + \
        0.5 * np.sum(Q * np.asarray(system.stiffness @ Q), axis=0) + U


def _time_calls(fn, q, repeats: int = 200) -> float:
    """Median over 5 batches of the seconds per call of ``fn(q)``."""
    batches = []
    for _ in range(5):
        tic = time.perf_counter()
        for _ in range(repeats):
            fn(q)
        batches.append((time.perf_counter() - tic) / repeats)
    return float(np.median(batches))


def breather(x, t, w: float = BREATHER_FREQUENCY, centre: float = BREATHER_CENTRE):
    """Exact breather of ``q_tt = q_xx - sin q``:
    ``4 arctan( sqrt(1 - w^2)/w sin(w t) / cosh(sqrt(1 - w^2) (x - centre)) )``."""
    s = np.sqrt(1.0 - w * w)
    return 4.0 * np.arctan(s / w * np.sin(w * t) / np.cosh(s * (x - centre)))


def fom_ladder(scene: Scene, study: SineGordonStudy) -> list[dict]:
    """The FOM's accuracy against cost over [0, train_window].

    Two ladders of Newmark + Newton runs, each error a relative mass norm
    ``||q_h(T) - q_ref||_M / ||q_ref||_M`` at ``T = train_window`` (``M = h I``):

    - time step, at the study's n: against the run at ``ladder_fine_dt`` on the
      same mesh (the time error alone);
    - mesh (node counts ``ladder_nodes``) at ``ladder_fine_dt``: against the exact
      breather ``q(x_i, T)`` (the space error; the time part is negligible there).

    Rows carry the run's stepping time; the fitted order goes into every row of its ladder.
    """
    from femrom.integrators import Newmark, Trajectory, integrate

    T = study.train_window
    s = np.sqrt(1.0 - BREATHER_FREQUENCY**2)

    def final_state(n, dt):
        model = build(scene if n is None else with_nodes(scene, n))
        x = _node_positions(model)
        v_exact = 4.0 * s / np.cosh(s * (x - BREATHER_CENTRE))
        if not np.allclose(model.initial_velocity, v_exact, atol=1e-12 * np.abs(v_exact).max()):
            raise ValueError("the scene's initial velocity is not the breather of BREATHER_FREQUENCY; "
                             "the exact reference of the mesh ladder would not apply")
        steps = int(round(T / dt))
        if abs(steps * dt - T) > 1e-9 * T:
            raise ValueError(f"ladder time step {dt:g} does not divide the window {T:g} s")
        final = Trajectory(every=steps, fields=("q",))
        summary = integrate(model.system, Newmark(), model.initial_displacement, model.initial_velocity,
                            dt, steps, consumers=[final], progress=False)
        row = {"n": model.system.n_dofs, "dt": dt, "steps": steps,
               "stepping_seconds": summary.stepping_seconds,
               "seconds_per_step": summary.stepping_seconds / steps}
        return row, final.q[:, -1], breather(x, steps * dt), model.system.mass

    def relative(a, b, M):
        e = a - b
        return float(np.sqrt(e @ (M @ e)) / np.sqrt(b @ (M @ b)))

    rows = []
    _, reference, _, _ = final_state(study.n, study.ladder_fine_dt)
    for dt in study.ladder_time_steps:
        row, q, _, M = final_state(study.n, dt)
        rows.append({"ladder": "time step", "label": f"dt={dt:g}", **row, "error": relative(q, reference, M),
                     "reference": f"dt = {study.ladder_fine_dt:g}, same mesh"})
    for n in study.ladder_nodes:
        row, q, exact, M = final_state(n, study.ladder_fine_dt)
        rows.append({"ladder": "mesh", "label": f"n={n}", **row, "error": relative(q, exact, M),
                     "reference": "exact breather"})
    for name, key, sign in (("time step", "dt", 1.0), ("mesh", "n", -1.0)):
        sel = [r for r in rows if r["ladder"] == name]
        slope = float(np.polyfit(np.log([r[key] for r in sel]), np.log([r["error"] for r in sel]), 1)[0])
        for r in sel:
            r["observed_order"] = sign * slope
    return rows

def run(out_dir, *, quick: bool = False, paper: bool = False, study: SineGordonStudy | None = None,
        scene_path=SCENE) -> dict:
    """Run the case; return its metrics (also written to ``out_dir/metrics.json``)."""
    from femrom.basis import POD
    from femrom.inference import (
        LagrangianOpInf,
        ProjectedNonlinearForce,
        SecondOrderOpInf,
        reduce_snapshots,
    )
    from femrom.integrators import Trajectory, simulate
    from femrom.rom import HyperReducedPotential, SecondOrderROM, ecsw_weights

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    study = study if study is not None else (QUICK if quick else PAPER if paper else SineGordonStudy())
    scene = Scene.from_toml(scene_path)
    if study.n is not None:
        scene = with_nodes(scene, study.n)
    dt = scene.time.dt if study.dt is None else study.dt
    scene = dataclasses.replace(scene, time=dataclasses.replace(scene.time, dt=dt, t_end=study.t_end))
    (out_dir / "scene.toml").write_text(scene.source_text)

    tic = time.perf_counter()
    model = build(scene)
    build_seconds = time.perf_counter() - tic
    system = model.system
    M, nl = system.mass, system.nonlinear
    # the velocity is needed for the energy of the FOM states; the scene keeps displacements
    velocities = Trajectory(fields=("v",))
    tic = time.perf_counter()
    fom = simulate(model, consumers=[velocities])
    fom_seconds = time.perf_counter() - tic
    Q, Qd, times = fom.fields["displacement"], velocities.v, fom.times
    n_train = int(round(study.train_window / dt))
    train, test = slice(0, n_train + 1), slice(n_train + 1, None)
    fom_train_seconds = fom_seconds * n_train / (times.size - 1)
    E_fom = fom_energy(system, Q, Qd)
    E0 = E_fom[0]
    scale = np.max(_m_norms(Q, M))
    q_norm = {"train": np.linalg.norm(_m_norms(Q[:, train], M)),
              "test": np.linalg.norm(_m_norms(Q[:, test], M))}
    F_train = nl.weights[:, None] * nl.dphi(Q[:, train])      # known nonlinear forcing data
    E_out = system.output_matrix

    rows, curves, hyper_info = [], {}, {}
    for r in study.ranks:
        tic = time.perf_counter()
        V = POD(r, product=M).fit(Q[:, train]).basis_
        data = reduce_snapshots(V, Q[:, train], dt, product=M, order=study.derivative_order,
                                nonlinear_forces=F_train)
        basis_seconds = time.perf_counter() - tic
        residual = Q - V @ (V.T @ np.asarray(M @ Q))
        proj_t = _m_norms(residual, M)
        projection = float(np.linalg.norm(proj_t[test]) / q_norm["test"])
        q0 = V.T @ np.asarray(M @ model.initial_displacement)
        v0 = V.T @ np.asarray(M @ model.initial_velocity)
        projected = ProjectedNonlinearForce(nl, V)

        methods = ["galerkin", "lopinf", "lopinf_hyper"] + (["plain_opinf"] if r == study.main_rank else [])
        learned = None
        for method in methods:
            tic = time.perf_counter()
            extra = {}
            if method == "galerkin":
                rom = SecondOrderROM.galerkin(system, V, product=M, mass_orthonormal=True)
            elif method in ("lopinf", "plain_opinf"):
                # the scene's effects: no damping, the known sin(q) force projected
                learner = (LagrangianOpInf if method == "lopinf" else SecondOrderOpInf).for_system(
                    system, V)
                rom = SecondOrderROM(learner=learner, basis=V, product=M).fit(data)
                if method == "lopinf":
                    learned = rom
            else:
                # the learned K^ with the sampled potential in place of the O(n) projected one
                nodes, xi, info = ecsw_weights(nl, V, V @ data.states[:, ::study.hyper_stride],
                                               tolerance=study.hyper_tolerance)
                hyper = HyperReducedPotential.from_potential(nl, V, nodes, xi)
                rom = SecondOrderROM(learned.operators_.without("projected_force").with_terms(hyper), V,
                                     product=M)
                extra = {"samples": int(nodes.size), "ecsw_residual": info["residual"],
                         "ecsw_seconds": info["seconds"],
                         "force_call_seconds": _time_calls(hyper.force, q0),
                         "tangent_call_seconds": _time_calls(hyper.tangent, q0),
                         "projected_force_call_seconds": _time_calls(projected.force, q0),
                         "projected_tangent_call_seconds": _time_calls(projected.tangent, q0)}
                hyper_info[r] = {"nodes": nodes, "weights": hyper.weights}
            fit_seconds = time.perf_counter() - tic
            try:
                solution = rom.predict(q0, times, v0=v0)
            except RuntimeError as exc:            # Newton failure or non-finite state
                rows.append({"method": method, "r": r, "failed": str(exc), "test_error": float("inf"),
                             "projection_error": projection})
                continue
            err_t = _m_norms(Q - V @ solution.q, M)
            energy = fom_energy(system, V @ solution.q, V @ solution.v)
            energy_error = np.abs(energy - E0) / E0
            rom_energy = solution.energy
            row = {
                "method": method, "r": r, "samples": extra.get("samples", system.n_dofs),
                "train_error": float(np.linalg.norm(err_t[train]) / q_norm["train"]),
                "test_error": float(np.linalg.norm(err_t[test]) / q_norm["test"]),
                "projection_error": projection,
                "energy_error_max": float(np.max(energy_error)),
                "energy_error_test_max": float(np.max(energy_error[test])),
                "rom_energy_drift": float(np.max(np.abs(rom_energy - rom_energy[0])) / abs(rom_energy[0])),
                "online_seconds": solution.info["stepping_seconds"],
                "seconds_per_step": solution.info["seconds_per_step"],
                "offline_seconds": fom_train_seconds + basis_seconds + fit_seconds,
                "speedup": fom.summary["stepping_seconds"] / solution.info["stepping_seconds"],
                **extra,
            }
            if method != "galerkin":
                K = rom.operators_.stiffness
                row["stiffness_asymmetry"] = float(np.linalg.norm(K - K.T) / np.linalg.norm(K))
            rows.append(row)
            if r == study.main_rank:
                curves[method] = {"state_error": err_t / scale, "energy_error": energy_error,
                                  "outputs": None if E_out is None else np.asarray(E_out @ (V @ solution.q)),
                                  "q": solution.q}
        if r == study.main_rank:
            curves["projection"] = {"state_error": proj_t / scale}
            main_basis = V

    # -- plots -------------------------------------------------------------
    T = float(times[n_train])
    r0 = study.main_rank
    names = {"galerkin": "intrusive Galerkin", "lopinf": "L-OpInf", "lopinf_hyper": "L-OpInf + hyper-reduction",
             "plain_opinf": "plain OpInf", "projection": "projection"}
    shown = [m for m in ("galerkin", "lopinf", "lopinf_hyper", "plain_opinf", "projection") if m in curves]
    plot_time_series(out_dir / "rom_state_error.png", times,
                     {f"{names[m]} (r={r0})": curves[m]["state_error"] for m in shown}, logy=True,
                     shade=(0.0, T), ylabel="||q - V q^||_M / max ||q||_M", envelope=250,
                     title=f"sine-Gordon n = {system.n_dofs}: state error, trained on [0, {T:g}] s")
    plot_time_series(out_dir / "rom_energy_error.png", times,
                     {"FOM": np.abs(E_fom - E0) / E0} |
                     {f"{names[m]} (r={r0})": curves[m]["energy_error"] for m in shown if m != "projection"},
                     logy=True, shade=(0.0, T), ylabel="|E - E0| / E0", envelope=250,
                     title="energy error (FOM energy of the reconstructed state)")
    if E_out is not None:
        outs = {"FOM": fom.outputs[0]}
        outs |= {names[m]: curves[m]["outputs"][0] for m in ("lopinf", "lopinf_hyper") if m in curves}
        plot_time_series(out_dir / "rom_outputs.png", times, outs, shade=(0.0, T),
                         ylabel=f"q at {system.output_names[0]}",
                         title=f"output {system.output_names[0]} (r={r0})")
    _plot_profiles(out_dir / "rom_profiles.png", model, Q, times, main_basis, curves, names,
                   [study.train_window, 0.5 * (study.train_window + study.t_end), study.t_end])
    plot_accuracy_cost_groups(out_dir / "accuracy_cost_rom.png", [r for r in rows if "failed" not in r],
                              "online_seconds", "test_error", "r", "method",
                              title="test-window error vs online time (labels: r)")

    tic = time.perf_counter()
    ladder_rows = fom_ladder(scene, study)
    ladder_seconds = time.perf_counter() - tic
    plot_accuracy_cost_groups(out_dir / "accuracy_cost_fom.png", ladder_rows, "stepping_seconds", "error",
                              "label", "ladder",
                              title=f"FOM error at t = {study.train_window:g} s: time steps at n = {system.n_dofs} "
                                    f"(vs dt = {study.ladder_fine_dt:g}), meshes vs the exact breather")

    columns = ["method", "r", "samples", "train_error", "test_error", "projection_error",
               "energy_error_max", "online_seconds", "seconds_per_step", "offline_seconds", "speedup"]
    metrics = {
        "case": "sine_gordon", "scene": scene.name, "n_dofs": system.n_dofs, "settings": asdict(study),
        "dt": dt, "machine": machine_description(), "build_seconds": build_seconds,
        "boundary_conditions": "q = 0 at both ends (the breather decays as exp(-0.6 |x - 20|))",
        "fom": {"seconds": fom_seconds, "summary": fom.summary,
                "energy_drift": float(np.max(np.abs(E_fom - E0)) / E0), "energy0": float(E0)},
        "rows": rows,
        "fom_ladder": ladder_rows, "fom_ladder_seconds": ladder_seconds,
        "hyper_nodes": {str(r): {"nodes": v["nodes"], "weights": v["weights"]} for r, v in hyper_info.items()},
    }
    write_metrics(out_dir / "metrics.json", metrics)
    report = [
        f"# {scene.description}", "",
        f"FOM: {system.n_dofs} dofs, {fom.summary['n_steps']} Newmark steps of {dt:g} s with Newton in "
        f"{fom.summary['stepping_seconds']:.2f} s ({fom.summary['stepping_seconds'] / fom.summary['n_steps'] * 1e3:.2f} "
        f"ms/step); energy drift {metrics['fom']['energy_drift']:.2e}. Training window [0, {T:g}] s, "
        f"test window ({T:g}, {study.t_end:g}] s.", "",
        "Errors in the mass norm over the test window; energy error = FOM energy of the reconstructed ROM "
        "state against E(0), maximum over [0, t_end]; speedup = FOM stepping time / ROM stepping time over "
        "the same window; samples = nodes at which the nonlinear potential is evaluated.", "",
        accuracy_cost_table(rows, columns), "",
        f"## FOM accuracy against cost (relative error at t = {study.train_window:g} s)", "",
        accuracy_cost_table(ladder_rows, ["ladder", "n", "dt", "steps", "error", "reference", "stepping_seconds",
                                          "seconds_per_step", "observed_order"]), "",
        "Newmark average acceleration and P1 with a lumped mass (symmetric finite differences) are "
        "both second order.", "",
    ]
    (out_dir / "report.md").write_text("\n".join(report))
    return metrics


def _plot_profiles(path, model, Q, times, V, curves, names, at):
    """q(x) of the FOM and the ROMs at a few times (the seed's extrapolation figure)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = _node_positions(model)
    order = np.argsort(x)
    x = x[order]
    fig, axes = plt.subplots(1, len(at), figsize=(4 * len(at), 3.2), sharey=True)
    for ax, t in zip(np.atleast_1d(axes), at):
        k = int(np.argmin(np.abs(times - t)))
        ax.plot(x, Q[order, k], "k-", lw=2.0, label="FOM")
        for m, style in (("lopinf", "--"), ("lopinf_hyper", ":")):
            if m in curves:
                ax.plot(x, (V @ curves[m]["q"][:, k])[order], style, lw=1.3, label=names[m])
        ax.set_title(f"t = {times[k]:g} s")
        ax.set_xlabel("x")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("q")
    np.atleast_1d(axes)[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _node_positions(model) -> np.ndarray:
    """(n,) ndarray: x of the free dofs (P1: one dof per node, in node order)."""
    mesh = model.space.mesh if hasattr(model.space, "mesh") else None
    free = model.system.condensation.free
    if mesh is not None and mesh.p.shape[1] == model.system.condensation.n_total:
        return np.asarray(mesh.p[0])[free]
    return np.arange(free.size, dtype=float)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="femrom run sine_gordon", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results") / "sine_gordon")
    parser.add_argument("--quick", action="store_true", help="n = 400, dt = 0.02, r = 3, 4 (tests)")
    parser.add_argument("--paper", action="store_true", help="dt = 0.005, r up to 12")
    parser.add_argument("--ranks", type=int, nargs="+", help="basis sizes r")
    args = parser.parse_args(argv)
    study = QUICK if args.quick else PAPER if args.paper else SineGordonStudy()
    if args.ranks:
        study = dataclasses.replace(study, ranks=tuple(args.ranks),
                                    main_rank=args.ranks[min(len(args.ranks) - 1, 2)])
    metrics = run(args.out, study=study)
    print(f"sine_gordon: {metrics['n_dofs']} dofs, FOM {metrics['fom']['summary']['stepping_seconds']:.2f} s, "
          f"energy drift {metrics['fom']['energy_drift']:.1e}; report in {args.out}")
    for row in metrics["rows"]:
        if "failed" in row:
            print(f"  {row['method']:>13s} r={row['r']:2d}: FAILED {row['failed']}")
            continue
        print(f"  {row['method']:>13s} r={row['r']:2d}: test error {row['test_error']:.2e} "
              f"(projection {row['projection_error']:.2e}), energy error {row['energy_error_max']:.2e}, "
              f"{row['samples']} samples, {row['seconds_per_step'] * 1e3:.3f} ms/step, speedup {row['speedup']:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
