"""``[outputs]``: what a run keeps (point probes, region averages, lines of probes, full fields,
energy) and how often."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from femrom.scene._errors import SceneError
from femrom.scene._tables import as_names, as_vector, one_of, take_table

FIELDS = ("displacement", "velocity", "acceleration")


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
        d = take_table(data, where, {"name": None, "start": None, "end": None, "path": None, "points": None,
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
        path = tuple(as_vector(v, f"{where}.path") for v in vertices)
        if any(len(v) != len(path[0]) for v in path):
            raise SceneError(f"[{where}] the points of the path have different dimensions: {path}")
        lengths = [math.dist(a, b) for a, b in zip(path[:-1], path[1:])]
        if min(lengths) <= 0:
            raise SceneError(f"[{where}] the path has two equal consecutive points; its pieces need a length")
        for key, low in (("points", 2), ("nodes", 1)):
            v = d[key]
            if isinstance(v, bool) or not isinstance(v, int) or v < low:
                raise SceneError(f"[{where}] {key} must be a whole number >= {low}, got {v!r}")
        components = as_names(d["components"], f"{where}.components")
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
        d = take_table(data, "outputs", {"probes": [], "averages": [], "lines": [], "fields": [], "energy": True,
                                    "save_every": 1})
        probes = []
        for kind, entries in (("probes", d["probes"]), ("averages", d["averages"])):
            for i, p in enumerate(entries):
                where = f"outputs.{kind}[{i}]"
                key = "at" if kind == "probes" else "over"
                allowed = {"name": f"{kind[:-1]}{i}", key: None, "component": None}
                if kind == "probes":
                    allowed["nodes"] = 0
                e = take_table(p, where, allowed, (key,))
                at = e[key] if isinstance(e[key], str) else as_vector(e[key], f"{where}.{key}")
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
        for f in as_names(d["fields"], "outputs.fields"):
            one_of(f, FIELDS, "output field")
        every = d["save_every"]
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise SceneError(f"[outputs] save_every must be a whole number >= 1, got {every!r}")
        if not isinstance(d["energy"], bool):
            raise SceneError(f"[outputs] energy must be true or false, got {d['energy']!r}")
        return cls(tuple(probes), tuple(d["fields"]), d["energy"], every, lines)
