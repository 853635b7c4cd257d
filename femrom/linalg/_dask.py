r"""Dask backend: the randomized SVD on a ``dask.array`` for data and clusters beyond one machine.

**Data.** A snapshot matrix A (n, K) from an array, a dask array, a plain
HDF5 dataset stored as (n, K), or a femrom snapshot store
(:class:`~femrom.snapshots.SnapshotStore` or its path) and a field. A store
keeps each trajectory's field as a (K_i, n) dataset chunked by whole
snapshots; its dask array is built lazily from the store's column-block plan
(:meth:`~femrom.snapshots.SnapshotStore.column_blocks`): one task per block
of whole HDF5 chunks reads (b, n) rows by path
(:func:`femrom.snapshots.read_rows`), the transpose is a dask view,
and the trajectories are concatenated along columns,
A = [X_000, X_001, ...] (n, sum K_i), with only committed snapshots. Tasks
open the file by path, so they also run on the workers of a real cluster
that see the file.

**Algorithm.** Euclidean and diagonal (lumped) products:
``dask.array.linalg.svd_compressed`` (Halko, Martinsson & Tropp 2011, Alg.
4.4 + 5.1) with ``iterator="QR"``: every product with A or A^T is
re-orthonormalised by a tall-skinny QR, 2 q + 2 passes over the data for q
power iterations (plus one for ||A||_W^2, which dask may fuse with the
first); for W = diag(w) the rows are scaled by sqrt(w) inside the graph and
U is scaled back. A general sparse SPD W (consistent mass): femrom's
pass-efficient range finder (:func:`~femrom.linalg.randomized_svd`, same
Omega for the same seed) with each pass one dask computation over the column
blocks, Z_j = A_j^T S and Y = sum_j A_j Z_j. W is applied only to (n, k)
arrays on the client (S = W Q U_R Sigma^{-1}, CholQR2 of Y) and, for
||A||_W^2 = sum_j trace(A_j^T W A_j), inside one task per column block (W
is one key of the graph, shipped once per worker). q + 2 passes; rows are
not split (a block is whole columns, so W A_j is a local product).

**Schedulers.** By default the computation runs on a
``dask.distributed.LocalCluster`` started for the call (one worker, one
thread per core, in this process: ``processes=False``, no dashboard;
``cluster_options`` overrides) and closed after it, also on errors. Three
exceptions: an active ``distributed.Client`` (``Client.current()``) is used
instead; data the process holds (an ndarray, a memmap, an open
``h5py.Dataset``) run on dask's threaded scheduler, as a cluster would only
copy them into its graph (or fail to send the dataset); and without
``distributed`` installed, the default is the threaded scheduler.
``scheduler_address="tcp://host:8786"`` connects to a running cluster (its
client is closed after the call, the cluster is left running); ``scheduler``
may name a local scheduler (``"threads"``, ``"synchronous"``,
``"processes"``) or be a Client.
"""

from __future__ import annotations

import os
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from femrom._errors import FemromValueError, nonnegative_integer, positive_integer
from femrom.linalg._blocks import default_block_columns
from femrom.linalg._lowrank import LowRankSVD
from femrom.linalg._product import InnerProduct
from femrom.linalg._randomized import _inverse_sqrt_factor, _next_scaling, _right_factor
from femrom.linalg._test_matrices import RANGE_STREAM, column_rows

_LOCAL_SCHEDULERS = ("threads", "synchronous", "sync", "single-threaded", "processes")


def _read_hdf5_block(path: str, name: str, rows: tuple[int, int], columns: tuple[int, int]) -> np.ndarray:
    import h5py

    with h5py.File(path, "r") as file:
        return np.asarray(file[name][rows[0]:rows[1], columns[0]:columns[1]], dtype=np.float64)


