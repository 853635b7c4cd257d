r"""Structure-preserving hyper-reduction of a local potential (energy-conserving sampling).

A nodal potential ``U(q) = sum_i w_i phi(q_i)`` (e.g. sine-Gordon,
``phi = 1 - cos``; :class:`femrom.fem.LocalPotential`) projected on a basis
``V`` (n, r) costs O(n) per evaluation: ``V^T (w * phi'(V q^))``. Replacing the
sum over all n nodes by a weighted sum over a few sampled nodes ``S``

.. math::

    \hat\Phi(\hat q) = \sum_{j \in S} \xi_j w_j \phi\big((V \hat q)_j\big), \qquad
    \hat f(\hat q) = \nabla \hat\Phi = V_S^T \big(\xi w_S \odot \phi'(V_S \hat q)\big), \qquad
    \nabla \hat f = V_S^T \operatorname{diag}\big(\xi w_S \odot \phi''(V_S \hat q)\big) V_S

keeps the reduced force an exact gradient (so the reduced model stays
Lagrangian and a conservative scheme conserves ``q'^T q' / 2 + q^T K^ q / 2 +
Phi^``) and its tangent symmetric; the cost is O(|S| r) per force and
O(|S| r^2) per tangent. This is the hyper-reduction of the *potential*, not
of the force vector (DEIM on the force breaks the gradient structure:
``../shared/seeds/001_*.txt``, "Structure-preserving Hyper-reduction").

The nodes and weights ``xi >= 0`` come from energy-conserving sampling and
weighting (ECSW: Farhat, Avery, Chapman & Cortial, IJNME 98, 2014): on training
states ``q_k`` every node's contribution to the reduced force,
``c_{ik} = V_i^T w_i phi'(q_{ik})`` (r numbers per snapshot), is a column of
``G`` ((r K [+ K]), n); ``G 1`` is the exact reduced force. A greedy
non-negative least-squares solve (Lawson & Hanson's active set, stopped once
``||G xi - G 1|| <= tol ||G 1||``) picks a sparse ``xi``. Optional rows with
the nodal potentials ``w_i phi(q_{ik})`` make the sampled potential match the
exact one as well.
"""

from __future__ import annotations

import time

import numpy as np

from femrom._errors import FemromValueError
from femrom.fem import DENSITIES
from femrom.inference import ReducedTerm, register_term

__all__ = ["HyperReducedPotential", "ecsw_weights", "sparse_nnls"]


