r"""Learning from snapshots saved every k-th step: what another solver's output every k steps gives.

:func:`subsampled_rows` takes a finished study (its store, runs, basis and product,
a :class:`~femrom.study.StudyState`) and, for each k, keeps every k-th column of the
training run (the store is read block by block, nothing re-run), fits one learner
at one r from

- the displacements alone, by the integrator-consistent differences at the snapshot
  spacing ``h = k dt`` (:meth:`~femrom.inference.SecondOrderData.integrator_consistent`),
  the ROM stepping ``h``;
- the displacements alone filled in to the FOM's ``dt`` by cubic splines
  (:meth:`~femrom.inference.SecondOrderData.upsampled`, the inputs known at every ``dt``),
  integrator-consistent at ``dt``, the ROM stepping ``dt`` (``integrator_dt``, k > 1),
- the same, the states between the snapshots refined by alternating least squares with
  the learner (:func:`~femrom.inference.alternating_fill`; ``refined_dt``, k > 1, linear
  scenes),
- the stored Newmark ``q'``, ``q''`` at the kept steps (when the store has them),
- 4th-order finite differences of the kept displacements,

and predicts the first test run, scored on its every-k-th-step grid (the other models
step ``h``); errors against the test run's kept steps (the field error exact, from the
study's projection of that run).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference import alternating_fill, learner_class, reduce_snapshots
from femrom.linalg import as_block_source, store_source
from femrom.rom import SecondOrderROM
from femrom.study._metrics import Projection, diverged_at, relative_error
from femrom.study._study import projected_forces

#: The derivative data compared, by label (``integrator_dt``, ``refined_dt``: only for k > 1).
SOURCES = ("integrator", "integrator_dt", "refined_dt", "stored", "fd4")
#: Sources whose ROM steps the FOM's dt, not the spacing h.
FINE_SOURCES = ("integrator_dt", "refined_dt")


def every_kth(source, k: int):
    """A block source of every ``k``-th column of ``source`` (columns ``0, k, 2k, ...``), block by block."""
    source = as_block_source(source)

    def blocks():
        offset = 0
        for block in source.blocks():
            first = (-offset) % k
            yield block[:, first::k]
            offset += block.shape[1]

    return as_block_source(blocks)


def subsampled_rows(state, every=(1, 2, 5, 10), *, r: int | None = None, learner: str = "lopinf") -> list[dict]:
    """One row per (k, derivative source): the learner at rank ``r`` (default: the study's largest).

    Rows hold ``every``, ``h``, ``rom_step``, ``learner``, ``derivatives``, ``train_output_error``,
    ``test_output_error``, ``test_field_error``, ``test_projection_error`` (the basis'
    floor on the kept steps) and ``fit_seconds``; a source the store lacks (stored
    derivatives) is skipped, a prediction that fails gets infinite errors and ``failed``.
    """
    config, store, runs, W = state.config, state.store, state.runs, state.product
    system = state.model.system
    r = max(config.basis.ranks) if r is None else int(r)
    V = state.basis[:, :r]
    train, test = runs[config.train[0].name], runs[config.test[0].name]
    projection = state.projections[test.name]
    stored = {"v", "a"} <= set(store.fields)
    rows = []
    for k in every:
        h = k * train.dt
        keep = slice(None, None, k)
        q = every_kth(store_source(store, "q", [train.name]), k)
        derivatives = {}
        if stored:
            derivatives = {"velocities": every_kth(store_source(store, "v", [train.name]), k),
                           "accelerations": every_kth(store_source(store, "a", [train.name]), k)}
        outputs = None if train.outputs is None else train.outputs[:, keep]
        raw = reduce_snapshots(V, q, h, product=W, inputs=None if train.U is None else train.U[:, keep],
                               outputs=outputs, **derivatives,
                               derivatives="stored" if stored else "finite_difference")
        if system.nonlinear is not None:
            if system.nonlinear.stateful:
                raise FemromValueError("learning every k-th step takes stateless nonlinear forces only")
            raw = replace(raw, nonlinear_forces=projected_forces(system.nonlinear, V, q))
        data = {"integrator": raw.integrator_consistent(), "fd4": raw.with_finite_differences(4)}
        fine_inputs = None
        if k > 1:      # filled in to the FOM's dt, the inputs known there: the ROM steps dt
            fine = (raw.n_samples - 1) * k + 1                  # the FOM steps the kept ones span
            fine_inputs = None if train.U is None else train.U[:, :fine]
            data["integrator_dt"] = raw.upsampled(k, fine_inputs).integrator_consistent()
            if raw.nonlinear_forces is None:
                data["refined_dt"] = raw     # fitted by alternating_fill below
        if stored:
            data["stored"] = raw
        floor = Projection(projection.coordinates[:, keep], projection.residual2[keep], projection.norm2[keep])
        for source in SOURCES:
            if source not in data:
                continue
            tic = time.perf_counter()
            fitter = learner_class(learner).for_system(system, basis=V)
            extra = {}
            if source == "refined_dt":
                _, history = alternating_fill(fitter, data[source], k, inputs=fine_inputs)
                extra = {"fill_sweeps": history[-1].sweep, "fill_residual": history[-1].residual,
                         "spline_residual": history[0].residual}
                rom = SecondOrderROM(fitter.operators_, V, product=W, learner=fitter)
            else:
                rom = SecondOrderROM(basis=V, product=W, learner=fitter).fit(data[source])
            row = {"every": k, "h": h, "rom_step": train.dt if source in FINE_SOURCES else h,
                   "learner": learner, "r": r, "derivatives": source,
                   "fit_seconds": time.perf_counter() - tic,
                   "test_projection_error": floor.projection_error(r)} | extra
            step = 1 if source in FINE_SOURCES else k          # the ROM's step: dt, or the spacing h
            grid = slice(None, None, k // step)                  # its solution at the kept steps
            try:
                with np.errstate(all="ignore"):
                    fit = rom.predict(train.times[::step], None if train.U is None else train.U[:, ::step],
                                      initial=(train.q0, train.v0))
                    prediction = rom.predict(test.times[::step], test.inputs.sampled(test.times[::step]),
                                             initial=(test.q0, test.v0))
                    fit, prediction = _at(fit, grid), _at(prediction, grid)
            except (RuntimeError, np.linalg.LinAlgError) as exc:
                rows.append(row | {"failed": str(exc), "train_output_error": float("inf"),
                                   "test_output_error": float("inf"), "test_field_error": float("inf")})
                continue
            with np.errstate(all="ignore"):       # a diverged model's errors overflow on the way to inf
                row |= {"train_output_error": float("nan") if outputs is None else relative_error(outputs, fit.outputs),
                        "test_output_error": float("nan") if test.outputs is None else relative_error(
                            test.outputs[:, keep], prediction.outputs),
                        "test_field_error": floor.field_error(prediction.q)}
            if test.outputs is not None:
                t = diverged_at(prediction.outputs, test.outputs[:, keep], test.times[keep])
                if t is not None:
                    row["diverged"] = f"test at t = {t:.4g} s (outputs non-finite or above 1e6 x the FOM's largest)"
            rows.append(row)
    return rows


def _at(solution, grid: slice):
    """A reduced solution's ``q`` and ``outputs`` at the columns ``grid``."""
    from types import SimpleNamespace

    return SimpleNamespace(q=solution.q[:, grid], outputs=None if solution.outputs is None else solution.outputs[:, grid])


def subsampled_section(rows: list[dict], train: str, test: str) -> str:
    """The report's section on ``rows`` (:func:`subsampled_rows`)."""
    from femrom.post import accuracy_cost_table

    return (f"## Learning from snapshots every k-th step (trained on {train}, tested on {test})\n\n"
            "The training run's displacements every k-th step, h = k dt; derivatives: `integrator` (from the "
            "displacements alone, the differences the ROM's Newmark steps reproduce, "
            "`SecondOrderData.integrator_consistent`; the ROM steps h), `integrator_dt` (the same, filled in to "
            "the FOM's dt by cubic splines, `SecondOrderData.upsampled`; the ROM steps dt), `refined_dt` (the "
            "same fill refined by alternating least squares with the learner, `femrom.inference.alternating_fill`; "
            "steps dt), `stored` (the FOM's "
            "Newmark q', q'' at the kept steps; steps h), `fd4` (4th-order differences of the kept displacements; "
            "steps h).\n\n"
            + accuracy_cost_table(rows, ["every", "h", "rom_step", "r", "derivatives", "train_output_error", "test_output_error",
                                         "test_field_error", "test_projection_error", "fill_sweeps",
                                         "fit_seconds", "diverged"]))
