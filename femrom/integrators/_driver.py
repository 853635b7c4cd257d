r"""The time loop: :func:`iterate` streams step results, :func:`integrate` feeds consumers.

A scheme (``Newmark``, ``GeneralizedAlpha``, ``CentralDifference``,
``ImplicitMidpoint``) only knows how to take one step; the driver sets it up
once per ``dt`` (where linear systems factorise their effective matrix),
computes the consistent initial acceleration ``M a_0 = B u(t_0) - C v_0 - K q_0
- f_nl``, loops, checks that the state stays finite, times everything and
reports progress. What is kept is up to the consumers (:mod:`._consumers`).

A scheme is any object with

- ``name`` (str) and ``order`` (int);
- ``init(system, dt, make_solver, mass_solver, t0, q0, v0, a0, state0) -> cache``:
  one-off work for this ``dt``; ``make_solver(A, spd=...)`` builds (and
  counts) a :class:`LinearSolver`, ``mass_solver()`` returns the (cached)
  solver of ``M``;
- optionally ``uses_mass_solver`` (bool, default False): whether steps solve
  with ``M``; otherwise the driver frees ``M``'s factor after the initial
  acceleration, before ``init`` factorises anything else;
- ``step(system, cache, t, q, v, a, state) -> (q1, v1, a1, state1, newton_iterations)``:
  one step of size ``cache.dt``, returning new arrays (never mutating its
  inputs) and the committed nonlinear state.
"""

from __future__ import annotations

import functools
import math
import time
import weakref
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from femrom._errors import FemromRuntimeError, FemromValueError
from femrom._progress import Progress
from femrom.integrators._newton import ConvergenceError
from femrom.solvers import LinearSolver, LinearSolverError, make_solver


class IntegrationError(FemromRuntimeError):
    """A run stopped: non-finite state, Newton or linear-solver failure.

    Attributes
    ----------
    step : int
        Index of the step that failed.
    t : float
        Time that step was to reach.
    """

    def __init__(self, message: str, *, step: int, t: float):
        super().__init__(message)
        self.step = step
        self.t = t


@dataclass(frozen=True, eq=False)
class StepResult:
    """The state after step ``step``: everything needed to restart from it.

    The arrays are fresh for every step and marked read-only: the integrator
    never changes them afterwards, so a consumer may keep references without
    copying (copy before modifying).

    Attributes
    ----------
    step : int
        Step index (0 is the initial state).
    t : float
        Time.
    q, v : (n,) ndarray
        Displacements and velocities.
    a : (n,) ndarray or None
        Accelerations (for ``GeneralizedAlpha`` the algorithmic acceleration;
        ``None`` for ``ImplicitMidpoint(accelerations=False)``).
    state : Any
        Committed internal state of the nonlinear force (``None`` without one);
        ``system.nonlinear.checkpoint(state)`` turns it into arrays.
    """

    step: int
    t: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray | None
    state: Any = None

    @classmethod
    def at_rest(cls, n_dofs: int, *, state: Any = None, t: float = 0.0, q=None) -> "StepResult":
        """Step 0 at rest: ``v = a = 0`` on ``n_dofs`` dofs, the displacement ``q`` (default zero), the
        nonlinear force's committed ``state`` (e.g. a joint's sliders at a preloaded equilibrium).

        At rest means no acceleration: ``q`` must be an equilibrium under the state and the
        forcing at ``t`` (for a model about a reference state, ``q = 0`` is).
        """
        n = int(n_dofs)
        if n < 1:
            raise FemromValueError(f"n_dofs must be a positive integer, got {n_dofs!r}")
        q = np.zeros(n) if q is None else _vector(q, n, "q")
        return cls(step=0, t=float(t), q=q, v=np.zeros(n), a=np.zeros(n), state=state)


