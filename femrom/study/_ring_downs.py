r"""Learned and intrusive reduced models of a small stateful reference model, compared on ring-downs.

The reference is a small :class:`~femrom.scene.SecondOrderSystem` (e.g. a modal model with a
hyper-reduced joint) at rest in a committed force state. :func:`reference_ring_down` runs it
(Newmark, average acceleration) from rest under its own inputs (a hammer blow) and keeps
``q, q', q''``, the inputs and the outputs. :func:`compare_ring_downs` then, for each ``r``:

- POD of the training runs' displacements in the mass product (``V^T M V = I``), nested in ``r``;
- data ``Q^ = V^T M Q`` with the stored derivatives projected the same way, and the inputs;
- models: the :class:`~femrom.study.ModelSpec` of ``settings.models``, any registered learner
  (by default ``galerkin``, ``lopinf`` and ``spml`` on damping and input terms; the jointed-beam
  study adds ``iwan_lopinf`` variants), fitted by the comparison engine from one
  :class:`~femrom.inference.TrainingSet`; ``galerkin`` is the reference projected on ``V`` with
  its stateful force (:func:`~femrom.inference.galerkin`: the force keeps its law and its state
  on its own coordinates) and starts in the reference's committed rest state; models with a
  stateful force step by Newmark with its return mapping, the others by ``learned_scheme``;
- each test run predicted from rest with the test input, over the test run's duration;
  output ``output`` (an acceleration) compared in time and through its Hilbert backbones.

Every predicted time grid is the reference's ``dt``; the backbones' period error of the
trapezoidal/midpoint family is removed by the caller's ``correction`` (the same map for all).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from femrom.inference import SecondOrderData, SpMLConfig, TrainingSet, concatenate
from femrom.integrators import Newmark, StepResult, Trajectory, integrate
from femrom.post import hilbert_backbone
from femrom.study._compare import compare_models
from femrom.study._experiment import dense
from femrom.study._models import ModelSpec
from femrom.study.experiments.ring_down import RingDownTest

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
    M = dense(mass)
    L = np.linalg.cholesky(0.5 * (M + M.T))
    Q = np.concatenate([run.q for run in runs], axis=1)
    U, s, _ = np.linalg.svd(L.T @ Q, full_matrices=False)
    V = np.linalg.solve(L.T, U[:, :r])
    return V, s


def ring_down_data(basis, mass, runs) -> SecondOrderData:
    """Reduced data of the runs (``V^T M`` of the stored ``q, q', q''``), inputs kept, one trajectory each."""
    P = basis.T @ dense(mass)
    return concatenate([SecondOrderData(P @ run.q, P @ run.v, P @ run.a, inputs=run.inputs, times=run.times)
                        for run in runs])


def _default_models() -> tuple:
    linear = {"terms": ("damping", "input")}
    return (ModelSpec("galerkin"), ModelSpec("lopinf", options=linear),
            ModelSpec("spml", options={**linear, "config": SpMLConfig()}))


@dataclass(frozen=True)
class RingDownComparison:
    """Settings of :func:`compare_ring_downs`: the models (:class:`~femrom.study.ModelSpec`, any
    registered learner with its options) and the ring-down experiment's settings."""

    ranks: tuple = (1, 2, 3, 5)
    models: tuple = field(default_factory=_default_models)
    output: int = 0                        #: the output row whose backbone is compared
    band: tuple = (60.0, 100.0)            #: band-pass of the Hilbert backbone [Hz]
    window: float = 0.2                    #: its window [s]
    learned_scheme: str = "discrete_gradient"   #: the scheme of models without a stateful force
    stateful_scheme: str = "newmark"       #: and of models with one (a return mapping)
    range_window: float | None = None      #: Hilbert window of the training runs' amplitude range (default window)
    range_trim: float | None = None        #: and its trim (default: hilbert_backbone's)


def compare_ring_downs(system, rest_state, training, validation, tests, settings: RingDownComparison = RingDownComparison(),
                       *, amplitude_range=None, correction=None, progress=print) -> dict:
    """Fit and predict every model at every ``r`` (module docstring), on the comparison engine
    (:func:`~femrom.study.compare_models`: each :class:`~femrom.study.ModelSpec` of ``settings.models``
    through a :class:`~femrom.study.RingDownTest` per test run).

    Parameters
    ----------
    system : SecondOrderSystem
        The reference (its output matrix gives the compared outputs, its inputs are replaced by each run's).
    rest_state
        Its force state at rest.
    training, validation : list of RingDown
        Runs of ``system`` to train on (POD and data) and for learners that choose to judge on.
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
    M = system.mass
    V_all, singular_values = mass_pod(M, training, max(settings.ranks))
    data = TrainingSet(system, V_all, {run.label: ring_down_data(V_all, M, [run]) for run in training},
                       validation={run.label: ring_down_data(V_all, M, [run]) for run in validation} or None)
    if amplitude_range is None:     # the amplitudes the training runs' own backbones span
        curves = [hilbert_backbone(run.outputs[settings.output], 1.0 / run.dt, settings.band,
                                   window=settings.range_window or settings.window, trim=settings.range_trim)
                  for run in training]
        amplitude_range = (float(min(np.min(c.amplitude) for c in curves)),
                           float(max(np.max(c.amplitude) for c in curves)))
    experiments = [RingDownTest(run, reference.inputs, system.output_matrix, amplitude_range, band=settings.band,
                                window=settings.window, output=settings.output, correction=correction,
                                rest_state=rest_state, scheme=settings.learned_scheme,
                                stateful_scheme=settings.stateful_scheme) for run, reference in tests]

    def describe(row):
        return (f"  {row['model']} r={row['r']} {row['experiment']}: time error {row['time_domain_error']:.3g}, "
                f"shift error {row['frequency_shift_error']}, damping error {row['damping_max_error']}, "
                f"{1e3 * row['seconds_per_step']:.3g} ms/step, fit {row['fit_seconds']:.1f} s, stable {row['stable']}")

    rows, outcomes = compare_models(settings.models, data, settings.ranks, experiments, progress=progress,
                                    describe=describe)
    for row in rows:
        row["test"] = row.pop("experiment")
    backbones = {("reference", None, e.label): e.reference_backbone for e in experiments}
    backbones.update({key: outcome["_backbone"] for key, outcome in outcomes["runs"].items() if "_backbone" in outcome})
    return {"rows": rows, "backbones": backbones,
            "predictions": {key: outcome["_signal"] for key, outcome in outcomes["runs"].items()},
            "singular_values": singular_values, "amplitude_range": [float(a) for a in amplitude_range],
            "basis": V_all, "models": outcomes["models"]}
