r"""Dynamic mode decomposition with control (DMDc): a first-order model from state, input and output samples."""

from __future__ import annotations

import time

import numpy as np

from femrom._errors import FemromTypeError, FemromValueError, positive_integer

from femrom.inference._io_data import InputOutputData
from femrom.inference._learner import Learner, register_learner
from femrom.inference._realization import KEPT_SINGULAR_VALUES
from femrom.inference._state_space import StateSpaceOperators

#: Which input samples drive a step: ``u_k`` (Proctor et al.), or ``u_k`` and ``u_{k+1}``.
INPUT_SAMPLES = ("start", "both")


def _check_rank(name: str, value, largest: int, why: str) -> int | None:
    if value is None:
        return None
    if int(value) != value or not 1 <= int(value) <= largest:
        raise FemromValueError(f"{name} must be an integer between 1 and {largest} ({why}), got {value}")
    return int(value)


@register_learner("dmdc")
class DMDc(Learner):
    r"""Exact DMD with control (Proctor, Brunton & Kutz, SIAM J. Appl. Dyn. Syst. 15(1), 2016).

    From state samples ``X`` (n, K), inputs ``U`` (m, K) and, optionally, outputs
    ``Y`` (p, K), with ``X_0``, ``X_1`` the columns ``k`` and ``k + 1`` of the same
    trajectory (never paired across a start), ``N`` pairs, and ``U_0`` the inputs
    at ``k`` (``input_samples="start"``) or at ``k`` and ``k + 1`` stacked
    (``"both"``, ``m_s = 2 m`` rows):

    .. math::

        \Omega = \begin{bmatrix} X_0 \\ U_0 \end{bmatrix} \approx \tilde U \tilde\Sigma \tilde V^\top
        \ (\text{rank } p), \qquad
        X_1 \approx \hat U \hat\Sigma \hat V^\top \ (\text{rank } r), \qquad
        \tilde U = \begin{bmatrix} \tilde U_1 \\ \tilde U_2 \end{bmatrix},

    .. math::

        \hat A = \hat U^\top X_1 \tilde V \tilde\Sigma^{-1} \tilde U_1^\top \hat U, \qquad
        \hat B = \hat U^\top X_1 \tilde V \tilde\Sigma^{-1} \tilde U_2^\top,

    the least-squares ``[A B] = X_1 \Omega^+`` restricted to the leading ``p``
    directions of the data and written in the ``r`` coordinates
    ``x~ = U^^T x`` (with ``p = n + m_s`` and ``r = n``, ordinary least squares in
    a rotated frame). The output map is fitted by least squares on those
    coordinates, ``min ||Y - C X~ - D U||_F`` (all columns), with ``D = 0`` unless
    ``feedthrough``; without outputs in the data the outputs are the states,
    ``C = U^`` (``y ~ x``), ``D = 0``.

    ``"both"`` fits ``x~_{k+1} = A^ x~_k + B^_0 u_k + B^_1 u_{k+1}``, the form of a
    scheme that uses the input at the step's end (Newmark: its ``[q; v]`` samples
    follow it exactly, the ``"start"`` form only up to an O(1) relative error in
    ``B``). It is a state space in the shifted state ``z = x~ - B^_1 u``:
    ``A = A^``, ``B = A^ B^_1 + B^_0``, ``D = C B^_1 + D_fit``, ``input_offset = B^_1``.

    The model is not stabilised: ``describe()`` reports the spectral radius of ``A``.

    Parameters
    ----------
    rank : int, optional
        ``p``, the truncation of ``Omega`` (default ``min(n + m_s, N)``).
    output_rank : int, optional
        ``r``, the truncation of ``X_1`` and the model's order (default ``min(n, p)``); ``r <= p``.
    feedthrough : bool
        Fit ``D`` with ``C`` (default ``D = 0``).
    input_samples : {"start", "both"}
        The inputs of a step: ``u_k`` (Proctor et al., default) or ``u_k`` and ``u_{k+1}``.

    Attributes
    ----------
    operators_ : StateSpaceOperators
        ``A`` (r, r), ``B`` (r, m), ``C`` (p_y, r), ``D`` (p_y, m), ``state_basis = U^`` (n, r),
        ``input_offset = B^_1`` (``"both"``) or ``None``.
    residual_ : float
        ``||X_1 - U^ (A^ X~_0 + B^ U_0)||_F / ||X_1||_F``.
    output_residual_ : float or None
        ``||Y - C X~ - D U||_F / ||Y||_F``.
    """

    method = "dmdc"
    model = "state_space"

    def __init__(self, rank: int | None = None, output_rank: int | None = None, *, feedthrough: bool = False,
                 input_samples: str = "start"):
        rank, output_rank = positive_integer(rank, "rank", optional=True), positive_integer(output_rank, "output_rank",
                                                                                             optional=True)
        if rank is not None and output_rank is not None and output_rank > rank:
            raise FemromValueError(f"output_rank {output_rank} exceeds rank {rank}: the model's order r must be <= p")
        if input_samples not in INPUT_SAMPLES:
            raise FemromValueError(f"unknown input_samples {input_samples!r}; valid: {', '.join(INPUT_SAMPLES)}")
        self.rank, self.output_rank, self.feedthrough = rank, output_rank, bool(feedthrough)
        self.input_samples = input_samples
        self.operators_ = None

    def _step_residual(self, data, Ur, A, Bs) -> float:
        """``||X_1 - U_r (A U_r^T X_0 + B^ U_0)|| / ||X_1||`` over the step pairs of ``data``."""
        X, U = data.states, data.inputs
        k0 = data.step_pairs()
        U0 = U[:, k0] if self.input_samples == "start" else np.vstack([U[:, k0], U[:, k0 + 1]])
        X1 = X[:, k0 + 1]
        return float(np.linalg.norm(X1 - Ur @ (A @ (Ur.T @ X[:, k0]) + Bs @ U0)) / np.linalg.norm(X1))

    @classmethod
    def for_training(cls, training, r: int, **options):
        """DMDc on the phase states ``[q^; q^']`` of the first ``r`` coordinates, inputs at both ends of
        a step (Newmark's form) unless ``input_samples`` says otherwise; the validation runs alike."""
        options.setdefault("input_samples", "both")
        return cls(**options), training.input_output(r), training.input_output(r, validation=True)

    def fit(self, data: InputOutputData, *, validation=None) -> "DMDc":
        """Fit ``A, B, C, D`` from the states, inputs and outputs of ``data``; ``validation``
        (InputOutputData with states): the one-step residual there is ``validation_residual_``."""
        if not isinstance(data, InputOutputData):
            raise FemromTypeError(f"DMDc.fit takes InputOutputData, got {type(data).__name__}")
        if data.states is None:
            raise FemromValueError("DMDc learns from state samples: the data have no states "
                                   "(InputOutputData.from_second_order(..., states='phase'))")
        X, U = data.states, data.inputs
        n, m = X.shape[0], U.shape[0]
        k0 = data.step_pairs()
        X0, X1 = X[:, k0], X[:, k0 + 1]
        U0 = U[:, k0] if self.input_samples == "start" else np.vstack([U[:, k0], U[:, k0 + 1]])
        ms, N = U0.shape[0], k0.size
        what = "[X; U]" if self.input_samples == "start" else "[X; U_k; U_k+1]"
        p = _check_rank("rank", self.rank, min(n + ms, N), f"{what} has {n + ms} rows and {N} step pairs")
        p = min(n + ms, N) if p is None else p
        r = _check_rank("output_rank", self.output_rank, min(n, N, p),
                        f"the states have {n} rows, {N} step pairs, rank p = {p}")
        r = min(n, p) if r is None else r
        tic = time.perf_counter()
        Ut, st, Vt = np.linalg.svd(np.vstack([X0, U0]), full_matrices=False)
        floor = st[0] * max(n + ms, N) * np.finfo(float).eps
        if not st[p - 1] > floor:
            raise FemromValueError(f"rank {p} exceeds the numerical rank {int(np.sum(st > floor))} of {what}: "
                                   "lower the rank or give richer inputs")
        Ur = np.linalg.svd(X1, full_matrices=False)[0][:, :r]
        G = (X1 @ Vt[:p].T) / st[:p]                           # X_1 V~ S~^-1 (n, p)
        UrG = Ur.T @ G
        A = UrG @ (Ut[:n, :p].T @ Ur)
        Bs = UrG @ Ut[n:, :p].T                                # [B^_0] or [B^_0, B^_1]
        Xr = Ur.T @ X
        self.residual_ = float(np.linalg.norm(X1 - Ur @ (A @ Xr[:, k0] + Bs @ U0)) / np.linalg.norm(X1))
        self.output_residual_ = None
        if data.outputs is None:
            C, D = Ur.copy(), np.zeros((n, m))
        else:
            Y = data.outputs
            regressors = np.vstack([Xr, U]) if self.feedthrough else Xr
            CD = np.linalg.lstsq(regressors.T, Y.T, rcond=None)[0].T
            C = CD[:, :r]
            D = CD[:, r:] if self.feedthrough else np.zeros((Y.shape[0], m))
            den = np.linalg.norm(Y)
            self.output_residual_ = float(np.linalg.norm(Y - C @ Xr - D @ U) / den) if den > 0 else 0.0
        offset = None
        if self.input_samples == "start":
            B = Bs
        else:                                                  # z = x~ - B^_1 u
            B0, offset = Bs[:, :m], Bs[:, m:]
            B, D = A @ offset + B0, D + C @ offset
        seconds = time.perf_counter() - tic
        self.validation_residual_ = None
        if validation is not None:
            if not isinstance(validation, InputOutputData) or validation.states is None:
                raise FemromValueError("DMDc validation data must be InputOutputData with states")
            self.validation_residual_ = self._step_residual(validation, Ur, A, Bs)
        self.omega_singular_values_ = st
        metadata = {"method": self.method, "rank": p, "output_rank": r, "feedthrough": self.feedthrough,
                    "input_samples": self.input_samples, "step_pairs": int(N),
                    "n_trajectories": data.n_trajectories, "fit_seconds": seconds,
                    "omega_singular_values": st[:p + KEPT_SINGULAR_VALUES].tolist(),
                    "data": dict(data.metadata)}
        self.operators_ = StateSpaceOperators(A=A, B=B, C=C, D=D, dt=data.dt, state_basis=Ur,
                                              input_offset=offset, metadata=metadata)
        return self

    def describe(self) -> dict:
        out = {"method": self.method, "rank": self.rank, "output_rank": self.output_rank,
               "feedthrough": self.feedthrough, "input_samples": self.input_samples}
        if self.is_fitted:
            ops = self.operators_
            out.update(rank=ops.metadata["rank"], output_rank=ops.metadata["output_rank"],
                       spectral_radius=ops.spectral_radius, residual=self.residual_,
                       output_residual=self.output_residual_, fit_seconds=ops.metadata["fit_seconds"])
        return out
