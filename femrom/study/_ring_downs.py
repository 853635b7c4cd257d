r"""Learned and intrusive reduced models of a small stateful reference model, compared on ring-downs.

The reference is a small :class:`~femrom.scene.SecondOrderSystem` (e.g. a modal model with a
hyper-reduced joint) at rest in a committed force state. :func:`reference_ring_down` runs it
(Newmark, average acceleration) from rest under its own inputs (a hammer blow) and keeps
``q, q', q''``, the inputs and the outputs. :func:`compare_ring_downs` then, for each ``r``:

- POD of the training runs' displacements in the mass product (``V^T M V = I``), nested in ``r``;
- data ``Q^ = V^T M Q`` with the stored derivatives projected the same way, and the inputs;
- models: ``"lopinf"`` (:class:`~femrom.inference.LagrangianOpInf`, linear: a flat backbone),
  ``"spml"`` (:class:`~femrom.inference.SpML`, a learned potential and a history-free convex
  dissipation ``F^(q')``), both predicted with the discrete-gradient scheme, the variants of
  ``settings.iwan`` (:class:`~femrom.inference.IwanLOpInf`, learned Jenkins sliders along the
  leading coordinate, stepped by Newmark with their return mapping), and ``"galerkin"``,
  the reference projected on ``V`` with its stateful force (:func:`~femrom.inference.galerkin`:
  the force keeps its law and its state on its own coordinates), stepped by Newmark from the
  reference's committed rest state; every model is a :class:`~femrom.rom.SecondOrderROM`
  predicted the same way;
- each test run predicted from rest with the test input, over the test run's duration;
  output ``output`` (an acceleration) compared in time and through its Hilbert backbones.

Every predicted time grid is the reference's ``dt``; the backbones' period error of the
trapezoidal/midpoint family is removed by the caller's ``correction`` (the same map for all).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference import IwanLOpInf, LagrangianOpInf, SecondOrderData, SpML, SpMLConfig, concatenate, galerkin
from femrom.integrators import Newmark, StepResult, Trajectory, integrate
from femrom.post import hilbert_backbone
from femrom.rom import SecondOrderROM
from femrom.study._backbone_metrics import backbone_errors

#: Columns of one comparison row.
RING_DOWN_COLUMNS = ("model", "r", "test", "frequency_shift_error", "damping_max_error", "time_domain_error",
                     "seconds_per_step", "fit_seconds", "stable")


@dataclass
class RingDown:
    """One run of a model from rest: time grid, reduced/full fields, inputs, outputs, timing."""

    label: str
    times: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    inputs: np.ndarray | None
    outputs: np.ndarray
    seconds: float
    info: dict = field(default_factory=dict)

    @property
    def dt(self) -> float:
        return float(self.times[1] - self.times[0])

    @property
    def seconds_per_step(self) -> float:
        return self.seconds / max(self.times.size - 1, 1)


def _dense(A):
    return A.toarray() if hasattr(A, "toarray") else np.asarray(A, dtype=float)


def reference_ring_down(system, rest_state, duration: float, dt: float, *, label: str = "",
                        scheme=None) -> RingDown:
    """``system`` from rest (``q = q' = q'' = 0``, force state ``rest_state``) under its own inputs, Newmark.

    The inputs must vanish at ``t = 0`` (a blow that starts there), so that rest is the initial state."""
    n = system.n_dofs
    steps = int(round(duration / dt))
    trajectory = Trajectory(fields=("q", "v", "a"))
    rest = StepResult.at_rest(n, state=rest_state)
    tic = time.perf_counter()
    summary = integrate(system, scheme or Newmark(), None, None, dt, steps, consumers=[trajectory], start=rest,
                        progress=None)
    seconds = time.perf_counter() - tic
    times = dt * np.arange(steps + 1)
    # a run from ``start`` records the steps after it: the rest state (t = 0) goes first
    rest_column = np.zeros((n, 1))
    q, v, a = (np.hstack([rest_column, np.asarray(getattr(trajectory, f)).reshape(n, -1)]) for f in ("q", "v", "a"))
    inputs = None if system.inputs is None else np.asarray(system.inputs.sampled(times))
    outputs = np.asarray(system.output_matrix @ a)
    return RingDown(label, times, q, v, a, inputs, outputs, seconds,
                    {"newton_iterations": getattr(summary, "newton_iterations", None)})


def mass_pod(mass, runs, r: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``r`` leading POD vectors of the runs' displacements in the ``mass`` product, and all singular values."""
    M = _dense(mass)
    L = np.linalg.cholesky(0.5 * (M + M.T))
    Q = np.concatenate([run.q for run in runs], axis=1)
    U, s, _ = np.linalg.svd(L.T @ Q, full_matrices=False)
    V = np.linalg.solve(L.T, U[:, :r])
    return V, s


def ring_down_data(basis, mass, runs) -> SecondOrderData:
    """Reduced data of the runs (``V^T M`` of the stored ``q, q', q''``), inputs kept, one trajectory each."""
    P = basis.T @ _dense(mass)
    return concatenate([SecondOrderData(P @ run.q, P @ run.v, P @ run.a, inputs=run.inputs, times=run.times)
                        for run in runs])


@dataclass(frozen=True)
class RingDownComparison:
    """Settings of :func:`compare_ring_downs`."""

    ranks: tuple = (1, 2, 3, 5)
    models: tuple = ("galerkin", "lopinf", "spml")
    spml: SpMLConfig = SpMLConfig()
    #: IwanLOpInf variants: (model name, ((keyword, value), ...)) pairs
    iwan: tuple = (("iwan", ()),)
    output: int = 0                        #: the output row whose backbone is compared
    band: tuple = (60.0, 100.0)            #: band-pass of the Hilbert backbone [Hz]
    window: float = 0.2                    #: its window [s]
    learned_scheme: str = "discrete_gradient"
    range_window: float | None = None      #: Hilbert window of the training runs' amplitude range (default window)
    range_trim: float | None = None        #: and its trim (default: hilbert_backbone's)


def _learner(name: str, settings: "RingDownComparison"):
    """The learner a model name stands for (``"lopinf"``, ``"spml"`` or a variant of ``settings.iwan``)."""
    if name == "spml":
        return SpML(["damping", "input"], config=settings.spml)
    variants = dict(settings.iwan)
    if name in variants:
        return IwanLOpInf(["damping", "input"], **dict(variants[name]))
    if name == "lopinf":
        return LagrangianOpInf(["damping", "input"])
    raise FemromValueError(f"unknown model {name!r}; valid: galerkin, lopinf, spml, {', '.join(variants)}")


def _stable(signal: np.ndarray) -> bool:
    """Finite, and the last tenth's peak no larger than the whole run's first tenth's (a ring-down decays)."""
    if not np.all(np.isfinite(signal)):
        return False
    k = max(signal.size // 10, 1)
    return bool(np.max(np.abs(signal[-k:])) <= np.max(np.abs(signal[:k])))


def compare_ring_downs(system, rest_state, training, validation, tests, settings: RingDownComparison = RingDownComparison(),
                       *, amplitude_range=None, correction=None, progress=print) -> dict:
    """Fit and predict every model at every ``r`` (module docstring).

    Parameters
    ----------
    system : SecondOrderSystem
        The reference (its output matrix gives the compared outputs, its inputs are replaced by each run's).
    rest_state
        Its force state at rest.
    training, validation : list of RingDown
        Runs of ``system`` to train on (POD and data) and to stop SpML's fit on.
    tests : list of (RingDown, SecondOrderSystem)
        Each test run with the reference system that made it (its inputs: the test input).
    amplitude_range : (2,) optional
        Where backbones are compared (default: the range of the training runs' own backbones).
    correction : callable, optional
        ``Backbone -> Backbone`` applied to every backbone (e.g. the period error of the scheme).

    Returns
    -------
    dict with ``rows`` (one per model, r and test: :data:`RING_DOWN_COLUMNS` and more), ``backbones``
    (``{(model, r, test): Backbone}``, the reference's under ``("reference", None, test)``), ``predictions``
    (``{(model, r, test): (p, k) outputs}``), ``singular_values``, ``basis`` (n, r_max) and ``models``
    (``{(model, r): SecondOrderROM}``, the Galerkin ones too).
    """
    correction = correction or (lambda b: b)
    E = _dense(system.output_matrix)
    M = system.mass
    r_max = max(settings.ranks)
    V_all, singular_values = mass_pod(M, training, r_max)
    data_all = ring_down_data(V_all, M, training)
    valid_all = ring_down_data(V_all, M, validation) if validation else None
    o = settings.output

    def backbone(signal, dt):
        return correction(hilbert_backbone(signal, 1.0 / dt, settings.band, window=settings.window))

    if amplitude_range is None:     # the amplitudes the training runs' own backbones span
        curves = [hilbert_backbone(run.outputs[o], 1.0 / run.dt, settings.band,
                                   window=settings.range_window or settings.window, trim=settings.range_trim)
                  for run in training]
        amplitude_range = (float(min(np.min(c.amplitude) for c in curves)),
                           float(max(np.max(c.amplitude) for c in curves)))

    backbones, predictions, rows, fitted = {}, {}, [], {}
    for run, _ in tests:
        backbones[("reference", None, run.label)] = backbone(run.outputs[o], run.dt)
    for r in settings.ranks:
        V = V_all[:, :r]
        data = data_all.truncated(r)
        valid = None if valid_all is None else valid_all.truncated(r)
        for name in settings.models:
            fit_seconds = 0.0
            if name == "galerkin":
                rom = SecondOrderROM(galerkin(system, V), V)
            else:
                learner = _learner(name, settings)
                tic = time.perf_counter()
                rom = SecondOrderROM(basis=V, learner=learner)
                rom = rom.fit(data, validation=valid)
                fit_seconds = time.perf_counter() - tic
            fitted[(name, r)] = rom
            # a stateful model (the projected joint, learned sliders) steps by Newmark with its return
            # mapping; the Galerkin model starts in the reference's committed rest state
            scheme = "newmark" if rom.operators_.stateful else settings.learned_scheme
            start = StepResult.at_rest(r, state=rest_state) if name == "galerkin" else None
            for run, reference in tests:
                tic = time.perf_counter()
                solution = rom.predict(run.times, reference.inputs, initial=start, scheme=scheme)
                seconds = time.perf_counter() - tic
                signal = E @ (V @ np.asarray(solution.a))
                seconds_per_step = seconds / max(run.times.size - 1, 1)
                key = (name, r, run.label)
                predictions[key] = signal
                reference_signal = run.outputs
                finite = bool(np.all(np.isfinite(signal)))
                error = (float(np.linalg.norm(signal[o] - reference_signal[o]) / np.linalg.norm(reference_signal[o]))
                         if finite else float("inf"))
                row = {"model": name, "r": r, "test": run.label, "time_domain_error": error,
                       "seconds_per_step": seconds_per_step, "fit_seconds": fit_seconds,
                       "stable": _stable(signal[o]), "frequency_shift_error": None, "damping_max_error": None}
                if finite:
                    try:
                        curve = backbone(signal[o], run.dt)
                        backbones[key] = curve
                        row.update(backbone_errors(curve, backbones[("reference", None, run.label)],
                                                   amplitude_range))
                    except ValueError as exc:      # a signal without the mode in the band
                        row["note"] = f"no backbone: {exc}"
                rows.append(row)
                progress(f"  {name} r={r} {run.label}: time error {error:.3g}, shift error "
                         f"{row['frequency_shift_error']}, damping error {row['damping_max_error']}, "
                         f"{1e3 * seconds_per_step:.3g} ms/step, fit {fit_seconds:.1f} s, stable {row['stable']}")
    return {"rows": rows, "backbones": backbones, "predictions": predictions,
            "singular_values": singular_values, "amplitude_range": [float(a) for a in amplitude_range],
            "basis": V_all, "models": fitted}
