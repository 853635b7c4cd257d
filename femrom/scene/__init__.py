"""Scenes: structure + material + effects + inputs + outputs -> SecondOrderSystem."""

from femrom.scene._build import FullOrderModel, build
from femrom.scene._config import (
    EFFECTS,
    INTEGRATORS,
    BoundaryConfig,
    EffectConfig,
    InitialConfig,
    InputConfig,
    LoadConfig,
    MaterialConfig,
    OutputConfig,
    ProbeConfig,
    Scene,
    StructureConfig,
    TimeConfig,
)
from femrom.scene._errors import SceneError
from femrom.scene._signals import Signal
from femrom.scene._system import SecondOrderSystem

__all__ = [
    "EFFECTS", "INTEGRATORS", "BoundaryConfig", "EffectConfig", "FullOrderModel", "InitialConfig",
    "InputConfig", "LoadConfig", "MaterialConfig", "OutputConfig", "ProbeConfig", "Scene",
    "SceneError", "SecondOrderSystem", "Signal", "StructureConfig", "TimeConfig", "build",
]
