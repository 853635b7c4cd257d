r"""Canonical Hamiltonian learners in a scene's study: H-OpInf on a conservative second-order model.

A scene ``M q'' + K q + f(q) = 0`` without damping and inputs, with a conservative
stateless ``f = grad U``, is canonical Hamiltonian in ``(q, p = M q')``:
``H = p^T M^-1 p / 2 + q^T K q / 2 + U(q)``. A POD basis with ``V^T M V = I`` is a
cotangent lift in the mass product (``q = V q^``, ``p = M V p^``), on which the
reduced Hamiltonian is

.. math::

    \hat H = \tfrac12 \hat p^\top \hat D_p \hat p + \tfrac12 \hat q^\top \hat D_q \hat q
             + U(V \hat q), \qquad \tilde D_p = I,\ \tilde D_q = V^\top K V

for the intrusive model. A canonical learner (``hopinf``) fits symmetric ``D^_q``,
``D^_p`` from the study's reduced data seen canonically
(:func:`~femrom.inference.canonical_from_second_order`: ``p^ = q^'``), its output map
``E^`` from the recorded outputs (on ``q^`` alone: the scene's outputs are
displacements), and the ROM steps with the implicit midpoint rule (symplectic; with
a potential, Newton on ``J grad H^``). :class:`SceneHamiltonianROM`
lets the study call it like a second-order ROM: full initial displacement and
velocity in, ``outputs``, ``q`` (reduced) and ``energy`` (``H^``) out.
"""

from __future__ import annotations

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference import HamiltonianOperators, registered_learners
from femrom.rom import HamiltonianROM
from femrom.scene import SceneError


def check_canonical_learners(system, config) -> None:
    """A canonical learner needs a conservative scene without inputs and a mass-orthonormal basis.

    One :class:`~femrom.scene.SceneError` naming the learner and what the scene has
    that a canonical Hamiltonian ROM cannot represent.
    """
    known = registered_learners()
    for i, spec in enumerate(config.learners):
        if spec.learner not in known or known[spec.learner].model != "canonical":
            continue
        where = f"[rom.learners[{i}]] {spec.learner!r} learns conservative systems (q' = dH/dp, p' = -dH/dq)"
        if system.damping is not None:
            raise SceneError(f"{where}, but the scene's damping dissipates energy; use lopinf")
        if system.n_inputs:
            raise SceneError(f"{where} without inputs, but the scene has {system.n_inputs} input(s); use lopinf")
        force = system.nonlinear
        if force is not None and (force.stateful or not force.conservative):
            raise SceneError(f"{where}, but the scene's nonlinear force {force!r} has no potential U(q); "
                             "use lopinf")
        if config.basis.product != "mass":
            raise SceneError(f"{where} on a cotangent lift in the mass product: [rom.basis] product must be "
                             f"'mass', got {config.basis.product!r}")


class SceneHamiltonianROM:
    r"""A :class:`~femrom.rom.HamiltonianROM` on a mass-orthonormal basis, called like a second-order ROM.

    ``predict(q0, times, v0=..., inputs=None)`` reduces the full initial state as
    ``q^_0 = V^T M q_0``, ``p^_0 = V^T M v_0`` (the reduced momentum, ``= q^'_0``) and
    returns the :class:`~femrom.rom.HamiltonianSolution` (``q``, ``p``, ``energy = H^``,
    ``outputs = E^ [q^; p^]``).

    Parameters
    ----------
    rom : HamiltonianROM
        Fitted, with ``basis`` ``V`` (n, r).
    product : (n, n) sparse matrix
        ``M``, with ``V^T M V = I``.
    """

    def __init__(self, rom: HamiltonianROM, product):
        self.rom = rom
        self.product = rom.product = product

    @property
    def r(self) -> int:
        return self.rom.r

    @property
    def basis(self) -> np.ndarray:
        return self.rom.basis

    @property
    def operators_(self) -> HamiltonianOperators:
        return self.rom.operators_

    def predict(self, times, inputs=None, *, initial=None):
        """Integrate from the full ``initial = (q0, v0)`` (or ``q0``); ``inputs`` must be absent or zero."""
        if inputs is not None and np.any(np.asarray(inputs) != 0):
            raise FemromValueError("a canonical Hamiltonian ROM has no inputs")
        q0, v0 = initial if isinstance(initial, (tuple, list)) else (initial, None)
        q0 = self.rom.reduce(q0)                 # V^T M q0: the ROM's basis is orthonormal in M
        p0 = np.zeros_like(q0) if v0 is None else self.rom.reduce(v0)
        return self.rom.predict(times, initial=(q0, p0))


def canonical_operator_checks(ops: HamiltonianOperators) -> dict:
    """``D^_q`` as the stiffness (smallest eigenvalue; symmetric by construction) and how far ``D^_p`` is from ``I``."""
    r = ops.r
    return {"stiffness_min_eig": float(np.min(np.linalg.eigvalsh(ops.position))),
            "stiffness_symmetric": bool(np.array_equal(ops.position, ops.position.T)),
            "momentum_identity_error": float(np.linalg.norm(ops.momentum - np.eye(r)) / np.sqrt(r))}
