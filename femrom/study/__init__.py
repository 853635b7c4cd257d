"""Reduced-model studies: FOM runs -> snapshot store -> basis -> learned and Galerkin ROMs -> errors, costs, report.

The comparison engine (``docs/architecture.md``, "One comparison engine"):

- models: :class:`ModelSpec` (a registered learner's name, options, label; ``.fit(training, r)``
  from a :class:`~femrom.inference.TrainingSet` through the learner's ``for_training``);
- experiments: :class:`Experiment` (``run(model) -> metrics``), registered by
  :func:`register_experiment` (:func:`registered_experiments`): :class:`UnseenInput` (a run the
  model was not trained on, :func:`evaluate`, :func:`scored_columns`), :class:`RingDownTest`,
  :class:`SteppedSineTest` (``.compare(models)``), :class:`ClosedLoopTest` (MPC on the FOM), and
  ``canonical_window`` (a canonical FOM run's two windows, :func:`canonical_rows`' experiment);
  :func:`rest_start` (a projection of a stateful reference starts in its committed state);
- :func:`compare_models`: every spec at every r through every experiment, a row each.

What the case scripts share, for any scene (``femrom run scene.toml`` with a ``[rom]`` section
calls :func:`run_study`, :class:`StudyState` for its ``extend`` hook and experiments):

- the study's steps: :func:`check_rom_config`, :func:`fom_runs`, :func:`pod_basis`,
  :func:`reduce_runs`, :func:`study_rows` (every ``[rom]`` learner and experiment, costs
  interleaved; :data:`ROW_COLUMNS`), :func:`swapped_rows` (training and test swapped);
- extrapolation in time: :func:`extrapolation_config`, :func:`extrapolation_scene`
  (:data:`EXTRAPOLATION_LEARNER_NAMES`), :func:`dispersion_error` (the floor of a learner that
  fits a scheme's discrete frequencies);
- canonical Hamiltonian FOMs (a :class:`~femrom.integrators.CanonicalSystem`): :func:`run_canonical`,
  :func:`canonical_rows` (the models of :class:`CanonicalSpec`, by the learner registry),
  :func:`canonical_time_step_ladder`, :func:`mass_generator`, :func:`plot_invariant_drifts`;
- metrics: :func:`mass_norm`, :class:`Projection` (exact field errors at every r from one pass),
  :func:`invariant_drift`; over time on one run: :func:`state_energy`,
  :func:`reconstructed_energy_error`, :func:`rom_table`, :func:`plot_histories`,
  :func:`plot_output_history`; learned forces: :func:`force_error`, :func:`nonlinear_forces`, and where a learned nonlinear
  model's error comes from against a true one: :func:`spml_error_split` (:class:`SpMLErrorSplit`,
  :func:`acceleration_residual`, :func:`modal_rates`);
- linear models as discrete state spaces on every run: :func:`linear_model_rows` (second-order
  ROMs and DMDc, ERA, OKID), :func:`linear_model_section`; MPC closed loops on a FOM:
  :func:`closed_loop_rows`, :func:`closed_loop_section` (:data:`CLOSED_LOOP_COLUMNS`);
- backbones: :func:`compare_backbones`, :func:`backbone_errors`, :func:`backbone_shift`;
- blows on a small stateful model: :func:`with_impulse`, :func:`output_ring_down`,
  :func:`ecsw_training`, :func:`step_cost`, :func:`reference_ring_down` (:class:`RingDown`),
  :func:`mass_pod`, :func:`ring_down_data`, :func:`compare_ring_downs` (:class:`RingDownComparison`,
  :data:`RING_DOWN_COLUMNS`);
- the jointed beam's facts and model chain: :data:`JOINTED_BEAM`, :class:`JointedBeamModel`
  (:class:`CalibratedBeam`), :func:`modal_qsma`;
- stepped sines: :func:`stepped_sine_response` (one model beside its linearisation at rest),
  :func:`compare_stepped_sines` (shakers against a reference);
- hyper-reduction: :func:`hyper_reduced_rows` (:data:`HYPER_COLUMNS`);
- costs: :class:`Cost`, :func:`blocked_cost`, :func:`repeated_cost`, :func:`repeated_costs`
  (interleaved), :func:`call_cost`, :func:`peak_rss_gb`;
- the scene's own run: :func:`scene_run`; the FOM's accuracy against its cost:
  :func:`time_step_ladder`, :func:`frequency_ladder`, :func:`natural_frequencies`,
  :func:`final_state`, :func:`final_state_ladders`, :func:`observed_order`,
  :func:`time_step_section`, :func:`frequency_section`, :func:`final_state_section`;
- snapshots every k-th step: :func:`subsampled_rows`, :func:`subsampled_section`;
- sweeps: :func:`run_sweep`, :func:`run_sweep_point`, :func:`sweep_runs` (a scene's ``[sweep]``
  as Dask tasks);
- figures: :func:`plot_accuracy_cost`.
"""

