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
             st_dev u64, st_ino u64, fingerprint (16 bytes), host length u16,
             host (UTF-8)
    records  offset u64, length u64, the old bytes (length)

A record is complete in the journal before its overwrite starts, so a record
cut short by a kill belongs to an overwrite that never began and is ignored.
Rolling back is idempotent: killed during a roll back, the journal stays and
the next roll back writes the same bytes again. (POSIX: ``os.pread``,
``os.pwrite``, ``flock``.) The file identity (device,
inode) makes a journal left next to a file that has since been replaced
(``SnapshotStore.create(..., overwrite=True)``) recognisably stale. A copy of
the store taken together with its journal (a backup restored, an rsync) has
another inode; it is recognised by content instead: the journal holds a
fingerprint (BLAKE2b) of the file's first and last ``FINGERPRINT_SPAN`` bytes
when the change began, and the journal belongs to a file whose bytes there,
with the journal's records written back, give that fingerprint again.

Only writers roll back (:func:`roll_back`). A reader never modifies the file: it
reads the store as it was before the unfinished change through
:class:`UndoneView`, the file's bytes with the journal's records laid over them
(:func:`pending_change`).
"""

from __future__ import annotations

import hashlib
import io
import os
import socket
import weakref
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
VERSION = 2
_HEADER = struct.Struct("<8sIQQQQ16sH")
#: Bytes at each end of the file that the fingerprint covers.
FINGERPRINT_SPAN = 65536
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
    fingerprint: bytes


def _spans(size: int) -> list[tuple[int, int]]:
    """The byte ranges ``[start, stop)`` the fingerprint of a file of ``size`` bytes covers."""
    head = (0, min(size, FINGERPRINT_SPAN))
    tail = (max(head[1], size - FINGERPRINT_SPAN), size)
    return [head] + ([tail] if tail[1] > tail[0] else [])


def _fingerprint(read: Callable[[int, int], bytes], size: int) -> bytes:
    """BLAKE2b (16 bytes) of the size and the fingerprinted ranges, read by ``read(start, stop)``."""
    digest = hashlib.blake2b(size.to_bytes(8, "little"), digest_size=16)
    for start, stop in _spans(size):
        digest.update(read(start, stop))
    return digest.digest()


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
            fingerprint = _fingerprint(lambda a, b: os.pread(self._fd, b - a, a), self.old_size)
            header = _HEADER.pack(MAGIC, VERSION, os.getpid(), self.old_size, stat.st_dev,
                                  stat.st_ino, fingerprint, len(host)) + host
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
    magic, version, pid, old_size, device, inode, fingerprint, host_length = _HEADER.unpack_from(data)
    if magic != MAGIC or version != VERSION:
        raise SnapshotStoreError(f"{journal}: not a femrom undo journal (version {VERSION})")
    end = _HEADER.size + host_length
    if len(data) < end:
        return None
    return JournalHeader(pid, data[_HEADER.size:end].decode(errors="replace"), old_size, device, inode,
                         fingerprint), end


def _records(data: bytes, position: int) -> tuple:
    """The complete records of a journal's bytes from ``position``: ``((offset, old bytes), ...)``."""
    records = []
    while position + _RECORD.size <= len(data):
        offset, length = _RECORD.unpack_from(data, position)
        position += _RECORD.size
        if position + length > len(data):
            break  # cut short by a kill: its overwrite never started
        records.append((offset, data[position:position + length]))
        position += length
    return tuple(records)


@dataclass(frozen=True)
class PendingChange:
    """The journal of an unfinished layout change of the store at ``path``.

    Attributes
    ----------
    path, journal : Path
    header : JournalHeader
    records : tuple of (int, bytes)
        The complete records, in journal order: ``(offset, bytes before the overwrite)``.
    """

    path: Path
    journal: Path
    header: JournalHeader
    records: tuple

    @classmethod
    def load(cls, path: Path) -> "PendingChange | None":
        """The journal next to ``path``; ``None`` if there is none or its header was cut short."""
        journal = journal_path(path)
        try:
            data = journal.read_bytes()
        except FileNotFoundError:
            return None
        parsed = read_header(journal) if data else None
        if parsed is None:
            return None
        header, position = parsed
        return cls(Path(path), journal, header, _records(data, position))

    def old_bytes(self, fd: int, start: int, stop: int) -> bytes:
        """The file's bytes ``[start, stop)`` (within the old size) as they were before the change."""
        stop = min(stop, self.header.old_size)
        if stop <= start:
            return b""
        data = bytearray(os.pread(fd, stop - start, start).ljust(stop - start, b"\0"))
        for offset, old in reversed(self.records):      # the first record of a byte holds its oldest value
            lo, hi = max(offset, start), min(offset + len(old), stop)
            if lo < hi:
                data[lo - start:hi - start] = old[lo - offset:hi - offset]
        return bytes(data)

    def belongs(self) -> bool:
        """Whether the journal is this file's: the same file (device, inode), or a copy of it
        (its bytes with the records written back give the journal's fingerprint)."""
        try:
            fd = os.open(self.path, os.O_RDONLY)
        except FileNotFoundError:
            return False
        try:
            stat = os.fstat(fd)
            if (self.header.device, self.header.inode) == (stat.st_dev, stat.st_ino):
                return True
            size = self.header.old_size
            return _fingerprint(lambda a, b: self.old_bytes(fd, a, b), size) == self.header.fingerprint
        finally:
            os.close(fd)

    def view(self) -> "UndoneView":
        """A read-only file object of the store as it was before the change (the file untouched)."""
        return UndoneView(self)

    def undo(self) -> None:
        """Write the old bytes back (last record first), truncate, ``fsync``, delete the journal."""
        fd = os.open(self.path, os.O_RDWR)
        try:
            for offset, old in reversed(self.records):
                _pwrite_all(fd, old, offset)
            os.ftruncate(fd, self.header.old_size)
            os.fsync(fd)
        finally:
            os.close(fd)
        self.journal.unlink()


