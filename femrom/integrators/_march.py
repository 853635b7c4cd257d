r"""Stepping a model on a given time grid with given forcing: whole trajectories and one step at a time.

:func:`iterate` (:mod:`._driver`) streams the steps of a run whose forcing is the
model's own ``u(t)``; here the forcing ``F = B u + f_0`` comes as samples (a
prediction's inputs, a controller's moves), and the states are kept in arrays:

- :func:`sampled_forcing`: ``F`` on the grid and at each step's input time
  ``t_k + theta h`` (a callable input evaluated there; samples interpolated,
  ``(1 - theta) F_k + theta F_{k+1}``);
- :func:`march`: a whole trajectory with any registered scheme. A linear model with
  dense operators runs the scheme's precomputed step map, one small matrix-vector
  product a step (:func:`run_linear`); a model whose fused step can march (learned
  sliders under the Newmark family, learned potentials and dissipations under the
  discrete-gradient scheme, :mod:`._fused`) runs in one compiled call; any other model
  calls the scheme's ``step``;
- :func:`march_batch`: ``B`` runs of one model (different inputs, starts, force states) at
  once; on a reduced model with a compiled joint all their steps go in one compiled call;
- :class:`Stepper`: one step at a time, ``y = stepper.step(u)``, for a controller
  in the loop or a stepped sine; the same two paths.
"""

from __future__ import annotations

import functools
import time
from typing import Callable

import numpy as np

from femrom._errors import FemromRuntimeError, FemromValueError
from femrom.integrators._fused import NonFiniteState
from femrom.integrators._newton import ConvergenceError
from femrom.integrators._scheme import LinearParts, dense_model, time_scheme
from femrom.solvers import make_solver


def run_linear(A: np.ndarray, x0: np.ndarray, n_steps: int, forcing: np.ndarray | None,
               timing: dict | None = None):
    """(s, n_steps + 1) ndarray: ``x_{k+1} = A x_k + forcing[:, k]``.

    One BLAS call per step and nothing else: the forcing is written next to
    the states in a C-ordered (n_steps + 1, 2 s) buffer whose row ``k`` is
    ``[x_k, f_k]``, and ``x_{k+1} = [A, I] [x_k; f_k]`` is a single
    ``dot(..., out=)`` into the next row (no temporaries). Without forcing,
    ``dot(A, x_k, out=)`` on an (n_steps + 1, s) buffer. At r ~ 20 a step is
    dominated by the interpreter's call overhead (``benchmarks/rom_step.py``),
    so the fused call saves the separate vector add of a step.

    The buffer is written once before the loop, so its pages are mapped before
    the steps run: a first touch inside the loop costs a page fault per 4 KiB,
    erratic on a shared machine (measured: 25 MB took 3.4 ms once, 45 ms another
    time; the loop at r = 8 ran 20 % slower untouched). ``timing``, a dict, gets
    ``loop_seconds``: the steps alone.
    """
    s = x0.size
    dot = np.dot
    if forcing is None:
        X = np.empty((n_steps + 1, s))
        X.fill(0.0)
        X[0] = x0
        tic = time.perf_counter()
        for k in range(n_steps):
            dot(A, X[k], out=X[k + 1])
        if timing is not None:
            timing["loop_seconds"] = time.perf_counter() - tic
        return X.T
    Aug = np.ascontiguousarray(np.hstack([A, np.eye(s)]))
    buffer = np.empty((n_steps + 1, 2 * s))
    buffer[:, :s] = 0.0
    buffer[0, :s] = x0
    buffer[:n_steps, s:] = forcing[:, :n_steps].T
    buffer[n_steps, s:] = 0.0
    tic = time.perf_counter()
    for k in range(n_steps):
        dot(Aug, buffer[k], out=buffer[k + 1, :s])
    if timing is not None:
        timing["loop_seconds"] = time.perf_counter() - tic
    return buffer[:, :s].T


