"""``femrom`` command line: run a scene file or a named case, list the cases.

    femrom cases                      list the named cases (the modules of femrom.cases)
    femrom --debug COMMAND ...        errors with their traceback (otherwise one line, exit 2)
    femrom run beam [case options]    run a named case (femrom/cases/beam.py); every case takes
                                      -o/--out, --quick, --yes and --debug, and lists its own
                                      options with --help
    femrom run my_scene.toml -o out/  run any scene file: outputs, energy, plot; with a
                                      [rom] section the whole reduced-model study and report
    femrom info my_scene.toml         build the scene and print its sizes and effects
    femrom sweep my_scene.toml -o out/ [--scheduler tcp://host:port] [--workers 2]
                                      the scene's [sweep] runs as Dask tasks, into out/sweep.h5
    femrom ingest series.pvd -o store.h5 [--inputs u.csv] [--density RHO] [--output NAME:X,Y,Z:C]
                                      another solver's displacement series into a snapshot store
    femrom data fetch brb             download public test data (pinned, SHA-256 checked) into the
                                      cache and print the folder; `data path NAME` prints the folder
                                      femrom reads, `data list` the data sets
"""

from __future__ import annotations

import argparse
import ast
import importlib
import importlib.util
import os
import pkgutil
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from femrom._errors import FemromError, FemromValueError


#: The package of the named cases: one module per case, its scene file beside it.
CASES_PACKAGE = "femrom.cases"


class CaseError(FemromValueError):
    """A case name that is not one of :func:`available_cases`."""


def available_cases() -> dict[str, str]:
    """Case name -> the first line of its module docstring, for every module of ``femrom.cases``
    (``pkgutil.iter_modules``; a name starting with ``_`` is not a case), in name order.

    The docstrings are read from the sources: listing runs no case."""
    package = importlib.import_module(CASES_PACKAGE)
    found = {}
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("_") or info.ispkg:
            continue
        found[info.name] = _first_doc_line(f"{CASES_PACKAGE}.{info.name}")
    return found


def _first_doc_line(module: str) -> str:
    spec = importlib.util.find_spec(module)
    if spec is None or not spec.origin or not spec.origin.endswith(".py"):
        return ""
    doc = ast.get_docstring(ast.parse(Path(spec.origin).read_text()))
    return doc.splitlines()[0].strip() if doc else ""


def load_case(name: str):
    """The case module ``femrom.cases.<name>`` (imported, not run).

    Raises
    ------
    CaseError
        ``name`` is not a case; the message lists the valid ones.
    """
    cases = available_cases()
    if name not in cases:
        raise CaseError(f"unknown case {name!r}; available: {', '.join(cases) or '(none)'}")
    return importlib.import_module(f"{CASES_PACKAGE}.{name}")


#: Steps and in-memory fields above which ``femrom run`` asks for ``--yes``.
CONFIRM_STEPS = 10_000_000


def memory_bound_bytes() -> int:
    """Half the machine's memory, or ``FEMROM_MEMORY_LIMIT_GB``: what a run may hold in fields."""
    text = os.environ.get("FEMROM_MEMORY_LIMIT_GB")
    if text:
        try:
            value = float(text)
        except ValueError:
            raise FemromValueError(f"FEMROM_MEMORY_LIMIT_GB must be a number of GB, got {text!r}") from None
        if not value > 0:
            raise FemromValueError(f"FEMROM_MEMORY_LIMIT_GB must be positive, got {text!r}")
        return int(value * 1e9)
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2)
    except (ValueError, OSError, AttributeError):
        return 8 * 10**9


