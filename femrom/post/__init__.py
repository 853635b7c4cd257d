"""Post-processing: metrics files, plots of responses and energy, accuracy-vs-cost tables,
deformed-shape renders and ParaView time series; a ROM's prediction exported on the user's
mesh (:func:`export_prediction`: ``.pvd`` with the error field, outputs as CSV); backbone and
damping-vs-amplitude curves from ring-down signals (:func:`hilbert_backbone`,
:func:`peak_backbone`), from static solves by quasi-static modal analysis
(:func:`quasi_static_modal_analysis`; along a frictional joint's loading path: :func:`static_qsma`),
backbone maps (:func:`period_corrected`: a time scheme's period error removed; :func:`with_linear_damping`),
the linearised frequency response of a stuck joint (:func:`linear_accelerance`), figures of
closed loops (:func:`plot_closed_loops`, :func:`render_closed_loop`), the jointed-beam impact
data (:func:`read_hammer_impact`), and the public test data femrom fetches, checks and caches
(:func:`fetch_dataset`, :func:`dataset_dir`)."""

from femrom._json import jsonable
from femrom.post._backbone import (
    Backbone,
    default_trim,
    hilbert_backbone,
    peak_backbone,
    spectral_peaks,
)
from femrom.post._backbone_maps import epmc_backbone, period_corrected, with_linear_damping
from femrom.post._datasets import (
    DATASETS,
    Dataset,
    DatasetError,
    DatasetNotFoundError,
    data_cache_dir,
    dataset,
    dataset_dir,
    fetch_dataset,
)
from femrom.post._closed_loop_figures import plot_closed_loops, render_closed_loop
from femrom.post._export import export_prediction
from femrom.post._frf import linear_accelerance
from femrom.post._integrate import BandIntegrals, ModalRecord, band_limited_integrals, band_weights, modal_record
from femrom.post._impact import (
    ImpactRecord,
    brb_data_dir,
    measured_backbone,
    measured_spectral_peaks,
    read_hammer_impact,
)
from femrom.post._metrics import relative_error
from femrom.post._response_controlled import (
    SteppedSineLevel,
    phase_resonance,
    phase_resonance_backbone,
    read_response_controlled,
    resonance_force,
)
from femrom.post._output import OutputFolderError, staged_output
from femrom.post._plots import (
    plot_accuracy_cost,
    plot_accuracy_cost_groups,
    plot_backbones,
    plot_forced_response,
    plot_response,
    plot_space_time,
    plot_time_series,
    pyplot,
    save_figure,
)
from femrom.post._qsma import QuasiStaticBackbone, masing_damping, quasi_static_modal_analysis
from femrom.post._static_qsma import static_qsma
from femrom.post._render import (
    mesh_arrays,
    render_available,
    render_grid,
    vertex_displacements,
    write_vtu_series,
)
from femrom.post._report import accuracy_cost_table, machine_description, table_section, write_metrics

__all__ = [
    "relative_error",
    "DATASETS", "Dataset", "DatasetError", "DatasetNotFoundError", "data_cache_dir", "dataset", "dataset_dir",
    "fetch_dataset",
    "BandIntegrals", "band_limited_integrals", "band_weights", "ModalRecord", "modal_record",
           "accuracy_cost_table", "Backbone", "brb_data_dir", "default_trim", "export_prediction",
           "hilbert_backbone", "ImpactRecord", "jsonable", "machine_description", "masing_damping", "measured_backbone",
           "measured_spectral_peaks", "phase_resonance", "plot_forced_response", "phase_resonance_backbone", "read_response_controlled", "resonance_force", "SteppedSineLevel", "mesh_arrays", "OutputFolderError", "peak_backbone",
           "plot_accuracy_cost", "plot_accuracy_cost_groups", "plot_backbones", "plot_response", "plot_space_time",
           "plot_time_series", "pyplot", "QuasiStaticBackbone", "quasi_static_modal_analysis",
           "read_hammer_impact", "render_available", "render_grid",
           "save_figure", "spectral_peaks", "staged_output", "table_section", "vertex_displacements",
           "write_metrics", "write_vtu_series",
           "linear_accelerance", "period_corrected", "plot_closed_loops", "render_closed_loop", "static_qsma",
           "with_linear_damping", "epmc_backbone"]