def _hdf5_array(path: str, name: str | None, chunks: Any):
    import dask
    import dask.array as da
    import h5py

    from femrom.snapshots import FORMAT_NAME

    with h5py.File(path, "r") as file:
        fmt = file.attrs.get("format")
        if fmt is not None and (fmt.decode() if isinstance(fmt, bytes) else str(fmt)) == FORMAT_NAME:
            raise FemromValueError(f"{path} is a femrom snapshot store, whose datasets are (K, n) per "
                                   "trajectory: give field= ('displacement', 'velocity', ...), not "
                                   "dataset=")
        if name is None:
            raise FemromValueError(f"give dataset= (the name of the (n, K) snapshot dataset in {path}), "
                                   "or field= for a femrom snapshot store")
        if name not in file:
            raise FemromValueError(f"{path} has no dataset {name!r}; it has: {', '.join(file.keys())}")
        shape, storage = file[name].shape, file[name].chunks
    if len(shape) != 2:
        raise FemromValueError(f"dataset {name!r} in {path} must be 2-D (n, K), got shape {shape}")
    if chunks is None:
        chunks = ("auto", storage[1] if storage else "auto")
    chunk_rows, chunk_cols = da.core.normalize_chunks(chunks, shape, dtype=np.float64)
    read = dask.delayed(_read_hdf5_block, pure=True)
    row_edges = np.cumsum((0,) + chunk_rows)
    col_edges = np.cumsum((0,) + chunk_cols)
    blocks = [[da.from_delayed(read(str(path), name, (int(r0), int(r1)), (int(c0), int(c1))),
                               shape=(int(r1 - r0), int(c1 - c0)), dtype=np.float64)
               for c0, c1 in zip(col_edges[:-1], col_edges[1:])]
              for r0, r1 in zip(row_edges[:-1], row_edges[1:])]
    return da.block(blocks)


def _read_store_rows(path: str, trajectory: str, key: str, start: int, stop: int) -> np.ndarray:
    """(stop - start, n) float64 rows of a store dataset (a task; runs wherever a worker is)."""
    from femrom.snapshots import read_rows

    return np.asarray(read_rows(path, trajectory, key, start, stop), dtype=np.float64)


def store_dask_array(store: Any, field: str, *, trajectories=None, block_columns: int | None = None):
    r"""The snapshot matrix A = [X_000, X_001, ...] (n, K) of a store's field as a dask array.

    Parameters
    ----------
    store : SnapshotStore, str or Path
        The store (or its path; opened, checked and closed here).
    field : str
        ``"displacement"`` / ``"q"``, ``"velocity"`` / ``"v"``,
        ``"acceleration"`` / ``"a"`` (also ``"inputs"`` / ``"u"``,
        ``"outputs"`` / ``"y"``).
    trajectories : sequence, optional
        Names or indices; all by default, in order.
    block_columns : int, optional
        Snapshots per dask chunk, rounded to whole HDF5 chunks of each
        trajectory (default: about 128 MB per chunk,
        :func:`~femrom.linalg.default_block_columns`).

    Returns
    -------
    dask.array.Array
        (n, K) float64, chunks (n, b_j): one row chunk, column chunks that
        never straddle a trajectory and read whole HDF5 chunks.

    Raises
    ------
    SnapshotStoreError
        Not a store (foreign, damaged, truncated file), an unknown field or
        trajectory, or no committed snapshot.
    """
    import dask
    import dask.array as da

    from femrom.snapshots import SnapshotStore, SnapshotStoreError

    owned = not isinstance(store, SnapshotStore)
    opened = SnapshotStore.open(store) if owned else store
    try:
        key = opened.field_key(field)
        names = opened.trajectories
        width = opened.read(names[0], key, 0, 0).shape[0] if names else 0  # n, or m, p for u, y
        target = default_block_columns(width) if block_columns is None else int(block_columns)
        if target < 1:
            raise FemromValueError(f"block_columns must be >= 1, got {block_columns}")
        plan = opened.column_blocks(key, target, trajectories)
        path = str(opened.path)
    finally:
        if owned:
            opened.close()
    if not plan:
        raise SnapshotStoreError(f"{path}: no committed snapshots of {field!r} to decompose")
    read = dask.delayed(_read_store_rows, pure=True)
    parts, rows = [], []
    for index, (name, start, stop) in enumerate(plan):
        rows.append(da.from_delayed(read(path, name, key, start, stop),
                                    shape=(stop - start, width), dtype=np.float64))
        if index + 1 == len(plan) or plan[index + 1][0] != name:  # a trajectory's last block
            parts.append(da.concatenate(rows, axis=0).T)  # (K_i, n) rows -> (n, K_i), lazily
            rows = []
    return da.concatenate(parts, axis=1)


