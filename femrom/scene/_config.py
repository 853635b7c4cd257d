"""Scene configuration: frozen dataclasses loaded from TOML.

A scene file lists a structure (geometry + mesh parameters + element), a
material (``[material]``, or ``[materials]``: one per region of the mesh), the
*effects* to simulate, boundary conditions, inputs, initial
conditions, the time window and the outputs to keep. Every key is checked: an
unknown key or effect is an error naming it and listing the valid ones.

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

import math

import numpy as np
import tomllib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from femrom.scene._effects import effect_class
from femrom.scene._errors import SceneError
from femrom.scene._errors import take_table as _take
from femrom.scene._rom import RomConfig
from femrom.scene._sweep import SweepConfig, with_parameters
from femrom.scene._signals import Signal
from femrom.solvers import strategies

ELEMENTS = ("hermite", "p1", "p2")
FIELDS = ("displacement", "velocity", "acceleration")
LOAD_KINDS = ("point_load", "surface_traction", "surface_pressure")
INITIAL_KINDS = ("zero", "static_load", "mode", "expression")


def _number(value, where: str) -> float:
    """A finite real number (not a bool or a string), or a SceneError naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SceneError(f"[{where.rsplit('.', 1)[0]}] {where.rsplit('.', 1)[-1]} must be a finite number, "
                         f"got {value!r}")
    return float(value)


