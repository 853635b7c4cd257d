r"""Hamiltonian operator inference for canonical Hamiltonian systems.

For ``y = [q; p]`` with ``q' = dH/dp``, ``p' = -dH/dq`` and a cotangent-lift
basis ``V_q = V_p = Phi`` (Peng & Mohseni, SIAM J. Sci. Comput. 38, 2016), the
reduced Hamiltonian ``H^ = q^T D^_q q / 2 + p^T D^_p p / 2 + H^_nl`` gives

.. math::

    \dot{\hat q} = \hat D_p \hat p + \hat f_q, \qquad
    \dot{\hat p} = -\hat D_q \hat q - \hat f_p ,

and Sharma, Wang & Kramer (Physica D 431, 2022) fit the symmetric operators by

.. math::

    \min_{\hat D_p = \hat D_p^\top} \| R_p - \hat D_p \hat P \|_F, \quad
    R_p = \dot{\hat Q} - \hat F_q ;\qquad
    \min_{\hat D_q = \hat D_q^\top} \| R_q - \hat D_q \hat Q \|_F, \quad
    R_q = -\dot{\hat P} - \hat F_p ,

whose optimality conditions are Lyapunov equations

.. math::

    (\hat P \hat P^\top) \hat D_p + \hat D_p (\hat P \hat P^\top)
        = \hat P R_p^\top + R_p \hat P^\top

(and likewise for ``D^_q``), solved by Bartels-Stewart
(:func:`scipy.linalg.solve_continuous_lyapunov`) in ``O(r^3)``, never as an
``r^2 x r^2`` Kronecker system. A Tikhonov weight ``lambda`` adds
``lambda I`` to the Gram matrix (``2 lambda`` on the left's diagonal).

Known nonlinear Hamiltonian terms (Sharma, Wang & Kramer 2022, Sec. 3): with
``H = q^T D_q q / 2 + p^T D_p p / 2 + H_nl(q, p)`` and ``H_nl`` known (a
potential object), the forcing data are
the projected gradients ``F^_q = Phi^T dH_nl/dp (Q, P)`` and
``F^_p = Phi^T dH_nl/dq (Q, P)``, subtracted before the Lyapunov fits
(:func:`reduce_canonical_snapshots`); the reduced model evaluates the same
term through :class:`ProjectedPotential`, ``H^_nl(q^, p^) = H_nl(Phi q^, Phi p^)``,
so its right-hand side stays ``J_{2r} grad H^``.

Every fit reports its error split (:class:`HamiltonianErrorSplit`, after Geng,
Singh, Ju, Kramer & Wang, CMAME 427, 2024): the projection error of the
training states, the error of finite-difference derivatives against given
ones, and the optimisation residual.

``shared=True`` (an option of femrom, not of the paper) fits one symmetric
``D^ = D^_q = D^_p`` to both residuals, for systems whose full operators are
equal (the NLS: ``D_q = D_p = -Laplacian``). The reduced Hamiltonian is then
invariant under the phase rotation ``(q^, p^) -> (q^ cos a - p^ sin a,
q^ sin a + p^ cos a)`` whenever ``H_nl`` is, and the reduced mass
``|q^|^2 + |p^|^2`` is an exact invariant of the ROM (Noether).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sl

from femrom._errors import FemromValueError
from femrom.inference._derivatives import finite_difference


def symmetric_lyapunov_fit(X: np.ndarray, R: np.ndarray, regularization: float = 0.0) -> np.ndarray:
    r"""(r, r) symmetric ``D`` minimising ``||R - D X||_F^2 + lambda ||D||_F^2``.

    Solves ``(G + lambda I) D + D (G + lambda I) = X R^T + R X^T`` with
    ``G = X X^T``.

    Parameters
    ----------
    X : (r, K) ndarray
    R : (r, K) ndarray
    regularization : float
        Absolute ``lambda >= 0``.
    """
    G = X @ X.T + regularization * np.eye(X.shape[0])
    S = X @ R.T
    D = sl.solve_continuous_lyapunov(G, S + S.T)
    return 0.5 * (D + D.T)


@dataclass(frozen=True, eq=False)
class HamiltonianOperators:
    r"""``q' = D_p p + f_q``, ``p' = -D_q q - f_p`` with symmetric ``D_q``, ``D_p`` (r, r)."""

    position: np.ndarray     # D_q
    momentum: np.ndarray     # D_p

    @property
    def r(self) -> int:
        return self.position.shape[0]

    def hamiltonian(self, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``q^T D_q q / 2 + p^T D_p p / 2`` column by column."""
        return 0.5 * (np.sum(q * (self.position @ q), axis=0) + np.sum(p * (self.momentum @ p), axis=0))


