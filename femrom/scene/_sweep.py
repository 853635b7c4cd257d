"""The ``[sweep]`` section: many full-order runs of one scene, over input and material parameters.

Example::

    [sweep]
    mode = "grid"                  # every combination; "zip": the i-th values together
    fields = ["q"]                 # what each run streams to the store
    parameters = { "inputs.0.signal.amplitude" = [1.0e4, 2.0e4], "material.youngs_modulus" = [0.9e6, 1.1e6] }

Parameter paths: ``material.<key>`` (a number of ``[material]``), ``materials.<name>.<key>``
(a number of ``[materials.<name>]``),
``inputs.<i>.signal.<key>`` (a number of the i-th input's signal), and
``effects.<name>.<key>`` (a number among a listed effect's options). The mesh
and the time window stay those of the scene: every run has the same dofs and
steps, so all of them go into one snapshot store.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

from femrom.scene._effects import effect_class
from femrom.scene._errors import SceneError
from femrom.scene._materials import material_constants
from femrom.scene._signals import Signal

MODES = ("grid", "zip")
STATE_FIELDS = ("q", "v", "a")


@dataclass(frozen=True)
class SweepConfig:
    """Parameter values by path, combined as a grid or zipped; the fields each run stores."""

    parameters: tuple[tuple[str, tuple[float, ...]], ...]
    mode: str = "grid"
    fields: tuple[str, ...] = ("q",)

    @classmethod
    def from_dict(cls, data, scene_data: dict) -> "SweepConfig":
        if not isinstance(data, dict):
            raise SceneError(f"[sweep] must be a table, got {type(data).__name__}")
        allowed = ("parameters", "mode", "fields")
        unknown = sorted(set(data) - set(allowed))
        if unknown:
            raise SceneError(f"unknown key {unknown[0]!r} in [sweep]; valid keys: {', '.join(allowed)}")
        mode = data.get("mode", "grid")
        if mode not in MODES:
            raise SceneError(f"[sweep] unknown mode {mode!r}; valid: {', '.join(MODES)}")
        fields = data.get("fields", ["q"])
        if not isinstance(fields, list) or "q" not in fields or any(f not in STATE_FIELDS for f in fields):
            raise SceneError(f"[sweep] fields must list 'q' and any of v, a; got {fields!r}")
        parameters = data.get("parameters")
        if not isinstance(parameters, dict) or not parameters:
            raise SceneError("[sweep] needs 'parameters': a table of path = [values]")
        checked = []
        for path, values in parameters.items():
            _check_path(path, scene_data)
            if not isinstance(values, list) or not values or any(
                    isinstance(v, bool) or not isinstance(v, (int, float)) for v in values):
                raise SceneError(f"[sweep.parameters] {path!r} must be a non-empty array of numbers, got {values!r}")
            for value in values:
                _check_value(path, float(value), scene_data)
            checked.append((path, tuple(float(v) for v in values)))
        if mode == "zip" and len({len(v) for _, v in checked}) != 1:
            raise SceneError(f"[sweep] mode 'zip' needs arrays of one length, got "
                             f"{ {p: len(v) for p, v in checked} }")
        return cls(tuple(checked), mode, tuple(fields))

    def points(self) -> list[tuple[tuple[str, float], ...]]:
        """The runs: each a tuple of ``(path, value)``, in a fixed order."""
        paths = [p for p, _ in self.parameters]
        values = [v for _, v in self.parameters]
        combos = itertools.product(*values) if self.mode == "grid" else zip(*values)
        return [tuple(zip(paths, combo)) for combo in combos]


def _check_path(path: str, scene: dict) -> None:
    """One SceneError naming a path that does not lead to a number of the scene."""
    parts = path.split(".")
    head = parts[0]
    if head == "material" and len(parts) == 2:
        if not isinstance(scene.get("material", {}).get(parts[1], None), (int, float)):
            raise SceneError(f"[sweep.parameters] {path!r}: [material] has no number {parts[1]!r}")
        return
    if head == "materials" and len(parts) == 3:
        table = (scene.get("materials") or {}).get(parts[1])
        if not isinstance(table, dict) or isinstance(table.get(parts[2]), bool) \
                or not isinstance(table.get(parts[2]), (int, float)):
            raise SceneError(f"[sweep.parameters] {path!r}: [materials.{parts[1]}] has no number {parts[2]!r}")
        return
    if head == "inputs" and len(parts) == 4 and parts[2] == "signal":
        inputs = scene.get("inputs", [])
        if not parts[1].isdigit() or int(parts[1]) >= len(inputs):
            raise SceneError(f"[sweep.parameters] {path!r}: the scene has {len(inputs)} input(s)")
        signal = Signal.from_dict(inputs[int(parts[1])]["signal"])
        value = dict(signal.parameters).get(parts[3])
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"[sweep.parameters] {path!r}: a {signal.kind} signal has no number {parts[3]!r}")
        return
    if head == "effects" and len(parts) == 3:
        if parts[1] not in scene.get("effects", {}):
            raise SceneError(f"[sweep.parameters] {path!r}: the scene lists no effect {parts[1]!r}")
        options = {**effect_class(parts[1]).options, **(scene["effects"][parts[1]] or {})}
        if isinstance(options.get(parts[2]), bool) or not isinstance(options.get(parts[2]), (int, float)):
            raise SceneError(f"[sweep.parameters] {path!r}: effect {parts[1]!r} has no numeric option {parts[2]!r}")
        return
    raise SceneError(f"[sweep.parameters] unknown path {path!r}; valid: material.<key>, materials.<name>.<key>, "
                     "inputs.<i>.signal.<key>, effects.<name>.<key>")


def _check_value(path: str, value: float, scene: dict) -> None:
    """The value must make a valid scene: a positive material constant, a valid signal or effect."""
    parts = path.split(".")
    where = f"[sweep.parameters] {path!r} = {value:g}"
    if parts[0] == "material" and not value > 0:
        raise SceneError(f"{where}: material constants must be positive")
    if parts[0] == "materials":
        try:
            material_constants({parts[2]: value}, f"materials.{parts[1]}")
        except SceneError as exc:
            raise SceneError(f"{where}: {exc}") from None
    if parts[0] == "inputs":
        try:
            Signal.from_dict({**scene["inputs"][int(parts[1])]["signal"], parts[3]: value})
        except SceneError as exc:
            raise SceneError(f"{where}: {exc}") from None
    if parts[0] == "effects":
        effect = effect_class(parts[1])
        try:
            effect.check({**effect.options, **(scene["effects"][parts[1]] or {}), parts[2]: value})
        except SceneError as exc:
            raise SceneError(f"{where}: {exc}") from None


def with_parameters(scene, values) -> "object":
    """The scene with each ``(path, value)`` of a sweep point set (paths as :class:`SweepConfig` checks them)."""
    for path, value in values:
        parts = path.split(".")
        if parts[0] == "material":
            scene = dataclasses.replace(scene, material=dataclasses.replace(scene.material, **{parts[1]: value}))
        elif parts[0] == "materials":
            materials = tuple(dataclasses.replace(m, **{parts[2]: value}) if m.label == parts[1] else m
                              for m in scene.materials)
            scene = dataclasses.replace(scene, materials=materials)
        elif parts[0] == "inputs":
            i = int(parts[1])
            signal = scene.inputs[i].signal
            params = dict(signal.parameters) | {parts[3]: value}
            inputs = list(scene.inputs)
            inputs[i] = dataclasses.replace(inputs[i], signal=Signal(signal.kind, tuple(sorted(params.items()))))
            scene = dataclasses.replace(scene, inputs=tuple(inputs))
        else:
            effects = tuple(dataclasses.replace(e, options=tuple(sorted((dict(e.options) | {parts[2]: value}).items())))
                            if e.name == parts[1] else e for e in scene.effects)
            scene = dataclasses.replace(scene, effects=effects)
    return scene
