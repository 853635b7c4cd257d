r"""``a h(a . q^)``: a learned Iwan (parallel Jenkins) element along one reduced direction."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError
from femrom.fem import CompiledSliders, compiled_laws, slider_return
from femrom.inference._terms import ReducedTerm, register_term


@dataclass(frozen=True)
class SliderState:
    """Committed state of the sliders: their spring stretches ``e`` (p,) and the coordinate ``x = a . q^``."""

    stretch: np.ndarray
    coordinate: float


def slider_stretches(x: np.ndarray, thresholds: np.ndarray, starts=(0,), *, initial=None) -> np.ndarray:
    r"""(p, K) spring stretches ``e_i`` of Jenkins sliders driven by the coordinate history ``x`` (K,).

    Slider ``i`` (a spring in series with a dry friction element that slips when the spring is
    stretched by ``phi_i``) follows the play operator

    .. math::

        e_i(t_k) = \operatorname{clip}\big(e_i(t_{k-1}) + x_k - x_{k-1},\; -\phi_i,\; \phi_i\big),

    the return mapping of the slider at every column. At each index of ``starts`` (a trajectory's
    first column) the sliders restart from ``initial`` (p,) if given, else from the state of a
    monotone loading from rest, ``e_i = clip(x, -phi_i, phi_i)``.
    """
    x = np.asarray(x, dtype=float).ravel()
    phi = np.asarray(thresholds, dtype=float).ravel()
    E = np.empty((phi.size, x.size))
    bounds = list(starts) + [x.size]
    for begin, end in zip(bounds[:-1], bounds[1:]):
        e = slider_return(x[begin] if initial is None else np.asarray(initial, float), phi)[0]
        E[:, begin] = e
        for k in range(begin + 1, end):
            e = slider_return(e + (x[k] - x[k - 1]), phi)[0]
            E[:, k] = e
    return E


@register_term
class LearnedHysteresis(ReducedTerm):
    r"""A discrete Iwan element (Jenkins sliders in parallel) acting along the reduced direction ``a``.

    .. math::

        \hat f(\hat q; e) = a \sum_{i=1}^{p} k_i\, e_i, \qquad x = a \cdot \hat q, \qquad
        e_i \leftarrow \operatorname{clip}(e_i + \Delta x, -\phi_i, \phi_i),

    slider ``i`` of stiffness ``k_i >= 0`` slipping when its spring is stretched by ``phi_i > 0``
    (slip force ``k_i phi_i``): a Prandtl-Ishlinskii (Masing) hysteresis with ``p`` states. The
    stored energy ``sum_i k_i e_i^2 / 2`` plus the linear terms' energy is the model's energy;
    a slipping slider only removes it (``k_i e_i . slip >= 0``), and Newmark's trapezoidal work
    on the return-mapped force keeps that discretely: for any ``k_i >= 0`` the energy of a free
    model never grows. Small motions (every slider stuck) see the extra stiffness
    ``(sum_i k_i) a a^T``; a cycle of amplitude ``A`` in ``x`` dissipates
    ``sum_{phi_i < A} 4 k_i phi_i (A - phi_i)``.

    Fitted by :class:`~femrom.inference.IwanLOpInf`; the state is a :class:`SliderState`.

    Parameters
    ----------
    direction : (r,) ndarray
        ``a`` (any length; the weights carry the scale).
    thresholds : (p,) ndarray
        ``phi_i > 0``, in the units of ``a . q^``.
    weights : (p,) ndarray
        ``k_i >= 0``.
    """

    name = "learned_hysteresis"
    structure = "dissipative"
    order = 34

    def __init__(self, direction, thresholds, weights):
        a = np.asarray(direction, dtype=float).ravel()
        phi = np.asarray(thresholds, dtype=float).ravel()
        k = np.asarray(weights, dtype=float).ravel()
        if a.size == 0 or not np.all(np.isfinite(a)) or not np.any(a):
            raise FemromValueError("learned hysteresis: direction must be a finite non-zero vector")
        if phi.size == 0 or not np.all(np.isfinite(phi)) or np.any(phi <= 0):
            raise FemromValueError("learned hysteresis: thresholds must be finite and > 0")
        if k.shape != phi.shape or not np.all(np.isfinite(k)) or np.any(k < 0):
            raise FemromValueError(f"learned hysteresis: weights must be {phi.size} finite values >= 0, got shape {k.shape}")
        self.direction, self.thresholds, self.weights = a, phi, k

    @property
    def r(self) -> int:
        return self.direction.size

    @property
    def stateful(self) -> bool:
        return True

    @property
    def stuck_stiffness(self) -> float:
        """``sum_i k_i``: the stiffness along ``a`` while every slider sticks."""
        return float(self.weights.sum())

    @property
    def slip_force(self) -> float:
        """``sum_i k_i phi_i``: the force along ``a`` once every slider slips."""
        return float(self.weights @ self.thresholds)

    # -- state ---------------------------------------------------------------------------
    def initial_state(self) -> SliderState:
        """Rest: every spring relaxed at ``x = 0``."""
        return SliderState(np.zeros(self.thresholds.size), 0.0)

    def loaded_state(self, q) -> SliderState:
        """The state after a monotone loading from rest to ``q`` (r,)."""
        x = float(self.direction @ q)
        return SliderState(slider_return(x, self.thresholds)[0], x)

    def state_after(self, Q: np.ndarray) -> SliderState:
        """The state after the history ``Q`` (r, K) (loaded from rest to its first column)."""
        x = self.direction @ np.asarray(Q, dtype=float)
        return SliderState(slider_stretches(x, self.thresholds)[:, -1], float(x[-1]))

    def _trial(self, q, state) -> np.ndarray:
        state = self.initial_state() if state is None else state
        x = float(self.direction @ q)
        return slider_return(state.stretch + (x - state.coordinate), self.thresholds)[0], state

    def commit(self, q, v, state) -> SliderState:
        stretch, _ = self._trial(q, state)
        return SliderState(stretch, float(self.direction @ q))

    def stored_energy(self, state: SliderState) -> float:
        """``sum_i k_i e_i^2 / 2``."""
        return 0.5 * float(self.weights @ state.stretch ** 2)

    # -- in a reduced step -----------------------------------------------------------------
    def force(self, q, v=None, state=None) -> np.ndarray:
        """(r,) ``a sum_i k_i e_i`` with the stretches return-mapped from ``state`` to ``q``."""
        stretch, _ = self._trial(q, state)
        return self.direction * float(self.weights @ stretch)

    def lhs(self, q, v=None, a=None, u=None, state=None):
        return self.force(q, v, state)

    def tangent(self, q, v=None, state=None):
        """``((sum of the stuck sliders' k_i) a a^T, None)``."""
        state = self.initial_state() if state is None else state
        x = float(self.direction @ q)
        stuck = slider_return(state.stretch + (x - state.coordinate), self.thresholds)[1]
        return float(self.weights[stuck].sum()) * np.outer(self.direction, self.direction), None

    def compiled_sliders(self) -> CompiledSliders | None:
        """The sliders as compiled step kernels take them (:class:`femrom.fem.CompiledSliders`), or ``None`` when
        the compiled laws are off (:func:`femrom.fem.use_compiled_laws`): a reduced Newmark step then runs
        in one compiled call."""
        if not compiled_laws():
            return None
        return CompiledSliders(np.ascontiguousarray(self.direction), np.ascontiguousarray(self.thresholds),
                               np.ascontiguousarray(self.weights), SliderState)

    def forces(self, Q: np.ndarray, Vel=None, starts=(0,)) -> np.ndarray:
        """(r, K) force along a history ``Q`` (each trajectory of ``starts`` loaded from rest to its first column)."""
        x = self.direction @ np.asarray(Q, dtype=float)
        return np.outer(self.direction, self.weights @ slider_stretches(x, self.thresholds, starts))

    def target(self, data) -> np.ndarray:
        return self.forces(data.states, starts=data.starts)

    # -- storage ------------------------------------------------------------------------
    def save(self, group) -> None:
        group.create_dataset("direction", data=self.direction)
        group.create_dataset("thresholds", data=self.thresholds)
        group.create_dataset("weights", data=self.weights)

    @classmethod
    def load(cls, group, **context) -> "LearnedHysteresis":
        return cls(group["direction"][()], group["thresholds"][()], group["weights"][()])

    def describe(self) -> dict:
        return {"term": self.name, "structure": self.structure, "sliders": int(self.thresholds.size),
                "active_sliders": int(np.count_nonzero(self.weights)),
                "stuck_stiffness": self.stuck_stiffness, "slip_force": self.slip_force}
