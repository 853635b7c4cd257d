"""Column blocks of a snapshot matrix A (n, K) that never has to be in memory.

A *block source* is read one pass at a time, each pass yielding (n, b)
float64 column blocks of A in a fixed order. What can be turned into one
(:func:`as_block_source`):

- a 2-D array-like with ``shape`` and slicing (``ndarray``, ``np.memmap``,
  an ``h5py.Dataset`` stored as (n, K)): read as ``A[:, j:j + b]``;
- a :class:`femrom.snapshots.SnapshotStore`: its displacements, all
  trajectories in order (:func:`store_source` chooses the field, the
  trajectories and chunk-aligned blocks);
- an object with ``iter_blocks()`` returning a fresh iterator of blocks;
- a zero-argument callable returning a fresh iterator of blocks;
- a list or tuple of blocks;
- a one-shot iterator or generator: readable once, so only single-pass
  methods accept it.

Except for in-memory ndarrays, the next block is read by a background thread
while the current one is being used (``prefetch``, default 1 block ahead), so
reading a file overlaps with the products (numpy's BLAS releases the GIL).
"""

from __future__ import annotations

import queue
import threading
from typing import Any, Callable, Iterator

import numpy as np

from femrom._errors import FemromTypeError, FemromValueError

# Default block: about 128 MB of float64 columns, at least 32 columns (skinny blocks
# make the block products slow matrix-vector-like kernels).
_BLOCK_BYTES = 128 * 2**20
_MIN_BLOCK_COLUMNS = 32


