r"""Reduced second-order models: fit, predict, step, state space, energy, reconstruction, HDF5.

.. math::

    \hat M \ddot{\hat q} + \hat C \dot{\hat q} + \hat K \hat q + \hat f(\hat q, \dot{\hat q}; s)
        = \hat B u(t) + \hat f_0, \qquad y = \hat E \hat q, \qquad q \approx V \hat q,

the terms of a :class:`~femrom.inference.ReducedOperators`, whose
:attr:`~femrom.inference.ReducedOperators.system` (a
:class:`~femrom.scene.SecondOrderSystem` with dense operators) any registered time
scheme of :mod:`femrom.integrators` steps (Newmark average acceleration by
default, the implicit midpoint rule, Stoermer-Verlet, the discrete gradient).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field

import numpy as np

from femrom._errors import FemromValueError
from femrom._json import dumps
from femrom.inference import ReducedOperators, galerkin, term_class
from femrom.integrators import LinearParts, Stepper, march, time_scheme, uniform_step
from femrom.rom._base import LazyFields, ReducedModel
from femrom.rom._statespace import DiscreteStateSpace

#: Version of the HDF5 layout :meth:`SecondOrderROM.save` writes (one group per term).
FILE_VERSION = 2


@dataclass(frozen=True, eq=False)
class ReducedSolution(LazyFields):
    """A reduced trajectory; full fields are rebuilt only on request.

    Attributes
    ----------
    t : (k,) ndarray
    q, v, a : (r, k) ndarray
        Reduced displacements, velocities, accelerations.
    energy : (k,) ndarray
        ``v^T M^ v / 2`` plus the terms' potentials (``q^T K^ q / 2``, a
        conservative force's, ``- f_0^T q``).
    outputs : (p, k) ndarray or None
        ``E^ q``.
    basis : (n, r) ndarray or None
    info : dict
        Scheme, step, timings (``stepping_seconds``, ``seconds_per_step``),
        Newton iterations of a nonlinear model.
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


