"""``femrom run scene.toml`` for a scene with a ``[rom]`` section: the whole report of one structure."""

from __future__ import annotations

import dataclasses
import resource
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom._errors import FemromValueError
from femrom.post import accuracy_cost_table, machine_description, write_metrics
from femrom.post import plot_accuracy_cost as plot_points
from femrom.scene import Scene, build
from femrom.snapshots import SnapshotStore
from femrom.study._figures import plot_accuracy_cost, plot_energy, plot_errors, plot_outputs, render_fields
from femrom.study._ladders import TIME_STEP_COLUMNS, ladder_table, time_step_ladder
from femrom.study._canonical import check_canonical_learners
from femrom.study._study import check_rom_config, fom_runs, interval_cost, model_spec, needs_stored_derivatives, \
    pod_basis, product_matrix, reduce_runs, study_experiments_of, study_rows

ROW_COLUMNS = ["r", "learner", "derivatives", "train_output_error", "test_output_error", "test_field_error",
               "test_energy_ratio", "fit_seconds", "seconds_per_step", "speedup", "diverged"]


def peak_rss_gb() -> float:
    """Peak resident memory of this process so far [GiB] (``ru_maxrss``, Linux kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def public_rows(rows: list[dict]) -> list[dict]:
    """Rows without their in-memory objects (keys starting with ``_``), for JSON."""
    return [{k: v for k, v in row.items() if not k.startswith("_")} for row in rows]


@dataclass(frozen=True, eq=False)
class StudyState:
    """What :func:`run_study` hands its ``extend`` hook, with the snapshot store still open."""

    scene: Scene
    model: object
    config: object
    store: SnapshotStore
    runs: dict
    product: object
    basis: np.ndarray
    rows: list
    evaluations: dict
    projections: dict
    out_dir: Path
    progress: object
    timings: dict
    data: dict | None = None
    """The training runs' reduced data in the largest basis (:class:`~femrom.inference.SecondOrderData` by run
    name): what a case's own learners (identified state-space models) fit on."""