def _vector(value, where: str) -> tuple[float, ...]:
    """A point or direction: a list of finite numbers."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise SceneError(f"[{where.rsplit('.', 1)[0]}] {where.rsplit('.', 1)[-1]} must be a list of numbers, "
                         f"got {value!r}")
    return tuple(_number(x, where) for x in value)


def _names(value, where: str) -> tuple[str, ...]:
    """A list of names (boundaries, fields): a lone string is refused, not split into letters."""
    if isinstance(value, str) or not isinstance(value, (list, tuple)) or \
            not all(isinstance(x, str) and x for x in value):
        raise SceneError(f"[{where.rsplit('.', 1)[0]}] {where.rsplit('.', 1)[-1]} must be a list of names, "
                         f"got {value!r}")
    return tuple(value)


def _choice(value, valid, what):
    if value not in valid:
        raise SceneError(f"unknown {what} {value!r}; valid: {', '.join(valid)}")
    return value


@dataclass(frozen=True)
class StructureConfig:
    geometry: str
    element: str = "p1"
    parameters: tuple[tuple[str, float], ...] = ()

    @classmethod
    def from_dict(cls, data):
        d = _take(data, "structure", {"geometry": None, "element": "p1", "parameters": {}}, ("geometry",))
        if not isinstance(d["parameters"], dict):
            raise SceneError(f"[structure] parameters must be a table of numbers, got {d['parameters']!r}")
        params = _take(d["parameters"], "structure.parameters", dict(d["parameters"] or {}))
        if not isinstance(d["geometry"], str) or not d["geometry"]:
            raise SceneError(f"[structure] geometry must be a geometry name, got {d['geometry']!r}")
        return cls(d["geometry"], _choice(d["element"], ELEMENTS, "element"),
                   tuple(sorted((k, _number(v, f"structure.parameters.{k}")) for k, v in params.items())))


@dataclass(frozen=True)
class MaterialConfig:
    """Isotropic linear-elastic material (SI). Line structures use ``area`` and
    ``second_moment``: bending rigidity ``E I``, axial rigidity ``E A``, mass
    per length ``rho A``."""

    youngs_modulus: float
    density: float
    poisson_ratio: float | None = None
    area: float | None = None
    second_moment: float | None = None

    @classmethod
    def from_dict(cls, data):
        keys = {"youngs_modulus": None, "density": None, "poisson_ratio": None,
                "area": None, "second_moment": None}
        d = _take(data, "material", keys, ("youngs_modulus", "density"))
        return cls(**_material_constants(d, "material"))


def _material_constants(d: dict, where: str) -> dict:
    """The material numbers of table ``[where]`` as floats (None kept), or one SceneError naming the key."""
    for k, v in d.items():
        if v is None:
            continue
        number = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        if k == "poisson_ratio":     # the elasticity form is positive definite for -1 < nu < 1/2
            if not (number and -1.0 < v < 0.5):
                raise SceneError(f"[{where}] poisson_ratio must lie in (-1, 0.5), got {v!r}")
        elif not (number and v > 0):
            raise SceneError(f"[{where}] {k} must be a finite positive number, got {v!r}")
    return {k: (None if v is None else float(v)) for k, v in d.items()}


@dataclass(frozen=True)
class RegionMaterialConfig:
    """One entry of ``[materials]``: an isotropic solid material on named regions (SI).

    ``[materials.<label>]`` gives ``youngs_modulus``, ``poisson_ratio``,
    ``density`` and optionally ``regions``, the physical volumes of the mesh it
    fills (default: the one region named ``label``). Every element of the
    mesh must get exactly one material (checked when the scene is built,
    :func:`femrom.scene.element_materials`).
    """

    label: str
    regions: tuple[str, ...]
    youngs_modulus: float
    poisson_ratio: float
    density: float


def _materials_from_dict(data) -> tuple[RegionMaterialConfig, ...]:
    """``[materials]``: a table of material tables, each on its regions; a region listed twice is an error."""
    if not isinstance(data, dict) or not data:
        raise SceneError("[materials] must be a table of [materials.<region>] tables, e.g. "
                         "[materials.body] youngs_modulus = 2e6, poisson_ratio = 0.45, density = 1100")
    materials, owner = [], {}
    for label, table in data.items():
        where = f"materials.{label}"
        d = _take(table, where, {"youngs_modulus": None, "poisson_ratio": None, "density": None,
                                 "regions": [label]}, ("youngs_modulus", "poisson_ratio", "density"))
        regions = _names(d.pop("regions"), f"{where}.regions")
        for region in regions:
            if region in owner:
                raise SceneError(f"[materials] region {region!r} has two materials: "
                                 f"[materials.{owner[region]}] and [{where}]")
            owner[region] = label
        materials.append(RegionMaterialConfig(label, regions, **_material_constants(d, where)))
    return tuple(materials)


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
        opts = _take(options, f"effects.{name}", effect.options)
        effect.check(opts)
        effects.append(EffectConfig(name, tuple(sorted(opts.items()))))
    return tuple(effects)


@dataclass(frozen=True)
class LoadConfig:
    """A spatial load pattern: one column of ``B`` (or a static load).

    ``at`` is a boundary name or a point ``[x, y, z]``; ``component`` is the
    displacement component (``w``/``slope`` on beams, ``u`` on bars, ``x``/``y``/``z``
    on solids) or ``direction`` a vector for tractions. ``magnitude`` scales it.
    """

    kind: str
    at: Any
    component: str | None = None
    direction: tuple[float, ...] | None = None
    magnitude: float = 1.0

    @classmethod
    def from_dict(cls, data, where):
        d = _take(data, where, {"kind": "point_load", "at": None, "component": None,
                                "direction": None, "magnitude": 1.0}, ("at",))
        _choice(d["kind"], LOAD_KINDS, f"load kind in [{where}]")
        at = d["at"] if isinstance(d["at"], str) else _vector(d["at"], f"{where}.at")
        direction = None if d["direction"] is None else _vector(d["direction"], f"{where}.direction")
        if d["kind"] == "surface_traction" and direction is None:
            raise SceneError(f"[{where}] a surface_traction needs a 'direction' vector")
        if d["component"] is not None and not isinstance(d["component"], str):
            raise SceneError(f"[{where}] component must be a component name, got {d['component']!r}")
        return cls(d["kind"], at, d["component"], direction, _number(d["magnitude"], f"{where}.magnitude"))


@dataclass(frozen=True)
class InputConfig:
    """One input ``u_j(t)``: its signal and its column of ``B``.

    ``load`` is one load table or an array of them; the column is their sum,
    ``b_j = sum_l f_l``, so one input can drive several surfaces with signs
    (antagonistic chambers: ``magnitude = 1`` on one, ``-1`` on the other).
    ``load`` is the first, ``extra_loads`` the rest; :attr:`loads` all of them.
    """

    name: str
    load: LoadConfig
    signal: Signal
    extra_loads: tuple[LoadConfig, ...] = ()

    @classmethod
    def from_dict(cls, data, index):
        where = f"inputs[{index}]"
        d = _take(data, where, {"name": f"u{index}", "load": None, "signal": None}, ("load", "signal"))
        tables = d["load"] if isinstance(d["load"], list) else [d["load"]]
        if not tables:
            raise SceneError(f"[{where}] 'load' is an empty array; give at least one load table")
        loads = [LoadConfig.from_dict(t, f"{where}.load[{k}]" if len(tables) > 1 else f"{where}.load")
                 for k, t in enumerate(tables)]
        return cls(str(d["name"]), loads[0], Signal.from_dict(d["signal"], f"{where}.signal"),
                   tuple(loads[1:]))

    @property
    def loads(self) -> tuple[LoadConfig, ...]:
        return (self.load, *self.extra_loads)


@dataclass(frozen=True)
class BoundaryConfig:
    """Homogeneous Dirichlet conditions on named boundaries.

    ``clamped``: every dof (beam: deflection and slope; solid: x, y, z).
    ``pinned``: displacement dofs only (beam: deflection; solid: same as clamped).
    """

    clamped: tuple[str, ...] = ()
    pinned: tuple[str, ...] = ()

    @classmethod
    def from_dict(cls, data):
        d = _take(data, "boundary", {"clamped": [], "pinned": []})
        return cls(_names(d["clamped"], "boundary.clamped"), _names(d["pinned"], "boundary.pinned"))


@dataclass(frozen=True)
class InitialConfig:
    """Initial displacement and velocity.

    kinds: ``zero``; ``static_load`` (``q0 = K^-1 f`` of a load, at rest);
    ``mode`` (eigenmode ``index`` (1-based) scaled to a peak ``amplitude``);
    ``expression`` (numpy expressions of ``x, y, z, pi`` for ``displacement``
    and ``velocity`` of one ``component``).
    """

    kind: str = "zero"
    load: LoadConfig | None = None
    index: int = 1
    amplitude: float = 1.0
    component: str | None = None
    displacement: str = "0"
    velocity: str = "0"

    @classmethod
    def from_dict(cls, data):
        d = _take(data, "initial_conditions", {"kind": "zero", "load": None, "index": 1, "amplitude": 1.0,
                                               "component": None, "displacement": "0", "velocity": "0"})
        _choice(d["kind"], INITIAL_KINDS, "initial condition kind")
        load = None
        if d["kind"] == "static_load":
            if d["load"] is None:
                raise SceneError("[initial_conditions] kind 'static_load' needs a 'load' table")
            load = LoadConfig.from_dict(d["load"], "initial_conditions.load")
        if isinstance(d["index"], bool) or not isinstance(d["index"], int) or d["index"] < 1:
            raise SceneError(f"[initial_conditions] index must be a mode number (1-based), got {d['index']!r}")
        return cls(d["kind"], load, d["index"], _number(d["amplitude"], "initial_conditions.amplitude"),
                   d["component"],
                   str(d["displacement"]), str(d["velocity"]))


#: The most steps one run may take: 1e8 steps of a 1e3-dof model are ~1e5 s of stepping; beyond
#: that a window is a mistake (dt = 1e-14 over 0.01 s asks for 1e12) more often than a plan.
MAX_STEPS = 1e8


@dataclass(frozen=True)
class TimeConfig:
    """The time window and scheme. ``integrator`` names a scheme registered in
    :mod:`femrom.integrators` (checked there, by ``scheme_for``: the scene layer
    sits below the integrators); ``spectral_radius`` is generalized-alpha's."""

    t_end: float
    dt: float
    integrator: str = "newmark"
    spectral_radius: float = 0.8
    solver: str = "auto"

    @classmethod
    def from_dict(cls, data):
        d = _take(data, "time", {"t_end": None, "dt": None, "integrator": "newmark",
                                 "spectral_radius": 0.8, "solver": "auto"}, ("t_end", "dt"))
        if not isinstance(d["integrator"], str) or not d["integrator"]:
            raise SceneError(f"[time] integrator must be a scheme name, got {d['integrator']!r}")
        for key in ("t_end", "dt", "spectral_radius"):
            v = d[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise SceneError(f"[time] {key} must be a finite number, got {v!r}")
        if not (0 < float(d["dt"]) <= float(d["t_end"])):
            raise SceneError(f"[time] needs 0 < dt <= t_end, got dt={d['dt']}, t_end={d['t_end']}")
        steps = float(d["t_end"]) / float(d["dt"])
        if steps > MAX_STEPS:
            raise SceneError(f"[time] t_end / dt = {steps:.3g} steps, more than femrom runs in one go "
                             f"({MAX_STEPS:.0e}); raise dt or split the window")
        if not 0 <= float(d["spectral_radius"]) <= 1:
            raise SceneError(f"[time] spectral_radius must lie in [0, 1], got {d['spectral_radius']}")
        if d["solver"] not in strategies():
            raise SceneError(f"[time] unknown solver {d['solver']!r}; valid: {', '.join(strategies())}")
        return cls(float(d["t_end"]), float(d["dt"]), d["integrator"], float(d["spectral_radius"]), d["solver"])

    @property
    def n_steps(self) -> int:
        return int(round(self.t_end / self.dt))


@dataclass(frozen=True)
class ProbeConfig:
    """One output row: ``component`` at point ``at`` (interpolated; with ``nodes >= 1`` the
    mean over the ``nodes`` nearest nodes), or (``average``) its mean over region ``at``."""

    name: str
    at: Any
    component: str | None = None
    average: bool = False
    nodes: int = 0


@dataclass(frozen=True)
class LineConfig:
    """A line of probes: ``points`` points equally spaced by arc length along a polyline
    ``path`` (both ends included), each read as the mean of one displacement component over
    its ``nodes`` nearest nodes, for each of ``components``.

    Expands to the outputs ``<name>_<i>_<component>``, ``i = 00, 01, ...`` from the path's
    first vertex, point by point (all components of point 0, then point 1, ...).
    """

    name: str
    path: tuple[tuple[float, ...], ...]
    points: int
    components: tuple[str, ...]
    nodes: int = 1

    @classmethod
    def from_dict(cls, data, index: int) -> "LineConfig":
        where = f"outputs.lines[{index}]"
        d = _take(data, where, {"name": None, "start": None, "end": None, "path": None, "points": None,
                                "components": None, "nodes": 1}, ("name", "points", "components"))
        if not isinstance(d["name"], str) or not d["name"] or any(c in d["name"] for c in "/\\\0"):
            raise SceneError(f"[{where}] name must be a non-empty string, got {d['name']!r}")
        if d["path"] is not None and (d["start"] is not None or d["end"] is not None):
            raise SceneError(f"[{where}] give 'path' (a polyline) or 'start' and 'end', not both")
        if d["path"] is None:
            if d["start"] is None or d["end"] is None:
                raise SceneError(f"[{where}] needs 'start' and 'end' points (or a 'path' polyline)")
            vertices = [d["start"], d["end"]]
        else:
            vertices = d["path"]
            if isinstance(vertices, (str, bytes)) or not isinstance(vertices, (list, tuple)) or len(vertices) < 2:
                raise SceneError(f"[{where}] path must list at least two points [x, y, z], got {vertices!r}")
        path = tuple(_vector(v, f"{where}.path") for v in vertices)
        if any(len(v) != len(path[0]) for v in path):
            raise SceneError(f"[{where}] the points of the path have different dimensions: {path}")
        lengths = [math.dist(a, b) for a, b in zip(path[:-1], path[1:])]
        if min(lengths) <= 0:
            raise SceneError(f"[{where}] the path has two equal consecutive points; its pieces need a length")
        for key, low in (("points", 2), ("nodes", 1)):
            v = d[key]
            if isinstance(v, bool) or not isinstance(v, int) or v < low:
                raise SceneError(f"[{where}] {key} must be a whole number >= {low}, got {v!r}")
        components = _names(d["components"], f"{where}.components")
        if len(set(components)) != len(components):
            raise SceneError(f"[{where}] components are listed twice: {list(components)}")
        return cls(d["name"], path, d["points"], components, d["nodes"])

    def locations(self) -> np.ndarray:
        """(points, dim) ndarray: the points, equally spaced by arc length, both ends included."""
        path = np.asarray(self.path, dtype=float)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
        s = np.linspace(0.0, arc[-1], self.points)
        return np.stack([np.interp(s, arc, path[:, k]) for k in range(path.shape[1])], axis=1)

    def probes(self) -> tuple[ProbeConfig, ...]:
        """One :class:`ProbeConfig` per point and component, named ``<name>_<i>_<component>``."""
        digits = max(2, len(str(self.points - 1)))
        return tuple(ProbeConfig(f"{self.name}_{i:0{digits}d}_{c}", tuple(float(v) for v in x), c, nodes=self.nodes)
                     for i, x in enumerate(self.locations()) for c in self.components)


@dataclass(frozen=True)
class OutputConfig:
    """What a run keeps: probes (``E`` rows), full fields, energy; nothing else.

    ``probes`` holds every output row in order: the point probes, the averages, then the
    expanded lines of probes (``lines`` keeps the lines as written)."""

    probes: tuple[ProbeConfig, ...] = ()
    fields: tuple[str, ...] = ()
    energy: bool = True
    save_every: int = 1
    lines: tuple[LineConfig, ...] = ()

    @classmethod
    def from_dict(cls, data):
        d = _take(data, "outputs", {"probes": [], "averages": [], "lines": [], "fields": [], "energy": True,
                                    "save_every": 1})
        probes = []
        for kind, entries in (("probes", d["probes"]), ("averages", d["averages"])):
            for i, p in enumerate(entries):
                where = f"outputs.{kind}[{i}]"
                key = "at" if kind == "probes" else "over"
                allowed = {"name": f"{kind[:-1]}{i}", key: None, "component": None}
                if kind == "probes":
                    allowed["nodes"] = 0
                e = _take(p, where, allowed, (key,))
                at = e[key] if isinstance(e[key], str) else _vector(e[key], f"{where}.{key}")
                if not isinstance(e["name"], str) or not e["name"]:
                    raise SceneError(f"[{where}] name must be a non-empty string, got {e['name']!r}")
                nodes = e.get("nodes", 0)
                if isinstance(nodes, bool) or not isinstance(nodes, int) or nodes < 0:
                    raise SceneError(f"[{where}] nodes must be a whole number >= 0 (0: interpolate at the point), "
                                     f"got {nodes!r}")
                probes.append(ProbeConfig(e["name"], at, e["component"], kind == "averages", nodes))
        if not isinstance(d["lines"], list):
            raise SceneError(f"[outputs] lines must be an array of tables ([[outputs.lines]]), got {d['lines']!r}")
        lines = tuple(LineConfig.from_dict(line, i) for i, line in enumerate(d["lines"]))
        for line in lines:
            probes.extend(line.probes())
        names = [p.name for p in probes]
        if len(set(names)) != len(names):
            raise SceneError(f"[outputs] output names must be unique, got {names}")
        for f in _names(d["fields"], "outputs.fields"):
            _choice(f, FIELDS, "output field")
        every = d["save_every"]
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise SceneError(f"[outputs] save_every must be a whole number >= 1, got {every!r}")
        if not isinstance(d["energy"], bool):
            raise SceneError(f"[outputs] energy must be true or false, got {d['energy']!r}")
        return cls(tuple(probes), tuple(d["fields"]), d["energy"], every, lines)


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
            materials=_materials_from_dict(data["materials"]) if "materials" in data else (),
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
        try:
            text = path.read_text()
        except FileNotFoundError:
            raise SceneError(f"scene file not found: {path}") from None
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
