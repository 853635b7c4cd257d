"""Reduced-model studies: FOM runs -> snapshot store -> basis -> learned and Galerkin ROMs -> errors, costs, report.

What the case scripts share, for any scene (``femrom run scene.toml`` with a
``[rom]`` section calls :func:`run_study`):

- runs: :func:`femrom.snapshots.run_fom` (one model, any input signals, fields streamed to a
  store, each step timed without the consumers) gives each :class:`~femrom.snapshots.FOMRun`;
- a study of extrapolation in time (train on a release's first window, predict far beyond it):
  :func:`extrapolation_config` (its learners :data:`EXTRAPOLATION_LEARNERS`, named
  :data:`EXTRAPOLATION_LEARNER_NAMES`),
  :func:`extrapolation_scene` (a scene with it);
- the study's steps: :func:`fom_runs`, :func:`pod_basis`, :func:`reduce_runs`,
  :func:`training_data`, :func:`fit_rom`, :func:`evaluate`, :func:`rom_costs`, :func:`study_costs`,
  :func:`study_rows`;
- canonical learners (``hopinf``) on conservative scenes: :func:`check_canonical_learners`,
  :func:`fit_canonical_rom`, :class:`SceneHamiltonianROM` (a Hamiltonian ROM on the
  mass-orthonormal basis, called like a second-order one);
- canonical Hamiltonian FOMs (no scene: a :class:`~femrom.integrators.CanonicalSystem`):
  :func:`run_canonical`, :func:`canonical_rows` (cotangent lift, H-OpInf, Galerkin and the
  unstructured baselines of :class:`CanonicalSpec`, training and extrapolation windows,
  invariant drifts, costs by timed blocks), :func:`canonical_time_step_ladder`,
  :func:`state_error`, :func:`mass_generator`, :func:`plot_invariant_drifts`;
- metrics (:func:`femrom.post.relative_error` beside them): :func:`mass_norm`, :class:`Projection` / :func:`project_run`
  (exact field errors at every r from one pass), :func:`energy_ratio`;
- over time on one run: :func:`state_energy` and :func:`reconstructed_energy_error` (the FOM
  energy of a ROM's reconstructed state), :func:`rom_table` (errors, energy errors and costs
  per learner and r), :func:`invariant_drift`, :func:`plot_energy_error_history`,
  :func:`plot_output_history`, :func:`plot_histories` (the pictures of a table),
  :func:`evaluate_runs` (a case's own ROM on every run, as the study's), :func:`extra_rom_rows`
  (a case's own ROMs as study rows, timed interleaved with the study's);
- learned nonlinear forces against a reference (the Galerkin-projected force):
  :func:`force_error`, :func:`conservative_acceleration`, :func:`nonlinear_forces`;
- linear models in one form (:mod:`femrom.study._linear_models`): :class:`LinearModelSpec`,
  :func:`fit_linear_model`, :func:`linear_model_rows` (second-order ROMs and identified DMDc, ERA,
  OKID models as discrete state spaces on every run: output errors, spectral radii, long-window
  stability, fit and step costs), :func:`state_space_data`, their table and figure
  (:func:`linear_model_table`, :func:`plot_linear_model_errors`);
- backbones against each other (:mod:`femrom.study._backbone_metrics`): :func:`compare_backbones`
  (both at common amplitudes, :class:`BackboneComparison`), :func:`backbone_errors` (shift and damping
  errors), :func:`backbone_shift` (one backbone between two amplitudes);
- hammer blows on a small stateful model: :func:`with_impulse`, :func:`output_ring_down` (the outputs'
  accelerations and ECSW snapshots, :class:`OutputRingDown`), :func:`ecsw_training`
  (:class:`ImpactTraining`), :func:`step_cost` (a large model's seconds per step after a blow);
  learned models against such a reference: :func:`reference_ring_down`,
  :func:`compare_ring_downs`;
- the jointed beam's facts and model chain, shared by its cases: :data:`JOINTED_BEAM`
  (:class:`BrakeReussBeam`), :class:`JointedBeamModel` (scene, calibration, Iwan joint, modal
  model, ECSW; :class:`CalibratedBeam`);
- stepped sines: :func:`stepped_sine_response` (one model beside its linearisation at rest),
  :func:`compare_stepped_sines` (models against a reference);
- MPC closed loops on a FOM, each controller model on each reference: :func:`closed_loop_rows`
  (:data:`CLOSED_LOOP_COLUMNS`), :func:`open_loop_error`;
- hyper-reduction: :func:`hyper_reduced_rows` (a learned ROM's known conservative force
  replaced by its ECSW-sampled potential, :data:`HYPER_COLUMNS`);
- costs: :class:`Cost` (the fastest of several timed blocks, and their quartiles),
  :func:`blocked_cost`, :func:`repeated_costs` (interleaved), :func:`call_cost` (of a function);
- the scene's own run: :func:`scene_run` (:class:`SceneRun`: response plot, energy drift,
  report section);
- the FOM's accuracy against its cost: :func:`time_step_ladder`, :func:`frequency_ladder`,
  :func:`natural_frequencies`, :func:`final_state`, :func:`final_state_ladders` (time steps
  against a fine run, meshes against an exact solution, in the mass norm at a final time),
  :func:`observed_order`, :func:`ladder_section` (a ladder's plot and report section,
  :func:`ladder_table` its text), :func:`time_step_section`, :func:`frequency_section`,
  :func:`final_state_section` (each with its ladder's columns);
- snapshots every k-th step (what another solver's output gives): :func:`subsampled_rows`
  (one learner from the displacements alone, from stored derivatives and from differences,
  read from the study's store every k-th column: :func:`every_kth`), :func:`subsampled_section`;
- sweeps: :func:`run_sweep` (a scene's ``[sweep]`` as Dask tasks, one store file
  per run, merged into one store; a killed worker's run reruns elsewhere);
- figures and report: :func:`plot_outputs`, :func:`plot_errors`, :func:`plot_error_history`,
  :func:`plot_energy`, :func:`plot_accuracy_cost`, :func:`render_fields`,
  :func:`write_report`.
"""

