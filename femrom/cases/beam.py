"""Euler-Bernoulli cantilever: FOM, then L-OpInf / Galerkin / plain OpInf ROMs, and what accuracy costs.

A steel cantilever (Hermite elements on a Gmsh line; clamped at x = 0, free at
x = L) is released from its static deflection under a tip load
(``beam.toml``). The ROM part runs on the study layer
(:func:`femrom.study.run_study`; settings :class:`RomStudy`): FOM -> snapshots
of a training window -> mass-orthonormal POD -> intrusive Galerkin, L-OpInf
and plain OpInf on the same data and basis, for several r, predicting 20x the
training window; it is repeated on coarser snapshots (:data:`COARSE_ROM`),
where plain OpInf blows up. What is the beam's own: the analytic cantilever
frequencies, its dt and mesh ladders, and the a priori dispersion floor of a
learned model (:func:`dispersion_error`); the table with the FOM energy of the
reconstructed ROM state is :func:`femrom.study.rom_table`. The case writes, into its output folder:

- the study's report (``report.md``, ``metrics.json``, ``response.png``,
  ``rom_error.png``, ``energy.png``, ``accuracy_cost.png``) with the beam's
  sections, and the coarse study's under ``coarse/``;
- ``rom_state_error.png``, ``rom_energy_error.png``, ``rom_tip_end.png``,
  ``accuracy_cost_rom.png`` (test error vs online time), ``accuracy_cost_rom_r.png``
  and the same with prefix ``coarse_``;
- ``fom_response.png``: tip and midspan deflection and the relative energy change;
- ``accuracy_cost_dt.png``: tip error against stepping time for a ladder of time
  steps (reference: dt / 8 on the same mesh); ``accuracy_cost_mesh.png``: error of
  the first four natural frequencies against the analytic cantilever roots, for a
  ladder of mesh sizes, against assembly + eigen-solve time.

Run ``python -m femrom run beam [--out DIR] [--quick]``; tests import :func:`run`.
"""


import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom.cases import case_parser
from femrom.post import machine_description, plot_accuracy_cost_groups, staged_output, table_section
from femrom.scene import Derivatives, Scene
from femrom.study import EXTRAPOLATION_LEARNER_NAMES, dispersion_error, extrapolation_scene, frequency_ladder, frequency_section, invariant_drift, \
    natural_frequencies, plot_histories, plot_output_history, rom_table, run_study, scene_run, scored_columns, \
    time_step_ladder, time_step_section

SCENE = Path(__file__).with_suffix(".toml")

# beta_n L of a cantilever (Blevins 1979, table 8-1; ../shared/DESIGN.md)
CANTILEVER_ROOTS = np.array([1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349])


def analytic_frequencies(scene: Scene, count: int = 4) -> np.ndarray:
    """Cantilever omega_n = (beta_n L)^2 sqrt(E I / (rho A L^4)) [rad/s]."""
    m = scene.material
    length = dict(scene.structure.parameters)["length"]
    return CANTILEVER_ROOTS[:count] ** 2 * np.sqrt(
        m.youngs_modulus * m.second_moment / (m.density * m.area * length**4))


@dataclass(frozen=True)
class RomStudy:
    """Settings of the ROM part: snapshot step ``dt`` (also the ROMs' Newmark step), training
    window ``[0, train_window]``, prediction over ``extension`` windows (the seed shows 20x),
    ranks, the r of the time-history plots, the finite-difference order, whether the learners
    fit a damping ``C^`` (they are not told the beam is undamped), the FOM's mesh size."""

    dt: float = 5.0e-5
    train_window: float = 0.15
    extension: float = 20.0
    ranks: tuple[int, ...] = (2, 4, 6, 8, 10, 12)
    main_rank: int = 8
    derivative_order: int = 4
    damping: bool = True
    mesh_size: float | None = None


QUICK_ROM = RomStudy(dt=1.0e-4, train_window=0.1, ranks=(2, 4, 6), main_rank=6, mesh_size=0.05)
PAPER_ROM = RomStudy(dt=2.5e-5, train_window=0.15, ranks=(2, 4, 6, 8, 10, 12, 16, 20), main_rank=10,
                     mesh_size=0.01)
# The same comparison on coarser snapshots (the scene's FOM step; 4x the quick step): the
# finite-difference accelerations of the poorly resolved high POD modes are then wrong by
# O(1) (data error), the regime in which the seed shows plain OpInf blowing up.
COARSE_ROM = RomStudy(dt=2.0e-4, ranks=(8, 10, 12), main_rank=12)
QUICK_COARSE_ROM = dataclasses.replace(QUICK_ROM, dt=4.0e-4, ranks=(6, 8), main_rank=8)


