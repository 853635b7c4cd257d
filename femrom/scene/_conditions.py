"""``[boundary]``, ``[[inputs]]`` with their loads, and ``[initial_conditions]``: the supports,
the loading and the initial state of a run."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from femrom.scene._errors import SceneError
from femrom.scene._signals import Signal
from femrom.scene._tables import as_names, as_number, as_vector, one_of, take_table

LOAD_KINDS = ("point_load", "surface_traction", "surface_pressure")
INITIAL_KINDS = ("zero", "static_load", "mode", "expression")


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
        d = take_table(data, where, {"kind": "point_load", "at": None, "component": None,
                                "direction": None, "magnitude": 1.0}, ("at",))
        one_of(d["kind"], LOAD_KINDS, f"load kind in [{where}]")
        at = d["at"] if isinstance(d["at"], str) else as_vector(d["at"], f"{where}.at")
        direction = None if d["direction"] is None else as_vector(d["direction"], f"{where}.direction")
        if d["kind"] == "surface_traction" and direction is None:
            raise SceneError(f"[{where}] a surface_traction needs a 'direction' vector")
        if d["component"] is not None and not isinstance(d["component"], str):
            raise SceneError(f"[{where}] component must be a component name, got {d['component']!r}")
        return cls(d["kind"], at, d["component"], direction, as_number(d["magnitude"], f"{where}.magnitude"))


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
        d = take_table(data, where, {"name": f"u{index}", "load": None, "signal": None}, ("load", "signal"))
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
        d = take_table(data, "boundary", {"clamped": [], "pinned": []})
        return cls(as_names(d["clamped"], "boundary.clamped"), as_names(d["pinned"], "boundary.pinned"))


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
        d = take_table(data, "initial_conditions", {"kind": "zero", "load": None, "index": 1, "amplitude": 1.0,
                                               "component": None, "displacement": "0", "velocity": "0"})
        one_of(d["kind"], INITIAL_KINDS, "initial condition kind")
        load = None
        if d["kind"] == "static_load":
            if d["load"] is None:
                raise SceneError("[initial_conditions] kind 'static_load' needs a 'load' table")
            load = LoadConfig.from_dict(d["load"], "initial_conditions.load")
        if isinstance(d["index"], bool) or not isinstance(d["index"], int) or d["index"] < 1:
            raise SceneError(f"[initial_conditions] index must be a mode number (1-based), got {d['index']!r}")
        return cls(d["kind"], load, d["index"], as_number(d["amplitude"], "initial_conditions.amplitude"),
                   d["component"],
                   str(d["displacement"]), str(d["velocity"]))
