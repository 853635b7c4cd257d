"""A store's writers, live or killed: which process writes a store, reading a store as it was
before a killed writer's unfinished change, and undoing that change.

A writer changes a store's layout under an undo journal (:mod:`._journal`) and then
writes in HDF5's SWMR mode, which sets "open for write" flags in the superblock
(:mod:`._superblock`). A process killed meanwhile leaves the journal and the flags;
they name its pid and host. Readers never modify the file: they read it through the
journal (:func:`open_committed`). The next writer, or :func:`recover`, checks that the
process is gone, rolls the change back and clears the flags. One process holds at most
one writer per file (:data:`WRITING`).
"""

from __future__ import annotations

import os
import socket
import warnings
import weakref
from pathlib import Path

import h5py

from femrom.snapshots import _format, _journal
from femrom.snapshots._errors import SnapshotStoreError
from femrom.snapshots._superblock import SuperblockError, clear_write_flags, read_superblock


class PendingChangeWarning(UserWarning):
    """A store is read as it was before a killed writer's unfinished change (its undo journal is
    still beside it)."""


def open_committed(path: Path) -> tuple[h5py.File, bool]:
    """:func:`_format.open_for_reading`; the store as it was before a killed writer's unfinished
    layout change, if one is pending (read through the journal, the file left untouched).
    Returns ``(file, swmr)``."""
    if path.is_dir():
        raise SnapshotStoreError(f"{path}: is a folder, not a store file")
    change = _journal.pending_change(path, _process_alive)
    if change is None:
        return _format.open_for_reading(path)
    warnings.warn(f"{path}: a writer (process {change.header.pid}) was killed while changing the store's "
                  f"layout; reading the store as it was before that change (the next writer, or "
                  f"femrom.snapshots.recover, undoes it and deletes {change.journal.name})",
                  PendingChangeWarning, stacklevel=3)
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


def recover_killed_writer(path: Path) -> None:
    """Undo a killed writer's unfinished layout change and clear its "open for write"
    flags, after checking it is gone (a live one is a SnapshotStoreError)."""
    _journal.roll_back(path, _process_alive, other_host_is_gone=True)
    try:
        block = read_superblock(path)
    except SuperblockError:
        return  # not a version-3 superblock: opening it reports what is wrong
    if not block.open_for_write:
        return
    pid = live_writer(path)
    if pid is not None:
        raise SnapshotStoreError(f"{path}: is open for writing by process {pid}")
    clear_write_flags(path)


def live_writer(path: Path) -> int | None:
    """The pid of the live process on this host that a store open for writing names, else ``None``.

    Raises :class:`SnapshotStoreError` if the file cannot be opened.
    """
    f, _ = _format.open_for_reading(path)
    with f:
        pid, host = f.attrs.get("writer_pid"), _format.text(f.attrs.get("writer_host", ""))
    if pid is not None and host == socket.gethostname():
        if int(pid) == os.getpid() and path_key(path) in WRITING:
            return int(pid)
        if _process_alive(int(pid)):
            return int(pid)
    return None


def refuse_live_writer(path: Path) -> None:
    """Raise if a live process is writing the file at ``path`` or changing its layout."""
    _journal.roll_back(path, _process_alive, other_host_is_gone=True)
    try:
        if not read_superblock(path).open_for_write:
            return
        pid = live_writer(path)
    except (SuperblockError, SnapshotStoreError, OSError):
        return  # not a file a femrom writer has open
    if pid is not None:
        raise SnapshotStoreError(f"{path}: is open for writing by process {pid}")


#: The store objects of this process that hold a writer, by file (a second one is refused: two
#: writers in one process would change the layout under each other, and the file's "open for
#: write" flags name this process, which recovery could not tell from a dead one).
WRITING: "weakref.WeakValueDictionary[str, object]" = weakref.WeakValueDictionary()


def path_key(path: Path) -> str:
    """The key of a store file in :data:`WRITING`: its real path."""
    return os.path.realpath(path)


def _process_alive(pid: int) -> bool:
    if pid == os.getpid():      # this process: a writer of its own is known in WRITING, so the flags are stale
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
