r"""Disturbance models for offset-free tracking: a constant unknown ``d`` added to the model.

.. math::

    z_{k+1} = A z_k + B u_k + B_d d_k, \qquad d_{k+1} = d_k, \qquad
    y_k = C z_k + D u_k + C_d d_k.

An observer of the augmented state ``[z; d]`` estimates ``d`` from the outputs,
and the MPC predicts with the offsets ``w_z = B_d d``, ``w_y = C_d d``. When the
plant differs from the model (the plant is the FOM, the model a ROM), ``d``
absorbs the steady mismatch, so a constant reference is reached without offset.

Two kinds:

- ``"output"`` (``B_d = 0``, ``C_d = I_p``; ``n_d = p``): a constant error on every
  output. The augmented pair is detectable whenever ``(A, C)`` is and ``A`` has no
  eigenvalue 1 (the rank test below), and with ``n_d = p`` the estimator's
  innovation is zero at any steady state, so the closed loop's steady outputs
  are the model-optimal ones for the true plant: zero offset for a reachable
  constant reference (Muske and Badgwell 2002; Pannocchia and Rawlings 2003).
  The default: femrom's controllers have more outputs (40 centreline points)
  than inputs (6), and only ``n_d = p`` removes the offset of every output.
- ``"input"`` (``B_d = B``, ``C_d = D``; ``n_d = m``): a constant error on the
  inputs (an actuator gain or bias). Fewer states, but with ``p > m`` it leaves
  an offset where the mismatch is not input-shaped.

A disturbance model is detectable with ``(A, C)`` iff
``rank [[I - A, -B_d], [C, C_d]] = n + n_d``; :meth:`DisturbanceModel.augment` checks it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError
from femrom.rom import DiscreteStateSpace


@dataclass(frozen=True, eq=False)
class DisturbanceModel:
    r"""``B_d`` (n, n_d) and ``C_d`` (p, n_d) of a constant disturbance (module docstring).

    Build with :meth:`output` or :meth:`input` (or :meth:`of` by name).
    """

    kind: str
    state_matrix: np.ndarray
    output_matrix: np.ndarray

    @property
    def n_disturbances(self) -> int:
        return self.state_matrix.shape[1]

    @classmethod
    def output(cls, model: DiscreteStateSpace) -> "DisturbanceModel":
        """A constant error on every output: ``B_d = 0``, ``C_d = I_p``."""
        n, p = model.n_states, model.n_outputs
        return cls("output", np.zeros((n, p)), np.eye(p))

    @classmethod
    def input(cls, model: DiscreteStateSpace) -> "DisturbanceModel":
        """A constant error on every input: ``B_d = B``, ``C_d = D``."""
        return cls("input", model.B.copy(), model.D.copy())

    @classmethod
    def of(cls, kind: str, model: DiscreteStateSpace) -> "DisturbanceModel":
        """The disturbance model named ``kind`` (``"output"`` or ``"input"``)."""
        makers = {"output": cls.output, "input": cls.input}
        if kind not in makers:
            raise FemromValueError(f"unknown disturbance model {kind!r}; valid: {', '.join(makers)}")
        return makers[kind](model)

    def augment(self, model: DiscreteStateSpace) -> DiscreteStateSpace:
        """The model of ``[z; d]``: ``A_a = [[A, B_d], [0, I]]``, ``B_a = [B; 0]``, ``C_a = [C, C_d]``.

        Raises ValueError when the augmented model is not detectable (the rank test).
        """
        n, m, p, nd = model.n_states, model.n_inputs, model.n_outputs, self.n_disturbances
        if self.state_matrix.shape != (n, nd) or self.output_matrix.shape != (p, nd):
            raise FemromValueError(f"{self.kind} disturbance matrices have shapes {self.state_matrix.shape}, "
                                   f"{self.output_matrix.shape}; the model needs ({n}, n_d), ({p}, n_d)")
        test = np.block([[np.eye(n) - model.A, -self.state_matrix], [model.C, self.output_matrix]])
        rank = np.linalg.matrix_rank(test)
        if rank < n + nd:
            raise FemromValueError(f"{self.kind} disturbance model is not detectable with this model: "
                                   f"rank [[I - A, -B_d], [C, C_d]] = {rank} < n + n_d = {n + nd} "
                                   "(an integrating model, or more disturbances than independent outputs)")
        A = np.block([[model.A, self.state_matrix], [np.zeros((nd, n)), np.eye(nd)]])
        B = np.vstack([model.B, np.zeros((nd, m))])
        C = np.hstack([model.C, self.output_matrix])
        offset = None if model.input_offset is None else np.vstack([model.input_offset, np.zeros((nd, m))])
        return DiscreteStateSpace(A=A, B=B, C=C, D=model.D, dt=model.dt, input_offset=offset,
                                  metadata={**model.metadata, "disturbance": self.kind, "n_disturbances": nd})
