r"""Hyper-reduction of a projected joint: a few weighted interface pairs, the stuck joint exact.

A joint force seen through ``q = q_0 + V q^`` (:class:`femrom.fem.TransformedForce` of a
:class:`femrom.fem.JointForce`) is a sum over its ``s`` pairs,

.. math::

    \hat f(\hat q; z) = \sum_{i=1}^{s} c_i(\hat q; z_i), \qquad
    c_i = (L_i V)^\top A_i\, t_i\big(L_i (q_0 + V \hat q); z_i\big) \ (r,),

and a reduced step costs ``O(s)`` law evaluations however small ``r`` is. Split each
pair's contribution at the rest state ``(0, z_0)`` into its value, its stuck tangent
``K_i = (L_i V)^T A_i D_i (L_i V)`` and the remainder, which is zero while the pair sticks:

.. math::

    c_i(\hat q; z_i) = c_i(0; z_{0,i}) + K_i \hat q + \rho_i(\hat q; z_i).

The first two terms summed over all pairs are one constant and one matrix: kept exactly,
so the linear model (the stuck joint, the calibrated ``f_1``) is untouched. Only the slip
remainder is sampled, by energy-conserving sampling and weighting (ECSW: Farhat, Avery,
Chapman & Cortial, IJNME 98, 2014): on training states ``(q^_k, z_k)`` the columns
``rho_i(q^_k; z_{k,i})`` (each snapshot's block scaled by its total remainder, so small
amplitudes count as much as large ones) form ``G``, and a sparse ``w >= 0`` with
``||G w - G 1|| <= tol ||G 1||`` (:func:`sparse_nnls`) picks the pairs ``S``. The
hyper-reduced model is then

.. math::

    \big(\hat K + \textstyle\sum_i K_i - \sum_{i \in S} w_i K_i\big) \hat q
        + \sum_{i \in S} w_i c_i(\hat q; z_i)
        = \hat f_0 - \sum_i c_i(0; z_{0,i}) + \sum_{i \in S} w_i c_i(0; z_{0,i}) + \hat B u:

a linear stiffness correction, a constant load correction, and the joint restricted to
the pairs ``S`` with their areas scaled by ``w_i`` (:meth:`femrom.fem.JointForce.restricted`).
Each sampled pair is still an interface element of the law, so the sampled force is
dissipative where the law is, and the discrete energy balance of the hyper-reduced
model holds with its own (weighted) friction dissipation. The cost of a step is
``O(|S|)`` law evaluations.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.fem import JointForce, TransformedForce, transform_force
from femrom.inference import ReducedOperators, registered_terms
from femrom.rom._hyper import sparse_nnls


def _projected_joint(model) -> TransformedForce:
    """The joint on the reduced coordinates of a Galerkin model: its projected force's transformed force
    (the model as :class:`~femrom.inference.ReducedOperators` or as its system)."""
    term = model.term("projected_force") if isinstance(model, ReducedOperators) else model.nonlinear
    force = getattr(term, "transformed", None)
    if not (isinstance(force, TransformedForce) and isinstance(force.force_model, JointForce)):
        raise FemromValueError("the model's nonlinear force must be a projected joint (femrom.inference.galerkin "
                               f"of a system with a JointForce), got {type(force).__name__}")
    return force


def _dense(matrix) -> np.ndarray:
    return matrix.toarray() if sp.issparse(matrix) else np.asarray(matrix)


class _PairContributions:
    """``c_i(q^; z_i)`` (r, s) and the stuck tangents' action ``K_i q^`` (r, s) of a projected joint."""

    def __init__(self, force: TransformedForce, rest_state):
        self.force, self.joint = force, force.force_model
        s, r = self.joint.n_pairs, force.n_dofs
        self.LV = _dense(force.local_map).reshape(s, 3, r)          # (s, 3, r): L_i V
        self.rest = self(np.zeros(r), rest_state)
        D = force.local_tangent(force.localize(np.zeros(r)), None, rest_state)[0]
        self.D0 = _dense(D).reshape(s, 3, s, 3)[np.arange(s), :, np.arange(s), :]   # (s, 3, 3): A_i D_i

    def __call__(self, q_hat, state) -> np.ndarray:
        x = self.force.localize(np.asarray(q_hat, dtype=float))
        g = self.force.local_force(x, None, state).reshape(-1, 3)
        return np.einsum("sar,sa->rs", self.LV, g)

    def stuck(self, q_hat) -> np.ndarray:
        local = np.einsum("sar,r->sa", self.LV, np.asarray(q_hat, dtype=float))
        return np.einsum("sar,sab,sb->rs", self.LV, self.D0, local)

    def remainder(self, q_hat, state) -> np.ndarray:
        return self(q_hat, state) - self.rest - self.stuck(q_hat)


