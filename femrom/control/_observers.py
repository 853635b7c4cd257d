r"""State observers from outputs: steady-state Kalman filter and pole placement.

Both are the same filter with a different gain ``M`` (n_a, p):

.. math::

    \hat x_{k|k} = \hat x_{k|k-1} + M \left( y_k - C \hat x_{k|k-1} - D u_k \right),
    \qquad \hat x_{k+1|k} = A \hat x_{k|k} + B u_k,

on the model ``x = z`` or, with a :class:`~femrom.control.DisturbanceModel`, on the
augmented ``x = [z; d]``. ``u_k`` is the input applied at the sample ``y_k`` (the
stepper convention ``y_k = C z_k + D u_k``), so the feedthrough ``D`` is removed
from the innovation. The estimate is of ``z``; a model exported with an input
offset (``z = x - E u``, Newmark's state) gives its own state back as
``z + E u`` (:meth:`LinearObserver.model_state`). The error of the filtered
estimate obeys ``e_{k+1} = (I - M C) A e_k``: :meth:`LinearObserver.error_poles`.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg as sla
import scipy.signal as ssig

from femrom._errors import FemromValueError
from femrom.control._disturbance import DisturbanceModel
from femrom.control._problem import vector, weight_matrix
from femrom.rom import DiscreteStateSpace


class LinearObserver:
    r"""The filter of the module docstring with a given gain ``M``.

    Parameters
    ----------
    model : DiscreteStateSpace
        The controller's model.
    gain : (n_a, p) ndarray
        ``M``, with ``n_a = n + n_d``.
    disturbance : DisturbanceModel, optional
        The augmentation the gain was designed for.
    initial_state : (n,) array_like, optional
        The prior ``z_{0|-1}`` (zeros by default); the disturbance starts at zero.

    Attributes
    ----------
    augmented : DiscreteStateSpace
        The model the filter runs on (``model`` itself without a disturbance).
    gain_ : (n_a, p) ndarray
    estimate : (n_a,) ndarray
        The current estimate (after :meth:`update` the filtered one, after
        :meth:`predict` the one-step prediction).
    """

    def __init__(self, model: DiscreteStateSpace, gain: np.ndarray, *,
                 disturbance: DisturbanceModel | None = None, initial_state=None):
        if not isinstance(model, DiscreteStateSpace):
            raise FemromValueError(f"model must be a DiscreteStateSpace, got a {type(model).__name__}")
        self.model, self.disturbance = model, disturbance
        self.augmented = model if disturbance is None else disturbance.augment(model)
        n_a, p = self.augmented.n_states, model.n_outputs
        gain = np.asarray(gain, dtype=float)
        if gain.shape != (n_a, p):
            raise FemromValueError(f"gain has shape {gain.shape}, expected ({n_a}, {p})")
        self.gain_ = gain
        self.reset(initial_state)

    # -- sizes -----------------------------------------------------------------------------
    @property
    def n_states(self) -> int:
        """``n``: the model's states (without disturbances)."""
        return self.model.n_states

    @property
    def n_disturbances(self) -> int:
        return 0 if self.disturbance is None else self.disturbance.n_disturbances

    # -- the filter ------------------------------------------------------------------------
    def reset(self, initial_state=None, disturbance=None) -> None:
        """Set the prior ``[z_{0|-1}; d_{0|-1}]`` (zeros by default)."""
        n, nd = self.n_states, self.n_disturbances
        z = np.zeros(n) if initial_state is None else np.asarray(initial_state, dtype=float).ravel()
        d = np.zeros(nd) if disturbance is None else np.asarray(disturbance, dtype=float).ravel()
        if z.size != n:
            raise FemromValueError(f"initial_state has {z.size} entries, expected {n}")
        if d.size != nd:
            raise FemromValueError(f"disturbance has {d.size} entries, expected {nd}")
        self.estimate = np.concatenate([z, d])

    def update(self, y, u=None) -> np.ndarray:
        """(n_a,) filtered estimate after the measurement ``y_k`` (p,) taken with input ``u_k`` (m,)."""
        model = self.augmented
        if y is None:
            raise FemromValueError("update needs the measured output y")
        y = vector(y, model.n_outputs, "output")
        u = vector(u, model.n_inputs, "u")
        innovation = y - model.C @ self.estimate - model.D @ u
        self.estimate = self.estimate + self.gain_ @ innovation
        return self.estimate

    def predict(self, u=None) -> np.ndarray:
        """(n_a,) one-step prediction ``A x + B u_k`` from the current estimate."""
        model = self.augmented
        self.estimate = model.A @ self.estimate + model.B @ vector(u, model.n_inputs, "u")
        return self.estimate

    # -- what a controller reads -----------------------------------------------------------
    @property
    def state_estimate(self) -> np.ndarray:
        """(n,) the estimate of ``z``."""
        return self.estimate[:self.n_states]

    @property
    def disturbance_estimate(self) -> np.ndarray:
        """(n_d,) the estimate of ``d`` (empty without a disturbance model)."""
        return self.estimate[self.n_states:]

    def offsets(self) -> tuple[np.ndarray, np.ndarray]:
        """``(w_z, w_y) = (B_d d, C_d d)``: the MPC's offsets (zeros without a disturbance model)."""
        if self.disturbance is None:
            return np.zeros(self.n_states), np.zeros(self.model.n_outputs)
        d = self.disturbance_estimate
        return self.disturbance.state_matrix @ d, self.disturbance.output_matrix @ d

    def model_state(self, u=None) -> np.ndarray:
        """(n,) ``z + E u``: the model's own state (``[q; v]`` of a Newmark ROM) at input ``u``."""
        z = self.state_estimate
        E = self.model.input_offset
        return z.copy() if E is None else z + E @ vector(u, self.model.n_inputs, "u")

    def error_poles(self) -> np.ndarray:
        """Eigenvalues of ``(I - M C) A``: the estimation error's dynamics (inside the unit circle)."""
        model = self.augmented
        return np.linalg.eigvals((np.eye(model.n_states) - self.gain_ @ model.C) @ model.A)