def run_study(scene: Scene, out_dir, *, model=None, store_path=None, extend=None, progress=print) -> dict:
    """Build the scene, run its ``[rom]`` study, write the report; return the metrics.

    Writes into ``out_dir``: ``metrics.json``, ``report.md``, ``response.png``
    (FOM and ROM outputs at the largest r), ``rom_error.png`` (errors against r),
    ``energy.png`` (reduced energy over the extended window of the first test),
    ``accuracy_cost.png`` (error against measured cost), ``render.png`` and
    ``paraview/<scene>.pvd`` on 3D meshes, ``accuracy_cost_dt.png`` with a time-step
    ladder; ``snapshots.h5`` (or ``store_path``) only with ``report.keep_snapshots``.

    ``extend(state) -> (metrics, sections)``, called with a :class:`StudyState`
    while the store is open, lets a case add its own studies: ``metrics`` (a dict)
    joins the metrics, ``sections`` (markdown strings) close the report.
    """
    config = scene.rom
    if config is None:
        raise FemromValueError(f"scene {scene.name!r} has no [rom] section")
    check_rom_config(config)
    say = progress or (lambda message: None)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    timings = {}
    tic = time.perf_counter()
    model = build(scene) if model is None else model
    timings["build_seconds"] = time.perf_counter() - tic
    system = model.system
    check_canonical_learners(system, config)
    W = product_matrix(system, config)
    stored = needs_stored_derivatives(config)
    store_path = out_dir / "snapshots.h5" if store_path is None else Path(store_path)
    store = SnapshotStore.create(store_path, model, fields=("q", "v", "a") if stored else ("q",), overwrite=True)
    try:
        tic = time.perf_counter()
        runs = fom_runs(model, config, store, progress=say)
        timings["fom_seconds"] = time.perf_counter() - tic
        rss_after_fom = peak_rss_gb()
        store_bytes, store_fields = store_path.stat().st_size, list(store.fields)
        train = tuple(s.name for s in config.train)
        test = tuple(s.name for s in config.test)
        say(f"POD of {', '.join(train)} ({config.basis.method}, r <= {max(config.basis.ranks)})")
        tic = time.perf_counter()
        pod = pod_basis(store, train, W, config)
        timings["pod_seconds"] = time.perf_counter() - tic
        tic = time.perf_counter()
        order = next((s.derivatives.order for s in config.learners if s.derivatives.kind == "finite_differences"), 4)
        data, projections = reduce_runs(store, runs, train, pod.basis_, W, stored_derivatives=stored, order=order,
                                        nonlinear=system.nonlinear)
        timings["projection_seconds"] = time.perf_counter() - tic
        tic = time.perf_counter()
        experiments = study_experiments_of(StudyState(scene, model, config, store, runs, W, pod.basis_, [], {},
                                                      projections, out_dir, say, timings, data), config)
        rows, evaluations = study_rows(system, pod.basis_, W, data, projections, runs, config,
                                       experiments=experiments, progress=say)
        timings["rom_seconds"] = time.perf_counter() - tic

        r_show = max(config.basis.ranks)
        labels = [s.label for s in config.learners]
        roles = {name: ("training" if name in train else "unseen") for name in runs}
        title = f"{scene.name}: {system.n_dofs} dofs, trained on {', '.join(train)}"
        plot_outputs(out_dir / "response.png", runs, evaluations, r_show, labels, system.output_names, title,
                     roles=roles)
        plot_errors(out_dir / "rom_error.png", rows, title)
        first_test = runs[test[0]]
        if first_test.energy is not None:
            plot_energy(out_dir / "energy.png", evaluations, r_show, labels, first_test,
                        f"reduced energy over {config.extension:g}x the window of {test[0]}")
        fom_cost = interval_cost(max(runs.values(), key=lambda run: run.times.size))    # as study_rows' speedups
        plot_accuracy_cost(out_dir / "accuracy_cost.png", rows, fom_cost.to_dict(),
                           f"{scene.name}: unseen-input output error vs cost")
        show = next((s.label for s in config.learners if not model_spec(s).intrusive), labels[0])
        shown = evaluations.get((r_show, show, test[0]))
        renders = {"render": None, "paraview": None, "render_backend": f"{show} r={r_show} failed"} \
            if shown is None else render_fields(out_dir, model, store, first_test, shown.solution,
                                                f"{show} r={r_show}", render=config.report.render,
                                                paraview=config.report.paraview)
        extra, sections = {}, []
        if extend is not None:
            extra, sections = extend(StudyState(scene, model, config, store, runs, W, pod.basis_, rows,
                                                evaluations, projections, out_dir, say, timings, data))
    finally:
        store.close()
    if not config.report.keep_snapshots:
        store_path.unlink(missing_ok=True)

    dt_rows = []
    if config.report.time_step_factors:
        say(f"time-step ladder: dt x {', '.join(map(str, config.report.time_step_factors))}")
        dt_rows = time_step_ladder(model, runs[train[0]], config.report.time_step_factors,
                                   min_block_seconds=config.timing.min_block_seconds)
        plot_points(out_dir / "accuracy_cost_dt.png", dt_rows[:-1], "stepping_seconds", "output_error", "dt",
                    title=f"FOM time step: output error (vs dt = {scene.time.dt:g}) vs stepping time")

    metrics = {
        "scene": scene.name, "n_dofs": system.n_dofs, "n_inputs": system.n_inputs,
        "output_names": list(system.output_names), "effects": list(scene.effect_names),
        "machine": machine_description(), "build_timings": model.timings, **timings,
        "fom": {name: {**run.summary, "cost": run.cost.to_dict()} for name, run in runs.items()},
        "fom_seconds_per_step": fom_cost.seconds, "fom_cost": fom_cost.to_dict(),
        "train": list(train), "test": list(test), "ranks": list(config.basis.ranks),
        "extension": config.extension, "learners": labels,
        "snapshots": {"bytes": store_bytes, "fields": store_fields,
                      "path": (store_path.name if store_path.parent == out_dir else str(store_path))
                      if config.report.keep_snapshots else None},
        "factorization_seconds": runs[train[0]].summary.get("factorization_seconds"),
        "pod": {"method": config.basis.method, "product": config.basis.product, "seconds": timings["pod_seconds"],
                "passes": config.basis.power_iterations + 2 if config.basis.method == "randomized" else 1,
                "singular_values": pod.singular_values_[:r_show], "projection_error": pod.projection_error_},
        "roms": public_rows(rows), "time_step_ladder": dt_rows, "renders": renders,
        "peak_rss_gb_after_fom": rss_after_fom, "peak_rss_gb": peak_rss_gb(),
    }
    write_report(out_dir / "report.md", metrics, (out_dir / "energy.png").exists(), sections)
    metrics |= extra              # a case's own metrics; its keys win (the report above is the study's)
    write_metrics(out_dir / "metrics.json", metrics)
    (out_dir / "scene.toml").write_text(scene.source_text)
    return metrics


