"""Sine-Gordon breather, n = 2000: L-OpInf with a known nonlinear force, then hyper-reduction.

``q_tt = q_xx - sin(q)`` on [0, 40] with fixed ends, P1 elements with a lumped
mass (the symmetric finite-difference discretization of the seed), released
as the exact breather of frequency 0.8 (``sine_gordon.toml``). The seed
(``../shared/seeds/000_*.txt``, "Sine-Gordon equation (n = 2000)") trains on
[0, 5] s and predicts to 25 s (400 % outside the training interval) with
bounded energy error. On the study layer (:func:`femrom.study.run_study`), for
several basis sizes r:

- FOM (Newmark average acceleration, Newton) over [0, 5] s (training) and over
  [0, 25] s (the test, scored after 5 s), displacements streamed to a store;
- mass-orthonormal POD of the training snapshots (``V^T M V = I``);
- L-OpInf: ``min_{K^ = K^^T > 0} ||Q^'' + F^ + K^ Q^||_F`` with the projected
  forcing data ``F^ = V^T f_nl(Q)`` of the stored snapshots (the seed's
  formulation), finite-difference accelerations; online the known force
  ``V^T f_nl(V q^)`` (O(n) per call); plain OpInf and the intrusive Galerkin ROM
  on the same data and basis;
- what is the case's own: hyper-reduction (the learned K^ with the reduced
  potential sampled on a few nodes with non-negative ECSW weights,
  :mod:`femrom.rom._hyper`, so the reduced force stays the exact gradient of a
  reduced potential), the FOM's ladders against the exact breather, the FOM
  energy of the reconstructed ROM state, and the profiles q(x).

The case writes the study's report (``report.md``, ``metrics.json``,
``response.png``, ``rom_error.png``, ``energy.png``, ``accuracy_cost.png``)
with its own sections, ``rom_state_error.png``, ``rom_energy_error.png``,
``rom_outputs.png``, ``rom_profiles.png`` (q(x) at t = 5, 15, 25 s),
``accuracy_cost_rom.png``, ``accuracy_cost_fom.png`` (:func:`fom_ladder`) and
``scene.toml``.

Run ``python -m femrom run sine_gordon [--out DIR] [--quick]``; tests import :func:`run`.
"""

import argparse
import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom.integrators import Newmark, Trajectory, integrate
from femrom.post import accuracy_cost_table, plot_accuracy_cost_groups, plot_time_series
from femrom.rom import HyperReducedPotential, SecondOrderROM, ecsw_weights
from femrom.scene import BasisSpec, Derivatives, LearnerSpec, ReportSpec, RomConfig, RunSpec, Scene, build
from femrom.study import evaluate, plot_error_history, repeated_cost, rom_costs, run_study, scored_columns

SCENE = Path(__file__).with_suffix(".toml")
NAMES = {"galerkin": "intrusive Galerkin", "lopinf": "L-OpInf", "lopinf_hyper": "L-OpInf + hyper-reduction",
         "plain_opinf": "plain OpInf"}


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

def study_scene(scene: Scene, study: SineGordonStudy) -> Scene:
    """The scene at the study's n and dt, with a ``[rom]`` section: train on [0, T], test to t_end scored after T."""
    if study.n is not None:
        scene = with_nodes(scene, study.n)
    dt = scene.time.dt if study.dt is None else study.dt
    scene = dataclasses.replace(scene, time=dataclasses.replace(scene.time, dt=dt, t_end=study.t_end))
    T = int(round(study.train_window / dt)) * dt
    data = Derivatives("finite_differences", study.derivative_order)
    config = RomConfig(
        train=(RunSpec("train", t_end=T),), test=(RunSpec("extrapolation", t_end=study.t_end, score_after=T),),
        learners=(LearnerSpec("galerkin", "galerkin", data), LearnerSpec("lopinf", "lopinf", data),
                  LearnerSpec("plain_opinf", "opinf", data)),
        basis=BasisSpec(tuple(study.ranks), method="svd"), extension=1.0,
        report=ReportSpec(render=False, paraview=False))
    return dataclasses.replace(scene, rom=config)


def fom_energy(system, Q, Vel) -> np.ndarray:
    """(k,) ndarray ``q'^T M q' / 2 + q^T K q / 2 + U(q)`` of full (n, k) states."""
    nl = system.nonlinear
    U = np.sum(nl.weights[:, None] * nl.phi(Q), axis=0)
    return 0.5 * np.sum(Vel * (system.mass @ Vel) + Q * (system.stiffness @ Q), axis=0) + U


def call_seconds(fn, q) -> float:
    """Seconds per call of ``fn(q)``: the fastest of 5 timed blocks of at least 0.1 s."""
    def block(n):
        tic = time.perf_counter()
        for _ in range(n):
            fn(q)
        return time.perf_counter() - tic
    return repeated_cost(block, 100).seconds


