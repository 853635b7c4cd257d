r"""A reduced-model study of a canonical Hamiltonian FOM: one trajectory, a training window, extrapolation.

For ``q' = dH/dp``, ``p' = -dH/dq`` (:class:`~femrom.integrators.CanonicalSystem`,
``H = q^T D_q q / 2 + p^T D_p p / 2 + H_nl(q, p)``) the steps are

1. :func:`run_canonical`: the FOM trajectory and its cost per step (timed blocks);
2. :func:`canonical_rows`: for every r a cotangent-lift basis ``Phi`` of the training
   window (:class:`~femrom.basis.CotangentLiftPSD`), reduced data with finite-difference
   derivatives and the projected known gradient, and the models of a list of
   :class:`CanonicalSpec` (each built through the learner registry): ``galerkin`` (``Phi^T D Phi``, intrusive), ``hopinf``
   (symmetric ``D^_q``, ``D^_p``; :class:`~femrom.rom.HamiltonianROM`), ``canonical_opinf``
   (an unconstrained ``A^``; :class:`~femrom.rom.FirstOrderROM`), the last two with a
   Tikhonov weight or one chosen from a grid by the training window alone;
   each is run over the whole window, scored on the training and the test window
   (state error, blow-up, drift of every named invariant and of ``H``), and all are
   timed together per step (:func:`~femrom.study.repeated_costs`);
3. :func:`canonical_time_step_ladder`: the FOM's error at a time against its cost, over
   a ladder of time steps.

Errors are relative Frobenius norms of ``[Q; P]`` over a window; a drift is
``max |I(t) - I(0)| / |I(0)|`` over a window (:func:`invariant_drift`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError
from femrom.basis import CotangentLiftPSD
from femrom.inference import HamiltonianOperators, learner_class, reduce_canonical_snapshots, registered_learners
from femrom.integrators import integrate_canonical
from femrom.rom import FirstOrderROM, HamiltonianROM
from femrom.study._metrics import invariant_drift
from femrom.study.experiments.canonical_window import CanonicalWindow, linear_operator, mass_generator, state_error, \
    window_metrics
from femrom._timing import Cost, repeated_cost, repeated_costs

#: The kinds of learned model a canonical study runs (besides the intrusive projection).
CANONICAL_KINDS = ("canonical", "first_order")


@dataclass(frozen=True)
class CanonicalSpec:
    """One reduced model of a canonical study, reported under ``label``.

    ``learner``: a registered learner, the intrusive ``galerkin`` or one of canonical or first-order
    models (:data:`CANONICAL_KINDS`: ``hopinf``, ``canonical_opinf``); ``scheme``: the ROM's integrator
    (``"midpoint"``; ``"rk4"`` for ``canonical_opinf``); ``shared``: one ``D^`` for both
    blocks (``hopinf``); ``regularization``: a relative Tikhonov weight, or a tuple of
    them from which the one whose prediction fits the training window best is chosen
    (training data only).
    """

    label: str
    learner: str
    scheme: str = "midpoint"
    shared: bool = False
    regularization: float | tuple = 0.0

    def __post_init__(self):
        cls = learner_class(self.learner)
        if not self.intrusive and cls.model not in CANONICAL_KINDS:
            valid = [name for name, c in registered_learners().items() if c.model in CANONICAL_KINDS]
            raise FemromValueError(f"learner {self.learner!r} fits {cls.model} models; a canonical study takes "
                                   f"galerkin and {', '.join(valid)}")

    @property
    def intrusive(self) -> bool:
        """Whether the learner reads the full operators (the Galerkin projection)."""
        return "system" in learner_class(self.learner).needs

    @property
    def selects(self) -> bool:
        return isinstance(self.regularization, tuple)


@dataclass(frozen=True, eq=False)
class CanonicalRun:
    """A FOM trajectory: ``times`` (k,), ``q``, ``p`` (n, k), ``hamiltonian`` (k,), Newton ``iterations``,
    the stepping ``seconds`` of this run and its :class:`~femrom.study.Cost` per step."""

    times: np.ndarray
    q: np.ndarray
    p: np.ndarray
    hamiltonian: np.ndarray
    iterations: np.ndarray
    seconds: float
    cost: Cost

    @property
    def dt(self) -> float:
        return float(self.times[1] - self.times[0])


def _canonical_block(system, q0, p0, dt, scheme):
    def block(n: int) -> float:
        return integrate_canonical(system, q0, p0, dt, n, scheme).seconds
    return block


def run_canonical(system, q0, p0, dt: float, n_steps: int, *, scheme: str = "midpoint",
                  repeats: int = 5, min_block_seconds: float = 0.1) -> CanonicalRun:
    """Integrate the FOM over ``n_steps`` and measure its cost per step by timed blocks from ``(q0, p0)``."""
    tr = integrate_canonical(system, q0, p0, dt, n_steps, scheme)
    cost = repeated_cost(_canonical_block(system, q0, p0, dt, scheme), min(n_steps, 1000), repeats=repeats,
                         min_block_seconds=min_block_seconds)
    return CanonicalRun(dt * np.arange(n_steps + 1), tr.q, tr.p, tr.hamiltonian, tr.iterations, tr.seconds, cost)


def pointwise_error(Q, P, Qr, Pr) -> np.ndarray:
    """(k,) ``||[qr - q; pr - p]|| / ||[q; p]||`` at every time."""
    num = np.sum((Qr - Q) ** 2 + (Pr - P) ** 2, axis=0)
    return np.sqrt(num / np.sum(Q * Q + P * P, axis=0))


class _Models:
    """Fits the specs' models on one basis and its data."""

    def __init__(self, system, V, data):
        self.system, self.V, self.data = system, V, data
        self.potential = system.potential
        self.galerkin = HamiltonianROM.galerkin(system, V)      # projected once per basis

    def fit(self, spec: CanonicalSpec, regularization: float):
        """The model of ``spec`` (by the registry: the projection, or the learner's kind of ROM)."""
        if spec.intrusive:
            return HamiltonianROM(self.galerkin.operators_, self.V, self.potential, scheme=spec.scheme)
        cls = learner_class(spec.learner)
        learner = cls(regularization, **({"shared": True} if spec.shared else {})).fit(self.data)
        rom_class = HamiltonianROM if cls.model == "canonical" else FirstOrderROM
        return rom_class(learner.operators_, self.V, self.potential, learner=learner, scheme=spec.scheme)


