r"""Reduced training data: projected snapshots and their time derivatives.

For a basis ``V`` (n, r) orthonormal in the product ``W`` (``V^T W V = I``;
``W = M`` for a mass-orthonormal basis, ``W = I`` for a Euclidean one) the
reduced coordinates of a snapshot are ``q^ = V^T W q``. Projected data:

- states ``Q^ = V^T W Q`` (r, K);
- velocities and accelerations ``Q^', Q^''``: finite differences of ``Q^``
  (:func:`~femrom.inference.finite_difference`; differencing commutes with the
  projection, so it is done in r dimensions), or the projected stored
  ``V^T W Q'``, ``V^T W Q''`` of the full-order run;
- known nonlinear forces ``F^ = V^T F`` (Galerkin: the force is a covector,
  projected with ``V^T``, not ``V^T W``);
- inputs ``U`` (m, K) and outputs ``Y`` (p, K) unchanged.

The diagnostics record what the error split of Geng et al. (CMAME 427, 2024)
needs: the projection error of the states and, when the full-order run
stored them, the error of the finite-difference derivatives against the
stored ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from femrom.inference._derivatives import finite_difference

#: Where the reduced derivatives come from.
DERIVATIVE_SOURCES = ("finite_difference", "stored")


@dataclass(frozen=True, eq=False)
class SecondOrderData:
    r"""Reduced snapshots of one or more trajectories, column-aligned.

    Attributes
    ----------
    states, velocities, accelerations : (r, K) ndarray
        ``Q^``, ``Q^'``, ``Q^''``.
    inputs : (m, K) ndarray or None
        ``U``.
    nonlinear_forces : (r, K) ndarray or None
        ``F^``: the projected known nonlinear force at each snapshot.
    outputs : (p, K) ndarray or None
        Recorded outputs ``Y`` (for the output map ``E^``).
    times : (K,) ndarray or None
    diagnostics : dict
        ``projection_error``, ``velocity_error``, ``acceleration_error``
        (relative, when known), ``derivative_source``, ``order``, ``dt``,
        ``n_trajectories``.
    """

    states: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    inputs: np.ndarray | None = None
    nonlinear_forces: np.ndarray | None = None
    outputs: np.ndarray | None = None
    times: np.ndarray | None = None
    diagnostics: dict = field(default_factory=dict)

    def __post_init__(self):
        shape = self.states.shape
        if self.states.ndim != 2:
            raise ValueError(f"states must be (r, K), got shape {shape}")
        for name in ("velocities", "accelerations", "nonlinear_forces"):
            A = getattr(self, name)
            if A is not None and A.shape != shape:
                raise ValueError(f"{name} has shape {A.shape}, expected {shape}")
        for name in ("inputs", "outputs"):
            A = getattr(self, name)
            if A is not None and (A.ndim != 2 or A.shape[1] != shape[1]):
                raise ValueError(f"{name} must be (., {shape[1]}), got shape {A.shape}")

    @property
    def r(self) -> int:
        return self.states.shape[0]

    @property
    def n_samples(self) -> int:
        return self.states.shape[1]

    @property
    def n_inputs(self) -> int:
        return 0 if self.inputs is None else self.inputs.shape[0]

    def without_boundary(self, count: int) -> "SecondOrderData":
        """Drop ``count`` columns at each end (e.g. the one-sided stencils)."""
        if count <= 0:
            return self
        keep = slice(count, self.n_samples - count)
        pick = lambda A: None if A is None else A[..., keep]  # noqa: E731
        return replace(self, states=pick(self.states), velocities=pick(self.velocities),
                       accelerations=pick(self.accelerations), inputs=pick(self.inputs),
                       nonlinear_forces=pick(self.nonlinear_forces), outputs=pick(self.outputs),
                       times=pick(self.times))


def concatenate(datasets) -> SecondOrderData:
    """One data set from several trajectories (columns side by side).

    Diagnostics are combined as root-mean-square of the relative errors.
    """
    datasets = list(datasets)
    if not datasets:
        raise ValueError("no data sets to concatenate")
    if len(datasets) == 1:
        return datasets[0]

    def cat(name):
        values = [getattr(d, name) for d in datasets]
        if all(v is None for v in values):
            return None
        if any(v is None for v in values):
            raise ValueError(f"{name} present in some trajectories only")
        return np.hstack(values)

    diagnostics = {"n_trajectories": sum(d.diagnostics.get("n_trajectories", 1) for d in datasets)}
    for key in ("projection_error", "velocity_error", "acceleration_error"):
        values = [d.diagnostics.get(key) for d in datasets]
        if all(v is not None for v in values):
            diagnostics[key] = float(np.sqrt(np.mean(np.square(values))))
    sources = {d.diagnostics.get("derivative_source") for d in datasets}
    if len(sources) == 1:
        diagnostics["derivative_source"] = sources.pop()
    return SecondOrderData(states=cat("states"), velocities=cat("velocities"),
                           accelerations=cat("accelerations"), inputs=cat("inputs"),
                           nonlinear_forces=cat("nonlinear_forces"), outputs=cat("outputs"),
                           times=None, diagnostics=diagnostics)


def reduced_coordinates(basis: np.ndarray, X: np.ndarray, product=None) -> np.ndarray:
    """(r, K) ndarray ``V^T W X`` (``W = I`` when ``product`` is ``None``)."""
    X = np.asarray(X, dtype=float)
    return basis.T @ (X if product is None else np.asarray(product @ X))


def _relative_norm(E: np.ndarray, X: np.ndarray, product=None) -> float:
    if product is None:
        num, den = np.sum(E * E), np.sum(X * X)
    else:
        num, den = np.sum(E * np.asarray(product @ E)), np.sum(X * np.asarray(product @ X))
    return float(np.sqrt(num / den)) if den > 0 else 0.0


def reduce_snapshots(basis: np.ndarray, states: np.ndarray, dt: float, *, product=None,
                     velocities: np.ndarray | None = None,
                     accelerations: np.ndarray | None = None,
                     derivatives: str = "finite_difference", order: int = 4,
                     inputs: np.ndarray | None = None,
                     nonlinear_forces: np.ndarray | None = None,
                     outputs: np.ndarray | None = None, t0: float = 0.0) -> SecondOrderData:
    r"""Project full-order snapshots onto ``V`` and build their derivatives.

    Parameters
    ----------
    basis : (n, r) ndarray
        ``V``, orthonormal in ``product``.
    states : (n, K) ndarray
        ``Q``: displacement snapshots at ``t0 + k dt``.
    dt : float
        Snapshot spacing.
    product : (n, n) sparse or ndarray, optional
        ``W`` with ``V^T W V = I`` (the mass for a mass-orthonormal basis).
    velocities, accelerations : (n, K) ndarray, optional
        The run's stored ``Q'`` and ``Q''``. With ``derivatives="stored"`` they
        are the training derivatives; otherwise they are the reference against
        which the finite-difference error is reported.
    derivatives : {"finite_difference", "stored"}
    order : {2, 4, 6}
        Finite-difference order.
    inputs : (m, K) ndarray, optional
    nonlinear_forces : (n, K) ndarray, optional
        ``f_nl`` at each snapshot; projected with ``V^T``.
    outputs : (p, K) ndarray, optional

    Returns
    -------
    SecondOrderData
    """
    if derivatives not in DERIVATIVE_SOURCES:
        raise ValueError(f"unknown derivative source {derivatives!r}; valid: {DERIVATIVE_SOURCES}")
    V = np.asarray(basis, dtype=float)
    Q = np.asarray(states, dtype=float)
    if V.ndim != 2 or Q.ndim != 2 or V.shape[0] != Q.shape[0]:
        raise ValueError(f"basis {V.shape} and states {Q.shape} do not match: expected (n, r), (n, K)")
    Qh = reduced_coordinates(V, Q, product)
    diagnostics = {"projection_error": _relative_norm(Q - V @ Qh, Q, product),
                   "derivative_source": derivatives, "order": order, "dt": float(dt),
                   "n_trajectories": 1}
    stored_v = None if velocities is None else reduced_coordinates(V, velocities, product)
    stored_a = None if accelerations is None else reduced_coordinates(V, accelerations, product)
    if derivatives == "stored":
        if stored_v is None or stored_a is None:
            raise ValueError("derivatives='stored' needs both velocities and accelerations")
        Qd, Qdd = stored_v, stored_a
    else:
        Qd = finite_difference(Qh, dt, order=order, derivative=1)
        Qdd = finite_difference(Qh, dt, order=order, derivative=2)
        if stored_v is not None:
            diagnostics["velocity_error"] = _relative_norm(Qd - stored_v, stored_v)
        if stored_a is not None:
            diagnostics["acceleration_error"] = _relative_norm(Qdd - stored_a, stored_a)
    F = None if nonlinear_forces is None else V.T @ np.asarray(nonlinear_forces, dtype=float)
    U = None if inputs is None else np.atleast_2d(np.asarray(inputs, dtype=float))
    Y = None if outputs is None else np.atleast_2d(np.asarray(outputs, dtype=float))
    times = float(t0) + float(dt) * np.arange(Q.shape[1])
    return SecondOrderData(states=Qh, velocities=Qd, accelerations=Qdd, inputs=U,
                           nonlinear_forces=F, outputs=Y, times=times, diagnostics=diagnostics)