def uniform_step(times) -> tuple[np.ndarray, float]:
    """``(times, h)`` of a uniform increasing grid of at least two points; one clear error otherwise."""
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or times.size < 2:
        raise FemromValueError("times must be a 1-d grid of at least two points")
    h = float(times[1] - times[0])
    if not h > 0 or not np.allclose(np.diff(times), h, rtol=1e-9, atol=0.0):
        raise FemromValueError("times must be uniformly spaced and increasing")
    return times, h


def input_samples(inputs, times: np.ndarray, m: int) -> np.ndarray | None:
    """(m, k) input samples on ``times`` from a callable ``u(t)`` or an (m, k) array (``None``: no inputs)."""
    if m == 0:
        if inputs is not None:
            raise FemromValueError("this model has no input operator, but inputs were given")
        return None
    if inputs is None:
        raise FemromValueError(f"this model has {m} inputs: pass inputs (callable u(t) or (m, k) array)")
    if callable(inputs):
        return np.column_stack([np.atleast_1d(np.asarray(inputs(t), dtype=float)) for t in times])
    U = np.atleast_2d(np.asarray(inputs, dtype=float))
    if U.shape != (m, times.size):
        raise FemromValueError(f"inputs have shape {U.shape}, expected ({m}, {times.size})")
    if not np.all(np.isfinite(U)):
        raise FemromValueError("inputs are not finite")
    return U


def input_sample(u, m: int) -> np.ndarray:
    """(m,) ndarray of one input sample (zeros for ``None``); one clear error for a wrong size."""
    if u is None:
        return np.zeros(m)
    u = np.array(u, dtype=float, ndmin=1).ravel()     # a copy: a caller may reuse its array in place
    if u.size != m:
        raise FemromValueError(f"input has {u.size} entries, expected {m}")
    return u


def _columns(matrix, U):
    product = matrix @ U
    return np.asarray(product.toarray() if hasattr(product, "toarray") else product)


def sampled_forcing(system, inputs, times: np.ndarray, theta: float):
    r"""``(F_grid (n, k), F_input (n, k - 1), present)``: ``F = B u + f_0`` on the grid and at each
    step's input time ``t_k + theta h``.

    A callable ``u(t)`` is evaluated at ``(1 - theta) t_k + theta t_{k+1}``; samples give
    ``(1 - theta) F_k + theta F_{k+1}`` (second order for ``theta = 1/2``). ``present`` is
    whether the model has any forcing (inputs or a load).
    """
    m = 0 if system.input_matrix is None else system.input_matrix.shape[1]
    U = input_samples(inputs, times, m)
    n = system.n_dofs
    f0 = system.load
    grid = np.zeros((n, times.size)) if U is None else _columns(system.input_matrix, U)
    if f0 is not None:
        grid = grid + f0[:, None]
    present = U is not None or f0 is not None
    if theta == 1.0:
        return grid, grid[:, 1:], present
    if callable(inputs) and U is not None:
        middle = (1.0 - theta) * times[:-1] + theta * times[1:]
        at = _columns(system.input_matrix,
                      np.column_stack([np.atleast_1d(np.asarray(inputs(t), dtype=float)) for t in middle]))
        if f0 is not None:
            at = at + f0[:, None]
    elif theta == 0.5:
        at = 0.5 * (grid[:, 1:] + grid[:, :-1])
    else:
        at = (1.0 - theta) * grid[:, :-1] + theta * grid[:, 1:]
    return grid, at, present


def dense_solver(A, spd: bool = True):
    """The solver factory of small dense models."""
    return make_solver(A, "dense" if not hasattr(A, "tocsr") else "auto", spd=spd)


