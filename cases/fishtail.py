"""Soft-robotic fishtail: P2 FOM under chamber pressure, snapshots streamed to HDF5, L-OpInf vs Galerkin vs OpInf.

The tail of ``meshes/fishtail.geo`` (silicone, clamped at the head) is bent by
two chambers driven antagonistically by one pressure input (``fishtail.toml``;
``n_inputs=2`` drives each chamber by its own input). The case

1. builds the P2 FOM at a mesh level (``LEVELS``) and runs it twice, under the
   sigmoid pressure of the scene file and under a pressure step, factorising
   the effective matrix once for both runs (:class:`femrom.solvers.SolverCache`;
   the mass solve of the initial acceleration by Jacobi-CG, no second factor);
   ``q``, ``q'``, ``q''`` stream into an HDF5 snapshot store and are never
   held in memory;
2. builds a mass-orthonormal POD basis of the training run's displacements by
   the out-of-core randomized SVD reading the store (``train="sigmoid"`` or
   ``"step"``); projects each run once onto the largest basis (one pass over
   the store) and takes the smaller r by truncation (the basis is nested);
3. for several r fits the intrusive Galerkin ROM, L-OpInf (``K^ = K^^T > 0``,
   ``C^ = C^^T >= 0``) and plain OpInf, from the run's stored Newmark ``q'``,
   ``q''`` or from finite differences of the reduced displacements (the
   learners see only reduced snapshots, inputs and outputs, never the FOM
   matrices);
4. tests every ROM on the other input: output error (tip x, y, z), full-field
   error in the mass norm (from the reduced coordinates: ``V^T M V = I`` makes
   it exact without another pass over the snapshots), reduced energy over an
   extended window, time per step and speedup over the FOM;
5. measures the FOM's cost and accuracy over the time step and the mesh size;
6. writes into its folder: ``metrics.json``, ``report.md``, ``response.png``
   (FOM and ROM tip outputs), ``rom_error.png``, ``energy.png``, the
   accuracy-vs-cost plots, ``render.png`` (deformed tail coloured by ``|u|``,
   FOM above, L-OpInf below, at several times), ``paraview/fishtail.pvd`` and,
   with ``keep_snapshots``, ``snapshots.h5``.

Every level runs the same way, up to the papers' size (``--level large``,
7.6e5 dofs: about 12.4 GB of memory, mostly the factor, and 0.9 GB of snapshots
per field, run and 150 steps on disk; ``benchmarks/fishtail_ladder.py`` runs the ladder).

Run ``python -m femrom run fishtail [--out DIR] [--quick] [--level small]``;
tests import :func:`run`.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from femrom.basis import POD
from femrom.inference import LagrangianOpInf, SecondOrderOpInf, project_columns, reduce_snapshots
from femrom.integrators import simulate
from femrom.linalg import store_source
from femrom.post import (
    accuracy_cost_table,
    machine_description,
    mesh_arrays,
    plot_accuracy_cost,
    pyplot,
    render_available,
    render_grid,
    save_figure,
    vertex_displacements,
    write_metrics,
    write_vtu_series,
)
from femrom.rom import SecondOrderROM
from femrom.scene import InputConfig, Scene, Signal, build
from femrom.snapshots import SnapshotStore
from femrom.solvers import SolverCache, make_solver

SCENE = Path(__file__).with_suffix(".toml")

#: mesh_size of fishtail.geo per level (P2 dofs with the fixed ones, gmsh 4.15: tiny 4.8e3,
#: small 2.1e4, medium 9.4e4, large about 7.7e5; tiny: tests; small: the default; medium and
#: large: benchmarks/fishtail_ladder.py; large matches the n = 779,232 of the MORwiki model,
#: Siebelts, Kater & Meurer 2018).
LEVELS = {"tiny": 0.03, "small": 0.006, "medium": 0.0028, "large": 0.00122}

#: ROMs per r: the intrusive reference, and both learners from the run's stored
#: Newmark velocities and accelerations ("stored") or from 4th-order finite
#: differences of the reduced displacements ("_fd").
LEARNERS = ("galerkin", "lopinf", "opinf", "lopinf_fd", "opinf_fd")
LABELS = {"galerkin": "Galerkin (intrusive)", "lopinf": "L-OpInf", "opinf": "OpInf",
          "lopinf_fd": "L-OpInf (FD)", "opinf_fd": "OpInf (FD)"}


# -- scenes ---------------------------------------------------------------------
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
    raise ValueError(f"unknown pressure signal {kind!r}; valid: sigmoid, step")


def with_inputs(scene: Scene, n_inputs: int) -> Scene:
    """One antagonistic input (the scene file), or two: ``u_1`` left chamber, ``u_2`` right.

    With two inputs the antagonistic drive is ``u_2 = -u_1`` (see :func:`signals`),
    so both models see the same loads; a ROM then learns a (r, 2) ``B^``.
    """
    if n_inputs == 1:
        return scene
    if n_inputs != 2:
        raise ValueError(f"the fishtail has 1 (antagonistic) or 2 (one per chamber) inputs, got {n_inputs}")
    first = scene.inputs[0]
    left, right = first.loads
    inputs = (InputConfig("pressure_left", dataclasses.replace(left, magnitude=1.0), first.signal),
              InputConfig("pressure_right", dataclasses.replace(right, magnitude=1.0), first.signal))
    return dataclasses.replace(scene, inputs=inputs)


class PressureInputs:
    """``u(t)``: ``[p(t)]`` (antagonistic) or ``[p(t), -p(t)]`` (one input per chamber)."""

    def __init__(self, signal: Signal, n_inputs: int):
        self.signal, self.signs = signal, np.array([1.0, -1.0][:n_inputs])

    def __call__(self, t):
        return self.signs * float(self.signal(t))

    def sampled(self, times) -> np.ndarray:
        """(m, k) ndarray of ``u`` on ``times``."""
        return self.signs[:, None] * np.asarray(self.signal(np.asarray(times)), dtype=float)[None, :]


def load_scene(level="small", *, n_inputs: int = 1, quick: bool = False, scene_path=SCENE) -> Scene:
    scene = with_inputs(with_level(Scene.from_toml(scene_path), level), n_inputs)
    if quick:
        scene = with_time(scene, t_end=0.5 * scene.time.t_end)
    return scene


# -- full-order runs ----------------------------------------------------------------
def solver_factory(model):
    """The integrators' solver factory for a case: one cached setup of the effective matrix,
    shared by every run with the same ``dt``, and Jacobi-CG for the mass.

    The consistent mass is solved once per run (the initial acceleration); Jacobi-CG
    does it in a few dozen iterations at any mesh size (Wathen 1987) without a second
    direct factor next to the effective matrix's (at 7.6e5 dofs each is GBs).
    ``factory.cache.clear()`` frees the factor.
    """
    cache = SolverCache(model.scene.time.solver)
    mass = model.system.mass

    def factory(A, spd=True):
        if A is mass:
            return make_solver(A, "jacobi-cg", rtol=1e-12)
        return cache(A, spd=spd)

    factory.cache = cache
    return factory


def run_fom(model, signal: Signal, *, dt=None, store: SnapshotStore | None = None, name: str | None = None,
            solver=None, consumers=()) -> dict:
    """Integrate the FOM under one pressure signal; fields ``q, v, a`` stream into ``store``.

    Returns the times, outputs, energy, inputs (callable and sampled ``U``) and the
    run's summary; full fields only in the store (trajectory ``name``).
    """
    u = PressureInputs(signal, model.system.n_inputs)
    system = dataclasses.replace(model.system, inputs=u)
    outputs = dataclasses.replace(model.scene.outputs, fields=())
    model = dataclasses.replace(model, system=system, scene=dataclasses.replace(model.scene, outputs=outputs))
    writers = [] if store is None else [store.writer(name)]  # closed by the driver at the end
    result = simulate(model, dt=dt, consumers=(*writers, *consumers), progress=None, solver=solver)
    return {"times": result.times, "outputs": result.outputs, "energy": result.energy,
            "inputs": u, "U": u.sampled(result.times), "summary": result.summary, "trajectory": name}


def store_blocks(store: SnapshotStore, field: str, trajectory: str):
    """A block source of one trajectory's field: about 128 MB column blocks of whole chunks."""
    return store_source(store, field, [trajectory])


