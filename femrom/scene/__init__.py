"""Scenes: structure + material + effects + inputs + outputs -> SecondOrderSystem.

Effects are registered classes (:class:`Effect`, :func:`register_effect`):
one module each in the package ``femrom.scene.effects``, found by :func:`registered_effects`.

A scene has one ``[material]`` (:class:`MaterialConfig`) or ``[materials]``, a material per
region of the mesh (:class:`RegionMaterialConfig`), resolved to constants per element by
:func:`element_materials` (every element exactly one material). Its outputs are point probes,
region averages and lines of probes (:class:`LineConfig`: n points along a polyline, each
the mean of a component over its nearest nodes). Inputs sampled on a grid for training and
tests: :func:`multisine`, :func:`chirp`, :func:`band_limited_noise` (``array`` signals with a
raised-cosine onset, :func:`onset`).

A preloaded structure with a frictional joint (:mod:`femrom.scene._prestressed`):
:func:`prestressed_model` (build and :func:`preload` on point supports), :func:`with_law_parameters`,
:func:`mode_frequency` and :func:`calibrate_law_parameter` (a law parameter set by a measured
frequency), :func:`beam_mode_shapes`, :func:`clamped_iwan_joint` (the Iwan joint about the preload).
"""

from femrom.scene._build import FullOrderModel, build
from femrom.scene._conditions import BoundaryConfig, InitialConfig, InputConfig, LoadConfig
from femrom.scene._config import EffectConfig, Scene, StructureConfig
from femrom.scene._craig_bampton import CraigBampton, boundary_dofs_of, craig_bampton
from femrom.scene._effects import EFFECTS, Assembly, Effect, effect_class, register_effect, registered_effects
from femrom.scene._errors import SceneError
from femrom.scene._excitation import band_limited_noise, chirp, multisine, onset, sample_times, sampled_signal
from femrom.scene._materials import MaterialConfig, RegionMaterialConfig, element_materials
from femrom.scene._modal import BeamModeShape, Modes, beam_mode_shape, linearized_modes, tangent_stiffness
from femrom.scene._outputs import LineConfig, OutputConfig, ProbeConfig
from femrom.scene._prestressed import (
    PrestressedModel,
    beam_mode_shapes,
    calibrate_law_parameter,
    clamped_iwan_joint,
    mode_frequency,
    prestressed_model,
    with_law_parameters,
)
from femrom.scene._rom import BasisSpec, Derivatives, LearnerSpec, ReportSpec, RomConfig, RunSpec, TimingSpec
from femrom.scene._signals import Signal, SignalVector, half_sine_spectrum
from femrom.scene._static import Preload, StaticSolution, point_supports, preload, solve_static, with_friction_coefficient
from femrom.scene._sweep import SweepConfig
from femrom.scene._system import SecondOrderSystem
from femrom.scene._time import MAX_STEPS, TimeConfig

__all__ = [
    "MAX_STEPS",
    "EFFECTS", "Assembly", "BasisSpec", "BoundaryConfig", "Derivatives", "LearnerSpec", "ReportSpec",
    "RomConfig", "RunSpec", "CraigBampton", "boundary_dofs_of", "craig_bampton", "TimingSpec", "Effect", "EffectConfig", "FullOrderModel", "InitialConfig",
    "InputConfig", "LineConfig", "LoadConfig", "MaterialConfig", "OutputConfig", "ProbeConfig",
    "RegionMaterialConfig", "Scene", "element_materials",
    "SceneError", "SecondOrderSystem", "Signal", "SignalVector", "SweepConfig", "StructureConfig", "TimeConfig", "build",
    "band_limited_noise", "chirp", "multisine", "onset", "sample_times", "sampled_signal",
    "effect_class", "half_sine_spectrum", "register_effect", "registered_effects",
    "BeamModeShape", "Modes", "Preload", "StaticSolution", "beam_mode_shape", "linearized_modes",
    "point_supports", "preload", "solve_static", "tangent_stiffness", "with_friction_coefficient",
    "PrestressedModel", "beam_mode_shapes", "calibrate_law_parameter", "clamped_iwan_joint", "mode_frequency",
    "prestressed_model", "with_law_parameters",
]
