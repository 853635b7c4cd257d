r"""Reduced second-order operators and their two views.

A reduced model in ``r`` generalized coordinates ``q^`` reads

.. math::

    \hat M \ddot{\hat q} + \hat C \dot{\hat q} + \hat K \hat q
        + \hat f(\hat q, \dot{\hat q}) = \hat B u(t), \qquad y = \hat E \hat q .

Each term is an operator with two views (as in the ``opinf`` package):

- :meth:`galerkin` -- its intrusive projection onto a basis ``V`` (n, r) of a
  :class:`~femrom.scene.SecondOrderSystem` (``V^T K V``, ``V^T C V``,
  ``V^T B``, ``E V``, ``V^T f(V q^)``);
- :meth:`datablock` -- its rows of data in the regression
  ``|| M^ Q'' + F^ + X D ||_F`` (the reduced states for ``K``, the velocities
  for ``C``, minus the inputs for ``B``).

Whether the mass is the identity depends on the basis: ``V^T M V = I`` holds
for a mass-orthonormal basis only (``../shared/DESIGN.md``, "The reduced
mass").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp


def _dense(A) -> np.ndarray:
    return A.toarray() if sp.issparse(A) else np.asarray(A, dtype=float)


def _sym_project(A, V: np.ndarray) -> np.ndarray:
    """``V^T A V`` symmetrised (round-off only) for a symmetric ``A``."""
    P = V.T @ np.asarray(A @ V)
    return 0.5 * (P + P.T)


@dataclass(frozen=True)
class Stiffness:
    r"""``K^ q^``: symmetric positive definite, ``K^ >= eps I`` when learned."""

    name = "stiffness"
    structure = "psd"

    @staticmethod
    def galerkin(system, V: np.ndarray) -> np.ndarray:
        """(r, r) ndarray ``V^T K V``."""
        return _sym_project(system.stiffness, V)

    @staticmethod
    def datablock(data) -> np.ndarray:
        """(r, K) ndarray: the reduced states ``Q^``."""
        return data.states


@dataclass(frozen=True)
class Damping:
    r"""``C^ q^'``: symmetric positive semidefinite."""

    name = "damping"
    structure = "psd"

    @staticmethod
    def galerkin(system, V: np.ndarray) -> np.ndarray | None:
        """(r, r) ndarray ``V^T C V`` (``None`` without damping)."""
        return None if system.damping is None else _sym_project(system.damping, V)

    @staticmethod
    def datablock(data) -> np.ndarray:
        """(r, K) ndarray: the reduced velocities ``Q^'``."""
        return data.velocities


@dataclass(frozen=True)
class Input:
    r"""``B^ u``: unconstrained (r, m)."""

    name = "input"
    structure = "free"

    @staticmethod
    def galerkin(system, V: np.ndarray) -> np.ndarray | None:
        """(r, m) ndarray ``V^T B`` (``None`` without inputs)."""
        if system.input_matrix is None:
            return None
        return np.asarray(V.T @ _dense(system.input_matrix))

    @staticmethod
    def datablock(data) -> np.ndarray:
        """(m, K) ndarray ``-U``: the sign moves ``B^ U`` to the residual's side."""
        return -data.inputs


@dataclass(frozen=True)
class Mass:
    r"""``M^ q^''``: the identity for a mass-orthonormal basis."""

    name = "mass"

    @staticmethod
    def galerkin(system, V: np.ndarray) -> np.ndarray:
        """(r, r) ndarray ``V^T M V``."""
        return _sym_project(system.mass, V)

    @staticmethod
    def datablock(data) -> np.ndarray:
        """(r, K) ndarray: the reduced accelerations ``Q^''``."""
        return data.accelerations


@dataclass(frozen=True)
class Output:
    r"""``y = E^ q^``, fitted by least squares from recorded outputs."""

    name = "output"

    @staticmethod
    def galerkin(system, V: np.ndarray) -> np.ndarray | None:
        """(p, r) ndarray ``E V`` (``None`` without outputs)."""
        if system.output_matrix is None:
            return None
        return np.asarray(system.output_matrix @ V)

    @staticmethod
    def datablock(data) -> np.ndarray:
        """(r, K) ndarray: the reduced states ``Q^``."""
        return data.states


class ProjectedNonlinearForce:
    r"""``f^(q^, v^) = V^T f_nl(V q^, V v^)`` with tangent ``V^T J V``.

    The projection of a known nonlinear force (``femrom.fem.NonlinearForce``):
    every evaluation costs a full-order one (no hyper-reduction). Internal
    state (stick-slip joints) is carried through on the full dofs.

    Parameters
    ----------
    force : NonlinearForce
    basis : (n, r) ndarray
    """

    def __init__(self, force, basis: np.ndarray):
        self.force_model = force
        self.basis = np.asarray(basis, dtype=float)
        self.conservative = bool(getattr(force, "conservative", False))
        self.velocity_dependent = bool(getattr(force, "velocity_dependent", False))

    def initial_state(self) -> Any:
        return self.force_model.initial_state()

    def force(self, q, v=None, state=None) -> np.ndarray:
        """(r,) ndarray ``V^T f_nl(V q, V v)``."""
        V = self.basis
        return V.T @ self.force_model.force(V @ q, None if v is None else V @ v, state)

    def forces(self, Q: np.ndarray, Vel: np.ndarray | None = None) -> np.ndarray:
        """(r, K) ndarray: :meth:`force` of every column (stateless forces)."""
        return np.column_stack([self.force(Q[:, k], None if Vel is None else Vel[:, k])
                                for k in range(Q.shape[1])])

    def tangent(self, q, v=None, state=None):
        """``(V^T df/dq V, V^T df/dv V)`` as (r, r) ndarrays (the second may be ``None``)."""
        V = self.basis
        dq, dv = self.force_model.tangent(V @ q, None if v is None else V @ v, state)
        Jq = None if dq is None else V.T @ np.asarray(dq @ V)
        Jv = None if dv is None else V.T @ np.asarray(dv @ V)
        return Jq, Jv

    def potential(self, q) -> float:
        return self.force_model.potential(self.basis @ q)

    def commit(self, q, v, state):
        return self.force_model.commit(self.basis @ q, self.basis @ v, state)


