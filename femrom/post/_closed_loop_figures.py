"""Figures of closed loops (:func:`femrom.control.closed_loop` results): an output against its
reference with the applied inputs, and the plant's deformed body at a few times."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from femrom.post._render import mesh_arrays, render_available, render_grid, vertex_displacements
from femrom.post._plots import pyplot, save_figure


def plot_closed_loops(path, results: dict, dt: float, bound: float, *, title: str = "", output: int = -1,
                      output_label: str = "output", scale: float = 1.0, unit: str = "",
                      input_label: str = "inputs") -> Path:
    """One column per reference: on top output ``output`` (times ``scale``, in ``unit``) of each loop and
    the reference, below each loop's applied inputs (one colour per loop) and the bounds ``+-bound``.

    ``results``: ``{(label, r, reference name): ClosedLoopResult}`` (:func:`femrom.study.closed_loop_rows`)."""
    plt = pyplot()
    references = list(dict.fromkeys(key[2] for key in results))
    fig, axes = plt.subplots(2, len(references), figsize=(6 * len(references), 6), squeeze=False, sharex=True)
    for j, name in enumerate(references):
        top, bottom = axes[0, j], axes[1, j]
        first = True
        for (label, r, ref), result in results.items():
            if ref != name:
                continue
            t = dt * np.arange(result.n_samples)
            if first:
                top.plot(t, scale * result.reference[output], "k-", lw=2, label="reference")
                first = False
            line, = top.plot(t, scale * result.outputs[output], "--", label=f"{label} r={r}")
            for i in range(result.inputs.shape[0]):
                bottom.plot(t, result.inputs[i], color=line.get_color(), lw=0.8,
                            alpha=0.5 + 0.25 * i / max(result.inputs.shape[0] - 1, 1),
                            label=f"{label} r={r}" if i == 0 else None)
        top.set_title(f"{name}: {output_label}", fontsize=9)
        top.set_ylabel(f"{output_label} [{unit}]" if unit else output_label)
        bottom.set_ylabel(input_label)
        bottom.set_xlabel("t [s]")
        bottom.axhline(bound, color="r", lw=0.6, ls=":")
        bottom.axhline(-bound, color="r", lw=0.6, ls=":")
        for ax in (top, bottom):
            ax.grid(alpha=0.3)
        top.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path, dpi=110)


def render_closed_loop(path, fom, result, label: str, dt: float, *, n_frames: int = 4, camera: str = "xz") -> dict:
    """The FOM's deformed body under a closed loop at ``n_frames`` times evenly spread after the start,
    from ``result.plant_states`` (the loop's recorded free-dof displacements).

    Returns ``{"control_render": file name or None, "control_render_backend": why or which}`` (no file
    without a render backend or without recorded states)."""
    ok, reason = render_available()
    if not ok or result.plant_states is None:
        return {"control_render": None, "control_render_backend": reason}
    points, cells = mesh_arrays(fom.space.mesh)
    picks = np.unique(np.linspace(0, result.n_samples - 1, n_frames + 1).round().astype(int)[1:])
    frames = [vertex_displacements(fom.space.basis, fom.system.condensation.expand(result.plant_states[:, k]))
              for k in picks]
    render_grid(path, points, cells, [frames], titles=[f"t = {k * dt:.2f} s" for k in picks],
                row_labels=[f"FOM under MPC ({label})"], window_size=(320 * picks.size, 320), camera=camera)
    return {"control_render": Path(path).name, "control_render_backend": reason}
