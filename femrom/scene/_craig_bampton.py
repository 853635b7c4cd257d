r"""Craig-Bampton reduction of a :class:`SecondOrderSystem` that keeps its nonlinear force.

The dofs split into *boundary* dofs ``b`` (kept physical: the dofs a
nonlinear force touches, plus the load and output dofs) and *interior* dofs
``i``. The interior is represented by

- static *constraint modes* ``Psi = -K_ii^{-1} K_ib`` (n_i, n_b): the interior's
  static response to a unit displacement of each boundary dof (one sparse
  factorisation of ``K_ii``, n_b solves);
- ``m`` fixed-interface *normal modes* ``Phi`` (n_i, m): the lowest
  eigenpairs of ``K_ii phi = omega^2 M_ii phi`` (boundary clamped),
  mass-normalised, by shift-invert Lanczos about 0 with the same factor,

so that (Craig & Bampton, AIAA J. 6:1313-1319, 1968)

.. math::

    q = T \hat q, \qquad
    T = \begin{bmatrix} I & 0 \\ \Psi & \Phi \end{bmatrix}, \qquad
    \hat q = \begin{bmatrix} q_b \\ \eta \end{bmatrix}, \qquad
    \hat K = \begin{bmatrix} K_{bb} + K_{bi}\Psi & 0 \\ 0 & \Omega^2 \end{bmatrix}, \quad
    \hat M = T^\top M T, \quad \hat C = T^\top C T,

(rows in the order ``b, i`` for display; ``T`` itself is in the system's
dof order), ``B^ = T^T B``, ``E^ = E T``, ``f_0^ = T^T f_0``, and the
nonlinear force ``L^T g(L q)`` becomes ``(L T)^T g(L T q^)``: because ``L``
only touches boundary dofs and ``T[b] = [I 0]``, ``L T`` is ``L``'s columns
renumbered, the force is evaluated exactly (not approximated) and its state
is unchanged (:class:`femrom.fem.TransformedForce`).

What is exact and what is not:

- with all interior modes kept, ``T`` is square and invertible: the reduced
  model has the full model's frequencies;
- with ``m`` modes, the reduced frequencies are Rayleigh-Ritz upper bounds of
  the full ones, decreasing as modes are added (nested subspaces);
- a static load on boundary dofs is reproduced exactly whatever ``m``: the
  constraint modes are the static condensation (Guyan);
- rigid-body motion (a free-free structure) lies in the range of ``Psi`` as
  long as fixing the boundary dofs holds the interior (``K_ii`` regular); a
  boundary that does not is refused with an error;
- damping is projected, ``C^ = T^T C T``: Rayleigh ``C = alpha M + beta K``
  stays ``alpha M^ + beta K^`` exactly (the reduced modal ratios follow the
  reduced frequencies); any other ``C`` is its Galerkin projection.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, eigsh

from femrom._errors import FemromValueError
from femrom.fem import transform_force
from femrom.scene._system import SecondOrderSystem
from femrom.solvers import LinearSolverError, make_solver

#: Interior sizes up to which the fixed-interface eigenproblem is solved densely (``eigh``).
DENSE_INTERIOR = 600
#: Largest ``||K_ii Psi + K_ib|| / ||K_ib||`` accepted: above it ``K_ii`` is (numerically) singular,
#: i.e. the boundary dofs do not hold the interior (a free body left among the interior dofs).
CONSTRAINT_RESIDUAL = 1e-8


@dataclass(frozen=True, eq=False)
class CraigBampton:
    r"""A Craig-Bampton model: the reduced system and the map back, ``q = T q^``.

    Attributes
    ----------
    system : SecondOrderSystem
        The reduced system on ``k = n_b + m`` coordinates ``q^ = (q_b, eta)``:
        the boundary dofs' displacements first (in ascending dof order), then
        the modal amplitudes.
    transformation : (n, k) ndarray
        ``T``.
    boundary_dofs : (n_b,) int ndarray
        The original dofs kept as coordinates ``0 .. n_b - 1``.
    interior_frequencies : (m,) ndarray
        ``omega_j / 2 pi`` [Hz] of the fixed-interface modes kept.
    seconds : dict
        Wall time of each stage (``factorization``, ``constraint_modes``,
        ``normal_modes``, ``projection``).
    """

    system: SecondOrderSystem
    transformation: np.ndarray
    boundary_dofs: np.ndarray
    interior_frequencies: np.ndarray
    seconds: dict = field(default_factory=dict)

    @property
    def n_boundary(self) -> int:
        return self.boundary_dofs.size

    @property
    def n_modes(self) -> int:
        return self.interior_frequencies.size

    def coordinate(self, dof: int) -> int:
        """The reduced coordinate of boundary dof ``dof`` (ValueError if it is interior)."""
        position = int(np.searchsorted(self.boundary_dofs, dof))
        if position >= self.n_boundary or self.boundary_dofs[position] != dof:
            raise FemromValueError(f"dof {dof} is not a boundary dof of this Craig-Bampton model")
        return position

    def expand(self, q_hat: np.ndarray) -> np.ndarray:
        """(n,) or (n, s) ndarray ``T q^`` on the original system's dofs."""
        return self.transformation @ q_hat


