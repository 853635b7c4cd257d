r"""The tracking problem an MPC solves, independent of how the QP is written.

.. math::

    \min_{u_0, \dots, u_{N-1}} \; \sum_{j=0}^{N-1} \Big[ (y_j - r_j)^T Q (y_j - r_j)
        + u_j^T R u_j + (u_j - u_{j-1})^T S (u_j - u_{j-1}) \Big]
        + (z_N - z_T)^T P (z_N - z_T)

    \text{s.t.}\quad z_{j+1} = A z_j + B u_j + w_z, \quad y_j = C z_j + D u_j + w_y,
    \quad |u_{j,i}| \le b_i, \quad z_0 = \hat z, \quad u_{-1} = u_{\mathrm{prev}}.

``z_0`` is the (estimated) state at the time the first input ``u_0`` is applied,
``r_j`` the reference at that time and the ``N - 1`` following samples,
``u_prev`` the input applied one step earlier, ``w_z`` and ``w_y`` constant
offsets of the dynamics and the outputs (an estimated disturbance,
:class:`~femrom.control.DisturbanceModel`), ``z_T`` the terminal state the
terminal cost ``P`` pulls towards.

:class:`MPCConfig` holds the settings, :class:`MPCProblem` the matrices a QP
formulation (``femrom/control/formulations``) is built from.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from femrom._errors import FemromTypeError, FemromValueError
from femrom.control._qp_solver import QPSolver
from femrom.rom import DiscreteStateSpace

#: What an MPC does when a solve fails (infeasible, solver error, no solution).
FAILURE_POLICIES = ("shift", "hold", "raise")


@dataclass(frozen=True, eq=False)
class MPCConfig:
    r"""Settings of a :class:`~femrom.control.LinearMPC`.

    Attributes
    ----------
    horizon : int
        ``N``: inputs decided per solve (and output samples in the cost).
    output_weight : float, (p,) or (p, p) array_like
        ``Q``: a scalar times ``I``, a diagonal, or a symmetric PSD matrix.
    input_weight : float, (m,) or (m, m) array_like
        ``R`` on the inputs themselves.
    input_rate_weight : float, (m,) or (m, m) array_like, or None
        ``S`` on the input moves ``u_j - u_{j-1}`` (``u_{-1}`` is the previous input).
        The QP needs ``R`` or ``S`` positive definite.
    input_bound : float, (m,) array_like, or None
        ``b``: ``|u_{j,i}| <= b_i`` (``None`` or ``inf`` entries: no bound).
    terminal_weight : None, "dare" or (n_z, n_z) array_like
        ``P`` on ``z_N - z_T``; ``"dare"`` is the LQR cost-to-go of the
        unconstrained regulator, the stabilising solution of
        ``P = A^T P A - A^T P B (R + B^T P B)^{-1} B^T P A + C^T Q C``
        (needs ``D = 0``, ``S = None`` and ``R`` positive definite).
    formulation : str or None
        A registered QP formulation (:func:`~femrom.control.registered_formulations`):
        ``"condensed"`` (inputs only, dense Hessian; cvxpy), ``"sparse"`` (states and
        inputs, the dynamics as equality constraints; cvxpy) or ``"condensed_osqp"``
        (the condensed QP in OSQP without cvxpy's per-solve work). ``None``: the
        fastest measured for the solver (``benchmarks/mpc_solve.py``),
        ``"condensed_osqp"`` with OSQP and ``"condensed"`` with any other.
    solver : QPSolver
        The QP solver and its settings (tolerance, iteration limit, options):
        ``QPSolver("osqp")`` (the default) or ``QPSolver("clarabel", tolerance=1e-9)``.
    on_failure : {"shift", "hold", "raise"}
        After a failed solve (infeasible, solver error, non-finite solution):
        ``"shift"`` applies the next input of the last successful plan (the
        tail of a plan satisfies the bounds), ``"hold"`` repeats the previous
        input, ``"raise"`` raises :class:`~femrom.control.MPCError`. A solve
        the solver flags as inaccurate but finite is used and counted, except under
        ``"raise"``, where it is a failure.
    accuracy : float or None
        Every plan the solver calls optimal is certified to be within
        ``accuracy * max(||U||, ||g|| / L)`` of the QP's optimum (2-norm over the plan;
        ``g`` the QP's gradient term and ``L`` its Hessian's largest eigenvalue, the
        problem's own input scale), by the projected-gradient bound of
        :mod:`femrom.control._certificate`; a plan that fails is repaired by an
        active-set solve and certified again, and one that still fails counts as a
        failed solve. ``None``: plans are used as the solver returns them.
    """

    horizon: int = 50
    output_weight: object = 1.0
    input_weight: object = 0.0
    input_rate_weight: object = None
    input_bound: object = 0.1
    terminal_weight: object = None
    formulation: str | None = None
    solver: QPSolver = QPSolver()
    on_failure: str = "shift"
    accuracy: float | None = 1e-4

    def __post_init__(self):
        if self.accuracy is not None and not (isinstance(self.accuracy, (int, float, np.floating))
                                              and not isinstance(self.accuracy, bool) and 0 < self.accuracy < 1):
            raise FemromValueError(f"accuracy must be None or a number in (0, 1), got {self.accuracy!r}")
        if not (isinstance(self.horizon, (int, np.integer)) and self.horizon >= 1):
            raise FemromValueError(f"horizon must be a positive integer, got {self.horizon!r}")
        if self.on_failure not in FAILURE_POLICIES:
            raise FemromValueError(f"on_failure must be one of {', '.join(FAILURE_POLICIES)}, got {self.on_failure!r}")
        if not isinstance(self.solver, QPSolver):
            raise FemromTypeError(f"solver must be a QPSolver (QPSolver('osqp'), QPSolver('clarabel')), "
                                  f"got {self.solver!r}")

    @property
    def formulation_name(self) -> str:
        """The formulation used: ``formulation``, or the default for the solver."""
        if self.formulation is not None:
            return self.formulation
        return "condensed_osqp" if self.solver.name == "osqp" else "condensed"

    def describe(self) -> dict:
        """The settings as plain JSON values (weights as given, arrays as lists)."""
        def plain(value):
            if isinstance(value, np.ndarray):
                return value.tolist()
            return value
        settings = {}
        for name in self.__dataclass_fields__:
            if name == "solver":        # flat, under the keys the settings have always had
                settings.update(self.solver.describe())
            else:
                settings[name] = plain(getattr(self, name))
        settings["formulation"] = self.formulation_name
        return settings


def vector(x, size: int, name: str) -> np.ndarray:
    """(size,) float ndarray (zeros for ``None``); one clear error for a wrong size or non-finite entries."""
    if x is None:
        return np.zeros(size)
    x = np.asarray(x, dtype=float).ravel()
    if x.size != size:
        raise FemromValueError(f"{name} has {x.size} entries, expected {size}")
    if not np.all(np.isfinite(x)):
        raise FemromValueError(f"{name} has non-finite entries")
    return x


def weight_matrix(weight, size: int, name: str, *, allow_none: bool = False) -> np.ndarray | None:
    """(size, size) symmetric PSD matrix from a scalar, a diagonal or a matrix; one clear error otherwise."""
    if weight is None:
        if allow_none:
            return None
        raise FemromValueError(f"{name} is required")
    W = np.asarray(weight, dtype=float)
    if W.ndim == 0:
        W = float(W) * np.eye(size)
    elif W.ndim == 1:
        if W.size != size:
            raise FemromValueError(f"{name} has {W.size} diagonal entries, expected {size}")
        W = np.diag(W)
    elif W.shape != (size, size):
        raise FemromValueError(f"{name} has shape {W.shape}, expected ({size}, {size})")
    if not np.all(np.isfinite(W)):
        raise FemromValueError(f"{name} has non-finite entries")
    if not np.allclose(W, W.T, rtol=1e-10, atol=1e-14 * max(1.0, np.abs(W).max())):
        raise FemromValueError(f"{name} is not symmetric")
    W = 0.5 * (W + W.T)
    smallest = np.linalg.eigvalsh(W)[0] if size else 0.0
    if smallest < -1e-10 * max(1.0, np.abs(W).max()):
        raise FemromValueError(f"{name} is not positive semidefinite (smallest eigenvalue {smallest:.3g})")
    return W


def square_root(W: np.ndarray) -> np.ndarray:
    """``L`` with ``L^T L = W`` for a symmetric PSD ``W`` (diagonal kept diagonal)."""
    if np.count_nonzero(W - np.diag(np.diag(W))) == 0:
        return np.diag(np.sqrt(np.maximum(np.diag(W), 0.0)))
    values, vectors = np.linalg.eigh(W)
    return (vectors * np.sqrt(np.maximum(values, 0.0))).T


@dataclass(frozen=True, eq=False)
class MPCProblem:
    r"""The matrices of the tracking problem (module docstring): what a formulation builds its QP from.

    Attributes
    ----------
    A : (n, n) ndarray
    B : (n, m) ndarray
    C : (p, n) ndarray
    D : (p, m) ndarray
    horizon : int
        ``N``.
    Q : (p, p) ndarray
    R : (m, m) ndarray
    S : (m, m) ndarray or None
    P : (n, n) ndarray or None
    bound : (m,) ndarray
        ``b_i``; ``inf`` where an input has no bound.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    horizon: int
    Q: np.ndarray
    R: np.ndarray
    S: np.ndarray | None
    P: np.ndarray | None
    bound: np.ndarray

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        return self.B.shape[1]

    @property
    def n_outputs(self) -> int:
        return self.C.shape[0]

    @property
    def bounded(self) -> np.ndarray:
        """(m,) bool: which inputs have a finite bound."""
        return np.isfinite(self.bound)

    @classmethod
    def from_model(cls, model: DiscreteStateSpace, config: MPCConfig) -> "MPCProblem":
        """The matrices of ``model`` and the weights and bounds of ``config``; one clear error for bad input."""
        if not isinstance(model, DiscreteStateSpace):
            raise FemromValueError(f"model must be a DiscreteStateSpace (e.g. rom.to_state_space(dt)), "
                                   f"got a {type(model).__name__}")
        if model.metadata.get("constant_input"):
            raise FemromValueError("model has a constant input channel (a constant load, metadata['constant_input']): "
                                   "the MPC decides every input; control a model exported without the load")
        m, p = model.n_inputs, model.n_outputs
        if m == 0 or p == 0:
            raise FemromValueError(f"model needs inputs and outputs to be controlled, has m = {m}, p = {p}")
        for name in ("A", "B", "C", "D"):
            if not np.all(np.isfinite(getattr(model, name))):
                raise FemromValueError(f"model.{name} has non-finite entries")
        Q = weight_matrix(config.output_weight, p, "output_weight")
        R = weight_matrix(config.input_weight, m, "input_weight")
        S = weight_matrix(config.input_rate_weight, m, "input_rate_weight", allow_none=True)
        if S is not None and not np.any(S):
            S = None
        definite = np.linalg.eigvalsh(R)[0] > 0 or (S is not None and np.linalg.eigvalsh(S)[0] > 0)
        if not definite:
            raise FemromValueError("input_weight or input_rate_weight must be positive definite "
                                   "(otherwise the QP's inputs are not unique)")
        bound = _bounds(config.input_bound, m)
        P = _terminal(config.terminal_weight, model, Q, R, S)
        return cls(A=model.A, B=model.B, C=model.C, D=model.D, horizon=int(config.horizon),
                   Q=Q, R=R, S=S, P=P, bound=bound)


def _bounds(bound, m: int) -> np.ndarray:
    if bound is None:
        return np.full(m, np.inf)
    b = np.asarray(bound, dtype=float)
    if b.ndim == 0:
        b = np.full(m, float(b))
    if b.shape != (m,):
        raise FemromValueError(f"input_bound has shape {b.shape}, expected a scalar or ({m},)")
    if np.any(np.isnan(b)) or np.any(b <= 0):
        raise FemromValueError(f"input_bound must be positive (inf for no bound), got {b}")
    return b


def _terminal(weight, model: DiscreteStateSpace, Q, R, S) -> np.ndarray | None:
    if weight is None:
        return None
    if isinstance(weight, str):
        if weight != "dare":
            raise FemromValueError(f"terminal_weight must be None, 'dare' or a matrix, got {weight!r}")
        if S is not None or np.any(model.D):
            raise FemromValueError("terminal_weight='dare' is the LQR cost-to-go of a model without "
                                   "feedthrough (D = 0) and without input_rate_weight")
        try:
            P = sla.solve_discrete_are(model.A, model.B, model.C.T @ Q @ model.C, R)
        except (np.linalg.LinAlgError, ValueError) as err:
            raise FemromValueError(f"terminal_weight='dare': the Riccati equation has no stabilising "
                                   f"solution ({err})") from None
        return 0.5 * (P + P.T)
    return weight_matrix(weight, model.n_states, "terminal_weight")


@dataclass(frozen=True, eq=False)
class CondensedQP:
    r"""The tracking problem with the states eliminated: ``J = U^T H U + 2 g^T U + const``.

    With ``U = [u_0; ...; u_{N-1}]`` (m N,), ``R_s = [r_0; ...; r_{N-1}]`` (p N,) and
    the predictions ``Y = Phi z_0 + Gamma U + Psi w_z + 1 (x) w_y``,
    ``z_N = A^N z_0 + Gamma_N U + S_N w_z`` (``S_j = sum_{l<j} A^l``),

    .. math::

        H = \Gamma^T \bar Q \Gamma + \bar R + T^T \bar S T + \Gamma_N^T P \Gamma_N,

        g = G_z z_0 + G_r R_s + G_u u_{prev} + G_{wz} w_z + G_{wy} w_y + G_T z_T,

    where ``T`` takes first differences (``u_0 - u_{-1}`` first) and the bars are
    block diagonals. Every matrix is computed once; a step costs one (m N, p N)
    product for the reference and a few small ones.

    Attributes
    ----------
    hessian : (m N, m N) ndarray
        ``H`` (symmetric positive definite).
    state_map, reference_map, previous_input_map, state_offset_map, output_offset_map, terminal_map : ndarray
        ``G_z`` (m N, n), ``G_r`` (m N, p N), ``G_u`` (m N, m), ``G_wz`` (m N, n),
        ``G_wy`` (m N, p), ``G_T`` (m N, n) (``None`` without a terminal cost).
    """

    hessian: np.ndarray
    state_map: np.ndarray
    reference_map: np.ndarray
    previous_input_map: np.ndarray
    state_offset_map: np.ndarray
    output_offset_map: np.ndarray
    terminal_map: np.ndarray | None

    def gradient(self, state, reference, u_previous, state_offset, output_offset, terminal_state) -> np.ndarray:
        """(m N,) ``g`` for one step; ``reference`` is (p, N)."""
        g = self.state_map @ state + self.reference_map @ reference.ravel(order="F")
        g += self.previous_input_map @ u_previous
        g += self.state_offset_map @ state_offset + self.output_offset_map @ output_offset
        if self.terminal_map is not None:
            g += self.terminal_map @ terminal_state
        return g

    @classmethod
    def from_problem(cls, problem: MPCProblem) -> "CondensedQP":
        A, B, C, D, N = problem.A, problem.B, problem.C, problem.D, problem.horizon
        n, m, p = problem.n_states, problem.n_inputs, problem.n_outputs
        # powers A^l and partial sums S_l = sum_{i<l} A^i, l = 0..N
        powers, sums = [np.eye(n)], [np.zeros((n, n))]
        for _ in range(N):
            sums.append(sums[-1] + powers[-1])
            powers.append(A @ powers[-1])
        markov = [C @ powers[l] @ B for l in range(N)]            # C A^l B
        Phi = np.vstack([C @ powers[j] for j in range(N)])       # (p N, n)
        Psi = np.vstack([C @ sums[j] for j in range(N)])         # (p N, n)
        Gamma = np.zeros((p * N, m * N))
        for j in range(N):
            Gamma[j * p:(j + 1) * p, j * m:(j + 1) * m] = D
            for i in range(j):
                Gamma[j * p:(j + 1) * p, i * m:(i + 1) * m] = markov[j - 1 - i]
        QGamma = np.vstack([problem.Q @ Gamma[j * p:(j + 1) * p] for j in range(N)])  # Qbar Gamma
        H = Gamma.T @ QGamma + np.kron(np.eye(N), problem.R)
        G_z = QGamma.T @ Phi
        G_r = -QGamma.T
        G_wz = QGamma.T @ Psi
        G_wy = QGamma.T @ np.tile(np.eye(p), (N, 1))
        G_u = np.zeros((m * N, m))
        if problem.S is not None:
            T = np.eye(m * N) - np.eye(m * N, k=-m)
            H += T.T @ np.kron(np.eye(N), problem.S) @ T
            G_u[:m] = -problem.S          # -T^T Sbar E_1: only the first block row of T meets u_prev
        G_T = None
        if problem.P is not None:
            Gamma_N = np.hstack([powers[N - 1 - i] @ B for i in range(N)])   # (n, m N)
            PG = problem.P @ Gamma_N
            H += Gamma_N.T @ PG
            G_z = G_z + PG.T @ powers[N]
            G_wz = G_wz + PG.T @ sums[N]
            G_T = -PG.T
        H = 0.5 * (H + H.T)
        return cls(hessian=H, state_map=G_z, reference_map=G_r, previous_input_map=G_u,
                   state_offset_map=G_wz, output_offset_map=G_wy, terminal_map=G_T)

    def cost_scale(self) -> float:
        """``1 / max(diag H)``: the factor that brings the QP's Hessian to order one."""
        top = float(np.max(np.diag(self.hessian)))
        return 1.0 / top if top > 0 else 1.0
