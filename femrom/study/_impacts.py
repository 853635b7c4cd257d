r"""Hammer blows on a small stateful model: the blow, the ring-down's outputs, ECSW's training runs.

A blow is a half-sine impulse on one input (:func:`with_impulse`). :func:`output_ring_down`
steps the model from rest in a committed force state (Newmark, average acceleration) and keeps
what a long run needs: the outputs' accelerations ``E q''`` and, every ``keep_every`` steps,
the state ``(q, z)`` (ECSW's training snapshots of a stateful force); :func:`reference_ring_down`
keeps ``q, q', q''``, the inputs and the outputs instead (training data of learned models).
:func:`ecsw_training` runs one ring-down per blow and gathers those snapshots
(:func:`femrom.rom.ecsw_joint` samples the joint on them). :func:`step_cost` times a (large)
model's steps after a blow, the first step (and the factorisation in it) left out.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from femrom.integrators import Newmark, StepResult, Trajectory, integrate
from femrom.scene import Signal, SignalVector


def with_impulse(system, peak: float, width: float, *, input: int = 0):
    """``system`` with input ``input``'s signal a half-sine blow of peak ``peak`` [N] and duration ``width``
    [s] starting at ``t = 0`` (``u = peak sin(pi t / width)`` on ``[0, width]``); the other signals kept."""
    blow = Signal.from_dict({"kind": "impulse", "amplitude": float(peak), "start": 0.0, "duration": width})
    signals = list(system.inputs.signals)
    signals[input] = blow
    return dataclasses.replace(system, inputs=SignalVector(signals))


@dataclass
class OutputRingDown:
    """A run from rest: the outputs' accelerations and the kept states.

    Attributes
    ----------
    accelerations : (p, k) ndarray
        ``E q''`` at steps ``1 .. k`` (``t = dt .. k dt``; the rest state at ``t = 0`` is not listed).
    seconds : float
        Stepping time.
    newton_iterations : int
        Over the run.
    snapshots : list of (q (n,), state)
        Every ``keep_every``-th step's displacement and committed force state (empty if not asked).
    """

    accelerations: np.ndarray
    seconds: float
    newton_iterations: int
    snapshots: list = field(default_factory=list)

    @property
    def ms_per_step(self) -> float:
        return 1e3 * self.seconds / max(self.accelerations.shape[1] - 1, 1)


def output_ring_down(system, rest_state, duration: float, dt: float, *, keep_every: int = 0,
                     scheme=None) -> OutputRingDown:
    """``system`` from rest (``q = q' = q'' = 0``, force state ``rest_state``) under its own inputs for
    ``round(duration / dt)`` steps of ``scheme`` (default Newmark, average acceleration; e.g.
    :class:`~femrom.integrators.DiscreteGradient` for a joint with a step force). The inputs must
    vanish at ``t = 0`` (a blow that starts there), so that rest is the initial state."""
    r = system.n_dofs
    n_steps = int(round(duration / dt))
    trajectory = Trajectory(fields=("a",))
    kept = []

    def keep(result):
        if keep_every and result.step % keep_every == 0:
            kept.append((result.q.copy(), result.state))

    rest = StepResult.at_rest(r, state=rest_state)
    tic = time.perf_counter()
    summary = integrate(system, scheme or Newmark(), None, None, dt, n_steps, consumers=[trajectory, keep],
                        start=rest, progress=None)
    accelerations = np.asarray(system.output_matrix @ trajectory.a)
    return OutputRingDown(accelerations, time.perf_counter() - tic, summary.newton_iterations, kept)


@dataclass
class ImpactTraining:
    """ECSW's training runs: the kept ``(q, state)`` of all blows, and each blow's ring-down."""

    snapshots: list
    runs: dict          #: peak [N] -> OutputRingDown


def ecsw_training(system, rest_state, peaks, *, width: float, window: float, dt: float, input: int = 0,
                  keep_every: int = 4, progress=None, scheme=None) -> ImpactTraining:
    """One :func:`output_ring_down` of ``window`` seconds per blow of ``peaks`` [N] (half-sines of duration
    ``width`` on input ``input``, steps of ``scheme``, default Newmark), every ``keep_every``-th step's
    ``(q, state)`` kept for ECSW (:func:`femrom.rom.ecsw_joint`)."""
    snapshots, runs = [], {}
    for peak in peaks:
        if progress is not None:
            progress(f"ECSW training: {peak:g} N blow, {window:g} s ...")
        run = output_ring_down(with_impulse(system, peak, width, input=input), rest_state, window, dt,
                               keep_every=keep_every, scheme=scheme)
        snapshots += run.snapshots
        runs[peak] = run
    return ImpactTraining(snapshots, runs)


def step_cost(system, displacement, state, dt: float, n_steps: int, *, scheme=None) -> dict:
    """Seconds per step of ``system`` stepped ``n_steps`` times from ``displacement`` at rest (``q' = q'' = 0``,
    committed force ``state``) under its own inputs (``scheme``: default Newmark), from the steps' end
    times after the first: ``(t_n - t_1) / (n - 1)``.

    Returns ``{"n_dofs", "steps", "seconds_total", "seconds_per_step", "newton_iterations"}``."""
    n = system.n_dofs
    stamps = []
    start = StepResult.at_rest(n, q=displacement, state=state)
    tic = time.perf_counter()
    summary = integrate(system, scheme or Newmark(), None, None, dt, n_steps,
                        consumers=[lambda result: stamps.append(time.perf_counter())], start=start, progress=None)
    total = time.perf_counter() - tic
    per_step = (stamps[-1] - stamps[0]) / max(len(stamps) - 1, 1)
    return {"n_dofs": n, "steps": n_steps, "seconds_total": total, "seconds_per_step": per_step,
            "newton_iterations": getattr(summary, "newton_iterations", None)}
