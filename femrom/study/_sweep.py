"""FOM sweeps as Dask tasks: one task per run, one store file per task, merged into one store.

Each point of a scene's ``[sweep]`` (:class:`~femrom.scene.SweepConfig`) is a
Dask task that builds the model (kept on the worker for the next point with the
same material and effects), integrates it, and streams its fields into a store
file of its own: written under a temporary name, renamed when complete. A
worker killed mid-run leaves only its temporary file; Dask reruns its task on
another worker, and the finished runs are never touched. A sweep started again
in the same folder skips the runs whose file is complete. When every run is
done, the runs are copied into one store (:meth:`SnapshotStore.import_trajectory`,
each copy journaled), with their parameter values as trajectory attributes.

``LocalCluster`` (processes, one thread each) by default; any running
scheduler by address (``tcp://host:port``), whose workers must see the output
folder (a shared file system).
"""

from __future__ import annotations

import json
import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path

from femrom._errors import FemromValueError
from femrom.post import write_metrics
from femrom.snapshots import SnapshotStore, SnapshotStoreError
from femrom.snapshots import run_fom

#: paths that change only the input signals (the built model can be reused)
_SIGNAL_PATHS = ("inputs.",)


@dataclass(frozen=True)
class SweepRun:
    """One point of a sweep: its trajectory name and ``(path, value)`` pairs."""

    name: str
    values: tuple[tuple[str, float], ...]

    @property
    def model_values(self) -> tuple:
        return tuple((p, v) for p, v in self.values if not p.startswith(_SIGNAL_PATHS))


def sweep_runs(scene) -> list[SweepRun]:
    """The runs of the scene's ``[sweep]``, named ``p000``, ``p001``, ..."""
    if scene.sweep is None:
        raise FemromValueError(f"scene {scene.name!r} has no [sweep] section")
    return [SweepRun(f"p{i:03d}", values) for i, values in enumerate(scene.sweep.points())]


_WORKER_MODEL: dict = {}


def _model_for(scene, values):
    """The built model of ``scene`` with ``values`` set, kept for the worker's next task."""
    from femrom.scene import build

    key = (scene.source_text, repr(scene), values)
    if _WORKER_MODEL.get("key") != key:
        _WORKER_MODEL.clear()   # one model per worker: a sweep's models can be GBs each
        _WORKER_MODEL.update(key=key, model=build(scene.with_parameters(values)))
    return _WORKER_MODEL["model"]


def run_sweep_point(scene, run: SweepRun, part: str) -> dict:
    """Integrate one point (on a worker) into the store file ``part``; returns its summary.

    The store is written as ``.<part>.<pid>.partial`` and renamed to ``part`` when
    the run is complete: a killed run never leaves a file that looks finished.
    """
    tic = time.perf_counter()
    part = Path(part)
    model = _model_for(scene, run.model_values)
    signals = tuple(i.signal for i in scene.with_parameters(run.values).inputs)
    partial = part.with_name(f".{part.name}.{os.getpid()}.partial")
    store = SnapshotStore.create(partial, model, fields=scene.sweep.fields, overwrite=True)
    try:
        result = run_fom(model, signals or None, name=run.name, store=store)
    finally:
        store.close()
    os.replace(partial, part)
    return {"name": run.name, "values": dict(run.values), "n_steps": result.summary["n_steps"],
            "stepping_seconds": result.summary["stepping_seconds"], "seconds": time.perf_counter() - tic,
            "seconds_per_step": result.cost.seconds, "host": socket.gethostname(), "pid": os.getpid()}


def _complete(part: Path, name: str) -> bool:
    if not part.is_file():
        return False
    try:
        with SnapshotStore.open(part) as store:
            return store.is_complete(name)
    except SnapshotStoreError:
        return False


def run_sweep(scene, out_dir, *, scheduler: str | None = None, n_workers: int = 2, client=None,
              keep_parts: bool = False, progress=print) -> dict:
    """Run every point of the scene's ``[sweep]`` as a Dask task; merge them into ``out_dir/sweep.h5``.

    Parameters
    ----------
    scene : Scene
        With a ``[sweep]`` section.
    out_dir : path
        Gets ``sweep.h5`` (one trajectory per point, parameters as attributes),
        ``sweep.json`` (the runs: values, timings, which worker) and, while running,
        ``sweep_parts/`` (one store per finished point; removed at the end
        unless ``keep_parts``).
    scheduler : str, optional
        Address of a running Dask scheduler; ``None``: a ``LocalCluster`` of
        ``n_workers`` processes with one thread each.
    client : distributed.Client, optional
        Use this client instead (tests kill its workers).

    Returns
    -------
    dict
        What ``sweep.json`` holds.
    """
    from distributed import Client, LocalCluster, as_completed

    from femrom.scene import build

    say = progress or (lambda message: None)
    out_dir = Path(out_dir)
    parts = out_dir / "sweep_parts"
    runs = sweep_runs(scene)
    todo = [run for run in runs if not _complete(parts / f"{run.name}.h5", run.name)]
    if len(todo) < len(runs):
        say(f"sweep: {len(runs) - len(todo)} of {len(runs)} runs already done in {parts}")
    tic = time.perf_counter()
    cluster = None
    if client is None:
        if scheduler is None:
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None)
        own_client = Client(cluster if cluster is not None else scheduler)
    else:
        own_client = None
    active = client or own_client
    results = {}
    try:
        parts.mkdir(parents=True, exist_ok=True)     # only once a scheduler answers
        futures = {active.submit(run_sweep_point, scene, run, str(parts / f"{run.name}.h5"), pure=False,
                                 key=f"femrom-sweep-{run.name}-{os.getpid()}-{time.time_ns()}"): run
                   for run in todo}
        for done, future in enumerate(as_completed(futures), start=1):
            summary = future.result()
            results[summary["name"]] = summary
            say(f"sweep: {done}/{len(todo)} runs done ({summary['name']} "
                f"{', '.join(f'{k} = {v:g}' for k, v in summary['values'].items())}: {summary['seconds']:.1f} s)")
    finally:
        if own_client is not None:
            own_client.close()
        if cluster is not None:
            cluster.close()
    wall = time.perf_counter() - tic

    say(f"sweep: merging {len(runs)} runs into {out_dir / 'sweep.h5'}")
    merged = SnapshotStore.create(out_dir / "sweep.h5", build(scene), fields=scene.sweep.fields, overwrite=True)
    try:
        for run in runs:
            merged.import_trajectory(parts / f"{run.name}.h5", run.name,
                                     attrs={"sweep_values": json.dumps(dict(run.values))})
    finally:
        merged.close()
    if not keep_parts:
        for path in parts.iterdir():
            path.unlink()
        parts.rmdir()
    else:
        for path in parts.glob(".*.partial"):   # what killed workers left
            path.unlink()
    summary = {"scene": scene.name, "n_runs": len(runs), "ran": len(todo), "wall_seconds": wall,
               "scheduler": scheduler or f"LocalCluster({n_workers} processes x 1 thread)",
               "runs": [results.get(run.name, {"name": run.name, "values": dict(run.values), "skipped": True})
                        for run in runs]}
    write_metrics(out_dir / "sweep.json", summary)
    return summary
