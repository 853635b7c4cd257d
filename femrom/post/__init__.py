"""Post-processing: metrics files, plots of responses and energy, accuracy-vs-cost tables."""

from femrom.post._report import (
    accuracy_cost_table,
    plot_accuracy_cost,
    plot_response,
    write_metrics,
)

__all__ = ["accuracy_cost_table", "plot_accuracy_cost", "plot_response", "write_metrics"]
