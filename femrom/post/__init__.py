"""Post-processing: metrics files, plots of responses and energy, accuracy-vs-cost tables,
deformed-shape renders and ParaView time series; a ROM's prediction exported on the user's
mesh (:func:`export_prediction`: ``.pvd`` with the error field, outputs as CSV)."""

from femrom._json import jsonable
from femrom.post._export import export_prediction
from femrom.post._output import OutputFolderError, staged_output
from femrom.post._render import (
    mesh_arrays,
    render_available,
    render_grid,
    vertex_displacements,
    write_vtu_series,
)
from femrom.post._report import (
    accuracy_cost_table,
    machine_description,
    plot_accuracy_cost,
    plot_accuracy_cost_groups,
    plot_response,
    plot_time_series,
    pyplot,
    save_figure,
    table_section,
    write_metrics,
)

__all__ = ["OutputFolderError", "accuracy_cost_table", "export_prediction", "staged_output", "jsonable", "machine_description", "mesh_arrays", "plot_accuracy_cost",
           "plot_accuracy_cost_groups", "plot_response", "plot_time_series", "pyplot", "render_available",
           "render_grid", "save_figure", "table_section", "vertex_displacements", "write_metrics", "write_vtu_series"]
