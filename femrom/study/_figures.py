"""The study's figures: responses, errors against r, energy over the extended window,
accuracy against measured cost, and FOM/ROM renders with a ParaView series."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from femrom.post import mesh_arrays, pyplot, render_available, render_grid, save_figure, vertex_displacements, \
    write_vtu_series

STYLES = ("--", "-", ":", "-.", (0, (3, 1, 1, 1)), (0, (5, 2)))
#: relative errors are drawn at most this large: above it a model has diverged
DIVERGED = 10.0
MARKERS = ("s", "o", "^", "x", "v", "D", "P")


def _clipped(y: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, bool]:
    """A diverged curve drawn clipped at ten times the reference's peak."""
    peak = 10 * max(float(np.max(np.abs(reference))), 1e-300)
    if np.all(np.abs(y) <= peak):
        return y, False
    return np.clip(np.nan_to_num(y, posinf=peak, neginf=-peak), -peak, peak), True


def plot_outputs(path, runs: dict, evaluations: dict, r: int, labels, output_names, title: str,
                 *, roles: dict, components=None, scale: float = 1.0, unit: str = "") -> Path:
    """FOM outputs (black) and each learner's ROM at rank ``r``, one row per run, one column per output."""
    plt = pyplot()
    names = list(output_names)
    components = list(range(len(names)))[:3] if components is None else list(components)
    fig, axes = plt.subplots(len(runs), len(components), figsize=(4.2 * len(components) + 1, 3.0 * len(runs)),
                             squeeze=False)
    for i, (key, run) in enumerate(runs.items()):
        for j, comp in enumerate(components):
            ax = axes[i, j]
            ax.plot(run.times, scale * run.outputs[comp], "k-", lw=2.0, label="FOM")
            for label, style in zip(labels, STYLES * 3):
                ev = evaluations.get((r, label, key))
                if ev is None:
                    continue
                y, clipped = _clipped(ev.solution.outputs[comp], run.outputs[comp])
                ax.plot(run.times, scale * y, linestyle=style, lw=1.2,
                        label=f"{label} r={r}" + (" (diverged, clipped)" if clipped else ""))
            ax.set_title(f"{key} ({roles[key]}): {names[comp]}", fontsize=9)
            ax.set_ylabel(unit)
            ax.grid(alpha=0.3)
            if i == 0 and j == 0:
                ax.legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path, dpi=110)


