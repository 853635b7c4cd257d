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

Snapshots need not be in memory: every full-order argument of
:func:`reduce_snapshots` may be any block source of
:func:`femrom.linalg.as_block_source` (an array, a snapshot store's
``iter_blocks``, a callable returning column blocks), read in one pass. For a
nested basis (POD), project once with the largest basis and take
:meth:`SecondOrderData.truncated` for each smaller r.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference._derivatives import finite_difference
from femrom.linalg import as_block_source

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
    starts : tuple of int
        Columns where a trajectory begins (``(0,)`` for one trajectory): a
        stateful known force restarts its state there.
    diagnostics : dict
        ``projection_error``, ``velocity_error``, ``acceleration_error``
        (relative, when known), ``derivative_source``, ``order``, ``dt``,
        ``n_trajectories``; from :func:`reduce_snapshots` also
        ``projection_residual`` ``||Q - V Q^||_W`` and ``state_norm``
        ``||Q||_W`` (Frobenius), and per column ``column_residual2``
        ``||q_j - V q^_j||_W^2`` and ``column_norm2`` ``||q_j||_W^2`` ((K,)
        ndarrays), which :meth:`truncated` and :meth:`without_boundary` update;
        ``trimmed_columns`` after :meth:`without_boundary`.
    """

    states: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    inputs: np.ndarray | None = None
    nonlinear_forces: np.ndarray | None = None
    outputs: np.ndarray | None = None
    times: np.ndarray | None = None
    diagnostics: dict = field(default_factory=dict)
    starts: tuple = (0,)

    def __post_init__(self):
        shape = self.states.shape
        starts = tuple(int(s) for s in self.starts)
        if not starts or starts[0] != 0 or any(b <= a for a, b in zip(starts, starts[1:])) \
                or starts[-1] >= max(shape[-1], 1):
            raise FemromValueError(f"starts must begin at 0 and increase inside the {shape[-1]} columns, got {starts}")
        object.__setattr__(self, "starts", starts)
        if self.states.ndim != 2:
            raise FemromValueError(f"states must be (r, K), got shape {shape}")
        for name in ("velocities", "accelerations", "nonlinear_forces"):
            A = getattr(self, name)
            if A is not None and A.shape != shape:
                raise FemromValueError(f"{name} has shape {A.shape}, expected {shape}")
        for name in ("inputs", "outputs"):
            A = getattr(self, name)
            if A is not None and (A.ndim != 2 or A.shape[1] != shape[1]):
                raise FemromValueError(f"{name} must be (., {shape[1]}), got shape {A.shape}")
        for name in ("states", "velocities", "accelerations", "nonlinear_forces", "inputs", "outputs"):
            A = getattr(self, name)
            if A is None:
                continue
            if not np.issubdtype(A.dtype, np.number) or np.iscomplexobj(A):
                raise FemromValueError(f"{name} must be real numbers, got dtype {A.dtype}")
            bad = np.flatnonzero(~np.isfinite(A).all(axis=0))
            if bad.size:
                raise FemromValueError(f"{name}: snapshot column {bad[0]} is not finite")

    @property
    def r(self) -> int:
        return self.states.shape[0]

    @property
    def n_samples(self) -> int:
        return self.states.shape[1]

    @property
    def n_inputs(self) -> int:
        return 0 if self.inputs is None else self.inputs.shape[0]

    def between(self, start: float, stop: float) -> "SecondOrderData":
        """The columns with ``start <= t < stop`` (the times must be given), diagnostics kept."""
        if self.times is None:
            raise FemromValueError("between needs the data's times")
        if len(self.starts) > 1:
            raise FemromValueError("take a time window of each trajectory before concatenating them")
        keep = (self.times >= start) & (self.times < stop)
        pick = lambda A: None if A is None else A[..., keep]  # noqa: E731
        return replace(self, states=pick(self.states), velocities=pick(self.velocities),
                       accelerations=pick(self.accelerations), inputs=pick(self.inputs),
                       nonlinear_forces=pick(self.nonlinear_forces), outputs=pick(self.outputs),
                       times=pick(self.times), starts=(0,), diagnostics=dict(self.diagnostics))

    def without_boundary(self, count: int) -> "SecondOrderData":
        """Drop ``count`` columns at each end (e.g. the one-sided stencils)."""
        if count <= 0:
            return self
        if len(self.starts) > 1:
            raise FemromValueError("trim each trajectory before concatenating them")
        keep = slice(count, self.n_samples - count)
        pick = lambda A: None if A is None else A[..., keep]  # noqa: E731
        diagnostics = dict(self.diagnostics, trimmed_columns=self.diagnostics.get("trimmed_columns", 0) + count)
        for key in ("column_residual2", "column_norm2"):
            if diagnostics.get(key) is not None:
                diagnostics[key] = diagnostics[key][keep]
        return replace(self, states=pick(self.states), velocities=pick(self.velocities),
                       accelerations=pick(self.accelerations), inputs=pick(self.inputs),
                       nonlinear_forces=pick(self.nonlinear_forces), outputs=pick(self.outputs),
                       times=pick(self.times), diagnostics=diagnostics)


    def truncated(self, r: int) -> "SecondOrderData":
        r"""The data of the first ``r`` basis vectors, for a nested basis ``V_r = V[:, :r]`` (POD).

        Rows ``:r`` of the states, derivatives and forces. The projection
        error is updated exactly when the basis is orthonormal in the product
        the data were projected with: the discarded coordinates add
        orthogonally, ``||Q - V_r Q^_r||_W^2 = ||Q - V Q^||_W^2 + ||Q^_{r:}||_F^2``.
        Derivative-error diagnostics (finite differences against stored
        derivatives) are dropped: they are not separable by rows.
        """
        r = int(r)
        if not 1 <= r <= self.r:
            raise FemromValueError(f"cannot truncate data of r = {self.r} to r = {r}")
        if r == self.r:
            return self
        rows = lambda A: None if A is None else A[:r]  # noqa: E731
        d = {k: v for k, v in self.diagnostics.items() if k not in ("velocity_error", "acceleration_error")}
        residual, norm = d.get("projection_residual"), d.get("state_norm")
        if residual is not None and norm:
            d["projection_residual"] = float(np.hypot(residual, np.linalg.norm(self.states[r:])))
            d["projection_error"] = d["projection_residual"] / norm
        else:
            d.pop("projection_error", None)
        if d.get("column_residual2") is not None:
            d["column_residual2"] = d["column_residual2"] + np.sum(self.states[r:] ** 2, axis=0)
        return replace(self, states=rows(self.states), velocities=rows(self.velocities),
                       accelerations=rows(self.accelerations),
                       nonlinear_forces=rows(self.nonlinear_forces), diagnostics=d)

    def with_finite_differences(self, order: int = 4) -> "SecondOrderData":
        """The same states with velocities and accelerations by finite differences of order ``order``.

        Needs one uniformly sampled trajectory (``diagnostics["dt"]``). When
        the current derivatives are the run's stored ones, the relative error
        of the differences against them goes into the diagnostics.
        """
        dt = self.diagnostics.get("dt")
        if dt is None or self.diagnostics.get("n_trajectories", 1) != 1:
            raise FemromValueError("finite differences need one trajectory with a known step dt")
        Qd = finite_difference(self.states, dt, order=order, derivative=1)
        Qdd = finite_difference(self.states, dt, order=order, derivative=2)
        d = dict(self.diagnostics, derivative_source="finite_difference", order=order)
        if self.diagnostics.get("derivative_source") == "stored":
            d["velocity_error"] = _relative_norm(Qd - self.velocities, self.velocities)
            d["acceleration_error"] = _relative_norm(Qdd - self.accelerations, self.accelerations)
        return replace(self, velocities=Qd, accelerations=Qdd, diagnostics=d)


    def upsampled(self, substeps: int, inputs: np.ndarray | None = None) -> "SecondOrderData":
        r"""The data on a grid ``substeps`` times finer: reduced states filled in by cubic splines.

        Snapshots saved every k-th step of a solver with step ``dt`` (spacing
        ``h = k dt``) do not determine a Newmark model at ``h`` when the dynamics are
        only just resolved at ``dt``: the k-step propagator is out of its reach. A ROM
        stepping ``dt`` is, and the missing reduced states between the snapshots are
        smooth functions of time: interpolating them (``scipy.interpolate.CubicSpline``,
        not-a-knot, per coordinate; its error ``O(h^4)``) gives data on the fine grid for
        :meth:`integrator_consistent`, whose ROM then steps ``dt``. States, outputs and
        projected forces are interpolated; the inputs, known at any time, are taken as
        given on the fine grid (``inputs``, (m, k K') ndarray) or interpolated too.

        Parameters
        ----------
        substeps : int
            ``k``: the fine step is ``diagnostics["dt"] / k``.
        inputs : (m, (K - 1) k + 1) ndarray, optional

        Returns
        -------
        SecondOrderData
            With ``diagnostics["dt"]`` the fine step and ``upsampled = k``; velocities
            and accelerations are placeholders (zeros) for :meth:`integrator_consistent`.
        """
        from scipy.interpolate import CubicSpline

        k = int(substeps)
        h = self.diagnostics.get("dt")
        if k < 1 or h is None or self.diagnostics.get("n_trajectories", 1) != 1 or len(self.starts) > 1:
            raise FemromValueError("upsampling needs one trajectory with a known step dt and substeps >= 1")
        if k == 1:
            return self
        coarse = np.arange(self.n_samples) * h
        fine = np.arange((self.n_samples - 1) * k + 1) * (h / k)
        def spline(X):
            if X is None:
                return None
            Y = CubicSpline(coarse, X, axis=1)(fine)
            Y[:, ::k] = X                                  # the data themselves, not their round-off
            return Y

        if inputs is not None:
            inputs = np.atleast_2d(np.asarray(inputs, dtype=float))
            if inputs.shape[1] != fine.size:
                raise FemromValueError(f"inputs on the fine grid must have {fine.size} columns, got {inputs.shape[1]}")
        states = spline(self.states)
        d = {key: v for key, v in self.diagnostics.items()
             if key not in ("column_residual2", "column_norm2", "velocity_error", "acceleration_error")}
        d.update(dt=h / k, upsampled=k)
        return replace(self, states=states, velocities=np.zeros_like(states), accelerations=np.zeros_like(states),
                       inputs=inputs if inputs is not None else spline(self.inputs),
                       nonlinear_forces=spline(self.nonlinear_forces), outputs=spline(self.outputs),
                       times=None if self.times is None else self.times[0] + fine, diagnostics=d)

    def integrator_consistent(self) -> "SecondOrderData":
        r"""Data from the displacements alone that the Newmark (average acceleration) ROM reproduces exactly.

        Newmark's average-acceleration scheme with step ``h`` (the trapezoidal rule)
        gives ``q_{k+1} - q_k = h (v_k + v_{k+1}) / 2`` and ``v_{k+1} - v_k = h (a_k + a_{k+1}) / 2``,
        and it enforces ``M a_k + C v_k + K q_k + f_k = B u_k`` at every step. Averaging that
        equation with the weights ``(1, 2, 1) / 4`` (``A x_k = (x_{k-1} + 2 x_k + x_{k+1}) / 4``)
        leaves only displacements:

        .. math::

            M \frac{q_{k+1} - 2 q_k + q_{k-1}}{h^2} + C \frac{q_{k+1} - q_{k-1}}{2h}
            + K\, A q_k + A f_k = B\, A u_k .

        So the regression with accelerations ``delta^2 Q^ / h^2``, velocities
        ``delta Q^ / (2h)``, states ``A Q^`` and inputs, forces and outputs averaged
        alike is satisfied exactly by the reduced operators of a Newmark trajectory
        (its stored ``a_k``, ``v_k`` are not needed), and a model fitted to it and
        stepped by Newmark with the same ``h`` reproduces sampled data of any scheme as
        closely as a second-order model can: ``h`` is the snapshot spacing (every
        ``k``-th step of a finer run: the ROM steps with ``h = k dt``). Finite differences
        of the continuous derivatives instead fit the data's own time error, which
        the ROM's Newmark steps then add a second time (period elongation twice).

        Needs one uniformly sampled trajectory (``diagnostics["dt"]``); drops its first
        and last column. Per-column projection diagnostics are dropped (the columns
        are averages).
        """
        h = self.diagnostics.get("dt")
        if h is None or self.diagnostics.get("n_trajectories", 1) != 1 or len(self.starts) > 1:
            raise FemromValueError("integrator-consistent data need one trajectory with a known step dt")
        if self.n_samples < 3:
            raise FemromValueError(f"integrator-consistent data need at least 3 snapshots, got {self.n_samples}")
        Q = self.states
        average = lambda X: None if X is None else 0.25 * (X[:, :-2] + 2.0 * X[:, 1:-1] + X[:, 2:])  # noqa: E731
        d = {k: v for k, v in self.diagnostics.items()
             if k not in ("column_residual2", "column_norm2", "velocity_error", "acceleration_error")}
        d.update(derivative_source="integrator", order=None, trimmed_columns=d.get("trimmed_columns", 0) + 1)
        return replace(self, states=average(Q), velocities=(Q[:, 2:] - Q[:, :-2]) / (2.0 * h),
                       accelerations=(Q[:, 2:] - 2.0 * Q[:, 1:-1] + Q[:, :-2]) / h**2,
                       inputs=average(self.inputs), nonlinear_forces=average(self.nonlinear_forces),
                       outputs=average(self.outputs),
                       times=None if self.times is None else self.times[1:-1], diagnostics=d)


def sampling_step(data: SecondOrderData) -> float | None:
    """The uniform time step between the columns of each trajectory of ``data`` (``None`` if unknown
    or not uniform): from its times, or from ``diagnostics["sampling_step"]`` of concatenated data."""
    if data.times is None:
        return data.diagnostics.get("sampling_step")
    t = np.asarray(data.times, dtype=float)
    if t.size < 2:
        return None
    h = np.diff(t)
    return float(h[0]) if np.allclose(h, h[0], rtol=1e-6, atol=0) else None


def concatenate(datasets) -> SecondOrderData:
    """One data set from several trajectories (columns side by side).

    Diagnostics are combined as root-mean-square of the relative errors; a step shared by every
    trajectory is kept as ``diagnostics["sampling_step"]`` (:func:`sampling_step`).
    """
    datasets = list(datasets)
    if not datasets:
        raise FemromValueError("no data sets to concatenate")
    if len(datasets) == 1:
        return datasets[0]

    def cat(name):
        values = [getattr(d, name) for d in datasets]
        if all(v is None for v in values):
            return None
        if any(v is None for v in values):
            raise FemromValueError(f"{name} present in some trajectories only")
        return np.hstack(values)

    diagnostics = {"n_trajectories": sum(d.diagnostics.get("n_trajectories", 1) for d in datasets)}
    for key in ("projection_error", "velocity_error", "acceleration_error"):
        values = [d.diagnostics.get(key) for d in datasets]
        if all(v is not None for v in values):
            diagnostics[key] = float(np.sqrt(np.mean(np.square(values))))
    sources = {d.diagnostics.get("derivative_source") for d in datasets}
    if len(sources) == 1:
        diagnostics["derivative_source"] = sources.pop()
    trimmed = max(d.diagnostics.get("trimmed_columns", 0) for d in datasets)
    if trimmed:
        diagnostics["trimmed_columns"] = trimmed
    steps = [sampling_step(d) for d in datasets]
    if steps[0] is not None and all(h is not None and np.isclose(h, steps[0], rtol=1e-9) for h in steps):
        diagnostics["sampling_step"] = steps[0]
    offsets = np.cumsum([0] + [d.n_samples for d in datasets[:-1]])
    starts = tuple(int(o + s) for o, d in zip(offsets, datasets) for s in d.starts)
    return SecondOrderData(states=cat("states"), velocities=cat("velocities"),
                           accelerations=cat("accelerations"), inputs=cat("inputs"),
                           nonlinear_forces=cat("nonlinear_forces"), outputs=cat("outputs"),
                           times=None, diagnostics=diagnostics, starts=starts)


def reduced_coordinates(basis: np.ndarray, X, product=None) -> np.ndarray:
    """(r, K) ndarray ``V^T W X`` (``W = I`` when ``product`` is ``None``).

    ``X`` is an (n, K) array or any block source of
    :func:`femrom.linalg.as_block_source` (read in one pass).
    """
    if isinstance(X, np.ndarray):
        return basis.T @ (X if product is None else np.asarray(product @ X))
    return project_columns(basis, X, product)[0]


def project_columns(basis: np.ndarray, X, product=None, *, per_column: bool = False) -> tuple:
    r"""One pass over the columns of ``X``: ``(V^T W X, ||X - V V^T W X||_W, ||X||_W)``.

    Parameters
    ----------
    basis : (n, r) ndarray
        ``V``, orthonormal in ``W`` for the residual to be the projection error.
    X : (n, K) array or block source
        Read block by block (:func:`femrom.linalg.as_block_source`); memory
        O(n (r + b)) for blocks of b columns.
    product : (n, n) sparse or ndarray, optional
        ``W``; ``W @`` is applied once per block, and ``W V`` once in all.

    per_column : bool
        Return, instead of the two norms, the squared norms of every column:
        ``residual2`` and ``norm2``, (K,) ndarrays (errors over any window of columns).

    Returns
    -------
    coordinates : (r, K) ndarray
    residual, norm : float
        Frobenius norms in ``W`` of the projection residual and of ``X``
        (``residual2, norm2`` (K,) ndarrays with ``per_column``).
    """
    V = np.asarray(basis, dtype=float)
    WV = V if product is None else np.asarray(product @ V)
    parts, residual2, norm2 = [], [], []
    for block in as_block_source(X).blocks():
        WX = block if product is None else np.asarray(product @ block)
        coords = V.T @ WX
        parts.append(coords)
        # E = X - V c, and W E = W X - (W V) c: no second product with W
        E = block - V @ coords
        residual2.append(np.maximum(np.sum(E * (WX - WV @ coords), axis=0), 0.0))
        norm2.append(np.maximum(np.sum(block * WX, axis=0), 0.0))
    if not parts:
        raise FemromValueError("no snapshot columns to project")
    residual2, norm2 = np.concatenate(residual2), np.concatenate(norm2)
    if per_column:
        return np.hstack(parts), residual2, norm2
    return np.hstack(parts), float(np.sqrt(np.sum(residual2))), float(np.sqrt(np.sum(norm2)))


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
    states : (n, K) array or block source
        ``Q``: displacement snapshots at ``t0 + k dt``; like every full-order
        argument here, an array or any block source of
        :func:`femrom.linalg.as_block_source` (e.g. ``lambda:
        store.iter_blocks("q", 64, ["run"])``), read once.
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
        raise FemromValueError(f"unknown derivative source {derivatives!r}; valid: {DERIVATIVE_SOURCES}")
    V = np.asarray(basis, dtype=float)
    if V.ndim != 2:
        raise FemromValueError(f"basis must be (n, r), got shape {V.shape}")
    source = as_block_source(states)
    if source.n_rows is not None and source.n_rows != V.shape[0]:
        raise FemromValueError(f"basis {V.shape} and states with {source.n_rows} rows do not match: "
                               "expected (n, r), (n, K)")
    Qh, residual2, norm2 = project_columns(V, source, product, per_column=True)
    residual, norm = float(np.sqrt(np.sum(residual2))), float(np.sqrt(np.sum(norm2)))
    diagnostics = {"projection_error": residual / norm if norm > 0 else 0.0,
                   "projection_residual": residual, "state_norm": norm,
                   "column_residual2": residual2, "column_norm2": norm2,
                   "derivative_source": derivatives, "order": order, "dt": float(dt),
                   "n_trajectories": 1}
    stored_v = None if velocities is None else reduced_coordinates(V, velocities, product)
    stored_a = None if accelerations is None else reduced_coordinates(V, accelerations, product)
    if derivatives == "stored":
        if stored_v is None or stored_a is None:
            raise FemromValueError("derivatives='stored' needs both velocities and accelerations")
        Qd, Qdd = stored_v, stored_a
    else:
        Qd = finite_difference(Qh, dt, order=order, derivative=1)
        Qdd = finite_difference(Qh, dt, order=order, derivative=2)
        if stored_v is not None:
            diagnostics["velocity_error"] = _relative_norm(Qd - stored_v, stored_v)
        if stored_a is not None:
            diagnostics["acceleration_error"] = _relative_norm(Qdd - stored_a, stored_a)
    F = None if nonlinear_forces is None else reduced_coordinates(V, nonlinear_forces)
    U = None if inputs is None else np.atleast_2d(np.asarray(inputs, dtype=float))
    Y = None if outputs is None else np.atleast_2d(np.asarray(outputs, dtype=float))
    times = float(t0) + float(dt) * np.arange(Qh.shape[1])
    return SecondOrderData(states=Qh, velocities=Qd, accelerations=Qdd, inputs=U,
                           nonlinear_forces=F, outputs=Y, times=times, diagnostics=diagnostics)