def march(system, scheme, times, q0, v0, *, inputs=None, state0=None, solver=None, whole: bool = True) -> dict:
    r"""Step ``system`` over the uniform grid ``times`` from ``(q0, v0)`` and the force state ``state0``.

    Parameters
    ----------
    system : SecondOrderSystem
        Any model: sparse or dense operators, linear or with a (stateful) nonlinear force.
    scheme : Scheme or str
        A registered scheme (or its name).
    times : (k,) ndarray
        Uniform grid.
    q0, v0 : (n,) ndarray
    inputs : callable or (m, k) ndarray, optional
        ``u(t)`` or its samples on ``times`` (required when the model has inputs).
    state0 : optional
        The nonlinear force's committed state at ``t_0`` (default its initial state).
    solver : callable, optional
        ``(A, spd=...) -> LinearSolver`` for the scheme's set-up (default by the matrix:
        dense for a reduced model).
    whole : bool
        Whether a fused step that can march the whole trajectory in one compiled call does (default);
        ``False`` calls the scheme's step at each step (the compiled step included): the reference the
        whole march is tested and timed against.

    Returns
    -------
    dict with ``q``, ``v``, ``a`` ((n, k) ndarrays), ``state`` (at the end), ``newton_iterations``,
    ``stepping_seconds`` (the loop alone) and ``path`` (``"linear map"``, ``"steps"``, or ``"compiled
    steps"``: a scheme whose step is one compiled call for this model and that can march the whole
    trajectory in one: learned sliders under the Newmark family, learned potentials and dissipations under
    the discrete-gradient scheme, :mod:`._fused`; the latter also gives ``jacobians``, the Newton
    Jacobians formed).
    """
    scheme = time_scheme(scheme)
    scheme.check(system)
    times, h = uniform_step(times)
    n = system.n_dofs
    q0 = np.asarray(q0, dtype=float).reshape(n)
    v0 = np.asarray(v0, dtype=float).reshape(n)
    theta = float(scheme.input_time)
    F_grid, F_input, present = sampled_forcing(system, inputs, times, theta)
    n_steps = times.size - 1
    if system.nonlinear is None and dense_model(system):
        parts = LinearParts.of(system)
        scheme.check_step(parts, h)
        A, G = scheme.step_map(parts, h, np.eye(n))
        a0 = parts.acceleration(F_grid[:, 0], q0, v0)
        x0 = np.concatenate([q0, v0, a0] if scheme.carries_acceleration else [q0, v0])
        loop: dict = {}
        X = run_linear(A, x0, n_steps, G @ F_input if present else None, timing=loop)
        Q, V = X[:n], X[n:2 * n]
        if scheme.carries_acceleration:
            Acc = X[2 * n:]
        else:
            # the scheme never needs accelerations: recover them from the equation of motion
            Acc = np.linalg.solve(parts.mass, F_grid - parts.damping_matrix @ V - parts.stiffness @ Q)
        return {"q": Q, "v": V, "a": Acc, "state": None, "newton_iterations": 0,
                "stepping_seconds": loop["loop_seconds"], "path": "linear map"}
    factory = solver or dense_solver
    nonlinear = system.nonlinear
    state = state0 if state0 is not None or nonlinear is None else nonlinear.initial_state()
    mass_solver = factory(system.mass, spd=True)
    rhs = F_grid[:, 0]
    if system.damping is not None:
        rhs = rhs - system.damping @ v0
    rhs = rhs - system.stiffness @ q0
    if nonlinear is not None:
        rhs = rhs - nonlinear.force(q0, v0, state)
    a = mass_solver.solve(rhs)
    cache = scheme.init(system, h, factory, lambda: mass_solver, times[0], q0, v0, a, state)
    fused = getattr(cache, "fused", None)
    if whole and callable(getattr(fused, "march", None)) and fused.enabled():
        # the whole trajectory in one compiled call (the same steps as the loop below)
        tic = time.perf_counter()
        try:
            out = fused.march(q0, v0, a, state, F_input[:, :n_steps] if present else None, n_steps,
                              forces_end=F_grid[:, 1:] if present else None)
        except ConvergenceError as err:
            raise ConvergenceError(f"step {err.step} (t = {times[err.step]:.6g}): {err}") from None
        except NonFiniteState as err:
            raise FemromRuntimeError(f"the state became non-finite at t = {times[err.step]:.6g}") from None
        seconds = time.perf_counter() - tic
        Q, V, Acc, state, iterations = out[:5]
        result = {"q": Q, "v": V, "a": Acc, "state": state, "newton_iterations": int(np.sum(iterations)),
                  "stepping_seconds": seconds, "path": "compiled steps"}
        if len(out) > 5:
            result["jacobians"] = int(np.sum(out[5]))
        return result
    Q, V, Acc = (np.empty((n, times.size)) for _ in range(3))
    Q[:, 0], V[:, 0], Acc[:, 0] = q0, v0, a
    q, v, iterations = q0, v0, 0
    tic = time.perf_counter()
    for k in range(n_steps):
        t = times[k]
        try:
            q, v, a1, state, its = scheme.step(system, cache, t, q, v, a, state,
                                               F_input[:, k] if present else None,
                                               (lambda k=k: F_grid[:, k + 1]) if present else None)
        except ConvergenceError as err:
            raise ConvergenceError(f"step {k + 1} (t = {times[k + 1]:.6g}): {err}") from None
        if not np.all(np.isfinite(q)):
            raise FemromRuntimeError(f"the state became non-finite at t = {times[k + 1]:.6g}")
        a = a1 if a1 is not None else np.full(n, np.nan)
        Q[:, k + 1], V[:, k + 1], Acc[:, k + 1] = q, v, a
        iterations += its
    return {"q": Q, "v": V, "a": Acc, "state": state, "newton_iterations": iterations,
            "stepping_seconds": time.perf_counter() - tic, "path": "steps"}