def as_dask_array(data: Any, *, field: str | None = None, trajectories=None,
                  block_columns: int | None = None, dataset: str | None = None, chunks: Any = None):
    """An (n, K) float64 ``dask.array`` from a snapshot store, an HDF5 path, a dask array or an array.

    Parameters
    ----------
    data : SnapshotStore, str or Path, dask array, ndarray or h5py.Dataset
        A store (or a path with ``field``): see :func:`store_dask_array`. A
        path with ``dataset``: a plain HDF5 file holding A as (n, K).
    field, trajectories
        For a snapshot store (:func:`store_dask_array`).
    block_columns : int, optional
        Snapshots per column chunk: for a store rounded to whole HDF5 chunks
        (:func:`store_dask_array`), otherwise ``chunks=("auto", block_columns)``.
    dataset : str, optional
        Dataset name inside a plain HDF5 file.
    chunks : optional
        Dask chunks of an array or plain HDF5 data (default: dask's "auto"
        for arrays; for HDF5 files "auto" rows and the file's own column
        chunking). Not for a store, whose chunks follow its HDF5 chunks.
    """
    import dask.array as da

    from femrom.snapshots import SnapshotStore

    if isinstance(data, SnapshotStore) or (isinstance(data, (str, Path)) and field is not None):
        if field is None:
            raise FemromValueError("give field= ('displacement', 'velocity', 'acceleration', ...) to "
                                   f"read the snapshot matrix of {data}")
        if dataset is not None or chunks is not None:
            raise FemromValueError("a snapshot store is read by field= (and block_columns=), not "
                                   "dataset= or chunks=")
        return store_dask_array(data, field, trajectories=trajectories, block_columns=block_columns)
    if field is not None or trajectories is not None:
        raise FemromValueError(f"field= and trajectories= apply to a snapshot store, not to "
                               f"{type(data).__name__}")
    if block_columns is not None:
        if chunks is not None:
            raise FemromValueError("give chunks= or block_columns=, not both")
        chunks = ("auto", int(block_columns))
    if isinstance(data, (str, Path)):
        array = _hdf5_array(str(data), dataset, chunks)
    elif isinstance(data, da.Array):
        array = data if chunks is None else data.rechunk(chunks)
    else:
        array = da.from_array(data, chunks="auto" if chunks is None else chunks)
    if array.ndim != 2:
        raise FemromValueError(f"snapshot array must be 2-D (n, K), got shape {array.shape}")
    return array.astype(np.float64, copy=False)


def _is_client(scheduler: Any) -> bool:
    return hasattr(scheduler, "submit") and hasattr(scheduler, "gather")


@contextmanager
def dask_scheduler(scheduler: Any = None, *, scheduler_address: str | None = None,
                   cluster_options: dict | None = None, local_data: bool = False) -> Iterator[Any]:
    """What ``dask.compute(..., scheduler=...)`` gets, for the duration of a block (module doc).

    A cluster or client started here is closed when the block ends, also on errors.

    Parameters
    ----------
    scheduler : None, str or distributed.Client
        ``None``: the active Client, else a LocalCluster (``local_data``:
        threads), else threads without ``distributed``; a local scheduler name;
        or a Client.
    scheduler_address : str, optional
        Address of a running ``dask.distributed`` scheduler.
    cluster_options : dict, optional
        Keyword arguments of the default ``LocalCluster``.
    local_data : bool
        The data are held by this process (an ndarray, a memmap, an open
        ``h5py.Dataset``): no LocalCluster by default, threads.
    """
    if scheduler_address is not None:
        if scheduler is not None:
            raise FemromValueError("give scheduler= or scheduler_address=, not both")
        try:
            from distributed import Client
        except ImportError:
            raise ImportError("scheduler_address needs dask.distributed: pip install "
                              "'femrom[dist]'") from None
        with Client(str(scheduler_address), set_as_default=False) as client:
            yield client
        return
    if scheduler is None:
        yield from _default_scheduler(cluster_options, local_data)
        return
    if isinstance(scheduler, str) and scheduler in _LOCAL_SCHEDULERS:
        yield scheduler
        return
    if _is_client(scheduler):
        yield scheduler
        return
    hint = " (an address goes in scheduler_address=)" if isinstance(scheduler, str) else ""
    raise FemromValueError(f"scheduler must be None, one of {', '.join(_LOCAL_SCHEDULERS)} or a "
                           f"distributed.Client; got {scheduler!r}{hint}")


