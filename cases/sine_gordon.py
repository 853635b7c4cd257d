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
  reduced potential), the FOM's ladders against the exact breather, and the
  profiles q(x); the table, the FOM energy of the reconstructed ROM state and its
  histories are :func:`femrom.study.rom_table` and :func:`femrom.study.plot_histories`.

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
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom.post import pyplot, save_figure, table_section
from femrom.rom import HyperReducedPotential, SecondOrderROM, ecsw_weights
from femrom.scene import Derivatives, Scene, build
from femrom.study import LEARNER_NAMES, call_cost, evaluate_runs, extrapolation_config, final_state, invariant_drift, \
    ladder_section, mass_norm, observed_order, plot_histories, plot_output_history, rom_costs, rom_table, run_study

SCENE = Path(__file__).with_suffix(".toml")
NAMES = LEARNER_NAMES | {"lopinf_hyper": "L-OpInf + hyper-reduction"}


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
    elements = n + 1
    length = dict(scene.structure.parameters)["length"]
    return scene.with_geometry(mesh_size=length / elements, probe_position=(elements // 2) / elements)


def breather(x, t, w: float = BREATHER_FREQUENCY, centre: float = BREATHER_CENTRE):
    """Exact breather of ``q_tt = q_xx - sin q``:
    ``4 arctan( sqrt(1 - w^2)/w sin(w t) / cosh(sqrt(1 - w^2) (x - centre)) )``."""
    s = np.sqrt(1.0 - w * w)
    return 4.0 * np.arctan(s / w * np.sin(w * t) / np.cosh(s * (x - centre)))


def fom_ladder(scene: Scene, study: SineGordonStudy) -> list[dict]:
    """The FOM's accuracy against cost over [0, train_window].

    Two ladders of Newmark + Newton runs (:func:`femrom.study.final_state`), each error a
    relative mass norm ``||q_h(T) - q_ref||_M / ||q_ref||_M`` at ``T = train_window`` (``M = h I``):

    - time step, at the study's n: against the run at ``ladder_fine_dt`` on the
      same mesh (the time error alone);
    - mesh (node counts ``ladder_nodes``) at ``ladder_fine_dt``: against the exact
      breather ``q(x_i, T)`` (the space error; the time part is negligible there).

    Rows carry the run's stepping time; the fitted order goes into every row of its ladder.
    """
    T = study.train_window
    s = np.sqrt(1.0 - BREATHER_FREQUENCY**2)

    def final(n, dt):
        model = build(scene if n is None else with_nodes(scene, n))
        x = _node_positions(model)
        v_exact = 4.0 * s / np.cosh(s * (x - BREATHER_CENTRE))
        if not np.allclose(model.initial_velocity, v_exact, atol=1e-12 * np.abs(v_exact).max()):
            raise ValueError("the scene's initial velocity is not the breather of BREATHER_FREQUENCY; "
                             "the exact reference of the mesh ladder would not apply")
        q, row = final_state(model, dt, T)
        M = model.system.mass
        return row, q, breather(x, row["steps"] * dt), lambda a, b: mass_norm(M, a - b) / mass_norm(M, b)

    rows = []
    _, reference, _, _ = final(study.n, study.ladder_fine_dt)
    for dt in study.ladder_time_steps:
        row, q, _, relative = final(study.n, dt)
        rows.append({"ladder": "time step", "label": f"dt={dt:g}", **row, "error": relative(q, reference),
                     "reference": f"dt = {study.ladder_fine_dt:g}, same mesh"})
    for n in study.ladder_nodes:
        row, q, exact, relative = final(n, study.ladder_fine_dt)
        rows.append({"ladder": "mesh", "label": f"n={n}", **row, "error": relative(q, exact),
                     "reference": "exact breather"})
    for name, key, sign in (("time step", "dt", 1.0), ("mesh", "n", -1.0)):
        sel = [r for r in rows if r["ladder"] == name]
        order = sign * observed_order([r[key] for r in sel], [r["error"] for r in sel])
        for r in sel:
            r["observed_order"] = order
    return rows


def study_scene(scene: Scene, study: SineGordonStudy) -> Scene:
    """The scene at the study's n and dt, with a ``[rom]`` section
    (:func:`femrom.study.extrapolation_config`): train on [0, T], test to t_end scored after T."""
    if study.n is not None:
        scene = with_nodes(scene, study.n)
    dt = scene.time.dt if study.dt is None else study.dt
    config = extrapolation_config(dt, study.train_window, study.t_end, study.ranks,
                                  derivatives=Derivatives("finite_differences", study.derivative_order))
    return dataclasses.replace(scene.with_time(dt=dt, t_end=study.t_end), rom=config)


def hyper_reduce(state, study: SineGordonStudy) -> tuple[list[dict], dict]:
    """Per r: the learned ROM with its potential sampled by ECSW on every ``hyper_stride``-th
    training state, evaluated like the study's ROMs and timed with the L-OpInf ROMs
    (interleaved), its reduced force and tangent timed per call against the unsampled ones.

    Returns rows of the study's form (learner ``lopinf_hyper``; with the ECSW fit, the nodes and
    weights, the call costs) and their evaluations by ``(r, learner, run)``."""
    nl, V, train_run = state.model.system.nonlinear, state.basis, state.runs["train"]
    train_states = state.projections["train"].coordinates
    fom_step = max(state.runs.values(), key=lambda run: run.times.size).cost.seconds
    rows, evaluations, timed = [], {}, {}
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
        rows.append({"learner": "lopinf_hyper", "r": r, "_rom": rom, "samples": int(nodes.size), "nodes": nodes,
                     "weights": hyper.weights, "ecsw_residual": info["residual"], "ecsw_seconds": info["seconds"],
                     **{f"{name}_call_seconds": call_cost(fn, q0).seconds for name, fn in (
                         ("force", hyper.force), ("tangent", hyper.tangent),
                         ("projected_force", projected.force), ("projected_tangent", projected.tangent))}})
        evaluations |= {(r, "lopinf_hyper", name): ev for name, ev in evaluate_runs(rom, state).items()}
        timed |= {(r, "rom"): rom, (r, "lopinf"): learned}
    costs = rom_costs(timed, state.runs["extrapolation"], repeats=state.config.timing.repeats)
    for row in rows:
        cost, lopinf = costs[(row["r"], "rom")], costs[(row["r"], "lopinf")]
        row.update(seconds_per_step=cost.seconds, cost=cost.to_dict(), speedup=fom_step / cost.seconds,
                   lopinf_seconds_per_step=lopinf.seconds, speedup_over_lopinf=lopinf.seconds / cost.seconds)
    return rows, evaluations


#: what a hyper-reduced row adds to the table
HYPER_COLUMNS = ("ecsw_residual", "ecsw_seconds", "force_call_seconds", "tangent_call_seconds",
                 "projected_force_call_seconds", "projected_tangent_call_seconds", "lopinf_seconds_per_step",
                 "speedup_over_lopinf")


def case_rows(state, study: SineGordonStudy, out_dir: Path) -> dict:
    """The case's table: the study's ROMs and the hyper-reduced ones (:func:`femrom.study.rom_table`:
    errors, the FOM energy of the reconstructed state, the ROM's own energy drift, the costs), with
    the nodes at which each samples the potential; and its plots."""
    system, V, test = state.model.system, state.basis, state.runs["extrapolation"]
    T, r0 = state.config.test[0].score_after, study.main_rank
    hyper_rows, hyper_evaluations = hyper_reduce(state, study)
    sources, evaluations = [*state.rows, *hyper_rows], state.evaluations | hyper_evaluations
    rows, histories = rom_table(system, V, test, sources, evaluations, train="train", score_after=T)
    for row, src in zip(rows, sources):
        if "failed" not in row:
            row |= {"samples": src.get("samples", system.n_dofs)} | {k: src[k] for k in HYPER_COLUMNS if k in src}
    plot_histories(out_dir, test, state.projections["extrapolation"], evaluations, rows, histories, r0, NAMES,
                   title=f"sine-Gordon n = {system.n_dofs}, trained on [0, {T:g}] s", shade=(0.0, T), envelope=250)
    shown = {m: NAMES[m] for m in ("lopinf", "lopinf_hyper") if (r0, m, test.name) in evaluations}
    plot_output_history(out_dir / "rom_outputs.png", test, evaluations, r0, shown, shade=(0.0, T),
                        ylabel=f"q at {system.output_names[0]}", title=f"output {system.output_names[0]} (r={r0})")
    _plot_profiles(out_dir / "rom_profiles.png", state.model, state.store.read("extrapolation", "q"), test.times,
                   V[:, :r0], {shown[m]: evaluations[(r0, m, test.name)].solution.q for m in shown},
                   [study.train_window, 0.5 * (study.train_window + study.t_end), study.t_end])
    return {"rows": rows, "fom_energy_drift": invariant_drift(test.energy), "energy0": float(test.energy[0]),
            "hyper_nodes": {str(h["r"]): {"nodes": h["nodes"], "weights": h["weights"]} for h in hyper_rows}}


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
        summary = state.runs["extrapolation"].summary
        metrics = {"case": "sine_gordon", "settings": dataclasses.asdict(study), "dt": scene.time.dt,
                   "boundary_conditions": "q = 0 at both ends (the breather decays as exp(-0.6 |x - 20|))",
                   "fom": {"seconds": summary["stepping_seconds"], "summary": summary,
                           "energy_drift": own["fom_energy_drift"], "energy0": own["energy0"]},
                   "rows": own["rows"], "fom_ladder": ladder, "hyper_nodes": own["hyper_nodes"]}
        sections = [
            table_section("The case's table", own["rows"], COLUMNS, text=(
                "Errors in the mass norm over the test window; energy error = FOM energy of the reconstructed ROM "
                "state against E(0), maximum over [0, t_end]; speedup = FOM step over ROM step (each the fastest "
                "of timed blocks); samples = nodes at which the nonlinear potential is evaluated.")),
            ladder_section(out_dir / "accuracy_cost_fom.png", ladder, "stepping_seconds", "error", "label",
                           group="ladder", heading=f"FOM accuracy against cost (relative error at t = "
                           f"{study.train_window:g} s; time steps at n = {state.model.system.n_dofs} against dt = "
                           f"{study.ladder_fine_dt:g}, meshes against the exact breather)",
                           columns=["ladder", "n", "dt", "steps", "error", "reference", "stepping_seconds",
                                    "seconds_per_step", "observed_order"],
                           note="Newmark average acceleration and P1 with a lumped mass (symmetric finite "
                                "differences) are both second order.")]
        return metrics, sections

    return run_study(scene, out_dir, extend=extend, progress=None)


def _plot_profiles(path, model, Q, times, V, curves: dict, at):
    """q(x) of the FOM (``Q``, (n, k)) and of the ROMs (``curves``: legend name -> (r, k)
    coordinates in ``V``) at a few times ``at`` (the seed's extrapolation figure)."""
    plt = pyplot()
    x = _node_positions(model)
    order = np.argsort(x)
    x = x[order]
    fig, axes = plt.subplots(1, len(at), figsize=(4 * len(at), 3.2), sharey=True)
    for ax, t in zip(np.atleast_1d(axes), at):
        k = int(np.argmin(np.abs(times - t)))
        ax.plot(x, Q[order, k], "k-", lw=2.0, label="FOM")
        for (name, q), style in zip(curves.items(), ("--", ":")):
            ax.plot(x, (V @ q[:, k])[order], style, lw=1.3, label=name)
        ax.set_title(f"t = {times[k]:g} s")
        ax.set_xlabel("x")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("q")
    np.atleast_1d(axes)[0].legend(fontsize=8)
    save_figure(fig, path, dpi=100)


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