@dataclass(frozen=True)
class IntegrationSummary:
    """Timings and counts of one run.

    Attributes
    ----------
    scheme, solver : str
        Scheme name; linear-solver strategies used, in order of first use
        (``"+"``-joined, e.g. ``"diagonal+superlu"``: mass, then effective matrix).
    n_dofs, n_steps : int
        System size and steps taken (excluding step 0).
    dt : float
    setup_seconds : float
        Initial acceleration and scheme setup, including factorisations.
    factorization_seconds : float
        Time inside factorisations / preconditioner setups (all of the run).
    stepping_seconds : float
        Time inside the steps (consumers excluded).
    steps_per_second : float
    consumer_seconds : float
        Time spent in consumers (:func:`integrate` only).
    n_factorizations : int
        Factorisations or multigrid setups: 1 for a linear implicit run
        (plus 1 for a non-diagonal mass), one per Newton iteration otherwise.
    newton_iterations : int
        Total Newton iterations (0 for a linear system: Newton never runs).
    linear_iterations : int or None
        Total Krylov iterations of iterative strategies.
    details : dict
        Scheme extras (e.g. ``omega_max`` and the stability bound).
    """

    scheme: str
    solver: str
    n_dofs: int
    n_steps: int
    dt: float
    setup_seconds: float
    factorization_seconds: float
    stepping_seconds: float
    steps_per_second: float
    n_factorizations: int
    newton_iterations: int
    linear_iterations: int | None
    consumer_seconds: float = 0.0
    details: dict = field(default_factory=dict)


class _SolverLog:
    """A solver factory that counts what it builds.

    Solvers built during setup live as long as the scheme holds them: the log
    keeps only weak references, so a factor used once (the mass matrix for
    the initial acceleration of an implicit scheme: 1.2 GB at 5e5 dofs) is
    freed when setup ends. Transient ones (Newton tangents) are tallied and
    dropped when the next one is made.
    """

    def __init__(self, solver: str | Callable):
        self._make = functools.partial(make_solver, strategy=solver) if isinstance(solver, str) \
            else solver
        self.names: list[str] = []
        self._persistent: list[weakref.ref] = []
        self._persistent_iterations: list[int | None] = []  # last count seen
        self.transient: LinearSolver | None = None
        self.n_factorizations = 0
        self.factorization_seconds = 0.0
        self._retired_iterations: int | None = None
        self.stepping = False

    def __call__(self, A, spd: bool = True) -> LinearSolver:
        solver = self._make(A, spd=spd)
        if solver.name not in self.names:
            self.names.append(solver.name)
        self.n_factorizations += solver.n_factorizations
        self.factorization_seconds += solver.setup_seconds
        if self.stepping:
            self._retire(self.transient)
            self.transient = solver
        else:
            self._persistent.append(weakref.ref(solver))
            self._persistent_iterations.append(solver.total_iterations)
        return solver

    def start_stepping(self):
        """Setup is over: remember what setup solvers counted, then let go of them."""
        self._persistent_iterations = [
            ref().total_iterations if ref() is not None else count
            for ref, count in zip(self._persistent, self._persistent_iterations)]
        self.stepping = True

    @property
    def persistent(self) -> list[LinearSolver]:
        """The setup solvers still alive (held by the scheme's cache)."""
        return [solver for ref in self._persistent if (solver := ref()) is not None]

    def _retire(self, solver):
        if solver is not None and solver.total_iterations is not None:
            self._retired_iterations = (self._retired_iterations or 0) + solver.total_iterations

    @property
    def linear_iterations(self) -> int | None:
        counts = [solver.total_iterations if (solver := ref()) is not None else count
                  for ref, count in zip(self._persistent, self._persistent_iterations)]
        if self.transient is not None:
            counts.append(self.transient.total_iterations)
        counts = [c for c in counts if c is not None]
        if not counts and self._retired_iterations is None:
            return None
        return sum(counts) + (self._retired_iterations or 0)


def _vector(x, n: int, name: str) -> np.ndarray:
    x = np.array(x, dtype=float, copy=True)
    if x.shape != (n,):
        raise FemromValueError(f"{name} has shape {x.shape}, expected ({n},)")
    if not np.all(np.isfinite(x)):
        raise FemromValueError(f"{name} has non-finite entries")
    x.setflags(write=False)
    return x


def _freeze(x):
    if x is not None:
        x.setflags(write=False)
    return x