def study_scene(scene: Scene, study: RomStudy) -> Scene:
    """The scene of a ROM study: its mesh and step, and a ``[rom]`` section
    (:func:`femrom.study.extrapolation_scene`): train on ``[0, T]``, test the same release over
    ``extension x T``, scored after ``T``; the learners fit a damping with ``study.damping``."""
    if study.mesh_size is not None:
        scene = scene.with_geometry(mesh_size=study.mesh_size)
    T = int(round(study.train_window / study.dt)) * study.dt
    return extrapolation_scene(scene, study.dt, T, study.extension * T, study.ranks,
                               derivatives=Derivatives("finite_differences", study.derivative_order),
                               terms=("damping",) if study.damping else ())


def beam_rows(state, study: RomStudy, out_dir: Path, prefix: str) -> dict:
    """The beam's metrics of a study's ROMs, and its plots: the study's errors over the training
    window and after it and the FOM energy of the reconstructed ROM state
    (:func:`femrom.study.rom_table`, with the operators' smallest eigenvalues), with the dispersion
    floor and the offline time; state error, energy error and tip over time at ``main_rank``."""
    system, V, test = state.model.system, state.basis, state.runs["extrapolation"]
    times, T = test.times, state.config.test[0].score_after
    window, projection, r_main = scored_columns(test, T), state.projections["extrapolation"], study.main_rank
    rows, histories = rom_table(system, V, test, state.rows, state.evaluations, train="train", score_after=T,
                                carry=("fit_seconds",))
    offline = (state.runs["train"].summary["stepping_seconds"] + state.timings["pod_seconds"]
               + state.timings["projection_seconds"])
    for row, study_row in zip(rows, state.rows):
        dispersion = None
        if not np.any(test.v0):        # the formula is for a release from rest
            dispersion = dispersion_error(system, test.q0, study.dt, times[window], row["r"], projection.norm(window))
        row.update({
            "dt": study.dt, "dispersion_error": dispersion,
            "predicted_learned_error": None if dispersion is None else float(np.hypot(row["projection_error"],
                                                                                        dispersion)),
            "offline_seconds": offline + study_row["fit_seconds"]})
    plot_histories(out_dir, test, projection, state.evaluations, rows, histories, r_main, EXTRAPOLATION_LEARNER_NAMES, prefix=prefix,
                   title=f"beam ROMs (dt = {study.dt:g}, trained on [0, {T:g}] s)", shade=(0.0, T), fom_energy=False)
    plot_output_history(out_dir / f"{prefix}rom_tip_end.png", test, state.evaluations, r_main, EXTRAPOLATION_LEARNER_NAMES,
                        last=2 * T, ylabel="tip deflection [m]",
                        title=f"tip over the last {2 * T:g} s of the prediction (r={r_main})")
    plot_accuracy_cost_groups(out_dir / f"{prefix}accuracy_cost_rom_r.png", rows, "r", "test_error", "r", "method",
                              title="ROM test error vs r")
    return {"settings": dataclasses.asdict(study), "n_dofs": system.n_dofs, "train_window": float(times[window.start - 1]),
            "fom_seconds": test.summary["stepping_seconds"], "fom_summary": test.summary,
            "fom_energy_drift": invariant_drift(test.energy), "rows": rows}


def rom_study(scene: Scene, study: RomStudy, out_dir: Path, *, plots_dir: Path, prefix: str = "",
              finish=None) -> dict:
    """One ROM study on the study layer into ``out_dir``; the beam's plots (names starting with
    ``prefix``) into ``plots_dir``. ``finish(rom_metrics) -> (metrics, sections)`` adds to the
    study's metrics and report (default: the beam's ROM metrics as ``rom_beam`` and their section).
    Returns the study's metrics."""
    def extend(state):
        rom_metrics = beam_rows(state, study, plots_dir, prefix)
        return finish(rom_metrics) if finish else ({"rom_beam": rom_metrics}, [rom_section(rom_metrics, "")])

    with np.errstate(over="ignore", invalid="ignore"):          # plain OpInf may blow up
        return run_study(study_scene(scene, study), out_dir, extend=extend, progress=None)


def rom_section(m: dict, title: str) -> str:
    st = m["settings"]
    return table_section(
        f"ROMs{title}: intrusive Galerkin, L-OpInf and plain OpInf on the same data and basis", m["rows"],
        ROM_COLUMNS, text=f"{m['n_dofs']} dofs, Newmark dt = {st['dt']:g} s over {st['extension']:g} x the training "
        f"window [0, {m['train_window']:g}] s; order-{st['derivative_order']} finite differences; the learners fit "
        f"K^{' and C^' if st['damping'] else ''}. Columns: docs/cases/beam.md.")


