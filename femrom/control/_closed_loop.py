r"""The closed loop: a plant, an observer of its outputs and an MPC, one sample at a time.

At sample ``k`` the loop has the plant's outputs ``y_k`` (taken with the input
``u_k`` already applied) and

1. updates the observer: ``x_{k|k}`` from ``y_k`` and ``u_k``;
2. predicts ``x_{k+1|k} = A x_{k|k} + B u_k``: the state at the next sample;
3. asks the MPC for ``u_{k+1}`` from that prediction, the reference window
   ``r_{k+1} .. r_{k+N}``, ``u_k`` and the disturbance offsets;
4. steps the plant with ``u_{k+1}`` and reads ``y_{k+1}``.

The QP is solved between two samples with the outputs up to ``y_k``, so the
input it returns can be applied at ``t_{k+1}``: the loop is real-time when a
solve (``qp_seconds``) takes less than ``dt``. The plant may be anything with
``step(u) -> y`` and ``output`` (:mod:`._plants`); the controller never sees
more than the outputs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError
from femrom._json import dumps
from femrom._progress import Progress
from femrom.control._problem import vector


@dataclass(frozen=True, eq=False)
class ClosedLoopResult:
    r"""What :func:`closed_loop` recorded, and its metrics.

    Attributes
    ----------
    outputs : (p, K) ndarray
        The plant's outputs ``y_k`` (without measurement noise).
    inputs : (m, K) ndarray
        The applied inputs ``u_k`` (``u_0`` is the initial input, the others the MPC's).
    reference : (p, K) ndarray
    estimates : (n_a, K) ndarray
        The observer's filtered estimates ``x_{k|k}`` (state, then disturbance).
    qp_seconds : (K - 1,) ndarray
        Wall time of each MPC call (parameters, QP solve, unpacking).
    solver_seconds : (K - 1,) ndarray
        The QP solver's own time of each solve.
    statuses : tuple of str
        The solver status of each solve.
    input_bound : (m,) ndarray
        The MPC's bounds (``inf``: none).
    n_fallbacks : int
        Solves replaced by the MPC's ``on_failure`` policy.
    plant_states : (s, K) ndarray or None
        What ``record_state(plant)`` returned at each sample.
    dt : float or None
    """

    outputs: np.ndarray
    inputs: np.ndarray
    reference: np.ndarray
    estimates: np.ndarray
    qp_seconds: np.ndarray
    solver_seconds: np.ndarray
    statuses: tuple
    input_bound: np.ndarray
    n_fallbacks: int = 0
    plant_states: np.ndarray | None = None
    dt: float | None = None

    @property
    def n_samples(self) -> int:
        return self.outputs.shape[1]

    def tracking_error(self, start: int = 1) -> float:
        r"""Relative RMS tracking error over the samples ``k = start .. K - 1``:

        .. math::

            e = \sqrt{\frac{\sum_k \sum_i (y_{ik} - r_{ik})^2}{\sum_k \sum_i r_{ik}^2}},

        the RMS of ``y - r`` over the RMS amplitude of the reference (``y_0`` is not
        the controller's doing, hence ``start = 1``).
        """
        e = self.outputs[:, start:] - self.reference[:, start:]
        scale = np.sqrt(np.sum(self.reference[:, start:] ** 2))
        if scale == 0:
            raise FemromValueError("the reference is zero over the window: use the RMS output instead")
        return float(np.sqrt(np.sum(e ** 2)) / scale)

    def input_effort(self, start: int = 1) -> float:
        r"""RMS of the applied inputs: ``sqrt(mean_{i, k >= start} u_{ik}^2)``."""
        return float(np.sqrt(np.mean(self.inputs[:, start:] ** 2)))

    def max_constraint_violation(self, start: int = 1) -> float:
        r"""``max_{i, k >= start} max(|u_{ik}| - b_i, 0)``: how far an applied input left its bound."""
        excess = np.abs(self.inputs[:, start:]) - self.input_bound[:, None]
        return float(max(np.max(excess, initial=-np.inf), 0.0))

    def metrics(self, start: int = 1) -> dict:
        """The closed loop's numbers as a JSON-ready dict.

        ``tracking_error``, ``input_effort``, ``max_constraint_violation`` (above),
        ``qp_seconds_per_step`` (median of the MPC calls) and ``qp_seconds_max``,
        ``solver_seconds_per_step`` (median of the solver's own time),
        ``realtime_factor`` (``dt`` over the median call; > 1 is faster than real
        time), ``n_fallbacks``, ``n_inaccurate`` (solves the solver flagged
        inaccurate), ``n_repaired`` (plans that failed the MPC's accuracy certificate and
        were repaired), ``n_steps``.
        """
        qp = self.qp_seconds
        median = float(np.median(qp)) if qp.size else float("nan")
        solver = self.solver_seconds[np.isfinite(self.solver_seconds)]
        return {
            "tracking_error": self.tracking_error(start),
            "input_effort": self.input_effort(start),
            "max_constraint_violation": self.max_constraint_violation(start),
            "qp_seconds_per_step": median,
            "qp_seconds_max": float(np.max(qp)) if qp.size else float("nan"),
            "solver_seconds_per_step": float(np.median(solver)) if solver.size else float("nan"),
            "realtime_factor": (self.dt / median) if self.dt and median > 0 else None,
            "n_fallbacks": int(self.n_fallbacks),
            "n_inaccurate": sum(status.startswith("optimal_inaccurate") for status in self.statuses),
            "n_repaired": sum(status.endswith("(repaired)") for status in self.statuses),
            "n_steps": self.n_samples - 1,
        }


    # -- storage ------------------------------------------------------------------------
    _ARRAYS = ("outputs", "inputs", "reference", "estimates", "qp_seconds", "solver_seconds", "input_bound")

    def save(self, path, *, metadata: dict | None = None) -> None:
        """Write the arrays, the statuses, the metrics and ``metadata`` (e.g. the controller's
        ``describe()``) to HDF5."""
        import h5py

        with h5py.File(path, "w") as f:
            f.attrs["format"] = "femrom.ClosedLoopResult"
            f.attrs["version"] = 1
            f.attrs["n_fallbacks"] = int(self.n_fallbacks)
            if self.dt is not None:
                f.attrs["dt"] = float(self.dt)
            f.attrs["metrics"] = dumps(self.metrics())
            f.attrs["metadata"] = dumps(metadata or {})
            for name in self._ARRAYS:
                f.create_dataset(name, data=getattr(self, name))
            f.create_dataset("statuses", data=np.array(self.statuses, dtype=object), dtype=h5py.string_dtype())
            if self.plant_states is not None:
                f.create_dataset("plant_states", data=self.plant_states)

    @classmethod
    def load(cls, path) -> "ClosedLoopResult":
        import h5py

        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != "femrom.ClosedLoopResult":
                raise FemromValueError(f"{path} is not a femrom ClosedLoopResult file")
            arrays = {name: f[name][()] for name in cls._ARRAYS}
            statuses = tuple(s.decode() if isinstance(s, bytes) else str(s) for s in f["statuses"][()])
            states = f["plant_states"][()] if "plant_states" in f else None
            dt = float(f.attrs["dt"]) if "dt" in f.attrs else None
            return cls(**arrays, statuses=statuses, n_fallbacks=int(f.attrs["n_fallbacks"]),
                       plant_states=states, dt=dt)


def _padded(reference: np.ndarray, extra: int) -> np.ndarray:
    """The reference with its last column repeated ``extra`` times (the window past the end)."""
    return np.hstack([reference, np.repeat(reference[:, -1:], extra, axis=1)])


def closed_loop(plant, controller, observer, reference, n_steps: int | None = None, *, u0=None,
                output_noise: float | None = None, seed: int = 0, record_state=None,
                dt: float | None = None, progress: bool | None = None) -> ClosedLoopResult:
    r"""Run ``plant`` under ``controller`` with ``observer`` (module docstring) for ``n_steps`` samples.

    Parameters
    ----------
    plant : object with ``step(u) -> y`` and ``output``
        :class:`StateSpacePlant`, :class:`ReducedPlant`, :class:`FullOrderPlant` or any other.
    controller : LinearMPC
    observer : LinearObserver
        On the controller's model (:class:`KalmanObserver`, :class:`PolePlacementObserver`);
        its estimate at call time is the prior ``x_{0|-1}``.
    reference : (p, K) array_like
        ``r_k`` at the samples ``k = 0 .. K - 1``. The MPC looks ``N`` samples
        ahead: past the reference's end the last sample is held, a reference
        the plant may not be able to follow, so give ``N`` samples more than
        the run.
    n_steps : int, optional
        Samples to step: default ``K - 1 - N`` (every window inside the
        reference), at most ``K - 1``.
    u0 : (m,) array_like, optional
        The input applied at ``t_0`` (zeros by default; the plant must have been made with it).
    output_noise : float, optional
        Standard deviation of white noise added to the outputs the observer sees
        (the recorded outputs stay clean).
    seed : int
        Seed of the noise's ``numpy.random.default_rng``.
    record_state : callable, optional
        ``record_state(plant) -> (s,) array``, stored per sample in ``plant_states``
        (e.g. ``lambda plant: plant.state`` of a :class:`StateSpacePlant`).
    dt : float, optional
        Sampling time for the metrics' real-time factor (default the controller model's).
    progress : bool or None
        Progress line (``None``: only on a terminal).

    Returns
    -------
    ClosedLoopResult
    """
    R = np.asarray(reference, dtype=float)
    p, m, N = controller.n_outputs, controller.n_inputs, controller.horizon
    if R.ndim != 2 or R.shape[0] != p:
        raise FemromValueError(f"reference has shape {R.shape}, expected ({p}, K): one row per output")
    if not np.all(np.isfinite(R)):
        raise FemromValueError("reference has non-finite entries")
    K = R.shape[1]
    if n_steps is None:
        if K - 1 - N < 1:
            raise FemromValueError(f"the reference has {K} samples: give at least the horizon N = {N} + 2, "
                                   "or n_steps explicitly")
        n_steps = K - 1 - N
    n_steps = int(n_steps)
    if not 0 <= n_steps <= K - 1:
        raise FemromValueError(f"n_steps must be in [0, {K - 1}] for a reference of {K} samples, got {n_steps}")
    if observer.model.n_states != controller.n_states or observer.model.n_outputs != p \
            or observer.model.n_inputs != m:
        raise FemromValueError(f"observer's model has (n, m, p) = ({observer.model.n_states}, "
                               f"{observer.model.n_inputs}, {observer.model.n_outputs}), the controller's "
                               f"({controller.n_states}, {m}, {p})")
    y = vector(plant.output, p, "plant output")
    u = vector(u0, m, "u0")
    window_source = _padded(R, N)
    rng = np.random.default_rng(seed)
    n_a = observer.estimate.size
    Y, U, X = np.empty((p, n_steps + 1)), np.empty((m, n_steps + 1)), np.empty((n_a, n_steps + 1))
    states = []
    qp_seconds, solver_seconds, statuses = [], [], []
    fallbacks_before = controller.n_fallbacks
    progress_line = Progress(n_steps, label="closed loop", enabled=progress)
    try:
        for k in range(n_steps + 1):
            Y[:, k], U[:, k] = y, u
            if record_state is not None:
                states.append(np.asarray(record_state(plant), dtype=float).ravel())
            measured = y if output_noise is None else y + output_noise * rng.standard_normal(p)
            X[:, k] = observer.update(measured, u)
            if k == n_steps:
                break
            observer.predict(u)
            w_z, w_y = observer.offsets()
            u = controller.control(observer.state_estimate, window_source[:, k + 1:k + 1 + N], u,
                                   state_offset=w_z, output_offset=w_y)
            qp_seconds.append(controller.solve_seconds[-1])
            solver_seconds.append(controller.solver_seconds[-1])
            statuses.append(controller.statuses[-1])
            y = vector(plant.step(u), p, "plant output")
            progress_line.update()
    finally:
        progress_line.close()
    return ClosedLoopResult(
        outputs=Y, inputs=U, reference=R[:, :n_steps + 1].copy(), estimates=X,
        qp_seconds=np.asarray(qp_seconds), solver_seconds=np.asarray(solver_seconds),
        statuses=tuple(statuses), input_bound=controller.input_bound.copy(),
        n_fallbacks=controller.n_fallbacks - fallbacks_before,
        plant_states=np.column_stack(states) if states else None,
        dt=float(dt) if dt is not None else float(controller.model.dt))


def open_loop(plant, inputs) -> np.ndarray:
    """(p, K) outputs of ``plant`` driven by the input samples (m, K) (``inputs[:, 0]`` is the plant's ``u_0``).

    A reference the plant can follow exactly (a *feasible* reference): its response to a known input.
    """
    U = np.atleast_2d(np.asarray(inputs, dtype=float))
    y0 = np.asarray(plant.output, dtype=float).ravel()
    Y = np.empty((y0.size, U.shape[1]))
    Y[:, 0] = y0
    for k in range(1, U.shape[1]):
        Y[:, k] = plant.step(U[:, k])
    return Y


def travelling_wave(positions, times, amplitude, wavenumber: float, angular_frequency: float,
                    phase: float = 0.0) -> np.ndarray:
    r"""(p, K) ``y(x_i, t_k) = a(x_i) sin(k x_i - omega t_k + phase)``: an eel-like centreline wave.

    Parameters
    ----------
    positions : (p,) array_like
        ``x_i`` along the body (the output points).
    times : (K,) array_like
    amplitude : float, (p,) array_like or callable
        ``a(x)``: the envelope (e.g. growing towards the tail); a callable gets ``positions``.
    wavenumber, angular_frequency : float
        ``k`` (rad per unit length) and ``omega`` (rad/s): the wave travels at ``omega / k``.
    """
    x = np.asarray(positions, dtype=float).ravel()
    t = np.asarray(times, dtype=float).ravel()
    a = amplitude(x) if callable(amplitude) else amplitude
    a = np.broadcast_to(np.asarray(a, dtype=float), x.shape)
    return a[:, None] * np.sin(wavenumber * x[:, None] - angular_frequency * t[None, :] + phase)
