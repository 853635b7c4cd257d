r"""Reduced second-order models: fit, predict, energy, reconstruction, HDF5.

.. math::

    \hat M \ddot{\hat q} + \hat C \dot{\hat q} + \hat K \hat q + \hat f(\hat q, \dot{\hat q})
        = \hat B u(t), \qquad y = \hat E \hat q, \qquad q \approx V \hat q,

integrated with a reduced variational scheme (:mod:`._steppers`: Newmark
average acceleration by default, the implicit midpoint rule, or
Stoermer-Verlet).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from femrom.inference import ReducedOperators, galerkin, reduced_coordinates
from femrom.rom._steppers import SCHEMES, linear_step_map, run_linear, run_nonlinear, verlet_bound


class LazyFields:
    """Full fields ``V x(t_k)`` of a reduced solution, rebuilt only on request.

    For dataclasses with ``t`` (k,), ``basis`` (n, r) or ``None`` and the (r, k)
    coordinate arrays named in ``FIELDS``.
    """

    FIELDS: tuple[str, ...] = ("q",)

    def _coordinates(self, which: str) -> np.ndarray:
        if self.basis is None:
            raise ValueError("this model has no basis: full fields cannot be reconstructed")
        if which not in self.FIELDS:
            raise ValueError(f"unknown field {which!r}; valid: {self.FIELDS}")
        return getattr(self, which)

    def field(self, k: int, which: str = "q") -> np.ndarray:
        """(n,) ndarray ``V x(t_k)``, ``x`` one of :attr:`FIELDS`."""
        return self.basis @ self._coordinates(which)[:, k]

    def fields(self, block: int = 256, which: str = "q") -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Yield ``(t_block, V X_block)``, ``X`` one of :attr:`FIELDS`, ``block`` steps at a time.

        Memory stays at (n, block) whatever the trajectory's length.
        """
        X = self._coordinates(which)
        for start in range(0, X.shape[1], block):
            stop = min(start + block, X.shape[1])
            yield self.t[start:stop], self.basis @ X[:, start:stop]


