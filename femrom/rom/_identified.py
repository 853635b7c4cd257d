r"""Identified first-order ROMs: a state-space learner's operators with predict, stepper and HDF5.

.. math::

    z_{k+1} = A z_k + B u_k, \qquad y_k = C z_k + D u_k, \qquad u_k = u(t_0 + k\,\Delta t),

fitted by a learner of ``model = "state_space"`` (:class:`~femrom.inference.DMDc`,
:class:`~femrom.inference.ERA`, :class:`~femrom.inference.OKID`), whose
:class:`~femrom.inference.StateSpaceOperators` this model turns into a
:class:`~femrom.rom.DiscreteStateSpace`. Unlike a second-order ROM, the model
exists at its training step only: ``dt`` is part of it.

The state ``z`` is abstract for ERA and OKID (balanced coordinates; ``z_0 = 0``
is rest) and a projection ``z = U_r^T x`` of the data's state ``x`` for DMDc
(``x0=`` gives ``z_0 = U_r^T x_0``, less ``E u_0`` when the input of a step's end
is part of the model: ``input_offset``).
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from femrom._errors import FemromTypeError, FemromValueError
from femrom._json import dumps
from femrom.inference import StateSpaceOperators
from femrom.integrators import input_samples
from femrom.rom._base import uniform_step
from femrom.rom._statespace import DiscreteStateSpace, StateSpaceSolution, StateSpaceStepper, input_sample


class StateSpaceROM:
    r"""An identified discrete state-space model: fit, predict, step, export, save.

    Parameters
    ----------
    operators : StateSpaceOperators, optional
        Given operators (else :meth:`fit`).
    learner : Learner, optional
        A learner with ``model = "state_space"`` (:class:`~femrom.inference.DMDc`, ...).

    Attributes
    ----------
    operators_ : StateSpaceOperators
    """

    def __init__(self, operators: StateSpaceOperators | None = None, *, learner=None):
        if learner is not None and getattr(learner, "model", None) != "state_space":
            raise FemromValueError(f"learner {type(learner).__name__} fits {getattr(learner, 'model', None)!r} models, "
                             "not 'state_space' ones")
        if operators is not None and not isinstance(operators, StateSpaceOperators):
            raise FemromTypeError(f"operators must be StateSpaceOperators, got {type(operators).__name__}")
        self.operators_ = operators
        self.learner = learner
        self._state_space = None

    def fit(self, data, *, validation=None) -> "StateSpaceROM":
        """Fit the learner on ``data`` (InputOutputData, or MarkovParameters for ERA) and keep its operators."""
        if self.learner is None:
            raise FemromValueError("this ROM has no learner; pass learner=DMDc(...), ERA(...) or OKID(...)")
        self.operators_ = self.learner.fit(data, validation=validation).operators_
        self._state_space = None
        return self

    def _ops(self) -> StateSpaceOperators:
        if self.operators_ is None:
            raise FemromValueError("this ROM is not fitted: call fit(data) or pass operators")
        return self.operators_

    @property
    def state_space(self) -> DiscreteStateSpace:
        """The :class:`~femrom.rom.DiscreteStateSpace` of the operators."""
        if self._state_space is None:
            ops = self._ops()
            self._state_space = DiscreteStateSpace(A=ops.A, B=ops.B, C=ops.C, D=ops.D, dt=ops.dt,
                                                   input_offset=ops.input_offset, metadata=dict(ops.metadata))
        return self._state_space

    @property
    def dt(self) -> float:
        return self._ops().dt

    @property
    def n_states(self) -> int:
        return self._ops().n_states

    @property
    def spectral_radius(self) -> float:
        return self._ops().spectral_radius

    def initial_state(self, z0=None, x0=None, u0=None) -> np.ndarray:
        """(n_z,) ``z_0``: given, from the data's state ``x_0`` (``U_r^T x_0 - E u_0``), or rest (zeros).

        ``u0`` (default zeros) is the input sample at ``t_0``, needed with ``x0`` when
        the state is shifted (``input_offset = E``, DMDc with ``input_samples="both"``).
        """
        ops = self._ops()
        if z0 is not None and x0 is not None:
            raise FemromValueError("give z0 (the model's state) or x0 (the data's state), not both")
        if x0 is not None:
            if ops.state_basis is None:
                raise FemromValueError(f"this model's state is abstract ({ops.metadata.get('method', 'identified')}): "
                                 "give z0, not x0")
            x0 = np.asarray(x0, dtype=float).ravel()
            if x0.size != ops.state_basis.shape[0]:
                raise FemromValueError(f"x0 has {x0.size} entries, the data's state has {ops.state_basis.shape[0]}")
            z0 = ops.state_basis.T @ x0
            if ops.input_offset is not None:
                z0 = z0 - ops.input_offset @ input_sample(u0, ops.n_inputs)
        if z0 is None:
            return np.zeros(ops.n_states)
        z0 = np.asarray(z0, dtype=float).ravel()
        if z0.size != ops.n_states:
            raise FemromValueError(f"z0 has {z0.size} entries, the model has {ops.n_states} states")
        if not np.all(np.isfinite(z0)):
            raise FemromValueError("z0 is not finite")
        return z0

    def _samples(self, inputs, times: np.ndarray) -> np.ndarray:
        """(m, K) samples of ``inputs`` on ``times`` (:func:`~femrom.integrators.input_samples`; (0, K) without inputs)."""
        U = input_samples(inputs, times, self._ops().n_inputs)
        return np.zeros((0, times.size)) if U is None else U

    def predict(self, times, inputs=None, *, initial=None) -> StateSpaceSolution:
        r"""Outputs and states on a uniform grid with the model's step.

        Parameters
        ----------
        times : (K,) ndarray
            ``t_0, t_0 + dt, ...`` with the training ``dt``.
        inputs : (m, K) ndarray or callable
            The samples ``u(t_k)``, or ``u(t) -> (m,)`` (required when the model has inputs).
        initial : (n_z,) ndarray, optional
            The model's state ``z_0`` (default rest, zeros); from the data's state ``x_0``:
            ``initial=rom.initial_state(x0=x_0, u0=u_0)``.
        """
        ops = self._ops()
        times, h = uniform_step(times)
        if not np.isclose(h, ops.dt, rtol=1e-9, atol=0.0):
            raise FemromValueError(f"times have step {h:g}, the model was identified at dt = {ops.dt:g}")
        U = self._samples(inputs, times)
        z = self.initial_state(initial, None, U[:, 0])
        tic = time.perf_counter()
        outputs, states = self.state_space.simulate(U, z)
        seconds = time.perf_counter() - tic
        n_steps = times.size - 1
        return StateSpaceSolution(t=times, states=states, outputs=outputs, info={
            "dt": h, "n_steps": n_steps, "stepping_seconds": seconds,
            "seconds_per_step": seconds / max(n_steps, 1)})

    def stepper(self, *, initial=None, u0=None) -> StateSpaceStepper:
        """A :class:`~femrom.rom.StateSpaceStepper` at ``initial = z_0`` (default rest):
        ``y_{k+1} = stepper.step(u_{k+1})``."""
        return self.state_space.stepper(initial=self.initial_state(initial, None, u0), u0=u0)

    def estimate_states(self, inputs, outputs, z0=None) -> np.ndarray:
        r"""(n_z, K + 1) state estimates ``z^_0 ... z^_K`` from measured samples, by the identified observer.

        .. math::

            \hat z_{k+1} = A \hat z_k + B u_k + L (y_k - C \hat z_k - D u_k),

        ``L = operators_.observer_gain`` (OKID). ``z^_k`` uses ``y_0 ... y_{k-1}``;
        the last column is the estimate to start a prediction from after the data.

        Parameters
        ----------
        inputs : (m, K) ndarray
        outputs : (p, K) ndarray
        z0 : (n_z,) ndarray, optional
            Default rest.
        """
        ops = self._ops()
        if ops.observer_gain is None:
            raise FemromValueError(f"this model ({ops.metadata.get('method', 'identified')}) has no observer gain: "
                             "OKID identifies one")
        U = np.atleast_2d(np.asarray(inputs, dtype=float))
        Y = np.atleast_2d(np.asarray(outputs, dtype=float))
        if U.shape[0] != ops.n_inputs or Y.shape != (ops.n_outputs, U.shape[1]):
            raise FemromValueError(f"inputs {U.shape} and outputs {Y.shape} do not match the model's "
                             f"({ops.n_inputs}, K) and ({ops.n_outputs}, K)")
        if not (np.all(np.isfinite(U)) and np.all(np.isfinite(Y))):
            raise FemromValueError("inputs or outputs are not finite")
        A, B, C, D, L = ops.A, ops.B, ops.C, ops.D, ops.observer_gain
        Z = np.empty((ops.n_states, U.shape[1] + 1))
        Z[:, 0] = self.initial_state(z0)
        for k in range(U.shape[1]):
            z = Z[:, k]
            Z[:, k + 1] = A @ z + B @ U[:, k] + L @ (Y[:, k] - C @ z - D @ U[:, k])
        return Z

    def to_state_space(self, dt: float | None = None) -> DiscreteStateSpace:
        """The model's :class:`~femrom.rom.DiscreteStateSpace` (``dt`` must be the identified one)."""
        if dt is not None and not np.isclose(float(dt), self.dt, rtol=1e-9, atol=0.0):
            raise FemromValueError(f"an identified model exists at its step dt = {self.dt:g} only, asked for {dt:g}")
        return self.state_space

    # -- storage -----------------------------------------------------------------------
    def save(self, path) -> None:
        """An HDF5 file that :meth:`DiscreteStateSpace.load` reads too, plus the state basis and observer gain.

        Written to a temporary file beside ``path`` and moved into place, so a
        failed write leaves no half file.
        """
        import h5py

        ops = self._ops()
        path = Path(path)
        handle, tmp = tempfile.mkstemp(suffix=".h5.tmp", dir=path.parent)
        os.close(handle)
        try:
            self.state_space.save(tmp)
            with h5py.File(tmp, "a") as f:
                f.attrs["model"] = "femrom.StateSpaceROM"
                f.attrs["operators_metadata"] = dumps(ops.metadata)
                if ops.state_basis is not None:
                    f.create_dataset("state_basis", data=ops.state_basis)
                if ops.observer_gain is not None:
                    f.create_dataset("observer_gain", data=ops.observer_gain)
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.remove(tmp)
            raise

    @classmethod
    def load(cls, path) -> "StateSpaceROM":
        """Read a model written by :meth:`save` (or any DiscreteStateSpace file: then ``z0`` only)."""
        import h5py

        model = DiscreteStateSpace.load(path)
        with h5py.File(path, "r") as f:
            basis = f["state_basis"][()] if "state_basis" in f else None
            gain = f["observer_gain"][()] if "observer_gain" in f else None
            metadata = json.loads(f.attrs["operators_metadata"]) if "operators_metadata" in f.attrs \
                else dict(model.metadata)
        ops = StateSpaceOperators(A=model.A, B=model.B, C=model.C, D=model.D, dt=model.dt, state_basis=basis,
                                  input_offset=model.input_offset, observer_gain=gain, metadata=metadata)
        return cls(ops)
