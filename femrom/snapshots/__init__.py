"""Snapshot stores: runs streamed into HDF5, crash-safe, resumable, read in column blocks.

- :class:`SnapshotStore` -- one file per system: several trajectories of
  ``q`` (and ``v``, ``a`` when asked), inputs ``u``, outputs ``y`` and times
  ``t``, with the scene text, femrom version, dof map, units, scheme and ``dt``
  as metadata. :meth:`~SnapshotStore.iter_blocks` yields (n, k) column blocks
  of the snapshot matrix without ever holding it all.
- :class:`SnapshotWriter` -- a consumer of the integrators (``store.writer()``)
  that commits every completed chunk together with the integrator's
  checkpoint, in HDF5's SWMR mode so a killed run leaves a readable file.
- :func:`resume` -- continue a stopped run from its last committed chunk,
  bit-identically.
- :func:`read_series`, :func:`ingested_model`, :func:`ingest` -- another solver's
  displacement series (``.pvd`` + ``.vtu``, XDMF, an HDF5/``.npz`` array with its
  mesh) streamed into a store, with femrom's own model of the data (P1 on the
  series' mesh, a mass matrix, Dirichlet dofs detected or named, tabulated inputs,
  probes); one :class:`IngestError` line naming the file and step for a bad series.
- :func:`run_fom` -- a built model integrated under given input signals, its fields
  streamed into a store and each step timed without the consumers (:class:`FOMRun`;
  :func:`solver_factory`: one factorisation for all runs of one ``dt``);
- :func:`read_rows` -- committed rows of one dataset by path, for readers
  elsewhere (Dask workers) that a store planned with
  :meth:`~SnapshotStore.column_blocks`.

A kill at any moment is covered: a new store is written under a temporary
name and renamed into place; adding a trajectory (or trimming one for
``resume``) happens under an undo journal (``<store>.journal``) that the next
writer (or :func:`recover`) rolls back if the process died, also for a copy of
the store taken with its journal; a reader reads the store as it was before,
says so (:class:`PendingChangeWarning`) and never modifies the file. After that the file is in HDF5's SWMR mode, where every
committed chunk stays readable.

Fields are named by key or by name: ``q`` / ``displacement``, ``v`` /
``velocity``, ``a`` / ``acceleration``, ``u`` / ``inputs``, ``y`` / ``outputs``.

Every problem with a file (missing, not HDF5, truncated, foreign, wrong-shaped,
a declared length beyond the data, a read past it) is a one-line
:class:`SnapshotStoreError` naming the file.
"""

from femrom.snapshots._errors import SnapshotStoreError
from femrom.snapshots._ingest import (
    SERIES_READERS,
    DisplacementSeries,
    IngestedModel,
    IngestError,
    TabulatedInputs,
    ingest,
    ingested_model,
    read_input_table,
    read_series,
)
from femrom.snapshots._format import DEFAULT_UNITS, FORMAT_NAME, FORMAT_VERSION
from femrom.snapshots._resume import model_solver, resume
from femrom.snapshots._runs import FOMRun, run_fom, solver_factory
from femrom.snapshots._reading import read_rows
from femrom.snapshots._recovery import PendingChangeWarning, recover
from femrom.snapshots._store import SnapshotStore
from femrom.snapshots._writer import SnapshotWriter, default_chunk_steps

__all__ = [
    "SERIES_READERS", "DisplacementSeries", "IngestError", "IngestedModel", "TabulatedInputs", "ingest",
    "ingested_model", "read_input_table", "read_series",
    "DEFAULT_UNITS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "FOMRun",
    "SnapshotStore",
    "PendingChangeWarning",
    "recover",
    "run_fom",
    "solver_factory",
    "SnapshotStoreError",
    "SnapshotWriter",
    "default_chunk_steps",
    "model_solver",
    "read_rows",
    "resume",
]
