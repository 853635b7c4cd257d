"""A snapshot store: trajectories of ``(q, v, a, u, y, t)`` in one HDF5 file, made and written.

:class:`SnapshotStore` creates a store (under a temporary name, renamed into place),
opens one, and hands out its one writer (:class:`~femrom.snapshots.SnapshotWriter`,
:mod:`._writer`) or copies another store's trajectory in, each layout change under
the undo journal (:mod:`._journal`, :mod:`._recovery`). Reading is
:class:`~femrom.snapshots._reading.StoreReader`'s.
"""

from __future__ import annotations

import datetime
import os
import socket
from pathlib import Path

import h5py
import numpy as np

import femrom
from femrom._errors import FemromTypeError, FemromValueError
from femrom.integrators import scheme_for
from femrom.snapshots import _format, _journal
from femrom.snapshots._errors import SnapshotStoreError
from femrom.snapshots._format import trajectory_name
from femrom.snapshots._reading import StoreReader
from femrom.snapshots._recovery import (WRITING, open_committed, path_key, recover_killed_writer,
                                        refuse_live_writer)
from femrom.snapshots._writer import SnapshotWriter


def split_model(model_or_system):
    """``(model, system)`` from a :class:`~femrom.scene.FullOrderModel` or a bare system."""
    if hasattr(model_or_system, "system") and hasattr(model_or_system, "scene"):
        return model_or_system, model_or_system.system
    if hasattr(model_or_system, "mass") and hasattr(model_or_system, "n_dofs"):
        return None, model_or_system
    raise FemromTypeError(f"expected a FullOrderModel or a SecondOrderSystem, got "
                          f"{type(model_or_system).__name__}")


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


class SnapshotStore(StoreReader):
    """Snapshots of one system in an HDF5 file: several trajectories, one layout.

    Make one with :meth:`create`, open one with :meth:`open`. Each field ``q``,
    ``v``, ``a`` of a trajectory is a (K, n) dataset chunked as (c, n): a
    chunk is ``c`` whole snapshot columns, so column blocks read contiguously.
    Rows past a trajectory's *declared length* are never read. The reading
    methods are those of :class:`~femrom.snapshots._reading.StoreReader`.

    Attributes
    ----------
    path : Path
    system : SecondOrderSystem or None
        Needed to write (inputs, outputs, nonlinear checkpoints) and to restore
        a nonlinear state from a checkpoint.
    """

    def __init__(self, path, *, system=None):
        self._writer = None
        super().__init__(path, system=system)

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
            refuse_live_writer(path)
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
            attrs["scheme"] = getattr(scheme, "label", str(scheme))
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

    def close(self) -> None:
        """Close the file (an open writer is closed first, keeping its data)."""
        if self._writer is not None:
            self._writer.close()
        super().close()

    def __repr__(self) -> str:
        return f"SnapshotStore({str(self.path)!r})"

    # -- writing -----------------------------------------------------------
    def writer(self, trajectory=None, *, chunk_steps: int | None = None, every: int = 1,
               n_steps: int | None = None, dt: float | None = None, scheme=None,
               fsync: bool = False, inputs=None):
        """A consumer that streams a run into a new trajectory; see :class:`SnapshotWriter`."""
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
            src, _ = open_committed(source_path)
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
        key = path_key(self.path)
        owner = WRITING.get(key)
        if owner is not None and owner is not self:
            busy = getattr(owner._writer, "trajectory", "?")
            raise SnapshotStoreError(f"{self.path}: is open for writing by another SnapshotStore of this process "
                                     f"(trajectory {busy!r}); close that writer first")
        if self._file is not None:
            self._file.close()
            self._file = None
        recover_killed_writer(self.path)
        with _journal.journaled_file(self.path, fsync=fsync) as f:
            with self._guard("checking the layout"):
                _format.check_store(f, self.path)
            f.attrs["writer_pid"] = os.getpid()
            f.attrs["writer_host"] = socket.gethostname()
            change_layout(f)
        f = _format.open_swmr_writer(self.path)
        self._file, self._swmr_reader, self._writer = f, False, writer
        WRITING[key] = self
        return f

    def _writer_closed(self) -> None:
        key = path_key(self.path)
        if WRITING.get(key) is self:
            del WRITING[key]
        self._writer = None
        if self._file is not None:
            self._file.close()
            self._file = None
