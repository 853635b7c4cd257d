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

Every problem with a file (missing, not HDF5, truncated, foreign, wrong-shaped,
a declared length beyond the data, a read past it) is a one-line
:class:`SnapshotStoreError` naming the file.
"""

from femrom.snapshots._errors import SnapshotStoreError
from femrom.snapshots._format import DEFAULT_UNITS, FORMAT_NAME, FORMAT_VERSION
from femrom.snapshots._resume import model_solver, resume
from femrom.snapshots._store import SnapshotStore
from femrom.snapshots._writer import SnapshotWriter, default_chunk_steps

__all__ = [
    "DEFAULT_UNITS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "SnapshotStore",
    "SnapshotStoreError",
    "SnapshotWriter",
    "default_chunk_steps",
    "model_solver",
    "resume",
]