from femrom.study._learned_forces import force_error, nonlinear_forces
from femrom.study._spml_split import SpMLErrorSplit, acceleration_residual, modal_rates, spml_error_split
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
from femrom.study._forced import compare_stepped_sines, harmonic_balance_sweep, periodic_training, stepped_sine_response
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
from femrom.study._jointed_beam import JOINTED_BEAM, CalibratedBeam, JointedBeamModel, MeasuredRangeJoint, modal_qsma, \
    with_attached_mass
from femrom.study._closed_loops import CLOSED_LOOP_COLUMNS, closed_loop_rows, closed_loop_section
from femrom.study._linear_model_figures import linear_model_section
from femrom.study._scene_run import scene_run
from femrom.study._experiment import Experiment, register_experiment, registered_experiments, rest_start
from femrom.study.experiments.closed_loop import ClosedLoopTest
from femrom.study.experiments.ring_down import RingDownTest
from femrom.study.experiments.stepped_sine import SteppedSineTest
from femrom.study.experiments.unseen_input import UnseenInput, evaluate, scored_columns
from femrom.study._study import (
    check_rom_config,
    fom_runs,
    pod_basis,
    reduce_runs,
    study_rows,
)
from femrom.study._subsampled import subsampled_rows, subsampled_section
from femrom.study._sweep import run_sweep, run_sweep_point, sweep_runs
from femrom._timing import Cost, blocked_cost, call_cost, repeated_cost, repeated_costs


__all__ = [
    "backbone_errors", "backbone_shift", "blocked_cost", "CalibratedBeam", "call_cost", "canonical_rows",
    "canonical_time_step_ladder", "CanonicalSpec", "check_rom_config",
    "CLOSED_LOOP_COLUMNS", "dispersion_error", "ClosedLoopTest", "closed_loop_rows", "closed_loop_section", "compare_backbones", "compare_models", "compare_ring_downs",
    "compare_stepped_sines", "Cost", "ecsw_training", "evaluate", "Experiment", "extrapolation_config",
    "EXTRAPOLATION_LEARNER_NAMES", "extrapolation_scene", "final_state", "final_state_ladders",
    "final_state_section", "fom_runs", "force_error", "spml_error_split", "SpMLErrorSplit", "acceleration_residual", "modal_rates", "frequency_ladder", "frequency_section",
    "HYPER_COLUMNS", "hyper_reduced_rows", "invariant_drift", "JOINTED_BEAM", "JointedBeamModel",
    "linear_model_rows", "linear_model_section", "mass_generator", "mass_norm", "mass_pod", "modal_qsma",
    "ModelSpec", "natural_frequencies", "nonlinear_forces", "observed_order",
    "output_ring_down", "peak_rss_gb", "plot_accuracy_cost", "plot_histories", "plot_invariant_drifts",
    "plot_output_history", "pod_basis",
    "Projection", "reconstructed_energy_error", "reduce_runs", "reference_ring_down",
    "register_experiment", "registered_experiments", "repeated_cost", "repeated_costs", "rest_start",
    "RING_DOWN_COLUMNS", "ring_down_data", "RingDown", "RingDownComparison", "RingDownTest", "rom_table",
    "ROW_COLUMNS", "run_canonical", "run_study", "run_sweep", "run_sweep_point", "scene_run",
    "scored_columns", "state_energy", "step_cost", "stepped_sine_response", "harmonic_balance_sweep", "periodic_training", "MeasuredRangeJoint", "with_attached_mass", "SteppedSineTest", "study_rows", "swapped_rows",
    "StudyState", "subsampled_rows", "subsampled_section", "sweep_runs", "time_step_ladder",
    "time_step_section", "UnseenInput", "with_impulse",
]
