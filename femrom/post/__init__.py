"""Post-processing: metrics files, plots of responses and energy, accuracy-vs-cost tables,
deformed-shape renders and ParaView time series."""

from femrom.post._render import (
    mesh_arrays,
    render_available,
    render_grid,
    vertex_displacements,
    write_vtu_series,
)
from femrom.post._report import (
    accuracy_cost_table,
    plot_accuracy_cost,
    plot_response,
    write_metrics,
)

__all__ = ["accuracy_cost_table", "mesh_arrays", "plot_accuracy_cost", "plot_response",
           "render_available", "render_grid", "vertex_displacements", "write_metrics",
           "write_vtu_series"]