@register_term
class HyperReducedPotential(ReducedTerm):
    r"""``Phi^(q^) = sum_j omega_j phi((V_S q^)_j)`` with its gradient and symmetric Hessian.

    A reduced nonlinear force term of :class:`~femrom.inference.ReducedOperators`
    (e.g. in place of the projected force: ``ops.without("projected_force").with_terms(hyper)``):
    conservative, stateless, no velocity dependence; saved with its density's
    name and parameters, so a model holding it loads whole.

    Parameters
    ----------
    rows : (s, r) ndarray
        ``V_S``: the basis rows of the sampled nodes.
    weights : (s,) ndarray
        ``omega = xi * w_S`` (sampling weight times the node's quadrature weight), >= 0.
    phi, dphi, ddphi : callables
        The potential density and its first two derivatives (vectorised).
    nodes : (s,) int ndarray, optional
        Indices of the sampled nodes among the free dofs (for reports).
    density : str, optional
        The :data:`femrom.fem.DENSITIES` name of ``phi``, with ``density_parameters``
        (what :meth:`save` writes).
    """

    name = "hyper_reduced_potential"
    structure = "known"
    order = 31

    def __init__(self, rows, weights, phi, dphi, ddphi, nodes=None, *, density: str | None = None,
                 density_parameters: dict | None = None):
        self.rows = np.ascontiguousarray(rows, dtype=float)
        self.weights = np.asarray(weights, dtype=float)
        if self.rows.ndim != 2 or self.weights.shape != (self.rows.shape[0],):
            raise FemromValueError(f"rows {self.rows.shape} and weights {self.weights.shape} do not match")
        if np.any(self.weights < 0):
            raise FemromValueError("hyper-reduction weights must be non-negative")
        self.phi, self.dphi, self.ddphi = phi, dphi, ddphi
        self.nodes = None if nodes is None else np.asarray(nodes, dtype=np.int64)
        self.density = density
        self.density_parameters = dict(density_parameters or {})

    @classmethod
    def from_potential(cls, potential, basis: np.ndarray, nodes, xi) -> "HyperReducedPotential":
        """Sample a :class:`~femrom.fem.LocalPotential` on ``nodes`` (indices of its local
        coordinates, as :func:`ecsw_weights` returns them) with weights ``xi``."""
        nodes = np.asarray(nodes, dtype=np.int64)
        V = np.asarray(potential.localize(np.asarray(basis, dtype=float)))
        return cls(V[nodes], np.asarray(xi, dtype=float) * potential.weights[nodes],
                   potential.phi, potential.dphi, potential.ddphi, nodes,
                   density=getattr(potential, "density", None),
                   density_parameters=getattr(potential, "density_parameters", None))

    @classmethod
    def full(cls, potential, basis: np.ndarray) -> "HyperReducedPotential":
        """Every node with ``xi = 1``: the unreduced projected potential."""
        s = potential.weights.size
        return cls.from_potential(potential, basis, np.arange(s), np.ones(s))

    @property
    def n_samples(self) -> int:
        return self.rows.shape[0]

    @property
    def r(self) -> int:
        return self.rows.shape[1]

    # -- the term in a reduced step ------------------------------------------
    @property
    def conservative(self) -> bool:
        return True

    def lhs(self, q, v=None, a=None, u=None, state=None):
        return self.force(q)

    def target(self, data) -> np.ndarray:
        return self.forces(data.states)

    def potential(self, q) -> float:
        """``Phi^(q^)``."""
        return float(self.weights @ self.phi(self.rows @ q))

    def force(self, q, v=None, state=None) -> np.ndarray:
        """(r,) ndarray ``V_S^T (omega * phi'(V_S q^))``."""
        return self.rows.T @ (self.weights * self.dphi(self.rows @ q))

    def forces(self, Q: np.ndarray, Vel=None) -> np.ndarray:
        """(r, K) ndarray: :meth:`force` of every column of ``Q`` (r, K)."""
        return self.rows.T @ (self.weights[:, None] * self.dphi(self.rows @ Q))

    def tangent(self, q, v=None, state=None):
        """``(V_S^T diag(omega * phi''(V_S q^)) V_S, None)``: symmetric (r, r)."""
        d = self.weights * self.ddphi(self.rows @ q)
        J = self.rows.T @ (d[:, None] * self.rows)
        return 0.5 * (J + J.T), None                # symmetric to the last bit (BLAS is not)

    # -- storage ----------------------------------------------------------------
    def save(self, group) -> None:
        if self.density is None:
            raise FemromValueError("a hyper-reduced potential without a named density cannot be saved")
        group.attrs["density"] = self.density
        for key, value in self.density_parameters.items():
            group.attrs[f"density.{key}"] = float(value)
        group.create_dataset("rows", data=self.rows)
        group.create_dataset("weights", data=self.weights)
        if self.nodes is not None:
            group.create_dataset("nodes", data=self.nodes)

    @classmethod
    def load(cls, group, **context) -> "HyperReducedPotential":
        density = str(group.attrs["density"])
        parameters = {k.split(".", 1)[1]: float(v) for k, v in group.attrs.items() if k.startswith("density.")}
        phi, dphi, ddphi = DENSITIES[density](**parameters)
        nodes = group["nodes"][()] if "nodes" in group else None
        return cls(group["rows"][()], group["weights"][()], phi, dphi, ddphi, nodes, density=density,
                   density_parameters=parameters)

    def describe(self) -> dict:
        return {"term": self.name, "structure": self.structure, "samples": self.n_samples,
                "density": self.density}


