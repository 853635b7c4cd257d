"""Run a built scene: choose the scheme and keep only the outputs the scene asks for."""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass

import numpy as np

from femrom.integrators._conditioning import ConditioningError, check_conditioning
from femrom.integrators._consumers import EnergyRecorder, OutputRecorder, Trajectory
from femrom.integrators._driver import integrate
from femrom.integrators._scheme import scheme_for
from femrom.solvers import make_solver

_FIELD_KEYS = {"displacement": "q", "velocity": "v", "acceleration": "a"}


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """What a scene keeps: times, outputs (p, k), energy (k,), fields (n, k) per name."""

    times: np.ndarray
    outputs: np.ndarray | None
    energy: np.ndarray | None
    fields: dict
    summary: dict


def _materials_text(scene) -> str:
    """The scene's material constants in one line: ``[material] ...`` or ``[materials] label: ...; ...``."""
    def constants(material):
        return ", ".join(f"{k} = {v:g}" for k, v in asdict(material).items()
                         if isinstance(v, (int, float)) and not isinstance(v, bool))
    if scene.material is not None:
        return f"[material] {constants(scene.material)}"
    return "[materials] " + "; ".join(f"{m.label}: {constants(m)}" for m in scene.materials)


def simulate(model, *, dt: float | None = None, t_end: float | None = None, consumers=(),
             progress: bool | None = None, solver=None, clock=None) -> SimulationResult:
    """Integrate a :class:`~femrom.scene.FullOrderModel` over its time window.

    Only what ``[outputs]`` lists is recorded: probe/average outputs, the
    energy, and full fields (in memory here; stream them to a store with an
    extra consumer). ``dt`` and ``t_end`` override the scene's (ladders).
    ``solver`` is a factory ``solver(A, spd=...) -> LinearSolver`` in place of
    :func:`~femrom.fem.make_solver` with the scene's strategy, e.g. a
    :class:`~femrom.fem.SolverCache` shared by several runs so that they
    factorise their common effective matrix once. ``clock``, a
    :class:`~femrom.integrators.StepClock`, times every step without the consumers.
    """
    scene, system = model.scene, model.system
    dt = scene.time.dt if dt is None else float(dt)
    t_end = scene.time.t_end if t_end is None else float(t_end)
    n_steps = int(round(t_end / dt))
    try:
        check_conditioning(system, dt)
    except ConditioningError as exc:
        raise ConditioningError(f"{scene.name}: {exc} ({_materials_text(scene)})") from None
    every = scene.outputs.save_every
    kept = []
    outputs = energy = trajectory = None
    if system.output_matrix is not None:
        outputs = OutputRecorder(system, every=every)
        kept.append(outputs)
    if scene.outputs.energy and (system.nonlinear is None or system.nonlinear.conservative):
        energy = EnergyRecorder(system, every=every)
        kept.append(energy)
    if scene.outputs.fields:
        trajectory = Trajectory(every=every, fields=tuple(_FIELD_KEYS[f] for f in scene.outputs.fields))
        kept.append(trajectory)

    modes = getattr(model.space, "rigid_body_modes", None)
    near_nullspace = None if modes is None else system.condensation.vector(modes())
    if solver is None:
        solver = functools.partial(make_solver, strategy=scene.time.solver, near_nullspace=near_nullspace)
    summary = integrate(system, scheme_for(scene.time), model.initial_displacement, model.initial_velocity,
                        dt, n_steps,
                        consumers=_clocked((*kept, *consumers), clock), solver=solver, progress=progress)
    times = dt * np.arange(0, n_steps + 1, every)
    fields = {}
    if trajectory is not None:
        fields = {name: getattr(trajectory, key) for name, key in _FIELD_KEYS.items()
                  if name in scene.outputs.fields}
    return SimulationResult(
        times=times,
        outputs=None if outputs is None else outputs.outputs,
        energy=None if energy is None else energy.total,
        fields=fields,
        summary=asdict(summary),
    )


def _clocked(consumers: tuple, clock) -> tuple:
    return consumers if clock is None else (clock.arrival, *consumers, clock.departure)