def check_run_size(scene, n_dofs: int, *, confirmed: bool) -> None:
    """Refuse, unless ``confirmed``, a run of over :data:`CONFIRM_STEPS` steps or whose kept fields
    exceed :func:`memory_bound_bytes` (``n_dofs x snapshots x fields x 8`` bytes)."""
    from femrom.scene import SceneError

    if confirmed:
        return
    steps = scene.time.n_steps
    if steps > CONFIRM_STEPS:
        raise SceneError(f"{scene.name}: {steps:.3g} steps ([time] t_end / dt) is more than {CONFIRM_STEPS:.0e}; "
                         f"pass --yes to run it anyway")
    snapshots = steps // scene.outputs.save_every + 1
    need = 8 * n_dofs * snapshots * len(scene.outputs.fields)
    bound = memory_bound_bytes()
    if need > bound:
        raise SceneError(f"{scene.name}: [outputs] fields would hold {need / 1e9:.3g} GB in memory ({n_dofs} dofs x "
                         f"{snapshots} snapshots x {len(scene.outputs.fields)} fields), more than {bound / 1e9:.3g} GB; "
                         f"keep fewer fields, raise save_every, or pass --yes")


def run_scene_file(path: Path, out_dir: Path, *, confirmed: bool = False) -> dict:
    """Build and integrate a scene; write outputs.npz, metrics.json and response.png
    (with a ``[rom]`` section: :func:`femrom.study.run_study`, the whole report).

    The results go to a staging folder beside ``out_dir`` that replaces it only when
    the run completes (:func:`femrom.post.staged_output`): a failed run leaves the
    previous results, and a second run into the same folder at once is refused.
    """
    from femrom.post import OutputFolderError, staged_output

    try:
        with staged_output(out_dir) as staging:
            metrics = _run_scene_file(path, staging, confirmed=confirmed)
    except OSError as exc:
        if exc.filename is not None and not str(exc.filename).startswith(str(out_dir.parent / f".{out_dir.name}.")):
            raise   # about a file of its own (an input, the mesh cache): its message names it
        reason = exc.strerror or str(exc)
        raise OutputFolderError(f"{out_dir}: {reason} while writing the results; nothing was changed there") from None
    return metrics


def _run_scene_file(path: Path, out_dir: Path, *, confirmed: bool = False) -> dict:
    from femrom.integrators import scheme_for, simulate
    from femrom.post import plot_response, write_metrics
    from femrom.scene import Scene, SceneError, build

    scene = Scene.from_toml(path)
    try:   # the scheme and the learners are checked here, before the mesh and the assembly
        scheme_for(scene.time)
    except ValueError as exc:
        raise SceneError(f"{path}: {exc}") from None
    if scene.rom is not None:
        from femrom.study import check_rom_config, run_study

        try:
            check_rom_config(scene.rom)
        except SceneError as exc:
            raise SceneError(f"{path}: {exc}") from None
        return run_study(scene, out_dir, progress=lambda message: print(f"femrom: {message}", file=sys.stderr))
    if scene.time.n_steps > CONFIRM_STEPS:   # known before the build
        check_run_size(scene, 0, confirmed=confirmed)
    tic = time.perf_counter()
    model = build(scene)
    build_seconds = time.perf_counter() - tic
    check_run_size(scene, model.system.n_dofs, confirmed=confirmed)
    result = simulate(model)
    out_dir.mkdir(parents=True, exist_ok=True)
    arrays = {"t": result.times}
    if result.outputs is not None:
        arrays["y"] = result.outputs
    if result.energy is not None:
        arrays["energy"] = result.energy
    np.savez(out_dir / "outputs.npz", **arrays)
    (out_dir / "scene.toml").write_text(scene.source_text)
    metrics = {"scene": scene.name, "n_dofs": model.system.n_dofs, "effects": scene.effect_names,
               "build_seconds": build_seconds, "build_timings": model.timings, **result.summary}
    write_metrics(out_dir / "metrics.json", metrics)
    plot_response(out_dir / "response.png", result.times, result.outputs, model.system.output_names,
                  result.energy, title=scene.name)
    return metrics