def boundary_dofs_of(system: SecondOrderSystem, *, inputs: bool = True, outputs: bool = True,
                     extra=None) -> np.ndarray:
    """(n_b,) sorted dofs: the nonlinear forces' (nonzero columns of their local maps), the nonzero
    rows of ``B`` (``inputs``), the nonzero columns of ``E`` (``outputs``) and ``extra``."""
    n = system.n_dofs
    parts = [np.asarray(force.dofs, dtype=np.int64) for force in system.nonlinear_forces]
    if inputs and system.input_matrix is not None:
        B = sp.csr_matrix(system.input_matrix)
        B.eliminate_zeros()
        parts.append(np.flatnonzero(np.diff(B.indptr)))
    if outputs and system.output_matrix is not None:
        E = sp.csc_matrix(system.output_matrix)
        E.eliminate_zeros()
        parts.append(np.flatnonzero(np.diff(E.indptr)))
    if extra is not None:
        extra = np.asarray(extra, dtype=np.int64).ravel()
        if extra.size and (extra.min() < 0 or extra.max() >= n):
            raise FemromValueError(f"boundary_dofs must lie in [0, {n}), got [{extra.min()}, {extra.max()}]")
        parts.append(extra)
    return np.unique(np.concatenate(parts)) if parts else np.zeros(0, dtype=np.int64)