ROM_COLUMNS = ["method", "r", "train_error", "test_error", "projection_error", "error_over_projection",
               "predicted_learned_error", "energy_error_max", "blowup_time", "online_seconds", "offline_seconds",
               "speedup"]


def run(out_dir, *, quick: bool = False, scene_path=SCENE, rom: RomStudy | None = None,
        paper: bool = False, ladders: bool = True) -> dict:
    """Run the case; return its metrics (also written to ``out_dir/metrics.json``).

    ``rom`` overrides the ROM study's settings (default :class:`RomStudy`,
    :data:`QUICK_ROM` with ``quick``, :data:`PAPER_ROM` with ``paper``);
    ``ladders=False`` skips the FOM dt and mesh ladders.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    base = Scene.from_toml(scene_path)
    scene = base.with_time(t_end=0.5, dt=4 * base.time.dt) if quick else base
    fom = scene_run(scene, out_dir / "fom_response.png")      # tip and midspan deflection, energy change
    model = fom.model
    exact = analytic_frequencies(scene)
    omega = natural_frequencies(model.system)
    dt_rows, mesh_rows, sections = [], [], [fom.section()]
    if ladders:   # tip error (max over time, relative to the peak) against a run at dt / 8
        dt_rows = time_step_ladder(model, None, (8, 4, 2, 1) if not quick else (4, 2, 1), reference_divisor=8,
                                   error="max", outputs=[0])
        mesh_rows = frequency_ladder(scene, (0.1, 0.05, 0.025) if quick else (0.2, 0.1, 0.05, 0.025, 0.0125),
                                     exact=exact)
        sections += [
            time_step_section(out_dir / "accuracy_cost_dt.png", dt_rows, note="Pre-asymptotic below 2: docs/cases/beam.md.",
                              heading="Time step: tip error (vs dt/8) against stepping time"),
            frequency_section(out_dir / "accuracy_cost_mesh.png", mesh_rows, heading="Mesh: first four natural "
                              "frequencies against the analytic roots (vs build + eigensolve time)")]
    study = rom if rom is not None else (QUICK_ROM if quick else PAPER_ROM if paper else RomStudy())
    coarse = QUICK_COARSE_ROM if quick else COARSE_ROM
    coarse_metrics = rom_study(base, coarse, out_dir / "coarse", plots_dir=out_dir, prefix="coarse_")["rom_beam"]

    def finish(rom_metrics):
        metrics = {
            "case": "beam", "scene": scene.name, **fom.metrics(), "machine": machine_description(),
            "frequencies_hz": omega / (2 * np.pi), "analytic_frequencies_hz": exact / (2 * np.pi),
            "time_step_ladder": dt_rows, "mesh_ladder": mesh_rows,
            "boundary_conditions": "cantilever: deflection and slope clamped at x = 0, free at x = L",
            "rom": rom_metrics, "rom_coarse_data": coarse_metrics,
        }
        coarse_title = f" on coarser snapshots (dt = {coarse_metrics['settings']['dt']:g} s)"
        return metrics, [*sections, rom_section(rom_metrics, ""), rom_section(coarse_metrics, coarse_title)]

    return rom_study(base, study, out_dir, plots_dir=out_dir, finish=finish)


def main(argv=None) -> int:
    parser = case_parser("beam", __doc__, quick="short window and ladders (tests)")
    parser.add_argument("--paper", action="store_true",
                        help="finer mesh (h = 0.01, 200 dofs), dt = 2.5e-5, r up to 20")
    parser.add_argument("--ranks", type=int, nargs="+", help="basis sizes r of the ROM ladder")
    parser.add_argument("--train-window", type=float, help="training window [s]")
    parser.add_argument("--no-ladders", action="store_true", help="skip the FOM dt and mesh ladders")
    args = parser.parse_args(argv)
    study = QUICK_ROM if args.quick else PAPER_ROM if args.paper else RomStudy()
    if args.ranks:
        study = dataclasses.replace(study, ranks=tuple(args.ranks),
                                    main_rank=args.ranks[min(len(args.ranks) - 1, 3)])
    if args.train_window:
        study = dataclasses.replace(study, train_window=args.train_window)
    with staged_output(args.out) as out:    # the results appear whole, or the old ones stay
        metrics = run(out, quick=args.quick, rom=study, ladders=not args.no_ladders)
    print(f"beam: {metrics['n_dofs']} dofs, energy drift {metrics['energy_relative_drift']:.1e}, f1 = "
          f"{metrics['frequencies_hz'][0]:.3f} Hz (analytic {metrics['analytic_frequencies_hz'][0]:.3f}); "
          f"report in {args.out / 'report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
