r"""A snapshot store: trajectories of ``(q, v, a, u, y, t)`` in one HDF5 file.

The snapshot matrix of a field is ``X = [x_0, x_1, ..., x_{K-1}]``, an (n, K)
matrix whose columns are the states of every trajectory, one after another.
It never has to fit in memory: :meth:`SnapshotStore.iter_blocks` yields it as
(n, k) column blocks, each read from whole chunks on disk.
"""

from __future__ import annotations

import datetime
import os
import socket
import weakref
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import h5py
import numpy as np

import femrom
from femrom._errors import FemromTypeError, FemromValueError
from femrom.fem import Condensation
from femrom.integrators import StepResult, scheme_for
from femrom.snapshots import _format, _journal
from femrom.snapshots._errors import SnapshotStoreError
from femrom.snapshots._superblock import SuperblockError, clear_write_flags, read_superblock


def split_model(model_or_system):
    """``(model, system)`` from a :class:`~femrom.scene.FullOrderModel` or a bare system."""
    if hasattr(model_or_system, "system") and hasattr(model_or_system, "scene"):
        return model_or_system, model_or_system.system
    if hasattr(model_or_system, "mass") and hasattr(model_or_system, "n_dofs"):
        return None, model_or_system
    raise FemromTypeError(f"expected a FullOrderModel or a SecondOrderSystem, got "
                          f"{type(model_or_system).__name__}")


def trajectory_name(trajectory) -> str:
    """Trajectories are named ``"000"``, ``"001"``, ...; an int ``i`` means ``f"{i:03d}"``."""
    if isinstance(trajectory, (int, np.integer)):
        return f"{int(trajectory):03d}"
    return str(trajectory)


def _state_fields(model, system, fields) -> tuple[str, ...]:
    if fields is None:
        asked = model.scene.outputs.fields if model is not None else ()
        fields = ("q", *(_format.FIELD_KEYS[f] for f in asked if _format.FIELD_KEYS[f] != "q"))
    fields = tuple(dict.fromkeys(fields))
    unknown = [f for f in fields if f not in _format.STATE_FIELDS]
    if unknown:
        raise FemromValueError(f"unknown snapshot field {unknown[0]!r}; valid: "
                               f"{', '.join(_format.STATE_FIELDS)}")
    if "q" not in fields:
        raise FemromValueError("a snapshot store always keeps 'q'")
    return tuple(f for f in _format.STATE_FIELDS if f in fields)


