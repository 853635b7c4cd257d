r"""A reduced-model study of one built model: FOM runs -> store -> POD -> fitted ROMs -> tests.

The steps, each a function usable on its own:

1. :func:`fom_runs`: every training and test run of a :class:`~femrom.scene.RomConfig`,
   fields streamed into one snapshot store (one factorisation for all runs of one ``dt``);
2. :func:`pod_basis`: a POD basis of the training displacements, orthonormal in the mass
   (or Euclidean) product, by the out-of-core randomized SVD reading the store;
3. :func:`reduce_runs`: one pass per run over the store: the training data in the
   largest basis, every run's :class:`Projection` (for exact field errors at every r);
4. :meth:`ModelSpec.fit`: the ROM of one registered learner at one r, from the study's
   :class:`~femrom.inference.TrainingSet` (:func:`training_set`; ``galerkin`` reads the
   full operators, every other learner the reduced data only; a canonical learner on a
   conservative scene: :mod:`femrom.study._canonical`);
5. :func:`evaluate`: output error, field error, energy over an extended window, and
   :func:`rom_costs`: the ROMs' seconds per step by interleaved repetition.

:func:`study_rows` runs 4 and 5 over ranks and learners; every row has
``r``, ``learner`` (the label), ``fit_seconds``, per run ``errors[run]``, and the
first training and test run's errors flattened as ``train_*`` / ``test_*``.
"""

from __future__ import annotations

import inspect
from dataclasses import replace

import numpy as np

from femrom._errors import FemromValueError
from femrom.basis import POD
from femrom.inference import HamiltonianOperators, TrainingSet, learner_class, reduce_snapshots, registered_learners
from femrom.linalg import store_source
from femrom.scene import RomConfig, SceneError
from femrom.study._canonical import canonical_operator_checks
from femrom.study._experiment import EXPERIMENTS, registered_experiments
from femrom.study._models import ModelSpec
from femrom.study._metrics import Projection, project_run
from femrom.study.experiments.unseen_input import BLOWUP, Evaluation, UnseenInput
from femrom.snapshots import FOMRun, run_fom, solver_factory
from femrom._timing import Cost, repeated_costs

#: the kinds of model a scene's ``[rom]`` study predicts from a full initial state
STUDY_KINDS = ("second_order", "canonical")


def check_rom_config(config: RomConfig) -> None:
    """Learner and experiment names against their registries (one SceneError naming the culprit), before
    anything is built: every registered learner of second-order or canonical models may be named."""
    known = registered_learners()
    valid = [name for name, cls in known.items() if cls.model in STUDY_KINDS]
    for i, spec in enumerate(config.learners):
        if spec.learner not in known:
            raise SceneError(f"[rom.learners[{i}]] unknown learner {spec.learner!r}; valid: {', '.join(valid)}")
        if spec.learner not in valid:
            raise SceneError(f"[rom.learners[{i}]] {spec.learner!r} fits {known[spec.learner].model} models, "
                             f"not second-order or canonical ones; the [rom] pipeline takes: {', '.join(valid)}")
        keywords = _keywords(known[spec.learner])
        if spec.terms and "extra_terms" not in keywords:
            raise SceneError(f"[rom.learners[{i}]] {spec.learner!r} learns no terms beyond its own: remove 'terms'")
        unknown = [name for name, _ in spec.options if name not in keywords]
        if unknown:
            raise SceneError(f"[rom.learners[{i}]] {spec.learner!r} has no option {unknown[0]!r}; valid: "
                             f"{', '.join(sorted(keywords))}")
    experiments = registered_experiments()
    for i, spec in enumerate(config.experiments):
        if spec.kind not in experiments:
            raise SceneError(f"[rom.experiments[{i}]] unknown experiment {spec.kind!r}; "
                             f"registered: {', '.join(experiments)}")


def _keywords(cls) -> set[str]:
    """The keyword options a learner class takes (its constructor's and its ``for_training``'s)."""
    names = set()
    for function in (cls.__init__, cls.for_training):
        names |= {p.name for p in inspect.signature(function).parameters.values()
                  if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and p.name not in ("self", "cls", "training", "r")}
    return names


def needs_stored_derivatives(config: RomConfig) -> bool:
    """Whether any learner of ``config`` reads reduced data from the runs' stored ``q'``, ``q''``
    (else only ``q`` is stored)."""
    return any(spec.derivatives.kind == "stored" and "reduced_data" in learner_class(spec.learner).needs
               for spec in config.learners)


