r"""Symplectic time stepping of linear canonical Hamiltonian ROMs.

``q' = D_p p``, ``p' = -D_q q`` (``H = q^T D_q q / 2 + p^T D_p p / 2``), with
``h = dt``:

- ``"symplectic_euler_a"``: ``q_{k+1} = q_k + h D_p p_k``, ``p_{k+1} = p_k - h D_q q_{k+1}``;
- ``"symplectic_euler_b"``: ``p_{k+1} = p_k - h D_q q_k``, ``q_{k+1} = q_k + h D_p p_{k+1}``;
- ``"verlet"``: half a step of ``p``, a full step of ``q``, half a step of ``p``;
- ``"midpoint"``: the implicit midpoint rule, ``(I - h A / 2) y_{k+1} = (I + h A / 2) y_k``.

All four are symplectic (Hairer, Lubich & Wanner, Geometric Numerical
Integration, 2006, VI.3); the midpoint rule also conserves the quadratic ``H``
exactly, the others a modified Hamiltonian (no drift). Each becomes one
precomputed (2r, 2r) step matrix.

With a known nonlinear term, ``H^ = q^T D_q q / 2 + p^T D_p p / 2 + H_nl(Phi q, Phi p)``
(:class:`femrom.inference.ProjectedPotential`), the ROM steps
``y' = J_{2r} grad H^`` with :func:`femrom.integrators.integrate_canonical`:
``"midpoint"`` (implicit midpoint with Newton on the symmetric tangent
``grad^2 H^``: symplectic, exact for quadratic invariants, ``H^`` oscillates
by ``O(h^2)`` without drift) or ``"avf"`` (average vector field: ``H^``
conserved to the Newton tolerance, not symplectic). The explicit symplectic
Euler and Stoermer-Verlet splittings need a separable ``H^ = T(p) + V(q)``;
a potential coupling ``q`` and ``p`` (the NLS) is not, so they are refused.
Without a potential ``"avf"`` is the midpoint rule (the average of a linear
gradient is its midpoint value).

:class:`HamiltonianROM` is built intrusively (:meth:`HamiltonianROM.galerkin`,
``D~ = Phi^T D Phi``) or learned (``HamiltonianROM(basis=Phi,
learner=HamiltonianOpInf()).fit(data)`` on :class:`~femrom.inference.CanonicalData`,
or :meth:`HamiltonianROM.fit_snapshots` on full snapshots); :meth:`HamiltonianROM.predict`
returns a :class:`HamiltonianSolution` (reduced trajectories, ``H^``, outputs;
full fields rebuilt only on request) and :meth:`HamiltonianROM.save` /
:meth:`HamiltonianROM.load` keep the model in HDF5 with its metadata.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field

import numpy as np

from femrom._errors import FemromTypeError, FemromValueError
from femrom._json import dumps
from femrom.inference import CanonicalData, HamiltonianOperators, HamiltonianOpInf, ProjectedPotential
from femrom.integrators import CanonicalSystem, Newton, integrate_canonical, run_linear, time_scheme
from femrom.rom._base import LazyFields, ReducedModel, uniform_step
from femrom.rom._statespace import DiscreteStateSpace

#: Largest ``max |Phi^T Phi - I|`` accepted for a cotangent lift: SVD bases are
#: orthonormal to ~1e-15 sqrt(n), randomized ones to ~1e-12; beyond 1e-8 the
#: lift's symplecticity ``A^T J A = J`` (and ``Q^ = Phi^T Q``) fails at that level.
_ORTHONORMALITY = 1e-8


def canonical_scheme(name, potential: bool):
    """The registered scheme ``name`` for a canonical model (with a non-separable potential: one
    with a quadrature of the gradient along the step); one clear error otherwise."""
    scheme = time_scheme(name)
    scheme.check_kind("canonical")
    if potential:
        scheme.canonical_nodes()            # raises for a scheme that needs a separable H
    return scheme


def hamiltonian_step_matrix(ops: HamiltonianOperators, dt: float, scheme) -> np.ndarray:
    """(2r, 2r) ndarray ``S`` with ``[q; p]_{k+1} = S [q; p]_k`` of a registered canonical scheme."""
    return canonical_scheme(scheme, False).canonical_step_matrix(ops.position, ops.momentum, float(dt))


@dataclass(frozen=True, eq=False)
class HamiltonianSolution(LazyFields):
    """A reduced canonical trajectory; full fields are rebuilt only on request.

    Unpacks as ``q, p, hamiltonian = solution`` (what ``predict`` returned
    before it returned this object).

    Attributes
    ----------
    t : (k,) ndarray
    q, p : (r, k) ndarray
        Reduced positions and momenta.
    hamiltonian : (k,) ndarray
        ``H^(q, p)``: ``q^T D^_q q / 2 + p^T D^_p p / 2 (+ H_nl(Phi q, Phi p))``.
    outputs : (m, k) ndarray or None
        ``E^ [q; p]``.
    basis : (n, r) ndarray or None
        ``Phi`` (a reference, not a copy).
    info : dict
        Scheme, step, timings, Newton iterations (with a potential).
    """

    t: np.ndarray
    q: np.ndarray
    p: np.ndarray
    hamiltonian: np.ndarray
    outputs: np.ndarray | None = None
    basis: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    def __iter__(self):
        return iter((self.q, self.p, self.hamiltonian))

    @property
    def energy(self) -> np.ndarray:
        """(k,) ndarray: the reduced Hamiltonian (the name :class:`ReducedSolution` uses)."""
        return self.hamiltonian

    FIELDS = ("q", "p")


class HamiltonianROM(ReducedModel):
    r"""A canonical Hamiltonian ROM (linear, or with a known projected potential).

    .. math::

        \dot{\hat q} = \hat D_p \hat p + \nabla_{\hat p} \hat H_{nl}, \qquad
        \dot{\hat p} = -\hat D_q \hat q - \nabla_{\hat q} \hat H_{nl}, \qquad
        y = \hat E [\hat q; \hat p], \qquad (q, p) \approx (\Phi \hat q, \Phi \hat p),

    with ``H^_nl(q^, p^) = H_nl(Phi q^, Phi p^)``.

    Parameters
    ----------
    operators : HamiltonianOperators, optional
        Given ``D^_q``, ``D^_p`` (else :meth:`fit` or :meth:`galerkin`).
    basis : (n, r) ndarray, optional
        The cotangent-lift ``Phi`` (``Phi^T Phi = I``): ``q ~ Phi q^``, ``p ~ Phi p^``.
    potential : object, optional
        The known full-order ``H_nl`` (``value``, ``gradient``, ``hessian``);
        needs ``basis``. The ROM uses ``H_nl(Phi q^, Phi p^)``.
    newton : Newton
        Tolerances of the implicit steps with a potential.
    learner : HamiltonianOpInf, optional
        What :meth:`fit` uses (default ``HamiltonianOpInf()``).
    output_matrix : (m, 2r) ndarray, optional
        ``E^`` acting on ``[q^; p^]``.
    scheme : str
        Default scheme of :meth:`predict`: ``"midpoint"``, ``"avf"``,
        ``"symplectic_euler_a"``, ``"symplectic_euler_b"``, ``"verlet"`` (the
        last three without a potential only).

    Attributes
    ----------
    operators_ : HamiltonianOperators
    output_matrix_ : (m, 2r) ndarray or None
    potential_ : ProjectedPotential or None
    metadata_ : dict
        How the operators were obtained (learner settings and error split, or
        ``{"method": "galerkin"}``); saved with the model.
    last_trajectory_ : CanonicalTrajectory
        Newton iterations and stepping time of the last nonlinear ``predict``.
    """

    def __init__(self, operators: HamiltonianOperators | None = None,
                 basis: np.ndarray | None = None, potential=None,
                 newton: Newton = Newton(rtol=1e-12), *, learner: HamiltonianOpInf | None = None,
                 output_matrix: np.ndarray | None = None, scheme: str = "midpoint"):
        if potential is not None and basis is None:
            raise FemromValueError("a known potential is evaluated through the basis: give basis")
        canonical_scheme(scheme, potential is not None)
        self.basis = None if basis is None else np.asarray(basis, dtype=float)
        if operators is not None and self.basis is not None and self.basis.shape[1] != operators.r:
            raise FemromValueError(f"basis has {self.basis.shape[1]} columns, operators have r = {operators.r}")
        self.operators_ = operators
        self.newton = newton
        self.learner = learner
        self.scheme = scheme
        self.potential = potential
        self.potential_ = None if potential is None else ProjectedPotential(potential, self.basis)
        self.output_matrix_ = None if output_matrix is None else np.atleast_2d(
            np.asarray(output_matrix, dtype=float))
        self.metadata_ = {"method": "given"} if operators is not None else {}

    # -- construction --------------------------------------------------------
    @classmethod
    def galerkin(cls, system: CanonicalSystem, basis: np.ndarray, *,
                 output_matrix=None, newton: Newton = Newton(rtol=1e-12),
                 scheme: str = "midpoint") -> "HamiltonianROM":
        """The intrusive ROM: ``D~_q = Phi^T D_q Phi``, ``D~_p = Phi^T D_p Phi``, the system's potential.

        Parameters
        ----------
        system : CanonicalSystem
            Full ``D_q``, ``D_p`` (dense or sparse) and potential.
        basis : (n, r) ndarray
            ``Phi`` with ``Phi^T Phi = I``.
        output_matrix : (m, 2n) array, optional
            Full output map of ``[q; p]``; reduced to ``E [Phi, 0; 0, Phi]``.
        """
        V = _cotangent_lift(basis)
        n = V.shape[0]

        def project(D):
            A = V.T @ np.asarray(D @ V)
            return 0.5 * (A + A.T)      # symmetric to round-off anyway: keep it exactly

        ops = HamiltonianOperators(position=project(system.position),
                                   momentum=project(system.momentum))
        E = None
        if output_matrix is not None:
            E_full = output_matrix
            if E_full.shape[1] != 2 * n:
                raise FemromValueError(f"output_matrix has {E_full.shape[1]} columns, expected 2n = {2 * n}")
            E = np.hstack([np.asarray(E_full[:, :n] @ V), np.asarray(E_full[:, n:] @ V)])
        rom = cls(ops, V, system.potential, newton, output_matrix=E, scheme=scheme)
        rom.metadata_ = {"method": "galerkin"}
        return rom

    def fit(self, data: CanonicalData, *, validation=None) -> "HamiltonianROM":
        r"""Learn ``D^_q``, ``D^_p`` (and ``E^`` when the data carry outputs) with the learner.

        Parameters
        ----------
        data : CanonicalData
            Reduced data, e.g. :func:`femrom.inference.reduce_canonical_snapshots`
            of full snapshots on this model's basis and potential (what
            :meth:`fit_snapshots` does).
        validation : CanonicalData, optional
            Held-out data the learner judges itself on.

        Returns
        -------
        self
        """
        if self.learner is None:
            self.learner = HamiltonianOpInf()
        learner = self.learner.fit(data, validation=validation)
        self.operators_ = learner.operators_
        if learner.output_matrix_ is not None:
            self.output_matrix_ = learner.output_matrix_
        self.metadata_ = learner.describe()
        return self

    def fit_snapshots(self, Q: np.ndarray, P: np.ndarray, dt: float | None = None, **options) -> "HamiltonianROM":
        r"""Project full snapshots on this model's basis (and potential) and :meth:`fit`.

        Parameters
        ----------
        Q, P : (n, K) ndarray
            Position and momentum snapshots on a uniform grid of step ``dt``.
        dt : float, optional
            Needed for finite-difference derivatives.
        **options
            Of :func:`femrom.inference.reduce_canonical_snapshots`: ``ddt_q``,
            ``ddt_p``, ``derivatives``, ``order``, ``gradient_data``, ``outputs``.
        """
        from femrom.inference import reduce_canonical_snapshots

        if self.basis is None:
            raise FemromValueError("fit projects full snapshots onto the cotangent lift: pass basis=Phi")
        _cotangent_lift(self.basis)
        return self.fit(reduce_canonical_snapshots(self.basis, Q, P, dt, potential=self.potential, **options))

    # -- evaluation ----------------------------------------------------------
    def _ops(self) -> HamiltonianOperators:
        if self.operators_ is None:
            raise FemromValueError("this ROM is not fitted: call fit(Q, P, dt), galerkin(...) or pass operators")
        return self.operators_

    @property
    def r(self) -> int:
        return self._ops().r

    @property
    def system_(self) -> CanonicalSystem:
        ops = self._ops()
        return CanonicalSystem(ops.position, ops.momentum, self.potential_)

    def hamiltonian(self, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Reduced ``H^`` of (r, k) columns: quadratic part plus ``H_nl(Phi q^, Phi p^)``."""
        return np.atleast_1d(self.system_.hamiltonian(q, p))

    def outputs(self, q: np.ndarray, p: np.ndarray) -> np.ndarray | None:
        """(m, k) ndarray ``E^ [q; p]`` (``None`` without an output map)."""
        E = self.output_matrix_
        return None if E is None else E @ np.vstack([q, p])

    def reconstruct(self, q: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Full ``(Phi q^, Phi p^)`` now (a solution's :meth:`~HamiltonianSolution.fields` streams them)."""
        if self.basis is None:
            raise FemromValueError("this model has no basis: full fields cannot be reconstructed")
        return self.basis @ q, self.basis @ p

    def predict(self, times, inputs=None, *, initial=None, scheme: str | None = None) -> HamiltonianSolution:
        r"""Integrate the ROM on a uniform time grid.

        Parameters
        ----------
        times : (k,) ndarray
            Uniform grid ``t_0, t_0 + h, ...``.
        inputs : None
            A canonical model has no inputs.
        initial : (q0, p0), optional
            Initial position and momentum, each reduced (r,) or full (n,) (then ``Phi^T x``);
            with ``r = n`` a vector is read as reduced. Default rest.
        scheme : str, optional
            Default: the model's ``scheme``. Without a potential one precomputed
            (2r, 2r) step matrix (:func:`hamiltonian_step_matrix`); with one,
            :func:`femrom.integrators.integrate_canonical` (``"midpoint"``, ``"avf"``: the registered
            schemes with a quadrature of the gradient).

        Returns
        -------
        HamiltonianSolution
            Unpacks as ``(q, p, hamiltonian)``.
        """
        scheme = self.scheme if scheme is None else scheme
        ops = self._ops()
        times, h = uniform_step(times)
        q0, p0 = self.canonical_initial(initial, inputs)
        r, n_steps = ops.r, times.size - 1
        info = {"scheme": scheme, "dt": h, "n_steps": n_steps}
        tic = time.perf_counter()
        if self.potential_ is not None:
            canonical_scheme(scheme, True)
            tr = integrate_canonical(self.system_, q0, p0, h, n_steps, scheme, self.newton)
            self.last_trajectory_ = tr
            Q, P, H = tr.q, tr.p, tr.hamiltonian
            info.update(stepping_seconds=tr.seconds, newton_iterations=int(tr.iterations.sum()))
        else:
            S = hamiltonian_step_matrix(ops, h, scheme)
            loop = {}
            X = run_linear(S, np.concatenate([q0, p0]), n_steps, None, timing=loop)
            info["stepping_seconds"] = loop["loop_seconds"]
            Q, P = X[:r], X[r:]
            H = ops.hamiltonian(Q, P)
        info["seconds"] = time.perf_counter() - tic
        info["seconds_per_step"] = info["stepping_seconds"] / max(n_steps, 1)
        return HamiltonianSolution(t=times, q=Q, p=P, hamiltonian=H, outputs=self.outputs(Q, P),
                                   basis=self.basis, info=info)

    def stepper(self, dt: float, *, initial=None, scheme: str | None = None) -> "HamiltonianStepper":
        """A :class:`HamiltonianStepper` at ``initial = (q0, p0)`` (reduced or full): ``y = stepper.step()``."""
        q0, p0 = self.canonical_initial(initial)
        return HamiltonianStepper(self, q0, p0, float(dt), self.scheme if scheme is None else scheme)

    def to_state_space(self, dt: float, scheme: str | None = None) -> DiscreteStateSpace:
        """``z+ = S z``, ``y = E^ z`` (``z = [q^; p^]``, no inputs) of a model without a potential."""
        if self.potential_ is not None:
            raise FemromValueError("the model has a nonlinear potential: it has no linear state-space form")
        S = hamiltonian_step_matrix(self._ops(), dt, self.scheme if scheme is None else scheme)
        n = S.shape[0]
        C = np.eye(n) if self.output_matrix_ is None else self.output_matrix_
        return DiscreteStateSpace(A=S, B=np.zeros((n, 0)), C=C, D=np.zeros((C.shape[0], 0)), dt=float(dt),
                                  metadata={"scheme": self.scheme if scheme is None else scheme,
                                            "state": "[q; p]"})

    # -- storage -------------------------------------------------------------
    def save(self, path, *, include_basis: bool = True) -> None:
        """Write operators, output map, optional basis, scheme, Newton tolerances and metadata to HDF5.

        A known potential is code, not data: the file records its class and,
        for a dataclass with plain fields (e.g. ``QuarticPotential(gamma)``),
        its parameters; :meth:`load` needs it passed again and checks it
        against that record.
        """
        import h5py

        ops = self._ops()
        if self.potential is not None and not (include_basis and self.basis is not None):
            raise FemromValueError("a model with a known potential evaluates it through the basis: "
                             "save it with include_basis=True")
        with h5py.File(path, "w") as f:
            f.attrs["format"] = "femrom.HamiltonianROM"
            f.attrs["version"] = 1
            f.attrs["scheme"] = self.scheme
            f.attrs["newton"] = json.dumps(dataclasses.asdict(self.newton))
            f.attrs["potential"] = json.dumps(None if self.potential is None
                                              else _describe_potential(self.potential))
            f.attrs["metadata"] = dumps(self.metadata_)
            g = f.create_group("operators")
            g.create_dataset("position", data=ops.position)
            g.create_dataset("momentum", data=ops.momentum)
            if self.output_matrix_ is not None:
                g.create_dataset("output_matrix", data=self.output_matrix_)
            if include_basis and self.basis is not None:
                f.create_dataset("basis", data=self.basis, compression="gzip")

    @classmethod
    def load(cls, path, *, potential=None, newton: Newton | None = None) -> "HamiltonianROM":
        """Read a model written by :meth:`save`.

        Parameters
        ----------
        path : str or Path
        potential : object, optional
            The known ``H_nl``: required when the saved model had one (it is
            checked against the stored class and parameters), refused when it
            had none.
        newton : Newton, optional
            Replaces the saved tolerances.
        """
        import h5py

        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != "femrom.HamiltonianROM":
                raise FemromValueError(f"{path} is not a femrom HamiltonianROM file")
            g = f["operators"]
            ops = HamiltonianOperators(position=g["position"][()], momentum=g["momentum"][()])
            E = g["output_matrix"][()] if "output_matrix" in g else None
            basis = f["basis"][()] if "basis" in f else None
            scheme = str(f.attrs["scheme"])
            saved_newton = Newton(**json.loads(f.attrs["newton"]))
            stored = json.loads(f.attrs["potential"])
            metadata = json.loads(f.attrs["metadata"])
        if stored is not None and potential is None:
            raise FemromValueError(f"{path} holds a model with a known potential ({stored['repr']}), "
                             "which cannot be stored: pass potential=...")
        if stored is None and potential is not None:
            raise FemromValueError(f"{path} holds a model without a potential, but potential was given")
        if stored is not None:
            given = _describe_potential(potential)
            if given["class"] != stored["class"] or (
                    stored["parameters"] is not None and given["parameters"] != stored["parameters"]):
                raise FemromValueError(f"potential {given['repr']} does not match the saved "
                                 f"{stored['repr']}")
        rom = cls(ops, basis, potential, saved_newton if newton is None else newton,
                  output_matrix=E, scheme=scheme)
        rom.metadata_ = metadata
        return rom


def _describe_potential(potential) -> dict:
    """``{"class", "parameters", "repr"}`` of a potential: what of it a file can hold.

    ``parameters`` are the fields of a dataclass when all are plain numbers,
    strings or arrays (JSON), else ``None``.
    """
    cls = type(potential)
    parameters = None
    if dataclasses.is_dataclass(potential) and not isinstance(potential, type):
        try:
            parameters = json.loads(json.dumps(
                {f.name: _plain(getattr(potential, f.name)) for f in dataclasses.fields(potential)}))
        except TypeError:
            parameters = None
    return {"class": f"{cls.__module__}.{cls.__qualname__}", "parameters": parameters,
            "repr": repr(potential)[:200]}


def _plain(value):
    if isinstance(value, np.ndarray) and value.dtype.kind in "biuf":
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    raise FemromTypeError(f"{type(value).__name__} is not plain data")


def _cotangent_lift(basis) -> np.ndarray:
    V = np.asarray(basis, dtype=float)
    if V.ndim != 2:
        raise FemromValueError(f"basis must be (n, r), got shape {V.shape}")
    error = float(np.max(np.abs(V.T @ V - np.eye(V.shape[1]))))
    if error > _ORTHONORMALITY:
        raise FemromValueError(f"basis is not orthonormal (max |Phi^T Phi - I| = {error:.2g}): "
                         "a cotangent lift needs Phi^T Phi = I")
    return V


class HamiltonianStepper:
    """A canonical ROM one step at a time: ``y_{k+1} = stepper.step()`` (no inputs).

    Linear models apply the scheme's step matrix; with a potential each step
    is one :func:`~femrom.integrators.integrate_canonical` step.
    """

    def __init__(self, rom: HamiltonianROM, q0, p0, dt: float, scheme: str):
        self.rom, self.dt, self.scheme = rom, dt, scheme
        self.q, self.p, self.t = np.array(q0, dtype=float), np.array(p0, dtype=float), 0.0
        self._S = None if rom.potential_ is not None else hamiltonian_step_matrix(rom._ops(), dt, scheme)
        canonical_scheme(scheme, rom.potential_ is not None)

    @property
    def outputs(self) -> np.ndarray:
        E = self.rom.output_matrix_
        y = np.concatenate([self.q, self.p])
        return y if E is None else E @ y

    def step(self, u=None) -> np.ndarray:
        """Advance by ``dt``; return ``E^ [q; p]`` (``[q; p]`` without an output map)."""
        if u is not None and np.size(u):
            raise FemromValueError("a canonical Hamiltonian ROM has no inputs")
        if self._S is not None:
            y = self._S @ np.concatenate([self.q, self.p])
            r = self.q.size
            self.q, self.p = y[:r], y[r:]
        else:
            tr = integrate_canonical(self.rom.system_, self.q, self.p, self.dt, 1, self.scheme, self.rom.newton)
            self.q, self.p = tr.q[:, 1], tr.p[:, 1]
        self.t += self.dt
        return self.outputs
