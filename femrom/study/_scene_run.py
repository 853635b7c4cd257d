"""A scene's own full-order run, as a report shows it: built and stepped once, its response
plotted, its energy drift measured."""

from __future__ import annotations

import time
from dataclasses import dataclass

from femrom.integrators import simulate
from femrom.post import plot_response
from femrom.scene import build
from femrom.study._metrics import invariant_drift


@dataclass(frozen=True, eq=False)
class SceneRun:
    """The scene's model and its run over the scene's window.

    Attributes
    ----------
    model : FullOrderModel
    result : SimulationResult
        Times (k,), outputs (p, k), energy (k,), the integrator's summary.
    build_seconds : float
        Mesh, assembly and initial state.
    """

    model: object
    result: object
    build_seconds: float

    @property
    def energy_drift(self) -> float:
        """``max_t |E(t) - E(0)| / |E(0)|`` (``nan`` without an energy record)."""
        return float("nan") if self.result.energy is None else invariant_drift(self.result.energy)

    def metrics(self) -> dict:
        """``n_dofs``, ``build_seconds``, ``build_timings``, ``simulation`` (the summary),
        ``energy_relative_drift``."""
        return {"n_dofs": self.model.system.n_dofs, "build_seconds": self.build_seconds,
                "build_timings": self.model.timings, "simulation": self.result.summary,
                "energy_relative_drift": self.energy_drift}

    def section(self) -> str:
        """The report's paragraph on the run: dofs, steps, stepping time, energy drift."""
        s = self.result.summary
        return (f"## The scene's FOM run\n\n{self.model.system.n_dofs} free dofs, {s['n_steps']} steps "
                f"of {self.model.scene.time.dt:g} s in {s['stepping_seconds']:.2f} s; energy drift "
                f"{self.energy_drift:.2e}.")


def scene_run(scene, plot=None) -> SceneRun:
    """Build ``scene`` (timed), simulate it over its ``[time]`` window, and with ``plot`` (a path)
    draw its outputs and relative energy change (:func:`~femrom.post.plot_response`)."""
    tic = time.perf_counter()
    model = build(scene)
    build_seconds = time.perf_counter() - tic
    result = simulate(model)
    if plot is not None:
        plot_response(plot, result.times, result.outputs, model.system.output_names, result.energy,
                      title=f"{scene.name} FOM, {model.system.n_dofs} dofs, {result.summary['scheme']}")
    return SceneRun(model, result, build_seconds)
