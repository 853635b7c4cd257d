"""Scene configuration: frozen dataclasses loaded from TOML.

A scene file lists a structure (geometry + mesh parameters + element), a
material (``[material]``, or ``[materials]``: one per region of the mesh), the
*effects* to simulate, boundary conditions, inputs, initial
conditions, the time window and the outputs to keep. Every key is checked: an
unknown key or effect is an error naming it and listing the valid ones.

This module holds the scene and its ``[structure]`` and ``[effects]``; each other
section has its module: ``[material]``/``[materials]`` (:mod:`._materials`),
``[boundary]``, ``[[inputs]]`` and ``[initial_conditions]`` (:mod:`._conditions`),
``[time]`` (:mod:`._time`), ``[outputs]`` (:mod:`._outputs`), ``[rom]`` (:mod:`._rom`),
``[sweep]`` (:mod:`._sweep`); :mod:`._tables` checks the keys and values of them all.

Example (``cases/beam.toml``)::

    name = "cantilever"
    [structure]
    geometry = "beam_line"
    element = "hermite"
    parameters = { length = 1.0, mesh_size = 0.02 }
    [material]
    youngs_modulus = 2.1e11
    density = 7850.0
    area = 1.0e-4
    second_moment = 8.33e-10
    [effects]
    inertia = { mass = "consistent" }
    bending = {}
    [boundary]
    clamped = ["left"]
    [initial_conditions]
    kind = "static_load"
    load = { kind = "point_load", at = "right", component = "w", magnitude = 10.0 }
    [time]
    t_end = 0.5
    dt = 1.0e-4
    integrator = "newmark"
    [outputs]
    probes = [{ name = "tip", at = "right", component = "w" }]
"""

from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from femrom.scene._conditions import BoundaryConfig, InitialConfig, InputConfig
from femrom.scene._effects import effect_class
from femrom.scene._errors import SceneError
from femrom.scene._materials import MaterialConfig, RegionMaterialConfig, materials_from_dict
from femrom.scene._outputs import OutputConfig
from femrom.scene._rom import RomConfig
from femrom.scene._sweep import SweepConfig, with_parameters
from femrom.scene._tables import as_number, one_of, take_table
from femrom.scene._time import TimeConfig

ELEMENTS = ("hermite", "p1", "p2")


@dataclass(frozen=True)
class StructureConfig:
    geometry: str
    element: str = "p1"
    parameters: tuple[tuple[str, float], ...] = ()

    @classmethod
    def from_dict(cls, data):
        d = take_table(data, "structure", {"geometry": None, "element": "p1", "parameters": {}}, ("geometry",))
        if not isinstance(d["parameters"], dict):
            raise SceneError(f"[structure] parameters must be a table of numbers, got {d['parameters']!r}")
        params = take_table(d["parameters"], "structure.parameters", dict(d["parameters"] or {}))
        if not isinstance(d["geometry"], str) or not d["geometry"]:
            raise SceneError(f"[structure] geometry must be a geometry name, got {d['geometry']!r}")
        return cls(d["geometry"], one_of(d["element"], ELEMENTS, "element"),
                   tuple(sorted((k, as_number(v, f"structure.parameters.{k}")) for k, v in params.items())))


@dataclass(frozen=True)
class EffectConfig:
    name: str
    options: tuple[tuple[str, Any], ...] = ()

    def option(self, key):
        return dict(self.options)[key]


def _effects_from_dict(data) -> tuple[EffectConfig, ...]:
    if not isinstance(data, dict) or not data:
        raise SceneError("[effects] must list at least 'inertia' and a stiffness effect")
    effects = []
    for name, options in data.items():
        effect = effect_class(name)
        opts = take_table(options, f"effects.{name}", effect.options)
        effect.check(opts)
        effects.append(EffectConfig(name, tuple(sorted(opts.items()))))
    return tuple(effects)


