"""Euler-Bernoulli cantilever: FOM, then L-OpInf / Galerkin / plain OpInf ROMs, and what accuracy costs.

A steel cantilever (Hermite elements on a Gmsh line; clamped at x = 0, free at
x = L) is released from its static deflection under a tip load
(``beam.toml``). The ROM part runs on the study layer
(:func:`femrom.study.run_study`; settings :class:`RomStudy`): FOM -> snapshots
of a training window -> mass-orthonormal POD -> intrusive Galerkin, L-OpInf
and plain OpInf on the same data and basis, for several r, predicting 20x the
training window; it is repeated on coarser snapshots (:data:`COARSE_ROM`),
where plain OpInf blows up. What is the beam's own: the analytic cantilever
frequencies, its dt and mesh ladders, the FOM energy of the reconstructed ROM
state, and the a priori dispersion floor of a learned model
(:func:`dispersion_error`). The case writes, into its output folder:

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


import argparse
import dataclasses
from dataclasses import dataclass
import time
from pathlib import Path

import numpy as np

from femrom.integrators import simulate
from femrom.post import accuracy_cost_table, machine_description, plot_accuracy_cost, plot_response
from femrom.scene import BasisSpec, Derivatives, LearnerSpec, ReportSpec, RomConfig, RunSpec, Scene, build
from femrom.study import frequency_ladder, natural_frequencies, plot_error_history, run_study, scored_columns, time_step_ladder

SCENE = Path(__file__).with_suffix(".toml")

# beta_n L of a cantilever (Blevins 1979, table 8-1; ../shared/DESIGN.md)
CANTILEVER_ROOTS = np.array([1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349])


def with_time_step(scene: Scene, dt: float) -> Scene:
    return dataclasses.replace(scene, time=dataclasses.replace(scene.time, dt=dt))


def with_mesh_size(scene: Scene, mesh_size: float) -> Scene:
    params = dict(scene.structure.parameters) | {"mesh_size": mesh_size}
    structure = dataclasses.replace(scene.structure, parameters=tuple(sorted(params.items())))
    return dataclasses.replace(scene, structure=structure)


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
LABELS = {"galerkin": "intrusive Galerkin", "lopinf": "L-OpInf", "plain_opinf": "plain OpInf"}


def newmark_frequencies(omega: np.ndarray, dt: float) -> np.ndarray:
    """Frequencies of Newmark average acceleration: ``tan(Omega dt / 2) = omega dt / 2`` (no amplitude error)."""
    return 2.0 / dt * np.arctan(0.5 * omega * dt)


def dispersion_error(system, q0: np.ndarray, dt: float, times: np.ndarray, r: int, norm: float) -> float:
    r"""A priori test-window error of a ROM that learned the FOM's *discrete* frequencies.

    Released from ``q0`` at rest, the Newmark FOM is exactly
    ``q_n = sum_k a_k cos(Omega_k t_n) phi_k`` (``phi_k`` mass-orthonormal modes,
    ``Omega_k`` :func:`newmark_frequencies` of ``omega_k``). Finite differences of
    order p of ``cos(Omega t)`` return ``Omega`` up to ``O((Omega dt)^p)``, so a
    learner that fits the data exactly learns ``Omega_k``, not ``omega_k``; the
    ROM's own Newmark step then runs at ``Omega'_k = newmark_frequencies(Omega_k)``.
    Over the modes 1..r (those a POD basis of this data spans) that phase error is

    .. math::

        d(r) = \Big(\sum_{t \in \text{test}} \sum_{k \le r}
               a_k^2 (\cos\Omega'_k t - \cos\Omega_k t)^2\Big)^{1/2} / \|Q_{test}\|_M,

    and such a ROM's error is ``sqrt(projection^2 + d(r)^2)``. ``norm`` is
    ``||Q_test||_M``, ``times`` the test window's times.
    """
    import scipy.linalg as sl

    omega2, modes = sl.eigh(system.stiffness.toarray(), system.mass.toarray())
    amplitudes = modes[:, :r].T @ np.asarray(system.mass @ q0)
    learned = newmark_frequencies(np.sqrt(omega2[:r]), dt)
    stepped = newmark_frequencies(learned, dt)
    phase = np.cos(np.outer(stepped, times)) - np.cos(np.outer(learned, times))
    return float(np.sqrt(np.sum(amplitudes[:, None] ** 2 * phase**2)) / norm)


def study_scene(scene: Scene, study: RomStudy) -> Scene:
    """The scene of a ROM study: its mesh and step, and a ``[rom]`` section: train on
    ``[0, T]``, test the same release over ``extension x T``, scored after ``T``."""
    if study.mesh_size is not None:
        scene = with_mesh_size(scene, study.mesh_size)
    n_train = int(round(study.train_window / study.dt))
    T = n_train * study.dt
    data = Derivatives("finite_differences", study.derivative_order)
    terms = ("damping",) if study.damping else ()
    config = RomConfig(
        train=(RunSpec("train", t_end=T),),
        test=(RunSpec("extrapolation", t_end=int(round(study.extension * n_train)) * study.dt, score_after=T),),
        learners=(LearnerSpec("galerkin", "galerkin", data), LearnerSpec("lopinf", "lopinf", data, terms=terms),
                  LearnerSpec("plain_opinf", "opinf", data, terms=terms)),
        basis=BasisSpec(tuple(study.ranks), method="svd"), extension=1.0,
        report=ReportSpec(render=False, paraview=False))
    return dataclasses.replace(with_time_step(scene, study.dt), rom=config)


def beam_rows(state, study: RomStudy, out_dir: Path, prefix: str) -> dict:
    """The beam's metrics of a study's ROMs, and its plots: mass-norm errors over the training
    window and after it (the study's), the dispersion floor, the FOM energy of the reconstructed
    ROM state against ``E(0)``; state error, energy error and tip over time at ``main_rank``."""
    from femrom.post import plot_accuracy_cost_groups, plot_time_series

    system, V, test = state.model.system, state.basis, state.runs["extrapolation"]
    times, T = test.times, state.config.test[0].score_after
    window = scored_columns(test, T)
    E0, r_main = test.energy[0], study.main_rank
    rows, energy_errors, tips = [], {}, {"FOM": test.outputs[0]}
    for row in state.rows:
        r, method = row["r"], row["learner"]
        solution = state.evaluations[(r, method, "extrapolation")].solution
        dispersion = None
        if not np.any(test.v0):        # the formula is for a release from rest
            dispersion = dispersion_error(system, test.q0, study.dt, times[window], r,
                                          state.projections["extrapolation"].norm(window))
        with np.errstate(over="ignore", invalid="ignore"):
            Q, Vel = V[:, :r] @ solution.q, V[:, :r] @ solution.v
            energy_error = np.abs(0.5 * np.sum(Vel * (system.mass @ Vel) + Q * (system.stiffness @ Q), axis=0)
                                  - E0) / E0
        eig, K = row["_rom"].operators_.eigenvalues(), row["_rom"].operators_.stiffness
        projection = row["test_projection_error"]
        rows.append({
            "method": method, "r": r, "dt": study.dt, "train_error": row["train_field_error"],
            "test_error": row["test_field_error"], "projection_error": projection,
            "projection_error_train": row["train_projection_error"], "dispersion_error": dispersion,
            "predicted_learned_error": None if dispersion is None else float(np.hypot(projection, dispersion)),
            "error_over_projection": row["test_field_error"] / projection,
            "energy_error_max": float(np.nanmax(energy_error)) if np.all(np.isfinite(Q)) else float("inf"),
            "energy_error_train_max": float(np.nanmax(energy_error[:window.start])),
            "rom_energy_growth": row["test_energy_growth"], "blowup_time": row["test_blowup_time"],
            "stiffness_min_eig": float(eig["stiffness"][0]),
            "stiffness_asymmetry": float(np.linalg.norm(K - K.T) / np.linalg.norm(K)),
            "damping_min_eig": float(eig["damping"][0]) if "damping" in eig else None,
            "online_seconds": row["seconds_per_step"] * (times.size - 1), "cost": row["cost"],
            "offline_seconds": state.runs["train"].summary["stepping_seconds"] + state.timings["pod_seconds"]
            + state.timings["projection_seconds"] + row["fit_seconds"],
            "fit_seconds": row["fit_seconds"], "speedup": row["speedup"]})
        if r == r_main:
            energy_errors[f"{LABELS[method]} (r={r})"] = energy_error
            tips[LABELS[method]] = np.asarray(system.output_matrix[0] @ Q).ravel()
    title = f"beam ROMs (dt = {study.dt:g})"
    plot_error_history(out_dir / f"{prefix}rom_state_error.png", test, state.projections["extrapolation"],
                       state.evaluations, r_main, list(LABELS), shade=(0.0, T),
                       title=f"{title}: state error, trained on [0, {T:g}] s")
    plot_time_series(out_dir / f"{prefix}rom_energy_error.png", times, energy_errors, logy=True, envelope=400,
                     ymax=10.0, shade=(0.0, T), ylabel="|E(V q^, V q^') - E0| / E0",
                     title=f"{title}: energy error (FOM energy of the reconstructed state)")
    last = times >= times[-1] - 2 * T
    plot_time_series(out_dir / f"{prefix}rom_tip_end.png", times[last], {k: v[last] for k, v in tips.items()},
                     ylabel="tip deflection [m]", title=f"tip over the last {2 * T:g} s of the prediction (r={r_main})")
    plot_accuracy_cost_groups(out_dir / f"{prefix}accuracy_cost_rom.png", rows, "online_seconds", "test_error", "r",
                              "method", title="ROM test error vs online time (labels: r)")
    plot_accuracy_cost_groups(out_dir / f"{prefix}accuracy_cost_rom_r.png", rows, "r", "test_error", "r", "method",
                              title="ROM test error vs r")
    return {"settings": dataclasses.asdict(study), "n_dofs": system.n_dofs, "train_window": float(times[window.start - 1]),
            "fom_seconds": test.summary["stepping_seconds"], "fom_summary": test.summary,
            "fom_energy_drift": float(np.max(np.abs(test.energy - E0)) / E0), "rows": rows}


def rom_study(scene: Scene, study: RomStudy, out_dir: Path, *, plots_dir: Path, prefix: str = "",
              finish=None) -> tuple[dict, dict]:
    """One ROM study on the study layer into ``out_dir``; the beam's plots (names starting with
    ``prefix``) into ``plots_dir``. ``finish(rom_metrics) -> (metrics, sections)`` adds to the
    study's metrics and report. Returns the study's metrics and the beam's ROM metrics."""
    result = {}

    def extend(state):
        result.update(beam_rows(state, study, plots_dir, prefix))
        return finish(result) if finish else ({"rom_beam": result}, [rom_section(result, "")])

    return run_study(study_scene(scene, study), out_dir, extend=extend, progress=None), result


def rom_section(m: dict, title: str) -> str:
    st = m["settings"]
    return (f"## ROMs{title}: intrusive Galerkin, L-OpInf and plain OpInf on the same data and basis\n\n"
            f"{m['n_dofs']} dofs, Newmark dt = {st['dt']:g} s over {st['extension']:g} x the training window "
            f"[0, {m['train_window']:g}] s; order-{st['derivative_order']} finite differences; the learners fit "
            f"K^{' and C^' if st['damping'] else ''}. Columns: docs/cases/beam.md.\n\n"
            + accuracy_cost_table(m["rows"], ROM_COLUMNS))


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
    scene = base
    if quick:
        scene = with_time_step(dataclasses.replace(scene, time=dataclasses.replace(scene.time, t_end=0.5)),
                               4 * scene.time.dt)
    tic = time.perf_counter()
    model = build(scene)
    build_seconds = time.perf_counter() - tic
    result = simulate(model)
    energy = result.energy
    drift = float(np.max(np.abs(energy - energy[0])) / energy[0])
    plot_response(out_dir / "fom_response.png", result.times, result.outputs, model.system.output_names,
                  energy, title=f"cantilever FOM, {model.system.n_dofs} dofs, {result.summary['scheme']}")
    exact = analytic_frequencies(scene)
    omega = natural_frequencies(model.system)
    dt_rows = mesh_rows = []
    if ladders:   # tip error (max over time, relative to the peak) against a run at dt / 8
        dt_rows = time_step_ladder(model, None, (8, 4, 2, 1) if not quick else (4, 2, 1), reference_divisor=8,
                                   error="max", outputs=[0])
        mesh_rows = frequency_ladder(scene, (0.1, 0.05, 0.025) if quick else (0.2, 0.1, 0.05, 0.025, 0.0125),
                                     exact=exact)
        plot_accuracy_cost(out_dir / "accuracy_cost_dt.png", dt_rows, "stepping_seconds", "output_error", "dt",
                           title="FOM time step: tip error vs stepping time")
        plot_accuracy_cost(out_dir / "accuracy_cost_mesh.png", mesh_rows, "seconds", "frequency_error",
                           "dofs", title="FOM mesh: frequency error vs build + eigensolve time")
    study = rom if rom is not None else (QUICK_ROM if quick else PAPER_ROM if paper else RomStudy())
    coarse = QUICK_COARSE_ROM if quick else COARSE_ROM
    with np.errstate(over="ignore", invalid="ignore"):
        _, coarse_metrics = rom_study(base, coarse, out_dir / "coarse", plots_dir=out_dir, prefix="coarse_")

    def finish(rom_metrics):
        metrics = {
            "case": "beam", "scene": scene.name, "n_dofs": model.system.n_dofs, "machine": machine_description(),
            "build_seconds": build_seconds, "build_timings": model.timings, "simulation": result.summary,
            "energy_relative_drift": drift,
            "frequencies_hz": omega / (2 * np.pi), "analytic_frequencies_hz": exact / (2 * np.pi),
            "time_step_ladder": dt_rows, "mesh_ladder": mesh_rows,
            "boundary_conditions": "cantilever: deflection and slope clamped at x = 0, free at x = L",
            "rom": rom_metrics, "rom_coarse_data": coarse_metrics,
        }
        sections = [f"## The scene's FOM run\n\n{model.system.n_dofs} free dofs, {result.summary['n_steps']} steps "
                    f"of {scene.time.dt:g} s in {result.summary['stepping_seconds']:.2f} s; energy drift {drift:.2e}."]
        if dt_rows:
            sections += [
                "## Time step: tip error (vs dt/8) against stepping time\n\n"
                + accuracy_cost_table(dt_rows, ["dt", "steps", "output_error", "stepping_seconds"])
                + f"\n\nObserved order {dt_rows[0]['observed_order']:.2f} (pre-asymptotic below 2: docs/cases/beam.md).",
                "## Mesh: first four natural frequencies against the analytic roots\n\n"
                + accuracy_cost_table(mesh_rows, ["mesh_size", "dofs", "frequency_error", "f1_hz", "seconds"])]
        sections += [rom_section(rom_metrics, ""),
                     rom_section(coarse_metrics, f" on coarser snapshots (dt = {coarse_metrics['settings']['dt']:g} s)")]
        return metrics, sections

    with np.errstate(over="ignore", invalid="ignore"):
        metrics, _ = rom_study(base, study, out_dir, plots_dir=out_dir, finish=finish)
    return metrics


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="femrom run beam", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results") / "beam")
    parser.add_argument("--quick", action="store_true", help="short window and ladders (tests)")
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
    metrics = run(args.out, quick=args.quick, rom=study, ladders=not args.no_ladders)
    print(f"beam: {metrics['n_dofs']} dofs, energy drift {metrics['energy_relative_drift']:.1e}, f1 = "
          f"{metrics['frequencies_hz'][0]:.3f} Hz (analytic {metrics['analytic_frequencies_hz'][0]:.3f}); "
          f"report in {args.out / 'report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
