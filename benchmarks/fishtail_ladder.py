"""Fishtail mesh ladder: what the FOM and its ROMs cost from 2e4 to the papers' 7.8e5 dofs.

For each mesh level of ``cases/fishtail.py`` (small ~2e4, medium ~1e5, large
~7.8e5 free P2 dofs; the MORwiki "Artificial Fishtail" of Siebelts, Kater &
Meurer 2018 has n = 779,232), in its own subprocess (so that its peak memory
is its own):

1. mesh generation (gmsh, cached) and assembly of K, M, C = a M + b K, B, E;
2. two Newmark runs of ``--steps`` steps (sigmoid pressure: training; step:
   test), the effective matrix factorised once by PARDISO and reused by both
   runs; the mass solve of the initial acceleration by Jacobi-preconditioned
   CG (a second direct factor would double the memory at the large size);
   q, v, a streamed into an HDF5 snapshot store (``--store-dir``, default /tmp),
   never held in memory;
3. a mass-orthonormal POD basis by the out-of-core randomized SVD
   (femrom.linalg.randomized_svd through femrom.basis.POD) reading the store;
4. reduced data (``V^T M Q``, stored Newmark ``q'``, ``q''``) block by block,
   the intrusive Galerkin ROM, L-OpInf and plain OpInf for each r; each ROM
   is run on the unseen step input: output error, full-field error in the
   mass norm (streamed), time per step and speedup over the FOM;
5. peak resident memory (``ru_maxrss``) of the level's process; the parent
   samples the child's RSS and kills it above ``--memory-limit-gb``.

Run from the repository root (femrom importable)::

    python benchmarks/fishtail_ladder.py --levels small            # ~2 min
    python benchmarks/fishtail_ladder.py --levels small medium large --steps 200

Results: ``benchmarks/results/fishtail_ladder.json`` (levels merged into the
existing file) and a table on stdout.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "cases"))
sys.path.insert(0, str(ROOT))

RESULTS = ROOT / "benchmarks" / "results" / "fishtail_ladder.json"
#: mesh_size per level; large: 0.00122 gives about 7.7e5 free dofs (measured: 0.00125 -> 7.2e5 total)
LADDER_SIZES = {"small": 0.006, "medium": 0.0028, "large": 0.00122}


# -- solvers ---------------------------------------------------------------------------
def _solver_factory(system, log: dict):
    """PARDISO for the effective matrix, cached across runs with the same dt; Jacobi-CG for M."""
    from femrom.fem import LinearSolver, make_solver
    from scipy.sparse.linalg import cg

    class JacobiCG(LinearSolver):
        name = "jacobi-cg"

        def __init__(self, A):
            super().__init__(A)
            self._A = A
            self._inv = 1.0 / A.diagonal()
            self.total_iterations = 0

        def _solve(self, b, x0):
            count = [0]
            x, info = cg(self._A, b, x0=x0, rtol=1e-12, atol=0.0, maxiter=2000,
                         M=sp.diags(self._inv), callback=lambda _: count.__setitem__(0, count[0] + 1))
            self.total_iterations += count[0]
            if info != 0:
                raise RuntimeError(f"Jacobi-CG on the mass did not converge ({count[0]} iterations)")
            return x

    cache = {}

    def factory(A, spd=True):
        if A is system.mass:
            return JacobiCG(A)
        key = (A.shape, A.nnz, float(A.data.sum()))
        if key not in cache:
            cache.clear()
            tic = time.perf_counter()
            cache[key] = make_solver(A, strategy="auto", spd=spd)
            log["factorization_seconds"] = time.perf_counter() - tic
            log["solver"] = cache[key].name
        return cache[key]

    return factory, cache


# -- one level ---------------------------------------------------------------------------
def run_level(level: str, *, steps: int, dt: float, ranks, store_dir: Path, svd_power: int) -> dict:
    import fishtail
    from femrom.basis import POD
    from femrom.inference import LagrangianOpInf, SecondOrderData, SecondOrderOpInf
    from femrom.integrators import EnergyRecorder, Newmark, OutputRecorder, integrate
    from femrom.post._report import machine_description
    from femrom.rom import SecondOrderROM
    from femrom.scene import build
    from femrom.snapshots import SnapshotStore

    result = {"level": level, "mesh_size": LADDER_SIZES[level], "steps": steps, "dt": dt,
              "machine": machine_description(), "load_before": os.getloadavg()}
    scene = fishtail.with_time(fishtail.load_scene(LADDER_SIZES[level]), dt=dt, t_end=steps * dt)
    tic = time.perf_counter()
    model = build(scene)
    result["build_seconds"] = time.perf_counter() - tic
    result["build_timings"] = model.timings
    system = model.system
    n = system.n_dofs
    result["n_dofs"] = n
    print(f"[{level}] {n} free dofs, built in {result['build_seconds']:.1f} s", flush=True)

    log = {}
    factory, cache = _solver_factory(system, log)
    store_path = store_dir / f"femrom_fishtail_{level}.h5"
    store = SnapshotStore.create(store_path, model, fields=("q", "v", "a"), overwrite=True)
    runs = {}
    for kind in ("sigmoid", "step"):
        u = fishtail.PressureInputs(fishtail.pressure_signal(scene, kind), system.n_inputs)
        sys_u = dataclasses.replace(system, inputs=u)
        outputs, energy = OutputRecorder(sys_u), EnergyRecorder(sys_u)
        writer = store.writer(kind)
        tic = time.perf_counter()
        summary = integrate(sys_u, Newmark(), np.zeros(n), np.zeros(n), dt, steps,
                            consumers=[writer, outputs, energy], solver=factory, progress=False)
        wall = time.perf_counter() - tic
        runs[kind] = {"outputs": outputs.outputs, "energy": energy.total, "inputs": u,
                      "times": dt * np.arange(steps + 1), "U": u.sampled(dt * np.arange(steps + 1))}
        result[f"fom_{kind}"] = {"wall_seconds": wall, "stepping_seconds": summary.stepping_seconds,
                                 "setup_seconds": summary.setup_seconds,
                                 "seconds_per_step": summary.stepping_seconds / steps,
                                 "snapshot_seconds": summary.consumer_seconds}
        print(f"[{level}] FOM {kind}: {summary.stepping_seconds / steps:.3f} s/step, "
              f"setup {summary.setup_seconds:.1f} s, streaming {summary.consumer_seconds:.1f} s", flush=True)
    result["factorization_seconds"] = log.get("factorization_seconds")
    result["solver"] = log.get("solver")
    result["rss_after_fom_gb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    cache.clear()  # free the factor before the SVD
    fom_sps = result["fom_sigmoid"]["seconds_per_step"]
    result["fom_seconds_per_step"] = fom_sps
    result["store_gb"] = store_path.stat().st_size / 2**30

    block = max(8, min(steps + 1, int(2**28 // (8 * n))))
    M = system.mass
    tic = time.perf_counter()
    pod = POD(rank=max(ranks), product=M, method="randomized", power_iterations=svd_power).fit(
        lambda: store.iter_blocks("q", block, trajectories=["sigmoid"]))
    result["svd_seconds"] = time.perf_counter() - tic
    result["svd_passes"] = svd_power + 2
    result["singular_values"] = pod.singular_values_
    V_all = pod.basis_
    print(f"[{level}] randomized SVD: {result['svd_seconds']:.1f} s", flush=True)

    def reduced(field, trajectory, V):
        return np.hstack([V.T @ (M @ b) for b in store.iter_blocks(field, block, trajectories=[trajectory])])

    rows = []
    test_q_norm2 = sum(float(np.sum(b * (M @ b))) for b in store.iter_blocks("q", block, ["step"]))
    for r in ranks:
        V = np.ascontiguousarray(V_all[:, :r])
        tic = time.perf_counter()
        train = runs["sigmoid"]
        data = SecondOrderData(states=reduced("q", "sigmoid", V), velocities=reduced("v", "sigmoid", V),
                               accelerations=reduced("a", "sigmoid", V), inputs=train["U"],
                               outputs=train["outputs"], times=train["times"],
                               diagnostics={"derivative_source": "stored", "dt": dt, "n_trajectories": 1})
        reduce_seconds = time.perf_counter() - tic
        for name in ("galerkin", "lopinf", "opinf"):
            tic = time.perf_counter()
            if name == "galerkin":
                rom = SecondOrderROM.galerkin(system, V, product=M, mass_orthonormal=True)
            else:
                learner = LagrangianOpInf if name == "lopinf" else SecondOrderOpInf
                rom = SecondOrderROM(basis=V, product=M, learner=learner(damping=True)).fit(data)
            fit_seconds = time.perf_counter() - tic
            test = runs["step"]
            sps = []
            for _ in range(3):  # min of repeats: the machine is shared
                solution = rom.predict(np.zeros(r), test["times"], inputs=test["inputs"])
                sps.append(solution.info["seconds_per_step"])
            y = solution.outputs
            out_err = float(np.linalg.norm(y - test["outputs"]) / np.linalg.norm(test["outputs"]))
            err2, k0 = 0.0, 0
            for b in store.iter_blocks("q", block, ["step"]):
                e = b - V @ solution.q[:, k0:k0 + b.shape[1]]
                err2 += float(np.sum(e * (M @ e)))
                k0 += b.shape[1]
            rows.append({"r": r, "learner": name, "fit_seconds": fit_seconds,
                         "reduce_seconds": reduce_seconds,
                         "test_output_error": out_err,
                         "test_field_error": float(np.sqrt(err2 / test_q_norm2)),
                         "rom_seconds_per_step": min(sps),
                         "speedup": fom_sps / max(min(sps), 1e-12)})
            print(f"[{level}] r={r} {name}: output error {out_err:.2e}, "
                  f"speedup {rows[-1]['speedup']:.0f}", flush=True)
    result["roms"] = rows
    result["peak_rss_gb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    result["load_after"] = os.getloadavg()
    store.close()
    if not KEEP_STORE:
        store_path.unlink(missing_ok=True)
    return result


KEEP_STORE = False


# -- driver ----------------------------------------------------------------------------------
def _child(level, args) -> dict | None:
    out = Path(args.store_dir) / f"fishtail_ladder_{level}.json"
    out.unlink(missing_ok=True)
    cmd = [sys.executable, __file__, "--worker", level, "--steps", str(args.steps), "--dt", str(args.dt),
           "--ranks", *map(str, args.ranks), "--store-dir", str(args.store_dir),
           "--svd-power", str(args.svd_power), "--worker-out", str(out)]
    import psutil

    proc = subprocess.Popen(cmd)
    peak = 0.0
    while proc.poll() is None:
        try:
            rss = psutil.Process(proc.pid).memory_info().rss / 2**30
        except psutil.Error:
            rss = 0.0
        peak = max(peak, rss)
        if rss > args.memory_limit_gb:
            proc.kill()
            print(f"[{level}] killed: RSS {rss:.1f} GB above --memory-limit-gb {args.memory_limit_gb}")
            return {"level": level, "error": f"killed at {rss:.1f} GB RSS"}
        time.sleep(1.0)
    if proc.returncode != 0 or not out.exists():
        return {"level": level, "error": f"worker exited with {proc.returncode}"}
    result = json.loads(out.read_text())
    result["sampled_peak_rss_gb"] = peak
    return result


def table(results) -> str:
    lines = ["| level | dofs | build s | factor s | FOM s/step | peak GB | SVD s | r | learner | fit s "
             "| ROM s/step | speedup | output err | field err |",
             "|" + "---|" * 14]
    for res in results:
        if "error" in res:
            lines.append(f"| {res['level']} | failed: {res['error']} |" + " |" * 12)
            continue
        for row in res["roms"]:
            lines.append(
                f"| {res['level']} | {res['n_dofs']} | {res['build_seconds']:.1f} | "
                f"{res['factorization_seconds']:.1f} | {res['fom_seconds_per_step']:.3f} | "
                f"{res['peak_rss_gb']:.1f} | {res['svd_seconds']:.1f} | {row['r']} | {row['learner']} | "
                f"{row['fit_seconds']:.2f} | {row['rom_seconds_per_step']:.2e} | {row['speedup']:.0f} | "
                f"{row['test_output_error']:.2e} | {row['test_field_error']:.2e} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--levels", nargs="+", default=["small", "medium", "large"], choices=tuple(LADDER_SIZES))
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--dt", type=float, default=1e-3)
    parser.add_argument("--ranks", type=int, nargs="+", default=[4, 8, 12])
    parser.add_argument("--store-dir", default="/tmp")
    parser.add_argument("--svd-power", type=int, default=1)
    parser.add_argument("--memory-limit-gb", type=float, default=14.0)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--worker-out", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        from femrom.post._report import _jsonable

        res = run_level(args.worker, steps=args.steps, dt=args.dt, ranks=args.ranks,
                        store_dir=Path(args.store_dir), svd_power=args.svd_power)
        Path(args.worker_out).write_text(json.dumps(_jsonable(res), indent=2))
        return 0
    merged = json.loads(args.out.read_text()) if args.out.exists() else {"levels": {}}
    results = []
    for level in args.levels:
        res = _child(level, args)
        results.append(res)
        merged["levels"][level] = res
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(merged, indent=2) + "\n")
    print(table(results))
    print(f"results in {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