class SnapshotStore:
    """Snapshots of one system in an HDF5 file: several trajectories, one layout.

    Make one with :meth:`create`, open one with :meth:`open`. Each field ``q``,
    ``v``, ``a`` of a trajectory is a (K, n) dataset chunked as (c, n): a
    chunk is ``c`` whole snapshot columns, so column blocks read contiguously.
    Rows past a trajectory's *declared length* are never read.

    Attributes
    ----------
    path : Path
    system : SecondOrderSystem or None
        Needed to write (inputs, outputs, nonlinear checkpoints) and to restore
        a nonlinear state from a checkpoint.
    """

    def __init__(self, path, *, system=None):
        self.path = Path(path)
        self.system = system
        self._file: h5py.File | None = None
        self._swmr_reader = False
        self._writer = None
        self._handle()
        if system is not None and system.n_dofs != self.n_dofs:
            raise SnapshotStoreError(f"{self.path}: store has {self.n_dofs} dofs, the system "
                                     f"{system.n_dofs}")

    # -- making and opening ----------------------------------------------
    @classmethod
    def create(cls, path, model_or_system, *, fields=None, scheme=None, dt: float | None = None,
               n_steps: int | None = None, units: dict | None = None,
               overwrite: bool = False, checksums: bool = True) -> "SnapshotStore":
        """Create an empty store for a system (or a built scene).

        Parameters
        ----------
        path : str or Path
        model_or_system : FullOrderModel or SecondOrderSystem
            A model also records the scene's TOML text, its scheme, ``dt`` and
            step count, and (by default) the fields its ``[outputs]`` lists.
        fields : tuple of str, optional
            Which of ``"q"``, ``"v"``, ``"a"`` to keep (``"q"`` always).
            Inputs ``u`` and outputs ``y`` are kept when the system has them.
        scheme : scheme or str, optional
            Default scheme name of the trajectories (a model's scene gives one).
        dt : float, optional
            Default time step of the trajectories.
        n_steps : int, optional
            Default planned number of steps (``resume`` runs up to it).
        units : dict, optional
            Units of the quantities; SI (:data:`DEFAULT_UNITS`) by default.
        overwrite : bool
            Replace an existing file (not one a live process is writing).
        checksums : bool
            A Fletcher-32 checksum per chunk of every trajectory's rows (HDF5's filter):
            a byte changed on disk is an error on reading, not a wrong number. On by
            default: it costs under 5 % of a streamed run's writing and reading
            (``benchmarks/store_checksums.py``).

        Notes
        -----
        The file is written under a temporary name in the same folder
        (``.<name>.<pid>.creating``) and renamed into place, so a process
        killed meanwhile leaves no store (or the old one, when overwriting)
        and at most that temporary file, never a partial store.
        """
        path = Path(path)
        model, system = split_model(model_or_system)
        fields = _state_fields(model, system, fields)
        if path.is_dir():
            raise SnapshotStoreError(f"{path}: is a folder, not a store file")
        if not path.parent.is_dir():
            raise SnapshotStoreError(f"{path}: its folder {path.parent} does not exist")
        if path.exists() and not overwrite:
            raise SnapshotStoreError(f"{path}: file exists (pass overwrite=True to replace it)")
        if path.exists():
            _refuse_live_writer(path)
        scene = None if model is None else model.scene
        if scene is not None:
            scheme = scheme_for(scene.time) if scheme is None else scheme
            dt = scene.time.dt if dt is None else dt
            n_steps = scene.time.n_steps if n_steps is None else n_steps
        if dt is not None and (isinstance(dt, bool) or not isinstance(dt, (int, float, np.floating))
                               or not np.isfinite(dt) or dt <= 0):
            raise SnapshotStoreError(f"{path}: dt must be a positive finite number, got {dt!r}")
        if n_steps is not None and (isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer))
                                    or n_steps < 0):
            raise SnapshotStoreError(f"{path}: n_steps must be a whole number >= 0, got {n_steps!r}")
        cond = system.condensation
        attrs = {
            "format": _format.FORMAT_NAME,
            "format_version": _format.FORMAT_VERSION,
            "femrom_version": femrom.__version__,
            "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "scene_name": "" if scene is None else scene.name,
            "scene_toml": "" if scene is None else scene.source_text,
            "units": _format.dumps(_format.DEFAULT_UNITS if units is None else units),
            "fields": _format.dumps(list(fields)),
            "n_dofs": system.n_dofs,
            "n_inputs": system.n_inputs,
            "n_outputs": system.n_outputs,
            "output_names": _format.dumps(list(system.output_names)),
            "system": _format.dumps(system.metadata),
            "checksums": bool(checksums),
        }
        if scheme is not None:
            attrs["scheme"] = getattr(scheme, "name", str(scheme))
        if dt is not None:
            attrs["dt"] = float(dt)
        if n_steps is not None:
            attrs["n_steps"] = int(n_steps)
        temporary = path.with_name(f".{path.name}.{os.getpid()}.creating")
        try:
            with _format.open_file(temporary, "w", libver="latest") as f:
                f.attrs.update(attrs)
                dofmap = f.create_group("dofmap")
                dofmap.attrs["n_total"] = cond.n_total
                dofmap.create_dataset("free", data=np.asarray(cond.free, dtype=np.int64))
                dofmap.create_dataset("fixed", data=np.asarray(cond.fixed, dtype=np.int64))
                f.create_group("trajectories")
            os.replace(temporary, path)
        except BaseException:
            temporary.unlink(missing_ok=True)
            raise
        _journal.journal_path(path).unlink(missing_ok=True)  # the replaced file's, if any
        return cls(path, system=system)

    @classmethod
    def open(cls, path, *, system=None) -> "SnapshotStore":
        """Open an existing store (read-only until a writer is made).

        Raises
        ------
        SnapshotStoreError
            Missing, not HDF5, truncated, foreign, wrong-shaped or inconsistent.
        """
        return cls(path, system=system)

    def _handle(self) -> h5py.File:
        if self._file is None:
            f, swmr = _open_for_reading(self.path)
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
        """Close the file (an open writer is closed first, keeping its data)."""
        if self._writer is not None:
            self._writer.close()
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self) -> str:
        return f"SnapshotStore({str(self.path)!r})"

    # -- writing -----------------------------------------------------------
    def writer(self, trajectory=None, *, chunk_steps: int | None = None, every: int = 1,
               n_steps: int | None = None, dt: float | None = None, scheme=None,
               fsync: bool = False, inputs=None):
        """A consumer that streams a run into a new trajectory; see :class:`SnapshotWriter`."""
        from femrom.snapshots._writer import SnapshotWriter

        return SnapshotWriter(self, trajectory, chunk_steps=chunk_steps, every=every,
                              n_steps=n_steps, dt=dt, scheme=scheme, fsync=fsync, inputs=inputs)

    def import_trajectory(self, source, trajectory, name=None, *, attrs: dict | None = None,
                          fsync: bool = False) -> str:
        """Copy one complete trajectory of another store (same dofs and fields) into this one.

        The copy is one layout change under the undo journal (:mod:`._journal`):
        a kill leaves this store with the trajectory or without it, never with a
        part. What :mod:`femrom.study`'s sweeps do with the stores their workers
        wrote, one per run.

        Parameters
        ----------
        source : str, Path or SnapshotStore
        trajectory : str or int
            The trajectory in ``source``.
        name : str, optional
            Its name here (default: the same).
        attrs : dict, optional
            Extra attributes of the copied trajectory (e.g. a sweep's parameters),
            values str, int, float or bool.

        Returns
        -------
        str
            The new trajectory's name.
        """
        other = source if isinstance(source, SnapshotStore) else SnapshotStore.open(source)
        try:
            name = trajectory_name(trajectory if name is None else name)
            if other.n_dofs != self.n_dofs or other.fields != self.fields:
                raise SnapshotStoreError(f"{other.path}: {other.n_dofs} dofs and fields {other.fields} do not "
                                         f"match {self.path}'s {self.n_dofs} and {self.fields}")
            if not other.is_complete(trajectory):
                raise SnapshotStoreError(f"{other.path}: trajectory {trajectory_name(trajectory)!r} is not complete")
            source_path = other.path
        finally:
            if other is not source:
                other.close()

        def change_layout(f) -> None:
            trajectories = f["trajectories"]
            if name in trajectories:
                raise SnapshotStoreError(f"{self.path}: trajectory {name!r} exists")
            src, _ = _open_for_reading(source_path)
            with src:
                f.copy(src["trajectories"][trajectory_name(trajectory)], trajectories, name=name)
            for key, value in (attrs or {}).items():
                trajectories[name].attrs[key] = value

        class _Import:  # this store's writer while the layout changes
            trajectory = name

        self._open_for_writing(_Import, change_layout, fsync=fsync)
        self._writer_closed()
        return name

    def _open_for_writing(self, writer, change_layout, *, fsync: bool = False) -> h5py.File:
        """Make ``writer`` this store's writer and return the file, open in SWMR write mode.

        First ``change_layout(f)`` creates or trims the writer's trajectory on
        the file ``f`` open read-write under an undo journal
        (:mod:`._journal`): if the process is killed or ``change_layout``
        raises, the file goes back to how it was. Then the file is reopened
        directly in SWMR write mode, so from then on a kill leaves a readable
        file. A killed writer's flags and unfinished changes are cleared first.
        """
        if self._writer is not None:
            raise SnapshotStoreError(f"{self.path}: trajectory {self._writer.trajectory!r} is "
                                     "still being written; close its writer first")
        key = _path_key(self.path)
        owner = _WRITING.get(key)
        if owner is not None and owner is not self:
            busy = getattr(owner._writer, "trajectory", "?")
            raise SnapshotStoreError(f"{self.path}: is open for writing by another SnapshotStore of this process "
                                     f"(trajectory {busy!r}); close that writer first")
        if self._file is not None:
            self._file.close()
            self._file = None
        self._recover()
        with _journal.journaled_file(self.path, fsync=fsync) as f:
            with self._guard("checking the layout"):
                _format.check_store(f, self.path)
            f.attrs["writer_pid"] = os.getpid()
            f.attrs["writer_host"] = socket.gethostname()
            change_layout(f)
        f = _format.open_swmr_writer(self.path)
        self._file, self._swmr_reader, self._writer = f, False, writer
        _WRITING[key] = self
        return f

    def _writer_closed(self) -> None:
        key = _path_key(self.path)
        if _WRITING.get(key) is self:
            del _WRITING[key]
        self._writer = None
        if self._file is not None:
            self._file.close()
            self._file = None

    def _recover(self) -> None:
        """Undo a killed writer's unfinished layout change and clear its "open for write"
        flags, after checking it is gone."""
        _journal.roll_back(self.path, _process_alive, other_host_is_gone=True)
        try:
            block = read_superblock(self.path)
        except SuperblockError:
            return  # not a version-3 superblock: opening it reports what is wrong
        if not block.open_for_write:
            return
        pid = _live_writer(self.path)
        if pid is not None:
            raise SnapshotStoreError(f"{self.path}: is open for writing by process {pid}")
        clear_write_flags(self.path)

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
    f, _ = _open_for_reading(path)
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


