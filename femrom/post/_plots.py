"""The figures of femrom's reports: responses and energy, errors over time, accuracy against
cost, backbones; PNG files written on matplotlib's Agg backend (no display needed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from femrom._errors import FemromValueError
from femrom.post._backbone import Backbone


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, *, dpi: int) -> Path:
    """Lay out, write (making the folder) and close a figure; returns the path."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def plot_response(path, times, outputs=None, output_names=(), energy=None, title="") -> Path:
    """Outputs ``y(t)`` (top) and relative energy change ``(E - E0)/E0`` (bottom) to a PNG.

    Parameters
    ----------
    times : (k,) ndarray
    outputs : (p, k) ndarray or None
    energy : (k,) ndarray or None
    """
    plt = pyplot()

    panels = [x for x in (outputs, energy) if x is not None]
    fig, axes = plt.subplots(max(len(panels), 1), 1, figsize=(8, 3.2 * max(len(panels), 1)),
                             sharex=True, squeeze=False)
    axes = axes[:, 0]
    i = 0
    if outputs is not None:
        for row, name in zip(np.atleast_2d(outputs), output_names or [f"y{j}" for j in range(len(outputs))]):
            axes[i].plot(times, row, lw=1.0, label=name)
        axes[i].set_ylabel("output")
        axes[i].legend(loc="upper right", fontsize=8)
        axes[i].grid(alpha=0.3)
        i += 1
    if energy is not None:
        energy = np.asarray(energy)
        scale = abs(energy[0]) if energy[0] != 0 else max(np.max(np.abs(energy)), 1e-300)
        axes[i].plot(times, (energy - energy[0]) / scale, lw=1.0, color="tab:red")
        axes[i].set_ylabel("(E - E0) / |E0|")
        axes[i].grid(alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    if title:
        axes[0].set_title(title)
    return save_figure(fig, path, dpi=120)


def plot_time_series(path, times, series: dict, *, ylabel: str = "", logy: bool = False,
                     shade: tuple[float, float] | None = None, title: str = "",
                     shade_label: str = "training window", envelope: int | None = None,
                     ymax: float | None = None) -> Path:
    """Several curves over time on one axis, e.g. errors of several ROMs.

    Parameters
    ----------
    times : (k,) ndarray
    series : dict of name -> (k,) ndarray
    shade : (t0, t1), optional
        A window to shade (the training window).
    envelope : int, optional
        Draw the maximum over ``envelope`` equal bins instead of every sample (fast
        oscillating errors of long runs stay readable).
    ymax : float, optional
        Clip values above (a blow-up then runs along the top edge, marked "clipped").
    """
    plt = pyplot()

    fig, ax = plt.subplots(figsize=(8, 3.6))
    styles = ("-", "--", ":", "-.")
    for i, (name, values) in enumerate(series.items()):
        values = np.asarray(values, dtype=float)
        t = np.asarray(times, dtype=float)[:values.size]
        if ymax is not None:
            over = ~np.isfinite(values) | (values > ymax)
            if over.any():
                values = np.where(over, ymax, values)
                name = f"{name} (clipped)"
        if envelope is not None and values.size > 2 * envelope:
            edges = np.linspace(0, values.size, envelope + 1).astype(int)
            values = np.array([np.nanmax(values[a:b]) for a, b in zip(edges[:-1], edges[1:])])
            t = np.array([t[(a + b) // 2] for a, b in zip(edges[:-1], edges[1:])])
        if logy:
            values = np.where(values > 0, values, np.nan)
        ax.plot(t, values, styles[i % len(styles)], lw=1.2, label=name)
    if shade is not None:
        ax.axvspan(shade[0], shade[1], color="0.85", zorder=0, label=shade_label)
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel("t [s]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    return save_figure(fig, path, dpi=100)


def plot_space_time(path, grid, times, panels: dict, *, mark: float | None = None, label: str = "") -> Path:
    """One colour map per entry of ``panels`` (name -> (n_x, k) field over ``grid`` (n_x,) and ``times``
    (k,)), side by side on one colour scale from 0 to the first panel's maximum; ``mark``: a time drawn
    as a white line (the end of training); non-finite values drawn as 0. At most 400 time rows are drawn."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 3.2), sharey=True)
    stride = max(1, np.size(times) // 400)
    top = float(np.max(next(iter(panels.values()))))
    for ax, (name, field) in zip(np.atleast_1d(axes), panels.items()):
        ax.pcolormesh(grid, times[::stride], np.nan_to_num(np.asarray(field)[:, ::stride].T), shading="auto",
                      vmin=0, vmax=top)
        if mark is not None:
            ax.axhline(mark, color="w", lw=0.8)
        ax.set_title(f"{label}{name}", fontsize=9)
        ax.set_xlabel("x")
    np.atleast_1d(axes)[0].set_ylabel("t")
    return save_figure(fig, path, dpi=90)


def plot_accuracy_cost(path, rows: list[dict], cost: str, error: str, label: str, title="") -> Path:
    """Log-log error against cost, one point per row, annotated with ``label``."""
    plt = pyplot()

    fig, ax = plt.subplots(figsize=(6, 4))
    x = [r[cost] for r in rows]
    y = [r[error] for r in rows]
    ax.loglog(x, y, "o-")
    for r, xi, yi in zip(rows, x, y):
        ax.annotate(str(r[label]), (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set_xlabel(cost)
    ax.set_ylabel(error)
    ax.grid(alpha=0.3, which="both")
    if title:
        ax.set_title(title)
    return save_figure(fig, path, dpi=120)


def plot_accuracy_cost_groups(path, rows: list[dict], cost: str, error: str, label: str,
                              group: str, title: str = "", *, marks: dict | None = None) -> Path:
    """Log-log error against cost, one line per value of ``group`` (e.g. the method),
    each point annotated with ``label`` (e.g. r). Non-finite errors are left out. ``marks``:
    ``{name: cost}`` drawn as labelled vertical lines (e.g. the full model's step)."""
    plt = pyplot()

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for k, (name, value) in enumerate((marks or {}).items()):
        if value is not None and np.isfinite(value) and value > 0:
            ax.axvline(value, color="0.4", ls=("--", ":", "-.")[k % 3], lw=1.0, label=str(name))
    for name in dict.fromkeys(r[group] for r in rows):
        sel = [r for r in rows if r[group] == name and np.isfinite(r[error]) and r[error] > 0]
        if not sel:
            continue
        x, y = [r[cost] for r in sel], [r[error] for r in sel]
        ax.loglog(x, y, "o-", label=str(name))
        for r, xi, yi in zip(sel, x, y):
            ax.annotate(str(r[label]), (xi, yi), textcoords="offset points", xytext=(3, 3), fontsize=7)
    ax.set_xlabel(cost)
    ax.set_ylabel(error)
    ax.grid(alpha=0.3, which="both")
    x_low, x_high = ax.get_xlim()
    if x_high > 10 * x_low:            # decade labels only: the minor ones overlap on wide axes
        from matplotlib.ticker import NullFormatter
        ax.xaxis.set_minor_formatter(NullFormatter())
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    return save_figure(fig, path, dpi=100)


def plot_forced_response(path, levels: list, *, output: str, measured=None, title: str = "") -> Path:
    """Amplitude (top) and phase (bottom) of one output's fundamental against frequency, one curve per
    force level, beside measured response-controlled levels; returns the path written (PNG, Agg).

    Parameters
    ----------
    path : str or Path
    levels : list of dict
        Stepped-sine rows (``force_n``, ``outputs[output]``: points with ``frequency_hz``,
        ``amplitude_m_s2``, ``phase_rad``), as :func:`femrom.study.harmonic_balance_sweep` gives.
    output : str
    measured : list of SteppedSineLevel, optional
        Drawn as points coloured by their force on the models' log colour scale
        (:func:`read_response_controlled`); their phase is
        the response's relative to the force as the file gives it, and the models' acceleration phase
        is drawn turned by ``-pi`` to the same convention.
    """
    if not levels:
        raise FemromValueError("levels must hold at least one stepped-sine row")
    plt = pyplot()
    fig, (ax_a, ax_p) = plt.subplots(2, 1, figsize=(6.8, 6.4), sharex=True)
    forces = [float(level["force_n"]) for level in levels]
    if measured:
        top = max(max(forces), max(float(np.max(m.force_n)) for m in measured))
    else:
        top = max(forces)
    from matplotlib.colors import LogNorm

    bottom = min(min(forces), min(float(np.min(m.force_n)) for m in measured) if measured else min(forces))
    norm = LogNorm(vmin=max(bottom, 1e-12), vmax=top)
    colour = plt.get_cmap("viridis")
    for level in levels:
        points = level["outputs"][output]
        f = [p["frequency_hz"] for p in points]
        c = colour(norm(float(level["force_n"])))
        ax_a.plot(f, [p["amplitude_m_s2"] for p in points], "-", color=c, lw=1.4, label=f"model {level['force_n']:g} N")
        ax_p.plot(f, np.mod(np.array([p["phase_rad"] for p in points]), 2 * np.pi) - np.pi, "-", color=c, lw=1.4)
    if measured:
        for m in measured:
            ax_a.scatter(m.frequency_hz, m.amplitude_m_s2, c=m.force_n, cmap=colour, norm=norm, s=9,
                         marker="o", edgecolors="none")
            ax_p.scatter(m.frequency_hz, m.phase_rad, c=m.force_n, cmap=colour, norm=norm, s=9, marker="o",
                         edgecolors="none")
        ax_a.plot([], [], "o", color="grey", ms=3, label="measured, constant amplitude (colour: force)")
    ax_a.set_ylabel(f"{output} amplitude [m/s^2]")
    ax_p.set_ylabel("phase of response to force [rad]")
    ax_p.set_xlabel("frequency [Hz]")
    for ax in (ax_a, ax_p):
        ax.grid(alpha=0.3)
    ax_a.legend(fontsize=7)
    if title:
        ax_a.set_title(title)
    return save_figure(fig, path, dpi=110)


def plot_backbones(path, backbones: dict, *, title: str = "", amplitude_label: str = "amplitude") -> Path:
    """Frequency (top) and damping ratio in % (bottom) against amplitude (log axis), one
    labelled curve per backbone, on shared axes; returns the path written (PNG, Agg).

    Parameters
    ----------
    path : str or Path
    backbones : dict of label -> Backbone
    title, amplitude_label : str
    """
    if not backbones:
        raise FemromValueError("backbones must name at least one Backbone")
    for label, backbone in backbones.items():
        if not isinstance(backbone, Backbone):
            raise FemromValueError(f"backbones[{label!r}] must be a Backbone, got {type(backbone).__name__}")
    plt = pyplot()
    fig, (ax_f, ax_z) = plt.subplots(2, 1, figsize=(6.4, 6.0), sharex=True)
    markers = ("o", "s", "^", "v", "D", "x")
    for n, (label, backbone) in enumerate(backbones.items()):
        positive = backbone.amplitude > 0
        style = dict(marker=markers[n % len(markers)], ms=3.5, lw=1.0, label=str(label))
        ax_f.plot(backbone.amplitude[positive], backbone.frequency_hz[positive], **style)
        ax_z.plot(backbone.amplitude[positive], 100 * backbone.damping_ratio[positive], **style)
    ax_f.set_xscale("log")
    ax_f.set_ylabel("frequency [Hz]")
    ax_z.set_ylabel("damping ratio [%]")
    ax_z.set_xlabel(amplitude_label)
    for ax in (ax_f, ax_z):
        ax.grid(alpha=0.3, which="both")
    ax_f.legend(fontsize=8)
    if title:
        ax_f.set_title(title, fontsize=10)
    return save_figure(fig, path, dpi=110)
