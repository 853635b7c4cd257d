"""Results that appear whole or not at all: a run writes into a staging folder renamed into place.

:func:`staged_output` checks the target before anything is computed (a file in its
place, a parent that cannot be written), locks it against a second run into the same
folder (an ``fcntl`` lock on ``.<name>.lock`` beside it, released when the process
ends however it ends), hands out a fresh staging folder beside it, and on success
swaps the staging folder in (an existing target is renamed aside first and removed
after). On any failure, disk full included, the staging folder is removed and the
previous results stay as they were.
"""

from __future__ import annotations

import os
import shutil
from contextlib import contextmanager
from pathlib import Path

from femrom._errors import FemromValueError

try:
    import fcntl
except ImportError:  # pragma: no cover - not on Linux
    fcntl = None


class OutputFolderError(FemromValueError):
    """The output folder cannot take the results (one line naming it)."""


@contextmanager
def staged_output(target):
    """``with staged_output(out) as folder:`` write everything into ``folder``; it becomes ``out`` at the end.

    Raises
    ------
    OutputFolderError
        ``out`` is a file, its parent cannot be created or written, or another
        process is writing results into it now.
    """
    target = Path(target)
    if target.exists() and not target.is_dir():
        raise OutputFolderError(f"{target}: exists and is not a folder")
    parent = target.parent if str(target.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputFolderError(f"{target}: its folder {parent} cannot be created ({exc.strerror})") from None
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputFolderError(f"{target}: its folder {parent} is not writable")
    lock_path = parent / f".{target.name}.lock"
    lock = open(lock_path, "a+")
    held = False
    try:
        if fcntl is not None:
            try:
                fcntl.flock(lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise OutputFolderError(f"{target}: another run is writing its results there now") from None
        held = True
        staging = parent / f".{target.name}.{os.getpid()}.staging"
        shutil.rmtree(staging, ignore_errors=True)
        staging.mkdir()
        try:
            yield staging
            old = parent / f".{target.name}.{os.getpid()}.old"
            if target.exists():
                os.replace(target, old)
            os.replace(staging, target)
            shutil.rmtree(old, ignore_errors=True)
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
    finally:
        if held:          # only the holder removes it, after its results are in place
            lock_path.unlink(missing_ok=True)
        lock.close()