def _sweep(args) -> int:
    from femrom.scene import Scene, SceneError
    from femrom.study import run_sweep

    try:
        scene = Scene.from_toml(args.scene)
        if scene.sweep is None:
            raise SceneError(f"{args.scene}: no [sweep] section (docs/scenes.md)")
    except SceneError as exc:
        print(f"femrom: {exc}", file=sys.stderr)
        return 2
    if args.workers < 1:
        print(f"femrom: --workers must be >= 1, got {args.workers}", file=sys.stderr)
        return 2
    out = args.out or Path("results") / f"{args.scene.stem}_sweep"
    try:
        summary = run_sweep(scene, out, scheduler=args.scheduler, n_workers=args.workers,
                            keep_parts=args.keep_parts,
                            progress=lambda message: print(f"femrom: {message}", file=sys.stderr))
    except (OSError, TimeoutError) as exc:     # no scheduler at that address, or it went away
        where = args.scheduler or "the LocalCluster"
        print(f"femrom: Dask scheduler {where}: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 2
    print(f"{summary['scene']}: {summary['n_runs']} runs in {summary['wall_seconds']:.1f} s on "
          f"{summary['scheduler']}; store {out / 'sweep.h5'}")
    return 0


def _probe(text: str) -> tuple[str, tuple[float, float, float], str]:
    """``NAME:X,Y,Z:COMPONENT`` of ``--output``."""
    try:
        name, point, component = text.split(":")
        x, y, z = (float(v) for v in point.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--output {text!r}: expected NAME:X,Y,Z:COMPONENT, e.g. tip:0.1,0,0.2:z") \
            from None
    return name, (x, y, z), component


def _ingest(args) -> int:
    """``femrom ingest SERIES -o STORE``: another solver's displacement series into a snapshot store."""
    from femrom.snapshots import IngestError, SnapshotStoreError, ingest, ingested_model, read_series

    say = (lambda message: print(f"femrom: {message}", file=sys.stderr))
    fixed = None if args.fixed == "none" else ("auto" if args.fixed == "auto" else args.fixed.split(","))
    out = args.out or args.series.with_suffix(".h5")
    try:
        series = read_series(args.series, field=args.field, mesh=args.mesh)
        model = ingested_model(series, density=args.density, lumped=args.lumped, fixed=fixed, inputs=args.inputs,
                               outputs=args.output, length_scale=args.length_scale, progress=say)
        ingest(series, model, out, every=args.every, overwrite=args.overwrite, length_scale=args.length_scale,
               progress=say)
    except (IngestError, SnapshotStoreError, FileNotFoundError) as exc:
        print(f"femrom: {exc}", file=sys.stderr)
        return 2
    s = model.system
    steps = series.times[::args.every]
    print(f"{args.series}: {steps.size} snapshots of {s.n_dofs} free dofs ({model.fixed.size} fixed, "
          f"{model.detail['fixed']}), t in [{steps[0]:g}, {steps[-1]:g}], {s.n_inputs} input(s), "
          f"{s.n_outputs} output(s); store {out}")
    return 0


def _data(args) -> int:
    """``femrom data list | fetch NAME | path NAME``: the public test data femrom fetches and caches."""
    from femrom.post import DATASETS, dataset, dataset_dir, fetch_dataset

    if args.data_command == "list":
        for name, data in DATASETS.items():
            print(f"{name}  {data.title}: {', '.join(data.files)} ({data.source}); offline copy: ${data.environment}")
        return 0
    data = dataset(args.name)
    if args.data_command == "path":
        print(dataset_dir(args.name))
        return 0
    folder = fetch_dataset(args.name, progress=lambda message: print(f"femrom: {message}", file=sys.stderr))
    print(f"{data.name}: {', '.join(data.files)} ({data.source}; SHA-256 checked) and "
          f"{', '.join(data.derived)} in {folder}")
    if os.environ.get(data.environment):
        print(f"femrom: note: {data.environment} is set, so femrom reads {os.environ[data.environment]} instead",
              file=sys.stderr)
    return 0


def _study_line(metrics: dict) -> str:
    """One line of a study's result: the first learned model's error at the largest r."""
    r = max(metrics["ranks"])
    rows = [x for x in metrics["roms"] if x["r"] == r]
    row = next((x for x in rows if x["method"] != "galerkin"), rows[0])
    return (f"{metrics['scene']}: {metrics['n_dofs']} dofs; {row['learner']} r={r} on the unseen "
            f"{metrics['test'][0]}: output error {row['test_output_error']:.2e}, "
            f"speedup {row['speedup']:.3g}x")


def _user_errors() -> tuple[type[BaseException], ...]:
    """The failures a user's input causes: reported in one line, exit 2 (``--debug``: the traceback)."""
    from femrom.mesh import MeshError
    from femrom.scene import SceneError
    from femrom.snapshots import IngestError, SnapshotStoreError

    # FemromError: every error femrom raises for a user (a Newton failure, a diverged run included);
    # OSError: a full disk, a folder without write permission, a missing file (its message names it)
    return FemromError, SceneError, IngestError, SnapshotStoreError, MeshError, CaseError, OSError, ValueError


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv          # anywhere: femrom --debug run beam, femrom run beam --debug
    argv = [arg for arg in argv if arg != "--debug"]
    shown = warnings.showwarning
    warnings.showwarning = _one_line_warning
    try:
        return _main(argv)
    except _user_errors() as exc:
        if debug:
            raise
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"femrom: {message}", file=sys.stderr)
        return 2
    finally:
        warnings.showwarning = shown


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning on the command line: ``femrom: warning: ...``, one line, no source excerpt."""
    text = str(message).splitlines()[0] if str(message) else category.__name__
    print(f"femrom: warning: {text}", file=sys.stderr if file is None else file)


def _main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="femrom", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("cases", help="list the named cases")
    run = sub.add_parser("run", help="run a named case or a scene file", add_help=False)
    run.add_argument("target", nargs="?")
    info = sub.add_parser("info", help="build a scene and print its size and effects")
    info.add_argument("scene", type=Path)
    sweep = sub.add_parser("sweep", help="run a scene's [sweep] as Dask tasks into one snapshot store")
    sweep.add_argument("scene", type=Path)
    sweep.add_argument("-o", "--out", type=Path, help="output folder (default results/<scene>_sweep)")
    sweep.add_argument("--scheduler", help="address of a running Dask scheduler (default: a LocalCluster)")
    sweep.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes (default 2)")
    sweep.add_argument("--keep-parts", action="store_true", help="keep the per-run store files")
    ing = sub.add_parser("ingest", help="stream another solver's displacement series into a snapshot store")
    ing.add_argument("series", type=Path, help=".pvd (+ .vtu), .xdmf, or an .h5/.npz array (K, n_points, 3)")
    ing.add_argument("-o", "--out", type=Path, help="the store (default: the series' name with .h5)")
    ing.add_argument("--mesh", type=Path, help="the mesh file of an array series (any format meshio reads)")
    ing.add_argument("--field", help="point-data name of the displacements (default: the only vector field)")
    ing.add_argument("--density", type=float, default=1.0, help="for the mass matrix (default 1)")
    ing.add_argument("--lumped", action="store_true", help="lumped (diagonal) mass instead of consistent")
    ing.add_argument("--fixed", default="auto",
                     help="Dirichlet dofs: auto (zero throughout), none, or boundary names NAME[,NAME]")
    ing.add_argument("--inputs", type=Path, help="input table: CSV with a 't' column, or .npz with t, u")
    ing.add_argument("--output", action="append", type=_probe, default=[],
                     help="a displacement probe NAME:X,Y,Z:COMPONENT (repeatable)")
    ing.add_argument("--every", type=int, default=1, help="keep every k-th step of the series")
    ing.add_argument("--length-scale", type=float, default=1.0,
                     help="multiplies the displacements (1e-3: a series in mm on a mesh in m)")
    ing.add_argument("--overwrite", action="store_true", help="replace an existing store")
    data = sub.add_parser("data", help="public test data: fetch (pinned, checked) into the cache, or show where")
    data_sub = data.add_subparsers(dest="data_command", required=True)
    data_sub.add_parser("list", help="the data sets femrom can fetch")
    data_fetch = data_sub.add_parser("fetch", help="download a data set into the cache and print the folder")
    data_fetch.add_argument("name", help="the data set (femrom data list)")
    data_path = data_sub.add_parser("path", help="print the folder femrom reads a data set from")
    data_path.add_argument("name", help="the data set (femrom data list)")

    if argv[:1] == ["run"]:
        args, rest = parser.parse_known_args(argv)
    else:
        args, rest = parser.parse_args(argv), []

    if args.command == "cases":
        cases = available_cases()
        width = max(map(len, cases), default=0)
        for name, doc in cases.items():
            print(f"{name:{width}s}  {doc}")
        return 0
    if args.command == "info":
        from femrom.scene import Scene, build

        model = build(Scene.from_toml(args.scene))
        s = model.system
        print(f"{model.scene.name}: {s.n_dofs} free dofs of {s.condensation.n_total}, "
              f"effects {', '.join(model.scene.effect_names)}; inputs {s.n_inputs}, outputs {s.n_outputs}")
        return 0
    if args.command == "sweep":
        return _sweep(args)
    if args.command == "ingest":
        return _ingest(args)
    if args.command == "data":
        return _data(args)
    # run
    if args.target is None or args.target in ("-h", "--help"):
        print("usage: femrom run CASE [case options] | femrom run SCENE.toml [-o OUT]")
        print("cases: " + ", ".join(available_cases()))
        return 0 if args.target else 2
    target = Path(args.target)
    # a scene path: anything but a case's name that ends in .toml, names a file or folder, or has a
    # separator (a case's name wins over a folder it left in the working directory: ./NAME is the folder)
    if args.target not in available_cases() and (
            target.suffix.lower() == ".toml" or target.exists() or "/" in args.target or os.sep in args.target):
        opts = argparse.ArgumentParser(prog="femrom run SCENE.toml")
        opts.add_argument("-o", "--out", type=Path, default=Path("results") / target.stem)
        opts.add_argument("--yes", action="store_true",
                          help=f"run even above {CONFIRM_STEPS:.0e} steps or half the memory in kept fields, "
                               "or with a step the conditioning check flags")
        o = opts.parse_args(rest)
        from femrom.integrators import ConditioningWarning
        from femrom.scene import SceneError

        try:
            with warnings.catch_warnings():
                if not o.yes:   # a step that resolves nothing of the model is refused, not just said
                    warnings.simplefilter("error", ConditioningWarning)
                metrics = run_scene_file(target, o.out, confirmed=o.yes)
        except SceneError as exc:
            print(f"femrom: {exc}", file=sys.stderr)
            return 2
        except ConditioningWarning as exc:
            print(f"femrom: {target}: {exc}; pass --yes to run it anyway", file=sys.stderr)
            return 2
        if "roms" in metrics:
            print(_study_line(metrics) + f"; report in {o.out / 'report.md'}")
        else:
            print(f"{metrics['scene']}: {metrics['n_dofs']} dofs, {metrics['n_steps']} steps in "
                  f"{metrics['stepping_seconds']:.2f} s; results in {o.out}")
        return 0
    module = load_case(args.target)
    from femrom.integrators import ConditioningWarning

    try:
        with warnings.catch_warnings():
            if "--yes" not in rest:     # as for a scene file: a flagged step is refused, not just said
                warnings.simplefilter("error", ConditioningWarning)
            return int(module.main(rest) or 0)
    except ConditioningWarning as exc:
        print(f"femrom: {args.target}: {exc}; pass --yes to run it anyway", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