def craig_bampton(system: SecondOrderSystem, n_modes: int, *, boundary_dofs=None, inputs: bool = True,
                  outputs: bool = True, solver: str = "auto") -> CraigBampton:
    r"""Reduce ``system`` onto its boundary dofs plus ``n_modes`` fixed-interface modes.

    Parameters
    ----------
    system : SecondOrderSystem
        ``M q'' + C q' + K q + f_nl = B u + f_0``; may be free-free (singular ``K``).
    n_modes : int
        Fixed-interface normal modes kept, ``0 <= n_modes <= n_i`` (0: static condensation).
    boundary_dofs : (t,) int array, optional
        Dofs kept physical in addition to those of the nonlinear forces (and of ``B``, ``E``).
    inputs, outputs : bool
        Keep the dofs where ``B`` loads and ``E`` reads (default): inputs then act and outputs
        read on physical coordinates, and a static input load is reproduced exactly.
    solver : str
        :func:`femrom.solvers.make_solver` strategy for ``K_ii`` (factorised once).

    Returns
    -------
    CraigBampton

    Raises
    ------
    FemromValueError
        ``n_modes`` out of range, no boundary dofs, or a boundary that leaves the interior
        free to move rigidly (``K_ii`` singular).
    """
    n = system.n_dofs
    b = boundary_dofs_of(system, inputs=inputs, outputs=outputs, extra=boundary_dofs)
    interior = np.setdiff1d(np.arange(n), b)
    n_b, n_i = b.size, interior.size
    n_modes = int(n_modes)
    if n_b == 0:
        raise FemromValueError("craig_bampton needs boundary dofs: the system has no nonlinear force, inputs or "
                               "outputs, and no boundary_dofs were given")
    if not 0 <= n_modes <= n_i:
        raise FemromValueError(f"n_modes must lie in [0, {n_i}] (the interior dofs), got {n_modes}")
    seconds = {}
    K = sp.csr_matrix(system.stiffness)
    M = sp.csr_matrix(system.mass)
    K_ii = K[interior][:, interior].tocsc()
    M_ii = M[interior][:, interior].tocsc()
    K_ib = K[interior][:, b]

    tic = time.perf_counter()
    try:
        factor = make_solver(K_ii, strategy=solver, spd=True) if n_i else None
    except LinearSolverError as err:
        raise FemromValueError(_singular_interior(n_b, n_i, str(err))) from None
    seconds["factorization"] = time.perf_counter() - tic

    tic = time.perf_counter()
    psi = np.zeros((n_i, n_b))
    if n_i:
        right = K_ib.toarray()
        psi = -np.asarray(factor.solve(right)).reshape(n_i, n_b)
        scale = max(float(np.linalg.norm(right)), np.finfo(float).tiny)
        residual = float(np.linalg.norm(K_ii @ psi + right)) / scale
        if not np.isfinite(residual) or residual > CONSTRAINT_RESIDUAL:
            raise FemromValueError(_singular_interior(n_b, n_i, f"constraint-mode residual {residual:.3g}"))
    seconds["constraint_modes"] = time.perf_counter() - tic

    tic = time.perf_counter()
    omega2, phi = _fixed_interface_modes(K_ii, M_ii, n_modes, factor)
    seconds["normal_modes"] = time.perf_counter() - tic

    tic = time.perf_counter()
    k = n_b + n_modes
    T = np.zeros((n, k))
    T[b, np.arange(n_b)] = 1.0
    T[np.ix_(interior, np.arange(n_b))] = psi
    T[np.ix_(interior, np.arange(n_b, k))] = phi

    K_hat = np.zeros((k, k))
    guyan = K[b][:, b].toarray() + np.asarray(K[b][:, interior] @ psi)
    K_hat[:n_b, :n_b] = 0.5 * (guyan + guyan.T)
    K_hat[np.arange(n_b, k), np.arange(n_b, k)] = omega2
    M_hat = _project(M, T)
    C_hat = None if system.damping is None else sp.csr_matrix(_project(sp.csr_matrix(system.damping), T))
    B_hat = None if system.input_matrix is None else np.asarray(T.T @ system.input_matrix)
    if B_hat is not None and B_hat.ndim == 1:
        B_hat = B_hat[:, None]
    E_hat = None if system.output_matrix is None else sp.csr_matrix(np.asarray(system.output_matrix @ T))
    load = None if system.load is None else T.T @ system.load
    force = transform_force(system.nonlinear, T)
    seconds["projection"] = time.perf_counter() - tic

    metadata = {**system.metadata, "craig_bampton": {"n_boundary": n_b, "n_modes": n_modes,
                                                     "n_original": n, "seconds": dict(seconds)}}
    reduced = SecondOrderSystem(mass=sp.csr_matrix(M_hat), stiffness=sp.csr_matrix(K_hat), damping=C_hat,
                                input_matrix=B_hat, inputs=system.inputs, output_matrix=E_hat,
                                nonlinear=force, load=load, output_names=system.output_names,
                                metadata=metadata)
    b.setflags(write=False)
    return CraigBampton(system=reduced, transformation=T, boundary_dofs=b,
                        interior_frequencies=np.sqrt(np.maximum(omega2, 0.0)) / (2 * np.pi), seconds=seconds)


def _singular_interior(n_b: int, n_i: int, reason: str) -> str:
    return (f"the interior stiffness K_ii is singular ({reason}): the {n_b} boundary dofs do not hold the "
            f"{n_i} interior dofs, which keep a rigid-body motion; add boundary_dofs that fix each free body "
            "(e.g. a face, or three non-collinear nodes)")


def _fixed_interface_modes(K_ii, M_ii, n_modes: int, factor):
    """``(omega^2 (m,), Phi (n_i, m))``: the lowest mass-normalised modes of ``K_ii phi = omega^2 M_ii phi``."""
    n_i = K_ii.shape[0]
    if n_modes == 0:
        return np.zeros(0), np.zeros((n_i, 0))
    if n_i <= DENSE_INTERIOR or n_modes >= n_i - 1:
        values, vectors = sl.eigh(K_ii.toarray(), M_ii.toarray(), subset_by_index=(0, n_modes - 1))
    else:
        # shift-invert about 0 with the factor of K_ii already made for the constraint modes
        inverse = LinearOperator((n_i, n_i), matvec=lambda x: factor.solve(np.asarray(x).ravel()), dtype=float)
        values, vectors = eigsh(K_ii, k=n_modes, M=M_ii, sigma=0.0, which="LM", OPinv=inverse)
        order = np.argsort(values)
        values, vectors = values[order], vectors[:, order]
    # eigh and eigsh return M_ii-orthonormal vectors; normalise once more against round-off
    norms = np.sqrt(np.einsum("ij,ij->j", vectors, np.asarray(M_ii @ vectors)))
    return values, vectors / norms


def _project(A, T: np.ndarray) -> np.ndarray:
    """(k, k) symmetric ``T^T A T`` of a symmetric sparse ``A``."""
    product = T.T @ np.asarray(A @ T)
    return 0.5 * (product + product.T)