def study_experiments_of(state, config: RomConfig) -> list:
    """The experiments of ``[[rom.experiments]]``, each built by its class from the study's state
    (:meth:`~femrom.study.Experiment.for_study`)."""
    return [experiment for spec in config.experiments
            for experiment in EXPERIMENTS.get(spec.kind).for_study(state, **dict(spec.options))]


def model_spec(spec) -> ModelSpec:
    """The :class:`ModelSpec` of a ``[rom]`` learner entry (a :class:`~femrom.scene.LearnerSpec`): its
    options, its regularisation when set, its ``terms`` as terms beyond the scene's effects."""
    options = dict(spec.options)
    keywords = _keywords(learner_class(spec.learner))
    if spec.regularization and "regularization" in keywords:    # the section's default: for learners that regularise
        options.setdefault("regularization", spec.regularization)
    if spec.terms:
        options.setdefault("extra_terms", spec.terms)
    return ModelSpec(spec.learner, spec.label, tuple(options.items()), spec.derivatives)


def product_matrix(system, config: RomConfig):
    """``W`` of the basis: the mass matrix, or ``None`` (Euclidean)."""
    return system.mass if config.basis.product == "mass" else None


def fom_runs(model, config: RomConfig, store, *, progress=None) -> dict[str, FOMRun]:
    """Every run of ``config`` (training first), fields streamed into ``store``.

    Runs with the scene's ``dt`` share one factorisation of the effective matrix;
    the factor is freed at the end.
    """
    solver = solver_factory(model)
    runs = {}
    specs = (*config.train, *config.test)
    for k, spec in enumerate(specs):
        if progress:
            progress(f"FOM run {k + 1}/{len(specs)}: {spec.name}")
        runs[spec.name] = run_fom(model, spec.signals, name=spec.name, store=store, t_end=spec.t_end,
                                  solver=solver, min_block_seconds=config.timing.min_block_seconds,
                                  every=config.snapshot_every)
    runs_cache = {"hits": solver.cache.hits, "misses": solver.cache.misses}
    solver.cache.clear()  # free the factor before the SVD
    for run in runs.values():
        run.summary["solver_cache"] = runs_cache
    return runs


def pod_basis(store, trajectories, product, config: RomConfig) -> POD:
    """POD of the displacements of ``trajectories``, ``max(ranks)`` columns, read from the store.

    ``randomized``: ``power_iterations + 2`` passes over the store (with 2 the
    leading singular values of fast-decaying spectra are exact to about 1e-11,
    docs/benchmarks_snapshots.md); ``svd``: the columns in memory, exact.
    """
    spec = config.basis
    rank = max(spec.ranks)
    source = store_source(store, "q", list(trajectories))
    if spec.method == "svd":
        Q = np.hstack([block for block in source.blocks()])
        if rank > min(Q.shape):
            raise FemromValueError(f"[rom.basis] rank {rank} exceeds the {min(Q.shape)} snapshots' rank bound")
        return POD(rank=rank, product=product, method="svd").fit(Q)
    return POD(rank=rank, product=product, method="randomized", power_iterations=spec.power_iterations).fit(source)


def projected_forces(nonlinear, basis: np.ndarray, source) -> np.ndarray:
    """(R, K) ndarray ``V^T f_nl(q_j)`` of every stored displacement ``q_j`` (one pass, block by block).

    The learning target of a known stateless force from the full snapshots (the
    seed's formulation), not from their projection ``V^T f(V q^)``.
    """
    from femrom.linalg import as_block_source

    parts = [basis.T @ np.column_stack([nonlinear.force(q) for q in block.T])
             for block in as_block_source(source).blocks()]
    return np.hstack(parts)


def reduce_runs(store, runs: dict[str, FOMRun], train: tuple[str, ...], basis: np.ndarray, product,
                *, stored_derivatives: bool, order: int = 4, nonlinear=None):
    """The training data in the largest basis, and every run's :class:`Projection` (one pass each;
    a training run's comes with its data).

    Training data carry the run's stored integrator derivatives when the store has
    them (``stored_derivatives``), else finite differences of ``order`` (a learner
    may ask for another order: :meth:`~femrom.inference.TrainingSet.reduced`). With a stateless known
    ``nonlinear`` force, the training data carry its projection at the stored
    displacements (:func:`projected_forces`; a stateful force is evaluated by its
    reduced term along each trajectory instead).
    """
    data, projections = {}, {}
    for name, run in runs.items():
        q = store_source(store, "q", [name])
        if name not in train:
            projections[name] = project_run(basis, q, product)
        else:
            d = reduce_snapshots(
                basis, q, run.dt, product=product,
                velocities=store_source(store, "v", [name]) if stored_derivatives else None,
                accelerations=store_source(store, "a", [name]) if stored_derivatives else None,
                derivatives="stored" if stored_derivatives else "finite_difference", order=order,
                inputs=run.U, outputs=run.outputs, t0=float(run.times[0]))
            if nonlinear is not None and not nonlinear.stateful:
                d = replace(d, nonlinear_forces=projected_forces(nonlinear, basis, q))
            data[name] = d
            projections[name] = Projection(d.states, d.diagnostics["column_residual2"],
                                           d.diagnostics["column_norm2"])
    return data, projections


