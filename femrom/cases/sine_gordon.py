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
- what is the case's own: the choices of its hyper-reduction (the learned K^ with the
  reduced potential sampled by ECSW on every second training state to a residual of
  1e-4, :func:`femrom.study.hyper_reduced_rows`, so the reduced force stays the exact
  gradient of a reduced potential), the exact breather the FOM's ladders are measured
  against (:func:`femrom.study.final_state_ladders`), and the profiles q(x); the table,
  the FOM energy of the reconstructed ROM state and its histories are
  :func:`femrom.study.rom_table` and :func:`femrom.study.plot_histories`.

The case writes the study's report (``report.md``, ``metrics.json``,
``response.png``, ``rom_error.png``, ``energy.png``, ``accuracy_cost.png``)
with its own sections, ``rom_state_error.png``, ``rom_energy_error.png``,
``rom_outputs.png``, ``rom_profiles.png`` (q(x) at t = 5, 15, 25 s),
``accuracy_cost_rom.png``, ``accuracy_cost_fom.png`` (the FOM's ladders) and
``scene.toml``.

Run ``python -m femrom run sine_gordon [--out DIR] [--quick]``; tests import :func:`run`.
"""

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom.cases import case_parser
from femrom import FemromValueError
from femrom.post import accuracy_cost_table, pyplot, save_figure, staged_output, table_section
from femrom.scene import Derivatives, Scene, build
from femrom.study import HYPER_COLUMNS, EXTRAPOLATION_LEARNER_NAMES, extrapolation_scene, final_state_ladders, final_state_section, \
    hyper_reduced_rows, invariant_drift, plot_histories, plot_output_history, rom_table, run_study

SCENE = Path(__file__).with_suffix(".toml")
NAMES = EXTRAPOLATION_LEARNER_NAMES | {"lopinf_hyper": "L-OpInf + hyper-reduction"}


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
        The FOM's accuracy-vs-cost ladders (:func:`femrom.study.final_state_ladders`): time steps at the
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
#: velocity is ``4 sqrt(1 - w^2) / cosh(sqrt(1 - w^2) (x - centre))``; checked in :func:`exact_breather`).
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


def exact_breather(model, t: float) -> np.ndarray:
    """(n,) ndarray: the breather (:func:`breather`) at the model's nodes at time ``t`` (P1: one
    free dof per node). Raises ``ValueError`` unless the model was released as this breather
    (initial velocity ``4 sqrt(1 - w^2) / cosh(sqrt(1 - w^2) (x - centre))``)."""
    _, (x,) = model.free_coordinates()
    s = np.sqrt(1.0 - BREATHER_FREQUENCY**2)
    v_exact = 4.0 * s / np.cosh(s * (x - BREATHER_CENTRE))
    if not np.allclose(model.initial_velocity, v_exact, atol=1e-12 * np.abs(v_exact).max()):
        raise FemromValueError("the scene's initial velocity is not the breather of BREATHER_FREQUENCY; "
                         "the exact reference of the mesh ladder would not apply")
    return breather(x, t)


def study_scene(scene: Scene, study: SineGordonStudy) -> Scene:
    """The scene at the study's n and dt, with a ``[rom]`` section
    (:func:`femrom.study.extrapolation_scene`): train on [0, T], test to t_end scored after T."""
    if study.n is not None:
        scene = with_nodes(scene, study.n)
    return extrapolation_scene(scene, scene.time.dt if study.dt is None else study.dt, study.train_window,
                               study.t_end, study.ranks,
                               derivatives=Derivatives("finite_differences", study.derivative_order))


#: what a hyper-reduced row adds to the table
HYPER_ROW = (*HYPER_COLUMNS, "lopinf_seconds_per_step", "speedup_over_lopinf")


def case_rows(state, study: SineGordonStudy, out_dir: Path) -> tuple[list[dict], list[dict]]:
    """The case's table: the study's ROMs and the hyper-reduced ones (:func:`femrom.study.rom_table`:
    errors, the FOM energy of the reconstructed state, the ROM's own energy drift, the costs), with
    the nodes at which each samples the potential; and its plots. Returns the table and the
    hyper-reduced rows."""
    system, V, test = state.model.system, state.basis, state.runs["extrapolation"]
    T, r0 = state.config.test[0].score_after, study.main_rank
    # the learned K^ with the potential sampled by ECSW on every hyper_stride-th training state
    hyper_rows, hyper_evaluations = hyper_reduced_rows(state, learner="lopinf", tolerance=study.hyper_tolerance,
                                                       stride=study.hyper_stride)
    sources = [{"samples": system.n_dofs} | row for row in state.rows] + hyper_rows
    evaluations = state.evaluations | hyper_evaluations
    rows, histories = rom_table(system, V, test, sources, evaluations, train="train", score_after=T,
                                carry=HYPER_ROW)
    plot_histories(out_dir, test, state.projections["extrapolation"], evaluations, rows, histories, r0, NAMES,
                   title=f"sine-Gordon n = {system.n_dofs}, trained on [0, {T:g}] s", shade=(0.0, T), envelope=250)
    shown = {m: NAMES[m] for m in ("lopinf", "lopinf_hyper") if (r0, m, test.name) in evaluations}
    plot_output_history(out_dir / "rom_outputs.png", test, evaluations, r0, shown, shade=(0.0, T),
                        ylabel=f"q at {system.output_names[0]}", title=f"output {system.output_names[0]} (r={r0})")
    _plot_profiles(out_dir / "rom_profiles.png", state.model, state.store.read("extrapolation", "q"), test.times,
                   V[:, :r0], {shown[m]: evaluations[(r0, m, test.name)].solution.q for m in shown},
                   [study.train_window, 0.5 * (study.train_window + study.t_end), study.t_end])
    return rows, hyper_rows


COLUMNS = ["method", "r", "samples", "train_error", "test_error", "projection_error", "energy_error_max",
           "online_seconds", "seconds_per_step", "speedup"]


def run(out_dir, *, quick: bool = False, paper: bool = False, study: SineGordonStudy | None = None,
        scene_path=SCENE) -> dict:
    """Run the case; return its metrics (also written to ``out_dir/metrics.json``)."""
    out_dir = Path(out_dir)
    study = study if study is not None else (QUICK if quick else PAPER if paper else SineGordonStudy())
    scene = study_scene(Scene.from_toml(scene_path), study)

    def extend(state):
        rows, hyper_rows = case_rows(state, study, out_dir)
        ladder = final_state_ladders(state.model, study.train_window, study.ladder_time_steps, study.ladder_fine_dt,
                                     (build(with_nodes(scene, n)) for n in study.ladder_nodes), exact_breather,
                                     exact_name="exact breather")
        test = state.runs["extrapolation"]
        metrics = {"case": "sine_gordon", "settings": dataclasses.asdict(study), "dt": scene.time.dt,
                   "boundary_conditions": "q = 0 at both ends (the breather decays as exp(-0.6 |x - 20|))",
                   "fom": {"seconds": test.summary["stepping_seconds"], "summary": test.summary,
                           "energy_drift": invariant_drift(test.energy), "energy0": float(test.energy[0])},
                   "rows": rows, "fom_ladder": ladder,
                   "hyper_nodes": {str(h["r"]): {"nodes": h["nodes"], "weights": h["weights"]} for h in hyper_rows}}
        sections = [
            table_section("The case's table", rows, COLUMNS, text=(
                "Errors in the mass norm over the test window; energy error = FOM energy of the reconstructed ROM "
                "state against E(0), maximum over [0, t_end]; speedup = FOM step over ROM step (each the fastest "
                "of timed blocks); samples = nodes at which the nonlinear potential is evaluated.")),
            final_state_section(out_dir / "accuracy_cost_fom.png", ladder,
                                note="Newmark average acceleration and P1 with a lumped mass (symmetric finite "
                                     "differences) are both second order.")]
        return metrics, sections

    return run_study(scene, out_dir, extend=extend, progress=None)


def _plot_profiles(path, model, Q, times, V, curves: dict, at):
    """q(x) of the FOM (``Q``, (n, k)) and of the ROMs (``curves``: legend name -> (r, k)
    coordinates in ``V``) at a few times ``at`` (the seed's extrapolation figure)."""
    plt = pyplot()
    index, (x,) = model.free_coordinates()
    order = np.argsort(x)
    x, index = x[order], index[order]
    fig, axes = plt.subplots(1, len(at), figsize=(4 * len(at), 3.2), sharey=True)
    for ax, t in zip(np.atleast_1d(axes), at):
        k = int(np.argmin(np.abs(times - t)))
        ax.plot(x, Q[index, k], "k-", lw=2.0, label="FOM")
        for (name, q), style in zip(curves.items(), ("--", ":")):
            ax.plot(x, (V @ q[:, k])[index], style, lw=1.3, label=name)
        ax.set_title(f"t = {times[k]:g} s")
        ax.set_xlabel("x")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("q")
    np.atleast_1d(axes)[0].legend(fontsize=8)
    save_figure(fig, path, dpi=100)


def main(argv=None) -> int:
    parser = case_parser("sine_gordon", __doc__, quick="n = 400, dt = 0.02, r = 3, 4 (tests)")
    parser.add_argument("--paper", action="store_true", help="dt = 0.005, r up to 12")
    parser.add_argument("--ranks", type=int, nargs="+", help="basis sizes r")
    args = parser.parse_args(argv)
    study = QUICK if args.quick else PAPER if args.paper else SineGordonStudy()
    if args.ranks:
        study = dataclasses.replace(study, ranks=tuple(args.ranks),
                                    main_rank=args.ranks[min(len(args.ranks) - 1, 2)])
    with staged_output(args.out) as out:    # the results appear whole, or the old ones stay
        metrics = run(out, study=study)
    print(f"sine_gordon: {metrics['n_dofs']} dofs, FOM {metrics['fom']['summary']['stepping_seconds']:.2f} s, "
          f"energy drift {metrics['fom']['energy_drift']:.1e}; report in {args.out}")
    print(accuracy_cost_table(metrics["rows"], ["method", "r", "test_error", "projection_error", "energy_error_max",
                                                "samples", "seconds_per_step", "speedup", "failed"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