def _per_run(value, B: int, n: int, name: str) -> np.ndarray:
    """(B, n) ndarray of ``value``: zeros for ``None``, one (n,) vector for every run, or (B, n)."""
    if value is None:
        return np.zeros((B, n))
    x = np.asarray(value, dtype=float)
    if x.shape == (n,):
        return np.tile(x, (B, 1))
    if x.shape != (B, n):
        raise FemromValueError(f"{name} must be ({n},) or ({B}, {n}), got shape {x.shape}")
    return x.copy()


def march_batch(system, scheme, times, q0=None, v0=None, *, inputs=None, state0=None, a0=None,
                solver=None) -> dict:
    r"""``B`` runs of one model over the uniform grid ``times``, stepped together: :func:`march` for each.

    The runs share the model (matrices, joint) and the grid, and differ in their inputs (force
    levels, frequencies), starts and force states. When the scheme's step of this model is one
    compiled call on a projected joint (the Newmark family on a reduced model whose force offers a
    :class:`~femrom.fem.CompiledJoint`, compiled laws on), all steps of all runs go in one compiled
    call, step after step for every run, each run with its own Newton (a run that converged stops
    iterating while the others go on): ``path = "compiled batch"``. Any other model steps each run by
    the scheme's ``step`` (``path = "steps"``). Either way run ``b`` is :func:`march` of its own input,
    start and state, to round-off (``tests/test_batch_march.py``).

    Parameters
    ----------
    system : SecondOrderSystem
    scheme : Scheme or str
    times : (k,) ndarray
    q0, v0 : (n,) or (B, n) ndarray, optional
        Starts (default rest; one vector for every run).
    inputs : sequence of B (callables or (m, k) ndarrays), or (B, m, k) ndarray, optional
        Each run's ``u(t)`` or its samples (required when the model has inputs; it then gives ``B``).
    state0 : optional
        The force's committed state at ``t_0``: one for every run (default its initial state) or a
        sequence of ``B`` (an array with one more leading axis than the force's state).
    a0 : (n,) or (B, n) ndarray, optional
        The accelerations at ``t_0`` (default from the equation of motion), e.g. the last column of
        a previous batch's ``a``, so that a batch continues the runs of another exactly (a linear
        model with dense operators takes its own, from the equation of motion).
    solver : callable, optional
        As for :func:`march`.

    Returns
    -------
    dict with ``q``, ``v``, ``a`` ((B, n, k) ndarrays), ``state`` (the runs' final states: (B, ...)
    ndarray when the states are arrays), ``newton_iterations`` ((B, k - 1) int ndarray, by step),
    ``stepping_seconds`` and ``path``. A run that fails raises :class:`ConvergenceError` (or a
    :class:`~femrom.FemromRuntimeError` for a non-finite state) naming the run, step and time.
    """
    scheme = time_scheme(scheme)
    scheme.check(system)
    times, h = uniform_step(times)
    n = system.n_dofs
    nonlinear = system.nonlinear
    if inputs is not None and not callable(inputs):
        runs = list(inputs)
        B = len(runs)
    elif inputs is not None:
        raise FemromValueError("inputs must be a sequence of one input a run, not one callable")
    elif q0 is not None and np.ndim(q0) == 2:
        B, runs = np.shape(q0)[0], None
    else:
        raise FemromValueError("give the runs' inputs (one a run) or their starts q0 as a (B, n) array")
    if B < 1:
        raise FemromValueError("a batch needs at least one run")
    runs = runs if runs is not None else [None] * B
    Q0, V0 = _per_run(q0, B, n, "q0"), _per_run(v0, B, n, "v0")
    if nonlinear is None:
        states = [None] * B
    else:
        initial = nonlinear.initial_state()
        if state0 is None:
            states = [initial.copy() if hasattr(initial, "copy") else initial for _ in range(B)]
        elif np.ndim(state0) == np.ndim(initial) + 1:
            states = list(state0)
            if len(states) != B:
                raise FemromValueError(f"state0 has {len(states)} states for {B} runs")
        else:
            states = [state0] * B
    theta = float(scheme.input_time)
    factory = solver or dense_solver
    mass_solver = factory(system.mass, spd=True)
    n_steps = times.size - 1
    grids, forcing, A0, present = [], [], np.empty((B, n)), False
    for b in range(B):
        F_grid, F_input, present = sampled_forcing(system, runs[b], times, theta)
        grids.append(F_grid)
        forcing.append(F_input[:, :n_steps])
        if a0 is not None:
            continue
        rhs = F_grid[:, 0]
        if system.damping is not None:
            rhs = rhs - system.damping @ V0[b]
        rhs = rhs - system.stiffness @ Q0[b]
        if nonlinear is not None:
            rhs = rhs - nonlinear.force(Q0[b], V0[b], states[b])
        A0[b] = mass_solver.solve(rhs)
    if a0 is not None:
        A0 = _per_run(a0, B, n, "a0")
    if nonlinear is None and dense_model(system):
        cache = None
    else:
        cache = scheme.init(system, h, factory, lambda: mass_solver, times[0], Q0[0], V0[0], A0[0], states[0])
    fused = getattr(cache, "fused", None)
    if callable(getattr(fused, "march_batch", None)) and fused.enabled():
        tic = time.perf_counter()
        try:
            Q, V, Acc, state, iterations = fused.march_batch(Q0, V0, A0, np.array(states),
                                                             np.array(forcing) if present else None, n_steps)
        except ConvergenceError as err:
            raise ConvergenceError(f"run {err.run}, step {err.step} (t = {times[err.step]:.6g}): {err}") from None
        except NonFiniteState as err:
            raise FemromRuntimeError(f"run {err.run}: the state became non-finite at t = {times[err.step]:.6g}"
                                     ) from None
        return {"q": Q, "v": V, "a": Acc, "state": state, "newton_iterations": iterations,
                "stepping_seconds": time.perf_counter() - tic, "path": "compiled batch"}
    # the reference: each run by the scheme's step (a linear model by march's step map)
    Q, V, Acc = (np.empty((B, n, times.size)) for _ in range(3))
    iterations = np.zeros((B, n_steps), dtype=np.int64)
    finals = []
    tic = time.perf_counter()
    for b in range(B):
        if cache is None:
            out = march(system, scheme, times, Q0[b], V0[b], inputs=runs[b], solver=solver)
            Q[b], V[b], Acc[b] = out["q"], out["v"], out["a"]
            finals.append(None)
            continue
        if b:
            cache = scheme.init(system, h, factory, lambda: mass_solver, times[0], Q0[b], V0[b], A0[b], states[b])
        q, v, a, state = Q0[b], V0[b], A0[b], states[b]
        Q[b, :, 0], V[b, :, 0], Acc[b, :, 0] = q, v, a
        for k in range(n_steps):
            try:
                q, v, a1, state, its = scheme.step(system, cache, times[k], q, v, a, state,
                                                   forcing[b][:, k] if present else None,
                                                   (lambda k=k, b=b: grids[b][:, k + 1]) if present else None)
            except ConvergenceError as err:
                raise ConvergenceError(f"run {b}, step {k + 1} (t = {times[k + 1]:.6g}): {err}") from None
            if not np.all(np.isfinite(q)):
                raise FemromRuntimeError(f"run {b}: the state became non-finite at t = {times[k + 1]:.6g}")
            a = a1 if a1 is not None else np.full(n, np.nan)
            Q[b, :, k + 1], V[b, :, k + 1], Acc[b, :, k + 1] = q, v, a
            iterations[b, k] = its
        finals.append(state)
    if all(isinstance(x, np.ndarray) for x in finals):
        finals = np.stack(finals)
    return {"q": Q, "v": V, "a": Acc, "state": finals, "newton_iterations": iterations,
            "stepping_seconds": time.perf_counter() - tic, "path": "steps"}


