r"""What per-chunk Fletcher-32 checksums cost a snapshot store: streaming writes and reads, with and without.

A trajectory of ``K`` snapshots of ``n`` dofs (q, v, a, random values) is streamed through
:class:`femrom.snapshots.SnapshotWriter` into a store made with ``checksums=True`` and one with
``checksums=False``, then read back whole by :meth:`SnapshotStore.read` (warm page cache: the
file was just written). The two settings alternate, ``--repeats`` rounds each, in one process;
the ratio of medians (checksums / none) is the overhead of the input/output alone. Then the
same for a real streamed run, where it matters: the small fishtail (2e4 dofs, P2, Newmark with
PARDISO) for ``--fom-steps`` steps, storing q, v, a as the studies do. Results: a table on stdout
and ``benchmarks/results/store_checksums.json``.

Usage::

    python -m benchmarks.store_checksums            # n = 2e4 and 2e5, K = 400, 5 rounds
    python -m benchmarks.store_checksums --quick    # n = 2e4, K = 200, 3 rounds
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import scipy.sparse as sp

from femrom.scene import SecondOrderSystem
from femrom.snapshots import SnapshotStore


def _system(n: int) -> SecondOrderSystem:
    eye = sp.identity(n, format="csr")
    return SecondOrderSystem(mass=eye, stiffness=eye)


def _write(path: Path, system, rows: np.ndarray, checksums: bool) -> float:
    """Seconds to create the store and stream ``rows`` ((K, n), the same for q, v, a) into it."""
    tic = time.perf_counter()
    store = SnapshotStore.create(path, system, fields=("q", "v", "a"), dt=1.0, n_steps=len(rows) - 1,
                                 overwrite=True, checksums=checksums)
    writer = store.writer()
    for k, q in enumerate(rows):
        writer(SimpleNamespace(step=k, t=float(k), q=q, v=q, a=q))
    writer.close()
    store.close()
    return time.perf_counter() - tic


def _read(path: Path) -> float:
    tic = time.perf_counter()
    with SnapshotStore.open(path) as store:
        for field in ("q", "v", "a"):
            store.read("000", field)
    return time.perf_counter() - tic


def measure(n: int, n_snapshots: int, repeats: int, folder: Path) -> dict:
    rng = np.random.default_rng(0)
    rows = rng.standard_normal((n_snapshots, n))
    system = _system(n)
    times = {(kind, on): [] for kind in ("write", "read") for on in (False, True)}
    for _ in range(repeats):
        for on in (False, True):              # alternating: a disturbance falls on both alike
            path = folder / f"store_{int(on)}.h5"
            times["write", on].append(_write(path, system, rows, on))
            times["read", on].append(_read(path))
    out = {"n_dofs": n, "snapshots": n_snapshots, "megabytes": 3 * rows.nbytes / 2**20, "repeats": repeats}
    for kind in ("write", "read"):
        plain, checked = statistics.median(times[kind, False]), statistics.median(times[kind, True])
        out[kind] = {"seconds_plain": plain, "seconds_checksums": checked, "overhead": checked / plain - 1.0,
                     "all_plain": times[kind, False], "all_checksums": times[kind, True]}
    return out


def measure_fom(n_steps: int, repeats: int, folder: Path) -> dict:
    """The small fishtail streamed into a store, with and without checksums, alternating."""
    from femrom.cases import fishtail
    from femrom.integrators import simulate
    from femrom.scene import build

    model = build(fishtail.load_scene("small"))
    t_end = n_steps * model.scene.time.dt
    seconds = {False: [], True: []}
    for _ in range(repeats):
        for on in (False, True):
            path = folder / f"fom_{int(on)}.h5"
            tic = time.perf_counter()
            store = SnapshotStore.create(path, model, fields=("q", "v", "a"), overwrite=True, checksums=on)
            simulate(model, t_end=t_end, consumers=[store.writer()])
            store.close()
            seconds[on].append(time.perf_counter() - tic)
    plain, checked = statistics.median(seconds[False]), statistics.median(seconds[True])
    return {"case": "fishtail small", "n_dofs": model.system.n_dofs, "steps": n_steps, "repeats": repeats,
            "seconds_plain": plain, "seconds_checksums": checked, "overhead": checked / plain - 1.0,
            "all_plain": seconds[False], "all_checksums": seconds[True]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int)
    parser.add_argument("--fom-steps", type=int, default=300)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "store_checksums.json"))
    args = parser.parse_args()
    sizes = [(20_000, 200)] if args.quick else [(20_000, 400), (200_000, 400)]
    repeats = args.repeats or (3 if args.quick else 5)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for n, k in sizes:
            rows.append(measure(n, k, repeats, Path(folder)))
            r = rows[-1]
            print(f"n = {n:>7}, K = {k}, {r['megabytes']:.0f} MB: write {r['write']['seconds_plain']:.3f} s -> "
                  f"{r['write']['seconds_checksums']:.3f} s ({100 * r['write']['overhead']:+.1f} %), read "
                  f"{r['read']['seconds_plain']:.3f} s -> {r['read']['seconds_checksums']:.3f} s "
                  f"({100 * r['read']['overhead']:+.1f} %)", flush=True)
        fom = measure_fom(args.fom_steps // (3 if args.quick else 1), repeats, Path(folder))
    print("\n| n dofs | snapshots | MB | write, none (s) | write, checksums (s) | overhead | read, none (s) | "
          "read, checksums (s) | overhead |\n|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['n_dofs']} | {r['snapshots']} | {r['megabytes']:.0f} | {r['write']['seconds_plain']:.3f} | "
              f"{r['write']['seconds_checksums']:.3f} | {100 * r['write']['overhead']:+.1f} % | "
              f"{r['read']['seconds_plain']:.3f} | {r['read']['seconds_checksums']:.3f} | "
              f"{100 * r['read']['overhead']:+.1f} % |")
    print(f"\n{fom['case']} ({fom['n_dofs']} dofs), {fom['steps']} Newmark steps streaming q, v, a: "
          f"{fom['seconds_plain']:.2f} s -> {fom['seconds_checksums']:.2f} s ({100 * fom['overhead']:+.1f} %)")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"machine": platform.platform(), "runs": rows, "fom": fom}, indent=1))
    print(f"\nwritten: {args.out}")


if __name__ == "__main__":
    main()