@dataclass(frozen=True, eq=False)
class ReducedOperators:
    r"""``M^ q'' + C^ q' + K^ q + f^(q, q') = B^ u``,  ``y = E^ q``  in r coordinates.

    Attributes
    ----------
    stiffness : (r, r) ndarray
    mass : (r, r) ndarray or None
        ``None`` means the identity (mass-orthonormal basis).
    damping : (r, r) ndarray or None
    input_matrix : (r, m) ndarray or None
    output_matrix : (p, r) ndarray or None
    nonlinear : ProjectedNonlinearForce or None
    """

    stiffness: np.ndarray
    mass: np.ndarray | None = None
    damping: np.ndarray | None = None
    input_matrix: np.ndarray | None = None
    output_matrix: np.ndarray | None = None
    nonlinear: ProjectedNonlinearForce | None = None
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        r = self.stiffness.shape[0]
        if self.stiffness.shape != (r, r):
            raise ValueError(f"stiffness has shape {self.stiffness.shape}, expected square")
        for name in ("mass", "damping"):
            A = getattr(self, name)
            if A is not None and A.shape != (r, r):
                raise ValueError(f"{name} has shape {A.shape}, expected ({r}, {r})")
        if self.input_matrix is not None and self.input_matrix.shape[0] != r:
            raise ValueError(f"input_matrix has {self.input_matrix.shape[0]} rows, expected {r}")
        if self.output_matrix is not None and self.output_matrix.shape[1] != r:
            raise ValueError(f"output_matrix has {self.output_matrix.shape[1]} columns, "
                             f"expected {r}")

    @property
    def r(self) -> int:
        return self.stiffness.shape[0]

    @property
    def n_inputs(self) -> int:
        return 0 if self.input_matrix is None else self.input_matrix.shape[1]

    @property
    def mass_matrix(self) -> np.ndarray:
        """(r, r) ndarray ``M^`` (the identity when ``mass`` is ``None``)."""
        return np.eye(self.r) if self.mass is None else self.mass

    def eigenvalues(self) -> dict:
        """Eigenvalues of the symmetric parts of ``K^`` and ``C^`` (ascending)."""
        out = {"stiffness": np.linalg.eigvalsh(0.5 * (self.stiffness + self.stiffness.T))}
        if self.damping is not None:
            out["damping"] = np.linalg.eigvalsh(0.5 * (self.damping + self.damping.T))
        return out

    def frequencies(self) -> np.ndarray:
        """(r,) ndarray: ``sqrt`` of the generalized eigenvalues of ``(K^, M^)`` (rad/s);
        complex-valued entries (non-symmetric or indefinite ``K^``) as ``nan``."""
        import scipy.linalg as sl

        w2 = sl.eigvals(self.stiffness, self.mass_matrix)
        w2 = np.sort_complex(w2)
        out = np.full(w2.shape, np.nan)
        real = (np.abs(w2.imag) <= 1e-10 * np.abs(w2)) & (w2.real >= 0)
        out[real] = np.sqrt(w2.real[real])
        return out


def galerkin(system, basis: np.ndarray, *, mass_orthonormal: bool = False,
             rtol: float = 1e-8) -> ReducedOperators:
    r"""Intrusive Galerkin ROM of a :class:`~femrom.scene.SecondOrderSystem`.

    ``M~ = V^T M V``, ``C~ = V^T C V``, ``K~ = V^T K V``, ``B~ = V^T B``,
    ``E~ = E V`` and ``f~(q) = V^T f_nl(V q)`` (tangent ``V^T J V``).

    Parameters
    ----------
    system : SecondOrderSystem
    basis : (n, r) ndarray
        ``V``; with ``mass_orthonormal`` it must satisfy ``V^T M V = I``.
    mass_orthonormal : bool
        Check ``||V^T M V - I||_F <= rtol sqrt(r)`` and store ``M~ = I``
        (``mass=None``), else raise.

    Returns
    -------
    ReducedOperators
    """
    V = np.asarray(basis, dtype=float)
    if V.ndim != 2 or V.shape[0] != system.n_dofs:
        raise ValueError(f"basis has shape {V.shape}, expected ({system.n_dofs}, r)")
    mass = Mass.galerkin(system, V)
    if mass_orthonormal:
        r = V.shape[1]
        defect = np.linalg.norm(mass - np.eye(r))
        if defect > rtol * np.sqrt(r):
            raise ValueError(f"basis is not mass-orthonormal: ||V^T M V - I||_F = {defect:.3e}")
        mass = None
    return ReducedOperators(
        stiffness=Stiffness.galerkin(system, V),
        mass=mass,
        damping=Damping.galerkin(system, V),
        input_matrix=Input.galerkin(system, V),
        output_matrix=Output.galerkin(system, V),
        nonlinear=None if system.nonlinear is None else ProjectedNonlinearForce(system.nonlinear, V),
        metadata={"method": "galerkin", "mass_orthonormal": bool(mass_orthonormal)},
    )