# -- reduced models --------------------------------------------------------------------
def mass_norm(M, X) -> float:
    """Frobenius norm of ``X`` (n, k) in the mass product: ``sqrt(trace(X^T M X))``."""
    return float(np.sqrt(max(np.sum(X * (M @ X)), 0.0)))


def relative_error(reference: np.ndarray, approximation: np.ndarray) -> float:
    """``||approximation - reference||_F / ||reference||_F``."""
    return float(np.linalg.norm(approximation - reference) / np.linalg.norm(reference))


def pod_basis(store: SnapshotStore, trajectory: str, M, rank: int, *, power_iterations: int = 2) -> POD:
    """Mass-orthonormal POD of one run's displacements by the randomized SVD reading the store
    (``power_iterations + 2`` passes; with 2, the top singular values of these fast-decaying
    spectra are exact to ~1e-11, docs/benchmarks_snapshots.md)."""
    return POD(rank=rank, product=M, method="randomized", power_iterations=power_iterations).fit(
        store_blocks(store, "q", trajectory))


def project_runs(store: SnapshotStore, runs: dict, train: str, basis: np.ndarray, M, dt: float):
    """One pass per run and field over the store: the training data in the largest basis
    (stored Newmark derivatives), and every run's reduced displacements with the exact
    mass-norm residual of the largest basis and the run's norm (for field errors)."""
    train_run = runs[train]
    data = reduce_snapshots(basis, store_blocks(store, "q", train), dt, product=M,
                            velocities=store_blocks(store, "v", train),
                            accelerations=store_blocks(store, "a", train), derivatives="stored",
                            inputs=train_run["U"], outputs=train_run["outputs"])
    projections = {train: (data.states, data.diagnostics["projection_residual"], data.diagnostics["state_norm"])}
    for key in runs:
        if key != train:
            projections[key] = project_columns(basis, store_blocks(store, "q", key), M)
    return data, projections