def _default_scheduler(cluster_options: dict | None, local_data: bool) -> Iterator[Any]:
    try:
        import distributed
    except ImportError:
        distributed = None
    client = None
    if distributed is not None:
        try:
            client = distributed.Client.current()
        except ValueError:  # no active client
            client = None
    if client is not None:
        yield client
        return
    if distributed is None or local_data:
        yield "threads"
        return
    options = {"n_workers": 1, "threads_per_worker": os.cpu_count() or 1, "processes": False,
               "dashboard_address": None, **(cluster_options or {})}
    with ExitStack() as stack:
        cluster = stack.enter_context(distributed.LocalCluster(**options))
        yield stack.enter_context(distributed.Client(cluster, set_as_default=False))


def randomized_svd_dask(data: Any, rank: int, *, oversampling: int = 10, power_iterations: int = 2,
                        product: Any = None, seed: int = 0, field: str | None = None,
                        trajectories=None, block_columns: int | None = None,
                        dataset: str | None = None, chunks: Any = None, scheduler: Any = None,
                        scheduler_address: str | None = None,
                        cluster_options: dict | None = None) -> LowRankSVD:
    r"""Rank-``rank`` SVD of A (n, K) on Dask, A ~ U diag(s) Vt with U^T W U = I.

    The call of :func:`~femrom.linalg.randomized_svd` (``rank``,
    ``oversampling``, ``power_iterations``, ``product``, ``seed``,
    ``block_columns``) plus where the data and the cluster are. See the
    module doc for the algorithms, schedulers and chunks.

    Parameters
    ----------
    data : SnapshotStore, str or Path, dask array, ndarray or h5py.Dataset
        A snapshot store (or its path) with ``field``; a plain HDF5 file
        holding A as (n, K) with ``dataset``; or the (n, K) matrix.
    rank, oversampling, power_iterations, seed
        As :func:`~femrom.linalg.randomized_svd` (``k``, ``n_oversamples``,
        ``n_power_iter``, ``seed`` of ``svd_compressed``).
    product : None, (n,) array or (n, n) sparse matrix
        SPD inner product W (lumped or consistent mass); U^T W U = I and the
        approximation is optimal in the W-norm.
    field : str, optional
        Field of a snapshot store: ``"displacement"`` (``"q"``), ``"velocity"``
        (``"v"``), ``"acceleration"`` (``"a"``).
    trajectories : sequence, optional
        Trajectories of a store (all by default).
    block_columns : int, optional
        Snapshots per column chunk (for a store rounded to whole HDF5 chunks).
    dataset : str, optional
        Dataset of a plain HDF5 file.
    chunks : optional
        Dask chunks of array or plain HDF5 data.
    scheduler : None, str or distributed.Client
        ``None``: a LocalCluster for this call (see module doc); a local
        scheduler name (``"threads"``, ``"synchronous"``, ``"processes"``);
        or a Client.
    scheduler_address : str, optional
        A running ``dask.distributed`` scheduler, e.g. ``"tcp://host:8786"``.
    cluster_options : dict, optional
        Keyword arguments of the default LocalCluster (e.g.
        ``{"n_workers": 2, "processes": True}``).

    Returns
    -------
    LowRankSVD
        ``U`` (n, r), ``s`` (r,), ``Vt`` (r, K), ``total_energy`` = ||A||_W^2;
        ``passes`` = 2 q + 2 (``method="dask"``) or q + 2 for a sparse W
        (``method="dask-pass-efficient"``).

    Raises
    ------
    SnapshotStoreError
        ``data`` names a file that is not a readable store, or the field is
        not stored.
    """
    import dask.array as da

    rank = positive_integer(rank, "rank")
    oversampling = nonnegative_integer(oversampling, "oversampling")
    power_iterations = nonnegative_integer(power_iterations, "power_iterations")
    inner = InnerProduct(product)
    array = as_dask_array(data, field=field, trajectories=trajectories,
                          block_columns=block_columns, dataset=dataset, chunks=chunks)
    inner.check_dimension(array.shape[0])
    if rank > min(array.shape):
        raise FemromValueError(f"rank {rank} exceeds min(n, K) = min{array.shape}")
    local_data = not isinstance(data, (str, Path, da.Array)) and not hasattr(data, "column_blocks")
    with dask_scheduler(scheduler, scheduler_address=scheduler_address,
                        cluster_options=cluster_options, local_data=local_data) as where:
        if inner.kind == "matrix":
            return _pass_efficient(array, int(rank), int(oversampling), int(power_iterations),
                                   inner, int(seed), where)
        if inner.kind == "diagonal":
            sqrt_w = da.from_array(inner.sqrt_weights, chunks=(array.chunks[0],))
            array = array * sqrt_w[:, None]
        energy = (array**2).sum()
        u, s, vt = da.linalg.svd_compressed(array, k=int(rank), iterator="QR",
                                            n_power_iter=int(power_iterations),
                                            n_oversamples=int(oversampling), seed=int(seed),
                                            compute=False)
        u, s, vt, energy = _compute((u, s, vt, energy), where)
    if inner.kind == "diagonal":
        u = u / inner.sqrt_weights[:, None]
    return LowRankSVD(U=np.asarray(u), s=np.asarray(s), Vt=np.asarray(vt),
                      passes=2 * int(power_iterations) + 2, total_energy=float(energy),
                      n_columns=int(array.shape[1]),
                      sketch_size=min(int(rank) + int(oversampling), *array.shape), method="dask")