@dataclass(frozen=True, eq=False)
class ReducedSolution(LazyFields):
    """A reduced trajectory; full fields are rebuilt only on request.

    Attributes
    ----------
    t : (k,) ndarray
    q, v, a : (r, k) ndarray
        Reduced displacements, velocities, accelerations.
    energy : (k,) ndarray
        ``v^T M^ v / 2 + q^T K^ q / 2`` (plus the projected nonlinear potential
        when it is conservative).
    outputs : (p, k) ndarray or None
        ``E^ q``.
    basis : (n, r) ndarray or None
    info : dict
        Scheme, step, timings (``stepping_seconds``, ``seconds_per_step``).
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    energy: np.ndarray
    outputs: np.ndarray | None = None
    basis: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    FIELDS = ("q", "v", "a")


class SecondOrderROM:
    r"""A reduced second-order model, intrusive or learned.

    Parameters
    ----------
    operators : ReducedOperators, optional
        Given operators (e.g. from :func:`femrom.inference.galerkin`).
    basis : (n, r) ndarray, optional
        ``V``: projects full initial conditions and rebuilds full fields.
    product : (n, n) sparse or ndarray, optional
        ``W`` with ``V^T W V = I`` (the mass for a mass-orthonormal basis).
    learner : LagrangianOpInf or SecondOrderOpInf, optional
        What :meth:`fit` uses.

    Attributes
    ----------
    operators_ : ReducedOperators
    """

    def __init__(self, operators: ReducedOperators | None = None, basis: np.ndarray | None = None,
                 *, product=None, learner=None):
        self.operators_ = operators
        self.basis = None if basis is None else np.asarray(basis, dtype=float)
        self.product = product
        self.learner = learner
        if operators is not None and self.basis is not None and self.basis.shape[1] != operators.r:
            raise ValueError(f"basis has {self.basis.shape[1]} columns, operators have r = {operators.r}")

    @classmethod
    def galerkin(cls, system, basis: np.ndarray, *, product=None,
                 mass_orthonormal: bool = False) -> "SecondOrderROM":
        """The intrusive Galerkin ROM (see :func:`femrom.inference.galerkin`)."""
        ops = galerkin(system, basis, mass_orthonormal=mass_orthonormal)
        return cls(ops, basis, product=product)

    def fit(self, data) -> "SecondOrderROM":
        """Fit the learner on ``data`` (SecondOrderData or a list) and keep its operators."""
        if self.learner is None:
            raise ValueError("this ROM has no learner; pass learner=LagrangianOpInf(...)")
        self.operators_ = self.learner.fit(data).operators_
        return self

    # -- evaluation --------------------------------------------------------
    @property
    def r(self) -> int:
        return self._ops().r

    def _ops(self) -> ReducedOperators:
        if self.operators_ is None:
            raise ValueError("this ROM is not fitted: call fit(data) or pass operators")
        return self.operators_

    def reduce(self, x: np.ndarray) -> np.ndarray:
        """(r,) reduced coordinates of a full (n,) vector, ``V^T W x``."""
        if self.basis is None:
            raise ValueError("a full-order vector needs the basis to be reduced")
        return reduced_coordinates(self.basis, np.asarray(x, dtype=float), self.product)

    def _initial(self, x, name: str) -> np.ndarray:
        r = self.r
        if x is None:
            return np.zeros(r)
        x = np.asarray(x, dtype=float).ravel()
        if x.size == r:
            return x
        if self.basis is not None and x.size == self.basis.shape[0]:
            return self.reduce(x)
        raise ValueError(f"{name} has {x.size} entries: expected r = {r} (reduced) "
                         f"or n = {None if self.basis is None else self.basis.shape[0]} (full)")

    def energy(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(k,) or scalar: ``v^T M^ v / 2 + q^T K^ q / 2 (+ U^(q))`` column by column."""
        ops = self._ops()
        q2, v2 = np.atleast_2d(q.T).T, np.atleast_2d(v.T).T
        Mv = v2 if ops.mass is None else ops.mass @ v2
        Ksym = 0.5 * (ops.stiffness + ops.stiffness.T)
        e = 0.5 * np.sum(v2 * Mv, axis=0) + 0.5 * np.sum(q2 * (Ksym @ q2), axis=0)
        nl = ops.nonlinear
        if nl is not None and nl.conservative:
            e = e + np.array([nl.potential(q2[:, k]) for k in range(q2.shape[1])])
        return e if np.ndim(q) > 1 else float(e[0])

    def outputs(self, q: np.ndarray) -> np.ndarray | None:
        """(p, k) ndarray ``E^ q`` (``None`` without an output map)."""
        E = self._ops().output_matrix
        return None if E is None else E @ q

    def _forcing(self, inputs, times: np.ndarray, where: str):
        """(m, .) ndarray ``u`` at ``t_{k+1}`` (``where="end"``), ``t_k + h/2`` (``"mid"``)
        or every ``t_k`` (``"grid"``); ``None`` without inputs."""
        m = self._ops().n_inputs
        if m == 0:
            if inputs is not None:
                raise ValueError("this model has no input operator, but inputs were given")
            return None
        if inputs is None:
            raise ValueError(f"this model has {m} inputs: pass inputs (callable u(t) or (m, k) array)")
        if callable(inputs):
            ts = {"end": times[1:], "mid": 0.5 * (times[1:] + times[:-1]), "grid": times}[where]
            U = np.column_stack([np.atleast_1d(np.asarray(inputs(t), dtype=float)) for t in ts])
        else:
            U = np.atleast_2d(np.asarray(inputs, dtype=float))
            if U.shape != (m, times.size):
                raise ValueError(f"inputs have shape {U.shape}, expected ({m}, {times.size})")
            # midpoint values of a sampled signal: the average (second order)
            if where == "end":
                U = U[:, 1:]
            elif where == "mid":
                U = 0.5 * (U[:, 1:] + U[:, :-1])
        return U

    def predict(self, q0, times, *, v0=None, inputs=None, scheme: str = "newmark") -> ReducedSolution:
        r"""Integrate the reduced model on a uniform time grid.

        Parameters
        ----------
        q0 : (r,) or (n,) ndarray
            Initial displacement, reduced or full (then ``V^T W q0``); with
            ``r = n`` a vector is read as reduced (use :meth:`reduce`).
        times : (k,) ndarray
            Uniform grid ``t_0, t_0 + h, ...``.
        v0 : (r,) or (n,) ndarray, optional
            Initial velocity (default zero).
        inputs : callable or (m, k) ndarray, optional
            ``u(t) -> (m,)`` or the sampled inputs on ``times``.
        scheme : {"newmark", "midpoint", "verlet"}

        Returns
        -------
        ReducedSolution
        """
        if scheme not in SCHEMES:
            raise ValueError(f"unknown reduced scheme {scheme!r}; valid: {SCHEMES}")
        ops = self._ops()
        times = np.asarray(times, dtype=float)
        if times.ndim != 1 or times.size < 2:
            raise ValueError("times must be a 1-d grid of at least two points")
        h = float(times[1] - times[0])
        if not h > 0 or not np.allclose(np.diff(times), h, rtol=1e-9, atol=0.0):
            raise ValueError("times must be uniformly spaced and increasing")
        q0, v0 = self._initial(q0, "q0"), self._initial(v0, "v0")
        M, C, K, B = ops.mass_matrix, ops.damping, ops.stiffness, ops.input_matrix
        if scheme == "verlet":
            bound = verlet_bound(M, 0.5 * (K + K.T))
            if h > bound:
                raise ValueError(f"dt = {h:.6g} exceeds the Stoermer-Verlet bound "
                                 f"2/omega_max = {bound:.6g} of the reduced model")
        tic = time.perf_counter()
        if ops.nonlinear is None:
            r = ops.r
            A, F = linear_step_map(M, C, K, B, h, scheme)
            U = self._forcing(inputs, times, "mid" if scheme == "midpoint" else "end")
            forcing = None if U is None else F @ U
            grid_inputs = self._forcing(inputs, times, "grid")
            f0 = 0.0 if grid_inputs is None else B @ grid_inputs[:, 0]
            a0 = np.linalg.solve(M, f0 - (0.0 if C is None else C @ v0) - K @ q0)
            x0 = np.concatenate([q0, v0] if scheme == "midpoint" else [q0, v0, a0])
            step_tic = time.perf_counter()
            X = run_linear(A, x0, times.size - 1, forcing)
            stepping = time.perf_counter() - step_tic
            Q, Vel = X[:r], X[r:2 * r]
            if scheme == "midpoint":
                # the rule never needs accelerations: recover them from the equation of motion
                rhs = -K @ Q - (0.0 if C is None else C @ Vel)
                if grid_inputs is not None:
                    rhs = rhs + B @ grid_inputs
                Acc = np.linalg.solve(M, rhs)
            else:
                Acc = X[2 * r:]
        else:
            def force_at(t):
                if B is None:
                    return np.zeros(ops.r)
                if not callable(inputs):
                    raise ValueError("a nonlinear ROM needs inputs as a callable u(t)")
                return B @ np.atleast_1d(np.asarray(inputs(t), dtype=float))

            step_tic = time.perf_counter()
            Q, Vel, Acc = run_nonlinear(M, C, K, B, ops.nonlinear, h, scheme, q0, v0, times,
                                        force_at)
            stepping = time.perf_counter() - step_tic
        n_steps = times.size - 1
        info = {"scheme": scheme, "dt": h, "n_steps": n_steps,
                "seconds": time.perf_counter() - tic, "stepping_seconds": stepping,
                "seconds_per_step": stepping / max(n_steps, 1)}
        return ReducedSolution(t=times, q=Q, v=Vel, a=Acc, energy=self.energy(Q, Vel),
                               outputs=self.outputs(Q), basis=self.basis, info=info)

    # -- storage -----------------------------------------------------------
    def save(self, path, *, include_basis: bool = True) -> None:
        """Write operators, optional basis and metadata to an HDF5 file."""
        import h5py

        ops = self._ops()
        with h5py.File(path, "w") as f:
            f.attrs["format"] = "femrom.SecondOrderROM"
            f.attrs["version"] = 1
            g = f.create_group("operators")
            for name in ("stiffness", "mass", "damping", "input_matrix", "output_matrix"):
                value = getattr(ops, name)
                if value is not None:
                    g.create_dataset(name, data=value)
            f.attrs["nonlinear"] = ops.nonlinear is not None
            f.attrs["metadata"] = json.dumps(_jsonable(ops.metadata))
            if include_basis and self.basis is not None:
                f.create_dataset("basis", data=self.basis, compression="gzip")

    @classmethod
    def load(cls, path, *, nonlinear=None, product=None) -> "SecondOrderROM":
        """Read a model written by :meth:`save`.

        A model with a nonlinear force stores only that it had one: pass the
        :class:`~femrom.inference.ProjectedNonlinearForce` again.
        """
        import h5py

        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != "femrom.SecondOrderROM":
                raise ValueError(f"{path} is not a femrom SecondOrderROM file")
            g = f["operators"]
            arrays = {name: (g[name][()] if name in g else None)
                      for name in ("stiffness", "mass", "damping", "input_matrix", "output_matrix")}
            had_nonlinear = bool(f.attrs["nonlinear"])
            metadata = json.loads(f.attrs["metadata"])
            basis = f["basis"][()] if "basis" in f else None
        if had_nonlinear and nonlinear is None:
            raise ValueError(f"{path} holds a model with a nonlinear force: pass nonlinear=...")
        ops = ReducedOperators(**arrays, nonlinear=nonlinear, metadata=metadata)
        return cls(ops, basis, product=product)


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return repr(value)