def _is_finite(q, v, a) -> bool:
    """Whether no entry is inf/nan (one pass: a sum propagates them)."""
    with np.errstate(invalid="ignore", over="ignore"):
        total = float(q.sum()) + float(v.sum())
        if a is not None:
            total += float(a.sum())
    return math.isfinite(total)


class Integration(Iterator[StepResult]):
    """The iterator :func:`iterate` returns; :meth:`summary` reports the run so far."""

    def __init__(self, system, scheme, q0, v0, dt: float, n_steps: int, *, t0: float = 0.0,
                 solver: str | Callable = "auto", progress: bool | None = None,
                 start: StepResult | None = None):
        dt, n_steps = float(dt), int(n_steps)
        if not (dt > 0.0 and math.isfinite(dt)):
            raise FemromValueError(f"dt must be positive and finite, got {dt}")
        if n_steps < 0:
            raise FemromValueError(f"n_steps must be >= 0, got {n_steps}")
        self.system, self.scheme, self.dt, self.n_steps = system, scheme, dt, n_steps
        self._log = _SolverLog(solver)
        n = system.n_dofs
        setup_start = time.perf_counter()
        mass_solver = functools.cache(lambda: self._log(system.mass, spd=True))
        if start is None:
            q0, v0 = _vector(q0, n, "q0"), _vector(v0, n, "v0")
            state0 = None if system.nonlinear is None else system.nonlinear.initial_state()
            a0 = _freeze(mass_solver().solve(system.residual_force(float(t0), q0, v0, state0)))
            self._first = StepResult(step=0, t=float(t0), q=q0, v=v0, a=a0, state=state0)
        else:
            if q0 is not None or v0 is not None:
                raise FemromValueError("pass q0 = v0 = None when restarting from start=StepResult")
            self._first = start
        first = self._first
        if not getattr(scheme, "uses_mass_solver", False):
            mass_solver.cache_clear()  # free M's factor before A_eff is factorised
        self._cache = scheme.init(system, dt, self._log, mass_solver, first.t, first.q, first.v,
                                  first.a, first.state)
        del mass_solver  # the scheme's cache keeps it if it needs it
        self._log.start_stepping()
        self.setup_seconds = time.perf_counter() - setup_start
        self.stepping_seconds = 0.0
        self.newton_iterations = 0
        self.steps_done = 0
        self._progress = progress
        self._generator = self._run(yield_first=start is None)

    def __next__(self) -> StepResult:
        return next(self._generator)

    def _run(self, yield_first: bool) -> Iterator[StepResult]:
        current = self._first
        if yield_first:
            yield current
        system, scheme, cache, dt = self.system, self.scheme, self._cache, self.dt
        theta = float(scheme.input_time)
        step0 = current.step
        progress = Progress(self.n_steps, label=getattr(scheme, "label", type(scheme).__name__),
                            enabled=self._progress)
        try:
            for k in range(1, self.n_steps + 1):
                # t accumulates like the scheme's own clock (t + dt), so that a
                # restart from any StepResult replays the same times bit for bit
                step, t1 = step0 + k, current.t + dt
                tic = time.perf_counter()
                t0 = current.t
                try:
                    q, v, a, state, iterations = scheme.step(
                        system, cache, t0, current.q, current.v, current.a, current.state,
                        system.external_force(t0 + theta * dt), lambda t0=t0: system.external_force(t0 + dt))
                except (ConvergenceError, LinearSolverError) as err:
                    raise IntegrationError(f"step {step} (t = {t1:.6g}) failed: {err}",
                                           step=step, t=t1) from err
                if not _is_finite(q, v, a):
                    raise IntegrationError(
                        f"non-finite state at step {step} (t = {t1:.6g}); the last finite state "
                        f"is step {step - 1} (t = {current.t:.6g})", step=step, t=t1)
                current = StepResult(step=step, t=t1, q=_freeze(q), v=_freeze(v), a=_freeze(a),
                                     state=state)
                self.stepping_seconds += time.perf_counter() - tic
                self.newton_iterations += iterations
                self.steps_done += 1
                progress.update()
                yield current
        finally:
            progress.close()

    def summary(self) -> IntegrationSummary:
        """Timings and counts of the steps taken so far."""
        log = self._log
        return IntegrationSummary(
            scheme=getattr(self.scheme, "label", type(self.scheme).__name__),
            solver="+".join(log.names) or "none",
            n_dofs=self.system.n_dofs, n_steps=self.steps_done, dt=self.dt,
            setup_seconds=self.setup_seconds,
            factorization_seconds=log.factorization_seconds,
            stepping_seconds=self.stepping_seconds,
            steps_per_second=(self.steps_done / self.stepping_seconds
                              if self.stepping_seconds else 0.0),
            n_factorizations=log.n_factorizations,
            newton_iterations=self.newton_iterations,
            linear_iterations=log.linear_iterations,
            details=dict(getattr(self._cache, "details", None) or {}),
        )


