"""Finish a run that was stopped (killed, interrupted, failed) from its last committed chunk."""

from __future__ import annotations

import functools

import numpy as np

from femrom._errors import FemromValueError
from femrom.solvers import make_solver
from femrom.integrators import IntegrationSummary, integrate, scheme_for
from femrom.snapshots._errors import SnapshotStoreError
from femrom.snapshots._format import trajectory_name
from femrom.snapshots._store import SnapshotStore, split_model
from femrom.snapshots._writer import SnapshotWriter


def model_solver(model):
    """The linear-solver factory :func:`femrom.integrators.simulate` uses for a model.

    Resuming with the same strategy is what makes the continued run bit-identical.
    """
    modes = getattr(model.space, "rigid_body_modes", None)
    near_nullspace = None if modes is None else model.system.condensation.vector(modes())
    return functools.partial(make_solver, strategy=model.scene.time.solver,
                             near_nullspace=near_nullspace)


def resume(store_path, model_or_system, scheme=None, *, trajectory=None, dt: float | None = None,
           n_steps: int | None = None, solver=None, consumers=(), progress: bool | None = None,
           fsync: bool = False) -> IntegrationSummary:
    """Continue a trajectory from its committed checkpoint up to its planned last step.

    The rows past the declared length (a killed writer's) are dropped, the
    integrator restarts from the checkpoint with
    ``iterate(..., start=StepResult(...))`` and the writer appends. With the
    same system, scheme, ``dt`` and solver the result is bit-identical to an
    uninterrupted run.

    Parameters
    ----------
    store_path : str or Path
    model_or_system : FullOrderModel or SecondOrderSystem
        What was integrated (a model also gives the scheme, solver and, if no
        chunk was committed yet, the initial state).
    scheme : scheme, optional
        Default: the model's scene's. Its ``name`` must match the trajectory's.
    trajectory : str or int, optional
        Default: the last trajectory.
    dt, n_steps : optional
        Default: the trajectory's recorded ``dt`` and planned last step; if
        given, ``dt`` must equal the recorded one.
    solver : str or callable, optional
        Default: the model's solver factory (:func:`model_solver`), else ``"auto"``.
    consumers : iterable
        Extra consumers of the continued steps.
    progress : bool or None
    fsync : bool
        ``fsync`` at every commit.

    Returns
    -------
    IntegrationSummary
        Of the continued part (``n_steps`` is the number of steps taken now;
        0 when the trajectory was complete).
    """
    model, system = split_model(model_or_system)
    store = SnapshotStore.open(store_path, system=system)
    try:
        names = store.trajectories
        if not names:
            raise SnapshotStoreError(f"{store.path}: has no trajectory to resume")
        name = names[-1] if trajectory is None else trajectory_name(trajectory)
        attrs = store.attrs(name)
        if scheme is None:
            if model is None:
                raise FemromValueError("pass the scheme (or a FullOrderModel whose scene names one)")
            scheme = scheme_for(model.scene.time)
        recorded = attrs.get("scheme")
        if recorded is not None and recorded != scheme.label:
            raise SnapshotStoreError(f"{store.path}: trajectory {name!r} was run with {recorded}, "
                                     f"not {scheme.label}")
        dt = _recorded(store, name, attrs, "dt", dt)
        n_steps = int(_recorded(store, name, attrs, "n_steps", n_steps, must_match=False))
        if solver is None:
            solver = "auto" if model is None else model_solver(model)
        start = store.checkpoint(name)
        length = store.length(name)
        _check_checkpoint(store, name, start, length)
        writer = SnapshotWriter(store, name, append=True, fsync=fsync)
        try:
            q0 = v0 = None
            if start is None:  # killed before anything was stored: start over
                if model is None:
                    raise SnapshotStoreError(f"{store.path}: trajectory {name!r} has no checkpoint "
                                             "yet; run it again from its initial state")
                q0, v0 = model.initial_displacement, model.initial_velocity
                remaining = n_steps
            else:
                if length == 0:
                    writer(start)  # the initial checkpoint is the first row, not yet stored
                remaining = n_steps - start.step
                if remaining < 0:
                    raise SnapshotStoreError(f"{store.path}: trajectory {name!r} is at step "
                                             f"{start.step}, past n_steps = {n_steps}")
        except BaseException:
            writer.close()
            raise
        return integrate(system, scheme, q0, v0, dt, remaining, start=start,
                         consumers=(writer, *consumers), solver=solver, progress=progress)
    finally:
        store.close()


def _recorded(store, name, attrs, key, given, must_match=True):
    value = attrs.get(key)
    if given is None:
        if value is None:
            raise SnapshotStoreError(f"{store.path}: trajectory {name!r} records no {key}; pass {key}=")
        return value
    if must_match and value is not None and float(given) != float(value):
        raise SnapshotStoreError(f"{store.path}: trajectory {name!r} was run with {key} = {value}, "
                                 f"not {given}")
    return given


def _check_checkpoint(store, name, start, length) -> None:
    """The checkpoint must be the last committed row's state (bitwise), or the first row to come."""
    if start is None or length == 0:
        return
    last_step = int(store.steps(name)[-1])
    if start.step != last_step or not np.array_equal(store.read(name, "q", length - 1, length)[:, 0],
                                                     start.q):
        raise SnapshotStoreError(f"{store.path}: trajectory {name!r}: checkpoint (step "
                                 f"{start.step}) does not match the last committed snapshot "
                                 f"(step {last_step})")