def _disturbance(disturbance, model) -> DisturbanceModel | None:
    if disturbance is None or isinstance(disturbance, DisturbanceModel):
        return disturbance
    return DisturbanceModel.of(disturbance, model)


class KalmanObserver(LinearObserver):
    r"""Steady-state Kalman filter: the gain from the discrete algebraic Riccati equation.

    With process noise ``w ~ N(0, W)`` on the (augmented) state and measurement
    noise ``v ~ N(0, V)`` on the outputs, the prior error covariance ``P`` solves

    .. math::

        P = A P A^T - A P C^T (C P C^T + V)^{-1} C P A^T + W,

    and ``M = P C^T (C P C^T + V)^{-1}``; the predictor gain ``A M`` is what
    python-control's ``dlqe(A, I, C, W, V)`` returns.

    Parameters
    ----------
    model : DiscreteStateSpace
    process_noise : float, (n,) or (n, n) array_like, optional
        ``W`` of the model's states (default ``I``).
    measurement_noise : float, (p,) or (p, p) array_like, optional
        ``V`` (default ``I``). Only the ratios of ``W``, ``W_d`` and ``V`` matter:
        scaling all three scales ``P`` and leaves ``M`` unchanged.
    disturbance : None, "output", "input" or DisturbanceModel
        Augment with a constant disturbance for offset-free tracking
        (:class:`~femrom.control.DisturbanceModel`).
    disturbance_noise : float, (n_d,) or (n_d, n_d) array_like, optional
        ``W_d``: how fast the disturbance estimate may move (it must be positive
        for the estimate to move at all). Default ``I / ||[B_d; C_d]||_2^2``: a
        disturbance moves the state and the outputs as much as the unit state
        noise does (``I`` for the output model; for the input model, whose
        ``B_d = B`` is of the order of ``dt^2`` in a Newmark model, much more).
    initial_state : (n,) array_like, optional

    Attributes
    ----------
    covariance_ : (n_a, n_a) ndarray
        ``P``.
    """

    def __init__(self, model: DiscreteStateSpace, process_noise=None, measurement_noise=None, *,
                 disturbance=None, disturbance_noise=None, initial_state=None):
        if not isinstance(model, DiscreteStateSpace):
            raise FemromValueError(f"model must be a DiscreteStateSpace, got a {type(model).__name__}")
        disturbance = _disturbance(disturbance, model)
        augmented = model if disturbance is None else disturbance.augment(model)
        n, p = model.n_states, model.n_outputs
        W = weight_matrix(1.0 if process_noise is None else process_noise, n, "process_noise")
        V = weight_matrix(1.0 if measurement_noise is None else measurement_noise, p, "measurement_noise")
        if np.linalg.eigvalsh(V)[0] <= 0:
            raise FemromValueError("measurement_noise must be positive definite")
        if disturbance is not None:
            nd = disturbance.n_disturbances
            if disturbance_noise is None:
                reach = np.linalg.norm(np.vstack([disturbance.state_matrix, disturbance.output_matrix]), 2)
                disturbance_noise = 1.0 / reach ** 2 if reach > 0 else 1.0
            Wd = weight_matrix(disturbance_noise, nd, "disturbance_noise")
            W = sla.block_diag(W, Wd)
        elif disturbance_noise is not None:
            raise FemromValueError("disturbance_noise needs a disturbance model")
        A, C = augmented.A, augmented.C
        try:
            P = sla.solve_discrete_are(A.T, C.T, W, V)
        except (np.linalg.LinAlgError, ValueError) as err:
            raise FemromValueError(f"no stabilising Kalman gain: the model is not detectable from its outputs, "
                                   f"or the process noise misses a mode on the unit circle ({err})") from None
        P = 0.5 * (P + P.T)
        gain = np.linalg.solve(C @ P @ C.T + V, C @ P).T
        self.covariance_ = P
        super().__init__(model, gain, disturbance=disturbance, initial_state=initial_state)