def _compute(objects: tuple, where: Any) -> tuple:
    import dask

    return dask.compute(*objects, scheduler=where)


def _block_energy(block: np.ndarray, weights) -> np.ndarray:
    """[[trace(A_j^T W A_j)]] of one column block (all n rows)."""
    return np.array([[np.einsum("ij,ij->", block, np.asarray(weights @ block))]])


def _omega_rows(seed: int, start: int, count: int, width: int, kept: int) -> np.ndarray:
    return column_rows(seed, RANGE_STREAM, start, count, width)[:, :kept]


def _pass_efficient(array, rank: int, oversampling: int, q: int, inner: InnerProduct, seed: int,
                    where: Any) -> LowRankSVD:
    r"""femrom's pass-efficient range finder (``randomized_svd``), one dask computation per pass.

    Pass 1: Y = A Omega, Omega^T Omega and ||A||_W^2; passes 2..q+1:
    Z = A^T S, Y = A Z, Z^T Z; last pass: Z = A^T S, Y = A Z, then
    A P_Z = (A U_Z) U_Z^T as in :func:`~femrom.linalg.randomized_svd`.
    """
    import dask
    import dask.array as da

    if len(array.chunks[0]) > 1:
        array = array.rechunk({0: -1})  # whole columns per block: W A_j is a local product
    n, n_columns = array.shape
    width = min(rank + oversampling, n, n_columns)
    starts = np.cumsum((0,) + array.chunks[1][:-1])
    rows = dask.delayed(_omega_rows, pure=True)
    omega = da.concatenate([da.from_delayed(rows(seed, int(start), int(count), rank + oversampling,
                                                 width), shape=(int(count), width), dtype=np.float64)
                            for start, count in zip(starts, array.chunks[1])], axis=0)
    weights = dask.delayed(inner.matrix, pure=True)
    energy = array.map_blocks(_block_energy, weights, chunks=(1, 1), dtype=np.float64).sum()
    y, gram, energy = _compute((array @ omega, omega.T @ omega, energy), where)
    basis, r_factor = inner.orthonormalize(y)
    coupling = r_factor @ _inverse_sqrt_factor(gram)

    def products(scaling: np.ndarray):
        s = da.from_array(scaling, chunks=(n, width))
        z = array.T @ s
        return z, array @ z

    for _ in range(q):
        z, y = products(_next_scaling(inner.apply(basis), coupling))
        y, gram = _compute((y, z.T @ z), where)
        basis, r_factor = inner.orthonormalize(y)
        coupling = r_factor @ _inverse_sqrt_factor(gram)
    z, y = products(_next_scaling(inner.apply(basis), coupling))
    y, z = _compute((y, z), where)
    u_z, coefficients = _right_factor(z)
    basis, r_factor = inner.orthonormalize(y @ coefficients)
    u_m, s, vt_m = np.linalg.svd(r_factor)
    return LowRankSVD(U=basis @ u_m[:, :rank], s=s[:rank], Vt=vt_m[:rank] @ u_z.T, passes=q + 2,
                      total_energy=float(energy), n_columns=int(n_columns), sketch_size=width,
                      method="dask-pass-efficient")