class UndoneView(io.RawIOBase):
    """The store's bytes before an unfinished change, read-only: the file's bytes with the
    journal's records laid over them, cut at the old size (for ``h5py.File(view, "r")``)."""

    def __init__(self, change: PendingChange):
        super().__init__()
        self.change = change
        self._fd = os.open(change.path, os.O_RDONLY)
        self._closer = weakref.finalize(self, os.close, self._fd)
        self._position = 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        base = {io.SEEK_SET: 0, io.SEEK_CUR: self._position, io.SEEK_END: self.change.header.old_size}[whence]
        self._position = base + offset
        return self._position

    def tell(self) -> int:
        return self._position

    def readinto(self, buffer) -> int:
        data = self.change.old_bytes(self._fd, self._position, self._position + len(buffer))
        buffer[:len(data)] = data
        self._position += len(data)
        return len(data)

    def close(self) -> None:
        if not self.closed:
            self._closer()
        super().close()


def _undo(path: Path, journal: Path) -> None:
    """Undo the change of ``journal`` (a cut-short header: nothing to undo) and delete the journal."""
    change = PendingChange.load(path)
    if change is not None:
        change.undo()
    else:
        journal.unlink()


def _check_process(path: Path, header: JournalHeader, process_alive, other_host_is_gone: bool) -> None:
    if header.host == socket.gethostname() and process_alive(header.pid):
        raise SnapshotStoreError(f"{path}: process {header.pid} is adding or resuming a "
                                 "trajectory; open it when that is done")
    if header.host != socket.gethostname() and not other_host_is_gone:
        raise SnapshotStoreError(f"{path}: process {header.pid} on host {header.host} was "
                                 "adding or resuming a trajectory and has not finished; open "
                                 "the store on that host, or for writing, to undo that change")


def pending_change(path: Path, process_alive: Callable[[int], bool]) -> PendingChange | None:
    """For a reader: the unfinished change of a killed process to read around, else ``None``.

    Nothing is written: a journal cut short, or another file's, is left where it is.

    Raises
    ------
    SnapshotStoreError
        The journal's process is still running, or ran on another host.
    """
    path = Path(path)
    change = PendingChange.load(path)
    if change is None or not change.belongs():
        return None
    _check_process(path, change.header, process_alive, other_host_is_gone=False)
    return change


def roll_back(path: Path, process_alive: Callable[[int], bool], *,
              other_host_is_gone: bool = False) -> bool:
    """Undo a change that a killed process left unfinished; ``True`` if there was one.

    For writers, who take the file over. A journal without a complete header
    was cut short before its change wrote anything; a journal of another file
    (replaced since: neither the same file nor a copy of the one it protects) is
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
        yes, as they do for a killed writer's flags.

    Raises
    ------
    SnapshotStoreError
        The journal's process is still running (or ran on another host and
        ``other_host_is_gone`` is false), or the file cannot be written.
    """
    path = Path(path)
    journal = journal_path(path)
    if not journal.exists():
        return False
    try:
        change = PendingChange.load(path)
        if change is None or not change.belongs():
            journal.unlink()
            return False
        _check_process(path, change.header, process_alive, other_host_is_gone)
        change.undo()
    except FileNotFoundError:
        return False  # rolled back by someone else meanwhile
    except PermissionError:
        raise SnapshotStoreError(f"{path}: a writer was killed while changing the file's layout "
                                 f"and its undo journal {journal} cannot be applied: permission "
                                 "denied") from None
    return True