class SecondOrderROM(ReducedModel):
    r"""A reduced second-order model, intrusive or learned.

    Parameters
    ----------
    operators : ReducedOperators, optional
        Given terms (e.g. from :func:`femrom.inference.galerkin`).
    basis : (n, r) ndarray, optional
        ``V``: projects full initial conditions and rebuilds full fields.
    product : (n, n) sparse or ndarray, optional
        ``W`` with ``V^T W V = I`` (the mass for a mass-orthonormal basis).
    learner : Learner, optional
        What :meth:`fit` uses (:class:`~femrom.inference.LagrangianOpInf`, ...).

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
            raise FemromValueError(f"basis has {self.basis.shape[1]} columns, operators have r = {operators.r}")

    @classmethod
    def galerkin(cls, system, basis: np.ndarray, *, product=None,
                 mass_orthonormal: bool = False) -> "SecondOrderROM":
        """The intrusive Galerkin ROM (see :func:`femrom.inference.galerkin`)."""
        ops = galerkin(system, basis, mass_orthonormal=mass_orthonormal)
        return cls(ops, basis, product=product)

    def fit(self, data=None, *, validation=None) -> "SecondOrderROM":
        """Fit the learner on ``data`` (SecondOrderData or a list) and keep its operators;
        ``validation``: held-out data the learner judges itself on (its ``fit``)."""
        if self.learner is None:
            raise FemromValueError("this ROM has no learner; pass learner=LagrangianOpInf(...)")
        self.operators_ = self.learner.fit(data, validation=validation).operators_
        return self

    # -- evaluation --------------------------------------------------------------
    @property
    def r(self) -> int:
        return self._ops().r

    def _ops(self) -> ReducedOperators:
        if self.operators_ is None:
            raise FemromValueError("this ROM is not fitted: call fit(data) or pass operators")
        return self.operators_

    def energy(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(k,) or scalar: ``v^T M^ v / 2`` plus the terms' potentials, column by column."""
        q2, v2 = np.atleast_2d(q.T).T, np.atleast_2d(v.T).T
        e = self._ops().energy(q2, v2)
        return e if np.ndim(q) > 1 else float(e[0])

    def outputs(self, q: np.ndarray) -> np.ndarray | None:
        """(p, k) ndarray ``E^ q`` (``None`` without an output map)."""
        E = self._ops().output_matrix
        return None if E is None else E @ q

    def predict(self, times, inputs=None, *, initial=None, scheme="newmark") -> ReducedSolution:
        r"""Integrate the reduced model on a uniform time grid.

        Parameters
        ----------
        times : (k,) ndarray
            Uniform grid ``t_0, t_0 + h, ...``.
        inputs : callable or (m, k) ndarray, optional
            ``u(t) -> (m,)`` or the sampled inputs on ``times`` (required when the
            model has inputs).
        initial : optional
            ``q0``, a ``(q0, v0)`` pair (each (r,) reduced or (n,) full, then ``V^T W x``;
            with ``r = n`` a vector is read as reduced) or a
            :class:`~femrom.integrators.StepResult` that also gives the nonlinear terms'
            committed state (``StepResult.at_rest(r, state=...)``); default rest.
        scheme : str or Scheme
            A registered time scheme (``"newmark"``, ``"implicit_midpoint"``,
            ``"central_difference"``, ``"discrete_gradient"``, ...; the aliases
            ``"midpoint"`` and ``"verlet"``) or an instance with its own options (Newton).

        Returns
        -------
        ReducedSolution
        """
        ops = self._ops()
        step = time_scheme(scheme)
        times, h = uniform_step(times)
        q0, v0, state0 = self.initial_state(initial)
        tic = time.perf_counter()
        run = march(ops.system, step, times, q0, v0, inputs=inputs, state0=state0)
        info = {"scheme": step.name, "dt": h, "n_steps": times.size - 1}
        if ops.nonlinear is not None:
            info["newton_iterations"] = run["newton_iterations"]
            if "jacobians" in run:
                info["newton_jacobians"] = run["jacobians"]
        stepping = run["stepping_seconds"]
        info.update(seconds=time.perf_counter() - tic, stepping_seconds=stepping,
                    seconds_per_step=stepping / max(times.size - 1, 1))
        Q, Vel = run["q"], run["v"]
        return ReducedSolution(t=times, q=Q, v=Vel, a=run["a"], energy=self.energy(Q, Vel),
                               outputs=self.outputs(Q), basis=self.basis, info=info)

    def stepper(self, dt: float, *, initial=None, t0: float = 0.0, u0=None, scheme="newmark") -> Stepper:
        """A :class:`~femrom.integrators.Stepper`: ``y = stepper.step(u)`` advances by ``dt``.

        ``initial`` as in :meth:`predict` (default rest; a :class:`~femrom.integrators.StepResult`
        also carries its acceleration over); ``u0`` the input sample at ``t0``.
        """
        q0, v0, state = self.initial_state(initial)
        a = getattr(initial, "a", None)
        a0 = None if a is None else self._initial(a, "initial.a")
        return Stepper(self._ops().system, scheme, dt, q0, v0, t0=t0, u0=u0, state=state, a0=a0)

    @property
    def model(self):
        """The reduced model as a :class:`~femrom.scene.SecondOrderSystem` (dense (r, r) operators):
        the one model type every time scheme, stepper, stepped sine and plant takes."""
        return self._ops().system

    def to_state_space(self, dt: float, scheme="newmark") -> DiscreteStateSpace:
        r"""The discrete state space ``z+ = A z + B u``, ``y = C z + D u`` of a linear model.

        On the samples ``u_k = u(t_k)`` (and ``u = [u; 1]`` when the model has a
        constant load), with ``x = [q; v] = z + E u`` (``input_offset = E``):
        the scheme's step written on ``[q; v]`` (the acceleration eliminated
        through ``M a = B u + f_0 - C v - K q``) is ``x_{k+1} = A x_k + E_0 u_k
        + E u_{k+1}``, hence ``B = A E + E_0`` and ``D = C E``. ``y = E^ q``
        (``q`` without an output map). Equal to :meth:`predict` with sampled
        inputs to round-off. Schemes that sample the forcing at the step's end or
        midpoint have this form.
        """
        step = time_scheme(scheme)
        ops = self._ops()
        if ops.nonlinear is not None:
            names = ", ".join(t.name for t in ops.terms if not hasattr(t, "matrix"))
            raise FemromValueError(f"the model has nonlinear terms ({names}): it has no linear state-space form")
        if float(step.input_time) not in (0.5, 1.0) or not step.physical_acceleration:
            raise FemromValueError(f"scheme {step.name!r} has no [q; v] state space: it samples the forcing at "
                                   f"t + {step.input_time:g} h and carries an algorithmic acceleration; use "
                                   "newmark, implicit_midpoint, central_difference or discrete_gradient")
        if not (isinstance(dt, (int, float, np.floating, np.integer)) and np.isfinite(dt) and dt > 0):
            raise FemromValueError(f"dt must be a finite number > 0, got {dt!r}")
        r, h = ops.r, float(dt)
        parts = LinearParts(ops.mass_matrix, ops.damping, ops.stiffness)
        step.check_step(parts, h)
        columns = [c for c in (ops.input_matrix, None if ops.load is None else ops.load[:, None]) if c is not None]
        forcing = np.hstack(columns) if columns else np.zeros((r, 0))
        A_full, G = step.step_map(parts, h, forcing)
        m = forcing.shape[1]
        if step.carries_acceleration:
            Minv = np.linalg.inv(parts.mass)
            P = np.vstack([np.eye(2 * r), np.hstack([-Minv @ parts.stiffness, -Minv @ parts.damping_matrix])])
            R = np.vstack([np.zeros((2 * r, m)), Minv @ forcing])
            A2, E0, E1 = (A_full @ P)[:2 * r], (A_full @ R)[:2 * r], G[:2 * r]
        else:
            A2, E0, E1 = A_full, 0.5 * G, 0.5 * G
        E = ops.output_matrix
        C = np.hstack([np.eye(r) if E is None else E, np.zeros((r if E is None else E.shape[0], r))])
        return DiscreteStateSpace(A=A2, B=A2 @ E1 + E0, C=C, D=C @ E1, dt=h, input_offset=E1, metadata={
            "scheme": step.name, "state": "[q; v] - input_offset u", "r": r,
            "constant_input": ops.load is not None, "outputs": "E q" if E is not None else "q"})

    # -- storage -----------------------------------------------------------------------
    def save(self, path, *, include_basis: bool = True) -> None:
        """Write every term, the optional basis and the metadata to an HDF5 file.

        Each term writes itself into ``terms/<name>`` (its class is found again
        by name on :meth:`load`); a projected known force stores its
        parameters when it has them, so the model loads whole.
        """
        import h5py

        ops = self._ops()
        with h5py.File(path, "w") as f:
            f.attrs["format"] = "femrom.SecondOrderROM"
            f.attrs["version"] = FILE_VERSION
            f.attrs["metadata"] = dumps(ops.metadata)
            group = f.create_group("terms")
            for term in ops.terms:
                sub = group.create_group(term.name)
                term.save(sub)
            if include_basis and self.basis is not None:
                f.create_dataset("basis", data=self.basis, compression="gzip")

    @classmethod
    def load(cls, path, *, nonlinear=None, product=None, **context) -> "SecondOrderROM":
        """Read a model written by :meth:`save`.

        ``nonlinear``: the full-order force of a projected-force term whose
        parameters could not be stored (checked against the saved class);
        ``context``: passed to the terms' ``load`` (a user's term may need more).
        """
        import h5py

        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != "femrom.SecondOrderROM":
                raise FemromValueError(f"{path} is not a femrom SecondOrderROM file")
            version = int(f.attrs.get("version", 1))
            if version != FILE_VERSION:
                raise FemromValueError(f"{path} has layout version {version}; this femrom reads {FILE_VERSION}")
            metadata = json.loads(f.attrs["metadata"])
            basis = f["basis"][()] if "basis" in f else None
            terms = [term_class(name).load(group, basis=basis, nonlinear=nonlinear, **context)
                     for name, group in f["terms"].items()]
        return cls(ReducedOperators(tuple(terms), metadata), basis, product=product)