def field_error(projection, q_rom: np.ndarray) -> float:
    r"""Relative mass-norm error ``||Q - V_r Q^_rom||_M / ||Q||_M`` from reduced quantities.

    With ``V`` (the largest basis) mass-orthonormal and ``V_r`` its first r columns,
    ``||Q - V_r Q^||_M^2 = ||Q - V X^||_M^2 + ||X^_{r:}||^2 + ||X^_{:r} - Q^||^2`` with
    ``X^ = V^T M Q``: the residual of the largest basis (computed exactly in the
    projection pass), the coordinates the r-basis drops, and the ROM's own error.
    """
    coords, residual, norm = projection
    r = q_rom.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):
        err2 = residual**2 + np.sum(coords[r:] ** 2) + np.sum((coords[:r] - q_rom) ** 2)
    return float(np.sqrt(err2) / norm) if np.isfinite(err2) else float("inf")


def fit_roms(system, data_all, basis, r: int, *, order: int = 4, regularization: float = 0.0,
             learners=LEARNERS) -> dict:
    """The ROMs of ``learners`` in the first ``r`` columns of one mass-orthonormal basis.

    ``galerkin`` projects the FOM matrices (the intrusive reference). The
    learners see only reduced snapshots: ``data_all`` truncated to r (the
    reduced displacements, inputs, outputs and the run's stored Newmark
    velocities and accelerations: ``lopinf``, ``opinf``), or the same
    displacements with finite differences of order ``order`` (``_fd``).
    """
    M = system.mass
    V = basis[:, :r]
    data = {"stored": data_all.truncated(r)}
    if any(name.endswith("_fd") for name in learners):
        data["fd"] = data["stored"].with_finite_differences(order)
    roms, seconds = {}, {}
    for name in learners:
        tic = time.perf_counter()
        if name == "galerkin":
            roms[name] = SecondOrderROM.galerkin(system, V, product=M, mass_orthonormal=True)
        else:
            learner = LagrangianOpInf if name.startswith("lopinf") else SecondOrderOpInf
            # the terms of the scene's effects: C^ (Rayleigh damping) and B^ (actuation)
            roms[name] = SecondOrderROM(basis=V, product=M, learner=learner.for_system(
                system, regularization=regularization)).fit(
                data["fd" if name.endswith("_fd") else "stored"])
        seconds[name] = time.perf_counter() - tic
    return {"roms": roms, "fit_seconds": seconds, "data": data}