def plot_errors(path, rows: list[dict], title: str, *, keys=("test_output_error", "test_field_error"),
                ylabels=("output error (unseen input)", "field error (unseen input)")) -> Path:
    """Errors against r, one line per learner (diverged models drawn at 1e3)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(keys), figsize=(5 * len(keys), 3.6), squeeze=False)
    for label, marker in zip(dict.fromkeys(row["learner"] for row in rows), MARKERS * 3):
        sel = [row for row in rows if row["learner"] == label]
        for ax, key in zip(axes[0], keys):
            ax.semilogy([row["r"] for row in sel],
                        [min(row[key], 1e3) if np.isfinite(row[key]) else 1e3 for row in sel],
                        marker + "-", label=label)
    for ax, ylabel in zip(axes[0], ylabels):
        ax.set_xlabel("r")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path, dpi=110)


def plot_energy(path, evaluations: dict, r: int, labels, run, title: str) -> Path:
    """FOM energy on the test window and each ROM's over the extended window (log scale)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.6))
    ax.semilogy(run.times, np.maximum(run.energy, 1e-30), "k-", lw=2, label=f"FOM ({run.name})")
    for label, style in zip(labels, STYLES * 3):
        ev = evaluations.get((r, label, run.name))
        if ev is None:
            continue
        e = np.abs(ev.long_energy)
        e = np.where(np.isfinite(e), np.minimum(e, 1e30), np.nan)
        ax.semilogy(ev.long_times, np.maximum(e, 1e-30), linestyle=style, label=f"{label} r={r}")
    ax.axvline(run.times[-1], color="grey", lw=0.8)
    peak = float(np.max(run.energy))
    ax.set_ylim(1e-4 * peak, 1e4 * peak)  # a model that blows up leaves through the top
    ax.set_xlabel("t [s]")
    ax.set_ylabel("energy [J]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    return save_figure(fig, path, dpi=110)


def plot_error_history(path, run, projection, evaluations: dict, r: int, labels, *, shade=None, title: str = "",
                       envelope: int | None = 400) -> Path:
    """Field error over time, ``||q(t) - V q^(t)||_W / max_t ||q(t)||_W``, of each learner's ROM at
    rank ``r`` on ``run``, and the basis's projection error (the floor); ``shade``: the training
    window; ``envelope``: the maximum per bin of that many bins (oscillating errors stay readable)."""
    from femrom.post import plot_time_series

    scale = float(np.sqrt(np.max(projection.norm2)))
    series = {f"{label} (r={r})": projection.column_errors(evaluations[(r, label, run.name)].solution.q) / scale
              for label in labels if (r, label, run.name) in evaluations}
    series[f"projection (r={r})"] = projection.column_projection_errors(r) / scale
    return plot_time_series(path, run.times, series, logy=True, shade=shade, envelope=envelope, ymax=10.0,
                            ylabel="||q - V q^||_W / max ||q||_W" + (" (bin max)" if envelope else ""), title=title)


def plot_accuracy_cost(path, rows: list[dict], fom_cost: dict, title: str, *, error: str = "test_output_error") -> Path:
    """Error against seconds per step (minimum of the timed blocks, bars up to their upper quartile), one line
    per learner, points annotated with r; the FOM's cost as a vertical band; errors above
    :data:`DIVERGED` (models that blew up) on that ceiling (dotted)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.6, 4.3))
    for label, marker in zip(dict.fromkeys(row["learner"] for row in rows), MARKERS * 3):
        sel = [row for row in rows if row["learner"] == label and np.isfinite(row[error]) and row[error] > 0]
        if not sel:
            continue
        x = np.array([row["cost"]["minimum"] for row in sel])
        lo = np.zeros_like(x)
        hi = np.array([row["cost"]["q75"] for row in sel]) - x
        y = [min(row[error], DIVERGED) for row in sel]      # a model that blew up sits on the ceiling
        ax.errorbar(x, y, xerr=[lo, hi], fmt=marker + "-", capsize=2, label=label)
        for row, xi, yi in zip(sel, x, y):
            ax.annotate(f"r={row['r']}", (xi, yi), textcoords="offset points", xytext=(3, 3), fontsize=7)
    ax.axvspan(fom_cost["minimum"], fom_cost["q75"], color="grey", alpha=0.3)
    ax.axvline(fom_cost["minimum"], color="k", lw=1, label="FOM step")
    ax.axhline(DIVERGED, color="r", lw=0.6, ls=":")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds per step (fastest timed block; bars: to the upper quartile)")
    ax.set_ylabel(error.replace("_", " "))
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    return save_figure(fig, path, dpi=110)


def render_fields(out_dir: Path, model, store, run, solution, label: str, *, n_times: int = 4, every: int = 10,
                  render: bool = True, paraview: bool = True) -> dict:
    """PNG of FOM (top) and ROM (bottom) deformed shapes at ``n_times`` times, and a ParaView
    series of both and their difference every ``every`` steps (3D meshes only).

    FOM fields are read from the store one snapshot at a time; ROM fields are
    rebuilt, ``V q^``, at the same steps.
    """
    space, cond = model.space, model.system.condensation
    if model.space.mesh.p.shape[0] != 3:
        return {"render": None, "paraview": None, "render_backend": "not a 3D mesh"}
    points, cells = mesh_arrays(space.mesh)
    times = run.times
    picks = np.unique(np.linspace(0, times.size - 1, n_times + 1).round().astype(int)[1:])

    def fom(k):
        return vertex_displacements(space.basis, cond.expand(store.read(run.name, "q", k, k + 1)[:, 0]))

    def rom(k):
        return vertex_displacements(space.basis, cond.expand(solution.field(k)))

    info = {"render": None, "paraview": None}
    if render:
        ok, reason = render_available()
        info["render_backend"] = reason
        if ok:
            tic = time.perf_counter()
            render_grid(out_dir / "render.png", points, cells, [[fom(k) for k in picks], [rom(k) for k in picks]],
                        titles=[f"t = {times[k]:.3f} s" for k in picks], row_labels=["FOM", label],
                        window_size=(320 * picks.size, 560))
            info["render_seconds"] = time.perf_counter() - tic
            info["render"] = "render.png"
    if paraview:
        tic = time.perf_counter()
        steps = np.arange(0, times.size, every)
        fom_series = np.stack([fom(k) for k in steps])
        rom_series = np.stack([rom(k) for k in steps])
        name = f"paraview/{model.scene.name}.pvd"
        write_vtu_series(out_dir / name, points, cells, times[steps],
                         {"displacement_fom": fom_series, "displacement_rom": rom_series,
                          "error": rom_series - fom_series})
        info["paraview_seconds"] = time.perf_counter() - tic
        info["paraview"] = name
    return info


def plot_invariant_drifts(path, times, reference: dict, kept: dict, names: dict, *, shade=None,
                          title: str = "") -> Path:
    """``|I(t) - I(0)| / |I(0)|`` of each invariant (one panel each) for the FOM (black) and each kept ROM.

    ``reference``: name -> (k,) FOM values; ``kept``: label -> {name: (k,) values};
    ``names``: name -> axis label. Exact invariants sit at round-off: the axis starts at 1e-16.
    """
    plt = pyplot()
    floor = 1e-16
    fig, axes = plt.subplots(len(names), 1, figsize=(7, 2.4 * len(names)), sharex=True, squeeze=False)
    for ax, (key, label) in zip(axes[:, 0], names.items()):
        ref = np.asarray(reference[key])
        ax.semilogy(times, np.maximum(np.abs(ref - ref[0]) / abs(ref[0]), floor), "k-", lw=1.0, label="FOM")
        for (name, values), style in zip(kept.items(), STYLES * 3):
            v = np.asarray(values[key])
            with np.errstate(all="ignore"):
                ax.semilogy(times, np.maximum(np.abs(v - v[0]) / abs(v[0]), floor), linestyle=style, lw=1.0,
                            label=name)
        if shade is not None:
            ax.axvspan(*shade, color="0.92")
        ax.set_ylim(floor, 1e2)
        ax.set_ylabel(f"|change| of {label}", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, ncol=4)
    axes[0, 0].set_title(title)
    axes[-1, 0].set_xlabel("t")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)