class ProjectedPotential:
    r"""``H^_nl(q^, p^) = H_nl(Phi q^, Phi p^)`` of a known potential through a cotangent lift.

    ``grad_q^ H^_nl = Phi^T dH_nl/dq (Phi q^, Phi p^)`` (likewise for ``p^``)
    and Hessian blocks ``Phi^T H_xy Phi`` (r, r), so that a reduced system built
    on it is again canonical Hamiltonian. Costs ``O(n r)`` per gradient and
    ``O(n r^2)`` per Hessian (pointwise potentials): the unreduced price that
    hyper-reduction would remove.

    Parameters
    ----------
    potential : object
        ``value``, ``gradient``, ``hessian`` on full states (n,) / (n, k).
    basis : (n, r) ndarray
        ``Phi``.
    """

    def __init__(self, potential, basis: np.ndarray):
        self.potential = potential
        self.basis = np.asarray(basis, dtype=float)

    def value(self, q: np.ndarray, p: np.ndarray):
        return self.potential.value(self.basis @ q, self.basis @ p)

    def gradient(self, q: np.ndarray, p: np.ndarray):
        gq, gp = self.potential.gradient(self.basis @ q, self.basis @ p)
        return self.basis.T @ gq, self.basis.T @ gp

    def hessian(self, q: np.ndarray, p: np.ndarray):
        V = self.basis
        blocks = []
        for h in self.potential.hessian(V @ q, V @ p):
            if h is None:                                       # a block the potential does not have
                blocks.append(np.zeros((V.shape[1], V.shape[1])))
            elif isinstance(h, np.ndarray) and h.ndim == 1:    # pointwise potential: Phi^T diag(h) Phi
                blocks.append(V.T @ (h[:, None] * V))
            else:                                               # sparse or dense (n, n): never densified
                blocks.append(V.T @ np.asarray(h @ V))
        return tuple(blocks)


class ForcePotential:
    r"""The potential ``U(q)`` of a conservative, stateless second-order force as a canonical ``H_nl(q, p) = U(q)``.

    A conservative force ``f(q) = grad U(q)`` of ``M q'' + K q + f(q) = 0`` is, in
    the canonical variables ``(q, p = M q')``, the Hamiltonian term ``H_nl = U(q)``:
    ``dH_nl/dq = f(q)``, ``dH_nl/dp = 0``. This wraps any such
    :class:`~femrom.fem.NonlinearForce` (``force``, ``tangent``, ``potential``)
    in the ``value`` / ``gradient`` / ``hessian`` interface of :class:`ProjectedPotential`.

    Parameters
    ----------
    force : NonlinearForce
        ``conservative`` and not ``stateful`` (else ValueError).
    """

    def __init__(self, force):
        if getattr(force, "stateful", False) or not getattr(force, "conservative", False):
            raise FemromValueError(f"{force!r} is not a conservative stateless force: it has no potential U(q)")
        self.force = force

    def value(self, q: np.ndarray, p: np.ndarray):
        """``U(q)``: a float for (n,), (k,) for (n, k) columns."""
        q = np.asarray(q, dtype=float)
        if q.ndim == 1:
            return self.force.potential(q)
        return np.array([self.force.potential(column) for column in q.T])

    def gradient(self, q: np.ndarray, p: np.ndarray):
        """``(f(q), 0)``, each shaped like ``q``."""
        q = np.asarray(q, dtype=float)
        fq = self.force.force(q) if q.ndim == 1 else np.column_stack([self.force.force(c) for c in q.T])
        return fq, np.zeros_like(q)

    def hessian(self, q: np.ndarray, p: np.ndarray):
        """``(df/dq, None, None)``: the (n, n) sparse tangent; the ``qp`` and ``pp`` blocks vanish."""
        return self.force.tangent(np.asarray(q, dtype=float))[0], None, None

    def __repr__(self) -> str:
        return f"ForcePotential({self.force!r})"


