r"""Input-output data on a uniform time grid, and Markov parameters: what identification learns from.

Identified first-order models (DMDc, ERA, OKID) describe the sampled map from
inputs to outputs,

.. math::

    z_{k+1} = A z_k + B u_k, \qquad y_k = C z_k + D u_k, \qquad u_k = u(t_0 + k\,\Delta t),

so their data are input samples ``U`` (m, K), output samples ``Y`` (p, K) and,
for DMDc, state samples ``X`` (n, K) (reduced coordinates such as the POD
coefficients ``[q^; q^']``), on one uniform grid of step ``dt``. Several
trajectories sit side by side; ``starts`` marks where each begins, and no
learner pairs a column with the next one across a start.

:meth:`InputOutputData.from_second_order` reads the same reduced data that
L-OpInf learns from (:class:`~femrom.inference.SecondOrderData`: ``Q^``,
``Q^'``, ``U``, ``Y``, ``starts``), so one set of full-order runs feeds every
learner.

The Markov parameters of such a model are its impulse response,

.. math::

    Y_0 = D, \qquad Y_k = C A^{k-1} B \quad (k \ge 1), \qquad
    y_k = \sum_{i=0}^{k} Y_i u_{k-i} \ \text{from rest};

:class:`MarkovParameters` holds ``Y_0 ... Y_{N-1}`` as an (N, p, m) array.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from femrom._errors import FemromValueError

#: How :meth:`InputOutputData.from_second_order` builds the state rows.
STATE_LAYOUTS = ("phase", "displacement", "none")


def _real_finite(name: str, A, ndim: int) -> np.ndarray:
    """``A`` as a float array of ``ndim`` dimensions; one clear error when it is not real and finite."""
    A = np.asarray(A)
    if A.ndim != ndim:
        raise FemromValueError(f"{name} must have {ndim} dimensions, got shape {A.shape}")
    if not np.issubdtype(A.dtype, np.number) or np.iscomplexobj(A):
        raise FemromValueError(f"{name} must be real numbers, got dtype {A.dtype}")
    A = A.astype(float, copy=False)
    if not np.all(np.isfinite(A)):
        bad = np.argwhere(~np.isfinite(A))[0]
        raise FemromValueError(f"{name} is not finite at index {tuple(int(i) for i in bad)}")
    return A


def _positive_step(dt) -> float:
    try:
        dt = float(dt)
    except (TypeError, ValueError):
        raise FemromValueError(f"dt must be a positive number, got {dt!r}") from None
    if not (np.isfinite(dt) and dt > 0):
        raise FemromValueError(f"dt must be a positive number, got {dt}")
    return dt


@dataclass(frozen=True, eq=False)
class InputOutputData:
    r"""Sampled inputs, outputs and (optionally) states of one or more trajectories, column-aligned.

    Attributes
    ----------
    inputs : (m, K) ndarray
        ``U``: column ``k`` is ``u(t_k)``.
    outputs : (p, K) ndarray or None
        ``Y`` (needed by OKID, and by DMDc for a fitted output map).
    dt : float
        The sampling step of every trajectory.
    states : (n, K) ndarray or None
        ``X``: reduced coordinates of the state at each sample (DMDc's data).
    starts : tuple of int
        Columns where a trajectory begins (``(0,)`` for one); every trajectory
        has at least two samples.
    metadata : dict
        Where the data came from (state layout, reduced dimension).
    """

    inputs: np.ndarray
    outputs: np.ndarray | None = None
    dt: float = 1.0
    states: np.ndarray | None = None
    starts: tuple = (0,)
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        U = _real_finite("inputs", self.inputs, 2)
        if U.shape[0] < 1:
            raise FemromValueError("inputs must have at least one row (m >= 1)")
        K = U.shape[1]
        object.__setattr__(self, "inputs", U)
        object.__setattr__(self, "dt", _positive_step(self.dt))
        for name in ("outputs", "states"):
            A = getattr(self, name)
            if A is None:
                continue
            A = _real_finite(name, A, 2)
            if A.shape[1] != K:
                raise FemromValueError(f"{name} have {A.shape[1]} columns, inputs have {K}")
            object.__setattr__(self, name, A)
        starts = tuple(int(s) for s in self.starts)
        if not starts or starts[0] != 0 or any(b <= a for a, b in zip(starts, starts[1:])) or starts[-1] >= K:
            raise FemromValueError(f"starts must begin at 0 and increase inside the {K} columns, got {starts}")
        ends = starts[1:] + (K,)
        short = [j for j, (a, b) in enumerate(zip(starts, ends)) if b - a < 2]
        if short:
            raise FemromValueError(f"trajectory {short[0]} has fewer than 2 samples (starts {starts}, K = {K})")
        object.__setattr__(self, "starts", starts)

    # -- sizes ---------------------------------------------------------------------------
    @property
    def n_inputs(self) -> int:
        return self.inputs.shape[0]

    @property
    def n_outputs(self) -> int:
        return 0 if self.outputs is None else self.outputs.shape[0]

    @property
    def n_states(self) -> int:
        return 0 if self.states is None else self.states.shape[0]

    @property
    def n_samples(self) -> int:
        return self.inputs.shape[1]

    @property
    def n_trajectories(self) -> int:
        return len(self.starts)

    def trajectories(self) -> list[slice]:
        """One column slice per trajectory."""
        ends = self.starts[1:] + (self.n_samples,)
        return [slice(a, b) for a, b in zip(self.starts, ends)]

    def step_pairs(self) -> np.ndarray:
        """(N,) int ndarray of the columns ``k`` whose successor ``k + 1`` is in the same trajectory."""
        return np.concatenate([np.arange(s.start, s.stop - 1) for s in self.trajectories()])

    # -- construction --------------------------------------------------------------------
    @classmethod
    def from_second_order(cls, data, *, states: str = "phase", dt: float | None = None) -> "InputOutputData":
        r"""The input-output view of reduced second-order data (:class:`~femrom.inference.SecondOrderData`).

        Parameters
        ----------
        data : SecondOrderData
            With inputs; its outputs, ``starts`` and ``diagnostics["dt"]`` are used.
        states : {"phase", "displacement", "none"}
            The state rows: ``[Q^; Q^']`` (2r, K), the first-order state of a
            second-order model (the default), ``Q^`` (r, K), or none.
        dt : float, optional
            The sampling step (default ``data.diagnostics["dt"]``).
        """
        if states not in STATE_LAYOUTS:
            raise FemromValueError(f"unknown state layout {states!r}; valid: {', '.join(STATE_LAYOUTS)}")
        if getattr(data, "inputs", None) is None:
            raise FemromValueError("the second-order data have no inputs: identification needs them")
        if dt is None:
            dt = data.diagnostics.get("dt")
            if dt is None:
                raise FemromValueError("the second-order data record no step dt: pass dt=")
        X = {"phase": lambda: np.vstack([data.states, data.velocities]),
             "displacement": lambda: data.states, "none": lambda: None}[states]()
        metadata = {"state_layout": states, "r": int(data.states.shape[0]),
                    "derivative_source": data.diagnostics.get("derivative_source")}
        return cls(inputs=data.inputs, outputs=data.outputs, dt=dt, states=X, starts=data.starts,
                   metadata=metadata)

    @classmethod
    def stack(cls, datasets) -> "InputOutputData":
        """One data set from several (trajectories side by side; the same ``dt`` and sizes)."""
        datasets = list(datasets)
        if not datasets:
            raise FemromValueError("no data sets to stack")
        first = datasets[0]
        for j, d in enumerate(datasets[1:], start=1):
            if not np.isclose(d.dt, first.dt, rtol=1e-12, atol=0.0):
                raise FemromValueError(f"data set {j} has dt = {d.dt}, data set 0 has {first.dt}")
            for name in ("n_inputs", "n_outputs", "n_states"):
                if getattr(d, name) != getattr(first, name):
                    raise FemromValueError(f"data set {j} has {name} = {getattr(d, name)}, "
                                           f"data set 0 has {getattr(first, name)}")

        def cat(name):
            values = [getattr(d, name) for d in datasets]
            return None if values[0] is None else np.hstack(values)

        offsets = np.cumsum([0] + [d.n_samples for d in datasets[:-1]])
        starts = tuple(int(o + s) for o, d in zip(offsets, datasets) for s in d.starts)
        return cls(inputs=cat("inputs"), outputs=cat("outputs"), dt=first.dt, states=cat("states"),
                   starts=starts, metadata=dict(first.metadata))


@dataclass(frozen=True, eq=False)
class MarkovParameters:
    r"""The impulse response ``Y_0 = D``, ``Y_k = C A^{k-1} B`` of a sampled linear system.

    Attributes
    ----------
    parameters : (N, p, m) ndarray
        ``parameters[k] = Y_k``, stored in this layout whatever ``layout`` was given.
    dt : float
    metadata : dict
        Where they came from (``"source"``: an impulse response, OKID, a model).
    layout : {None, "npm", "pmn"}
        How ``parameters`` was given: ``"npm"`` femrom's ``(N, p, m)``; ``"pmn"``
        python-control's ``(p, m, N)`` (``control.markov``), moved to ``(N, p, m)``.
        ``None`` (default) reads ``(N, p, m)`` but refuses an array with more inputs
        than samples (``m > N``), the sign of a ``(p, m, N)`` array given as
        femrom's; say ``"npm"`` to keep such an array as it is.
    """

    parameters: np.ndarray
    dt: float = 1.0
    metadata: dict = field(default_factory=dict)
    layout: str | None = None

    def __post_init__(self):
        if self.layout not in (None, "npm", "pmn"):
            raise FemromValueError(f"Markov parameters layout must be 'npm' (N, p, m) or 'pmn' (p, m, N: "
                                   f"python-control's), got {self.layout!r}")
        Y = _real_finite("Markov parameters", self.parameters, 3)
        if self.layout == "pmn":
            Y = np.ascontiguousarray(np.moveaxis(Y, -1, 0))
        if Y.shape[0] < 2 or Y.shape[1] < 1 or Y.shape[2] < 1:
            raise FemromValueError(f"Markov parameters must be (N >= 2, p >= 1, m >= 1), got shape {Y.shape}")
        if self.layout is None and Y.shape[2] > Y.shape[0]:
            raise FemromValueError(
                f"Markov parameters of shape {Y.shape} read as (N, p, m) are {Y.shape[0]} samples of a system with "
                f"{Y.shape[2]} inputs, more inputs than samples: python-control's layout is (p, m, N); give "
                "layout='pmn' for it, or layout='npm' if the shape is right")
        object.__setattr__(self, "parameters", Y)
        object.__setattr__(self, "layout", "npm")
        object.__setattr__(self, "dt", _positive_step(self.dt))

    @property
    def count(self) -> int:
        """``N``: ``Y_0 ... Y_{N-1}``."""
        return self.parameters.shape[0]

    @property
    def n_outputs(self) -> int:
        return self.parameters.shape[1]

    @property
    def n_inputs(self) -> int:
        return self.parameters.shape[2]

    @property
    def feedthrough(self) -> np.ndarray:
        """(p, m) ndarray ``Y_0 = D``."""
        return self.parameters[0]

    def relative_error(self, other: "MarkovParameters", count: int | None = None) -> float:
        r"""``||Y - Y_ref||_F / ||Y_ref||_F`` over ``Y_0 ... Y_{count-1}`` (``other`` the reference)."""
        count = min(self.count, other.count) if count is None else int(count)
        if count > min(self.count, other.count):
            raise FemromValueError(f"count {count} exceeds the {min(self.count, other.count)} parameters available")
        if self.parameters.shape[1:] != other.parameters.shape[1:]:
            raise FemromValueError(f"Markov parameters of shape {self.parameters.shape[1:]} and "
                                   f"{other.parameters.shape[1:]} cannot be compared")
        reference = other.parameters[:count]
        return float(np.linalg.norm(self.parameters[:count] - reference) / np.linalg.norm(reference))