def _predict(model, y0, times):
    r = model.r
    with np.errstate(all="ignore"):
        return model.predict(times, initial=(y0[:r], y0[r:]))


def canonical_rows(system, run: CanonicalRun, specs, *, ranks, train_window: float, order: int = 4,
                   gradient_data: str = "snapshots", invariants=None, keep: int | None = None,
                   sweep: bool = False, repeats: int = 5, min_block_seconds: float = 0.1, progress=None):
    """Fit and run every spec's model at every ``r``; one row each, costs measured together.

    Parameters
    ----------
    system : CanonicalSystem
        The FOM (Galerkin's operators and the known potential).
    run : CanonicalRun
        Its trajectory; the training window is ``[0, train_window]``, the test the rest.
    specs : sequence of CanonicalSpec
    ranks : sequence of int
    order : int
        Finite-difference order of the reduced derivatives.
    gradient_data : {"snapshots", "reconstructed"}
        Where the known gradient is evaluated for the data
        (:func:`~femrom.inference.reduce_canonical_snapshots`).
    invariants : callable, optional
        ``(Q, P) -> {name: (k,)}`` of full trajectories (their drifts join the rows).
    keep : int, optional
        The r whose reconstructed trajectories are returned (with ``H``, the invariants
        and the pointwise error).
    sweep : bool
        At ``keep``, one row per weight of every selecting spec, each run over the
        whole window (without it the weights run over the training window only).

    Returns
    -------
    rows : list of dict
        ``method`` (the label), ``r``, ``integrator``, ``regularization``, errors and
        drifts (:func:`window_metrics`), ``projection_error_test``, ``mass_generator``,
        ``max_real_eigenvalue``, ``fit_seconds``, ``basis_seconds``, ``seconds_per_step``
        with its ``cost`` spread and ``speedup`` over ``run.cost`` (``nan`` for a model
        that blew up: it is not timed); an ``hopinf`` row also its ``residual``,
        ``operator_error`` against Galerkin's ``D~_q``, ``operator_asymmetry``
        ``||D^_q - D^_p|| / ||D^_p||``, ``reduced_hamiltonian_drift_test`` and the
        condition numbers of the Gram matrices.
    kept : dict
        label -> trajectories at ``r = keep``.
    sweep_rows : list of dict
    """
    dt = run.dt
    Q, P = run.q, run.p
    k_train = int(round(train_window / dt)) + 1
    train, test = slice(0, k_train), slice(k_train, None)
    times = run.times
    Qt, Pt = Q[:, train], P[:, train]
    rows, kept, sweep_rows, timed = [], {}, [], {}
    window = CanonicalWindow(system, run, train_window, invariants=invariants)   # every model's experiment
    for r in ranks:
        if progress:
            progress(f"r = {r}")
        tic = time.perf_counter()
        psd = CotangentLiftPSD(r, method="svd").fit(Qt, Pt)
        basis_seconds = time.perf_counter() - tic
        V = psd.phi_
        projection = psd.projection_error(np.vstack([Q[:, test], P[:, test]]))
        data = reduce_canonical_snapshots(V, Qt, Pt, dt, potential=system.potential, order=order,
                                          gradient_data=gradient_data)
        models = _Models(system, V, data)
        y0 = np.concatenate([V.T @ Q[:, 0], V.T @ P[:, 0]])
        galerkin = models.galerkin.operators_
        for spec in specs:
            tic = time.perf_counter()
            weight = spec.regularization
            if spec.selects:    # the weight whose prediction fits the training window best
                full = sweep and r == keep
                candidates = []
                for rho in spec.regularization:
                    model = models.fit(spec, rho)
                    sol = _predict(model, y0, times if full else times[:k_train])
                    Yt = np.vstack([sol.q[:, :k_train], sol.p[:, :k_train]])
                    train_error = state_error(Qt, Pt, V @ Yt[:r], V @ Yt[r:]) if np.all(np.isfinite(Yt)) \
                        else float("inf")
                    candidates.append((train_error, rho, model))
                    if full:
                        A = linear_operator(model)
                        sweep_rows.append({"method": spec.label, "r": r, "regularization": rho,
                                           "train_error": train_error,
                                           **window_metrics(system, Q, P, V @ sol.q, V @ sol.p, train, test, dt,
                                                            invariants),
                                           "mass_generator": mass_generator(A),
                                           "max_real_eigenvalue": float(np.max(np.linalg.eigvals(A).real))})
                _, weight, model = min(candidates, key=lambda c: c[0])
            else:
                model = models.fit(spec, weight)
            fit_seconds = time.perf_counter() - tic
            outcome = window.run(model)
            solution, Qf, Pf = outcome.pop("_solution"), outcome.pop("_Q"), outcome.pop("_P")
            metrics = {k: outcome.pop(k) for k in ("mass_generator", "max_real_eigenvalue")}
            row = {"method": spec.label, "learner": spec.label, "r": r, "integrator": spec.scheme,
                   "regularization": None if spec.intrusive else weight,
                   "basis_seconds": basis_seconds,
                   "fit_seconds": None if spec.intrusive else fit_seconds,   # a projection: no fit
                   "offline_seconds": basis_seconds + (0.0 if spec.intrusive else fit_seconds),
                   **outcome, "projection_error_test": projection, **metrics}
            if not spec.intrusive and isinstance(model.operators_, HamiltonianOperators):   # learned D^_q, D^_p
                ops, learner = model.operators_, model.learner
                Qh, Ph = data.states_q, data.states_p
                row.update(residual=learner.residual_,
                           operator_error=float(np.linalg.norm(ops.position - galerkin.position)
                                                / np.linalg.norm(galerkin.position)),
                           operator_asymmetry=float(np.linalg.norm(ops.position - ops.momentum)
                                                    / np.linalg.norm(ops.momentum)),
                           reduced_hamiltonian_drift_test=invariant_drift(solution.hamiltonian, test),
                           gram_condition_q=float(np.linalg.cond(Qh @ Qh.T)),
                           gram_condition_p=float(np.linalg.cond(Ph @ Ph.T)),
                           gram_condition_shared=float(np.linalg.cond(Qh @ Qh.T + Ph @ Ph.T)))
            if row["finite"]:
                timed[len(rows)] = model
            rows.append(row)
            if r == keep:
                with np.errstate(all="ignore"):
                    kept[spec.label] = {"Q": Qf, "P": Pf, "H": system.hamiltonian(Qf, Pf),
                                        "H_reduced": solution.hamiltonian,
                                        **({} if invariants is None else invariants(Qf, Pf)),
                                        "error": pointwise_error(Q, P, Qf, Pf)}
    _timed_costs(rows, timed, run, repeats=repeats, min_block_seconds=min_block_seconds, progress=progress)
    return rows, kept, sweep_rows