@dataclass(frozen=True)
class Scene:
    """A complete scene: what to build, what to simulate, what to keep, and (``rom``, the
    optional ``[rom]`` section, :class:`~femrom.scene.RomConfig`) which reduced models to learn,
    and (``sweep``, :class:`~femrom.scene.SweepConfig`) which runs to sweep."""

    name: str
    structure: StructureConfig
    material: MaterialConfig | None
    effects: tuple[EffectConfig, ...]
    time: TimeConfig
    boundary: BoundaryConfig = BoundaryConfig()
    inputs: tuple[InputConfig, ...] = ()
    initial_conditions: InitialConfig = InitialConfig()
    outputs: OutputConfig = OutputConfig()
    description: str = ""
    rom: RomConfig | None = None
    sweep: SweepConfig | None = None
    source_text: str = field(default="", repr=False, compare=False)
    materials: tuple[RegionMaterialConfig, ...] = ()

    SECTIONS = ("name", "description", "structure", "material", "materials", "effects", "boundary",
                "inputs", "initial_conditions", "time", "outputs", "rom", "sweep")

    @classmethod
    def from_dict(cls, data: dict, source_text: str = "") -> "Scene":
        unknown = sorted(set(data) - set(cls.SECTIONS))
        if unknown:
            raise SceneError(f"unknown section {unknown[0]!r}; valid sections: {', '.join(cls.SECTIONS)}")
        for required in ("structure", "effects", "time"):
            if required not in data:
                raise SceneError(f"missing section [{required}]")
        if ("material" in data) == ("materials" in data):
            raise SceneError("give one of [material] (one material) and [materials] (a material per region)"
                             if "material" in data else "missing section [material] (or [materials], by region)")
        effects = _effects_from_dict(data["effects"])
        inputs = tuple(InputConfig.from_dict(d, i) for i, d in enumerate(data.get("inputs", [])))
        input_names = [i.name for i in inputs]
        if len(set(input_names)) != len(input_names):
            raise SceneError(f"[[inputs]] names must be unique, got {input_names}")
        names = {e.name for e in effects}
        if inputs and "actuation" not in names:
            raise SceneError("the scene lists [[inputs]] but not the 'actuation' effect")
        if "actuation" in names and not inputs:
            raise SceneError("the 'actuation' effect needs at least one [[inputs]] entry")
        if data.get("rom") is not None and not any((data.get("outputs") or {}).get(kind)
                                                    for kind in ("probes", "averages", "lines")):
            raise SceneError("[rom] compares reduced and full outputs: list probes, averages or lines in [outputs]")
        name = data.get("name", "scene")
        if not isinstance(name, str) or not name.strip() or any(c in name for c in "/\\\0"):
            raise SceneError(f"name must be a non-empty string without path separators, got {name!r}")
        return cls(
            name=name,
            description=str(data.get("description", "")),
            structure=StructureConfig.from_dict(data["structure"]),
            material=MaterialConfig.from_dict(data["material"]) if "material" in data else None,
            materials=materials_from_dict(data["materials"]) if "materials" in data else (),
            effects=effects,
            boundary=BoundaryConfig.from_dict(data.get("boundary")),
            inputs=inputs,
            initial_conditions=InitialConfig.from_dict(data.get("initial_conditions")),
            time=TimeConfig.from_dict(data["time"]),
            outputs=OutputConfig.from_dict(data.get("outputs")),
            rom=None if data.get("rom") is None else RomConfig.from_dict(data["rom"], len(inputs)),
            sweep=None if data.get("sweep") is None else SweepConfig.from_dict(data["sweep"], data),
            source_text=source_text,
        )

    @classmethod
    def from_toml(cls, path) -> "Scene":
        """Load a scene file; errors name the file and the offending key.

        A geometry given as a relative ``.geo`` path is looked for next to the
        scene file first (then in the working directory and ``meshes/``).
        """
        path = Path(path)
        if path.is_dir():
            raise SceneError(f"{path}: is a directory, not a scene file")
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise SceneError(f"scene file not found: {path}") from None
        except UnicodeDecodeError as exc:
            raise SceneError(f"{path}: not a text (UTF-8) scene file: byte {exc.start} is {exc.object[exc.start]:#04x}") \
                from None
        except OSError as exc:
            raise SceneError(f"{path}: cannot be read: {exc.strerror}") from None
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise SceneError(f"{path}: invalid TOML: {exc}") from None
        try:
            scene = cls.from_dict(data, source_text=text)
        except SceneError as exc:
            raise SceneError(f"{path}: {exc}") from None
        # a geometry file named relative to the scene file (a user's .geo next to the scene)
        beside = path.parent / scene.structure.geometry
        if scene.structure.geometry.endswith(".geo") and not Path(scene.structure.geometry).is_absolute() \
                and beside.is_file():
            scene = replace(scene, structure=replace(scene.structure, geometry=str(beside.resolve())))
        return scene

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    def with_parameters(self, values) -> "Scene":
        """The scene with a sweep point's ``(path, value)`` pairs set (:class:`SweepConfig`)."""
        return with_parameters(self, values)

    def with_time(self, **changes) -> "Scene":
        """The scene with ``[time]`` entries replaced, e.g. ``scene.with_time(dt=1e-4, t_end=0.5)``."""
        return replace(self, time=replace(self.time, **changes))

    def with_geometry(self, **parameters) -> "Scene":
        """The scene with geometry parameters set (``[structure] parameters``, e.g. ``mesh_size=0.05``),
        the others kept; what a mesh ladder needs."""
        merged = dict(self.structure.parameters) | parameters
        return replace(self, structure=replace(self.structure, parameters=tuple(sorted(merged.items()))))

    def effect(self, name: str) -> EffectConfig | None:
        return next((e for e in self.effects if e.name == name), None)

    def to_dict(self) -> dict:
        """Plain-dict view (for metadata in result files)."""
        return asdict(self)
