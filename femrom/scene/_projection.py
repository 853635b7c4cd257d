r"""A system projected onto a basis about a reference state: the intrusive Galerkin model of a scene.

With ``q = q_0 + V q^`` (``V`` (n, r), ``q_0`` an equilibrium such as a bolt preload,
``K q_0 + f(q_0; z_0) = f_0``) the equations of motion
``M q'' + C q' + K q + f(q, q'; z) = f_0 + B u`` become, multiplied by ``V^T``,

.. math::

    V^T M V \ddot q^ + V^T C V \dot q^ + V^T K V q^ + V^T f(q_0 + V q^, V \dot q^; z)
        = V^T (f_0 - K q_0) + V^T B u,

a :class:`SecondOrderSystem` of size ``r`` whose nonlinear force is the original's
seen through ``q_0 + V q^`` (:func:`femrom.fem.transform_force`, its state, e.g. a
joint's sliders, unchanged) and whose outputs are ``E V q^`` (measured from ``q_0``).
At ``q^ = 0`` with the state ``z_0`` the reduced system is in equilibrium.

A mode basis of the linearisation about ``q_0`` (``K_t = K + df/dq``, mass-normalised)
makes ``V^T M V = I``; ``damping_ratios`` then sets modal damping
``C^ = diag(2 zeta_i omega_i)`` with ``omega_i^2`` the diagonal of ``V^T K_t V``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.fem import transform_force
from femrom.scene._system import SecondOrderSystem


def _project(A, V: np.ndarray) -> np.ndarray:
    AV = A @ V
    return V.T @ (AV.toarray() if sp.issparse(AV) else np.asarray(AV))


def project_system(system: SecondOrderSystem, basis: np.ndarray, *, reference: np.ndarray | None = None,
                   reference_state=None, damping_ratios=None) -> SecondOrderSystem:
    r"""``system`` on the coordinates ``q = q_0 + V q^`` (module docstring).

    Parameters
    ----------
    system : SecondOrderSystem
        ``n`` dofs.
    basis : (n, r) ndarray
        ``V``, full column rank.
    reference : (n,) ndarray, optional
        ``q_0`` (default zero).
    reference_state : optional
        The nonlinear force's committed state at ``q_0``: the reduced force's tangent at
        ``q^ = 0`` under it enters ``omega_i^2`` for ``damping_ratios``.
    damping_ratios : float or (r,) array_like, optional
        Modal damping ``C^ = diag(2 zeta_i omega_i)`` in place of ``V^T C V`` (needs
        ``V^T M V = I``, checked to 1e-8).

    Returns
    -------
    SecondOrderSystem
        ``r`` dofs; ``metadata["projection"]`` records ``r`` and whether it is about a reference.
    """
    V = np.asarray(basis, dtype=float)
    n = system.n_dofs
    if V.ndim != 2 or V.shape[0] != n or V.shape[1] < 1:
        raise FemromValueError(f"basis must be (n, r) with n = {n}, got shape {V.shape}")
    if not np.all(np.isfinite(V)):
        raise FemromValueError("basis has non-finite entries")
    q0 = None if reference is None else np.asarray(reference, dtype=float).reshape(-1)
    if q0 is not None and (q0.shape != (n,) or not np.all(np.isfinite(q0))):
        raise FemromValueError(f"reference must be a finite ({n},) vector, got shape {q0.shape}")
    r = V.shape[1]
    M = _project(system.mass, V)
    K = _project(system.stiffness, V)
    M, K = 0.5 * (M + M.T), 0.5 * (K + K.T)
    force = transform_force(system.nonlinear, V, reference=q0)
    C = None if system.damping is None else _project(system.damping, V)
    if damping_ratios is not None:
        if np.max(np.abs(M - np.eye(r))) > 1e-8:
            raise FemromValueError("damping_ratios needs a mass-normalised basis (V^T M V = I)")
        zeta = np.broadcast_to(np.asarray(damping_ratios, dtype=float), (r,))
        if not np.all(np.isfinite(zeta)) or np.any(zeta < 0):
            raise FemromValueError(f"damping_ratios must be finite and >= 0, got {damping_ratios!r}")
        stiffness = K.copy()
        if force is not None:
            state = force.initial_state() if reference_state is None else reference_state
            D = force.tangent(np.zeros(r), np.zeros(r), state)[0]
            if D is not None:
                stiffness = stiffness + (D.toarray() if sp.issparse(D) else np.asarray(D))
        omega = np.sqrt(np.maximum(np.diag(stiffness), 0.0))
        C = np.diag(2.0 * zeta * omega)
    load = None
    if system.load is not None or q0 is not None:
        f0 = np.zeros(n) if system.load is None else system.load
        if q0 is not None:
            f0 = f0 - np.asarray(system.stiffness @ q0).reshape(-1)
        load = V.T @ f0
    B = None if system.input_matrix is None else np.asarray(V.T @ system.input_matrix)
    E = None if system.output_matrix is None else np.asarray(system.output_matrix @ V)
    metadata = {**system.metadata, "projection": {"r": r, "about_reference": q0 is not None}}
    return SecondOrderSystem(mass=sp.csr_matrix(M), stiffness=sp.csr_matrix(K),
                             damping=None if C is None else sp.csr_matrix(C), input_matrix=B, inputs=system.inputs,
                             output_matrix=E, nonlinear=force, load=load, output_names=system.output_names,
                             metadata=metadata)
