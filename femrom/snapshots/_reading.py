"""Reading a snapshot store: its metadata, trajectories, snapshot columns and checkpoints.

The snapshot matrix of a field is ``X = [x_0, x_1, ..., x_{K-1}]``, an (n, K)
matrix whose columns are the states of every trajectory, one after another.
It never has to fit in memory: :meth:`StoreReader.iter_blocks` yields it as
(n, k) column blocks, each read from whole chunks on disk, and
:meth:`StoreReader.column_blocks` plans such blocks for readers elsewhere
(:func:`read_rows`, by path, on Dask workers).
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import h5py
import numpy as np

from femrom._errors import FemromValueError
from femrom.fem import Condensation
from femrom.integrators import StepResult
from femrom.snapshots import _format
from femrom.snapshots._errors import SnapshotStoreError
from femrom.snapshots._format import trajectory_name
from femrom.snapshots._recovery import open_committed


class StoreReader:
    """An open snapshot store, read-only: the base of :class:`~femrom.snapshots.SnapshotStore`.

    Opening checks the layout (and, for a file a writer has open in SWMR mode, that
    every committed chunk is in the file); every read is one
    :class:`SnapshotStoreError` naming the file when the data are damaged.

    Attributes
    ----------
    path : Path
    system : SecondOrderSystem or None
        Needed to restore a nonlinear state from a checkpoint (and, for the
        store, to write).
    """

    def __init__(self, path, *, system=None):
        self.path = Path(path)
        self.system = system
        self._file: h5py.File | None = None
        self._swmr_reader = False
        self._handle()
        if system is not None and system.n_dofs != self.n_dofs:
            raise SnapshotStoreError(f"{self.path}: store has {self.n_dofs} dofs, the system "
                                     f"{system.n_dofs}")

    def _handle(self) -> h5py.File:
        if self._file is None:
            f, swmr = open_committed(self.path)
            try:
                with self._guard("checking the layout"):
                    _format.check_store(f, self.path)
                    if swmr:
                        _format.check_on_disk(f, self.path)
            except BaseException:
                f.close()
                raise
            self._file, self._swmr_reader = f, swmr
        return self._file

    @contextmanager
    def _guard(self, what: str):
        """Turn HDF5 failures (damaged or truncated data) into one-line errors naming the file."""
        try:
            yield
        except SnapshotStoreError:
            raise
        except (OSError, KeyError, ValueError, RuntimeError) as exc:
            raise SnapshotStoreError(f"{self.path}: damaged or unreadable ({what}): "
                                     f"{_format.hdf5_message(exc)}") from None

    def close(self) -> None:
        """Close the file."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- reading -------------------------------------------------------------
    @property
    def n_dofs(self) -> int:
        """Free dofs n: the row count of the snapshot matrix."""
        return int(self._handle().attrs["n_dofs"])

    @property
    def fields(self) -> tuple[str, ...]:
        """Per-step datasets kept: some of ``q``, ``v``, ``a``, then ``u``, ``y`` if present."""
        return _format.stored_fields(self._handle())

    @property
    def trajectories(self) -> tuple[str, ...]:
        """Trajectory names in order (``"000"``, ``"001"``, ...)."""
        return tuple(sorted(self._handle()["trajectories"]))

    @property
    def metadata(self) -> dict:
        """Format, femrom version, creation time, scene TOML, units, scheme, dt, dof map, ..."""
        with self._guard("reading metadata"):
            return _format.read_metadata(self._handle())

    @property
    def condensation(self) -> Condensation:
        """The dof map: free-dof snapshots back to full fields with ``.expand``."""
        f = self._handle()
        return Condensation.from_fixed(int(f["dofmap"].attrs["n_total"]), f["dofmap/fixed"][()])

    def _group(self, trajectory) -> h5py.Group:
        name = trajectory_name(trajectory)
        group = self._handle()["trajectories"].get(name)
        if group is None:
            raise SnapshotStoreError(f"{self.path}: no trajectory {name!r}; stored: "
                                     f"{', '.join(self.trajectories) or '(none)'}")
        return group

    def _dataset(self, group: h5py.Group, key: str) -> h5py.Dataset:
        ds = group[key]
        if self._swmr_reader:
            ds.refresh()  # a live writer may have appended since the file was opened
        return ds

    def length(self, trajectory) -> int:
        """Declared (committed) number of snapshots of a trajectory."""
        group = self._group(trajectory)
        with self._guard(f"reading trajectory {group.name}"):
            length = int(self._dataset(group, "committed")[0])
            for key in (*self.fields, "t", "step"):
                if self._dataset(group, key).shape[0] < length:
                    raise SnapshotStoreError(f"{self.path}: trajectory {group.name} declares "
                                             f"{length} snapshots but {key!r} holds "
                                             f"{group[key].shape[0]}")
        return length

    def n_snapshots(self, field: str = "q") -> int:
        """Columns K of the snapshot matrix of ``field``: committed steps of all trajectories."""
        self.field_key(field)
        return sum(self.length(name) for name in self.trajectories)

    def field_key(self, field: str) -> str:
        """The dataset of a stored field, named by key or by name: ``"q"`` or
        ``"displacement"``, ``"v"`` or ``"velocity"``, ``"a"`` or ``"acceleration"``,
        ``"u"`` or ``"inputs"``, ``"y"`` or ``"outputs"``.

        Raises
        ------
        SnapshotStoreError
            The field is not stored; the message lists the stored ones.
        """
        key = _format.FIELD_KEYS.get(field, field)
        fields = self.fields
        if key not in fields:
            names = ", ".join(_format.FIELD_NAMES[k] for k in fields)
            raise SnapshotStoreError(f"{self.path}: no field {field!r}; stored: "
                                     f"{', '.join(fields)} ({names})")
        return key

    def _rows(self, group, key, start, stop, length) -> np.ndarray:
        if not 0 <= start <= stop <= length:
            raise SnapshotStoreError(f"{self.path}: trajectory {group.name} has {length} committed "
                                     f"snapshots; cannot read [{start}, {stop})")
        with self._guard(f"reading {group.name}/{key}"):
            return self._dataset(group, key)[start:stop]

    def read(self, trajectory, field: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Snapshot columns ``start:stop`` of one trajectory.

        Returns
        -------
        (w, k) ndarray
            ``w = n`` for ``q``, ``v``, ``a``; ``m`` for ``u``; ``p`` for ``y``.
            Fortran-ordered (the transpose of the (k, w) rows read, no copy).

        Raises
        ------
        SnapshotStoreError
            ``stop`` beyond the declared length, or an unknown field/trajectory.
        """
        key = self.field_key(field)
        group = self._group(trajectory)
        length = self.length(trajectory)
        stop = length if stop is None else int(stop)
        return self._rows(group, key, int(start), stop, length).T

    def times(self, trajectory) -> np.ndarray:
        """(L,) ndarray: times of the committed snapshots."""
        group = self._group(trajectory)
        length = self.length(trajectory)
        return self._rows(group, "t", 0, length, length)

    def steps(self, trajectory) -> np.ndarray:
        """(L,) int ndarray: step indices of the committed snapshots."""
        group = self._group(trajectory)
        length = self.length(trajectory)
        return self._rows(group, "step", 0, length, length)

    def iter_blocks(self, field: str, block_steps: int,
                    trajectories=None) -> Iterator[np.ndarray]:
        """Column blocks of the snapshot matrix ``[X_000, X_001, ...]``, in order.

        Each block lies in one trajectory: (w, k) with ``k = block_steps``
        except the last block of a trajectory. Memory: one block. Choose
        ``block_steps`` a multiple of the trajectories' ``chunk_steps`` to
        read whole chunks.

        Parameters
        ----------
        field : str
        block_steps : int
        trajectories : sequence, optional
            Names or indices; all by default.
        """
        key, block_steps, names = self._block_plan_args(field, block_steps, trajectories)
        for name in names:
            group = self._group(name)
            length = self.length(name)
            for start in range(0, length, block_steps):
                yield self._rows(group, key, start, min(start + block_steps, length), length).T

    def _block_plan_args(self, field: str, block_steps: int, trajectories):
        """``(dataset key, block_steps, trajectory names)``, checked."""
        block_steps = int(block_steps)
        if block_steps < 1:
            raise FemromValueError(f"block_steps must be >= 1, got {block_steps}")
        names = self.trajectories if trajectories is None else \
            tuple(trajectory_name(t) for t in trajectories)
        return self.field_key(field), block_steps, names

    def column_blocks(self, field: str, block_steps: int,
                      trajectories=None) -> list[tuple[str, int, int]]:
        """The column blocks of :meth:`iter_blocks`, aligned with the HDF5 chunks, as a plan.

        Each block ``(trajectory, start, stop)`` lies in one trajectory and
        starts on a chunk boundary; it holds ``b`` committed snapshots, ``b``
        the multiple of the trajectory's chunk rows ``c`` nearest
        ``block_steps`` (halves up, at least ``c``), except the last block of a
        trajectory. Reading a block (:func:`read_rows`) reads whole chunks.

        Returns
        -------
        list of (str, int, int)
            In the column order of the snapshot matrix ``[X_000, X_001, ...]``.
        """
        key, block_steps, names = self._block_plan_args(field, block_steps, trajectories)
        plan = []
        for name in names:
            group = self._group(name)
            length = self.length(name)
            chunk = group[key].chunks[0]
            step = chunk * max(1, int(block_steps / chunk + 0.5))
            plan.extend((name, start, min(start + step, length)) for start in range(0, length, step))
        return plan

    def attrs(self, trajectory) -> dict:
        """A trajectory's run parameters: scheme, dt, n_steps, every, chunk_steps, created."""
        group = self._group(trajectory)
        return {k: (_format.text(v) if isinstance(v, (bytes, str)) else
                    (v.item() if isinstance(v, np.generic) else v))
                for k, v in group.attrs.items()}

    def is_complete(self, trajectory) -> bool:
        """Whether the last planned step (``n_steps`` attribute) is committed."""
        attrs = self.attrs(trajectory)
        if "n_steps" not in attrs:
            return False
        length = self.length(trajectory)
        final = (int(attrs["n_steps"]) // int(attrs["every"])) * int(attrs["every"])
        return length > 0 and int(self.steps(trajectory)[-1]) == final

    def checkpoint(self, trajectory, system=None) -> StepResult | None:
        """The committed restart state of a trajectory (``None`` before anything is committed).

        It is the state of the last committed snapshot, or, when none is
        committed yet, of the first one the writer received (not yet a row).
        The nonlinear state is restored with ``system.nonlinear.restore``
        (``system`` defaults to the store's); without a system it stays a
        dict of arrays.
        """
        group = self._group(trajectory)
        system = self.system if system is None else system
        with self._guard(f"reading {group.name}/checkpoint"):
            slot = int(self._dataset(group, "committed")[1])
            if slot < 0:
                return None
            ck = group["checkpoint"]
            q, v = _readonly(ck["q"][slot]), _readonly(ck["v"][slot])
            a = _readonly(ck["a"][slot]) if ck["has_a"][slot] else None
            arrays = {key: ck["state"][key][slot] for key in ck["state"]}
            step, t = int(ck["step"][slot]), float(ck["t"][slot])
        state = None
        if system is not None and system.nonlinear is not None:
            state = system.nonlinear.restore(arrays)
        elif arrays:
            state = arrays
        return StepResult(step=step, t=t, q=q, v=v, a=a, state=state)


def read_rows(path, trajectory: str, field: str, start: int, stop: int) -> np.ndarray:
    """Rows ``start:stop`` of one dataset of a store, opening the file for just this read.

    For readers away from the :class:`SnapshotStore` that planned the read
    (tasks on Dask workers, see :meth:`SnapshotStore.column_blocks`): the
    layout was checked there; this checks that the rows are still committed.

    Parameters
    ----------
    path : str or Path
    trajectory : str
        Its name (``"000"``, ...).
    field : str
        Key or name (``"q"`` or ``"displacement"``, ...).
    start, stop : int

    Returns
    -------
    (stop - start, w) ndarray
        Snapshots as rows, as stored (the transpose of snapshot columns).

    Raises
    ------
    SnapshotStoreError
        Rows past the declared length, a missing dataset, an unreadable file.
    """
    path = Path(path)
    field = _format.FIELD_KEYS.get(field, field)
    f, _ = open_committed(path)
    with f:
        where = f"/trajectories/{trajectory}/{field}"
        try:
            group = f["trajectories"][trajectory]
            length = _format.declared_length(group)
            if not 0 <= start <= stop <= length:
                raise SnapshotStoreError(f"{path}: trajectory {trajectory!r} has {length} committed "
                                         f"snapshots; cannot read [{start}, {stop})")
            return group[field][start:stop]
        except SnapshotStoreError:
            raise
        except (OSError, KeyError, ValueError, RuntimeError) as exc:
            raise SnapshotStoreError(f"{path}: damaged or unreadable (reading {where}): "
                                     f"{_format.hdf5_message(exc)}") from None


def _readonly(x: np.ndarray) -> np.ndarray:
    x = np.array(x, dtype=float)
    x.setflags(write=False)
    return x