def sparse_nnls(G: np.ndarray, b: np.ndarray, *, tolerance: float = 1e-3,
                max_support: int | None = None):
    r"""Greedy non-negative least squares ``min_{x >= 0} ||G x - b||``, stopped early.

    Lawson-Hanson active set: add the column with the largest positive
    gradient ``G^T (b - G x)``, solve the unconstrained problem on the active
    columns, step back to the feasible set when a coefficient turns negative.
    Stops when ``||G x - b|| <= tolerance ||b||``, when ``max_support`` columns
    are active, or at the NNLS optimum.

    Parameters
    ----------
    G : (m, n) ndarray
    b : (m,) ndarray

    Returns
    -------
    x : (n,) ndarray
        Sparse, non-negative.
    info : dict
        ``residual`` (relative), ``support``, ``iterations``, ``converged``.
    """
    G = np.asarray(G, dtype=float)
    b = np.asarray(b, dtype=float)
    m, n = G.shape
    max_support = min(m, n) if max_support is None else int(max_support)
    bnorm = float(np.linalg.norm(b)) or 1.0
    x = np.zeros(n)
    active = np.zeros(n, dtype=bool)
    residual = b.copy()
    iterations = 0
    while np.linalg.norm(residual) > tolerance * bnorm and active.sum() < max_support:
        gradient = G.T @ residual
        gradient[active] = -np.inf
        j = int(np.argmax(gradient))
        if not gradient[j] > 0:
            break                                   # NNLS optimum: no descent column left
        active[j] = True
        for _ in range(3 * n):                      # inner loop: restore feasibility
            iterations += 1
            idx = np.flatnonzero(active)
            z = np.linalg.lstsq(G[:, idx], b, rcond=None)[0]
            if np.all(z > 0):
                x[:] = 0.0
                x[idx] = z
                break
            xa = x[idx]
            bad = z <= 0
            alpha = np.min(xa[bad] / np.maximum(xa[bad] - z[bad], np.finfo(float).tiny))
            x[idx] = xa + alpha * (z - xa)
            drop = idx[x[idx] <= 1e-14 * max(np.max(np.abs(x[idx])), 1.0)]
            active[drop] = False
            x[drop] = 0.0
            if not active.any():
                break
        residual = b - G @ x
    rel = float(np.linalg.norm(residual) / bnorm)
    return x, {"residual": rel, "support": int(np.count_nonzero(x)), "iterations": iterations,
               "converged": rel <= tolerance}


def ecsw_weights(potential, basis: np.ndarray, states: np.ndarray, *, tolerance: float = 1e-3,
                 max_support: int | None = None, include_potential: bool = True):
    r"""Sampled nodes and weights ``xi >= 0`` reproducing the reduced force on training states.

    Parameters
    ----------
    potential : LocalPotential
        ``U(q) = sum_i w_i phi(x_i)`` on its s local coordinates ``x = L q``.
    basis : (n, r) ndarray
        ``V``.
    states : (n, K) ndarray
        Training states at which the sampled force must match ``V^T f(q)``;
        pass reconstructed ``V Q^`` to train on the states the ROM visits.
    tolerance : float
        Relative residual of the weighted sums (see :func:`sparse_nnls`).
    include_potential : bool
        Also match the nodal potentials (one extra row per snapshot).

    Returns
    -------
    nodes : (k,) int ndarray
        Sampled local coordinates (the dofs themselves for a potential on all dofs).
    xi : (k,) ndarray
    info : dict
        ``residual``, ``support``, ``seconds``, ``rows`` of ``G``.
    """
    tic = time.perf_counter()
    V = np.asarray(potential.localize(np.asarray(basis, dtype=float)))
    X = np.asarray(potential.localize(np.asarray(states, dtype=float)))
    n, r = V.shape
    w = potential.weights
    F = w[:, None] * potential.dphi(X)                     # (n, K) nodal forces
    # G[(k, a), i] = V[i, a] * F[i, k]: node i's share of the reduced force at snapshot k
    blocks = [(V * F[:, k:k + 1]).T for k in range(X.shape[1])]
    if include_potential:
        P = (w[:, None] * potential.phi(X)).T              # (K, n) nodal potentials
        # the same relative weight for the potential as for one force component
        scale = np.linalg.norm(np.vstack(blocks)) / max(np.linalg.norm(P), np.finfo(float).tiny) \
            / np.sqrt(r)
        blocks.append(scale * P)
    G = np.vstack(blocks)
    b = G.sum(axis=1)
    x, info = sparse_nnls(G, b, tolerance=tolerance, max_support=max_support)
    nodes = np.flatnonzero(x)
    info.update(seconds=time.perf_counter() - tic, rows=int(G.shape[0]))
    return nodes, x[nodes], info
