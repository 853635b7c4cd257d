"""Soft-robotic fishtail: P2 FOM under chamber pressure, L-OpInf vs Galerkin vs OpInf ROMs, renders.

The tail of ``meshes/fishtail.geo`` (silicone, clamped at the head) is bent by
two chambers driven antagonistically by one pressure input (``fishtail.toml``;
``n_inputs=2`` drives each chamber by its own input). The case

1. builds the P2 FOM at a mesh level (``LEVELS``) and runs it twice, under the
   sigmoid pressure of the scene file and under a pressure step;
2. builds a mass-orthonormal POD basis from the training run's displacement
   snapshots (``train="sigmoid"`` or ``"step"``), and for several r fits the
   intrusive Galerkin ROM, L-OpInf (``K^ = K^^T > 0``, ``C^ = C^^T >= 0``)
   and plain OpInf from finite differences of the reduced snapshots (no FOM
   matrices are used by the learners);
3. tests every ROM on the other input: output error (tip x, y, z), full-field
   error in the mass norm, reduced energy over an extended window, time per
   step and speedup over the FOM;
4. measures the FOM's cost and accuracy over the time step and the mesh size;
5. writes into its folder: ``metrics.json``, ``report.md``, ``response.png``
   (FOM and ROM tip outputs), ``rom_error.png``, ``energy.png``, the
   accuracy-vs-cost plots, ``render.png`` (deformed tail coloured by ``|u|``,
   FOM above, L-OpInf below, at several times) and ``paraview/fishtail.pvd``.

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
from femrom.inference import LagrangianOpInf, SecondOrderOpInf, reduce_snapshots
from femrom.integrators import simulate
from femrom.post import (
    accuracy_cost_table,
    mesh_arrays,
    plot_accuracy_cost,
    render_available,
    render_grid,
    vertex_displacements,
    write_metrics,
    write_vtu_series,
)
from femrom.post._report import machine_description
from femrom.rom import SecondOrderROM
from femrom.scene import InputConfig, LoadConfig, Scene, Signal, build

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
def run_fom(model, signal: Signal, *, dt=None, fields=True, consumers=()) -> dict:
    """Integrate the FOM under one pressure signal; snapshots ``Q``, ``Qv``, ``Qa`` in memory."""
    u = PressureInputs(signal, model.system.n_inputs)
    system = dataclasses.replace(model.system, inputs=u)
    kept = ("displacement", "velocity", "acceleration") if fields else ()
    outputs = dataclasses.replace(model.scene.outputs, fields=kept)
    model = dataclasses.replace(model, system=system,
                                scene=dataclasses.replace(model.scene, outputs=outputs))
    result = simulate(model, dt=dt, consumers=consumers, progress=False)
    return {"times": result.times, "outputs": result.outputs, "energy": result.energy,
            "Q": result.fields.get("displacement"), "Qv": result.fields.get("velocity"),
            "Qa": result.fields.get("acceleration"), "inputs": u, "U": u.sampled(result.times),
            "summary": result.summary}


# -- reduced models --------------------------------------------------------------------
def mass_norm(M, X) -> float:
    """Frobenius norm of ``X`` (n, k) in the mass product: ``sqrt(trace(X^T M X))``."""
    return float(np.sqrt(max(np.sum(X * (M @ X)), 0.0)))


def relative_error(reference: np.ndarray, approximation: np.ndarray) -> float:
    """``||approximation - reference||_F / ||reference||_F``."""
    return float(np.linalg.norm(approximation - reference) / np.linalg.norm(reference))


def fit_roms(system, basis, train: dict, dt: float, *, order: int = 4, regularization: float = 0.0,
             learners=LEARNERS) -> dict:
    """The ROMs of ``learners`` in one mass-orthonormal basis ``V`` (``V^T M V = I``).

    ``galerkin`` projects the FOM matrices (the intrusive reference). The
    learners see only snapshots: the reduced displacements ``V^T M Q``, the
    sampled inputs and outputs, and either the run's stored Newmark velocities
    and accelerations (``lopinf``, ``opinf``) or finite differences of order
    ``order`` of the reduced displacements (``lopinf_fd``, ``opinf_fd``).
    """
    M = system.mass
    common = dict(product=M, inputs=train["U"], outputs=train["outputs"], order=order)
    data = {}
    if any(not name.endswith("_fd") and name != "galerkin" for name in learners):
        data["stored"] = reduce_snapshots(basis, train["Q"], dt, velocities=train["Qv"],
                                          accelerations=train["Qa"], derivatives="stored", **common)
    if any(name.endswith("_fd") for name in learners):
        data["fd"] = reduce_snapshots(basis, train["Q"], dt, **common)
    roms, seconds = {}, {}
    for name in learners:
        tic = time.perf_counter()
        if name == "galerkin":
            roms[name] = SecondOrderROM.galerkin(system, basis, product=M, mass_orthonormal=True)
        else:
            learner = LagrangianOpInf if name.startswith("lopinf") else SecondOrderOpInf
            roms[name] = SecondOrderROM(basis=basis, product=M, learner=learner(
                damping=True, regularization=regularization)).fit(
                data["fd" if name.endswith("_fd") else "stored"])
        seconds[name] = time.perf_counter() - tic
    return {"roms": roms, "fit_seconds": seconds, "data": data}


def evaluate_rom(rom, system, run: dict, *, extension: float) -> dict:
    """Errors of one ROM on one FOM run, and its energy over an ``extension``-times window."""
    times = run["times"]
    solution = rom.predict(np.zeros(rom.r), times, inputs=run["inputs"])
    Y = solution.outputs
    Qr = rom.basis @ solution.q
    M = system.mass
    field_error = mass_norm(M, Qr - run["Q"]) / mass_norm(M, run["Q"])
    long_times = times[0] + (times[1] - times[0]) * np.arange(int(round(extension * (times.size - 1))) + 1)
    with np.errstate(all="ignore"):
        long = rom.predict(np.zeros(rom.r), long_times, inputs=run["inputs"])
    energy = long.energy
    finite = bool(np.all(np.isfinite(energy)))
    fom_peak = float(np.max(run["energy"]))
    return {
        "output_error": relative_error(run["outputs"], Y) if np.all(np.isfinite(Y)) else float("inf"),
        "field_error": field_error if np.isfinite(field_error) else float("inf"),
        "energy_ratio": float(np.max(np.abs(energy)) / fom_peak) if finite else float("inf"),
        "energy_final_ratio": float(abs(energy[-1]) / fom_peak) if finite else float("inf"),
        "seconds_per_step": solution.info["seconds_per_step"],
        "solution": solution,
        "long_times": long_times, "long_energy": energy,
    }


def rom_study(system, basis_all, runs: dict, train: str, ranks, dt: float, *, extension: float,
              fom_seconds_per_step: float, learners=LEARNERS) -> tuple[list[dict], dict]:
    """ROM rows (one per r and learner) trained on ``runs[train]``, tested on every run."""
    rows, best = [], {}
    for r in ranks:
        fitted = fit_roms(system, basis_all[:, :r], runs[train], dt, learners=learners)
        for name in learners:
            rom = fitted["roms"][name]
            row = {"r": r, "learner": name, "train": train, "fit_seconds": fitted["fit_seconds"][name]}
            for key, run in runs.items():
                ev = evaluate_rom(rom, system, run, extension=extension)
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
def time_step_ladder(model, signal: Signal, reference: dict, factors=(8, 4, 2)) -> list[dict]:
    """Tip-output error of runs at ``factor * dt`` against the run at the scene's ``dt``
    (``reference``, already computed), with their stepping time; and the observed order."""
    dt0 = model.scene.time.dt
    coarse = max(factors) * dt0
    t_common = np.arange(0.0, model.scene.time.t_end + 0.5 * coarse, coarse)

    def on_grid(run):
        return np.vstack([np.interp(t_common, run["times"], y) for y in run["outputs"]])

    ref = on_grid(reference)
    rows = []
    for factor in factors:
        run = run_fom(model, signal, dt=factor * dt0, fields=False)
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

    from femrom.fem import make_solver

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
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_outputs(path, runs: dict, best: dict, r: int, names, title: str):
    plt = _plt()
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
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_errors(path, rows: list[dict], title: str):
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for name, marker in (("galerkin", "s"), ("lopinf", "o"), ("opinf", "^"), ("lopinf_fd", "x"),
                         ("opinf_fd", "v")):
        sel = [r for r in rows if r["learner"] == name]
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
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_energy(path, best: dict, r: int, fom_run: dict, title: str):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 3.6))
    ax.semilogy(fom_run["times"], np.maximum(fom_run["energy"], 1e-30), "k-", lw=2, label="FOM (test input)")
    for name, style in (("galerkin", "--"), ("lopinf", "-"), ("opinf", ":"), ("lopinf_fd", "-."),
                        ("opinf_fd", ":")):
        ev = best[(r, name, "test")]
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
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- renders -------------------------------------------------------------------------------
def renders(out_dir: Path, model, run: dict, solution, r: int, *, n_times: int = 4,
            every: int = 10) -> dict:
    """PNG of FOM (top) and L-OpInf (bottom) deformed shapes, and a ParaView series of both."""
    space, cond = model.space, model.system.condensation
    points, cells = mesh_arrays(space.mesh)
    times = run["times"]
    picks = np.unique(np.linspace(0, times.size - 1, n_times + 1).round().astype(int)[1:])

    def vertex(Qfree, k):
        return vertex_displacements(space.basis, cond.expand(Qfree[:, k]))

    Qrom = solution.basis @ solution.q[:, picks]
    fom_panels = [vertex(run["Q"], k) for k in picks]
    rom_panels = [vertex(Qrom, j) for j in range(picks.size)]
    info = {}
    ok, reason = render_available()
    info["render_backend"] = reason
    if ok:
        tic = time.perf_counter()
        render_grid(out_dir / "render.png", points, cells, [fom_panels, rom_panels],
                    titles=[f"t = {times[k]:.3f} s" for k in picks],
                    row_labels=["FOM", f"L-OpInf r={r}"], window_size=(320 * picks.size, 560))
        info["render_seconds"] = time.perf_counter() - tic
        info["render"] = "render.png"
    else:
        info["render"] = None
    tic = time.perf_counter()
    steps = np.arange(0, times.size, every)
    fom_series = np.stack([vertex(run["Q"], k) for k in steps])
    rom_full = solution.basis @ solution.q[:, steps]
    rom_series = np.stack([vertex(rom_full, j) for j in range(steps.size)])
    write_vtu_series(out_dir / "paraview" / "fishtail.pvd", points, cells, times[steps],
                     {"displacement_fom": fom_series, "displacement_rom": rom_series,
                      "error": rom_series - fom_series})
    info["paraview_seconds"] = time.perf_counter() - tic
    info["paraview"] = "paraview/fishtail.pvd"
    return info


# -- the case ---------------------------------------------------------------------------------
def run(out_dir, *, quick: bool = False, level: str = "small", train: str = "sigmoid",
        n_inputs: int = 1, ranks=None, extension: float = 10.0, ladders: bool = True,
        render: bool = True, t_end: float | None = None, scene_path=SCENE) -> dict:
    """Run the case; return its metrics (also written to ``out_dir/metrics.json``).

    ``quick`` halves the window and shortens the ladders; ``t_end`` overrides
    the window; ``ladders`` / ``render`` switch the FOM cost ladders and the
    renders off (tests).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    scene = load_scene(level, n_inputs=n_inputs, quick=quick, scene_path=scene_path)
    if t_end is not None:
        scene = with_time(scene, t_end=t_end)
    ranks = tuple(ranks or ((2, 4, 6, 8) if quick else (2, 4, 6, 8, 12)))
    test = "step" if train == "sigmoid" else "sigmoid"

    tic = time.perf_counter()
    model = build(scene)
    build_seconds = time.perf_counter() - tic
    system = model.system
    runs = {}
    for kind in (train, test):
        runs[kind] = run_fom(model, pressure_signal(scene, kind))
    fom = runs[train]["summary"]
    fom_seconds_per_step = fom["stepping_seconds"] / fom["n_steps"]
    dt = scene.time.dt

    tic = time.perf_counter()
    pod = POD(rank=max(ranks), product=system.mass, method="svd").fit(runs[train]["Q"])
    svd_seconds = time.perf_counter() - tic
    rows, best = rom_study(system, pod.basis_, runs, train, ranks, dt, extension=extension,
                           fom_seconds_per_step=fom_seconds_per_step)
    best["_train"] = train
    # the reverse: the same two FOM runs, basis and ROMs from the other one
    tic = time.perf_counter()
    pod_reverse = POD(rank=max(ranks), product=system.mass, method="svd").fit(runs[test]["Q"])
    reverse_rows, _ = rom_study(system, pod_reverse.basis_, runs, test, ranks, dt, extension=extension,
                                fom_seconds_per_step=fom_seconds_per_step,
                                learners=("galerkin", "lopinf", "opinf"))
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

    dt_rows = mesh_rows = []
    if ladders:
        dt_rows = time_step_ladder(model, pressure_signal(scene, train), runs[train],
                                   factors=(8, 4, 2) if not quick else (4, 2))
        plot_accuracy_cost(out_dir / "accuracy_cost_dt.png", dt_rows[:-1], "stepping_seconds",
                           "output_error", "dt",
                           title=f"FOM time step: tip error (vs dt = {dt:g}) vs stepping time")
        mesh_levels = [0.02, 0.012, 0.009, LEVELS[level]]
        if quick:
            mesh_levels = [0.04, 0.03, 0.02]
        mesh_rows = mesh_ladder(scene, mesh_levels)
        plot_accuracy_cost(out_dir / "accuracy_cost_mesh.png", mesh_rows[:-1], "seconds", "tip_error",
                           "dofs", title="FOM mesh: static tip deflection error vs build + solve time")

    render_info = {}
    if render:
        render_info = renders(out_dir, model, runs[test], best[(r_show, "lopinf", "test")]["solution"], r_show)

    def strip(row):
        return {k: v for k, v in row.items()}

    metrics = {
        "case": "fishtail", "scene": scene.name, "level": level, "quick": quick,
        "mesh_size": dict(scene.structure.parameters)["mesh_size"],
        "n_dofs": system.n_dofs, "n_inputs": system.n_inputs, "output_names": names,
        "machine": machine_description(),
        "build_seconds": build_seconds, "build_timings": model.timings,
        "fom": {k: v["summary"] for k, v in runs.items()},
        "fom_seconds_per_step": fom_seconds_per_step,
        "fom_peak_tip_mm": {k: (1e3 * np.max(np.abs(v["outputs"]), axis=1)) for k, v in runs.items()},
        "train": train, "test": test, "ranks": ranks, "extension": extension,
        "pod": {"seconds": svd_seconds, "singular_values": pod.singular_values_[:max(ranks)],
                "projection_error": pod.projection_error_},
        "roms": [strip(r) for r in rows],
        "roms_reverse": reverse_rows, "reverse_seconds": reverse_seconds,
        "pod_reverse_projection_error": pod_reverse.projection_error_,
        "time_step_ladder": dt_rows, "mesh_ladder": mesh_rows,
        "renders": render_info,
    }
    write_metrics(out_dir / "metrics.json", metrics)
    write_report(out_dir / "report.md", metrics, rows, dt_rows, mesh_rows, reverse_rows)
    return metrics


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
    parser.add_argument("--level", default="small", choices=tuple(LEVELS))
    parser.add_argument("--train", default="sigmoid", choices=("sigmoid", "step"))
    parser.add_argument("--inputs", type=int, default=1, choices=(1, 2),
                        help="1: antagonistic chambers (default); 2: one input per chamber")
    args = parser.parse_args(argv)
    metrics = run(args.out, quick=args.quick, level=args.level, train=args.train, n_inputs=args.inputs)
    r = max(metrics["ranks"])
    row = next(x for x in metrics["roms"] if x["r"] == r and x["learner"] == "lopinf")
    print(f"fishtail ({args.level}): {metrics['n_dofs']} dofs, FOM {metrics['fom_seconds_per_step'] * 1e3:.1f} ms/step; "
          f"L-OpInf r={r} on the unseen {metrics['test']} input: output error {row['test_output_error']:.2e}, "
          f"speedup {row['speedup']:.0f}x; report in {args.out / 'report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
