r"""Dask backend: the randomized SVD on a ``dask.array`` for data and clusters beyond one machine.

``dask.array.linalg.svd_compressed`` (Halko, Martinsson & Tropp 2011,
Alg. 4.4 + 5.1) with ``iterator="QR"``: every product with A or A^T is
re-orthonormalised by a tall-skinny QR, so 2 q + 2 passes over the data for q
power iterations (plus one for ||A||_W^2, which dask may fuse with the first).
The data are (n, K) and chunked by rows and columns as given; an HDF5 file is
opened per chunk by path inside the tasks, so the graph also runs on a real
``dask.distributed`` cluster whose workers see the file.

The computation runs on the threaded scheduler by default (no cluster is
started); ``scheduler`` may name another local scheduler (``"synchronous"``,
``"processes"``), give the address of a ``dask.distributed`` scheduler, or be
a ``distributed.Client``.

Only the Euclidean product and diagonal (lumped) products are supported here:
for W = diag(w) the rows are scaled by sqrt(w) inside the graph and U is
scaled back.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from femrom.linalg._lowrank import LowRankSVD
from femrom.linalg._product import InnerProduct

_LOCAL_SCHEDULERS = ("threads", "synchronous", "sync", "single-threaded", "processes")


def _read_hdf5_block(path: str, name: str, rows: tuple[int, int], columns: tuple[int, int]) -> np.ndarray:
    import h5py

    with h5py.File(path, "r") as file:
        return np.asarray(file[name][rows[0]:rows[1], columns[0]:columns[1]], dtype=np.float64)


def _hdf5_array(path: str, name: str | None, chunks: Any):
    import dask
    import dask.array as da
    import h5py

    if name is None:
        raise ValueError(f"give dataset= (the name of the (n, K) snapshot dataset in {path})")
    with h5py.File(path, "r") as file:
        if name not in file:
            raise KeyError(f"{path} has no dataset {name!r}; it has: {', '.join(file.keys())}")
        shape, storage = file[name].shape, file[name].chunks
    if len(shape) != 2:
        raise ValueError(f"dataset {name!r} in {path} must be 2-D (n, K), got shape {shape}")
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


def as_dask_array(data: Any, *, dataset: str | None = None, chunks: Any = None):
    """An (n, K) float64 ``dask.array`` from a dask array, an array-like, or an HDF5 path.

    Parameters
    ----------
    data : dask array, ndarray, h5py.Dataset, str or Path
        A path names an HDF5 file; ``dataset`` names the (n, K) dataset in it.
    dataset : str, optional
        Dataset name inside the HDF5 file.
    chunks : optional
        Dask chunks (default: dask's "auto" for arrays; for HDF5 files
        "auto" rows and the file's own column chunking).
    """
    import dask.array as da

    if isinstance(data, (str, Path)):
        array = _hdf5_array(str(data), dataset, chunks)
    elif isinstance(data, da.Array):
        array = data if chunks is None else data.rechunk(chunks)
    else:
        array = da.from_array(data, chunks="auto" if chunks is None else chunks)
    if array.ndim != 2:
        raise ValueError(f"snapshot array must be 2-D (n, K), got shape {array.shape}")
    return array.astype(np.float64, copy=False)


def _compute(objects: tuple, scheduler: Any):
    import dask

    if scheduler is None:
        return dask.compute(*objects, scheduler="threads")
    if isinstance(scheduler, str) and scheduler in _LOCAL_SCHEDULERS:
        return dask.compute(*objects, scheduler=scheduler)
    if isinstance(scheduler, str):
        from distributed import Client

        with Client(scheduler) as client:
            return dask.compute(*objects, scheduler=client)
    if hasattr(scheduler, "submit") and hasattr(scheduler, "gather"):  # a distributed.Client
        return dask.compute(*objects, scheduler=scheduler)
    raise ValueError(f"scheduler must be None, one of {', '.join(_LOCAL_SCHEDULERS)}, a "
                     f"dask.distributed address or a Client; got {scheduler!r}")


def randomized_svd_dask(data: Any, rank: int, *, oversampling: int = 10, power_iterations: int = 2,
                        product: Any = None, seed: int = 0, dataset: str | None = None,
                        chunks: Any = None, scheduler: Any = None) -> LowRankSVD:
    r"""Rank-``rank`` SVD of A (n, K) with ``dask.array.linalg.svd_compressed``.

    Same call as :func:`randomized_svd` where it can be (see the module doc
    for schedulers and the supported products).

    Parameters
    ----------
    data : dask array, ndarray, h5py.Dataset, str or Path
        The (n, K) snapshot matrix, or an HDF5 file (with ``dataset``).
    rank, oversampling, power_iterations, seed
        As :func:`randomized_svd` (``k``, ``n_oversamples``, ``n_power_iter``,
        ``seed`` of ``svd_compressed``).
    product : None or (n,) array
        Diagonal (lumped) inner product; sparse matrices are not supported here.
    dataset : str, optional
        Name of the dataset when ``data`` is a path.
    chunks : optional
        Dask chunks of the data.
    scheduler : None, str or distributed.Client
        ``None``: local threads; a local scheduler name; a
        ``dask.distributed`` address such as ``"tcp://host:8786"``; or a Client.

    Returns
    -------
    LowRankSVD
        ``U`` (n, r), ``s`` (r,), ``Vt`` (r, K), ``passes`` = 2 q + 2.
    """
    import dask.array as da

    if int(rank) < 1:
        raise ValueError(f"rank must be >= 1, got {rank}")
    inner = InnerProduct(product)
    if inner.kind == "matrix":
        raise NotImplementedError("randomized_svd_dask supports the Euclidean and diagonal (lumped) "
                                  "products; use randomized_svd for a sparse mass matrix")
    array = as_dask_array(data, dataset=dataset, chunks=chunks)
    inner.check_dimension(array.shape[0])
    if rank > min(array.shape):
        raise ValueError(f"rank {rank} exceeds min(n, K) = min{array.shape}")
    if inner.kind == "diagonal":
        sqrt_w = da.from_array(inner.sqrt_weights, chunks=(array.chunks[0],))
        array = array * sqrt_w[:, None]
    energy = (array**2).sum()
    u, s, vt = da.linalg.svd_compressed(array, k=int(rank), iterator="QR",
                                        n_power_iter=int(power_iterations),
                                        n_oversamples=int(oversampling), seed=int(seed),
                                        compute=False)
    u, s, vt, energy = _compute((u, s, vt, energy), scheduler)
    if inner.kind == "diagonal":
        u = u / inner.sqrt_weights[:, None]
    return LowRankSVD(U=np.asarray(u), s=np.asarray(s), Vt=np.asarray(vt),
                      passes=2 * int(power_iterations) + 2, total_energy=float(energy),
                      n_columns=int(array.shape[1]),
                      sketch_size=min(int(rank) + int(oversampling), *array.shape), method="dask")
