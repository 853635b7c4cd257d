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
potential object, :mod:`femrom.integrators._hamiltonian`), the forcing data are
the projected gradients ``F^_q = Phi^T dH_nl/dp (Q, P)`` and
``F^_p = Phi^T dH_nl/dq (Q, P)``, subtracted before the Lyapunov fits
(:meth:`HamiltonianOpInf.fit_snapshots`); the reduced model evaluates the same
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

from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg as sl


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
            if isinstance(h, np.ndarray) and h.ndim == 1:      # pointwise potential: Phi^T diag(h) Phi
                blocks.append(V.T @ (h[:, None] * V))
            else:
                h = h.toarray() if hasattr(h, "toarray") else np.asarray(h)
                blocks.append(V.T @ h @ V)
        return tuple(blocks)


def project_potential_gradient(basis: np.ndarray, potential, Q: np.ndarray,
                               P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""``(F^_q, F^_p) = (Phi^T dH_nl/dp (Q, P), Phi^T dH_nl/dq (Q, P))``, each (r, K).

    ``Q``, ``P`` (n, K) are full states: the FOM snapshots (as in the paper) or
    their reconstructions ``Phi Q^``, ``Phi P^``.
    """
    gq, gp = potential.gradient(np.asarray(Q, float), np.asarray(P, float))
    return basis.T @ gp, basis.T @ gq


#: Where :meth:`HamiltonianOpInf.fit_snapshots` evaluates the known gradient.
GRADIENT_DATA = ("snapshots", "reconstructed")

#: Where :meth:`HamiltonianOpInf.fit_snapshots` takes the time derivatives from.
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


class HamiltonianOpInf:
    r"""Learn ``D^_q``, ``D^_p`` (symmetric) from reduced canonical data.

    Parameters
    ----------
    regularization : float
        Relative Tikhonov weight: ``lambda = rho * trace(X X^T) / r``.
    shared : bool
        Fit one symmetric ``D^ = D^_q = D^_p`` (module docstring).

    Attributes
    ----------
    operators_ : HamiltonianOperators
    residual_ : float
        Relative residual of both regressions together (``error_split_.optimization``).
    error_split_ : HamiltonianErrorSplit
        Projection, derivative and optimisation errors (projection and
        derivative only from :meth:`fit_snapshots`).
    """

    method = "hamiltonian_opinf"

    def __init__(self, regularization: float = 0.0, shared: bool = False):
        if not regularization >= 0:
            raise ValueError(f"regularization must be >= 0, got {regularization}")
        self.regularization = float(regularization)
        self.shared = bool(shared)

    def fit(self, states_q: np.ndarray, states_p: np.ndarray, ddt_q: np.ndarray,
            ddt_p: np.ndarray, forces_q: np.ndarray | None = None,
            forces_p: np.ndarray | None = None) -> "HamiltonianOpInf":
        """Fit from reduced (r, K) data ``Q^, P^, Q^', P^'`` and known ``F^_q, F^_p``."""
        states_q, states_p = np.asarray(states_q, float), np.asarray(states_p, float)
        shape = states_q.shape
        if states_q.ndim != 2:
            raise ValueError(f"states_q must be (r, K), got shape {shape}")
        for name, A in (("states_p", states_p), ("ddt_q", ddt_q), ("ddt_p", ddt_p),
                        ("forces_q", forces_q), ("forces_p", forces_p)):
            if A is not None and np.shape(A) != shape:
                raise ValueError(f"{name} has shape {np.shape(A)}, expected {shape} like states_q")
        Rp = ddt_q - (0.0 if forces_q is None else forces_q)
        Rq = -ddt_p - (0.0 if forces_p is None else forces_p)
        lam_p = self.regularization * np.sum(states_p**2) / states_p.shape[0]
        lam_q = self.regularization * np.sum(states_q**2) / states_q.shape[0]
        if self.shared:
            Dp = Dq = symmetric_lyapunov_fit(np.hstack([states_p, states_q]), np.hstack([Rp, Rq]),
                                             lam_p + lam_q)
        else:
            Dp = symmetric_lyapunov_fit(states_p, Rp, lam_p)
            Dq = symmetric_lyapunov_fit(states_q, Rq, lam_q)
        self.operators_ = HamiltonianOperators(position=Dq, momentum=Dp)
        # from the data columns, not from the Gram matrices (cancellation below sqrt(eps))
        num = np.linalg.norm(Rp - Dp @ states_p) ** 2 + np.linalg.norm(Rq - Dq @ states_q) ** 2
        den = np.linalg.norm(Rp) ** 2 + np.linalg.norm(Rq) ** 2
        self.residual_ = float(np.sqrt(num / den)) if den > 0 else 0.0
        self.error_split_ = HamiltonianErrorSplit(projection=None, derivative=None,
                                                  position_derivative=None,
                                                  momentum_derivative=None,
                                                  optimization=self.residual_)
        self.data_ = {"forces": forces_q is not None or forces_p is not None,
                      "n_samples": int(shape[1])}
        return self

    def fit_snapshots(self, basis: np.ndarray, Q: np.ndarray, P: np.ndarray, dt: float | None = None,
                      *, ddt_q: np.ndarray | None = None, ddt_p: np.ndarray | None = None,
                      potential=None, order: int = 4, gradient_data: str = "snapshots",
                      derivatives: str | None = None) -> "HamiltonianOpInf":
        r"""Project full snapshots through ``Phi`` and fit.

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
            Default: ``"stored"`` when ``ddt_q``, ``ddt_p`` are given.

        Attributes set
        --------------
        basis_ : (n, r) ndarray
        potential_ : ProjectedPotential or None
        error_split_ : HamiltonianErrorSplit
            With the projection error of ``[Q; P]`` and the derivative error.
        """
        from femrom.inference._derivatives import finite_difference

        if gradient_data not in GRADIENT_DATA:
            raise ValueError(f"unknown gradient_data {gradient_data!r}; valid: {GRADIENT_DATA}")
        if (ddt_q is None) != (ddt_p is None):
            raise ValueError("give both ddt_q and ddt_p, or neither")
        if derivatives is None:
            derivatives = "finite_difference" if ddt_q is None else "stored"
        if derivatives not in HAMILTONIAN_DERIVATIVE_SOURCES:
            raise ValueError(f"unknown derivatives {derivatives!r}; valid: "
                             f"{HAMILTONIAN_DERIVATIVE_SOURCES}")
        if derivatives == "stored" and ddt_q is None:
            raise ValueError("derivatives='stored' needs ddt_q and ddt_p")
        V = np.asarray(basis, dtype=float)
        Q, P = np.asarray(Q, dtype=float), np.asarray(P, dtype=float)
        if V.ndim != 2 or Q.ndim != 2 or Q.shape != P.shape or Q.shape[0] != V.shape[0]:
            raise ValueError(f"basis {V.shape}, Q {Q.shape} and P {P.shape} do not match: "
                             "expected (n, r), (n, K), (n, K)")
        Qh, Ph = V.T @ Q, V.T @ P
        stored = None if ddt_q is None else (V.T @ ddt_q, V.T @ ddt_p)
        if derivatives == "stored":
            dQ, dP = stored
        else:
            if dt is None:
                raise ValueError("finite-difference derivatives need dt")
            dQ, dP = finite_difference(Qh, dt, order), finite_difference(Ph, dt, order)
        Fq = Fp = None
        if potential is not None:
            at = (Q, P) if gradient_data == "snapshots" else (V @ Qh, V @ Ph)
            Fq, Fp = project_potential_gradient(V, potential, *at)
        self.fit(Qh, Ph, dQ, dP, Fq, Fp)
        self.basis_ = V
        self.potential_ = None if potential is None else ProjectedPotential(potential, V)
        # the error split: projection residual from the columns (||X||^2 - ||Phi^T X||^2 cancels)
        residual2 = _projection_residual2(V, Q, Qh) + _projection_residual2(V, P, Ph)
        norm2 = float(np.sum(Q * Q) + np.sum(P * P))
        split = {"projection": float(np.sqrt(residual2 / norm2)) if norm2 > 0 else 0.0}
        if derivatives == "stored":
            split.update(derivative=0.0, position_derivative=0.0, momentum_derivative=0.0)
        elif stored is not None:
            split.update(derivative=_relative(np.vstack([dQ - stored[0], dP - stored[1]]),
                                              np.vstack(stored)),
                         position_derivative=_relative(dQ - stored[0], stored[0]),
                         momentum_derivative=_relative(dP - stored[1], stored[1]))
        self.error_split_ = replace(self.error_split_, **split)
        self.data_.update(derivative_source=derivatives, gradient_data=gradient_data,
                          order=int(order) if derivatives == "finite_difference" else None,
                          dt=None if dt is None else float(dt))
        return self

    def describe(self) -> dict:
        """What was fitted how (stored with a saved :class:`~femrom.rom.HamiltonianROM`)."""
        out = {"method": self.method, "regularization": self.regularization,
               "shared": self.shared}
        if hasattr(self, "error_split_"):
            out["residual"] = self.residual_
            out["error_split"] = {k: getattr(self.error_split_, k)
                                  for k in self.error_split_.__dataclass_fields__}
            out["data"] = dict(self.data_)
        return out
