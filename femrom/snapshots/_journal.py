r"""An undo journal for the moments when a store's HDF5 metadata changes in place.

Adding a trajectory (or resuming one) creates groups and datasets, resizes
datasets and writes attributes. HDF5 can do that only outside SWMR mode, and
it then flushes its metadata in no particular order, rewriting existing
objects in place (the superblock, the root and ``/trajectories`` headers).
Measured (tests/test_snapshots.py): adding a trajectory to a store took 55
writes, 11 of them over old bytes, and a kill at 52 of 91 moments of it would
have left a file that does not open or has lost its old trajectory.

So those changes go through :func:`journaled_file`: an ``h5py.File`` on
h5py's ``fileobj`` driver whose file object, before it overwrites any byte
the file had when the change began, appends the old bytes to
``<store>.journal``. Growth past the old end needs no record. Closing the
HDF5 file and then deleting the journal commits the change. Whoever opens the
store next and finds a journal whose process is gone (:func:`roll_back`)
writes the saved bytes back in reverse order, truncates the file to its old
size and deletes the journal. A kill anywhere in a change therefore leaves
the store as it was before the change or as it is after it, nothing in
between.

Journal layout (little-endian)::

    header   magic b"FEMROMUJ", version u32, pid u64, old size u64,
             st_dev u64, st_ino u64, host length u16, host (UTF-8)
    records  offset u64, length u64, the old bytes (length)

A record is complete in the journal before its overwrite starts, so a record
cut short by a kill belongs to an overwrite that never began and is ignored.
Rolling back is idempotent: killed during a roll back, the journal stays and
the next roll back writes the same bytes again. (POSIX: ``os.pread``,
``os.pwrite``, ``flock``.) The file identity (device,
inode) makes a journal left next to a file that has since been replaced
(``SnapshotStore.create(..., overwrite=True)``) recognisably stale.
"""

from __future__ import annotations

import io
import os
import socket
import struct
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import h5py

from femrom.snapshots._errors import SnapshotStoreError

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no advisory lock taken
    fcntl = None

MAGIC = b"FEMROMUJ"
VERSION = 1
_HEADER = struct.Struct("<8sIQQQQH")
_RECORD = struct.Struct("<QQ")


def journal_path(path: Path) -> Path:
    """Where the undo journal of the store at ``path`` lives: ``<path>.journal``."""
    return path.with_name(path.name + ".journal")


@dataclass(frozen=True)
class JournalHeader:
    pid: int
    host: str
    old_size: int
    device: int
    inode: int


def _lock(fd: int, path: Path) -> None:
    """Take the exclusive lock HDF5 takes for writing (``flock``), unless
    ``HDF5_USE_FILE_LOCKING=FALSE``: a process reading the file without SWMR holds a
    shared lock, and its view would go stale under the change."""
    if fcntl is None or os.environ.get("HDF5_USE_FILE_LOCKING", "").strip().upper() in ("FALSE", "0"):
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        raise SnapshotStoreError(f"{path}: is open elsewhere (file locked by another process "
                                 "or handle); close it there first") from None


def _pwrite_all(fd: int, data: bytes, offset: int) -> None:
    view = memoryview(data)
    while view:
        written = os.pwrite(fd, view, offset)
        view, offset = view[written:], offset + written


