r"""Stream a run into a store, one committed chunk at a time.

A chunk of ``c`` steps is buffered in memory and committed in this order:

1. append its rows to every dataset (``q``, ``v``, ``a``, ``u``, ``y``, ``t``, ``step``);
2. write the checkpoint (the chunk's last step: ``t``, ``step``, ``q``, ``v``,
   ``a`` and ``system.nonlinear.checkpoint(state)``) into the checkpoint slot
   that the committed record does *not* point to;
3. flush;
4. write the committed record ``[L + c, slot]`` (one 16-byte raw write);
5. flush.

A process killed anywhere in 1-3 leaves the old record pointing at the old
rows and the old, intact checkpoint slot; killed in 4-5, the new record is
either not on disk or points at data that already is. The file is written in
HDF5's single-writer/multiple-reader (SWMR) mode, whose ordered metadata
flushes keep the file itself readable after a kill at any moment.

Before that, the writer's trajectory is created (or, for ``resume``, cut back
to its declared length), which HDF5 cannot do in SWMR mode. That change is
made under an undo journal (:mod:`._journal`): a kill during it leaves the
store as it was (the next reader or writer rolls it back) or with the new,
empty trajectory, never in between. The file is then reopened directly in
SWMR write mode.
"""

from __future__ import annotations

import datetime
import os

try:
    import resource
except ImportError:  # pragma: no cover - not on POSIX
    resource = None

import numpy as np
from h5py import h5s

from femrom._errors import FemromValueError
from femrom.snapshots import _format
from femrom.snapshots._errors import SnapshotStoreError
from femrom.snapshots._format import trajectory_name

#: A chunk of about this many bytes per field by default (large enough for fast
#: sequential reads, small enough to buffer).
DEFAULT_CHUNK_BYTES = 4 * 2**20
#: HDF5 chunks must stay below 4 GiB; keep a margin.
MAX_CHUNK_BYTES = 2**31


#: Bytes a commit may need beyond its chunks (chunk index nodes, object headers, the checkpoint).
METADATA_MARGIN = 1 << 20