def canonical_from_second_order(data) -> CanonicalData:
    r"""The canonical view ``(q^, p^ = q^')`` of reduced second-order data of a conservative system.

    In a basis with ``V^T M V = I`` the reduced Lagrangian of ``M q'' + K q + f(q) = 0`` is
    ``|q^'|^2 / 2 - q^T K~ q^ / 2 - U(V q^)``, so the reduced momentum is ``p^ = q^'``
    (``= V^T p`` of the full momentum ``p = M q'``) and

    .. math::

        \dot{\hat q} = \hat D_p \hat p, \qquad \dot{\hat p} = -\hat D_q \hat q - \hat F,

    with ``D~_p = I``, ``D~_q = K~`` for the intrusive model. The data are therefore
    ``Q^`` (states_q), ``Q^'`` (states_p and ddt_q), ``Q^''`` (ddt_p) and the projected
    force ``F^`` (forces_p) of a :class:`~femrom.inference.SecondOrderData`.

    Parameters
    ----------
    data : SecondOrderData
        Without inputs (a canonical Hamiltonian ROM has none).

    Returns
    -------
    CanonicalData
    """
    if data.inputs is not None and np.size(data.inputs) and np.any(data.inputs != 0):
        raise FemromValueError("the data carry nonzero inputs: a canonical Hamiltonian ROM has none")
    diagnostics = {key: data.diagnostics[key] for key in ("projection_error", "derivative_source", "order", "dt")
                   if key in data.diagnostics}
    forces_p = None if data.nonlinear_forces is None else np.asarray(data.nonlinear_forces, dtype=float)
    forces_q = None if forces_p is None else np.zeros_like(forces_p)
    return CanonicalData(data.states, data.velocities, data.velocities, data.accelerations, forces_q, forces_p,
                         data.outputs, diagnostics)