from femrom.study._learned_forces import force_error, nonlinear_forces
from femrom.study._figures import (
    plot_accuracy_cost,
    plot_invariant_drifts,
)
from femrom.study._extrapolation import (
    EXTRAPOLATION_LEARNER_NAMES,
    dispersion_error,
    extrapolation_config,
    extrapolation_scene,
)
from femrom.study._hamiltonian import (
    CanonicalSpec,
    canonical_rows,
    canonical_time_step_ladder,
    mass_generator,
    run_canonical,
)
from femrom.study._histories import (
    plot_histories,
    plot_output_history,
    reconstructed_energy_error,
    rom_table,
    state_energy,
)
from femrom.study._hyper import HYPER_COLUMNS, hyper_reduced_rows
from femrom.study._ladders import (
    final_state,
    final_state_ladders,
    final_state_section,
    frequency_ladder,
    frequency_section,
    natural_frequencies,
    observed_order,
    time_step_ladder,
    time_step_section,
)
from femrom.study._linear_models import linear_model_rows
from femrom.study._models import ModelSpec
from femrom.study._compare import compare_models
from femrom.study._metrics import Projection, invariant_drift, mass_norm
from femrom.study._pipeline import ROW_COLUMNS, StudyState, peak_rss_gb, run_study, swapped_rows
from femrom.study._forced import compare_stepped_sines, stepped_sine_response
from femrom.study._ring_downs import (
    RING_DOWN_COLUMNS,
    RingDown,
    RingDownComparison,
    compare_ring_downs,
    mass_pod,
    reference_ring_down,
    ring_down_data,
)
from femrom.study._backbone_metrics import backbone_errors, backbone_shift, compare_backbones
from femrom.study._impacts import (
    ecsw_training,
    output_ring_down,
    step_cost,
    with_impulse,
)
from femrom.study._jointed_beam import JOINTED_BEAM, CalibratedBeam, JointedBeamModel, modal_qsma
from femrom.study._closed_loops import CLOSED_LOOP_COLUMNS, closed_loop_rows, closed_loop_section, open_loop_error
from femrom.study._linear_model_figures import linear_model_section, linear_model_table
from femrom.study._scene_run import scene_run
from femrom.study._experiment import Experiment, register_experiment, registered_experiments, rest_start
from femrom.study.experiments.ring_down import RingDownTest
from femrom.study.experiments.stepped_sine import SteppedSineTest
from femrom.study.experiments.unseen_input import UnseenInput, evaluate, scored_columns
from femrom.study._study import (
    check_rom_config,
    fom_runs,
    pod_basis,
    projected_forces,
    reduce_runs,
    study_rows,
)
from femrom.study._canonical import check_canonical_learners
from femrom.study._subsampled import subsampled_rows, subsampled_section
from femrom.study._sweep import run_sweep, run_sweep_point, sweep_runs
from femrom._timing import Cost, blocked_cost, call_cost, repeated_cost, repeated_costs


__all__ = [
    "backbone_errors", "backbone_shift", "blocked_cost", "CalibratedBeam", "call_cost", "canonical_rows",
    "canonical_time_step_ladder", "CanonicalSpec", "check_canonical_learners", "check_rom_config",
    "CLOSED_LOOP_COLUMNS", "dispersion_error", "closed_loop_rows", "closed_loop_section", "compare_backbones", "compare_models", "compare_ring_downs",
    "compare_stepped_sines", "Cost", "ecsw_training", "evaluate", "Experiment", "extrapolation_config",
    "EXTRAPOLATION_LEARNER_NAMES", "extrapolation_scene", "final_state", "final_state_ladders",
    "final_state_section", "fom_runs", "force_error", "frequency_ladder", "frequency_section",
    "HYPER_COLUMNS", "hyper_reduced_rows", "invariant_drift", "JOINTED_BEAM", "JointedBeamModel",
    "linear_model_rows", "linear_model_section", "linear_model_table", "mass_generator", "mass_norm", "mass_pod", "modal_qsma",
    "ModelSpec", "natural_frequencies", "nonlinear_forces", "observed_order", "open_loop_error",
    "output_ring_down", "peak_rss_gb", "plot_accuracy_cost", "plot_histories", "plot_invariant_drifts",
    "plot_output_history", "pod_basis", "projected_forces",
    "Projection", "reconstructed_energy_error", "reduce_runs", "reference_ring_down",
    "register_experiment", "registered_experiments", "repeated_cost", "repeated_costs", "rest_start",
    "RING_DOWN_COLUMNS", "ring_down_data", "RingDown", "RingDownComparison", "RingDownTest", "rom_table",
    "ROW_COLUMNS", "run_canonical", "run_study", "run_sweep", "run_sweep_point", "scene_run",
    "scored_columns", "state_energy", "step_cost", "stepped_sine_response", "SteppedSineTest", "study_rows", "swapped_rows",
    "StudyState", "subsampled_rows", "subsampled_section", "sweep_runs", "time_step_ladder",
    "time_step_section", "UnseenInput", "with_impulse",
]
