r"""A reduced-model study of one built model: FOM runs -> store -> POD -> fitted ROMs -> tests.

The steps, each a function usable on its own:

1. :func:`fom_runs`: every training and test run of a :class:`~femrom.scene.RomConfig`,
   fields streamed into one snapshot store (one factorisation for all runs of one ``dt``);
2. :func:`pod_basis`: a POD basis of the training displacements, orthonormal in the mass
   (or Euclidean) product, by the out-of-core randomized SVD reading the store;
3. :func:`reduce_runs`: one pass per run over the store: the training data in the
   largest basis, every run's :class:`Projection` (for exact field errors at every r);
4. :func:`fit_rom`: the ROM of one learner at one r (``galerkin``: the intrusive
   projection; any registered second-order learner, or canonical one on a conservative
   scene (:mod:`femrom.study._canonical`): from reduced data only);
5. :func:`evaluate`: output error, field error, energy over an extended window, and
   :func:`rom_costs`: the ROMs' seconds per step by interleaved repetition.

:func:`study_rows` runs 4 and 5 over ranks and learners; every row has
``r``, ``learner`` (the label), ``fit_seconds``, per run ``errors[run]``, and the
first training and test run's errors flattened as ``train_*`` / ``test_*``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields, replace

import numpy as np

from femrom._errors import FemromValueError
from femrom.basis import POD
from femrom.inference import HamiltonianOperators, SecondOrderLearner, concatenate, learner_class, \
    reduce_snapshots, registered_learners
from femrom.linalg import store_source
from femrom.rom import SecondOrderROM
from femrom.scene import RomConfig, SceneError
from femrom.study._canonical import canonical_operator_checks, fit_canonical_rom, is_canonical
from femrom.study._metrics import Projection, energy_ratio, project_run, relative_error
from femrom.snapshots import FOMRun, run_fom, solver_factory
from femrom._timing import Cost, repeated_costs

GALERKIN = "galerkin"
#: a ROM has blown up once its energy exceeds this multiple of its initial energy
BLOWUP = 1e6


def study_learners() -> tuple[str, ...]:
    """The names a ``[rom]`` section may use: ``galerkin``, every registered second-order learner (a
    :class:`SecondOrderLearner`, or any learner of second-order models with ``for_system``, as
    :class:`~femrom.inference.SpML`) and every canonical one (``hopinf``: conservative scenes
    without inputs, :mod:`femrom.study._canonical`)."""
    return (GALERKIN, *(name for name, cls in registered_learners().items()
                        if name != GALERKIN and (issubclass(cls, SecondOrderLearner) or is_canonical(name)
                                                 or (cls.model == "second_order" and hasattr(cls, "for_system")))))


def check_rom_config(config: RomConfig) -> None:
    """Learner names against the registry (one SceneError naming the culprit), before anything is built."""
    valid = study_learners()
    for i, spec in enumerate(config.learners):
        if spec.learner in valid:
            continue
        known = registered_learners()
        if spec.learner in known:
            raise SceneError(f"[rom.learners[{i}]] {spec.learner!r} fits {known[spec.learner].model} models, "
                             f"not second-order or canonical ones; the [rom] pipeline takes: {', '.join(valid)}")
        raise SceneError(f"[rom.learners[{i}]] unknown learner {spec.learner!r}; valid: {', '.join(valid)}")


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
    may ask for another order: :func:`training_data`). With a stateless known
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


def training_data(data: dict, r: int, derivatives):
    """The first ``r`` coordinates of every training run's data, with the learner's derivatives, concatenated."""
    parts = []
    for d in data.values():
        d = d.truncated(r)
        if derivatives.kind == "integrator":
            d = d.integrator_consistent()
        elif derivatives.kind == "finite_differences" and (
                d.diagnostics.get("derivative_source") != "finite_difference"
                or d.diagnostics.get("order") != derivatives.order):
            d = d.with_finite_differences(derivatives.order)
        parts.append(d)
    return concatenate(parts)


def fit_rom(system, basis: np.ndarray, product, r: int, spec, data: dict) -> SecondOrderROM:
    """The ROM of ``spec`` (a :class:`~femrom.scene.LearnerSpec`) in the first ``r`` basis columns.

    ``galerkin`` projects the FOM's operators (intrusive). A learner sees only the
    reduced data; its terms are those of the system's effects
    (:meth:`~femrom.inference.SecondOrderLearner.for_system`) and the spec's ``terms``.
    """
    V = basis[:, :r]
    if is_canonical(spec.learner):
        return fit_canonical_rom(system, basis, product, r, spec, training_data(data, r, spec.derivatives))
    if spec.learner == GALERKIN:
        return SecondOrderROM.galerkin(system, V, product=product, mass_orthonormal=product is system.mass)
    cls = learner_class(spec.learner)
    learner = cls.for_system(system, basis=V, regularization=spec.regularization)
    if spec.terms:   # terms the structure does not have, learned all the same (e.g. damping of an undamped beam)
        known = [t.name for t in (*learner.learned_terms, *learner.known_terms)]
        learner = cls([*learner.learned_terms, *learner.known_terms, *(t for t in spec.terms if t not in known)],
                      regularization=spec.regularization)
    return SecondOrderROM(basis=V, product=product, learner=learner).fit(training_data(data, r, spec.derivatives))


@dataclass(frozen=True, eq=False)
class Evaluation:
    """A ROM on one run: errors, its solution on the run's grid, its energy over the extended window."""

    output_error: float
    field_error: float
    projection_error: float
    energy_ratio: float
    energy_final_ratio: float
    energy_growth: float
    blowup_time: float | None
    solution: object
    long_times: np.ndarray
    long_energy: np.ndarray

    ERRORS = ("output_error", "field_error", "projection_error", "energy_ratio", "energy_final_ratio",
              "energy_growth", "blowup_time")

    def errors(self) -> dict:
        return {"output_error": self.output_error, "field_error": self.field_error,
                "projection_error": self.projection_error, "energy_ratio": self.energy_ratio,
                "energy_final_ratio": self.energy_final_ratio, "energy_growth": self.energy_growth,
                "blowup_time": self.blowup_time}