def iterate(system, scheme, q0, v0, dt: float, n_steps: int, *, t0: float = 0.0,
            solver: str | Callable = "auto", progress: bool | None = None,
            start: StepResult | None = None) -> Integration:
    r"""Step ``M q'' + C q' + K q + f_nl(q, q') = B u(t)`` and yield every state.

    Setup happens here, before the first ``next``: the consistent initial
    acceleration ``M a_0 = B u(t_0) - C v_0 - K q_0 - f_nl(q_0, v_0)`` and the
    scheme's one-off work (a linear system's effective matrix is factorised
    once and reused by every step; the central-difference stability check).

    Parameters
    ----------
    system : SecondOrderSystem
    scheme : Newmark, GeneralizedAlpha, CentralDifference or ImplicitMidpoint
        Anything with ``name``, ``order``, ``init(...)`` and ``step(...)``.
    q0, v0 : (n,) ndarray
        Initial displacements and velocities (copied); ``None`` with ``start``.
    dt : float
        Time step.
    n_steps : int
        Steps to take after the initial state.
    t0 : float
        Initial time.
    solver : str or callable
        A :func:`make_solver` strategy, or a factory ``(A, spd=...) -> LinearSolver``
        (e.g. ``functools.partial(make_solver, strategy="amg-cg", near_nullspace=B)``).
    progress : bool or None
        Progress line on stderr: ``None`` only on an interactive terminal.
    start : StepResult, optional
        Resume from this state (its ``step``, ``t``, ``q``, ``v``, ``a``,
        ``state``); the same ``dt`` continues the run bit for bit. The start
        itself is not yielded again.

    Returns
    -------
    Integration
        An iterator of :class:`StepResult`: step 0 first (unless resuming),
        then ``n_steps`` steps; ``.summary()`` gives timings and counts.

    Raises
    ------
    IntegrationError
        During iteration: a non-finite state, or a Newton / linear-solver
        failure, naming the step and its time.
    """
    return Integration(system, scheme, q0, v0, dt, n_steps, t0=t0, solver=solver,
                       progress=progress, start=start)


def integrate(system, scheme, q0, v0, dt: float, n_steps: int, *,
              consumers: Iterable[Callable[[StepResult], Any]] = (), t0: float = 0.0,
              solver: str | Callable = "auto", progress: bool | None = None,
              start: StepResult | None = None) -> IntegrationSummary:
    """Run :func:`iterate` and hand every :class:`StepResult` to every consumer.

    A consumer is any callable ``consumer(result)``; if it has ``close()``,
    that is called at the end, also when the run stops with an error, so
    whatever was already streamed is kept. Other arguments as :func:`iterate`.

    Returns
    -------
    IntegrationSummary
    """
    consumers = tuple(consumers)
    run = iterate(system, scheme, q0, v0, dt, n_steps, t0=t0, solver=solver,
                  progress=progress, start=start)
    consumer_seconds = 0.0
    try:
        for result in run:
            tic = time.perf_counter()
            for consumer in consumers:
                consumer(result)
            consumer_seconds += time.perf_counter() - tic
    finally:
        for consumer in consumers:
            close = getattr(consumer, "close", None)
            if callable(close):
                close()
    return replace(run.summary(), consumer_seconds=consumer_seconds)
