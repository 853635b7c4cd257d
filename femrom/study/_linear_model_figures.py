"""The rows of :func:`femrom.study.linear_model_rows` as a table and a figure: output error against the
model size on each test run, one line per model."""

from __future__ import annotations

from pathlib import Path

from femrom.post import accuracy_cost_table, pyplot, save_figure

#: the report's table of the linear models: one line per (model, r), the test runs' errors side by side
LINEAR_MODEL_COLUMNS = ["model", "r", "state_order", "stable", "spectral_radius", "fit_seconds", "seconds_per_step"]


def linear_model_table(rows: list[dict]) -> list[dict]:
    """One line per (model, r): the output error on each test run side by side (columns named by the
    runs), the model's order, stability (on every run), spectral radius, fit time and step cost; a
    failed fit as ``stable: "fit failed: ..."``."""
    table = {}
    for row in rows:
        if "failed" in row:
            table[(row["model"], row["r"])] = {"model": row["model"], "r": row["r"],
                                               "stable": f"fit failed: {row['failed']}"}
            continue
        line = table.setdefault((row["model"], row["r"]), {
            "model": row["model"], "r": row["r"], "state_order": row["state_order"], "stable": row["stable"],
            "spectral_radius": row["spectral_radius"], "fit_seconds": row["fit_seconds"],
            "seconds_per_step": row["seconds_per_step"]})
        line[row["run"]] = row["test_output_error"]
        line["stable"] = line["stable"] and row["stable"]
    return list(table.values())


def plot_linear_model_errors(path, rows: list[dict], runs, title: str = "") -> Path:
    """Output error against r, one panel per test run of ``runs``, one line per model; the markers of
    unstable models hollow; errors above 1e3 drawn at 1e3."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(runs), figsize=(4.6 * len(runs), 3.8), squeeze=False, sharey=True)
    models = list(dict.fromkeys(row["model"] for row in rows if "failed" not in row))
    for ax, run in zip(axes[0], runs):
        for model, marker in zip(models, "osD^vx"):
            sel = [row for row in rows if row.get("run") == run and row["model"] == model]
            r = [row["r"] for row in sel]
            e = [min(row["test_output_error"], 1e3) for row in sel]
            line, = ax.semilogy(r, e, "-", label=model)
            for ri, ei, row in zip(r, e, sel):
                ax.plot(ri, ei, marker, color=line.get_color(), mfc=line.get_color() if row["stable"] else "none")
        ax.set_title(run, fontsize=9)
        ax.set_xlabel("r (2 r states)")
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].set_ylabel("relative output error (hollow: unstable)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path, dpi=110)


def linear_model_section(out_dir, rows: list[dict], runs, *, title: str, extension: float) -> str:
    """The report section of :func:`femrom.study.linear_model_rows`: ``comparison.png``
    (:func:`plot_linear_model_errors`) in ``out_dir`` and the table (:func:`linear_model_table`, the runs'
    errors after the model and size), with what "stable" and the costs mean."""
    plot_linear_model_errors(Path(out_dir) / "comparison.png", rows, list(runs), title)
    columns = LINEAR_MODEL_COLUMNS[:3] + list(runs) + LINEAR_MODEL_COLUMNS[3:]
    return ("## Linear models as discrete state spaces (output error on unseen inputs)\n\n"
            "Every model run from rest on each test input; stable: spectral radius <= 1 and, over "
            f"{extension:g}x the test window (the input zero after it), the free response in the "
            "second half no larger than the driven peak. "
            "Seconds per step: the state-space step, all models timed together.\n\n"
            + accuracy_cost_table(linear_model_table(rows), columns) + "\n\n![comparison](comparison.png)")
