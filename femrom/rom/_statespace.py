r"""Discrete-time linear state-space models: what controllers and identification speak.

.. math::

    z_{k+1} = A z_k + B u_k, \qquad y_k = C z_k + D u_k,

on the samples ``u_k = u(t_0 + k dt)``. A linear reduced model exports this
form (:meth:`SecondOrderROM.to_state_space`), so MPC, observers and ERA
checks need no glue (python-control's ``StateSpace(A, B, C, D, dt)``,
:meth:`DiscreteStateSpace.to_control`); identified first-order models (DMDc,
ERA, OKID) are models of this kind themselves.

A time scheme whose step uses the input at the step's end (Newmark's
``q_{k+1}`` depends on ``u_{k+1}``) is written in this form through the
shifted state ``z = x - E u`` (``input_offset = E``): ``x = [q; v]`` is
recovered as ``z + E u``, and the output has a feedthrough ``D = C_x E``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field

import numpy as np

from femrom._errors import FemromValueError
from femrom._json import dumps
from femrom.integrators import input_sample
from femrom.rom._base import Solution


def _matrix(value, name: str) -> np.ndarray:
    """``value`` as a finite float array, or one FemromValueError naming ``name``."""
    try:
        X = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise FemromValueError(f"{name} must be a numeric array, got {type(value).__name__}") from None
    if X.ndim > 2:
        raise FemromValueError(f"{name} must be a matrix, got shape {X.shape}")
    if not np.all(np.isfinite(X)):
        raise FemromValueError(f"{name} has non-finite entries")
    return X


@dataclass(frozen=True, eq=False)
class StateSpaceSolution(Solution):
    """A trajectory of a discrete state space (an identified model, a linear ROM's export).

    Attributes
    ----------
    t : (K,) ndarray
    states : (n_z, K) ndarray
    outputs : (p, K) ndarray
    info : dict
        ``dt``, ``n_steps``, ``stepping_seconds``, ``seconds_per_step``.
    """

    t: np.ndarray
    states: np.ndarray
    outputs: np.ndarray
    info: dict = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class DiscreteStateSpace:
    r"""``z_{k+1} = A z_k + B u_k``, ``y_k = C z_k + D u_k`` with sampling time ``dt``.

    Attributes
    ----------
    A : (n_z, n_z) ndarray
    B : (n_z, m) ndarray
    C : (p, n_z) ndarray
    D : (p, m) ndarray
    dt : float
    input_offset : (n_z, m) ndarray or None
        ``E`` with ``z = x - E u`` when the state was shifted from a model
        state ``x`` (:meth:`initial_state`); ``None`` means ``z = x``.
    metadata : dict
        Where the model came from (scheme, state layout, a constant input channel).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float
    input_offset: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        A = np.atleast_2d(_matrix(self.A, "A"))
        n = A.shape[0]
        if A.ndim != 2 or A.shape != (n, n):
            raise FemromValueError(f"A has shape {np.shape(self.A)}, expected square (n_states, n_states)")
        # a vector is one column of B (one input) or one row of C (one output); a matrix must have
        # the state dimension where it belongs: a transposed B or C is refused, never reshaped
        B = _matrix(self.B, "B")
        B = B.reshape(n, 1) if B.ndim == 1 and B.size == n else B
        if B.ndim != 2 or B.shape[0] != n:
            raise FemromValueError(f"B has shape {np.shape(self.B)}, expected (n_states, n_inputs) = ({n}, m)"
                                   + (" (a transposed B?)" if B.ndim == 2 and B.shape[1] == n else ""))
        C = _matrix(self.C, "C")
        C = C.reshape(1, n) if C.ndim == 1 and C.size == n else C
        if C.ndim != 2 or C.shape[1] != n:
            raise FemromValueError(f"C has shape {np.shape(self.C)}, expected (n_outputs, n_states) = (p, {n})"
                                   + (" (a transposed C?)" if C.ndim == 2 and C.shape[0] == n else ""))
        p, m = C.shape[0], B.shape[1]
        D = _matrix(self.D, "D")
        if D.ndim == 0:
            D = np.full((p, m), float(D))
        elif D.ndim == 1 and D.size == p * m and min(p, m) == 1:
            D = D.reshape(p, m)
        if D.shape != (p, m):
            raise FemromValueError(f"D has shape {np.shape(self.D)}, expected (n_outputs, n_inputs) = ({p}, {m})")
        if not (isinstance(self.dt, (int, float, np.floating, np.integer)) and np.isfinite(self.dt) and self.dt > 0):
            raise FemromValueError(f"dt must be a finite number > 0, got {self.dt!r}")
        for name, value in (("A", A), ("B", B), ("C", C), ("D", D)):
            object.__setattr__(self, name, value)
        if self.input_offset is not None:
            E = _matrix(self.input_offset, "input_offset")
            E = E.reshape(n, 1) if E.ndim == 1 and E.size == n and m == 1 else E
            if E.shape != (n, m):
                raise FemromValueError(f"input_offset has shape {np.shape(self.input_offset)}, expected ({n}, {m})")
            object.__setattr__(self, "input_offset", E)

    # -- sizes ---------------------------------------------------------------------------
    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        return self.B.shape[1]

    @property
    def n_outputs(self) -> int:
        return self.C.shape[0]

    def poles(self) -> np.ndarray:
        """Eigenvalues of ``A`` (inside the unit circle for an asymptotically stable model)."""
        return np.linalg.eigvals(self.A)

    def initial_state(self, x0: np.ndarray, u0: np.ndarray | None = None) -> np.ndarray:
        """``z_0 = x_0 - E u_0`` from a model state ``x_0`` and the first input sample."""
        x0 = np.asarray(x0, dtype=float).ravel()
        if x0.size != self.n_states:
            raise FemromValueError(f"x0 has {x0.size} entries, expected {self.n_states}")
        if self.input_offset is None or self.n_inputs == 0:
            return x0
        return x0 - self.input_offset @ self._input(u0)

    def _input(self, u) -> np.ndarray:
        return input_sample(u, self.n_inputs)

    # -- evaluation ---------------------------------------------------------------------
    def simulate(self, inputs: np.ndarray | None, z0: np.ndarray, n_steps: int | None = None):
        """``(Y, Z)``: outputs (p, K) and states (n_z, K) for input samples (m, K).

        Without inputs (``m = 0`` or ``None``) give ``n_steps``: ``K = n_steps + 1``.
        """
        m = self.n_inputs
        if inputs is None:
            if n_steps is None:
                raise FemromValueError("without inputs, give n_steps")
            U = np.zeros((m, n_steps + 1))
        else:
            U = np.atleast_2d(np.asarray(inputs, dtype=float))
            if U.shape[0] != m:
                raise FemromValueError(f"inputs have {U.shape[0]} rows, expected m = {m}")
        K = U.shape[1]
        z0 = np.asarray(z0, dtype=float).ravel()
        if z0.size != self.n_states or not np.all(np.isfinite(z0)):
            raise FemromValueError(f"z0 must be a finite state of {self.n_states} entries, got {z0.size}")
        Z = np.empty((self.n_states, K))
        Z[:, 0] = z0
        BU = self.B @ U
        for k in range(K - 1):
            Z[:, k + 1] = self.A @ Z[:, k] + BU[:, k]
        return self.C @ Z + self.D @ U, Z

    def predict(self, times, inputs=None, *, initial=None) -> StateSpaceSolution:
        """Outputs and states on the uniform grid ``times`` (step ``dt``) from ``initial = z_0`` (default zeros)
        for input samples (m, K) on it (required when the model has inputs)."""
        times = np.asarray(times, dtype=float)
        if times.ndim != 1 or times.size < 1:
            raise FemromValueError("times must be a 1-d grid")
        if times.size > 1 and not np.allclose(np.diff(times), self.dt, rtol=1e-9, atol=0.0):
            raise FemromValueError(f"times must be spaced by the model's dt = {self.dt:g}")
        if self.n_inputs and inputs is None:
            raise FemromValueError(f"this model has {self.n_inputs} inputs: pass their samples (m, K)")
        if inputs is not None and np.shape(inputs)[-1] != times.size:
            raise FemromValueError(f"inputs have {np.shape(inputs)[-1]} samples for {times.size} times")
        z0 = np.zeros(self.n_states) if initial is None else np.asarray(initial, dtype=float).ravel()
        if z0.size != self.n_states or not np.all(np.isfinite(z0)):
            raise FemromValueError(f"initial must be a finite state of {self.n_states} entries, got {z0.size}")
        tic = time.perf_counter()
        Y, Z = self.simulate(inputs, z0, None if inputs is not None else times.size - 1)
        seconds = time.perf_counter() - tic
        n_steps = times.size - 1
        return StateSpaceSolution(t=times, states=Z, outputs=Y, info={
            "dt": self.dt, "n_steps": n_steps, "stepping_seconds": seconds,
            "seconds_per_step": seconds / max(n_steps, 1)})

    def stepper(self, *, initial=None, u0=None) -> "StateSpaceStepper":
        """A :class:`StateSpaceStepper` at ``initial = z_0`` (default zeros) with the input sample ``u_0``."""
        return StateSpaceStepper(self, np.zeros(self.n_states) if initial is None else initial, u0)

    def to_control(self):
        """The python-control ``StateSpace(A, B, C, D, dt)`` (needs the ``control`` package)."""
        import control

        return control.ss(self.A, self.B, self.C, self.D, self.dt)

    # -- storage ------------------------------------------------------------------------
    def save(self, path) -> None:
        """Write the matrices, ``dt``, the input offset and the metadata to HDF5."""
        import h5py

        with h5py.File(path, "w") as f:
            f.attrs["format"] = "femrom.DiscreteStateSpace"
            f.attrs["version"] = 1
            f.attrs["dt"] = self.dt
            f.attrs["metadata"] = dumps(self.metadata)
            for name in ("A", "B", "C", "D"):
                f.create_dataset(name, data=getattr(self, name))
            if self.input_offset is not None:
                f.create_dataset("input_offset", data=self.input_offset)

    @classmethod
    def load(cls, path) -> "DiscreteStateSpace":
        import h5py

        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != "femrom.DiscreteStateSpace":
                raise FemromValueError(f"{path} is not a femrom DiscreteStateSpace file")
            arrays = {name: f[name][()] for name in ("A", "B", "C", "D")}
            offset = f["input_offset"][()] if "input_offset" in f else None
            return cls(**arrays, dt=float(f.attrs["dt"]), input_offset=offset,
                       metadata=json.loads(f.attrs["metadata"]))


class StateSpaceStepper:
    """One step at a time: ``y_{k+1} = step(u_{k+1})`` (the input sample at the new time).

    ``z_{k+1} = A z_k + B u_k`` uses the previous sample, the output
    ``y_{k+1} = C z_{k+1} + D u_{k+1}`` the new one, so a closed loop feeds the
    input it decides for ``t_{k+1}`` and reads the output there.
    """

    def __init__(self, model: DiscreteStateSpace, z0, u0=None):
        self.model = model
        self.z = np.asarray(z0, dtype=float).ravel().copy()
        self.u = model._input(u0)
        self.k = 0

    @property
    def output(self) -> np.ndarray:
        """``y_k`` at the current state and input."""
        return self.model.C @ self.z + self.model.D @ self.u

    def step(self, u=None) -> np.ndarray:
        """Advance to ``t_{k+1}`` with the input sample ``u_{k+1}``; return ``y_{k+1}``."""
        m = self.model
        self.z = m.A @ self.z + m.B @ self.u
        self.u = m._input(u)
        self.k += 1
        return self.output
