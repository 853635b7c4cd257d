"""The full-order model a scene builds: a sparse second-order system."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.fem import Condensation, ForceSum, NonlinearForce, sum_of_forces, transform_force


@dataclass(frozen=True, eq=False)
class SecondOrderSystem:
    r"""``M q'' + C q' + K q + f_nl(q, q'; s) = B u(t) + f_0``,  ``y = E q``: the one model type.

    The full-order model a scene builds (sparse operators on the free dofs), its
    Galerkin projections, learned and hyper-reduced models (dense (r, r) operators)
    are all instances: every time scheme, stepper, stepped sine and plant runs on
    any of them. Only the operators of the effects present are held; an absent
    effect is ``None`` and costs nothing downstream.

    Attributes
    ----------
    mass : (n, n) sparse or ndarray
        Consistent or lumped mass ``M`` (SPD).
    stiffness : (n, n) sparse or ndarray
        Stiffness ``K`` (symmetric; SPD once rigid-body modes are constrained).
    damping : (n, n) sparse or ndarray, or None
        Damping ``C`` (symmetric positive semidefinite), e.g. Rayleigh ``a M + b K``.
    input_matrix : (n, m) ndarray or sparse, or None
        Input columns ``B``.
    inputs : callable or None
        ``u(t) -> (m,) ndarray``: the model's own inputs (a scene's signals); without
        them the inputs are zero unless a caller supplies samples (a prediction).
    output_matrix : (p, n) sparse or ndarray, or None
        Output rows ``E``.
    nonlinear : NonlinearForce, sequence of them, or None
        Nonlinear internal forces, each on its own local coordinates with its
        own state; several are kept as one :class:`~femrom.fem.ForceSum`
        (:attr:`nonlinear_forces` lists them). A reduced model's learned terms are
        accepted as they are: any object with ``force``, ``tangent``,
        ``initial_state`` and ``commit`` (``femrom.inference`` holds them).
    load : (n,) ndarray or None
        A constant external force ``f_0`` (gravity, a preload).
    condensation : Condensation
        Free/fixed dof map back to full fields.
    output_names : tuple of str
        One name per output row.
    metadata : dict
        What built the system (scene name, mesh size, timings of each stage).
    """

    mass: sp.csr_matrix
    stiffness: sp.csr_matrix
    damping: sp.csr_matrix | None = None
    input_matrix: Any = None
    inputs: Callable[[float], np.ndarray] | None = None
    output_matrix: sp.csr_matrix | None = None
    nonlinear: NonlinearForce | None = None
    load: np.ndarray | None = None
    condensation: Condensation | None = None
    output_names: tuple[str, ...] = ()
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        n = self.mass.shape[0]
        for name in ("mass", "stiffness", "damping"):
            A = getattr(self, name)
            if A is not None and A.shape != (n, n):
                raise FemromValueError(f"{name} has shape {A.shape}, expected ({n}, {n})")
        for name in ("mass", "stiffness", "damping", "input_matrix", "output_matrix"):
            A = getattr(self, name)
            if A is None:
                continue
            values = A.data if sp.issparse(A) else np.asarray(A)
            if not np.issubdtype(values.dtype, np.number) or np.iscomplexobj(values):
                raise FemromValueError(f"{name} must be a real matrix, got dtype {values.dtype}")
            if not np.all(np.isfinite(values)):
                raise FemromValueError(f"{name} has non-finite entries")
        if self.inputs is not None and self.input_matrix is None:
            raise FemromValueError("inputs were given without an input_matrix")
        if self.input_matrix is not None and self.input_matrix.shape[0] != n:
            raise FemromValueError(f"input_matrix has {self.input_matrix.shape[0]} rows, expected {n}")
        if self.output_matrix is not None and self.output_matrix.shape[1] != n:
            raise FemromValueError(f"output_matrix has {self.output_matrix.shape[1]} columns, expected {n}")
        if isinstance(self.nonlinear, (list, tuple)):
            object.__setattr__(self, "nonlinear", sum_of_forces(self.nonlinear))
        if self.nonlinear is not None and not isinstance(self.nonlinear, NonlinearForce) and not all(
                callable(getattr(self.nonlinear, name, None)) for name in ("force", "tangent", "initial_state", "commit")):
            raise FemromValueError(f"nonlinear must be a NonlinearForce, a sequence of them, or a reduced force "
                                  f"with force, tangent, initial_state and commit; got {type(self.nonlinear).__name__}")
        size = getattr(self.nonlinear, "n_dofs", n)
        if size != n:
            raise FemromValueError(f"nonlinear force acts on {size} dofs, expected {n}")
        if self.load is not None:
            load = np.asarray(self.load, dtype=float).ravel()
            if load.shape != (n,):
                raise FemromValueError(f"load has shape {load.shape}, expected ({n},)")
            object.__setattr__(self, "load", load)
        if self.condensation is None:
            object.__setattr__(self, "condensation", Condensation.none(n))
        elif self.condensation.n_free != n:
            raise FemromValueError(f"condensation has {self.condensation.n_free} free dofs, expected {n}")

    # -- sizes and flags -------------------------------------------------
    @property
    def n_dofs(self) -> int:
        return self.mass.shape[0]

    @property
    def n_inputs(self) -> int:
        return 0 if self.input_matrix is None else self.input_matrix.shape[1]

    @property
    def n_outputs(self) -> int:
        return 0 if self.output_matrix is None else self.output_matrix.shape[0]

    @property
    def is_linear(self) -> bool:
        return self.nonlinear is None

    @property
    def is_dense(self) -> bool:
        """Whether the operators are ndarrays (a reduced model) rather than sparse matrices."""
        return not sp.issparse(self.stiffness)

    @property
    def nonlinear_forces(self) -> tuple:
        """The nonlinear forces one by one (empty for a linear system; a reduced model's terms)."""
        if self.nonlinear is None:
            return ()
        if isinstance(self.nonlinear, ForceSum):
            return self.nonlinear.forces
        terms = getattr(self.nonlinear, "terms", None)
        return tuple(terms) if isinstance(terms, (tuple, list)) else (self.nonlinear,)

    @property
    def has_diagonal_mass(self) -> bool:
        if self.is_dense:
            M = np.asarray(self.mass)
            return bool(np.all(M == np.diag(np.diag(M))))
        M = sp.csr_matrix(self.mass)
        return M.nnz == np.count_nonzero(M.diagonal()) and M.nnz <= M.shape[0]

    @property
    def effects(self) -> tuple[str, ...]:
        """The operator terms present, in the order of the equation."""
        present = ["inertia", "stiffness"]
        if self.damping is not None:
            present.append("damping")
        if self.nonlinear is not None:
            present.append("nonlinear")
        if self.input_matrix is not None:
            present.append("inputs")
        if self.load is not None:
            present.append("load")
        if self.output_matrix is not None:
            present.append("outputs")
        return tuple(present)

    def about(self, reference: np.ndarray) -> "SecondOrderSystem":
        r"""The model on the coordinates ``x = q - q_0`` about a reference state ``q_0`` (a preloaded equilibrium).

        ``M x'' + C x' + K x + f(q_0 + x, x'; s) = B u + (f_0 - K q_0)``: the load becomes
        ``f_0 - K q_0``, the nonlinear force reads ``q_0 + x`` (its state unchanged), the
        outputs ``E x`` are measured from ``q_0``. Projections of the result are models about
        the reference (``q = q_0 + V q^``).
        """
        q0 = np.asarray(reference, dtype=float).reshape(-1)
        n = self.n_dofs
        if q0.shape != (n,) or not np.all(np.isfinite(q0)):
            raise FemromValueError(f"reference must be a finite ({n},) vector, got shape {q0.shape}")
        load = (np.zeros(n) if self.load is None else self.load) - np.asarray(self.stiffness @ q0).reshape(-1)
        force = self.nonlinear
        if isinstance(force, NonlinearForce):
            force = transform_force(force, None, reference=q0)
        elif force is not None:
            raise FemromValueError("a model about a reference needs full-order nonlinear forces (NonlinearForce)")
        return replace(self, load=load, nonlinear=force, metadata={**self.metadata, "about_reference": True})

    # -- evaluations -----------------------------------------------------
    def external_force(self, t: float) -> np.ndarray | None:
        """(n,) ndarray ``B u(t) + f_0``, or ``None`` without inputs or load (no ``u(t)``: zero inputs)."""
        if self.input_matrix is None or self.inputs is None:
            return self.load
        u = np.atleast_1d(np.asarray(self.inputs(t), dtype=float))
        f = np.asarray(self.input_matrix @ u).ravel()
        return f if self.load is None else f + self.load

    def internal_force(self, q: np.ndarray, v: np.ndarray, state: Any = None) -> np.ndarray:
        """(n,) ndarray ``C v + K q + f_nl(q, v)``."""
        f = self.stiffness @ q
        if self.damping is not None:
            f = f + self.damping @ v
        if self.nonlinear is not None:
            f = f + self.nonlinear.force(q, v, state)
        return f

    def residual_force(self, t: float, q: np.ndarray, v: np.ndarray, state: Any = None) -> np.ndarray:
        """(n,) ndarray ``B u(t) - C v - K q - f_nl``: the right side of ``M a = .``."""
        f = -self.internal_force(q, v, state)
        ext = self.external_force(t)
        return f if ext is None else f + ext

    def kinetic_energy(self, v: np.ndarray) -> float:
        return 0.5 * float(v @ (self.mass @ v))

    def potential_energy(self, q: np.ndarray) -> float:
        """``q^T K q / 2 + U_nl(q) - f_0^T q``; raises for a non-conservative nonlinear force."""
        energy = 0.5 * float(q @ (self.stiffness @ q))
        if self.nonlinear is not None:
            energy += self.nonlinear.potential(q)
        if self.load is not None:
            energy -= float(self.load @ q)
        return energy

    def energy(self, q: np.ndarray, v: np.ndarray) -> float:
        """Total mechanical energy ``v^T M v / 2 + q^T K q / 2 + U_nl(q) - f_0^T q``."""
        return self.kinetic_energy(v) + self.potential_energy(q)

    def outputs(self, q: np.ndarray) -> np.ndarray | None:
        """(p,) or (p, k) ndarray ``E q``, or ``None`` without outputs."""
        if self.output_matrix is None:
            return None
        return np.asarray(self.output_matrix @ q)

    def full_field(self, q: np.ndarray) -> np.ndarray:
        """Map free-dof vectors back to the full mesh dofs (zeros on Dirichlet dofs)."""
        return self.condensation.expand(q)