def _open_for_reading(path: Path) -> tuple[h5py.File, bool]:
    """:func:`_format.open_for_reading`; the store as it was before a killed writer's unfinished
    layout change, if one is pending (read through the journal, the file left untouched)."""
    if path.is_dir():
        raise SnapshotStoreError(f"{path}: is a folder, not a store file")
    change = _journal.pending_change(path, _process_alive)
    if change is None:
        return _format.open_for_reading(path)
    try:
        return h5py.File(change.view(), "r"), False
    except (OSError, ValueError) as exc:
        raise SnapshotStoreError(f"{path}: {_format.hdf5_message(exc)} (read as before the unfinished "
                                 f"change of {change.journal})") from None


def recover(path) -> bool:
    """Undo the unfinished layout change a killed writer left in the store at ``path``.

    Readers never modify a store: they read it as it was before such a change, and
    the next writer undoes it. This does it now (e.g. before copying the file
    alone). Returns whether there was a change to undo.

    Raises
    ------
    SnapshotStoreError
        The change's process is still running, or the file cannot be written.
    """
    path = Path(path)
    if not path.exists():
        raise SnapshotStoreError(f"snapshot store not found: {path}")
    return _journal.roll_back(path, _process_alive, other_host_is_gone=True)


def _live_writer(path: Path) -> int | None:
    """The pid of the live process on this host that a store open for writing names, else ``None``.

    Raises :class:`SnapshotStoreError` if the file cannot be opened.
    """
    f, _ = _format.open_for_reading(path)
    with f:
        pid, host = f.attrs.get("writer_pid"), _format.text(f.attrs.get("writer_host", ""))
    if pid is not None and host == socket.gethostname():
        if int(pid) == os.getpid() and _path_key(path) in _WRITING:
            return int(pid)
        if _process_alive(int(pid)):
            return int(pid)
    return None


def _refuse_live_writer(path: Path) -> None:
    """Raise if a live process is writing the file at ``path`` or changing its layout."""
    _journal.roll_back(path, _process_alive, other_host_is_gone=True)
    try:
        if not read_superblock(path).open_for_write:
            return
        pid = _live_writer(path)
    except (SuperblockError, SnapshotStoreError, OSError):
        return  # not a file a femrom writer has open
    if pid is not None:
        raise SnapshotStoreError(f"{path}: is open for writing by process {pid}")


def _readonly(x: np.ndarray) -> np.ndarray:
    x = np.array(x, dtype=float)
    x.setflags(write=False)
    return x


#: The store objects of this process that hold a writer, by file (a second one is refused: two
#: writers in one process would change the layout under each other, and the file's "open for
#: write" flags name this process, which recovery could not tell from a dead one).
_WRITING: "weakref.WeakValueDictionary[str, SnapshotStore]" = weakref.WeakValueDictionary()


def _path_key(path: Path) -> str:
    return os.path.realpath(path)


def _process_alive(pid: int) -> bool:
    if pid == os.getpid():      # this process: a writer of its own is known in _WRITING, so the flags are stale
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