def default_chunk_steps(n_dofs: int) -> int:
    """Steps per chunk: about 4 MiB of float64 per field, clipped to [8, 1024]."""
    return int(np.clip(DEFAULT_CHUNK_BYTES // (8 * max(n_dofs, 1)), 8, 1024))


class SnapshotWriter:
    """A consumer that appends every ``every``-th :class:`StepResult` to one trajectory.

    Pass it to ``integrate(..., consumers=[writer])`` or
    ``simulate(model, consumers=[writer])``; the driver calls :meth:`close`
    when the run ends, also on errors, and that commits the last partial
    chunk. A run killed outright keeps every committed chunk and a checkpoint
    to :func:`~femrom.snapshots.resume` from.

    Parameters
    ----------
    store : SnapshotStore
        Must have a ``system`` (for inputs, outputs and nonlinear checkpoints).
    trajectory : str or int, optional
        Name of the new trajectory; the next free ``"000"``, ``"001"``, ... by default.
    chunk_steps : int, optional
        Steps per chunk (and per commit); :func:`default_chunk_steps` by default.
    every : int
        Keep steps whose index is a multiple of ``every``.
    n_steps : int, optional
        Planned last step (what ``resume`` runs up to); the store's default.
    dt : float, optional
        Time step, recorded for ``resume``; the store's default.
    scheme : scheme or str, optional
        Scheme (name) recorded for ``resume``; the store's default.
    fsync : bool
        Also ``fsync`` at each commit, and the undo journal while the
        trajectory is set up (survives power loss, not just a killed process).
    append : bool
        Continue the existing ``trajectory`` after its declared length instead
        (what :func:`~femrom.snapshots.resume` does); the other options are then
        the trajectory's own.
    inputs : callable, optional
        ``u(t) -> (m,)`` of the run written, stored as ``u``; the store's system's
        by default. A run under other signals than the store's system (a test
        input) passes its own, or the store records the wrong ``u``.

    Notes
    -----
    Making the writer creates the trajectory's datasets before the file is
    opened in SWMR mode (HDF5 cannot create objects in it), under an undo
    journal: a kill meanwhile leaves the store without the new trajectory
    (rolled back when it is next opened) or with it, empty (declared length
    0, no checkpoint). Old trajectories are never at risk.
    """

    def __init__(self, store, trajectory=None, *, chunk_steps: int | None = None, every: int = 1,
                 n_steps: int | None = None, dt: float | None = None, scheme=None,
                 fsync: bool = False, append: bool = False, inputs=None):
        system = store.system
        if system is None:
            raise SnapshotStoreError(f"{store.path}: open the store with system=... to write to it")
        self.store, self.system, self.fsync = store, system, bool(fsync)
        self.inputs = system.inputs if inputs is None else inputs
        self._closed = True

        def change_layout(f) -> None:  # under the undo journal (store._open_for_writing)
            trajectories = f["trajectories"]
            if append:
                self.trajectory = trajectory_name(trajectory)
                if self.trajectory not in trajectories:
                    raise SnapshotStoreError(f"{store.path}: no trajectory {self.trajectory!r} "
                                             "to append to")
                self._reopen(trajectories[self.trajectory])
            else:
                self.trajectory = _new_name(trajectories, trajectory, store.path)
                defaults = f.attrs
                self._create(
                    trajectories, self.trajectory, chunk_steps, every,
                    n_steps=defaults.get("n_steps") if n_steps is None else n_steps,
                    dt=defaults.get("dt") if dt is None else dt,
                    scheme=defaults.get("scheme") if scheme is None else
                    getattr(scheme, "label", str(scheme)))

        f = store._open_for_writing(self, change_layout, fsync=self.fsync)
        self._closed = False
        try:
            group = f["trajectories"][self.trajectory]
            self._group = group
            self.chunk_steps = int(group.attrs["chunk_steps"])
            self.every = int(group.attrs["every"])
            self._keys = _format.stored_fields(f)
            c = self.chunk_steps
            # datasets looked up once (an h5py lookup costs as much as a small write)
            self._rows = {key: group[key] for key in (*self._keys, "t", "step")}
            self._buffers = {key: np.empty((c, ds.shape[1])) for key, ds in self._rows.items()
                             if key in self._keys}
            self._buffers["t"] = np.empty(c)
            self._buffers["step"] = np.empty(c, dtype=np.int64)
            self._committed = group["committed"]
            self._checkpoint = {key: group["checkpoint"][key]
                                for key in ("step", "t", "has_a", "q", "v", "a")}
            self._state = dict(group["checkpoint/state"].items())
            self._buffered = 0
            self._last = None
        except BaseException:
            self._closed = True
            store._writer_closed()
            raise

    # -- setting up (under the undo journal, before SWMR mode: objects can only be created now)
    def _create(self, trajectories, name, chunk_steps, every, *, n_steps, dt, scheme):
        system, n = self.system, self.system.n_dofs
        every = int(every)
        if every < 1:
            raise FemromValueError(f"every must be >= 1, got {every}")
        c = default_chunk_steps(n) if chunk_steps is None else int(chunk_steps)
        if c < 1:
            raise FemromValueError(f"chunk_steps must be >= 1, got {c}")
        if 8 * c * n > MAX_CHUNK_BYTES:
            raise FemromValueError(f"chunk_steps = {c} makes {8 * c * n / 2**30:.1f} GiB chunks of "
                                   f"{n} dofs; HDF5 needs < 2 GiB: use chunk_steps <= "
                                   f"{MAX_CHUNK_BYTES // (8 * n)}")
        group = trajectories.create_group(name)
        group.attrs.update({
            "every": every, "chunk_steps": c,
            "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        })
        for key, value in (("n_steps", n_steps), ("dt", dt), ("scheme", scheme)):
            if value is not None:
                group.attrs[key] = value
        widths = {"q": n, "v": n, "a": n, "u": system.n_inputs, "y": system.n_outputs}
        checksums = bool(trajectories.file.attrs.get("checksums", False))   # stores made before: none
        for key in _format.stored_fields(trajectories.file):
            w = widths[key]
            group.create_dataset(key, shape=(0, w), maxshape=(None, w), chunks=(c, w), dtype="f8",
                                 fletcher32=checksums)
        group.create_dataset("t", shape=(0,), maxshape=(None,), chunks=(c,), dtype="f8", fletcher32=checksums)
        group.create_dataset("step", shape=(0,), maxshape=(None,), chunks=(c,), dtype="i8", fletcher32=checksums)
        # fixed-size datasets are given data, so their storage exists now and every
        # later write to them is raw data only (no metadata changes)
        group.create_dataset("committed", data=np.array([0, -1], dtype=np.int64))
        ck = group.create_group("checkpoint")
        ck.create_dataset("step", data=np.zeros(2, dtype=np.int64))
        ck.create_dataset("t", data=np.zeros(2))
        ck.create_dataset("has_a", data=np.zeros(2, dtype=np.int8))
        for key in ("q", "v", "a"):
            ck.create_dataset(key, data=np.zeros((2, n)))
        state = ck.create_group("state")
        if system.nonlinear is not None:
            template = system.nonlinear.checkpoint(system.nonlinear.initial_state())
            for key, value in template.items():
                if "/" in key or not key:
                    raise FemromValueError(f"checkpoint key {key!r} of {type(system.nonlinear).__name__} "
                                           "cannot name a dataset")
                value = np.asarray(value)
                state.create_dataset(key, data=np.zeros((2,) + value.shape, dtype=value.dtype))
        self._length, self._slot, self._last_step = 0, -1, None
        return group

    def _reopen(self, group):
        """Continue a trajectory: drop rows past its declared length (a killed writer's)."""
        length, slot = (int(x) for x in group["committed"][()])
        for key in (*_format.stored_fields(group.file), "t", "step"):
            group[key].resize(length, axis=0)
        self._length, self._slot = length, slot
        self._last_step = int(group["step"][length - 1]) if length else None
        return group

    # -- streaming ------------------------------------------------------------
    @property
    def length(self) -> int:
        """Committed snapshots of this trajectory."""
        return self._length

    def __call__(self, result) -> None:
        if self._closed:
            raise SnapshotStoreError(f"{self.store.path}: writer of trajectory "
                                     f"{self.trajectory!r} is closed")
        if result.step % self.every:
            return
        if self._last_step is not None and result.step <= self._last_step:
            raise SnapshotStoreError(f"{self.store.path}: trajectory {self.trajectory!r} already "
                                     f"holds step {self._last_step}; got step {result.step}")
        if self._slot < 0:
            self._commit_initial(result)
        row, buffers = self._buffered, self._buffers
        for key in self._keys:
            value = np.asarray(self._value(result, key))
            if value.dtype.kind not in "fiu" or not np.isfinite(value).all():
                what = f"dtype {value.dtype}" if value.dtype.kind not in "fiu" else "values that are not finite"
                raise SnapshotStoreError(f"{self.store.path}: step {result.step} of trajectory {self.trajectory!r} "
                                         f"has {key!r} with {what}; only real finite numbers are stored")
            buffers[key][row] = value
        buffers["t"][row], buffers["step"][row] = result.t, result.step
        self._last, self._last_step = result, result.step
        self._buffered += 1
        if (self._length + self._buffered) % self.chunk_steps == 0:
            self._commit()

    def _value(self, result, key):
        if key == "u":
            return np.asarray(self.inputs(result.t), dtype=float).ravel()
        if key == "y":
            return np.asarray(self.system.outputs(result.q)).ravel()
        value = getattr(result, key)
        if value is None:
            raise SnapshotStoreError(f"{self.store.path}: step {result.step} has no {key!r} "
                                     "(e.g. ImplicitMidpoint with accelerations=False); "
                                     "create the store without it")
        return value

    def _commit_initial(self, result) -> None:
        """Checkpoint the first state received, so even a run killed before its first chunk resumes."""
        self._write_checkpoint(0, result)
        self._flush()
        _write_rows(self._committed, 0, np.array([self._length, 0], dtype=np.int64))
        self._flush()
        self._slot = 0

    def _commit(self) -> None:
        k = self._buffered
        if k == 0:
            return
        self._check_room()
        start, stop = self._length, self._length + k
        for key, ds in self._rows.items():
            ds.resize(stop, axis=0)
            _write_rows(ds, start, self._buffers[key][:k])
        slot = 1 - self._slot  # the slot the committed record does not point to
        self._write_checkpoint(slot, self._last)
        self._flush()
        _write_rows(self._committed, 0, np.array([stop, slot], dtype=np.int64))
        self._flush()
        self._length, self._slot, self._buffered = stop, slot, 0

    def _check_room(self) -> None:
        """Refuse a commit the disk or the file-size limit cannot take, before HDF5 writes any of it.

        A write that fails inside HDF5 leaves its library state broken (measured: a raw
        ``RuntimeError`` "file write failed ... File too large", then a segmentation fault
        when the file is closed, and a file cut at the limit that no reader opens). Checked
        here instead: the whole chunks of this commit (HDF5 allocates chunks whole) plus
        :data:`METADATA_MARGIN` for its index and headers, against the free space of the
        file system and ``RLIMIT_FSIZE``. Nothing is written when it does not fit: the
        committed snapshots stay readable and the store opens afterwards.
        """
        need = METADATA_MARGIN + sum(int(buffer[:1].nbytes) * self.chunk_steps for buffer in self._buffers.values())
        path = self.store.path
        size = os.path.getsize(path)
        free = None
        try:
            stats = os.statvfs(path)
            free = stats.f_bavail * stats.f_frsize
        except OSError:          # pragma: no cover - a file system without statvfs
            pass
        limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0] if resource is not None else None
        if free is not None and free < need:
            raise SnapshotStoreError(f"{path}: disk full: trajectory {self.trajectory!r} needs {need} bytes for its "
                                     f"next {self._buffered} steps, {free} are free; its {self._length} committed "
                                     "steps are kept")
        if limit is not None and limit != resource.RLIM_INFINITY and size + need > limit:
            raise SnapshotStoreError(f"{path}: file size limit {limit} bytes reached (RLIMIT_FSIZE): trajectory "
                                     f"{self.trajectory!r} needs {need} more; its {self._length} committed steps "
                                     "are kept")

    def _write_checkpoint(self, slot: int, result) -> None:
        ck = self._checkpoint
        _write_rows(ck["step"], slot, np.array([result.step], dtype=np.int64))
        _write_rows(ck["t"], slot, np.array([result.t], dtype=float))
        _write_rows(ck["has_a"], slot, np.array([result.a is not None], dtype=np.int8))
        _write_rows(ck["q"], slot, result.q[None])
        _write_rows(ck["v"], slot, result.v[None])
        if result.a is not None:
            _write_rows(ck["a"], slot, result.a[None])
        nonlinear = self.system.nonlinear
        arrays = {} if nonlinear is None else nonlinear.checkpoint(result.state)
        if set(arrays) != set(self._state):
            raise SnapshotStoreError(f"{self.store.path}: checkpoint keys {sorted(arrays)} differ "
                                     f"from the initial state's {sorted(self._state)}")
        for key, value in arrays.items():
            ds = self._state[key]
            value = np.asarray(value)
            if value.shape != ds.shape[1:]:
                raise SnapshotStoreError(f"{self.store.path}: checkpoint array {key!r} has shape "
                                         f"{value.shape}, the initial state's {ds.shape[1:]}")
            _write_rows(ds, slot, value.astype(ds.dtype)[None])

    def _flush(self) -> None:
        f = self._group.file
        f.flush()
        if self.fsync:
            os.fsync(f.id.get_vfd_handle())

    def close(self) -> None:
        """Commit the buffered partial chunk and release the file (idempotent).

        When that commit cannot be made (:meth:`_check_room`), the file is released all
        the same and the error raised after: the committed steps stay readable.
        """
        if self._closed:
            return
        try:
            self._commit()
        finally:
            self._closed = True
            self.store._writer_closed()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _write_rows(ds, start: int, rows: np.ndarray) -> None:
    """``ds[start:start + len(rows)] = rows`` through the low-level API (3x less overhead).

    ``rows`` must have the dataset's dtype and trailing shape.
    """
    rows = np.ascontiguousarray(rows, dtype=ds.dtype)
    space = ds.id.get_space()
    space.select_hyperslab((start,) + (0,) * (rows.ndim - 1), rows.shape)
    ds.id.write(h5s.create_simple(rows.shape), space, rows)


def _new_name(trajectories, trajectory, path) -> str:
    if trajectory is None:
        taken = [int(name) for name in trajectories if name.isdigit()]
        return f"{max(taken, default=-1) + 1:03d}"
    name = trajectory_name(trajectory)
    if name in trajectories:
        raise SnapshotStoreError(f"{path}: trajectory {name!r} exists (use resume to continue it)")
    if "/" in name or not name:
        raise FemromValueError(f"invalid trajectory name {name!r}")
    return name