def hyper_reduce(state, study: SineGordonStudy) -> dict:
    """Per r: the learned ROM with its potential sampled by ECSW on every ``hyper_stride``-th
    training state, evaluated and timed like the study's ROMs (timed with the L-OpInf
    ROMs, interleaved). Returns rows by r with the ROM and the extra metrics."""
    nl, V, train_run = state.model.system.nonlinear, state.basis, state.runs["train"]
    train_states = state.projections["train"].coordinates
    out = {}
    for row in state.rows:
        if row["learner"] != "lopinf":
            continue
        r, learned = row["r"], row["_rom"]
        Vr = V[:, :r]
        nodes, xi, info = ecsw_weights(nl, Vr, Vr @ train_states[:r, ::study.hyper_stride],
                                       tolerance=study.hyper_tolerance)
        hyper = HyperReducedPotential.from_potential(nl, Vr, nodes, xi)
        rom = SecondOrderROM(learned.operators_.without("projected_force").with_terms(hyper), Vr, product=state.product)
        projected = learned.operators_.term("projected_force")
        q0 = Vr.T @ (state.product @ train_run.q0)
        out[r] = {"rom": rom, "lopinf": learned, "samples": int(nodes.size), "ecsw_residual": info["residual"],
                  "ecsw_seconds": info["seconds"], "nodes": nodes, "weights": hyper.weights,
                  "force_call_seconds": call_seconds(hyper.force, q0),
                  "tangent_call_seconds": call_seconds(hyper.tangent, q0),
                  "projected_force_call_seconds": call_seconds(projected.force, q0),
                  "projected_tangent_call_seconds": call_seconds(projected.tangent, q0),
                  "evaluations": {name: evaluate(rom, run, state.projections[name], extension=1.0,
                                                 score_after=spec.score_after)
                                  for spec in (*state.config.train, *state.config.test)
                                  for name, run in [(spec.name, state.runs[spec.name])]}}
    costs = rom_costs({(r, m): h[m] for r, h in out.items() for m in ("rom", "lopinf")},
                      state.runs["extrapolation"], repeats=state.config.timing.repeats)
    for r, h in out.items():
        h["cost"], h["lopinf_cost"] = costs[(r, "rom")], costs[(r, "lopinf")]
    return out


def case_rows(state, study: SineGordonStudy, out_dir: Path) -> dict:
    """The case's table: the study's ROMs and the hyper-reduced ones, with the FOM energy of the
    reconstructed state, the ROM's own energy drift and the costs; and its plots."""
    system, V, test = state.model.system, state.basis, state.runs["extrapolation"]
    times, T = test.times, state.config.test[0].score_after
    E0, window = test.energy[0], scored_columns(test, T)
    hyper = hyper_reduce(state, study)
    fom_step = max(state.runs.values(), key=lambda run: run.times.size).cost.seconds
    rows, curves = [], {}
    entries = [(row["learner"], row["r"], row, state.evaluations.get((row["r"], row["learner"], "extrapolation")))
               for row in state.rows]
    entries += [("lopinf_hyper", r, h, h["evaluations"]["extrapolation"]) for r, h in hyper.items()]
    for method, r, src, ev in entries:
        if ev is None:
            rows.append({"method": method, "r": r, "failed": src.get("failed"), "test_error": float("inf")})
            continue
        hyper_row = method == "lopinf_hyper"
        train_ev = src["evaluations"]["train"] if hyper_row else state.evaluations[(r, method, "train")]
        cost = src["cost"].seconds if hyper_row else src["seconds_per_step"]
        solution = ev.solution
        energy_error = np.abs(fom_energy(system, V[:, :r] @ solution.q, V[:, :r] @ solution.v) - E0) / E0
        rom_energy = solution.energy
        row = {"method": method, "r": r, "samples": src.get("samples", system.n_dofs),
               "train_error": train_ev.field_error, "test_error": ev.field_error,
               "projection_error": ev.projection_error, "energy_error_max": float(np.max(energy_error)),
               "energy_error_test_max": float(np.max(energy_error[window])),
               "rom_energy_drift": float(np.max(np.abs(rom_energy - rom_energy[0])) / abs(rom_energy[0])),
               "seconds_per_step": cost, "online_seconds": cost * (times.size - 1), "speedup": fom_step / cost}
        if hyper_row:
            row.update({k: src[k] for k in ("ecsw_residual", "ecsw_seconds", "force_call_seconds",
                                            "tangent_call_seconds", "projected_force_call_seconds",
                                            "projected_tangent_call_seconds")},
                       lopinf_seconds_per_step=src["lopinf_cost"].seconds,
                       speedup_over_lopinf=src["lopinf_cost"].seconds / cost)
        if method != "galerkin":
            K = (src["rom"] if hyper_row else src["_rom"]).operators_.stiffness
            row["stiffness_asymmetry"] = float(np.linalg.norm(K - K.T) / np.linalg.norm(K))
        rows.append(row)
        if r == study.main_rank:
            curves[method] = {"energy_error": energy_error, "q": solution.q,
                              "outputs": np.asarray(system.output_matrix @ (V[:, :r] @ solution.q))}
    r0 = study.main_rank
    evaluations = dict(state.evaluations) | {(r, "lopinf_hyper", "extrapolation"): h["evaluations"]["extrapolation"]
                                             for r, h in hyper.items()}
    shown = [m for m in NAMES if m in curves]
    plot_error_history(out_dir / "rom_state_error.png", test, state.projections["extrapolation"], evaluations, r0,
                       shown, shade=(0.0, T), envelope=250,
                       title=f"sine-Gordon n = {system.n_dofs}: state error, trained on [0, {T:g}] s")
    plot_time_series(out_dir / "rom_energy_error.png", times,
                     {"FOM": np.abs(test.energy - E0) / E0} | {f"{NAMES[m]} (r={r0})": curves[m]["energy_error"]
                                                               for m in shown},
                     logy=True, shade=(0.0, T), ylabel="|E - E0| / E0", envelope=250,
                     title="energy error (FOM energy of the reconstructed state)")
    plot_time_series(out_dir / "rom_outputs.png", times,
                     {"FOM": test.outputs[0]} | {NAMES[m]: curves[m]["outputs"][0] for m in ("lopinf", "lopinf_hyper")
                                                 if m in curves},
                     shade=(0.0, T), ylabel=f"q at {system.output_names[0]}",
                     title=f"output {system.output_names[0]} (r={r0})")
    Q = state.store.read("extrapolation", "q")
    _plot_profiles(out_dir / "rom_profiles.png", state.model, Q, times, V[:, :r0], curves, NAMES,
                   [study.train_window, 0.5 * (study.train_window + study.t_end), study.t_end])
    plot_accuracy_cost_groups(out_dir / "accuracy_cost_rom.png", [r for r in rows if "failed" not in r],
                              "online_seconds", "test_error", "r", "method",
                              title="test-window error vs online time (labels: r)")
    return {"rows": rows, "fom_energy_drift": float(np.max(np.abs(test.energy - E0)) / E0), "energy0": float(E0),
            "hyper_nodes": {str(r): {"nodes": h["nodes"], "weights": h["weights"]} for r, h in hyper.items()}}


