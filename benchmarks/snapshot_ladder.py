r"""Snapshot benchmark: out-of-core randomized SVD, streaming sketch overhead, library comparison.

Four parts, each configuration in its own subprocess (``--single``) so that
its peak resident memory is its own ``ru_maxrss``; the parent also watches the
child's RSS and kills it above ``--memory-limit-gb``.

1. **Synthetic out-of-core file.** A low-rank-plus-noise snapshot matrix
   A = U diag(s) V^T + nu E (n x K, planted rank R, E standard normal) is
   streamed column by column through :class:`femrom.snapshots.SnapshotWriter`
   into a :class:`~femrom.snapshots.SnapshotStore` (default 1e6 x 2000
   float64 = 16 GB) under a temporary directory, which is deleted at the end
   (``--keep`` keeps it).
2. **Multi-pass rSVD against one sequential read** of the same file, both
   through the store's read path (``iter_blocks``) and, for reference, a raw
   ``readinto`` of the file's bytes, for each (scheme, q) of ``FILE_RUNS``
   (classical q = 1, 2; pass-efficient with 2 and 3 passes). Page cache:
   "cold" evicts the file with ``posix_fadvise(POSIX_FADV_DONTNEED)`` before
   the baseline read and before *every* pass of the rSVD (a file larger than
   RAM); "warm" reads the file once untimed first so that it is (mostly)
   cached; ``fincore`` reports the cached fraction at each start. The top-r
   singular values of each run are compared with a converged reference of
   the same file (classical rSVD, rank 50 + 10, q = 3: convergence factor
   (sigma_61 / sigma_r)^14, sigma_61 at the noise floor).
3. **Real FOM.** The clamped steel beam of ``fom_ladder.py`` (P1, about 2e4
   and 1e5 dofs) is run with Newmark for ``--fom-steps`` steps three ways:
   plain, with a :class:`~femrom.linalg.StreamingSketch` consumer, and with a
   snapshot writer plus the sketch. The sketch's overhead is its consumer
   time over the stepping time; the top-r singular values of the sketch and
   of the multi-pass rSVD of the stored snapshots (both schemes,
   ``ACCURACY_RUNS``) are compared with LAPACK's SVD of the whole snapshot
   matrix.
4. **In memory, same run:** femrom ``randomized_svd`` (both schemes, several
   q; its Dask backend and streaming sketch) against ``sklearn.utils.extmath.randomized_svd`` and
   ``dask.array.linalg.svd_compressed`` on an (n, K) matrix with exactly known
   singular values (A = H [diag(s) V^T; 0], H a product of three Householder
   reflections, V random orthogonal; the randomized methods' error does not
   depend on the singular vectors for Gaussian test matrices).

Usage::

    python -m benchmarks.snapshot_ladder --quick       # small sizes, 1-3 min
    python -m benchmarks.snapshot_ladder               # full: 16 GB file, 40-60 min

See ``benchmarks/README.md`` and ``docs/benchmarks_snapshots.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

# -- sizes ----------------------------------------------------------------------
FULL = {
    # synthetic file: n x K, planted rank, noise level, chunk and block steps
    "n": 1_000_000, "K": 2000, "planted": 50, "noise": 1e-6,
    "chunk_steps": 8, "block_steps": 32,
    # rSVD of the file: rank, oversampling (q + 2 passes, runs in FILE_RUNS)
    "rank": 20, "oversampling": 10,
    # FOM: fom_ladder sizes (P1) and Newmark steps
    "fom_sizes": ("small", "medium"), "fom_steps": 1000, "fom_rank": 10,
    # in-memory comparison
    "mem_n": 100_000, "mem_K": 2000, "mem_rank": 20,
}
QUICK = {
    "n": 20_000, "K": 200, "planted": 50, "noise": 1e-6,
    "chunk_steps": 8, "block_steps": 32,
    "rank": 20, "oversampling": 10,
    "fom_sizes": ("small",), "fom_steps": 100, "fom_rank": 10,
    "mem_n": 20_000, "mem_K": 400, "mem_rank": 20,
}
#: (scheme, q) of the timed runs on the file: q + 2 passes each.
FILE_RUNS = (("classical", 1), ("classical", 2), ("pass_efficient", 0), ("pass_efficient", 1))
#: Reference singular values of the file: classical rSVD, rank + oversampling, q.
FILE_REFERENCE = {"rank": 50, "oversampling": 10, "q": 3}
#: (scheme, q) of the accuracy comparisons (FOM, in memory) and their oversampling.
ACCURACY_RUNS = (("classical", 1), ("classical", 2), ("pass_efficient", 0),
                 ("pass_efficient", 1), ("pass_efficient", 2))
ACCURACY_Q, ACCURACY_P = 2, 10  # q of the other libraries in part 4
#: Geometric spectrum of the in-memory matrix: s_j = 10^(-j/10), j = 0..K-1
#: (s_{r+p}/s_r = 0.1 at r = 20, p = 10).
MEM_DECAY = 10.0


def _peak_rss_gb() -> float:
    """Peak resident set size of this process so far (GB = 2^30 bytes; ru_maxrss is kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def _rss_gb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**30


# -- page cache --------------------------------------------------------------------
def evict(path) -> None:
    """Drop ``path``'s pages from the page cache (written back first)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
        os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    finally:
        os.close(fd)


def cached_fraction(path) -> float | None:
    """Fraction of ``path`` in the page cache (``fincore``), None if unavailable."""
    try:
        out = subprocess.run(["fincore", "--bytes", "--noheadings", "--output", "RES", str(path)],
                             capture_output=True, text=True, timeout=60, check=True).stdout
        return int(out.split()[0]) / os.path.getsize(path)
    except (OSError, subprocess.SubprocessError, ValueError, IndexError):
        return None


# -- 1. the synthetic file ------------------------------------------------------------
def _synthetic_factors(n, K, planted, seed):
    """Ut (R, n) and V (K, R) with orthonormal columns, s (R,) from 1 to 1e-2."""
    from femrom.linalg import householder_qr

    rng = np.random.default_rng([seed, 0])
    u, _ = householder_qr(rng.standard_normal((n, planted)))
    v, _ = np.linalg.qr(rng.standard_normal((K, planted)))
    s = 10.0 ** (-2.0 * np.arange(planted) / (planted - 1))
    return np.ascontiguousarray(u.T), v, s


def task_build(path, n, K, planted, noise, chunk_steps, seed=0) -> dict:
    """Stream A = U diag(s) V^T + noise E into a store, column by column."""
    import scipy.sparse as sp

    from femrom.integrators import StepResult
    from femrom.scene import SecondOrderSystem
    from femrom.snapshots import SnapshotStore

    tic = time.perf_counter()
    ut, v, s = _synthetic_factors(n, K, planted, seed)
    factor_seconds = time.perf_counter() - tic
    eye = sp.identity(n, format="csr")
    system = SecondOrderSystem(mass=eye, stiffness=eye, metadata={
        "synthetic": "low rank plus noise", "planted_rank": planted, "noise": noise})
    store = SnapshotStore.create(path, system, fields=("q",), dt=1.0, n_steps=K - 1,
                                 overwrite=True)
    zeros = np.zeros(n)
    rng = np.random.default_rng([seed, 1])
    tic = time.perf_counter()
    generate = 0.0
    with store.writer(chunk_steps=chunk_steps) as writer:
        for start in range(0, K, chunk_steps):
            t0 = time.perf_counter()
            count = min(chunk_steps, K - start)
            rows = rng.standard_normal((count, n))
            rows *= noise
            rows += (v[start:start + count] * s) @ ut
            generate += time.perf_counter() - t0
            for i in range(count):
                writer(StepResult(step=start + i, t=float(start + i), q=rows[i], v=zeros, a=None))
    write_seconds = time.perf_counter() - tic
    store.close()
    tic = time.perf_counter()
    evict(path)  # fsync + drop: the write is on disk
    sync_seconds = time.perf_counter() - tic
    size = os.path.getsize(path)
    return {"task": "build", "n": n, "K": K, "planted": planted, "noise": noise,
            "chunk_steps": chunk_steps, "file_bytes": size, "factor_seconds": factor_seconds,
            "generate_seconds": generate, "stream_seconds": write_seconds,
            "sync_seconds": sync_seconds,
            "write_gb_per_s": size / 1e9 / (write_seconds + sync_seconds),
            "planted_s": s.tolist(), "peak_rss_gb": _peak_rss_gb()}


# -- 2. reads and rSVD of the file ---------------------------------------------------
def _store_read(store, block_steps) -> tuple[float, int]:
    tic = time.perf_counter()
    total = 0
    for block in store.iter_blocks("q", block_steps):
        total += block.nbytes
    return time.perf_counter() - tic, total


def _raw_read(path) -> tuple[float, int]:
    buf = bytearray(64 * 2**20)
    view = memoryview(buf)
    tic = time.perf_counter()
    total = 0
    with open(path, "rb", buffering=0) as fh:
        while True:
            got = fh.readinto(view)
            if not got:
                break
            total += got
    return time.perf_counter() - tic, total


def task_rsvd_file(path, mode, rank, oversampling, q, block_steps, scheme="classical") -> dict:
    """Sequential reads, then the multi-pass rSVD of the same file, in one page-cache mode."""
    from femrom.linalg import randomized_svd
    from femrom.snapshots import SnapshotStore

    store = SnapshotStore.open(path)
    out = {"task": "rsvd_file", "mode": mode, "rank": rank, "oversampling": oversampling,
           "scheme": scheme, "q": q, "passes": q + 2, "block_steps": block_steps}
    if mode == "warm":
        _store_read(store, block_steps)  # untimed: bring the file into the cache
    reads = {}
    for name, read in (("raw", lambda: _raw_read(path)),
                       ("store", lambda: _store_read(store, block_steps))):
        if mode == "cold":
            evict(path)
        cached = cached_fraction(path)
        seconds, nbytes = read()
        reads[name] = {"seconds": seconds, "bytes": nbytes, "gb_per_s": nbytes / 1e9 / seconds,
                       "cached_at_start": cached}
    out["reads"] = reads
    rss_before = _rss_gb()
    pass_log = []

    def open_pass():
        if mode == "cold":
            evict(path)
        pass_log.append({"start": time.perf_counter(), "cached_at_start": cached_fraction(path)
                         if mode == "warm" else 0.0})
        return store.iter_blocks("q", block_steps)

    tic = time.perf_counter()
    result = randomized_svd(open_pass, rank, oversampling=oversampling, power_iterations=q,
                            scheme=scheme, progress=False)
    seconds = time.perf_counter() - tic
    assert result.passes == len(pass_log) == q + 2
    starts = [p["start"] for p in pass_log] + [tic + seconds]
    out.update({
        "seconds": seconds, "pass_seconds": [b - a for a, b in zip(starts[:-1], starts[1:])],
        "cached_at_pass_start": [p["cached_at_start"] for p in pass_log],
        "ratio_to_store_read": seconds / reads["store"]["seconds"],
        "ratio_to_raw_read": seconds / reads["raw"]["seconds"],
        "s": result.s.tolist(), "rss_before_gb": rss_before, "peak_rss_gb": _peak_rss_gb(),
        "threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
    })
    store.close()
    return out


def task_reference_file(path, rank, oversampling, q, block_steps) -> dict:
    """Converged singular values of the file (classical rSVD with a large sketch), untimed."""
    from femrom.linalg import randomized_svd
    from femrom.snapshots import SnapshotStore

    store = SnapshotStore.open(path)
    tic = time.perf_counter()
    result = randomized_svd(lambda: store.iter_blocks("q", block_steps), rank,
                            oversampling=oversampling, power_iterations=q, scheme="classical",
                            seed=12345, progress=False)
    seconds = time.perf_counter() - tic
    store.close()
    s = result.s
    return {"task": "reference_file", "rank": rank, "oversampling": oversampling, "q": q,
            "passes": result.passes, "seconds": seconds, "s": s.tolist(),
            # Ritz values converge like (sigma_{k+1} / sigma_i)^(2(2q+1)); sigma_{k+1} <= s[-1]
            # of this run, so this bounds the factor for sigma_20 (up to HMT's constants).
            "convergence_factor_s20": float((s[-1] / s[19]) ** (2 * (2 * q + 1))),
            "peak_rss_gb": _peak_rss_gb()}


# -- 3. the FOM -------------------------------------------------------------------
def _relative_errors(s, reference) -> list[float]:
    r = len(s)
    return (np.abs(np.asarray(s) - reference[:r]) / reference[:r]).tolist()


def task_fom(size, steps, rank, workdir) -> dict:
    """Newmark runs of the clamped beam: plain, + sketch, + store + sketch; accuracy of the bases."""
    from benchmarks.fom_ladder import DT, _cantilever  # the same beam as the FOM benchmark

    from femrom.integrators import Newmark, integrate
    from femrom.linalg import StreamingSketch, randomized_svd
    from femrom.snapshots import SnapshotStore

    system, _, _ = _cantilever(size, "p1")
    n = system.n_dofs
    zeros = np.zeros(n)
    integrate(system, Newmark(), zeros, zeros, DT, 3, solver="auto", progress=False)  # load MKL
    runs = {}
    sketches = {}

    def run(name, consumers):
        summary = integrate(system, Newmark(), zeros, zeros, DT, steps, consumers=consumers,
                            solver="auto", progress=False)
        runs[name] = {"stepping_seconds": summary.stepping_seconds,
                      "consumer_seconds": summary.consumer_seconds,
                      "setup_seconds": summary.setup_seconds, "n_steps": summary.n_steps,
                      "solver": summary.solver}

    path = Path(workdir) / f"fom_{size}.h5"
    run("plain", [])
    sketch = StreamingSketch(n, rank, seed=1)
    run("sketch", [sketch.consumer("q")])
    sketches["sketch"] = sketch
    store = SnapshotStore.create(path, system, fields=("q",), dt=DT, n_steps=steps,
                                 overwrite=True)
    sketch2 = StreamingSketch(n, rank, seed=2)
    run("store+sketch", [store.writer(), sketch2.consumer("q")])
    store.close()
    if n < 50_000:  # the store writer alone (its own overhead), where a run is cheap
        path_w = Path(workdir) / f"fom_{size}_w.h5"
        store_w = SnapshotStore.create(path_w, system, fields=("q",), dt=DT, n_steps=steps,
                                       overwrite=True)
        run("store", [store_w.writer()])
        store_w.close()
        path_w.unlink()
    for r in runs.values():
        r["consumer_over_stepping"] = r["consumer_seconds"] / r["stepping_seconds"]
    plain = runs["plain"]["stepping_seconds"] + runs["plain"]["consumer_seconds"]
    for r in runs.values():
        r["wall_over_plain"] = (r["stepping_seconds"] + r["consumer_seconds"]) / plain - 1.0

    store = SnapshotStore.open(path)
    chunk = store.attrs(0)["chunk_steps"]
    K = store.n_snapshots()
    tic = time.perf_counter()
    data = np.concatenate(list(store.iter_blocks("q", 64 * chunk)), axis=1)
    read_seconds = time.perf_counter() - tic
    tic = time.perf_counter()
    reference = np.linalg.svd(data, compute_uv=False)
    svd_seconds = time.perf_counter() - tic
    del data
    accuracy = {}
    for scheme, q in ACCURACY_RUNS:
        tic = time.perf_counter()
        result = randomized_svd(lambda: store.iter_blocks("q", 64 * chunk), rank,
                                oversampling=ACCURACY_P, power_iterations=q, scheme=scheme,
                                progress=False)
        accuracy[f"rsvd {scheme} q={q}"] = {"seconds": time.perf_counter() - tic,
                                            "scheme": scheme, "q": q, "passes": result.passes,
                                            "rel_err": _relative_errors(result.s, reference)}
    for name, sk in (("sketch", sketch), ("sketch(store run)", sketch2)):
        tic = time.perf_counter()
        result = sk.finalize()
        accuracy[name] = {"seconds": time.perf_counter() - tic,
                          "rel_err": _relative_errors(result.s, reference),
                          "range_size": sk.range_size, "core_size": sk.core_size,
                          "memory_mb": sk.memory_bytes / 2**20}
    store.close()
    path.unlink()
    return {"task": "fom", "size": size, "n": n, "K": K, "steps": steps, "dt": DT, "rank": rank,
            "runs": runs, "read_seconds": read_seconds, "reference_svd_seconds": svd_seconds,
            "reference_s": reference[:max(40, rank)].tolist(), "accuracy": accuracy,
            "peak_rss_gb": _peak_rss_gb()}


# -- 4. in memory --------------------------------------------------------------------
def known_spectrum_matrix(n, K, seed=0):
    """A = H [diag(s) V^T; 0] (n, K) with s_j = 10^(-j/MEM_DECAY) exactly; returns (A, s)."""
    rng = np.random.default_rng([seed, 3])
    s = 10.0 ** (-np.arange(K) / MEM_DECAY)
    v, _ = np.linalg.qr(rng.standard_normal((K, K)))
    a = np.zeros((n, K))
    a[:K] = s[:, None] * v.T
    for _ in range(3):  # H_i = I - 2 h h^T: orthogonal, makes every row dense
        h = rng.standard_normal(n)
        h /= np.linalg.norm(h)
        w = 2.0 * (h @ a)
        for i in range(0, n, 8192):  # in row slabs: no (n, K) temporary
            a[i:i + 8192] -= np.outer(h[i:i + 8192], w)
    return a, s


def task_memory(method, n, K, rank, scheme="classical", q=ACCURACY_Q) -> dict:
    """One randomized SVD of the known-spectrum matrix: time, peak RSS, error of the top-r values.

    ``scheme`` and ``q`` apply to ``method="femrom"`` (the other libraries use ACCURACY_Q).
    """
    a, s_exact = known_spectrum_matrix(n, K)
    import dask  # noqa: F401  (imports outside the timed region for every method)
    import dask.array as da
    import sklearn.utils.extmath as extmath

    from femrom.linalg import StreamingSketch, randomized_svd, randomized_svd_dask

    rss_data = _rss_gb()
    p = ACCURACY_P
    q = q if method == "femrom" else None if method == "femrom-sketch" else ACCURACY_Q
    passes = 1 if q is None else q + 2 if method == "femrom" else 2 * q + 2
    tic = time.perf_counter()
    if method == "femrom":
        s = randomized_svd(a, rank, oversampling=p, power_iterations=q, scheme=scheme,
                           progress=False).s
    elif method == "femrom-dask":
        s = randomized_svd_dask(a, rank, oversampling=p, power_iterations=q,
                                chunks=(max(K, n // 8), K)).s
    elif method == "femrom-sketch":
        s = StreamingSketch(n, rank).update_from(a).finalize().s
    elif method == "sklearn":
        _, s, _ = extmath.randomized_svd(a, rank, n_oversamples=p, n_iter=q,
                                         power_iteration_normalizer="QR", random_state=0)
    elif method == "dask":
        x = da.from_array(a, chunks=(max(K, n // 8), K))
        _, s, _ = da.linalg.svd_compressed(x, k=rank, n_power_iter=q, n_oversamples=p, seed=0,
                                           compute=True)
        s = np.asarray(s)
    else:
        raise ValueError(method)
    seconds = time.perf_counter() - tic
    errors = _relative_errors(s, s_exact)
    return {"task": "memory", "method": method, "n": n, "K": K, "rank": rank,
            "oversampling": p, "q": q, "scheme": scheme if method == "femrom" else None,
            "passes": passes, "seconds": seconds, "max_rel_err": max(errors),
            "rel_err": errors, "rss_data_gb": rss_data, "peak_rss_gb": _peak_rss_gb(),
            "data_gb": a.nbytes / 2**30}


# -- running children -----------------------------------------------------------------
TASKS = {"build": task_build, "rsvd_file": task_rsvd_file, "reference_file": task_reference_file,
         "fom": task_fom, "memory": task_memory}


def run_single(spec: str) -> dict:
    args = json.loads(spec)
    return TASKS[args.pop("task")](**args)


def run_child(spec: dict, memory_limit_gb: float, timeout: float, log) -> dict:
    """Run one task in a subprocess; kill it above the memory limit or the timeout."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--single", json.dumps(spec)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    tic = time.perf_counter()
    process = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=env)
    watched = {"max_rss_gb": 0.0, "killed": None}

    def watch():
        page = os.sysconf("SC_PAGE_SIZE")
        while process.poll() is None:
            try:
                with open(f"/proc/{process.pid}/statm") as fh:
                    rss = int(fh.read().split()[1]) * page / 2**30
            except OSError:
                break
            watched["max_rss_gb"] = max(watched["max_rss_gb"], rss)
            if rss > memory_limit_gb:
                watched["killed"] = f"RSS {rss:.2f} GB > {memory_limit_gb} GB"
                process.kill()
                break
            if time.perf_counter() - tic > timeout:
                watched["killed"] = f"timeout {timeout} s"
                process.kill()
                break
            time.sleep(0.25)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    stdout, stderr = process.communicate()
    thread.join()
    wall = time.perf_counter() - tic
    if process.returncode != 0:
        log(f"  FAILED ({watched['killed'] or process.returncode}): {stderr.strip()[-2000:]}")
        return {**spec, "error": watched["killed"] or stderr.strip()[-2000:], "wall_seconds": wall}
    result = json.loads(stdout.strip().splitlines()[-1])
    result["wall_seconds"] = wall
    result["watched_max_rss_gb"] = watched["max_rss_gb"]
    return result