def training_set(system, basis: np.ndarray, product, data: dict) -> TrainingSet:
    """What every learner of the study fits on: the training runs' data in the largest basis."""
    return TrainingSet(system, basis, data, product=product)


def interval_cost(run: FOMRun) -> Cost:
    """The FOM's cost per snapshot interval of ``run`` (``every`` FOM steps): what a ROM step replaces."""
    return run.cost.scaled(run.every)


def rom_costs(roms: dict, run: FOMRun, *, repeats: int = 5, min_block_seconds: float = 0.1) -> dict:
    """Seconds per reduced step of every ROM of ``roms`` on ``run``'s input, by interleaved repetition
    (:func:`~femrom.study.repeated_costs`).

    Each block integrates a ROM in slices of ``N`` steps of the run's ``dt`` (as many
    as make ``min_block_seconds`` together), from the run's initial state with its
    inputs, and counts only the stepping (not the set-up of the step map, the
    inputs, or the output buffer).
    """
    def block_of(rom):
        def block(n: int) -> float:
            times = run.times[0] + run.dt * np.arange(n + 1)
            with np.errstate(all="ignore"):
                solution = rom.predict(times, run.inputs.sampled(times), initial=(run.q0, run.v0))
            return solution.info["stepping_seconds"]
        return block

    # the calibration (sizing the blocks) needs a rough step cost only: at most 1000 steps
    return repeated_costs({key: block_of(rom) for key, rom in roms.items()}, min(run.times.size - 1, 1000),
                          repeats=repeats, min_block_seconds=min_block_seconds)


def rom_cost(rom, run: FOMRun, **options) -> Cost:
    """:func:`rom_costs` of one ROM."""
    return rom_costs({0: rom}, run, **options)[0]


def operator_checks(rom) -> dict:
    """Structure of a learned model: symmetry and smallest eigenvalues of ``K^`` and ``C^`` (of a
    canonical one: ``D^_q`` and the distance of ``D^_p`` from ``I``)."""
    ops = rom.operators_
    if isinstance(ops, HamiltonianOperators):
        return canonical_operator_checks(ops)
    K = ops.stiffness
    out = {"stiffness_min_eig": float(np.min(np.linalg.eigvalsh(0.5 * (K + K.T)))),
           "stiffness_symmetric": bool(np.array_equal(K, K.T))}
    if ops.damping is not None:
        C = ops.damping
        out["damping_min_eig"] = float(np.min(np.linalg.eigvalsh(0.5 * (C + C.T))))
    return out


def study_experiments(runs: dict[str, FOMRun], projections: dict, config: RomConfig) -> list:
    """The study's own experiments: every run (training ones too) as an :class:`UnseenInput`, over
    ``config.extension`` times its window, scored after its ``score_after``."""
    score_after = {spec.name: spec.score_after for spec in (*config.train, *config.test)}
    return [UnseenInput(run, projections[name], extension=config.extension, score_after=score_after.get(name))
            for name, run in runs.items()]