@dataclass(frozen=True)
class JointSampling:
    """The sampled pairs of a projected joint and their weights (:func:`ecsw_joint`).

    Attributes
    ----------
    pairs : (k,) int ndarray
        Indices into the joint's ``s`` pairs.
    weights : (k,) ndarray
        ``w_i > 0``.
    n_pairs : int
        ``s``.
    residual : float
        ``||G w - G 1|| / ||G 1||`` on the training states.
    n_snapshots : int
        Training states that slipped (a stuck state has no remainder and adds no rows).
    seconds : float
        Time to build ``G`` and solve.
    """

    pairs: np.ndarray
    weights: np.ndarray
    n_pairs: int
    residual: float
    n_snapshots: int
    seconds: float

    @classmethod
    def all_pairs(cls, n_pairs: int) -> "JointSampling":
        """Every pair at weight 1: the hyper-reduced system is the projected one."""
        return cls(np.arange(n_pairs), np.ones(n_pairs), n_pairs, 0.0, 0, 0.0)

    def describe(self) -> dict:
        return {"sampled_pairs": int(self.pairs.size), "of_pairs": int(self.n_pairs),
                "training_residual": float(self.residual), "training_snapshots": int(self.n_snapshots),
                "seconds": float(self.seconds)}


def ecsw_joint(system, snapshots, rest_state, *, tolerance: float = 1e-2,
               max_support: int | None = None) -> JointSampling:
    r"""Pairs and weights whose weighted slip remainder matches the joint's on training states.

    Parameters
    ----------
    system : ReducedOperators
        A Galerkin model whose nonlinear force is a projected joint (``r`` coordinates).
    snapshots : iterable of ``(q^ (r,), state)``
        Training states (e.g. every few steps of a reduced ring-down with all pairs, and
        the states of a quasi-static loading path).
    rest_state :
        The joint's state at ``q^ = 0`` (the reference of the projection).
    tolerance : float
        Relative residual of the weighted remainders (:func:`femrom.rom.sparse_nnls`).
    max_support : int, optional
        At most this many pairs.
    """
    tic = time.perf_counter()
    force = _projected_joint(system)
    if not 0 < tolerance < 1:
        raise FemromValueError(f"tolerance must lie in (0, 1), got {tolerance!r}")
    pairs = _PairContributions(force, rest_state)
    blocks = []
    scale = 0.0
    for q_hat, state in snapshots:
        rho = pairs.remainder(q_hat, state)
        norm = float(np.linalg.norm(rho.sum(axis=1)))
        blocks.append((rho, norm))
        scale = max(scale, norm)
    kept = [rho / norm for rho, norm in blocks if norm > 1e-9 * scale and norm > 0]
    if not kept:
        raise FemromValueError("no training state slips: the remainder is zero, nothing to sample (train on larger "
                         "amplitudes)")
    G = np.vstack(kept)
    weights, info = sparse_nnls(G, G.sum(axis=1), tolerance=tolerance, max_support=max_support)
    chosen = np.flatnonzero(weights > 0)
    return JointSampling(chosen, weights[chosen], force.force_model.n_pairs, info["residual"], len(kept),
                         time.perf_counter() - tic)


def hyper_reduced_system(system, sampling: JointSampling, rest_state):
    r"""The projected model with its joint sampled (module docstring): ``(model, rest state of the sample)``.

    The stuck joint's stiffness and the rest force stay exact (corrections to ``K^`` and
    the load); the joint acts through the sampled pairs with weighted areas. ``system`` is a
    Galerkin model (:func:`~femrom.inference.galerkin` of the full model about its preloaded
    state), as :class:`~femrom.inference.ReducedOperators` or as its
    :class:`~femrom.scene.SecondOrderSystem`, and the result is of the same kind; the returned
    state is ``rest_state[pairs]``.
    """
    force = _projected_joint(system)
    r = force.n_dofs
    restricted = force.force_model.restricted(sampling.pairs, sampling.weights)
    sampled = force.with_force(restricted)
    sampled_state = np.asarray(rest_state)[sampling.pairs]
    zero = np.zeros(r)
    K_all = _dense(force.tangent(zero, None, rest_state)[0])
    K_sampled = _dense(sampled.tangent(zero, None, sampled_state)[0])
    f_all = force.force(zero, None, rest_state)
    f_sampled = sampled.force(zero, None, sampled_state)
    load = np.zeros(r) if system.load is None else np.asarray(system.load, dtype=float)
    description = {"method": "ecsw_joint", **sampling.describe()}
    shifted = transform_force(restricted, None, reference=force.reference) if force.reference is not None \
        else restricted
    if isinstance(system, ReducedOperators):
        terms = registered_terms()
        term = system.term("projected_force")
        hyper = system.with_terms(terms["stiffness"](system.stiffness + K_all - K_sampled),
                                  terms["constant_load"](load - f_all + f_sampled),
                                  type(term)(shifted, term.basis))
        hyper.metadata["hyper_reduction"] = description
        return hyper, sampled_state
    term = system.nonlinear
    stiffness = _dense(system.stiffness) + K_all - K_sampled
    metadata = {**system.metadata, "hyper_reduction": description}
    hyper = dataclasses.replace(system, stiffness=stiffness, load=load - f_all + f_sampled,
                                nonlinear=type(term)(shifted, term.basis), metadata=metadata)
    return hyper, sampled_state