def evaluate_rom(rom, run: dict, projection, *, extension: float) -> dict:
    """Errors of one ROM on one FOM run, and its energy over an ``extension``-times window.

    A ROM that blows up (plain OpInf can) gets infinite errors; the overflow on the way
    is expected and not reported as a warning.
    """
    times = run["times"]
    long_times = times[0] + (times[1] - times[0]) * np.arange(int(round(extension * (times.size - 1))) + 1)
    with np.errstate(all="ignore"):
        solution = rom.predict(np.zeros(rom.r), times, inputs=run["inputs"])
        long = rom.predict(np.zeros(rom.r), long_times, inputs=run["inputs"])
        Y = solution.outputs
        finite_y = bool(np.all(np.isfinite(Y)))
        energy = long.energy
        finite = bool(np.all(np.isfinite(energy)))
        fom_peak = float(np.max(run["energy"]))
        return {
            "output_error": relative_error(run["outputs"], Y) if finite_y else float("inf"),
            "field_error": field_error(projection, solution.q),
            "energy_ratio": float(np.max(np.abs(energy)) / fom_peak) if finite else float("inf"),
            "energy_final_ratio": float(abs(energy[-1]) / fom_peak) if finite else float("inf"),
            "seconds_per_step": solution.info["seconds_per_step"],
            "solution": solution,
            "long_times": long_times, "long_energy": energy,
        }


def rom_study(system, basis, data_all, projections: dict, runs: dict, train: str, ranks, *, extension: float,
              fom_seconds_per_step: float, learners=LEARNERS) -> tuple[list[dict], dict]:
    """ROM rows (one per r and learner) trained on ``runs[train]``, tested on every run."""
    rows, best = [], {}
    for r in ranks:
        fitted = fit_roms(system, data_all, basis, r, learners=learners)
        for name in learners:
            rom = fitted["roms"][name]
            row = {"r": r, "learner": name, "train": train, "fit_seconds": fitted["fit_seconds"][name]}
            for key, run in runs.items():
                ev = evaluate_rom(rom, run, projections[key], extension=extension)
                tag = "train" if key == train else "test"
                row[f"{tag}_output_error"] = ev["output_error"]
                row[f"{tag}_field_error"] = ev["field_error"]
                row[f"{tag}_energy_ratio"] = ev["energy_ratio"]
                if tag == "test":
                    row["seconds_per_step"] = ev["seconds_per_step"]
                    row["speedup"] = fom_seconds_per_step / max(ev["seconds_per_step"], 1e-12)
                best[(r, name, tag)] = ev
            if name != "galerkin":
                ops = rom.operators_
                row["stiffness_min_eig"] = float(np.min(np.linalg.eigvalsh(0.5 * (ops.stiffness + ops.stiffness.T))))
                row["stiffness_symmetric"] = bool(np.array_equal(ops.stiffness, ops.stiffness.T))
                if ops.damping is not None:
                    row["damping_min_eig"] = float(np.min(np.linalg.eigvalsh(0.5 * (ops.damping + ops.damping.T))))
            rows.append(row)
    return rows, best


# -- FOM accuracy against cost --------------------------------------------------------------
def time_step_ladder(model, signal: Signal, reference: dict, factors=(10, 5, 2)) -> list[dict]:
    """Tip-output error of runs at ``factor * dt`` against the run at the scene's ``dt``
    (``reference``, already computed), with their stepping time; and the observed order.

    Every coarse step must divide the window (compared at the same final time).
    """
    dt0, t_end = model.scene.time.dt, model.scene.time.t_end
    for factor in factors:
        steps = t_end / (factor * dt0)
        if abs(steps - round(steps)) > 1e-9 * steps:
            raise ValueError(f"time step {factor * dt0:g} does not divide the window {t_end:g} s")
    coarse = max(factors) * dt0
    t_common = coarse * np.arange(int(round(t_end / coarse)) + 1)

    def on_grid(run):
        return np.vstack([np.interp(t_common, run["times"], y) for y in run["outputs"]])

    ref = on_grid(reference)
    rows = []
    for factor in factors:
        run = run_fom(model, signal, dt=factor * dt0)
        rows.append({"dt": factor * dt0, "steps": run["summary"]["n_steps"],
                     "output_error": relative_error(ref, on_grid(run)),
                     "stepping_seconds": run["summary"]["stepping_seconds"],
                     "seconds_per_step": run["summary"]["stepping_seconds"] / run["summary"]["n_steps"]})
    s = reference["summary"]
    rows.append({"dt": dt0, "steps": s["n_steps"], "output_error": 0.0,
                 "stepping_seconds": s["stepping_seconds"],
                 "seconds_per_step": s["stepping_seconds"] / s["n_steps"]})
    if len(factors) >= 2:
        order = float(np.polyfit(np.log([r["dt"] for r in rows[:-1]]),
                                 np.log([r["output_error"] for r in rows[:-1]]), 1)[0])
        for r in rows:
            r["observed_order"] = order
    return rows


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