# -- tables ---------------------------------------------------------------------------
def _f(x, digits=3):
    if x is None:
        return "-"
    if isinstance(x, str):
        return x
    if x == 0:
        return "0"
    if abs(x) < 1e-3 or abs(x) >= 1e5:
        return f"{x:.1e}"
    return f"{x:.{digits}g}"


def table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(_f(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def file_reference(results) -> np.ndarray | None:
    for r in results:
        if r.get("task") == "reference_file" and "error" not in r:
            return np.asarray(r["s"])
    return None


def file_table(results) -> str:
    rows = []
    reference = file_reference(results)
    for r in results:
        if r.get("task") != "rsvd_file" or "error" in r:
            continue
        errors = _relative_errors(r["s"], reference) if reference is not None else None
        rows.append([r["mode"], r.get("scheme", "classical"), f"{r['rank']}+{r['oversampling']}",
                     r["q"], r["passes"],
                     r["reads"]["raw"]["seconds"], r["reads"]["raw"]["gb_per_s"],
                     r["reads"]["store"]["seconds"], r["reads"]["store"]["gb_per_s"],
                     r["seconds"], " / ".join(f"{x:.1f}" for x in r["pass_seconds"]),
                     f"{r['ratio_to_store_read']:.2f}x", f"{r['ratio_to_raw_read']:.2f}x",
                     r["peak_rss_gb"], max(errors) if errors else None,
                     " / ".join(f"{x:.2f}" for x in (r.get("load_before") or [])[:1] + r["load_after"][:1])])
    return table(["cache", "scheme", "r+p", "q", "passes", "raw read [s]", "raw GB/s",
                  "store read [s]", "store GB/s", "rSVD [s]", "per pass [s]", "rSVD / store read",
                  "rSVD / raw read", "peak RSS [GiB]", "max rel. err top-r vs reference",
                  "load 1 min before / after"], rows)


def fom_tables(results) -> tuple[str, str]:
    rows, acc = [], []
    for r in results:
        if r.get("task") != "fom" or "error" in r:
            continue
        for name, run in r["runs"].items():
            rows.append([r["size"], r["n"], name, run["n_steps"], run["stepping_seconds"],
                         run["stepping_seconds"] / run["n_steps"], run["consumer_seconds"],
                         f"{100 * run['consumer_over_stepping']:.1f} %",
                         f"{100 * run['wall_over_plain']:+.1f} %"])
        for name, a in r["accuracy"].items():
            acc.append([r["size"], r["n"], r["K"], name, a.get("passes", 1), r["rank"], a["seconds"],
                        max(a["rel_err"]), a["rel_err"][0], a["rel_err"][-1]])
        acc.append([r["size"], r["n"], r["K"], "LAPACK SVD (reference)", "-", "all",
                    r["reference_svd_seconds"], "-", "-", "-"])
    return (table(["size", "dofs", "consumers", "steps", "stepping [s]", "per step [s]",
                   "consumer [s]", "consumer / stepping", "run vs plain"], rows),
            table(["size", "dofs", "K", "method", "passes", "r", "time [s]", "max rel. err top-r",
                   "rel. err s_1", "rel. err s_r"], acc))


def memory_table(results) -> str:
    rows = []
    for r in results:
        if r.get("task") != "memory" or "error" in r:
            continue
        rows.append([r["method"], r.get("scheme") or "-", r["n"], r["K"], r["rank"],
                     r["oversampling"], r["q"], r.get("passes"), r["seconds"], r["peak_rss_gb"],
                     r["peak_rss_gb"] - r["rss_data_gb"], r["max_rel_err"]])
    return table(["method", "scheme", "n", "K", "r", "p", "q", "passes", "time [s]",
                  "peak RSS [GiB]", "peak - after data [GiB]", "max rel. err top-r"], rows)


def machine() -> dict:
    def git(*args):
        try:
            return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                                  timeout=30).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    import dask
    import h5py
    import scipy
    import sklearn

    import femrom

    cpu = ""
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo")
                   if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return {"platform": platform.platform(), "cpu": cpu, "cpus": os.cpu_count(),
            "memory_gb": os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30,
            "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "h5py": h5py.__version__,
            "hdf5": h5py.version.hdf5_version, "dask": dask.__version__,
            "sklearn": sklearn.__version__, "femrom": femrom.__version__,
            "commit": git("rev-parse", "--short", "HEAD"),
            "uncommitted_changes": bool(git("status", "--porcelain"))}


# -- main --------------------------------------------------------------------------------
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="small sizes (1-3 min)")
    parser.add_argument("--parts", default="file,fom,memory",
                        help="comma-separated parts: file, fom, memory")
    parser.add_argument("--workdir", default=None,
                        help="directory for the temporary files (default: a new one in /tmp)")
    parser.add_argument("--keep", action="store_true", help="keep the synthetic file")
    parser.add_argument("--out", default=None, help="JSON output (default "
                        "benchmarks/results/snapshot_ladder.json; --quick: a temporary file)")
    parser.add_argument("--fom-sizes", default=None,
                        help="FOM sizes of fom_ladder.py (default small,medium; --quick: small)")
    parser.add_argument("--fom-steps", type=int, default=None,
                        help="Newmark steps of the FOM runs (default 1000; --quick: 100)")
    parser.add_argument("--file-runs", default=None,
                        help="scheme:q pairs of the file part (default "
                        + ",".join(f"{s}:{q}" for s, q in FILE_RUNS) + ")")
    parser.add_argument("--file-modes", default="cold,warm",
                        help="page-cache modes of the file part: cold, warm")
    parser.add_argument("--reuse", action="store_true",
                        help="reuse WORKDIR/synthetic.h5 if it exists (with --workdir, --keep)")
    parser.add_argument("--history", action="store_true",
                        help="keep the existing OUT file's run under 'previous_runs'")
    parser.add_argument("--quiet-flag", default="/tmp/quiet_ok",
                        help="file whose presence (machine declared quiet) is recorded per child")
    parser.add_argument("--memory-limit-gb", type=float, default=6.0)
    parser.add_argument("--timeout", type=float, default=3600.0)
    parser.add_argument("--single", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.single is not None:
        print(json.dumps(run_single(args.single)))
        return 0

    cfg = dict(QUICK if args.quick else FULL)
    cfg["file_runs"] = FILE_RUNS if args.file_runs is None else tuple(
        (item.split(":")[0], int(item.split(":")[1])) for item in args.file_runs.split(","))
    cfg["file_modes"] = tuple(args.file_modes.split(","))
    if args.fom_sizes:
        cfg["fom_sizes"] = tuple(args.fom_sizes.split(","))
    if args.fom_steps:
        cfg["fom_steps"] = int(args.fom_steps)
    parts = set(args.parts.split(","))
    out = Path(args.out) if args.out else (
        Path(tempfile.gettempdir()) / "snapshot_ladder_quick.json" if args.quick
        else HERE / "results" / "snapshot_ladder.json")
    workdir = Path(args.workdir or tempfile.mkdtemp(prefix="femrom-snapshot-ladder-", dir="/tmp"))
    workdir.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()

    def log(message):
        print(f"[{time.perf_counter() - started:7.1f} s] {message}", flush=True)

    previous = []
    if args.history and out.exists():
        old = json.loads(out.read_text())
        previous = old.pop("previous_runs", []) + [old]
    quiet_flag = Path(args.quiet_flag)
    info = {"machine": machine(), "config": {k: list(v) if isinstance(v, tuple) else v
                                             for k, v in cfg.items()},
            "file_reference": FILE_REFERENCE, "accuracy_runs": ACCURACY_RUNS,
            "quiet_flag": str(quiet_flag), "quiet_flag_at_start": quiet_flag.exists(),
            "quick": args.quick, "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "load_at_start": os.getloadavg(), "workdir": str(workdir), "results": []}
    results = info["results"]

    def child(spec):
        log(f"{spec['task']}: {json.dumps({k: v for k, v in spec.items() if k != 'task'})}")
        load_before, quiet_before = os.getloadavg(), quiet_flag.exists()
        r = run_child(spec, args.memory_limit_gb, args.timeout, log)
        r["load_before"], r["load_after"] = load_before, os.getloadavg()
        r["quiet_flag_before"], r["quiet_flag_after"] = quiet_before, quiet_flag.exists()
        results.append(r)
        log(f"  done in {r['wall_seconds']:.1f} s, peak RSS {r.get('peak_rss_gb', float('nan')):.2f} GiB, "
            f"load {load_before[0]:.2f} -> {r['load_after'][0]:.2f}, quiet flag "
            f"{quiet_before} -> {r['quiet_flag_after']}")
        return r

    path = workdir / "synthetic.h5"
    try:
        if "file" in parts:
            if args.reuse and path.exists():
                log(f"reusing {path}")
            else:
                child({"task": "build", "path": str(path), "n": cfg["n"], "K": cfg["K"],
                       "planted": cfg["planted"], "noise": cfg["noise"],
                       "chunk_steps": cfg["chunk_steps"]})
            for mode in cfg["file_modes"]:
                for scheme, q in cfg["file_runs"]:
                    child({"task": "rsvd_file", "path": str(path), "mode": mode,
                           "rank": cfg["rank"], "oversampling": cfg["oversampling"], "q": q,
                           "scheme": scheme, "block_steps": cfg["block_steps"]})
            child({"task": "reference_file", "path": str(path), **FILE_REFERENCE,
                   "block_steps": cfg["block_steps"]})
        sizes = list(cfg["fom_sizes"]) if "fom" in parts else []
        if sizes:  # the smallest FOM first, the largest last (the longest part)
            child({"task": "fom", "size": sizes.pop(0), "steps": cfg["fom_steps"],
                   "rank": cfg["fom_rank"], "workdir": str(workdir)})
        if "memory" in parts:
            memory = {"task": "memory", "n": cfg["mem_n"], "K": cfg["mem_K"], "rank": cfg["mem_rank"]}
            for scheme, q in ACCURACY_RUNS:
                child({**memory, "method": "femrom", "scheme": scheme, "q": q})
            for method in ("femrom-dask", "femrom-sketch", "sklearn", "dask"):
                child({**memory, "method": method})
        for size in sizes:
            child({"task": "fom", "size": size, "steps": cfg["fom_steps"],
                   "rank": cfg["fom_rank"], "workdir": str(workdir)})
    finally:
        if args.keep:
            log(f"kept {workdir}")
        else:
            shutil.rmtree(workdir, ignore_errors=True)

    info["load_at_end"] = os.getloadavg()
    info["quiet_flag_at_end"] = quiet_flag.exists()
    if previous:
        info["previous_runs"] = previous
    info["total_seconds"] = time.perf_counter() - started
    tables = {"file": file_table(results)}
    tables["fom_overhead"], tables["fom_accuracy"] = fom_tables(results)
    tables["memory"] = memory_table(results)
    info["tables"] = tables
    print()
    for name, text in tables.items():
        print(f"## {name}\n\n{text}\n")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(info, indent=1, default=float))
    log(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