class Stepper:
    r"""A model advanced one step at a time: ``y_{k+1} = stepper.step(u_{k+1})``.

    ``step`` takes the input sample at the new time ``t_{k+1}`` (a scheme that samples
    the forcing at ``t_k + theta h`` uses ``(1 - theta) u_k + theta u_{k+1}``, as
    :func:`march` does with samples) and returns the outputs ``E q_{k+1}`` (``q_{k+1}``
    without an output map). A controller closes the loop through it; its trajectory is
    :func:`march`'s. A linear model with dense operators steps by the scheme's step
    map; any other by the scheme's ``step``.

    Parameters
    ----------
    system : SecondOrderSystem
    scheme : Scheme or str
    dt : float
    q0, v0 : (n,) ndarray, optional
        Default zero.
    t0 : float
    u0 : (m,) ndarray, optional
        The input sample at ``t0`` (zeros by default).
    state : optional
        The nonlinear force's committed state at ``t0`` (default its initial state).
    a0 : (n,) ndarray, optional
        The acceleration at ``t0`` (default from the equation of motion), e.g. carried
        over from a previous stepper of the same run.
    solver : callable, optional
        Solver factory of the scheme's set-up.

    Attributes
    ----------
    t : float
    q, v : (n,) ndarray
    a : (n,) ndarray or None
        The acceleration (``None`` on the linear map of a scheme that carries ``[q; v]``).
    state : object
        The nonlinear force's committed state.
    iterations : int
        Newton iterations so far.
    """

    def __init__(self, system, scheme, dt: float, q0=None, v0=None, *, t0: float = 0.0, u0=None, state=None,
                 a0=None, solver=None):
        self.system, self.scheme, self.dt = system, time_scheme(scheme), float(dt)
        if not (self.dt > 0 and np.isfinite(self.dt)):
            raise FemromValueError(f"dt must be positive and finite, got {dt!r}")
        self.scheme.check(system)
        n = system.n_dofs
        self.input_matrix, self.load = system.input_matrix, system.load
        self.nonlinear = system.nonlinear
        self.output_matrix = system.output_matrix
        self.t, self.iterations = float(t0), 0
        self.q = np.zeros(n) if q0 is None else np.array(q0, dtype=float).reshape(n)
        self.v = np.zeros(n) if v0 is None else np.array(v0, dtype=float).reshape(n)
        self.state = state if state is not None or self.nonlinear is None else self.nonlinear.initial_state()
        self.u = self._input(u0)
        self._theta = float(self.scheme.input_time)
        self._linear = self.nonlinear is None and dense_model(system)
        factory = solver or dense_solver
        # the mass is factorised only when asked for: the initial acceleration, or a scheme that solves with it
        self._mass_solver = functools.cache(lambda: factory(system.mass, spd=True))
        self.a = self._acceleration(self.force(self.u)) if a0 is None else np.array(a0, dtype=float)
        if self._linear:
            parts = LinearParts.of(system)
            self.scheme.check_step(parts, self.dt)
            self._A, self._G = self.scheme.step_map(parts, self.dt, np.eye(n))
            self._x = np.concatenate([self.q, self.v] + ([self.a] if self.scheme.carries_acceleration else []))
            if not self.scheme.carries_acceleration:
                self.a = None
        else:
            self._cache = self.scheme.init(system, self.dt, factory, self._mass_solver, self.t, self.q,
                                           self.v, self.a, self.state)

    def _input(self, u) -> np.ndarray:
        return input_sample(u, 0 if self.input_matrix is None else self.input_matrix.shape[1])

    def _acceleration(self, force):
        rhs = force
        if self.system.damping is not None:
            rhs = rhs - self.system.damping @ self.v
        rhs = rhs - self.system.stiffness @ self.q
        if self.nonlinear is not None:
            rhs = rhs - self.nonlinear.force(self.q, self.v, self.state)
        return self._mass_solver().solve(rhs)

    @property
    def n_inputs(self) -> int:
        return 0 if self.input_matrix is None else self.input_matrix.shape[1]

    @property
    def acceleration(self) -> np.ndarray:
        """(n,) ``a`` at the current state: the carried one, else from the equation of motion
        under the last input sample (a scheme whose linear step map carries ``[q; v]``)."""
        return self.a if self.a is not None else self._acceleration(self.force(self.u))

    def force(self, u) -> np.ndarray:
        """(n,) ``F = B u + f_0``."""
        F = np.zeros(self.system.n_dofs) if self.input_matrix is None else _columns(self.input_matrix, u)
        return F if self.load is None else F + self.load

    @property
    def outputs(self) -> np.ndarray:
        """``E q`` at the current state (``q`` without an output map)."""
        return self.q if self.output_matrix is None else _columns(self.output_matrix, self.q)

    def advance(self, force_input: np.ndarray, force_end: Callable | np.ndarray) -> None:
        """One step with the forcing at the scheme's input time and at ``t + dt``."""
        if self._linear:
            x = self._A @ self._x + self._G @ force_input
            n = self.system.n_dofs
            self._x, self.q, self.v = x, x[:n], x[n:2 * n]
            if self.scheme.carries_acceleration:
                self.a = x[2 * n:]
        else:
            end = force_end if callable(force_end) else (lambda: force_end)
            try:
                q1, v1, a1, state1, iterations = self.scheme.step(self.system, self._cache, self.t, self.q, self.v,
                                                                  self.a, self.state, force_input, end)
            except ConvergenceError as err:
                raise ConvergenceError(f"t = {self.t + self.dt:.6g}: {err}") from None
            if not np.all(np.isfinite(q1)):
                raise FemromRuntimeError(f"the state became non-finite at t = {self.t + self.dt:.6g}")
            self.q, self.v, self.a, self.state = q1, v1, a1, state1
            self.iterations += iterations
        self.t += self.dt

    def step(self, u=None) -> np.ndarray:
        """Advance to ``t + dt`` with the input sample ``u`` at ``t + dt``; return the outputs there."""
        u1 = self._input(u)
        theta = self._theta
        w = u1 if theta == 1.0 else 0.5 * (self.u + u1) if theta == 0.5 else (1.0 - theta) * self.u + theta * u1
        self.advance(self.force(w), lambda: self.force(u1))
        self.u = u1
        return self.outputs
