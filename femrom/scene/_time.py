"""``[time]``: the time window, the scheme and the linear-solver strategy of a run."""

from __future__ import annotations

import math
from dataclasses import dataclass

from femrom.scene._errors import SceneError
from femrom.scene._tables import take_table
from femrom.solvers import strategies

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
        d = take_table(data, "time", {"t_end": None, "dt": None, "integrator": "newmark",
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
