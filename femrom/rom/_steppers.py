r"""Stepping small dense reduced models: the fused linear loop and a one-step-at-a-time stepper.

The full-order integrators of :mod:`femrom.integrators` accept a reduced
system wrapped as a ``SecondOrderSystem`` of csr matrices, but their per-step
Python overhead (step objects, solver strategies, checks) dominates at
r ~ 20 (``benchmarks/rom_step.py``). Here, for a linear model, every scheme
is one precomputed linear map ``x_{k+1} = A x_k + G F_{k+theta}``
(:mod:`._schemes`) applied with one small matrix-vector product per step
(:func:`run_linear`); a nonlinear force adds a dense Newton iteration per
step (:class:`ReducedStepper`).
"""

from __future__ import annotations

import time

import numpy as np

from femrom.rom._schemes import LinearParts, ReducedNewton
from femrom.rom._statespace import input_sample


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


class ReducedStepper:
    r"""A reduced model advanced one step at a time: ``y_{k+1} = stepper.step(u_{k+1})``.

    ``step`` takes the input sample at the new time ``t_{k+1}`` (a scheme that
    evaluates the input mid-step uses the average of the two samples, as
    ``predict`` does with sampled inputs) and returns the outputs ``E^ q_{k+1}``
    (``q_{k+1}`` without an output map). A controller closes the loop through
    it; the trajectory is ``predict``'s.

    Parameters
    ----------
    operators : ReducedOperators
    scheme : ReducedScheme
    dt : float
    q0, v0 : (r,) ndarray
    t0 : float
    u0 : (m,) ndarray, optional
        The input sample at ``t0`` (zeros by default).
    newton : ReducedNewton

    Attributes
    ----------
    t : float
    q, v : (r,) ndarray
    a : (r,) ndarray or None
        The acceleration (``None`` for a linear midpoint model, which carries ``[q; v]``).
    state : object
        The nonlinear terms' committed state.
    iterations : int
        Newton iterations so far.
    """

    def __init__(self, operators, scheme, dt: float, q0, v0, *, t0: float = 0.0, u0=None,
                 newton: ReducedNewton = ReducedNewton()):
        self.operators, self.scheme, self.dt, self.newton = operators, scheme, float(dt), newton
        ops = operators
        self.parts = LinearParts(ops.mass_matrix, ops.damping, ops.stiffness)
        scheme.check(self.parts, self.dt)
        self.input_matrix, self.load = ops.input_matrix, ops.load
        self.nonlinear = ops.nonlinear
        self.output_matrix = ops.output_matrix
        self.t, self.iterations = float(t0), 0
        self.q, self.v = np.array(q0, dtype=float), np.array(v0, dtype=float)
        self.state = None if self.nonlinear is None else self.nonlinear.initial_state()
        self.u = self._input(u0)
        self.a = self.parts.acceleration(self.force(self.u), self.q, self.v, self.nonlinear, self.state)
        if self.nonlinear is None:
            self._A, self._G = scheme.step_map(self.parts, self.dt, np.eye(self.parts.r))
            self._x = np.concatenate([self.q, self.v] + ([self.a] if scheme.carries_acceleration else []))
            if not scheme.carries_acceleration:
                self.a = None

    def _input(self, u) -> np.ndarray:
        return input_sample(u, 0 if self.input_matrix is None else self.input_matrix.shape[1])

    def force(self, u) -> np.ndarray:
        """(r,) ``F = B^ u + f^_0``."""
        F = np.zeros(self.parts.r) if self.input_matrix is None else self.input_matrix @ u
        return F if self.load is None else F + self.load

    @property
    def outputs(self) -> np.ndarray:
        """``E^ q`` at the current state (``q`` without an output map)."""
        return self.q if self.output_matrix is None else self.output_matrix @ self.q

    def advance(self, force_input: np.ndarray, force_end: np.ndarray) -> None:
        """One step with the forcing at the scheme's input time and at ``t_{k+1}``."""
        if self.nonlinear is None:
            x = self._A @ self._x + self._G @ force_input
            r = self.parts.r
            self._x, self.q, self.v = x, x[:r], x[r:2 * r]
            if self.scheme.carries_acceleration:
                self.a = x[2 * r:]
        else:
            q1, v1, a1, iterations = self.scheme.step(self.parts, self.nonlinear, self.dt, self.t, self.q,
                                                      self.v, self.a, self.state, force_input, self.newton)
            if a1 is None:
                a1 = self.parts.acceleration(force_end, q1, v1, self.nonlinear, self.state)
            self.state = self.nonlinear.commit(q1, v1, self.state)
            if not np.all(np.isfinite(q1)):
                raise RuntimeError(f"reduced state became non-finite at t = {self.t + self.dt:.6g}")
            self.q, self.v, self.a = q1, v1, a1
            self.iterations += iterations
        self.t += self.dt

    def step(self, u=None) -> np.ndarray:
        """Advance to ``t + dt`` with the input sample ``u`` at ``t + dt``; return the outputs there."""
        u1 = self._input(u)
        w = u1 if self.scheme.input_time == "end" else 0.5 * (self.u + u1)
        self.advance(self.force(w), self.force(u1))
        self.u = u1
        return self.outputs
