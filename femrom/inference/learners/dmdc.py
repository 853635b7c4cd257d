r"""Dynamic mode decomposition with control (DMDc): a first-order model from state, input and output samples."""

from __future__ import annotations

import time

import numpy as np

from femrom.inference._io_data import InputOutputData
from femrom.inference._learner import Learner, register_learner
from femrom.inference._realization import KEPT_SINGULAR_VALUES
from femrom.inference._state_space import StateSpaceOperators


def _check_rank(name: str, value, largest: int, why: str) -> int | None:
    if value is None:
        return None
    if int(value) != value or not 1 <= int(value) <= largest:
        raise ValueError(f"{name} must be an integer between 1 and {largest} ({why}), got {value}")
    return int(value)


@register_learner("dmdc")
class DMDc(Learner):
    r"""Exact DMD with control (Proctor, Brunton & Kutz, SIAM J. Appl. Dyn. Syst. 15(1), 2016).

    From state samples ``X`` (n, K), inputs ``U`` (m, K) and, optionally, outputs
    ``Y`` (p, K), with ``X_0``, ``X_1`` the columns ``k`` and ``k + 1`` of the same
    trajectory (never paired across a start), ``N`` pairs:

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
    ``z = U^^T x`` (with ``p = n + m`` and ``r = n``, ordinary least squares in a
    rotated frame). The output map is fitted by least squares on the model's
    states, ``min ||Y - C Z - D U||_F`` with ``Z = U^^T X`` (all columns), with
    ``D = 0`` unless ``feedthrough``; without outputs in the data the outputs
    are the states, ``C = U^`` (``y ~ x``), ``D = 0``.

    The model is not stabilised: ``describe()`` reports the spectral radius of ``A^``.

    Parameters
    ----------
    rank : int, optional
        ``p``, the truncation of ``Omega`` (default ``min(n + m, N)``).
    output_rank : int, optional
        ``r``, the truncation of ``X_1`` and the model's order (default ``min(n, p)``); ``r <= p``.
    feedthrough : bool
        Fit ``D`` with ``C`` (default ``D = 0``).

    Attributes
    ----------
    operators_ : StateSpaceOperators
        ``A^`` (r, r), ``B^`` (r, m), ``C`` (p_y, r), ``D`` (p_y, m), ``state_basis = U^`` (n, r).
    residual_ : float
        ``||X_1 - U^ (A^ U^^T X_0 + B^ U_0)||_F / ||X_1||_F``.
    output_residual_ : float or None
        ``||Y - C Z - D U||_F / ||Y||_F``.
    """

    method = "dmdc"
    model = "state_space"

    def __init__(self, rank: int | None = None, output_rank: int | None = None, *, feedthrough: bool = False):
        for name, value in (("rank", rank), ("output_rank", output_rank)):
            if value is not None and (int(value) != value or value < 1):
                raise ValueError(f"{name} must be a positive integer, got {value}")
        if rank is not None and output_rank is not None and output_rank > rank:
            raise ValueError(f"output_rank {output_rank} exceeds rank {rank}: the model's order r must be <= p")
        self.rank, self.output_rank, self.feedthrough = rank, output_rank, bool(feedthrough)
        self.operators_ = None

    def fit(self, data: InputOutputData) -> "DMDc":
        """Fit ``A^, B^, C, D`` from the states, inputs and outputs of ``data``."""
        if not isinstance(data, InputOutputData):
            raise TypeError(f"DMDc.fit takes InputOutputData, got {type(data).__name__}")
        if data.states is None:
            raise ValueError("DMDc learns from state samples: the data have no states "
                             "(InputOutputData.from_second_order(..., states='phase'))")
        X, U = data.states, data.inputs
        n, m = X.shape[0], U.shape[0]
        k0 = data.step_pairs()
        X0, X1, U0 = X[:, k0], X[:, k0 + 1], U[:, k0]
        N = k0.size
        p = _check_rank("rank", self.rank, min(n + m, N), f"[X; U] has {n + m} rows and {N} step pairs")
        p = min(n + m, N) if p is None else p
        r = _check_rank("output_rank", self.output_rank, min(n, N, p),
                        f"the states have {n} rows, {N} step pairs, rank p = {p}")
        r = min(n, p) if r is None else r
        tic = time.perf_counter()
        Ut, st, Vt = np.linalg.svd(np.vstack([X0, U0]), full_matrices=False)
        floor = st[0] * max(n + m, N) * np.finfo(float).eps
        if not st[p - 1] > floor:
            raise ValueError(f"rank {p} exceeds the numerical rank {int(np.sum(st > floor))} of [X; U]: "
                             "lower the rank or give richer inputs")
        Ur = np.linalg.svd(X1, full_matrices=False)[0][:, :r]
        G = (X1 @ Vt[:p].T) / st[:p]                           # X_1 V~ S~^-1 (n, p)
        UrG = Ur.T @ G
        A = UrG @ (Ut[:n, :p].T @ Ur)
        B = UrG @ Ut[n:, :p].T
        Z = Ur.T @ X
        self.residual_ = float(np.linalg.norm(X1 - Ur @ (A @ Z[:, k0] + B @ U0)) / np.linalg.norm(X1))
        self.output_residual_ = None
        if data.outputs is None:
            C, D = Ur.copy(), np.zeros((n, m))
        else:
            Y = data.outputs
            regressors = np.vstack([Z, U]) if self.feedthrough else Z
            CD = np.linalg.lstsq(regressors.T, Y.T, rcond=None)[0].T
            C = CD[:, :r]
            D = CD[:, r:] if self.feedthrough else np.zeros((Y.shape[0], m))
            den = np.linalg.norm(Y)
            self.output_residual_ = float(np.linalg.norm(Y - C @ Z - D @ U) / den) if den > 0 else 0.0
        seconds = time.perf_counter() - tic
        self.omega_singular_values_ = st
        metadata = {"method": self.method, "rank": p, "output_rank": r, "feedthrough": self.feedthrough,
                    "step_pairs": int(N), "n_trajectories": data.n_trajectories, "fit_seconds": seconds,
                    "omega_singular_values": st[:p + KEPT_SINGULAR_VALUES].tolist(),
                    "data": dict(data.metadata)}
        self.operators_ = StateSpaceOperators(A=A, B=B, C=C, D=D, dt=data.dt, state_basis=Ur, metadata=metadata)
        return self

    def describe(self) -> dict:
        out = {"method": self.method, "rank": self.rank, "output_rank": self.output_rank,
               "feedthrough": self.feedthrough}
        if self.is_fitted:
            ops = self.operators_
            out.update(rank=ops.metadata["rank"], output_rank=ops.metadata["output_rank"],
                       spectral_radius=ops.spectral_radius, residual=self.residual_,
                       output_residual=self.output_residual_, fit_seconds=ops.metadata["fit_seconds"])
        return out
