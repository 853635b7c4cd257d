r"""Elastic Coulomb friction under the normal pressure a preload left: the contact status frozen.

A bolted joint vibrating about its preloaded state: the points the preload closed stay
closed with their preload pressure ``p_0`` (a bilateral normal spring about it), the open
points carry nothing, and a closed point's tangential traction is a spring ``k_t`` in
series with a Coulomb slider of slip traction ``tau_s = mu p_0``:

.. math::

    t_t = c \operatorname{proj}_{|t| \le \tau_s}\big(k_t (g_t - z)\big), \qquad
    t_n = c\, k_n g_n, \qquad c \in \{0, 1\} \text{ (closed at the preload)}.

It is :mod:`dry_friction` with the normal traction's effect on the slip limit and the
contact status held at the preload. That keeps what matters for micro-slip damping
(where and how hard the interface is clamped) and drops the opening and closing of the
lightly pressed points at the edge of the clamped region: a penalty contact switching
inside a time step makes the trapezoidal rule gain energy (the ring-down of a modal
model of the jointed beam grew without bound at a 300 N impact with ``dry_friction``),
while this law is piecewise linear with a dissipative slider, so the average-
acceleration step stays energy-stable. ``p_0``, ``c`` and the slider positions live in the
state, set from a ``dry_friction`` preload by :func:`clamped_state`: they are a property
of the preloaded configuration, not constants of the law.

Parameters
----------
normal_stiffness : float
    ``k_n > 0`` [Pa/m].
tangential_stiffness : float
    ``k_t > 0`` [Pa/m].

State: (s, 4): slider position ``z`` (2), slip traction ``tau_s`` [Pa], closed flag ``c``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError
from femrom.fem._interface_law import (
    InterfaceLaw,
    check_parameters,
    radial_return,
    radial_return_tangent,
    register_interface_law,
    split_gap,
)


@register_interface_law
@dataclass(frozen=True)
class ClampedFrictionLaw(InterfaceLaw):
    """Elastic Coulomb friction with the preload's contact status and slip traction (module docstring)."""

    name = "clamped_friction"
    normal_stiffness: float
    tangential_stiffness: float

    def __post_init__(self):
        check_parameters(self, (("normal_stiffness", "> 0", lambda v: v > 0),
                                ("tangential_stiffness", "> 0", lambda v: v > 0)))

    def initial_state(self, n_points: int) -> np.ndarray:
        """Every point open (no contact): set a preloaded state with :func:`clamped_state`."""
        return np.zeros((int(n_points), 4))

    def _slider(self, gap, state):
        g_t, g_n = split_gap(gap)
        closed = state[:, 3] > 0.5
        trial = self.tangential_stiffness * (g_t - state[:, :2])
        t, ratio, direction, slipping = radial_return(trial, state[:, 2])
        t = np.where(closed[:, None], t, 0.0)
        return g_t, g_n, closed, trial, t, ratio, direction, slipping & closed

    def evaluate(self, gap, state, tangent=True):
        g_t, g_n, closed, _, t, ratio, direction, slipping = self._slider(gap, state)
        traction = np.empty((g_n.size, 3))
        traction[:, :2] = t
        traction[:, 2] = np.where(closed, self.normal_stiffness * g_n, 0.0)
        if not tangent:
            return traction, None
        D = np.zeros((g_n.size, 3, 3))
        D[:, :2, :2] = np.where(closed[:, None, None],
                                self.tangential_stiffness * radial_return_tangent(ratio, direction, slipping), 0.0)
        D[:, 2, 2] = np.where(closed, self.normal_stiffness, 0.0)
        return traction, D

    def commit(self, gap, state):
        g_t, _, _, _, t, *_ = self._slider(gap, state)
        new = np.array(state, dtype=float)
        new[:, :2] = g_t - t / self.tangential_stiffness
        return new

    def dissipation(self, gap, state):
        _, _, _, trial, t, *_ = self._slider(gap, state)
        return np.einsum("si,si->s", t, (trial - t) / self.tangential_stiffness)

    def stored_energy(self, gap, state):
        g_t, g_n = split_gap(gap)
        closed = state[:, 3] > 0.5
        slip = g_t - state[:, :2]
        return np.where(closed, 0.5 * self.tangential_stiffness * np.einsum("si,si->s", slip, slip)
                        + 0.5 * self.normal_stiffness * g_n**2, 0.0)


def clamped_state(gap: np.ndarray, dry_state: np.ndarray, *, normal_stiffness: float,
                  friction_coefficient: float) -> np.ndarray:
    """(s, 4) state of :class:`ClampedFrictionLaw` from a ``dry_friction`` preload.

    Parameters
    ----------
    gap : (s, 3) ndarray
        The local relative displacements at the preload (``JointForce.gaps``).
    dry_state : (s, 2) ndarray
        The ``dry_friction`` sliders committed at the preload.
    normal_stiffness, friction_coefficient : float
        The ``dry_friction`` law's ``k_n`` and ``mu``: ``p_0 = k_n max(-g_n, 0)``,
        ``tau_s = mu p_0``, closed where ``g_n < 0``.
    """
    gap = np.asarray(gap, dtype=float)
    dry_state = np.asarray(dry_state, dtype=float)
    if gap.ndim != 2 or gap.shape[1] != 3 or dry_state.shape != (gap.shape[0], 2):
        raise FemromValueError(f"gap must be (s, 3) and dry_state (s, 2), got {gap.shape} and {dry_state.shape}")
    if not (normal_stiffness > 0 and friction_coefficient >= 0):
        raise FemromValueError("normal_stiffness must be > 0 and friction_coefficient >= 0")
    closed = gap[:, 2] < 0.0
    state = np.zeros((gap.shape[0], 4))
    state[:, :2] = dry_state
    state[:, 2] = friction_coefficient * normal_stiffness * np.maximum(-gap[:, 2], 0.0)
    state[:, 3] = closed
    return state