def default_block_columns(n: int) -> int:
    """Columns per block so that an (n, b) float64 block is about 128 MB (b >= 32)."""
    return max(_MIN_BLOCK_COLUMNS, _BLOCK_BYTES // (8 * max(int(n), 1)))


def as_column_block(block: Any, n: int | None = None, *, finite: bool = True) -> np.ndarray:
    """One block as an (n, b) float64 array; a 1-D block is one column.

    Raises ``ValueError`` naming the bad shape when the block is not 1-D or
    2-D, or has a row count other than ``n``, and the bad entry when it is not a
    real (complex, bytes) or, with ``finite``, not a finite number (NaN or inf would
    otherwise surface as "SVD did not converge"). The finiteness check reads the
    whole block (half the cost of a block times a 14-column matrix, measured): a
    :class:`BlockSource` makes it on its first pass only.
    """
    raw = np.asarray(block)
    if raw.dtype.kind not in "fiu":
        raise FemromValueError(f"a block of snapshot columns must hold real numbers, got dtype {raw.dtype}")
    block = np.asarray(raw, dtype=np.float64)
    if block.ndim == 1:
        block = block[:, None]
    if block.ndim != 2:
        raise FemromValueError(f"a block of snapshot columns must be (n, b), got shape {block.shape}")
    if n is not None and block.shape[0] != n:
        raise FemromValueError(f"block has {block.shape[0]} rows, expected n = {n} "
                               "(blocks are columns of the (n, K) snapshot matrix)")
    if finite and not np.isfinite(block).all():
        row, column = np.argwhere(~np.isfinite(block))[0]
        raise FemromValueError(f"a block of snapshot columns is not finite: entry ({row}, {column}) of the block is "
                               f"{block[row, column]}")
    return block


class _Failure:
    def __init__(self, error: BaseException):
        self.error = error


_END = object()


def _read_ahead(blocks: Iterator[Any], depth: int) -> Iterator[Any]:
    """Iterate ``blocks`` with up to ``depth`` items read in advance by a thread."""
    items: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def put(item) -> bool:
        while not stop.is_set():
            try:
                items.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def reader() -> None:
        try:
            for item in blocks:
                item = np.asarray(item)          # read here; cast (and checked) by as_column_block
                if not put(item.astype(np.float64, copy=False) if item.dtype.kind in "fiu" else item):
                    return
            put(_END)
        except BaseException as error:  # handed to the consumer, raised there
            put(_Failure(error))

    thread = threading.Thread(target=reader, name="femrom-block-reader", daemon=True)
    thread.start()
    try:
        while True:
            item = items.get()
            if item is _END:
                return
            if isinstance(item, _Failure):
                raise item.error
            yield item
    finally:
        stop.set()
        thread.join()


class BlockSource:
    """Passes over the column blocks of an (n, K) snapshot matrix.

    Parameters
    ----------
    open_pass : callable
        ``open_pass()`` returns an iterator over the blocks of one pass.
    reiterable : bool
        Whether ``open_pass`` may be called more than once.
    n_rows : int or None
        Row count n when known up front.
    description : str
        What the source is, for error messages.
    prefetch : int
        Blocks read ahead by a background thread (0: read in the caller).

    Attributes
    ----------
    passes : int
        Number of passes opened so far.
    """

    def __init__(self, open_pass: Callable[[], Iterator[Any]], *, reiterable: bool,
                 n_rows: int | None = None, description: str = "block source",
                 prefetch: int = 0):
        self._open_pass = open_pass
        self.prefetch = max(0, int(prefetch))
        self.reiterable = bool(reiterable)
        self.n_rows = n_rows
        self.description = description
        self.passes = 0

    def blocks(self) -> Iterator[np.ndarray]:
        """Iterate over one pass: (n, b) float64 blocks, rows checked against n (and finite on the first pass)."""
        if self.passes >= 1 and not self.reiterable:
            raise FemromValueError(f"{self.description} can be read only once; pass a zero-argument "
                                   "callable returning a fresh iterator, or an object with iter_blocks()")
        self.passes += 1
        n = self.n_rows
        blocks = self._open_pass()
        if self.prefetch:
            blocks = _read_ahead(iter(blocks), self.prefetch)
        first = self.passes == 1         # the data do not change between passes: checked once
        for block in blocks:
            block = as_column_block(block, n, finite=first)
            if n is None:
                n = self.n_rows = block.shape[0]
            if block.shape[1]:
                yield block

    def require_passes(self, passes: int, method: str) -> None:
        """Raise if ``method`` needs more than one pass over a one-shot source."""
        if passes > 1 and not self.reiterable:
            raise FemromValueError(f"{method} reads the data {passes} times but {self.description} "
                                   "can be read only once; pass a zero-argument callable returning a "
                                   "fresh iterator, an object with iter_blocks(), or an array")


def _array_passes(array: Any, block_columns: int) -> Callable[[], Iterator[Any]]:
    n_columns = array.shape[1]

    def open_pass() -> Iterator[Any]:
        for start in range(0, n_columns, block_columns):
            yield array[:, start:start + block_columns]

    return open_pass


def as_block_source(data: Any, *, block_columns: int | None = None,
                    prefetch: int | None = None) -> BlockSource:
    """Wrap arrays, ``iter_blocks()`` objects, callables and iterators as a :class:`BlockSource`.

    Parameters
    ----------
    data : array-like (n, K), object with ``iter_blocks()``, callable, iterable or BlockSource
        The snapshot matrix or a way to read its column blocks (see module doc).
    block_columns : int, optional
        Columns per block when ``data`` is an array (default: about 128 MB
        per block, see :func:`default_block_columns`).
    prefetch : int, optional
        Blocks read ahead in a background thread; default 0 for an in-memory
        ndarray (nothing to read), 1 otherwise.

    Returns
    -------
    BlockSource
    """
    if isinstance(data, BlockSource):
        return data
    from femrom.snapshots import SnapshotStore

    if isinstance(data, SnapshotStore):
        return store_source(data, block_columns=block_columns,
                            prefetch=1 if prefetch is None else prefetch)
    ahead = (0 if isinstance(data, np.ndarray) else 1) if prefetch is None else int(prefetch)
    if hasattr(data, "shape") and hasattr(data, "__getitem__") and not callable(data):
        shape = tuple(data.shape)
        if len(shape) != 2:
            raise FemromValueError(f"snapshot array must be 2-D (n, K), got shape {shape}")
        b = default_block_columns(shape[0]) if block_columns is None else int(block_columns)
        if b < 1:
            raise FemromValueError(f"block_columns must be >= 1, got {block_columns}")
        return BlockSource(_array_passes(data, b), reiterable=True, n_rows=shape[0],
                           description=f"{type(data).__name__} of shape {shape}", prefetch=ahead)
    iter_blocks = getattr(data, "iter_blocks", None)
    if callable(iter_blocks):
        return BlockSource(iter_blocks, reiterable=True, prefetch=ahead,
                           description=f"{type(data).__name__}.iter_blocks()")
    if isinstance(data, (list, tuple)):
        return BlockSource(lambda: iter(data), reiterable=True, description="list of blocks")
    if hasattr(data, "__next__"):
        return BlockSource(lambda: data, reiterable=False, prefetch=ahead,
                           description=f"one-shot iterator ({type(data).__name__})")
    if callable(data):
        return BlockSource(data, reiterable=True, description="block callable", prefetch=ahead)
    raise FemromTypeError(f"cannot read snapshot blocks from {type(data).__name__}: give an (n, K) "
                          "array, an object with iter_blocks(), a callable returning an iterator of "
                          "(n, b) blocks, or a list of blocks")


def store_source(store, field: str = "q", trajectories=None, *, block_columns: int | None = None,
                 prefetch: int = 1) -> BlockSource:
    """A snapshot store's field as a block source: ``[X_000, X_001, ...]`` (n, K).

    Blocks hold a whole number of the store's HDF5 chunks (about
    ``block_columns`` columns, by default about 128 MB) and never span two
    trajectories, so every pass reads each chunk once.

    Parameters
    ----------
    store : SnapshotStore
    field : str
        ``"q"`` / ``"displacement"``, ``"v"`` / ``"velocity"``, ``"a"`` / ``"acceleration"``.
    trajectories : sequence of str or int, optional
        Which runs, in this column order; all by default.
    block_columns : int, optional
    prefetch : int
        Blocks read ahead in a background thread.
    """
    key = store.field_key(field)          # one clear error for a field the store lacks
    wanted = block_columns if block_columns is not None else default_block_columns(store.n_dofs)
    plan = store.column_blocks(key, wanted, trajectories)
    if not plan:
        raise FemromValueError(f"{store.path}: no committed snapshots of {field!r} to read")

    def blocks():
        for trajectory, start, stop in plan:
            yield store.read(trajectory, key, start, stop)

    return BlockSource(blocks, reiterable=True, n_rows=store.n_dofs, prefetch=int(prefetch),
                       description=f"{store.path.name}: {key} of {len({p[0] for p in plan})} "
                                   f"trajectories, {len(plan)} blocks")
