"""Full-order runs: one built model, several input signals, fields streamed to one snapshot store."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError
from femrom.integrators import StepClock, simulate
from femrom.scene import Signal, SignalVector
from femrom.solvers import SolverCache, make_solver
from femrom._timing import Cost, blocked_cost


@dataclass(frozen=True, eq=False)
class FOMRun:
    """One full-order run: what a study compares its reduced models against.

    Attributes
    ----------
    name : str
        Also the run's trajectory in the snapshot store (its fields live only there).
    times : (k,) ndarray
    outputs : (p, k) ndarray or None
    energy : (k,) ndarray or None
    inputs : SignalVector
        ``u(t)``; ``inputs.sampled(times)`` the (m, k) samples.
    q0, v0 : (n,) ndarray
        The initial state (a reduced model starts from its projection).
    summary : dict
        The integrator's summary (scheme, solver, timings, counts).
    cost : Cost
        Seconds per FOM step by repetition over blocks of the run's own steps.
    every : int
        The run keeps every ``every``-th FOM step (``times``, ``outputs``, ``energy``
        and the store alike): :attr:`dt` is the snapshot spacing, ``every`` FOM steps.
    """

    name: str
    times: np.ndarray
    outputs: np.ndarray | None
    energy: np.ndarray | None
    inputs: SignalVector
    q0: np.ndarray
    v0: np.ndarray
    summary: dict
    cost: Cost
    every: int = 1

    @property
    def U(self) -> np.ndarray | None:
        """(m, k) ndarray of the inputs on :attr:`times` (``None`` without inputs)."""
        return self.inputs.sampled(self.times)

    @property
    def dt(self) -> float:
        return float(self.times[1] - self.times[0])


#: from this many dofs on, the mass is solved by Jacobi-CG instead of a direct factor
MASS_CG_DOFS = 2000


def solver_factory(model):
    """A solver factory for the runs of one model: one cached setup of the effective
    matrix, shared by every run with the same ``dt``, and for the mass, from
    :data:`MASS_CG_DOFS` dofs on, Jacobi-CG.

    The consistent mass is solved once per run (the initial acceleration); Jacobi-CG
    does it in a few dozen iterations at any mesh size (Wathen 1987) without a second
    direct factor next to the effective matrix's (GBs at 1e6 dofs). Below that size a
    direct solve costs nothing and is exact. ``factory.cache.clear()`` frees the factor.
    """
    cache = SolverCache(model.scene.time.solver)
    mass = model.system.mass

    def factory(A, spd=True):
        if A is mass:
            if A.shape[0] >= MASS_CG_DOFS:
                return make_solver(A, "jacobi-cg", rtol=1e-12)
            return make_solver(A, model.scene.time.solver)
        return cache(A, spd=spd)

    factory.cache = cache
    return factory


def run_fom(model, signals: tuple[Signal, ...] | None = None, *, name: str = "run", store=None,
            dt: float | None = None, t_end: float | None = None, solver=None,
            min_block_seconds: float = 0.1, every: int = 1) -> FOMRun:
    """Integrate the model under ``signals`` (one per input; ``None``: the scene's).

    Displacements (and whatever else the store holds) stream into trajectory
    ``name`` of ``store``; no full field is kept in memory. ``dt``/``t_end``
    override the scene's. ``every``: keep every ``every``-th step only (step 0
    included), in the store and in the run's times, outputs and energy.
    """
    signals = tuple(i.signal for i in model.scene.inputs) if signals is None else tuple(signals)
    if len(signals) != model.system.n_inputs:
        raise FemromValueError(f"run {name!r}: {len(signals)} signal(s) for {model.system.n_inputs} input(s)")
    u = SignalVector(signals)
    system = dataclasses.replace(model.system, inputs=u) if signals else model.system
    outputs = dataclasses.replace(model.scene.outputs, fields=())
    model = dataclasses.replace(model, system=system, scene=dataclasses.replace(model.scene, outputs=outputs))
    clock = StepClock()
    n_steps = int(round((model.scene.time.t_end if t_end is None else t_end) / (model.scene.time.dt if dt is None
                                                                                 else dt)))
    every = int(every)
    if every < 1 or n_steps % every:
        raise FemromValueError(f"run {name!r}: every = {every} must be >= 1 and divide the {n_steps} steps")
    writers = [] if store is None else [store.writer(name, n_steps=n_steps, dt=dt, every=every, inputs=u)]  # closed by the driver
    result = simulate(model, dt=dt, t_end=t_end, consumers=writers, progress=None, solver=solver, clock=clock)
    keep = slice(None, None, every)
    pick = lambda x: None if x is None else x[..., keep]  # noqa: E731
    return FOMRun(name, result.times[keep], pick(result.outputs), pick(result.energy), u,
                  model.initial_displacement, model.initial_velocity, result.summary | {"snapshot_every": every},
                  blocked_cost(clock.step_seconds, min_block_seconds), every)