COLUMNS = ["method", "r", "samples", "train_error", "test_error", "projection_error", "energy_error_max",
           "online_seconds", "seconds_per_step", "speedup"]


def run(out_dir, *, quick: bool = False, paper: bool = False, study: SineGordonStudy | None = None,
        scene_path=SCENE) -> dict:
    """Run the case; return its metrics (also written to ``out_dir/metrics.json``)."""
    out_dir = Path(out_dir)
    study = study if study is not None else (QUICK if quick else PAPER if paper else SineGordonStudy())
    scene = study_scene(Scene.from_toml(scene_path), study)

    def extend(state):
        own = case_rows(state, study, out_dir)
        ladder = fom_ladder(scene, study)
        plot_accuracy_cost_groups(out_dir / "accuracy_cost_fom.png", ladder, "stepping_seconds", "error",
                                  "label", "ladder",
                                  title=f"FOM error at t = {study.train_window:g} s: time steps at n = "
                                        f"{state.model.system.n_dofs} (vs dt = {study.ladder_fine_dt:g}), meshes vs "
                                        "the exact breather")
        summary = state.runs["extrapolation"].summary
        metrics = {"case": "sine_gordon", "settings": dataclasses.asdict(study), "dt": scene.time.dt,
                   "boundary_conditions": "q = 0 at both ends (the breather decays as exp(-0.6 |x - 20|))",
                   "fom": {"seconds": summary["stepping_seconds"], "summary": summary,
                           "energy_drift": own["fom_energy_drift"], "energy0": own["energy0"]},
                   "rows": own["rows"], "fom_ladder": ladder, "hyper_nodes": own["hyper_nodes"]}
        sections = [
            "## The case's table\n\nErrors in the mass norm over the test window; energy error = FOM energy of the "
            "reconstructed ROM state against E(0), maximum over [0, t_end]; speedup = FOM step over ROM step (each "
            "the fastest of timed blocks); samples = nodes at which the nonlinear potential is evaluated.\n\n"
            + accuracy_cost_table(own["rows"], COLUMNS),
            f"## FOM accuracy against cost (relative error at t = {study.train_window:g} s)\n\n"
            + accuracy_cost_table(ladder, ["ladder", "n", "dt", "steps", "error", "reference", "stepping_seconds",
                                           "seconds_per_step", "observed_order"])
            + "\n\nNewmark average acceleration and P1 with a lumped mass (symmetric finite differences) are "
              "both second order."]
        return metrics, sections

    return run_study(scene, out_dir, extend=extend, progress=None)


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