# -- plots -------------------------------------------------------------------------------
def plot_outputs(path, runs: dict, best: dict, r: int, names, title: str):
    plt = pyplot()
    fig, axes = plt.subplots(len(runs), 2, figsize=(11, 3.3 * len(runs)), squeeze=False)
    for i, (key, run) in enumerate(runs.items()):
        for j, comp in enumerate((1, 0)):
            ax = axes[i, j]
            scale = 1e3
            ax.plot(run["times"], scale * run["outputs"][comp], "k-", lw=2.0, label="FOM")
            for name, style in (("galerkin", "--"), ("lopinf", "-"), ("opinf", ":")):
                for tag in ("train", "test"):
                    ev = best.get((r, name, tag))
                    if ev is not None and ev["solution"].t.size == run["times"].size and \
                            ((tag == "train") == (key == best["_train"])):
                        y = ev["solution"].outputs[comp]
                        peak = 10 * np.max(np.abs(run["outputs"][comp]))
                        label = f"{LABELS[name]} r={r}"
                        if not np.all(np.abs(y) <= peak):  # blown up: draw it clipped
                            y, label = np.clip(np.nan_to_num(y, posinf=peak, neginf=-peak), -peak, peak), \
                                label + " (diverged, clipped)"
                        ax.plot(run["times"], scale * y, style, lw=1.2, label=label)
            kind = "training" if key == best["_train"] else "unseen"
            ax.set_title(f"{key} input ({kind}): {names[comp]}", fontsize=9)
            ax.set_ylabel("[mm]")
            ax.grid(alpha=0.3)
            if i == 0 and j == 0:
                ax.legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle(title, fontsize=10)
    save_figure(fig, path, dpi=110)


def plot_errors(path, rows: list[dict], title: str):
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for name, marker in (("galerkin", "s"), ("lopinf", "o"), ("opinf", "^"), ("lopinf_fd", "x"),
                         ("opinf_fd", "v")):
        sel = [r for r in rows if r["learner"] == name]
        if not sel:  # learner not run
            continue
        ranks = [r["r"] for r in sel]
        for ax, key in zip(axes, ("test_output_error", "test_field_error")):
            ax.semilogy(ranks, [min(r[key], 1e3) if np.isfinite(r[key]) else 1e3 for r in sel],
                        marker + "-", label=LABELS[name])
    axes[0].set_ylabel("output error (unseen input)")
    axes[1].set_ylabel("full-field error, mass norm (unseen input)")
    for ax in axes:
        ax.set_xlabel("r")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    save_figure(fig, path, dpi=110)


