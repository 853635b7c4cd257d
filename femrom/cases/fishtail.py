"""Soft-robotic fishtail: P2 FOM under chamber pressure, snapshots streamed to HDF5, L-OpInf vs Galerkin vs OpInf.

The tail of ``meshes/fishtail.geo`` (silicone, clamped at the head) is bent by
two chambers driven antagonistically by one pressure input (``fishtail.toml``;
``n_inputs=2`` drives each chamber by its own input). On the study layer
(:func:`femrom.study.run_study`) the case

1. builds the P2 FOM at a mesh level (``LEVELS``) and runs it under the sigmoid
   pressure of the scene file and under a pressure step, one factorisation for
   both; ``q``, ``q'``, ``q''`` stream into an HDF5 store;
2. builds a mass-orthonormal POD basis of the training run by the out-of-core
   randomized SVD reading the store, and projects every run once;
3. for several r fits the intrusive Galerkin ROM, L-OpInf and plain OpInf from
   the stored Newmark derivatives and from 4th-order finite differences (``_fd``);
4. tests every ROM on the other input (output error, mass-norm field error,
   reduced energy over 10 windows, per-step cost by interleaved repetition);
5. trains on the other input too (the reverse study), and measures the FOM's
   accuracy against its cost over the time step and the mesh size;
6. writes the study's report, plots, renders and ParaView series into its folder.

What is the fishtail's own: its mesh levels, its two pressure signals, the
reverse study and the mesh ladder (static tip deflection and first frequency).
Every level runs the same way, up to the papers' size (``--level large``, 7.6e5
dofs; ``benchmarks/fishtail_ladder.py`` runs the ladder).

Run ``python -m femrom run fishtail [--out DIR] [--quick] [--level small]``;
tests import :func:`run`.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from femrom.cases import case_parser
from femrom import FemromValueError
from femrom.post import accuracy_cost_table, plot_accuracy_cost, staged_output
from femrom.scene import BasisSpec, Derivatives, InputConfig, LearnerSpec, ReportSpec, RomConfig, RunSpec, \
    Scene, Signal, build
from femrom.solvers import make_solver
from femrom.study import ROW_COLUMNS, run_study, subsampled_rows, subsampled_section, swapped_rows

SCENE = Path(__file__).with_suffix(".toml")

#: mesh_size of fishtail.geo per level (P2 dofs with the fixed ones, gmsh 4.15: tiny 4.8e3,
#: small 2.1e4, medium 9.4e4, large about 7.7e5; tiny: tests; small: the default; medium and
#: large: benchmarks/fishtail_ladder.py; large matches the n = 779,232 of the MORwiki model,
#: Siebelts, Kater & Meurer 2018).
LEVELS = {"tiny": 0.03, "small": 0.006, "medium": 0.0028, "large": 0.00122}

STORED, FD4 = Derivatives("stored"), Derivatives("finite_differences", 4)
#: ROMs per r: the intrusive reference, and both learners from the run's stored Newmark
#: velocities and accelerations, or from 4th-order finite differences of the reduced
#: displacements ("_fd").
LEARNERS = {"galerkin": LearnerSpec("galerkin", "galerkin", STORED),
            "lopinf": LearnerSpec("lopinf", "lopinf", STORED), "opinf": LearnerSpec("opinf", "opinf", STORED),
            "lopinf_fd": LearnerSpec("lopinf_fd", "lopinf", FD4), "opinf_fd": LearnerSpec("opinf_fd", "opinf", FD4)}


# -- scenes -----------------------------------------------------------------------------
def with_level(scene: Scene, level: str | float) -> Scene:
    """The scene on the mesh of a level name (``LEVELS``) or an explicit mesh_size."""
    size = LEVELS[level] if isinstance(level, str) else float(level)
    params = dict(scene.structure.parameters) | {"mesh_size": size}
    return dataclasses.replace(scene, structure=dataclasses.replace(
        scene.structure, parameters=tuple(sorted(params.items()))))


def with_time(scene: Scene, *, dt: float | None = None, t_end: float | None = None) -> Scene:
    time_config = dataclasses.replace(scene.time, dt=scene.time.dt if dt is None else dt,
                                      t_end=scene.time.t_end if t_end is None else t_end)
    return dataclasses.replace(scene, time=time_config)


def pressure_signal(scene: Scene, kind: str) -> Signal:
    """The scene's sigmoid, or a step of the same amplitude near ``midpoint - 4 width``.

    The step sits half a time step off the grid, ``(round(s / dt) + 1/2) dt``: on a
    grid point, the FOM's accumulated clock (``t + dt + ...``) and a ROM's grid
    ``k dt`` can fall on opposite sides of the jump by rounding, which shifts one
    model's input by a whole step (measured: a 4 % output error that no basis removes).
    """
    sigmoid = scene.inputs[0].signal
    p = dict(sigmoid.parameters)
    if kind == "sigmoid":
        return sigmoid
    if kind == "step":
        dt = scene.time.dt
        start = (round(max(p["midpoint"] - 4 * p["width"], 0.0) / dt) + 0.5) * dt
        return Signal.from_dict({"kind": "step", "amplitude": p["amplitude"], "start": start})
    raise FemromValueError(f"unknown pressure signal {kind!r}; valid: sigmoid, step")


def pressure_signals(scene: Scene, kind: str) -> tuple[Signal, ...]:
    """``u(t)``: ``[p(t)]`` (antagonistic) or ``[p(t), -p(t)]`` (one input per chamber)."""
    p = pressure_signal(scene, kind)
    return (p, p.scaled(-1.0))[:len(scene.inputs)]


def with_inputs(scene: Scene, n_inputs: int) -> Scene:
    """One antagonistic input (the scene file), or two: ``u_1`` left chamber, ``u_2 = -u_1`` right,
    so that both models see the same loads; a ROM then learns a (r, 2) ``B^``."""
    if n_inputs == 1:
        return scene
    if n_inputs != 2:
        raise FemromValueError(f"the fishtail has 1 (antagonistic) or 2 (one per chamber) inputs, got {n_inputs}")
    first = scene.inputs[0]
    left, right = first.loads
    inputs = (InputConfig("pressure_left", dataclasses.replace(left, magnitude=1.0), first.signal),
              InputConfig("pressure_right", dataclasses.replace(right, magnitude=1.0), first.signal.scaled(-1.0)))
    return dataclasses.replace(scene, inputs=inputs)


def load_scene(level="small", *, n_inputs: int = 1, quick: bool = False, scene_path=SCENE) -> Scene:
    scene = with_inputs(with_level(Scene.from_toml(scene_path), level), n_inputs)
    return with_time(scene, t_end=0.5 * scene.time.t_end) if quick else scene


def rom_config(scene: Scene, train: str, ranks, learners, *, extension: float, render: bool,
               dt_factors=(), keep_snapshots: bool = False, power_iterations: int = 2) -> RomConfig:
    """The study: train on one pressure signal, test on the other."""
    test = "step" if train == "sigmoid" else "sigmoid"
    report = ReportSpec(render=render, paraview=True, time_step_factors=tuple(dt_factors),
                        keep_snapshots=keep_snapshots)
    return RomConfig(train=(RunSpec(train, pressure_signals(scene, train)),),
                     test=(RunSpec(test, pressure_signals(scene, test)),),
                     learners=tuple(LEARNERS[x] for x in learners),
                     basis=BasisSpec(tuple(ranks), power_iterations=power_iterations),
                     extension=extension, report=report)


# -- what only the fishtail does -----------------------------------------------------------
def mesh_ladder(scene: Scene, levels) -> list[dict]:
    """Static tip deflection under a unit pressure and the first frequency per mesh size,
    errors against the finest level of the ladder, with build + solve time."""
    from scipy.sparse.linalg import eigsh

    rows = []
    for level in levels:
        tic = time.perf_counter()
        model = build(with_level(scene, level))
        s = model.system
        tip = s.output_matrix @ make_solver(s.stiffness, strategy=scene.time.solver).solve(
            np.asarray(s.input_matrix[:, 0]).ravel())
        seconds_static = time.perf_counter() - tic
        f1 = float(np.sqrt(eigsh(s.stiffness.tocsc(), k=1, M=s.mass.tocsc(), sigma=0.0,
                                 which="LM")[0][0]) / (2 * np.pi))
        rows.append({"mesh_size": LEVELS.get(level, level) if isinstance(level, str) else level,
                     "level": str(level), "dofs": s.n_dofs, "tip_y_per_pa": float(tip[1]), "f1_hz": f1,
                     "seconds": seconds_static})
    finest = rows[-1]
    for row in rows:
        row["tip_error"] = abs(row["tip_y_per_pa"] / finest["tip_y_per_pa"] - 1)
        row["f1_error"] = abs(row["f1_hz"] / finest["f1_hz"] - 1)
    return rows


# -- the case ---------------------------------------------------------------------------------
def run(out_dir, *, quick: bool = False, level: str = "small", train: str = "sigmoid",
        n_inputs: int = 1, ranks=None, extension: float = 10.0, ladders: bool = True,
        render: bool = True, t_end: float | None = None, reverse: bool = True, learners=tuple(LEARNERS),
        keep_snapshots: bool = False, store_path=None, svd_power_iterations: int = 2, scene_path=SCENE) -> dict:
    """Run the case; return its metrics (also written to ``out_dir/metrics.json``).

    ``quick`` halves the window and shortens the ladders; ``t_end`` overrides
    the window; ``ladders`` / ``render`` / ``reverse`` switch the FOM cost
    ladders, the renders and the reverse study off; ``store_path`` puts the
    snapshot store elsewhere than ``out_dir/snapshots.h5``, ``keep_snapshots`` keeps it.
    """
    out_dir = Path(out_dir)
    scene = load_scene(level, n_inputs=n_inputs, quick=quick, scene_path=scene_path)
    if t_end is not None:
        scene = with_time(scene, t_end=t_end)
    if train not in ("sigmoid", "step"):
        raise FemromValueError(f"unknown training input {train!r}; valid: sigmoid, step")
    learners = tuple(learners)
    if any(x not in LEARNERS for x in learners) or "lopinf" not in learners:
        raise FemromValueError(f"learners must include 'lopinf' and be among {', '.join(LEARNERS)}; got {learners}")
    ranks = tuple(ranks or ((2, 4, 6, 8) if quick else (2, 4, 6, 8, 12)))
    dt_factors = ((5, 2) if quick else (10, 5, 2)) if ladders else ()
    scene = dataclasses.replace(scene, rom=rom_config(scene, train, ranks, learners, extension=extension,
                                                      render=render, dt_factors=dt_factors,
                                                      keep_snapshots=keep_snapshots,
                                                      power_iterations=svd_power_iterations))

    def extend(state):
        metrics = {"case": "fishtail", "level": level, "quick": quick,
                   "mesh_size": dict(scene.structure.parameters)["mesh_size"],
                   "roms_reverse": swapped_rows(state, [x for x in ("galerkin", "lopinf", "opinf")
                                                         if x in learners]) if reverse else []}
        state.progress("learning from snapshots every k-th step")
        metrics["subsampled"] = subsampled_rows(state, (1, 2, 5, 10))
        sections = [subsampled_section(metrics["subsampled"], train, state.config.test[0].name)]
        if metrics["roms_reverse"]:
            sections.append(f"## The reverse: trained on the {state.config.test[0].name} input, tested on the "
                            f"{train} input\n\n" + accuracy_cost_table(metrics["roms_reverse"], ROW_COLUMNS))
        metrics["mesh_ladder"] = []
        if ladders:
            state.progress("mesh ladder")
            levels = [0.04, 0.03, 0.02] if quick else [0.02, 0.012, 0.009, LEVELS[level]]
            rows = metrics["mesh_ladder"] = mesh_ladder(scene, levels)
            plot_accuracy_cost(out_dir / "accuracy_cost_mesh.png", rows[:-1], "seconds", "tip_error", "dofs",
                               title="FOM mesh: static tip deflection error vs build + solve time")
            sections.append("## FOM mesh (static tip deflection and f1, vs the finest level listed)\n\n"
                            + accuracy_cost_table(rows, ["mesh_size", "dofs", "tip_y_per_pa", "tip_error",
                                                         "f1_hz", "f1_error", "seconds"])
                            + "\n\n![mesh ladder](accuracy_cost_mesh.png)")
        return metrics, sections

    return run_study(scene, out_dir, store_path=store_path, extend=extend,
                     progress=lambda message: print(f"fishtail: {message}", file=sys.stderr))


def main(argv=None) -> int:
    parser = case_parser("fishtail", __doc__, quick="short window, coarse mesh ladder (tests)")
    parser.add_argument("--level", default="small", choices=tuple(LEVELS),
                        help="mesh level: tiny 4.8e3, small 2e4 (default), medium 9e4, large 7.6e5 dofs")
    parser.add_argument("--train", default="sigmoid", choices=("sigmoid", "step"))
    parser.add_argument("--inputs", type=int, default=1, choices=(1, 2),
                        help="1: antagonistic chambers (default); 2: one input per chamber")
    parser.add_argument("--ranks", type=int, nargs="+", help="basis sizes r (default 2 4 6 8 12)")
    parser.add_argument("--ladders", action=argparse.BooleanOptionalAction, default=None,
                        help="FOM time-step and mesh ladders (default: on for tiny and small)")
    parser.add_argument("--reverse", action=argparse.BooleanOptionalAction, default=True,
                        help="also train on the other input and test on the first")
    parser.add_argument("--keep-snapshots", action="store_true", help="keep snapshots.h5 (q, q', q'')")
    parser.add_argument("--store", type=Path, help="where the snapshot store goes (default OUT/snapshots.h5)")
    args = parser.parse_args(argv)
    ladders = args.level in ("tiny", "small") if args.ladders is None else args.ladders
    with staged_output(args.out) as out:    # the results appear whole, or the old ones stay
        metrics = run(out, quick=args.quick, level=args.level, train=args.train, n_inputs=args.inputs,
                      ranks=args.ranks, ladders=ladders, reverse=args.reverse, keep_snapshots=args.keep_snapshots,
                      store_path=args.store)
    r = max(metrics["ranks"])
    row = next(x for x in metrics["roms"] if x["r"] == r and x["learner"] == "lopinf")
    print(f"fishtail ({args.level}): {metrics['n_dofs']} dofs, FOM {metrics['fom_seconds_per_step'] * 1e3:.1f} "
          f"ms/step; L-OpInf r={r} on the unseen {metrics['test'][0]} input: output error "
          f"{row['test_output_error']:.2e}, field error {row['test_field_error']:.2e}, speedup {row['speedup']:.0f}x")
    print(f"report: {args.out / 'report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