class UndoJournalFile(io.RawIOBase):
    """A read-write file object that journals the old bytes before every overwrite.

    What h5py's ``fileobj`` driver needs (``readinto``, ``write``, ``seek``,
    ``tell``, ``truncate``, ``flush``), on an unbuffered file descriptor.
    Writes at or past ``old_size`` (the size when the journal began) are not
    journaled: rolling back truncates them away.

    Parameters
    ----------
    path : Path
        The store, opened read-write.
    fsync : bool
        ``fsync`` the journal before every overwrite it protects (power loss,
        not just a killed process).

    Attributes
    ----------
    writes : int
        Writes to the store so far.
    """

    def __init__(self, path: Path, *, fsync: bool = False):
        super().__init__()
        self.path = Path(path)
        self.fsync = bool(fsync)
        self._fd = os.open(self.path, os.O_RDWR)
        self._journal_fd = None
        self._position = 0
        self.writes = 0
        try:
            _lock(self._fd, self.path)
            stat = os.fstat(self._fd)
            self.old_size = stat.st_size
            journal = journal_path(self.path)
            self._journal_fd = os.open(journal, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            host = socket.gethostname().encode()
            header = _HEADER.pack(MAGIC, VERSION, os.getpid(), self.old_size, stat.st_dev,
                                  stat.st_ino, len(host)) + host
            os.write(self._journal_fd, header)
            self._sync_journal()
        except FileExistsError:
            os.close(self._fd)
            raise SnapshotStoreError(f"{self.path}: another change is in progress (undo journal "
                                     f"{journal_path(self.path)} exists)") from None
        except BaseException:
            os.close(self._fd)
            raise

    # -- the io.RawIOBase protocol -------------------------------------------
    def readable(self) -> bool:
        return True

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        if whence == io.SEEK_SET:
            self._position = offset
        elif whence == io.SEEK_CUR:
            self._position += offset
        else:
            self._position = os.fstat(self._fd).st_size + offset
        return self._position

    def tell(self) -> int:
        return self._position

    def readinto(self, buffer) -> int:
        data = os.pread(self._fd, len(buffer), self._position)
        buffer[:len(data)] = data
        self._position += len(data)
        return len(data)

    def write(self, data) -> int:
        data = bytes(data)
        self.writes += 1
        self._save(self._position, min(self._position + len(data), self.old_size))
        _pwrite_all(self._fd, data, self._position)
        self._position += len(data)
        return len(data)

    def truncate(self, size: int | None = None) -> int:
        size = self._position if size is None else int(size)
        self._save(size, self.old_size)
        os.ftruncate(self._fd, size)
        return size

    def flush(self) -> None:
        pass  # unbuffered: every write is already in the operating system

    def close(self) -> None:
        if not self.closed:
            os.close(self._fd)
            if self._journal_fd is not None:
                os.close(self._journal_fd)
        super().close()

    # -- journaling ---------------------------------------------------------------
    def _save(self, start: int, stop: int) -> None:
        """Append the current bytes [start, stop) of the file to the journal (if any)."""
        if stop <= start:
            return
        old = os.pread(self._fd, stop - start, start)
        os.write(self._journal_fd, _RECORD.pack(start, len(old)) + old)
        self._sync_journal()

    def _sync_journal(self) -> None:
        if self.fsync:
            os.fsync(self._journal_fd)

    def commit(self) -> None:
        """Close, and delete the journal: the change is final (after the HDF5 file is closed)."""
        if self.fsync:
            os.fsync(self._fd)
        self.close()
        journal_path(self.path).unlink()


@contextmanager
def journaled_file(path: Path, *, fsync: bool = False) -> Iterator[h5py.File]:
    """``h5py.File(path, "r+")`` whose every change can be undone until the block ends.

    Leaving the block normally closes the file and commits (deletes the
    journal); an exception rolls the file back to how it was and re-raises.
    """
    path = Path(path)
    journal = UndoJournalFile(path, fsync=fsync)
    try:
        try:
            f = h5py.File(journal, "r+", libver="latest")
        except (OSError, ValueError) as exc:
            from femrom.snapshots._format import hdf5_message

            raise SnapshotStoreError(f"{path}: {hdf5_message(exc)}") from None
        try:
            yield f
        finally:
            f.close()
    except BaseException:
        journal.close()
        _undo(path, journal_path(path))
        raise
    journal.commit()


def read_header(journal: Path) -> tuple[JournalHeader, int] | None:
    """The header of ``journal`` and where its records start (``None``: cut short)."""
    data = journal.read_bytes()[:_HEADER.size + 2**16]
    if len(data) < _HEADER.size:
        return None
    magic, version, pid, old_size, device, inode, host_length = _HEADER.unpack_from(data)
    if magic != MAGIC or version != VERSION:
        raise SnapshotStoreError(f"{journal}: not a femrom undo journal")
    end = _HEADER.size + host_length
    if len(data) < end:
        return None
    return JournalHeader(pid, data[_HEADER.size:end].decode(), old_size, device, inode), end


def _undo(path: Path, journal: Path) -> None:
    """Write the journaled bytes back (last record first), truncate, delete the journal."""
    parsed = read_header(journal)
    if parsed is not None:
        header, position = parsed
        data = journal.read_bytes()
        records = []
        while position + _RECORD.size <= len(data):
            offset, length = _RECORD.unpack_from(data, position)
            position += _RECORD.size
            if position + length > len(data):
                break  # cut short by a kill: its overwrite never started
            records.append((offset, data[position:position + length]))
            position += length
        fd = os.open(path, os.O_RDWR)
        try:
            for offset, old in reversed(records):
                _pwrite_all(fd, old, offset)
            os.ftruncate(fd, header.old_size)
            os.fsync(fd)
        finally:
            os.close(fd)
    journal.unlink()


def roll_back(path: Path, process_alive: Callable[[int], bool], *,
              other_host_is_gone: bool = False) -> bool:
    """Undo a change that a killed process left unfinished; ``True`` if there was one.

    A journal without a complete header was cut short before its change
    wrote anything; a journal from a different file (replaced since) is
    stale. Both are deleted.

    Parameters
    ----------
    path : Path
        The store.
    process_alive : callable
        ``process_alive(pid)`` for a process on this host.
    other_host_is_gone : bool
        Whether a change made from another host may be undone (its process
        cannot be checked from here). Writers, who take the file over, say
        yes, as they do for a killed writer's flags; readers say no.

    Raises
    ------
    SnapshotStoreError
        The journal's process is still running (or, for a reader, ran on
        another host), or the file cannot be written.
    """
    path = Path(path)
    journal = journal_path(path)
    if not journal.exists():
        return False
    try:
        parsed = read_header(journal)
        if parsed is None:
            journal.unlink()
            return False
        header, _ = parsed
        stat = path.stat()
        if (header.device, header.inode) != (stat.st_dev, stat.st_ino):
            journal.unlink()
            return False
        if header.host == socket.gethostname() and process_alive(header.pid):
            raise SnapshotStoreError(f"{path}: process {header.pid} is adding or resuming a "
                                     "trajectory; open it when that is done")
        if header.host != socket.gethostname() and not other_host_is_gone:
            raise SnapshotStoreError(f"{path}: process {header.pid} on host {header.host} was "
                                     "adding or resuming a trajectory and has not finished; open "
                                     "the store on that host, or for writing, to undo that change")
        _undo(path, journal)
    except FileNotFoundError:
        return False  # rolled back by someone else meanwhile
    except PermissionError:
        raise SnapshotStoreError(f"{path}: a writer was killed while changing the file's layout "
                                 f"and its undo journal {journal} cannot be applied: permission "
                                 "denied") from None
    return True
