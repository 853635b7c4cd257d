r"""The operators of an identified first-order model: ``z+ = A z + B u``, ``y = C z + D u``.

A state-space learner (DMDc, ERA, OKID) leaves a :class:`StateSpaceOperators`
in ``operators_``: the four matrices, the sampling step and, for DMDc, the
map from the data's state coordinates to the model's. :mod:`femrom.rom` turns
it into a :class:`~femrom.rom.DiscreteStateSpace` (``StateSpaceROM``) for
prediction, stepping, control and HDF5; it stays a plain container here
because the inference layer sits below the models.

:func:`markov_parameters` gives ``Y_0 = D``, ``Y_k = C A^{k-1} B`` of any
object with ``A, B, C, D`` (these operators, a ``DiscreteStateSpace``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference._io_data import MarkovParameters, _positive_step, _real_finite


@dataclass(frozen=True, eq=False)
class StateSpaceOperators:
    r"""``z_{k+1} = A z_k + B u_k``, ``y_k = C z_k + D u_k`` at step ``dt``.

    Attributes
    ----------
    A : (n_z, n_z) ndarray
    B : (n_z, m) ndarray
    C : (p, n_z) ndarray
    D : (p, m) ndarray
    dt : float
    state_basis : (n_x, n_z) ndarray or None
        ``U_r`` with orthonormal columns when the model state is a projection
        ``z = U_r^T x`` of the data's state ``x`` (DMDc's output space), so an
        initial ``x_0`` maps to ``z_0 = U_r^T x_0``; ``None`` when the state has no
        such meaning (ERA, OKID: balanced coordinates).
    input_offset : (n_z, m) ndarray or None
        ``E`` when the state is shifted, ``z = U_r^T x - E u`` (DMDc fitted with the
        input at both ends of a step); ``None``: ``z = U_r^T x``.
    observer_gain : (n_z, p) ndarray or None
        ``L`` of the state estimator ``z^_{k+1} = A z^_k + B u_k + L (y_k - C z^_k - D u_k)``
        identified with the model (OKID), or ``None``.
    metadata : dict
        What fitted them (method, orders, Hankel sizes, singular values).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float
    state_basis: np.ndarray | None = None
    input_offset: np.ndarray | None = None
    observer_gain: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        A = _real_finite("A", np.atleast_2d(self.A), 2)
        n = A.shape[0]
        if A.shape != (n, n):
            raise FemromValueError(f"A has shape {A.shape}, expected square")
        B, C, D = (_real_finite(name, getattr(self, name), 2) for name in ("B", "C", "D"))
        if B.shape[0] != n:
            raise FemromValueError(f"B has {B.shape[0]} rows, A is ({n}, {n})")
        if C.shape[1] != n:
            raise FemromValueError(f"C has {C.shape[1]} columns, A is ({n}, {n})")
        if D.shape != (C.shape[0], B.shape[1]):
            raise FemromValueError(f"D has shape {D.shape}, expected ({C.shape[0]}, {B.shape[1]})")
        for name, value in (("A", A), ("B", B), ("C", C), ("D", D)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "dt", _positive_step(self.dt))
        if self.state_basis is not None:
            V = _real_finite("state_basis", self.state_basis, 2)
            if V.shape[1] != n:
                raise FemromValueError(f"state_basis has {V.shape[1]} columns, the model has {n} states")
            object.__setattr__(self, "state_basis", V)
        if self.input_offset is not None:
            E = _real_finite("input_offset", self.input_offset, 2)
            if E.shape != B.shape:
                raise FemromValueError(f"input_offset has shape {E.shape}, expected {B.shape}")
            object.__setattr__(self, "input_offset", E)
        if self.observer_gain is not None:
            L = _real_finite("observer_gain", self.observer_gain, 2)
            if L.shape != (n, C.shape[0]):
                raise FemromValueError(f"observer_gain has shape {L.shape}, expected ({n}, {C.shape[0]})")
            object.__setattr__(self, "observer_gain", L)

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        return self.B.shape[1]

    @property
    def n_outputs(self) -> int:
        return self.C.shape[0]

    def eigenvalues(self) -> np.ndarray:
        """(n_z,) complex ndarray: the poles ``eig(A)``."""
        return np.linalg.eigvals(self.A)

    @property
    def spectral_radius(self) -> float:
        """``max |eig(A)|``: below 1 for an asymptotically stable model (reported, never enforced)."""
        return float(np.max(np.abs(self.eigenvalues()))) if self.n_states else 0.0

    def markov_parameters(self, count: int) -> MarkovParameters:
        """``Y_0 ... Y_{count-1}`` of this model."""
        return markov_parameters(self, count)


def markov_parameters(model, count: int, dt: float | None = None) -> MarkovParameters:
    r"""``Y_0 = D``, ``Y_k = C A^{k-1} B`` for ``k < count`` of any model with ``A, B, C, D`` (and ``dt``).

    Parameters
    ----------
    model : object
        :class:`StateSpaceOperators`, a :class:`~femrom.rom.DiscreteStateSpace`, ...
    count : int
        ``N >= 2``.
    dt : float, optional
        Default ``model.dt`` (1 when it has none).
    """
    count = int(count)
    if count < 2:
        raise FemromValueError(f"count must be at least 2, got {count}")
    A, B, C, D = (np.asarray(getattr(model, name), dtype=float) for name in ("A", "B", "C", "D"))
    Y = np.empty((count, C.shape[0], B.shape[1]))
    Y[0] = D
    AkB = B
    for k in range(1, count):
        Y[k] = C @ AkB
        AkB = A @ AkB
    step = getattr(model, "dt", 1.0) if dt is None else dt
    return MarkovParameters(Y, dt=step, metadata={"source": f"model ({type(model).__name__})"},
                            layout="npm")