def _timed_costs(rows, models: dict, run: CanonicalRun, *, repeats, min_block_seconds, progress):
    """Seconds per step of every finite model, interleaved (:func:`repeated_costs`), from the run's start."""
    if progress:
        progress(f"timing {len(models)} reduced models ({repeats} interleaved rounds)")

    def block_of(model):
        V = model.basis
        y0 = np.concatenate([V.T @ run.q[:, 0], V.T @ run.p[:, 0]])

        def block(n: int) -> float:
            return _predict(model, y0, run.dt * np.arange(n + 1)).info["stepping_seconds"]
        return block

    n = min(run.times.size - 1, 1000)
    costs = repeated_costs({i: block_of(m) for i, m in models.items()}, n, repeats=repeats,
                           min_block_seconds=min_block_seconds)
    for i, row in enumerate(rows):
        if i not in costs:
            row.update(seconds_per_step=float("nan"), cost=None, speedup=float("nan"))
            continue
        cost = costs[i]
        row.update(seconds_per_step=cost.seconds, cost=cost.to_dict(),
                   speedup=run.cost.seconds / max(cost.seconds, 1e-15))


def canonical_time_step_ladder(system, q0, p0, dt: float, t_end: float, factors=(4, 2, 1),
                               reference_divisor: int = 4, *, scheme: str = "midpoint",
                               repeats: int = 3, min_block_seconds: float = 0.1) -> list[dict]:
    """The FOM's state error at ``t_end`` (against a run at ``dt / reference_divisor``) against its cost.

    One row per ``dt * factor``: ``error_at_end``, ``seconds_per_step`` (timed blocks),
    ``stepping_seconds`` (that cost times the steps), mean Newton iterations, and the
    ``observed_order`` fitted over the ladder (``polyfit`` of log error on log dt).
    """
    ref_dt = dt / reference_divisor
    ref = integrate_canonical(system, q0, p0, ref_dt, int(round(t_end / ref_dt)), scheme)
    yref = np.concatenate([ref.q[:, -1], ref.p[:, -1]])
    rows = []
    for factor in factors:
        h = factor * dt
        steps = int(round(t_end / h))
        tr = integrate_canonical(system, q0, p0, h, steps, scheme)
        y = np.concatenate([tr.q[:, -1], tr.p[:, -1]])
        cost = repeated_cost(_canonical_block(system, q0, p0, h, scheme), min(steps, 1000), repeats=repeats,
                             min_block_seconds=min_block_seconds)
        rows.append({"dt": h, "steps": steps, "error_at_end": float(np.linalg.norm(y - yref) / np.linalg.norm(yref)),
                     "seconds_per_step": cost.seconds, "stepping_seconds": cost.seconds * steps,
                     "cost": cost.to_dict(), "newton_iterations_mean": float(tr.iterations.mean())})
    order = float(np.polyfit(np.log([r["dt"] for r in rows]), np.log([r["error_at_end"] for r in rows]), 1)[0])
    for r in rows:
        r["observed_order"] = order
    return rows