def write_report(path: Path, m: dict, energy_plot: bool = True, sections=()) -> Path:
    """``report.md``: what the pipeline cost, the ROM table, the FOM ladder, the figures, then ``sections``."""
    fom = m["fom"][m["train"][0]]
    cost = m["fom_cost"]
    lines = [
        f"# {m['scene']}: reduced models", "",
        f"{m['n_dofs']} free dofs, {m['n_inputs']} input(s), outputs {', '.join(m['output_names'])}; "
        f"effects {', '.join(m['effects'])}. FOM: {fom['n_steps']} steps of {fom['dt']:g} s with "
        f"{fom['scheme']} / {fom['solver']}.", "",
        "## What the pipeline cost", "",
        "| stage | cost |", "|---|---|",
        f"| build (mesh, assembly) | {m['build_seconds']:.2f} s |",
        f"| FOM runs ({', '.join(m['fom'])}) | {m['fom_seconds']:.2f} s |",
        f"| FOM step (fastest of {cost['blocks']} blocks of {cost['steps_per_block']:g} steps; median, upper "
        f"quartile) | {cost['minimum'] * 1e3:.3g} ms ({cost['median'] * 1e3:.3g}, {cost['q75'] * 1e3:.3g}) |",
        f"| snapshot store ({', '.join(m['snapshots']['fields'])}) | {m['snapshots']['bytes'] / 2**20:.1f} MiB |",
        f"| POD ({m['pod']['method']}, {m['pod']['product']} product) | {m['pod_seconds']:.2f} s |",
        f"| projection of every run (one pass each) | {m['projection_seconds']:.2f} s |",
        f"| fitting, testing and timing the ROMs | {m['rom_seconds']:.2f} s |",
        f"| peak resident memory | {m['peak_rss_gb']:.2f} GiB |", "",
        "## Reduced models", "",
        f"Trained on {', '.join(m['train'])}, tested on {', '.join(m['test'])} (errors of the first test run; "
        "every run's in metrics.json). Output error: relative Frobenius over all outputs and steps; field error: "
        f"relative, in the basis's ({m['pod']['product']}) norm; energy ratio: max reduced energy over "
        f"{m['extension']:g}x the test window / max FOM energy. Seconds per step: the fastest of the timed blocks "
        "(spread in metrics.json); speedup: FOM step over ROM step, both measured in this run.", "",
        accuracy_cost_table(m["roms"], ROW_COLUMNS), "",
        "![response](response.png)", "", "![errors](rom_error.png)", "",
    ]
    if energy_plot:
        lines += ["![energy](energy.png)", ""]
    lines += ["![accuracy vs cost](accuracy_cost.png)", ""]
    if m["time_step_ladder"]:
        rows = m["time_step_ladder"]
        lines += [ladder_table(rows, heading=f"FOM time step (output error against the run at dt = {rows[-1]['dt']:g})",
                               columns=TIME_STEP_COLUMNS), "", "![dt ladder](accuracy_cost_dt.png)", ""]
    r = m["renders"]
    if r.get("render"):
        lines += ["## Renders", "", f"backend: {r.get('render_backend')}", "", "![render](render.png)", ""]
    elif r.get("render_backend"):
        lines += ["## Renders", "", f"no render: {r['render_backend']}", ""]
    if r.get("paraview"):
        lines += [f"ParaView series: `{r['paraview']}` (FOM, ROM and their difference).", ""]
    lines += [text for section in sections for text in (section, "")]
    path.write_text("\n".join(lines))
    return path


def swapped_rows(state: StudyState, labels=None) -> list[dict]:
    """The study again with training and test runs swapped (the same FOM runs, read from the open
    store): a POD basis of the test runs, the learners of ``labels`` (default all) fitted on them and
    scored on every run; its rows (:func:`study_rows`, without the in-memory objects)."""
    c = state.config
    config = dataclasses.replace(c, train=c.test, test=c.train,
                                 learners=tuple(s for s in c.learners if labels is None or s.label in labels))
    train = tuple(s.name for s in config.train)
    pod = pod_basis(state.store, train, state.product, config)
    data, projections = reduce_runs(state.store, state.runs, train, pod.basis_, state.product,
                                    stored_derivatives=needs_stored_derivatives(config))
    rows, _ = study_rows(state.model.system, pod.basis_, state.product, data, projections, state.runs, config,
                         progress=state.progress)
    return public_rows(rows)