def _first_steps(solution, k: int):
    """The first ``k`` time steps of a reduced solution (its arrays sliced, the rest shared)."""
    if solution.t.size == k:
        return solution
    head = {f.name: getattr(solution, f.name)[..., :k] for f in fields(solution)
            if isinstance(getattr(solution, f.name), np.ndarray) and f.name != "basis"}
    return replace(solution, **head)


def scored_columns(run: FOMRun, score_after: float | None) -> slice:
    """The columns of ``run`` its errors are scored over: all, or the steps after ``score_after``."""
    if score_after is None:
        return slice(None)
    return slice(int(np.searchsorted(run.times, score_after * (1 + 1e-12), side="right")), None)


def evaluate(rom, run: FOMRun, projection: Projection, *, extension: float,
             score_after: float | None = None) -> Evaluation:
    """Errors of ``rom`` on ``run`` and its reduced energy over ``extension`` times the run's window.

    The ROM runs over the whole window from the run's initial state; its output and
    field errors (and the projection error of its basis, the floor of the field error)
    are scored over the steps after ``score_after`` (all steps by
    default; a training window's end for a test of extrapolation in time). A ROM
    that blows up (plain OpInf can) gets infinite errors; the overflow on the way is
    expected and not reported as a warning. ``energy_growth`` is the ROM's largest
    energy over its initial one on the run's window, ``blowup_time`` the first time it
    exceeds :data:`BLOWUP` times that (``None``: never).
    """
    times = run.times
    columns = scored_columns(run, score_after)
    long_times = times[0] + run.dt * np.arange(int(round(extension * (times.size - 1))) + 1)
    with np.errstate(all="ignore"):
        # one integration over the extended window; the run's window is its first steps
        long = rom.predict(long_times, run.inputs.sampled(long_times), initial=(run.q0, run.v0))
        solution = _first_steps(long, times.size)
        output_error = float("nan") if run.outputs is None else relative_error(
            run.outputs[:, columns], solution.outputs[:, columns])
        ratio, final = energy_ratio(long.energy, run.energy)
        energy = solution.energy
        growth = float(np.nanmax(np.abs(energy)) / abs(energy[0])) if energy[0] else float("nan")
        big = ~np.isfinite(energy) | (np.abs(energy) > BLOWUP * abs(energy[0]))
        return Evaluation(output_error, projection.field_error(solution.q, columns),
                          projection.projection_error(rom.r, columns), ratio, final, growth,
                          float(times[np.argmax(big)]) if big.any() else None, solution, long_times, long.energy)


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


def study_rows(system, basis: np.ndarray, product, data: dict, projections: dict, runs: dict[str, FOMRun],
               config: RomConfig, *, learners=None, progress=None) -> tuple[list[dict], dict]:
    """One row per (r, learner): fit on the training data, evaluate on every run, cost on the first test
    (all models timed together, interleaved: :func:`study_costs`).

    A ROM whose prediction fails (a nonlinear model's Newton iteration) gets a
    ``failed`` message, infinite errors and no cost, and the study goes on.
    Returns the rows and the evaluations by ``(r, label, run)``. ``learners``
    (specs) defaults to the config's. Speedups are the FOM's cost per step per
    snapshot interval (from its longest run, the first of equal ones; :func:`interval_cost`) over the ROM's, both minima over timed blocks measured
    in this process.
    """
    learners = config.learners if learners is None else learners
    train = [s.name for s in config.train if s.name in data]
    test = [s.name for s in config.test]
    score_after = {spec.name: spec.score_after for spec in (*config.train, *config.test)}
    rows, evaluations = [], {}
    for r in config.basis.ranks:
        for spec in learners:
            if progress:
                progress(f"r = {r}: {spec.label}")
            tic = time.perf_counter()
            rom = fit_rom(system, basis, product, r, spec, data)
            row = {"r": r, "learner": spec.label, "method": spec.learner,
                   "derivatives": spec.derivatives.tag if spec.learner != GALERKIN else "-",
                   "train": train[0], "fit_seconds": time.perf_counter() - tic, "errors": {}}
            for name, run in runs.items():
                try:
                    ev = evaluate(rom, run, projections[name], extension=config.extension,
                                  score_after=score_after.get(name))
                except (RuntimeError, np.linalg.LinAlgError) as exc:   # a nonlinear ROM's Newton failed
                    row["failed"] = f"{name}: {exc}"
                    row["errors"][name] = dict.fromkeys(Evaluation.ERRORS, float("inf"))
                    continue
                evaluations[(r, spec.label, name)] = ev
                row["errors"][name] = ev.errors()
            for role, names in (("train", train), ("test", test)):
                if names:
                    for key, value in row["errors"][names[0]].items():
                        row[f"{role}_{key}"] = value
            if spec.learner != GALERKIN:
                row.update(operator_checks(rom))
            row["_rom"] = rom
            rows.append(row)
    if progress:
        progress(f"timing {len(rows)} reduced models ({config.timing.repeats} interleaved rounds)")
    costs = study_costs({i: row["_rom"] for i, row in enumerate(rows) if "failed" not in row}, runs, config)
    for i, row in enumerate(rows):      # a ROM that fails cannot be timed
        row.update(costs.get(i, {"seconds_per_step": float("nan"), "cost": None, "speedup": float("nan")}))
    return rows, evaluations


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