def study_rows(system, basis: np.ndarray, product, data: dict, projections: dict, runs: dict[str, FOMRun],
               config: RomConfig, *, learners=None, experiments=(), progress=None) -> tuple[list[dict], dict]:
    """One row per (r, learner): fit on the training data (:meth:`ModelSpec.fit` of every learner of the
    ``[rom]`` section), put through every experiment, cost on the first test (all models timed together,
    interleaved: :func:`study_costs`).

    The experiments are the study's own (:func:`study_experiments`: errors per run under
    ``errors[run]``) and ``experiments`` (more :class:`Experiment` objects, e.g. of
    ``[[rom.experiments]]``: their metrics under ``experiments[label]``). A ROM whose prediction fails (a
    nonlinear model's Newton iteration) gets a ``failed`` message, infinite errors and no cost, and the
    study goes on. Returns the rows and the evaluations by ``(r, label, run)``. ``learners``
    (specs) defaults to the config's. Speedups are the FOM's cost per step per
    snapshot interval (from its longest run, the first of equal ones; :func:`interval_cost`) over the ROM's, both minima over timed blocks measured
    in this process.
    """
    learners = config.learners if learners is None else learners
    training = training_set(system, basis, product, data)
    own = study_experiments(runs, projections, config)
    train = [s.name for s in config.train if s.name in data]
    test = [s.name for s in config.test]
    rows, evaluations = [], {}
    for r in config.basis.ranks:
        for spec in learners:
            if progress:
                progress(f"r = {r}: {spec.label}")
            model = model_spec(spec)
            rom = model.fit(training, r)
            row = {"r": r, "learner": spec.label, "method": spec.learner,
                   "derivatives": "-" if model.intrusive else spec.derivatives.tag,
                   "train": train[0], "fit_seconds": rom.fit_seconds_, "errors": {}}
            for experiment in own:
                try:
                    outcome = experiment.run(rom)
                except (RuntimeError, np.linalg.LinAlgError) as exc:   # a nonlinear ROM's Newton failed
                    row["failed"] = f"{experiment.label}: {exc}"
                    row["errors"][experiment.label] = dict.fromkeys(Evaluation.ERRORS, float("inf"))
                    continue
                evaluations[(r, spec.label, experiment.label)] = outcome["_evaluation"]
                row["errors"][experiment.label] = public(outcome)
            for experiment in experiments:
                try:
                    outcome = public(experiment.run(rom))
                except (RuntimeError, np.linalg.LinAlgError) as exc:
                    row.setdefault("failed", f"{experiment.label}: {exc}")
                    outcome = {"failed": str(exc)}
                row.setdefault("experiments", {})[experiment.label] = outcome
            for role, names in (("train", train), ("test", test)):
                if names:
                    for key, value in row["errors"][names[0]].items():
                        row[f"{role}_{key}"] = value
            blown = {name: e["blowup_time"] for name, e in row["errors"].items() if e.get("blowup_time") is not None}
            if blown:      # when, and why: not only a large number in the error columns
                row["diverged"] = "; ".join(f"{name} at t = {t:.4g} s (energy non-finite or above {BLOWUP:g} "
                                            "x its scale)" for name, t in blown.items())
            if not model.intrusive:
                row.update(operator_checks(rom))
            row["_rom"] = rom
            rows.append(row)
    if progress:
        progress(f"timing {len(rows)} reduced models ({config.timing.repeats} interleaved rounds)")
    costs = study_costs({i: row["_rom"] for i, row in enumerate(rows) if "failed" not in row}, runs, config)
    for i, row in enumerate(rows):      # a ROM that fails cannot be timed
        row.update(costs.get(i, {"seconds_per_step": float("nan"), "cost": None, "speedup": float("nan")}))
    return rows, evaluations


def public(outcome: dict) -> dict:
    """An experiment's metrics without its arrays and objects (keys starting with ``_``)."""
    return {key: value for key, value in outcome.items() if not key.startswith("_")}


def study_costs(roms: dict, runs: dict[str, FOMRun], config: RomConfig) -> dict:
    """The cost columns of a study's rows for ROMs timed together: :func:`rom_costs` (interleaved)
    on the first test run, with the config's ``[rom.timing]``.

    Returns, per key of ``roms``: ``seconds_per_step`` (the fastest block), ``cost``
    (:class:`Cost` as a dict, with its spread), ``speedup`` (the FOM's cost per snapshot
    interval of its longest run, :func:`interval_cost`, over the ROM's) and ``speedup_range``
    (FOM minimum over ROM upper quartile, FOM upper quartile over ROM minimum).
    """
    fom_cost = interval_cost(max(runs.values(), key=lambda run: run.times.size))   # the most steps: the most blocks
    costs = rom_costs(roms, runs[config.test[0].name], repeats=config.timing.repeats,
                      min_block_seconds=config.timing.min_block_seconds)
    return {key: {"seconds_per_step": cost.seconds, "cost": cost.to_dict(),
                  "speedup": fom_cost.seconds / max(cost.seconds, 1e-15),
                  "speedup_range": [fom_cost.minimum / max(cost.q75, 1e-15), fom_cost.q75 / max(cost.minimum, 1e-15)]}
            for key, cost in costs.items()}