def project_potential_gradient(basis: np.ndarray, potential, Q: np.ndarray,
                               P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""``(F^_q, F^_p) = (Phi^T dH_nl/dp (Q, P), Phi^T dH_nl/dq (Q, P))``, each (r, K).

    ``Q``, ``P`` (n, K) are full states: the FOM snapshots (as in the paper) or
    their reconstructions ``Phi Q^``, ``Phi P^``.
    """
    gq, gp = potential.gradient(np.asarray(Q, float), np.asarray(P, float))
    return basis.T @ gp, basis.T @ gq


#: Where :func:`reduce_canonical_snapshots` evaluates the known gradient.
GRADIENT_DATA = ("snapshots", "reconstructed")

#: Where :func:`reduce_canonical_snapshots` takes the time derivatives from.
HAMILTONIAN_DERIVATIVE_SOURCES = ("finite_difference", "stored")


@dataclass(frozen=True)
class HamiltonianErrorSplit:
    r"""The error sources of a Hamiltonian fit (Geng, Singh, Ju, Kramer & Wang, CMAME 427, 2024).

    The counterpart of :class:`~femrom.inference.ErrorSplit` for canonical
    data ``y = [q; p]`` (first derivatives only). Relative Frobenius norms:

    Attributes
    ----------
    projection : float or None
        ``||[Q; P] - blkdiag(Phi, Phi) [Q^; P^]||_F / ||[Q; P]||_F`` of the
        training states (``None`` for data that came reduced).
    derivative : float or None
        ``||[Q^'; P^']_fd - Phi^T [Q'; P']|| / ||Phi^T [Q'; P']||``: finite
        differences against the given full derivatives (``0`` when those were
        the training data, ``None`` when no reference is known).
    position_derivative, momentum_derivative : float or None
        The same for ``Q^'`` and ``P^'`` alone.
    optimization : float
        ``||[R_p - D^_p P^; R_q - D^_q Q^]||_F / ||[R_p; R_q]||_F``: the
        residual the fitted operators leave, from the data columns (a Gram
        expansion cancels below ``sqrt(eps)``).
    """

    projection: float | None
    derivative: float | None
    position_derivative: float | None
    momentum_derivative: float | None
    optimization: float


def _relative(E: np.ndarray, X: np.ndarray) -> float:
    den = float(np.sum(X * X))
    return float(np.sqrt(np.sum(E * E) / den)) if den > 0 else 0.0


def _projection_residual2(V: np.ndarray, X: np.ndarray, Xh: np.ndarray, block: int = 1024) -> float:
    """``||X - V Xh||_F^2`` from the columns, ``block`` at a time (memory (n, block))."""
    total = 0.0
    for start in range(0, X.shape[1], block):
        E = X[:, start:start + block] - V @ Xh[:, start:start + block]
        total += float(np.sum(E * E))
    return total


@dataclass(frozen=True, eq=False)
class CanonicalData:
    r"""Reduced canonical training data ``[Q^; P^]`` with their time derivatives and known forcing.

    Attributes
    ----------
    states_q, states_p : (r, K) ndarray
        ``Q^``, ``P^``.
    ddt_q, ddt_p : (r, K) ndarray
        ``Q^'``, ``P^'``.
    forces_q, forces_p : (r, K) ndarray or None
        ``F^_q = Phi^T dH_nl/dp``, ``F^_p = Phi^T dH_nl/dq`` of a known potential.
    outputs : (m, K) ndarray or None
        Measured outputs ``Y``.
    diagnostics : dict
        ``projection_error``, ``derivative_error``, ``position_derivative_error``,
        ``momentum_derivative_error`` (when known), ``derivative_source``,
        ``gradient_data``, ``order``, ``dt``.
    """

    states_q: np.ndarray
    states_p: np.ndarray
    ddt_q: np.ndarray
    ddt_p: np.ndarray
    forces_q: np.ndarray | None = None
    forces_p: np.ndarray | None = None
    outputs: np.ndarray | None = None
    diagnostics: dict = field(default_factory=dict)

    def __post_init__(self):
        shape = np.shape(self.states_q)
        if len(shape) != 2:
            raise FemromValueError(f"states_q must be (r, K), got shape {shape}")
        for name in ("states_p", "ddt_q", "ddt_p", "forces_q", "forces_p"):
            A = getattr(self, name)
            if A is not None and np.shape(A) != shape:
                raise FemromValueError(f"{name} has shape {np.shape(A)}, expected {shape} like states_q")
        if self.outputs is not None and np.shape(self.outputs)[-1] != shape[1]:
            raise FemromValueError(f"outputs have {np.shape(self.outputs)[-1]} columns, snapshots {shape[1]}")

    @property
    def r(self) -> int:
        return self.states_q.shape[0]

    @property
    def n_samples(self) -> int:
        return self.states_q.shape[1]


def reduce_canonical_snapshots(basis: np.ndarray, Q: np.ndarray, P: np.ndarray, dt: float | None = None,
                               *, ddt_q: np.ndarray | None = None, ddt_p: np.ndarray | None = None,
                               potential=None, order: int = 4, gradient_data: str = "snapshots",
                               derivatives: str | None = None,
                               outputs: np.ndarray | None = None) -> CanonicalData:
    r"""Project full canonical snapshots through a cotangent lift ``Phi``.

    ``Q^ = Phi^T Q``, ``P^ = Phi^T P``; derivative data ``Phi^T Q'``,
    ``Phi^T P'`` from the given full derivatives (``derivatives="stored"``,
    the default when they are given) or finite differences of order
    ``order`` of the reduced snapshots (``"finite_difference"``, uniform
    ``dt``; the given derivatives, if any, are then the reference of the
    derivative error); forcing data from :func:`project_potential_gradient`
    at the snapshots (``gradient_data="snapshots"``, the paper's choice) or
    at ``Phi Q^``, ``Phi P^`` (``"reconstructed"``, what the ROM evaluates).

    Parameters
    ----------
    basis : (n, r) ndarray
        ``Phi`` of the cotangent lift (``Phi^T Phi = I``).
    Q, P : (n, K) ndarray
    dt : float, optional
        Snapshot spacing (needed for finite differences).
    ddt_q, ddt_p : (n, K) ndarray, optional
        Full time derivatives.
    potential : object, optional
        The known ``H_nl``.
    order : {2, 4, 6}
    gradient_data : {"snapshots", "reconstructed"}
    derivatives : {"stored", "finite_difference"}, optional
    outputs : (m, K) ndarray, optional

    Returns
    -------
    CanonicalData
        With the projection error of ``[Q; P]`` and the derivative errors in its diagnostics.
    """
    if gradient_data not in GRADIENT_DATA:
        raise FemromValueError(f"unknown gradient_data {gradient_data!r}; valid: {GRADIENT_DATA}")
    if (ddt_q is None) != (ddt_p is None):
        raise FemromValueError("give both ddt_q and ddt_p, or neither")
    if derivatives is None:
        derivatives = "finite_difference" if ddt_q is None else "stored"
    if derivatives not in HAMILTONIAN_DERIVATIVE_SOURCES:
        raise FemromValueError(f"unknown derivatives {derivatives!r}; valid: "
                               f"{HAMILTONIAN_DERIVATIVE_SOURCES}")
    if derivatives == "stored" and ddt_q is None:
        raise FemromValueError("derivatives='stored' needs ddt_q and ddt_p")
    V = np.asarray(basis, dtype=float)
    Q, P = np.asarray(Q, dtype=float), np.asarray(P, dtype=float)
    if V.ndim != 2 or Q.ndim != 2 or Q.shape != P.shape or Q.shape[0] != V.shape[0]:
        raise FemromValueError(f"basis {V.shape}, Q {Q.shape} and P {P.shape} do not match: "
                               "expected (n, r), (n, K), (n, K)")
    Qh, Ph = V.T @ Q, V.T @ P
    stored = None if ddt_q is None else (V.T @ ddt_q, V.T @ ddt_p)
    if derivatives == "stored":
        dQ, dP = stored
    else:
        if dt is None:
            raise FemromValueError("finite-difference derivatives need dt")
        dQ, dP = finite_difference(Qh, dt, order), finite_difference(Ph, dt, order)
    Fq = Fp = None
    if potential is not None:
        at = (Q, P) if gradient_data == "snapshots" else (V @ Qh, V @ Ph)
        Fq, Fp = project_potential_gradient(V, potential, *at)
    # the projection residual from the columns (||X||^2 - ||Phi^T X||^2 cancels)
    residual2 = _projection_residual2(V, Q, Qh) + _projection_residual2(V, P, Ph)
    norm2 = float(np.sum(Q * Q) + np.sum(P * P))
    diagnostics = {"projection_error": float(np.sqrt(residual2 / norm2)) if norm2 > 0 else 0.0,
                   "derivative_source": derivatives, "gradient_data": gradient_data,
                   "order": int(order) if derivatives == "finite_difference" else None,
                   "dt": None if dt is None else float(dt)}
    if derivatives == "stored":
        diagnostics.update(derivative_error=0.0, position_derivative_error=0.0, momentum_derivative_error=0.0)
    elif stored is not None:
        diagnostics.update(derivative_error=_relative(np.vstack([dQ - stored[0], dP - stored[1]]),
                                                      np.vstack(stored)),
                           position_derivative_error=_relative(dQ - stored[0], stored[0]),
                           momentum_derivative_error=_relative(dP - stored[1], stored[1]))
    Y = None if outputs is None else np.atleast_2d(np.asarray(outputs, dtype=float))
    return CanonicalData(Qh, Ph, dQ, dP, Fq, Fp, Y, diagnostics)
