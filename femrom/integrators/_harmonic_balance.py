r"""Harmonic balance of any second-order model, with alternating frequency-time (AFT) forces.

A periodic motion of ``M q'' + C q' + K q + f_nl(q, q'; s) = f_0 + F b sin(Omega t)`` is sought
as a truncated real Fourier series in ``tau = Omega t``,

.. math::

    q(\tau) = a_0 + \sum_{k=1}^{H} a_k \cos k\tau + b_k \sin k\tau,

held as a (2H+1, n) array ``Z`` of rows ``[a_0, a_1, b_1, ..., a_H, b_H]`` (flattened row by
row into the unknown vector ``z``). Its Galerkin projection onto the same functions is the
harmonic-balance residual, per harmonic ``k`` in complex form ``Q_k = a_k - i b_k``,

.. math::

    R_k = \big(K - (k\Omega)^2 M + i k\Omega C\big) Q_k + F_{nl,k}(Z, \Omega) - F_{ext,k},

(Krack & Gross 2019, *Harmonic Balance for Nonlinear Vibration Problems*, ch. 2). Here it is
real: ``R = A(Omega) z + F_nl(z, Omega) - F_ext`` with

.. math::

    A(\Omega) = I \otimes K + \Omega\, D \otimes C + \Omega^2 D^2 \otimes M,

``D`` the (2H+1, 2H+1) derivative of the coefficients (``d/dtau``: ``a_k -> k b_k``,
``b_k -> -k a_k``).

**AFT** (Cameron & Griffin 1989, J. Appl. Mech. 56:149). The nonlinear force's coefficients
are not available in closed form for a contact or slider law, so ``q`` and ``q'`` are sampled
at ``N >= 2H+1`` equidistant instants ``tau_j = 2 pi j / N`` (inverse DFT, the (N, 2H+1)
matrix ``E``), the force is evaluated there in time, and its first ``H`` harmonics are taken
back (the DFT, the (2H+1, N) matrix ``P`` with ``P E = I``): ``F_nl = P f(E Z, Omega E D Z)``.

**A force with memory** (Jenkins, Iwan, a joint, learned sliders). The samples are a time
march of the force's return map: at each instant the force is evaluated with its state frozen
at the previous instant and the state is committed, as a time scheme does after a converged
step. The march goes over the sampled period *twice*, from the given state (the force's
initial state by default): the first pass brings the state onto the periodic hysteresis loop,
and the second is the one transformed. For Masing laws (Jenkins, Iwan, every parallel-slider
law in one direction) one pass is exact: the largest and smallest displacement of the period
wipe out the memory of anything before them, so the state after the first pass repeats
itself after the second. Where that is not guaranteed (2-D slip whose direction turns) the
relative change of the state over the second pass is reported (``state_change``).

**Jacobian.** ``dR/dz = A(Omega) + dF_nl/dz`` with the AFT of the force's tangent,

.. math::

    \frac{\partial F_{nl}}{\partial z} = \sum_j \big(P_{:,j} E_{j,:}\big) \otimes K_{t,j}
        + \Omega \big(P_{:,j} (E D)_{j,:}\big) \otimes C_{t,j},

``K_t, C_t`` the tangents at sample ``j`` (state frozen at sample ``j-1``): exact for forces
without memory. For a force with memory this omits how the frozen state itself depends on
earlier samples; a force that offers ``local_step_derivative`` (the forward derivative of one
return-map step in the coordinates and the state, :class:`femrom.fem.JenkinsForce`; a
:class:`femrom.fem.JointForce` whose law has ``step_derivative``; a projected term through its
``transformed`` force) has that
dependence carried along the march, which makes the Jacobian the exact derivative of the
discrete map (checked against finite differences in ``tests/test_harmonic_balance.py``).
``dR/dOmega`` is the derivative of ``A`` plus the velocity tangent's term. A force with memory
that also depends on the velocity (a joint whose law has a dashpot) keeps the exact Jacobian when its
``local_step_derivative`` takes the local velocities and their derivative (``step_derivative_rates``):
the samples' local rates ``Omega L (E D Z)_j`` are carried along the same directions (their
derivative ``Omega (E D)_j``) and along one more, ``Omega`` (``L (E D Z)_j``), whose force
derivative is the velocity term of ``dF_nl/dOmega``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femrom._errors import FemromRuntimeError, FemromValueError
from femrom.integrators._newton import Newton


class HarmonicBalanceError(FemromRuntimeError):
    """A harmonic-balance Newton solve did not converge."""


def default_samples(harmonics: int) -> int:
    r"""The smallest power of two above ``4H`` (at least 8).

    A cubic term of a motion with ``H`` harmonics has harmonics up to ``3H``; with ``N > 4H``
    samples none of them folds back onto the first ``H`` (aliasing-free for cubic
    polynomials). Non-smooth forces alias whatever ``N``: their error falls with ``N``
    (measured in ``benchmarks/harmonic_balance.py``).
    """
    return max(8, 1 << int(np.ceil(np.log2(4 * int(harmonics) + 1))))


@dataclass(frozen=True)
class FourierBasis:
    r"""Real Fourier series with ``harmonics`` harmonics sampled ``samples`` times per period.

    Attributes
    ----------
    harmonics : int
        ``H >= 0``.
    samples : int
        ``N >= 2H + 1`` instants ``tau_j = 2 pi j / N`` (default :func:`default_samples`).
    """

    harmonics: int
    samples: int | None = None

    def __post_init__(self):
        H = int(self.harmonics)
        if H < 0 or H != self.harmonics:
            raise FemromValueError(f"harmonics must be an integer >= 0, got {self.harmonics!r}")
        N = default_samples(H) if self.samples is None else int(self.samples)
        if N < 2 * H + 1 or (self.samples is not None and N != self.samples):
            raise FemromValueError(f"samples must be an integer >= 2 H + 1 = {2 * H + 1}, got {self.samples!r}")
        object.__setattr__(self, "harmonics", H)
        object.__setattr__(self, "samples", N)

    @property
    def size(self) -> int:
        """``2H + 1`` coefficients per dof."""
        return 2 * self.harmonics + 1

    @cached_property
    def order(self) -> np.ndarray:
        """(2H+1,) harmonic order of each row: ``[0, 1, 1, 2, 2, ...]``."""
        return np.concatenate([[0], np.repeat(np.arange(1, self.harmonics + 1), 2)])

    @cached_property
    def synthesis(self) -> np.ndarray:
        """(N, 2H+1) ``E``: values at ``tau_j`` of ``[1, cos tau, sin tau, cos 2 tau, ...]``."""
        tau = 2 * np.pi * np.arange(self.samples) / self.samples
        E = np.ones((self.samples, self.size))
        k = np.arange(1, self.harmonics + 1)
        E[:, 1::2] = np.cos(np.outer(tau, k))
        E[:, 2::2] = np.sin(np.outer(tau, k))
        return E

    @cached_property
    def analysis(self) -> np.ndarray:
        """(2H+1, N) ``P`` (the DFT's first harmonics): ``a_0 = mean``, ``a_k, b_k = (2/N) sum cos, sin``."""
        P = self.synthesis.T * (2.0 / self.samples)
        P[0] *= 0.5
        return P

    @cached_property
    def derivative(self) -> np.ndarray:
        """(2H+1, 2H+1) ``D``: the coefficients of ``dq/dtau`` are ``D Z``."""
        D = np.zeros((self.size, self.size))
        for k in range(1, self.harmonics + 1):
            c, s = 2 * k - 1, 2 * k
            D[c, s] = k
            D[s, c] = -k
        return D

    @cached_property
    def synthesis_derivative(self) -> np.ndarray:
        """(N, 2H+1) ``E D``: values of ``dq/dtau`` at the samples."""
        return self.synthesis @ self.derivative


def _as_operator(A, dense: bool):
    if A is None:
        return None
    if dense:
        return A.toarray() if sp.issparse(A) else np.asarray(A, dtype=float)
    return sp.csr_matrix(A)


def _tangent_matrix(D, n: int, dense: bool):
    """A force tangent (``None``, sparse, dense, or a DIA/diagonal) as an (n, n) array or csr."""
    if D is None:
        return None
    if dense:
        D = D.toarray() if sp.issparse(D) else np.asarray(D, dtype=float)
        return np.diag(D) if D.ndim == 1 else D
    if not sp.issparse(D):
        D = np.asarray(D, dtype=float)
        D = sp.diags(D) if D.ndim == 1 else D
    return sp.csr_matrix(D)


def _state_vector(state) -> np.ndarray | None:
    """The numbers of a force state flattened (arrays, tuples, dicts, dataclasses), or ``None``."""
    parts: list[np.ndarray] = []

    def walk(value) -> bool:
        if value is None:
            return True
        if isinstance(value, (np.ndarray, float, int, np.floating)):
            parts.append(np.asarray(value, dtype=float).reshape(-1))
            return True
        if isinstance(value, (tuple, list)):
            return all(walk(v) for v in value)
        if isinstance(value, dict):
            return all(walk(value[k]) for k in sorted(value))
        if hasattr(value, "__dataclass_fields__"):
            return all(walk(getattr(value, name)) for name in value.__dataclass_fields__)
        return False

    if not walk(state):
        return None
    return np.concatenate(parts) if parts else np.zeros(0)


@dataclass(frozen=True)
class AFTResult:
    """The nonlinear force's Fourier coefficients from one AFT evaluation.

    Attributes
    ----------
    coefficients : (2H+1, n) ndarray
        ``F_nl``.
    jacobian : (nz, nz) ndarray or sparse, or None
        ``dF_nl/dz`` (``nz = (2H+1) n``).
    omega_derivative : (nz,) ndarray or None
        ``dF_nl/dOmega`` (zero for a force without velocity dependence).
    state_change : float
        Change of the force's state over the second pass, relative to the state's norm or the
        largest sampled displacement, whichever is larger (0 for a periodic loop; nan when the
        state has no numbers to compare).
    state : Any
        The force's state at the end of the sampled period.
    """

    coefficients: np.ndarray
    jacobian: Any = None
    omega_derivative: np.ndarray | None = None
    state_change: float = 0.0
    state: Any = None


@dataclass(frozen=True)
class HarmonicBalanceSolution:
    """One periodic solution: the coefficients ``Z`` (2H+1, n) at ``omega`` and force ``force``."""

    coefficients: np.ndarray
    omega: float
    force: float
    iterations: int
    residual: float
    state_change: float = 0.0
    extra: dict = field(default_factory=dict)


class HarmonicBalance:
    r"""The harmonic-balance equations of a second-order model under ``F b sin(Omega t)``.

    Parameters
    ----------
    system : SecondOrderSystem
        Any model (sparse full, dense reduced), linear or with a nonlinear force (stateful ones
        included). A :class:`~femrom.rom.SecondOrderROM` is accepted through its ``model``.
    force : int or (n,) array, optional
        Where the harmonic force acts: an input column of the model or a force vector ``b``
        (as :class:`Shaker`); ``None`` for a free system (:func:`epmc`). The model's own inputs
        are not applied; its constant load ``f_0`` is (the zeroth harmonic).
    harmonics : int
        ``H`` (default 5).
    samples : int, optional
        ``N`` per period (default :func:`default_samples`).
    state : optional
        The force's state the march over the period starts from (default its initial state;
        a preloaded model's rest state).
    passes : int
        Marches over the sampled period of a force with memory (default 2: see the module).
    output : (p, n) array, optional
        Output rows (default the model's ``output_matrix``, else the identity).
    tangent : {"auto", "exact", "frozen"}
        The force part of the Jacobian of a force with memory: ``"exact"``, the derivative of the
        march (the force must give ``local_step_derivative``; Newton converges quadratically, each
        iteration carries the state's derivative); ``"frozen"``, each sample's tangent with the
        state frozen (cheaper iterations, more of them, and no convergence far in slip);
        ``"auto"`` (default): exact where the force gives the derivative and its local
        unknowns times ``2H+1`` are at most :data:`EXACT_TANGENT_LIMIT`, frozen otherwise.
    """

    def __init__(self, system, force=None, *, harmonics: int = 5, samples: int | None = None, state=None,
                 passes: int = 2, output=None, tangent: str = "auto"):
        model = getattr(system, "model", None)
        if model is not None and not hasattr(system, "mass"):
            system = model
        if not all(hasattr(system, name) for name in ("mass", "stiffness", "nonlinear")):
            raise FemromValueError(f"HarmonicBalance needs a SecondOrderSystem, got {type(system).__name__}")
        self.system = system
        self.basis = FourierBasis(harmonics, samples)
        n = system.n_dofs
        self.n_dofs = n
        self.dense = bool(system.is_dense) or n * self.basis.size <= 400
        self.mass = _as_operator(system.mass, self.dense)
        self.stiffness = _as_operator(system.stiffness, self.dense)
        self.damping = _as_operator(system.damping, self.dense)
        self.force_vector = self._force_vector(force)
        self.nonlinear = system.nonlinear
        self.initial_state = state if state is not None or self.nonlinear is None \
            else self.nonlinear.initial_state()
        self.stateful = bool(getattr(self.nonlinear, "stateful", False))
        if int(passes) < 1:
            raise FemromValueError(f"passes must be >= 1, got {passes!r}")
        self.passes = int(passes) if self.stateful else 1
        E = system.output_matrix if output is None else output
        self.output_matrix = np.eye(n) if E is None else (E.toarray() if sp.issparse(E) else np.atleast_2d(
            np.asarray(E, dtype=float)))
        if self.output_matrix.shape[1] != n:
            raise FemromValueError(f"output has {self.output_matrix.shape[1]} columns, the model {n} dofs")
        self._eye = np.eye(self.basis.size)
        D = self.basis.derivative
        self._kron = (lambda A, B: np.kron(A, B)) if self.dense else (lambda A, B: sp.kron(sp.csr_matrix(A), B,
                                                                                        format="csr"))
        self._A_K = self._kron(self._eye, self.stiffness)
        self._A_C = None if self.damping is None else self._kron(D, self.damping)
        self._A_M = self._kron(D @ D, self.mass)
        self._DM = self._kron(D, self.mass)
        if tangent not in TANGENTS:
            raise FemromValueError(f"tangent must be one of {', '.join(TANGENTS)}, got {tangent!r}")
        self.tangent = tangent
        self._hook = None if tangent == "frozen" else self._step_derivative_hook(required=tangent == "exact")

    # -- set-up ------------------------------------------------------------------------
    def _force_vector(self, force) -> np.ndarray | None:
        n = self.n_dofs
        if force is None:
            return None
        if isinstance(force, (int, np.integer)) and not isinstance(force, bool):
            B = self.system.input_matrix
            if B is None or not 0 <= force < self.system.n_inputs:
                raise FemromValueError(f"force {force} is no input column of the model "
                                       f"({self.system.n_inputs} inputs)")
            column = B[:, [int(force)]]
            return np.asarray(column.toarray() if sp.issparse(column) else column, dtype=float).reshape(-1)
        b = np.asarray(force, dtype=float).reshape(-1)
        if b.shape != (n,) or not np.all(np.isfinite(b)):
            raise FemromValueError(f"force must be an input index or a finite ({n},) vector, got shape {b.shape}")
        return b

    def _step_derivative_hook(self, required: bool = False):
        f = self.nonlinear

        def unavailable(why):
            if required:
                raise FemromValueError(f"tangent='exact': {why}")
            return None

        if f is None or not self.stateful:
            return unavailable("the model has no force with memory")
        velocity = bool(getattr(f, "velocity_dependent", False))
        # a projected force (a reduced model's term) is its force on the reduced coordinates, same state
        local = getattr(f, "transformed", None)
        f = f if local is None else local
        if velocity and not getattr(f, "step_derivative_rates", False):
            return unavailable(f"{type(f).__name__} depends on the velocities and its local_step_derivative "
                               "does not take them")
        if not callable(getattr(f, "local_step_derivative", None)) or not hasattr(f, "local_map"):
            return unavailable(f"{type(f).__name__} gives no local_step_derivative")
        carried = min(f.n_local, self.n_dofs) if self.dense else f.n_local    # directions the march carries
        if carried * self.basis.size > EXACT_TANGENT_LIMIT and not required:
            return None                            # the state's derivative would be too big
        self._stepper = f
        L = f.local_map
        return L.toarray() if self.dense else sp.csr_matrix(L)

    # -- pieces of the residual ----------------------------------------------------------
    @property
    def n_unknowns(self) -> int:
        return self.basis.size * self.n_dofs

    def linear_matrix(self, omega: float, xi: float = 0.0):
        r"""``A(Omega) = I (x) K + Omega D (x) (C - xi M) + Omega^2 D^2 (x) M`` ((nz, nz))."""
        A = self._A_K + omega * omega * self._A_M
        if self._A_C is not None:
            A = A + omega * self._A_C
        if xi != 0.0:
            A = A - xi * omega * self._DM
        return A

    def linear_omega_derivative(self, z: np.ndarray, omega: float, xi: float = 0.0) -> np.ndarray:
        """(nz,) ``dA/dOmega z``."""
        out = 2.0 * omega * (self._A_M @ z)
        if self._A_C is not None:
            out = out + self._A_C @ z
        if xi != 0.0:
            out = out - xi * (self._DM @ z)
        return np.asarray(out).reshape(-1)

    def external(self, force: float) -> np.ndarray:
        """(nz,) ``F_ext``: ``f_0`` in the zeroth harmonic, ``force b`` in ``b_1`` (``sin Omega t``)."""
        F = np.zeros((self.basis.size, self.n_dofs))
        if self.system.load is not None:
            F[0] = self.system.load
        if self.force_vector is not None and self.basis.harmonics >= 1:
            F[2] = force * self.force_vector
        return F.reshape(-1)

    def aft(self, z: np.ndarray, omega: float, *, jacobian: bool = True) -> AFTResult:
        """The nonlinear force's coefficients (and derivatives) at ``z`` (nz,) (module docstring)."""
        basis, n = self.basis, self.n_dofs
        nz = self.n_unknowns
        f = self.nonlinear
        if f is None:
            return AFTResult(np.zeros((basis.size, n)), None if not jacobian else
                             (np.zeros((nz, nz)) if self.dense else sp.csr_matrix((nz, nz))), np.zeros(nz))
        Z = np.asarray(z, dtype=float).reshape(basis.size, n)
        E, ED, P = basis.synthesis, basis.synthesis_derivative, basis.analysis
        q = E @ Z
        v = omega * (ED @ Z)
        N = basis.samples
        velocity = bool(getattr(f, "velocity_dependent", False))
        state = self.initial_state
        hook = self._hook if jacobian else None
        if hook is not None:
            stepper = self._stepper
            s = stepper.n_local
            # the directions carried through the march: the model's unknowns z when they are fewer
            # than the force's local ones (a reduced model), else the local coefficients
            on_dofs = self.dense and n < s
            m_z = basis.size * (n if on_dofs else s)
            seed = hook if on_dofs else np.eye(s)
            seeds = [np.kron(E[j], seed) for j in range(N)]
            if velocity:
                # a velocity-dependent force: the local rates omega L (E D Z)_j move along the same directions
                # (omega (E D)_j (x) seed) and, in one more direction, with Omega (L (E D Z)_j); the gaps do
                # not move with Omega
                m = m_z + 1
                rates = [stepper.localize(v[j]) for j in range(N)]
                rate_seeds = [np.column_stack([omega * np.kron(ED[j], seed),
                                               stepper.localize(ED[j] @ Z)]) for j in range(N)]
                seeds = [np.column_stack([d, np.zeros(s)]) for d in seeds]
                step = [{"xdot": rates[j], "dxdot": rate_seeds[j]} for j in range(N)]
            else:
                m = m_z
                step = [{}] * N
            dstate = np.zeros(np.shape(state) + (m,))
            dg = np.empty((N, s, m))
        for _ in range(self.passes - 1):
            for j in range(N):
                if hook is not None:
                    _, dstate = stepper.local_step_derivative(stepper.localize(q[j]), state, seeds[j], dstate,
                                                              **step[j])
                state = f.commit(q[j], v[j], state)
        before = _state_vector(state) if self.stateful else None
        forces = np.empty((N, n))
        Kt = [None] * N if jacobian else None
        Ct = [None] * N if jacobian and velocity else None
        joint = getattr(f, "dense_force_and_tangent", None) if jacobian and self.dense and hook is None else None
        for j in range(N):
            vj = v[j] if velocity else None
            if joint is not None:
                fj, dq, dv = joint(q[j], vj, state)
            else:
                fj = f.force(q[j], vj, state)
                dq, dv = f.tangent(q[j], vj, state) if jacobian and hook is None else (None, None)
            forces[j] = np.asarray(fj).reshape(-1)
            if jacobian and hook is None:
                Kt[j] = _tangent_matrix(dq, n, self.dense)
                if velocity:
                    Ct[j] = _tangent_matrix(dv, n, self.dense)
            if hook is not None:
                dg[j], dstate = stepper.local_step_derivative(stepper.localize(q[j]), state, seeds[j], dstate,
                                                              **step[j])
            state = f.commit(q[j], v[j], state) if self.stateful else state
        change = 0.0
        if self.stateful:
            after = _state_vector(state)
            if before is None or after is None:
                change = float("nan")
            elif before.size:
                # relative to the state's size, or the motion's where the state is nearly zero (stuck)
                size = max(np.linalg.norm(after), np.max(np.abs(q)), 1e-300)
                change = float(np.linalg.norm(after - before) / size)
        F = P @ forces
        if not jacobian:
            return AFTResult(F, state_change=change, state=state)
        if hook is not None:
            PG = np.einsum("hj,jsm->hsm", P, dg, optimize=on_dofs)    # (2H+1, s, m)
            if on_dofs:                           # dg (N, s, nz): the local force's derivative along z
                J = np.einsum("sa,hsm->ham", hook, PG[..., :m_z], optimize=True).reshape(nz, nz)
                dW = (PG[..., m_z] @ hook).reshape(-1) if velocity else np.zeros(nz)
            else:
                Lk = self._kron(self._eye, hook)
                J = Lk.T @ PG[..., :m_z].reshape(basis.size * s, -1) @ Lk
                dW = np.asarray(Lk.T @ PG[..., m_z].reshape(-1)).reshape(-1) if velocity else np.zeros(nz)
            return AFTResult(F, J, dW, change, state)
        J, dW = self._aft_jacobian(Kt, Ct, omega, v)
        return AFTResult(F, J, dW, change, state)

    def _aft_jacobian(self, Kt, Ct, omega, v):
        basis, n = self.basis, self.n_dofs
        E, ED, P = basis.synthesis, basis.synthesis_derivative, basis.analysis
        size = basis.size
        nz = self.n_unknowns
        if self.dense:
            zero = np.zeros((n, n))
            K = np.stack([zero if k is None else k for k in Kt])
            J = np.einsum("hj,jm,jab->hamb", P, E, K, optimize=True).reshape(nz, nz)
            dW = np.zeros(nz)
            if Ct is not None:
                C = np.stack([zero if c is None else c for c in Ct])
                J += omega * np.einsum("hj,jm,jab->hamb", P, ED, C, optimize=True).reshape(nz, nz)
                dW = np.einsum("hj,jab,jb->ha", P, C, v / omega if omega else np.zeros_like(v)).reshape(-1)
            return J, dW
        J = sp.csr_matrix((nz, nz))
        dW = np.zeros((size, n))
        for j in range(basis.samples):
            if Kt[j] is not None:
                J = J + sp.kron(sp.csr_matrix(np.outer(P[:, j], E[j])), Kt[j], format="csr")
            if Ct is not None and Ct[j] is not None:
                J = J + omega * sp.kron(sp.csr_matrix(np.outer(P[:, j], ED[j])), Ct[j], format="csr")
                if omega:
                    dW += np.outer(P[:, j], Ct[j] @ (v[j] / omega))
        return J, dW.reshape(-1)

    def residual(self, z: np.ndarray, omega: float, force: float = 0.0, *, xi: float = 0.0,
                 jacobian: bool = True) -> dict:
        r"""``R = A(Omega) z + F_nl - F_ext`` and, with ``jacobian``, ``dR/dz``, ``dR/dOmega``, ``dR/dF``.

        ``xi`` adds the self-excitation ``-xi M q'`` (:func:`epmc`). Returns a dict with
        ``residual``, ``jacobian``, ``d_omega``, ``d_force``, ``d_xi``, ``scale`` (the norm of
        the force terms the residual balances) and ``aft`` (:class:`AFTResult`).
        """
        z = np.asarray(z, dtype=float).reshape(-1)
        aft = self.aft(z, omega, jacobian=jacobian)
        A = self.linear_matrix(omega, xi)
        Fnl = aft.coefficients.reshape(-1)
        Fext = self.external(force)
        elastic = np.asarray(self._A_K @ z).reshape(-1)
        R = np.asarray(A @ z).reshape(-1) + Fnl - Fext
        scale = np.linalg.norm(elastic) + np.linalg.norm(Fnl) + np.linalg.norm(Fext)
        out = {"residual": R, "scale": scale, "aft": aft}
        if jacobian:
            out["jacobian"] = A + aft.jacobian
            out["d_omega"] = self.linear_omega_derivative(z, omega, xi) + aft.omega_derivative
            out["d_force"] = -self.external(1.0) + self.external(0.0)
            out["d_xi"] = -omega * np.asarray(self._DM @ z).reshape(-1)
        return out

    # -- solves ------------------------------------------------------------------------------
    def rest_tangent(self):
        """(n, n) ``K + df/dq`` at ``q = 0`` with the force's starting state (the stuck joint)."""
        K = self.stiffness
        if self.nonlinear is None:
            return K
        dq, _ = self.nonlinear.tangent(np.zeros(self.n_dofs), np.zeros(self.n_dofs), self.initial_state)
        dq = _tangent_matrix(dq, self.n_dofs, self.dense)
        return K if dq is None else K + dq

    def linear_guess(self, omega: float, force: float) -> np.ndarray:
        """(nz,) the solution of the model linearised at rest (``K + df/dq`` there)."""
        A = self._kron(self._eye, self.rest_tangent()) + omega * omega * self._A_M
        if self._A_C is not None:
            A = A + omega * self._A_C
        return solve_linear(A, self.external(force))

    def solve(self, omega: float, force: float, *, initial: np.ndarray | None = None,
              newton: Newton | None = None, chord: dict | None = None) -> HarmonicBalanceSolution:
        """The periodic solution at ``omega`` [rad/s] and ``force``: Newton from ``initial`` (nz,)
        (default :meth:`linear_guess`).

        ``chord``: a dict the caller keeps between neighbouring solves (a sweep) to reuse a Jacobian. A
        dense model's solve first takes chord steps with the Jacobian factored at the end of an earlier
        solve, each needing only the AFT's force (about a tenth of the exact Jacobian's cost for a joint,
        whose state derivative is carried through the march); when a step cuts the residual by less
        than :data:`CHORD_CONTRACTION`, Newton with fresh Jacobians takes over from the best point, and its last
        Jacobian is factored into ``chord`` for the next solve. The solution meets the same tolerance
        either way; ``iterations`` counts both kinds of step."""
        newton = newton or HB_NEWTON
        z0 = self.linear_guess(omega, force) if initial is None else np.asarray(initial, dtype=float).reshape(-1)
        chord_steps = 0
        if chord is not None and chord.get("lu") is not None and self.dense:
            z, norm, converged = z0, np.inf, False
            best = (np.inf, z0)
            for chord_steps in range(newton.max_iterations):
                r = self.residual(z, omega, force, jacobian=False)
                previous, norm = norm, float(np.linalg.norm(r["residual"]))
                if not np.isfinite(norm) or norm > CHORD_CONTRACTION * previous:
                    break
                best = min(best, (norm, z), key=lambda item: item[0])
                if norm <= newton.atol + newton.rtol * r["scale"]:
                    converged = True
                    break
                z = z - la.lu_solve(chord["lu"], r["residual"])
            if converged:
                aft = r["aft"]
                return HarmonicBalanceSolution(z.reshape(self.basis.size, self.n_dofs), float(omega), float(force),
                                               chord_steps, norm, aft.state_change)
            z0 = best[1]
        last = {}

        def fun(z):
            r = self.residual(z, omega, force)
            last["jacobian"] = r["jacobian"]
            return r["residual"], r["jacobian"], r["scale"]

        z, iterations, norm, extra = newton_solve(fun, z0, newton)
        if chord is not None and self.dense:
            chord["lu"] = la.lu_factor(last["jacobian"])
        aft = self.aft(z, omega, jacobian=False)
        return HarmonicBalanceSolution(z.reshape(self.basis.size, self.n_dofs), float(omega), float(force),
                                       iterations + chord_steps, norm, aft.state_change)

    # -- reading a solution ---------------------------------------------------------------------
    def periodic_states(self, Z: np.ndarray, omega: float) -> tuple[np.ndarray, np.ndarray, list]:
        """``(q (N, n), v (N, n), states)``: the sampled coordinates and velocities of a solution ``Z``
        (2H+1, n) at ``omega`` and the force's state at each sample of the last pass of the AFT's
        march (module docstring), as the force sees it there (committed at the sample before): the
        periodic loop's ``(q_j, state_j)`` pairs, e.g. to train a hyper-reduction on the motions
        harmonic balance computes. ``states`` is a list of N states (empty for a force without memory)."""
        Z = np.asarray(Z, dtype=float).reshape(self.basis.size, self.n_dofs)
        q = self.basis.synthesis @ Z
        v = omega * (self.basis.synthesis_derivative @ Z)
        f = self.nonlinear
        if f is None or not self.stateful:
            return q, v, []
        state = self.initial_state
        for _ in range(self.passes - 1):
            for j in range(self.basis.samples):
                state = f.commit(q[j], v[j], state)
        states = []
        for j in range(self.basis.samples):
            states.append(state)
            state = f.commit(q[j], v[j], state)
        return q, v, states

    def output_coefficients(self, Z: np.ndarray) -> np.ndarray:
        """(2H+1, p) coefficients of the outputs ``y = E q``."""
        return np.asarray(Z) @ self.output_matrix.T

    def phasor(self, Z: np.ndarray) -> np.ndarray:
        """(p,) the outputs' fundamentals ``Y = b_1 + i a_1``: ``y_1(t) = |Y| sin(Omega t + arg Y)``."""
        Y = self.output_coefficients(Z)
        if self.basis.harmonics < 1:
            return np.zeros(Y.shape[1], dtype=complex)
        return Y[2] + 1j * Y[1]


#: The Jacobian of a force with memory: see :class:`HarmonicBalance`'s ``tangent``.
TANGENTS = ("auto", "exact", "frozen")
#: Local unknowns times ``2H+1`` above which ``tangent="auto"`` takes the frozen tangent (the exact one
#: carries the state's derivative as a dense array of that many directions).
EXACT_TANGENT_LIMIT = 2000

#: Chord steps in :meth:`HarmonicBalance.solve` continue while each cuts the residual to at most this fraction
#: (a chord step costs the AFT's force alone, about a tenth of an exact Jacobian for a joint).
CHORD_CONTRACTION = 0.9

#: Harmonic-balance Newton defaults: a residual 1e-10 of the balanced forces, 40 iterations.
HB_NEWTON = Newton(rtol=1e-10, max_iterations=40)


def solve_linear(A, b):
    if sp.issparse(A):
        return spla.splu(sp.csc_matrix(A)).solve(np.asarray(b, dtype=float))
    return la.solve(A, b)


def newton_solve(fun, z0, newton: Newton, *, max_halvings: int = 6):
    r"""Newton for ``R(z) = 0`` with ``fun(z) -> (R, J, scale)``; backtracking on ``||R||``.

    Converged when ``||R|| <= atol + rtol scale`` (``scale`` the norm of the force terms the
    residual balances) or when an update no longer changes ``z`` in floating point. Returns
    ``(z, iterations, ||R||, {})``; raises :class:`HarmonicBalanceError`.
    """
    z = np.array(z0, dtype=float)
    R, J, scale = fun(z)
    norm = float(np.linalg.norm(R))
    for iteration in range(1, newton.max_iterations + 1):
        if norm <= newton.atol + newton.rtol * scale:
            return z, iteration - 1, norm, {}
        try:
            dz = -solve_linear(J, R)
        except (np.linalg.LinAlgError, RuntimeError) as error:
            raise HarmonicBalanceError(f"singular harmonic-balance Jacobian at iteration {iteration}: {error}") \
                from None
        step = 1.0
        for _ in range(max_halvings + 1):
            trial = z + step * dz
            R_t, J_t, scale_t = fun(trial)
            norm_t = float(np.linalg.norm(R_t))
            if np.isfinite(norm_t) and norm_t < norm:
                break
            step *= 0.5
        else:
            # no decrease: take the full step (Newton on a piecewise-smooth map may need it)
            trial = z + dz
            R_t, J_t, scale_t = fun(trial)
            norm_t = float(np.linalg.norm(R_t))
        small = np.linalg.norm(trial - z) <= 4 * np.finfo(float).eps * max(np.linalg.norm(trial), 1e-300)
        z, R, J, scale, norm = trial, R_t, J_t, scale_t, norm_t
        if small and norm <= 1e3 * (newton.atol + newton.rtol * scale):
            return z, iteration, norm, {}
    if norm <= newton.atol + newton.rtol * scale:
        return z, newton.max_iterations, norm, {}
    raise HarmonicBalanceError(f"harmonic balance: Newton did not converge in {newton.max_iterations} iterations "
                               f"(||R|| = {norm:.3e}, scale {scale:.3e})")