def plot_energy(path, best: dict, r: int, fom_run: dict, title: str):
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.6))
    ax.semilogy(fom_run["times"], np.maximum(fom_run["energy"], 1e-30), "k-", lw=2, label="FOM (test input)")
    for name, style in (("galerkin", "--"), ("lopinf", "-"), ("opinf", ":"), ("lopinf_fd", "-."),
                        ("opinf_fd", ":")):
        ev = best.get((r, name, "test"))
        if ev is None:  # learner not run
            continue
        e = np.abs(ev["long_energy"])
        e = np.where(np.isfinite(e), np.minimum(e, 1e30), np.nan)
        ax.semilogy(ev["long_times"], np.maximum(e, 1e-30), style, label=f"{LABELS[name]} r={r}")
    ax.axvline(fom_run["times"][-1], color="grey", lw=0.8)
    peak = float(np.max(fom_run["energy"]))
    ax.set_ylim(1e-4 * peak, 1e4 * peak)  # a model that blows up leaves through the top
    ax.set_xlabel("t [s]")
    ax.set_ylabel("energy [J]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    save_figure(fig, path, dpi=110)


# -- renders -------------------------------------------------------------------------------
def renders(out_dir: Path, model, store: SnapshotStore, run: dict, solution, r: int, *, n_times: int = 4,
            every: int = 10) -> dict:
    """PNG of FOM (top) and L-OpInf (bottom) deformed shapes, and a ParaView series of both.

    FOM fields are read from the store one snapshot at a time; ROM fields are
    reconstructed lazily, ``V q^``, at the same steps.
    """
    space, cond = model.space, model.system.condensation
    points, cells = mesh_arrays(space.mesh)
    times = run["times"]
    picks = np.unique(np.linspace(0, times.size - 1, n_times + 1).round().astype(int)[1:])

    def fom(k):
        return vertex_displacements(space.basis, cond.expand(store.read(run["trajectory"], "q", k, k + 1)[:, 0]))

    def rom(k):
        return vertex_displacements(space.basis, cond.expand(solution.basis @ solution.q[:, k]))

    info = {}
    ok, reason = render_available()
    info["render_backend"] = reason
    if ok:
        tic = time.perf_counter()
        render_grid(out_dir / "render.png", points, cells, [[fom(k) for k in picks], [rom(k) for k in picks]],
                    titles=[f"t = {times[k]:.3f} s" for k in picks],
                    row_labels=["FOM", f"L-OpInf r={r}"], window_size=(320 * picks.size, 560))
        info["render_seconds"] = time.perf_counter() - tic
        info["render"] = "render.png"
    else:
        info["render"] = None
    tic = time.perf_counter()
    steps = np.arange(0, times.size, every)
    fom_series = np.stack([fom(k) for k in steps])
    rom_series = np.stack([rom(k) for k in steps])
    write_vtu_series(out_dir / "paraview" / "fishtail.pvd", points, cells, times[steps],
                     {"displacement_fom": fom_series, "displacement_rom": rom_series,
                      "error": rom_series - fom_series})
    info["paraview_seconds"] = time.perf_counter() - tic
    info["paraview"] = "paraview/fishtail.pvd"
    return info


# -- the case ---------------------------------------------------------------------------------
def run(out_dir, *, quick: bool = False, level: str = "small", train: str = "sigmoid",
        n_inputs: int = 1, ranks=None, extension: float = 10.0, ladders: bool = True,
        render: bool = True, t_end: float | None = None, reverse: bool = True, learners=LEARNERS,
        keep_snapshots: bool = False, store_path=None, svd_power_iterations: int = 2,
        scene_path=SCENE) -> dict:
    """Run the case; return its metrics (also written to ``out_dir/metrics.json``).

    ``quick`` halves the window and shortens the ladders; ``t_end`` overrides
    the window; ``ladders`` / ``render`` / ``reverse`` switch the FOM cost
    ladders, the renders and the reverse study (trained on the other input)
    off; ``store_path`` puts the snapshot store elsewhere than
    ``out_dir/snapshots.h5`` (e.g. a larger disk), ``keep_snapshots`` keeps it.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    scene = load_scene(level, n_inputs=n_inputs, quick=quick, scene_path=scene_path)
    if t_end is not None:
        scene = with_time(scene, t_end=t_end)
    ranks = tuple(ranks or ((2, 4, 6, 8) if quick else (2, 4, 6, 8, 12)))
    if train not in ("sigmoid", "step"):
        raise ValueError(f"unknown training input {train!r}; valid: sigmoid, step")
    test = "step" if train == "sigmoid" else "sigmoid"
    learners = tuple(learners)
    unknown = [x for x in learners if x not in LEARNERS]
    if unknown or "lopinf" not in learners:
        raise ValueError(f"learners must include 'lopinf' and be among {', '.join(LEARNERS)}; got {learners}")

    tic = time.perf_counter()
    model = build(scene)
    build_seconds = time.perf_counter() - tic
    system = model.system
    M = system.mass
    dt = scene.time.dt
    store_path = out_dir / "snapshots.h5" if store_path is None else Path(store_path)
    store = SnapshotStore.create(store_path, model, fields=("q", "v", "a"), overwrite=True)
    solver = solver_factory(model)
    runs = {}
    for kind in (train, test):
        runs[kind] = run_fom(model, pressure_signal(scene, kind), store=store, name=kind, solver=solver)
    solver.cache.clear()  # the factor is not needed any more: free it before the SVD
    fom = runs[train]["summary"]
    fom_seconds_per_step = fom["stepping_seconds"] / fom["n_steps"]
    store_bytes = store_path.stat().st_size
    rss_after_fom = _peak_rss_gb()

    tic = time.perf_counter()
    pod = pod_basis(store, train, M, max(ranks), power_iterations=svd_power_iterations)
    svd_seconds = time.perf_counter() - tic
    tic = time.perf_counter()
    data_all, projections = project_runs(store, runs, train, pod.basis_, M, dt)
    projection_seconds = time.perf_counter() - tic
    rows, best = rom_study(system, pod.basis_, data_all, projections, runs, train, ranks, extension=extension,
                           fom_seconds_per_step=fom_seconds_per_step, learners=learners)
    best["_train"] = train
    reverse_rows, reverse_seconds, pod_reverse = [], 0.0, None
    if reverse:  # the same two FOM runs; basis and ROMs from the other one
        tic = time.perf_counter()
        pod_reverse = pod_basis(store, test, M, max(ranks), power_iterations=svd_power_iterations)
        data_rev, projections_rev = project_runs(store, runs, test, pod_reverse.basis_, M, dt)
        reverse_rows, _ = rom_study(system, pod_reverse.basis_, data_rev, projections_rev, runs, test, ranks,
                                    extension=extension, fom_seconds_per_step=fom_seconds_per_step,
                                    learners=[x for x in ("galerkin", "lopinf", "opinf") if x in learners])
        reverse_seconds = time.perf_counter() - tic
    r_show = max(ranks)
    names = system.output_names

    title = f"fishtail {level}: {system.n_dofs} dofs, train {train}, test {test}"
    plot_outputs(out_dir / "response.png", runs, best, r_show, names, title)
    plot_errors(out_dir / "rom_error.png", rows, title)
    plot_energy(out_dir / "energy.png", best, r_show, runs[test],
                f"reduced energy over {extension:g}x the window (unseen {test} input)")
    lopinf_rows = [r for r in rows if r["learner"] == "lopinf"]
    plot_accuracy_cost(out_dir / "accuracy_cost_r.png", lopinf_rows, "seconds_per_step",
                       "test_output_error", "r", title="L-OpInf: unseen-input output error vs s/step")
    (out_dir / "scene.toml").write_text(scene.source_text)

    render_info = {}
    if render:
        render_info = renders(out_dir, model, store, runs[test], best[(r_show, "lopinf", "test")]["solution"],
                              r_show)
    store.close()
    if not keep_snapshots:
        store_path.unlink(missing_ok=True)

    dt_rows = mesh_rows = []
    if ladders:
        dt_rows = time_step_ladder(model, pressure_signal(scene, train), runs[train],
                                   factors=(10, 5, 2) if not quick else (5, 2))
        plot_accuracy_cost(out_dir / "accuracy_cost_dt.png", dt_rows[:-1], "stepping_seconds",
                           "output_error", "dt",
                           title=f"FOM time step: tip error (vs dt = {dt:g}) vs stepping time")
        mesh_levels = [0.02, 0.012, 0.009, LEVELS[level]]
        if quick:
            mesh_levels = [0.04, 0.03, 0.02]
        mesh_rows = mesh_ladder(scene, mesh_levels)
        plot_accuracy_cost(out_dir / "accuracy_cost_mesh.png", mesh_rows[:-1], "seconds", "tip_error",
                           "dofs", title="FOM mesh: static tip deflection error vs build + solve time")

    metrics = {
        "case": "fishtail", "scene": scene.name, "level": level, "quick": quick,
        "mesh_size": dict(scene.structure.parameters)["mesh_size"],
        "n_dofs": system.n_dofs, "n_inputs": system.n_inputs, "output_names": names,
        "machine": machine_description(),
        "build_seconds": build_seconds, "build_timings": model.timings,
        "fom": {k: v["summary"] for k, v in runs.items()},
        "fom_seconds_per_step": fom_seconds_per_step,
        "factorization_seconds": fom["factorization_seconds"],
        "solver_cache": {"hits": solver.cache.hits, "misses": solver.cache.misses},
        "fom_peak_tip_mm": {k: (1e3 * np.max(np.abs(v["outputs"]), axis=1)) for k, v in runs.items()},
        "snapshots": {"path": str(store_path) if keep_snapshots else None, "bytes": store_bytes,
                      "fields": ["q", "v", "a"]},
        "peak_rss_gb_after_fom": rss_after_fom,
        "train": train, "test": test, "ranks": ranks, "extension": extension,
        "pod": {"seconds": svd_seconds, "method": "randomized", "passes": svd_power_iterations + 2,
                "singular_values": pod.singular_values_[:max(ranks)],
                "projection_error": pod.projection_error_},
        "projection_seconds": projection_seconds,
        "roms": rows,
        "roms_reverse": reverse_rows, "reverse_seconds": reverse_seconds,
        "pod_reverse_projection_error": None if pod_reverse is None else pod_reverse.projection_error_,
        "time_step_ladder": dt_rows, "mesh_ladder": mesh_rows,
        "renders": render_info,
        "peak_rss_gb": _peak_rss_gb(),
    }
    write_metrics(out_dir / "metrics.json", metrics)
    write_report(out_dir / "report.md", metrics, rows, dt_rows, mesh_rows, reverse_rows)
    return metrics


def _peak_rss_gb() -> float:
    """Peak resident memory of this process so far [GB] (``ru_maxrss``, Linux kB)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def write_report(path: Path, metrics: dict, rows, dt_rows, mesh_rows, reverse_rows=()):
    m = metrics
    columns = ["r", "learner", "train_output_error", "test_output_error", "test_field_error",
               "test_energy_ratio", "fit_seconds", "seconds_per_step", "speedup"]
    lines = [
        f"# Soft-robotic fishtail, level {m['level']}", "",
        f"{m['n_dofs']} free dofs (P2), {m['n_inputs']} input(s); FOM {m['fom'][m['train']]['n_steps']} steps "
        f"of {m['fom'][m['train']]['dt']:g} s with {m['fom'][m['train']]['scheme']} / "
        f"{m['fom'][m['train']]['solver']}: {m['fom_seconds_per_step'] * 1e3:.2f} ms per step, "
        f"build {m['build_seconds']:.2f} s.", "",
        "## What the pipeline cost", "",
        "| stage | cost |", "|---|---|",
        f"| build (mesh, assembly) | {m['build_seconds']:.2f} s |",
        f"| factorisation of the effective matrix (once for both runs) | {m['factorization_seconds']:.2f} s |",
        f"| FOM step | {m['fom_seconds_per_step'] * 1e3:.2f} ms |",
        f"| snapshot store (q, q', q'' of both runs, HDF5) | {m['snapshots']['bytes'] / 2**20:.1f} MiB |",
        f"| randomized SVD of the store ({m['pod']['passes']} passes) | {m['pod']['seconds']:.2f} s |",
        f"| projection of both runs (one pass each) | {m['projection_seconds']:.2f} s |",
        f"| peak resident memory | {m['peak_rss_gb']:.2f} GiB |", "",
        f"Trained on the {m['train']} input, tested on the {m['test']} input. Errors are relative "
        "(outputs: Frobenius over the three tip components and all steps; fields: mass norm); "
        f"energy ratio = max reduced energy over {m['extension']:g}x the window / max FOM energy.", "",
        accuracy_cost_table(rows, columns), "",
    ]
    if reverse_rows:
        lines += [f"## The reverse: trained on the {m['test']} input, tested on the {m['train']} input", "",
                  accuracy_cost_table(list(reverse_rows), columns), ""]
    if dt_rows:
        lines += [f"## FOM time step (tip error against the run at dt = {dt_rows[-1]['dt']:g})", "",
                  accuracy_cost_table(dt_rows, ["dt", "steps", "output_error", "stepping_seconds",
                                                "seconds_per_step"]), "",
                  f"Observed order {dt_rows[0].get('observed_order', float('nan')):.2f} (Newmark average "
                  "acceleration: 2 once the excited modes are resolved).", ""]
    if mesh_rows:
        lines += ["## FOM mesh (static tip deflection and f1, vs the finest level listed)", "",
                  accuracy_cost_table(mesh_rows, ["mesh_size", "dofs", "tip_y_per_pa", "tip_error",
                                                  "f1_hz", "f1_error", "seconds"]), ""]
    if m["renders"]:
        lines += ["## Renders", "", f"backend: {m['renders'].get('render_backend')}", "",
                  "![render](render.png)" if m["renders"].get("render") else "(no render)", "",
                  f"ParaView: {m['renders'].get('paraview')}", ""]
    path.write_text("\n".join(lines))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="femrom run fishtail", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results") / "fishtail")
    parser.add_argument("--quick", action="store_true", help="short window, coarse mesh ladder (tests)")
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
    metrics = run(args.out, quick=args.quick, level=args.level, train=args.train, n_inputs=args.inputs,
                  ranks=args.ranks, ladders=ladders, reverse=args.reverse, keep_snapshots=args.keep_snapshots,
                  store_path=args.store)
    r = max(metrics["ranks"])
    row = next(x for x in metrics["roms"] if x["r"] == r and x["learner"] == "lopinf")
    print(f"fishtail ({args.level}): {metrics['n_dofs']} dofs, FOM {metrics['fom_seconds_per_step'] * 1e3:.1f} "
          f"ms/step; L-OpInf r={r} on the unseen {metrics['test']} input: output error "
          f"{row['test_output_error']:.2e}, field error {row['test_field_error']:.2e}, speedup {row['speedup']:.0f}x")
    print(f"report: {args.out / 'report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