class PolePlacementObserver(LinearObserver):
    r"""An observer whose error dynamics ``(I - M C) A`` have the given poles.

    ``eig((I - M C) A) = eig(A^T - (C A)^T M^T)``: a state-feedback pole
    placement (``scipy.signal.place_poles``) on ``(A^T, (C A)^T)``; with more
    outputs than states the outputs' range is used (an SVD of ``C A``).

    Parameters
    ----------
    model : DiscreteStateSpace
    poles : (n_a,) array_like
        Wanted error poles, inside the unit circle, complex ones in conjugate pairs.
    disturbance : None, "output", "input" or DisturbanceModel
    initial_state : (n,) array_like, optional
    """

    def __init__(self, model: DiscreteStateSpace, poles, *, disturbance=None, initial_state=None):
        if not isinstance(model, DiscreteStateSpace):
            raise FemromValueError(f"model must be a DiscreteStateSpace, got a {type(model).__name__}")
        disturbance = _disturbance(disturbance, model)
        augmented = model if disturbance is None else disturbance.augment(model)
        A, C = augmented.A, augmented.C
        n_a = A.shape[0]
        poles = np.atleast_1d(np.asarray(poles, dtype=complex))
        if poles.shape != (n_a,):
            raise FemromValueError(f"poles has {poles.size} entries, expected {n_a} (the observer's states)")
        if np.any(np.abs(poles) >= 1):
            raise FemromValueError(f"poles must lie inside the unit circle, got moduli up to {np.abs(poles).max():.4g}")
        CA_T = (C @ A).T
        U, s, Vt = np.linalg.svd(CA_T, full_matrices=False)
        rank = int(np.sum(s > s[0] * 1e-12)) if s.size else 0
        Ur, sr, Vr = U[:, :rank], s[:rank], Vt[:rank].T
        try:
            with warnings.catch_warnings():
                # place_poles warns when its robustness iterations stall; the placement is checked below
                warnings.simplefilter("ignore", UserWarning)
                placed = ssig.place_poles(A.T, Ur, poles.real if np.all(poles.imag == 0) else poles)
        except ValueError as err:
            raise FemromValueError(f"cannot place the observer poles: {err}") from None
        gain = (Vr / sr) @ placed.gain_matrix          # M^T = V_r S_r^-1 K_r
        super().__init__(model, gain.T, disturbance=disturbance, initial_state=initial_state)
        achieved = np.sort_complex(self.error_poles())
        if np.max(np.abs(achieved - np.sort_complex(poles))) > 1e-6:
            raise FemromValueError("the observer poles could not be placed accurately (a nearly unobservable mode?)")
