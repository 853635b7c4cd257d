r"""FOM benchmark ladder: assembly, linear-solver strategies and memory of 3D elasticity.

A steel cantilever (``beam_solid``: 1.0 x 0.1 x 0.05 m, clamped face ``left``)
meshed by Gmsh at mesh sizes chosen so that P1 and P2 each reach about 2e4,
1e5 and 5e5 dofs, and for each (size, element):

1. stiffness assembly: femrom's ``elasticity_stiffness`` against skfem's stock
   ``asm(linear_elasticity(*lame_parameters(E, nu)), basis)`` on the same mesh
   and basis (skfem's default quadrature), their ratio and their difference;
2. consistent-mass assembly (``vector_mass``);
3. every linear-solver strategy of ``femrom.solvers.make_solver`` driving
   ``femrom.integrators.integrate`` with ``Newmark()`` (average acceleration)
   through the ``solver=`` factory, for a tip traction on ``right`` applied
   suddenly at ``t = 0``: setup, factorisation, time per step with reuse,
   Krylov iterations;
4. the same steps with a fresh ``make_solver(A_eff).solve(b)`` at every step
   (a few steps only), against reuse;
5. the peak resident memory of every configuration, each measured in its own
   subprocess (``--single``), which the parent also watches (and kills above
   ``--memory-limit-gb``).

Usage::

    python -m benchmarks.fom_ladder [--sizes small,medium,large] [--elements p1,p2]
                                    [--out benchmarks/results/fom_ladder.json]

prints Markdown tables and writes them with the raw numbers, the machine, the
femrom version and a timestamp to the JSON file. See ``benchmarks/README.md``.
"""

from __future__ import annotations

import argparse
import functools
import gc
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import threading
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

# -- the problem --------------------------------------------------------------
#: Beam dimensions (m): the defaults of meshes/beam_solid.geo.
GEOMETRY = {"length": 1.0, "width": 0.1, "height": 0.05}
#: Gmsh ``mesh_size`` per (size, element), calibrated on gmsh 4.15.2 to give
#: about 2e4, 1e5 and 5e5 total dofs (P2 has ~7x more dofs per vertex than P1).
MESH_SIZES = {
    "small": {"p1": 0.0095, "p2": 0.02},
    "medium": {"p1": 0.0052, "p2": 0.0107},
    "large": {"p1": 0.0029, "p2": 0.006},
}
#: Structural steel (E [Pa], nu, rho [kg/m^3]).
YOUNGS_MODULUS, POISSON_RATIO, DENSITY = 210e9, 0.3, 7850.0
#: Traction on the free end (Pa), in -z, switched on at t = 0.
TIP_TRACTION = (0.0, 0.0, -1e6)
#: Time step (s): the first bending period of the beam is about 24 ms
#: (Euler-Bernoulli, beta_1 L = 1.8751, omega_1 = 262 rad/s), so ~120 steps per period.
DT = 2e-4
#: Newmark steps per run with a reused factor (``--steps``). AMG-CG gets fewer
#: (``--amg-steps`` overrides them): each of its steps costs ~45 CG iterations
#: (0.5 s at 2e4 dofs, 7 s at 1e5, 60 s at 5e5 P2 here), so 100 steps at the
#: large size alone would take well over an hour.
STEPS = 100
AMG_STEPS = {"small": 10, "medium": 5, "large": 2}
#: Steps with a fresh solver at every step (the setup dominates; a few suffice).
FRESH_STEPS = {"small": 5, "medium": 3, "large": 2}
#: Newmark runs per strategy in one process (median reported): timings on a
#: shared machine vary by 2-3x from one minute to the next.
NEWMARK_REPEATS = {"small": 3, "medium": 2, "large": 1}
#: Repeats of the (cheap) femrom assembly; the median is reported.
ASSEMBLY_REPEATS = {"small": 3, "medium": 3, "large": 1}
STOCK_REPEATS = {"small": 3, "medium": 1, "large": 1}
#: Sizes at which the fresh-solve comparison runs (the brief asks for ~1e5 dofs).
FRESH_SIZES = ("small", "medium")
#: Skip the stock skfem form when its estimated time or memory exceeds these.
STOCK_MAX_SECONDS = 180.0
#: Stock-form cost per element when no smaller size was measured in the same
#: run (seconds, GB), measured on this project's machine (2 shared cores).
STOCK_SECONDS_PER_ELEMENT = {"p1": 1.5e-4, "p2": 1.2e-3}
STOCK_GB_PER_ELEMENT = {"p1": 4.0e-6, "p2": 6.0e-5}

STRATEGY_ORDER = ("pardiso", "cholmod", "amg-cg", "superlu")


# =============================================================================
# Child side: one configuration per process
# =============================================================================
def _peak_rss_gb() -> float:
    """Peak resident set size of this process so far (GB); ru_maxrss is in kB on Linux."""
    scale = 1 if sys.platform == "darwin" else 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale / 2**30


def _mesh(size: str, element: str):
    from femrom.mesh import build_mesh

    return build_mesh("beam_solid", {**GEOMETRY, "mesh_size": MESH_SIZES[size][element]})


def _vector_basis(mesh, element: str, intorder: int | None):
    import skfem

    scalar = {"p1": skfem.ElementTetP1, "p2": skfem.ElementTetP2}[element]()
    kwargs = {} if intorder is None else {"intorder": intorder}
    return skfem.Basis(mesh, skfem.ElementVector(scalar), **kwargs)


def _median_time(function, repeats: int):
    """(median seconds, last result) of ``repeats`` calls."""
    times, result = [], None
    for _ in range(repeats):
        result = None
        gc.collect()
        tic = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - tic)
    return statistics.median(times), times, result


def task_mesh(size: str, element: str) -> dict:
    """Generate (or reuse from the cache) the mesh and count it."""
    from femrom.mesh import generate_mesh

    tic = time.perf_counter()
    generate_mesh("beam_solid", {**GEOMETRY, "mesh_size": MESH_SIZES[size][element]})
    generate_seconds = time.perf_counter() - tic
    tic = time.perf_counter()
    mesh = _mesh(size, element)
    load_seconds = time.perf_counter() - tic
    n_nodes = mesh.p.shape[1] + (mesh.edges.shape[1] if element == "p2" else 0)
    return {"mesh_size": MESH_SIZES[size][element], "n_vertices": int(mesh.p.shape[1]),
            "n_elements": int(mesh.t.shape[1]), "n_total": 3 * int(n_nodes),
            "generate_seconds": generate_seconds, "load_seconds": load_seconds}


def task_assemble(size: str, element: str) -> dict:
    """femrom stiffness and consistent mass, on the cheap basis femrom itself uses."""
    from femrom.fem import elasticity_stiffness, vector_mass

    mesh = _mesh(size, element)
    tic = time.perf_counter()
    basis = _vector_basis(mesh, element, intorder=1)  # as femrom.fem.SolidSpace does
    basis_seconds = time.perf_counter() - tic
    repeats = ASSEMBLY_REPEATS[size]
    k_seconds, k_all, K = _median_time(
        lambda: elasticity_stiffness(basis, YOUNGS_MODULUS, POISSON_RATIO), repeats)
    nnz = int(K.nnz)
    del K
    m_seconds, m_all, M = _median_time(lambda: vector_mass(basis, DENSITY), repeats)
    return {"basis_seconds": basis_seconds, "stiffness_seconds": k_seconds,
            "stiffness_all": k_all, "mass_seconds": m_seconds, "mass_all": m_all,
            "n_total": int(basis.N), "nnz": nnz, "mass_nnz": int(M.nnz)}


def task_stock(size: str, element: str) -> dict:
    """skfem's stock form against femrom's, in one process on one default-quadrature basis."""
    import skfem
    from skfem.models.elasticity import linear_elasticity

    from femrom.fem import elasticity_stiffness, lame_parameters

    mesh = _mesh(size, element)
    tic = time.perf_counter()
    basis = _vector_basis(mesh, element, intorder=None)  # skfem's default quadrature
    basis_seconds = time.perf_counter() - tic
    repeats = STOCK_REPEATS[size]
    fast_seconds, fast_all, K_fast = _median_time(
        lambda: elasticity_stiffness(basis, YOUNGS_MODULUS, POISSON_RATIO), max(repeats, 1))
    form = linear_elasticity(*lame_parameters(YOUNGS_MODULUS, POISSON_RATIO))
    stock_seconds, stock_all, K_stock = _median_time(lambda: skfem.asm(form, basis), repeats)
    scale = abs(K_stock).max()
    difference = float(abs(K_stock.tocsr() - K_fast).max() / scale)
    return {"basis_seconds": basis_seconds, "quadrature_points": int(basis.X.shape[1]),
            "femrom_seconds": fast_seconds, "femrom_all": fast_all,
            "stock_seconds": stock_seconds, "stock_all": stock_all,
            "ratio": stock_seconds / fast_seconds, "max_relative_difference": difference}


class _StepClock:
    """Consumer: wall time between consecutive steps, and the last output ``y = E q``."""

    def __init__(self, system):
        self.system = system
        self.stamps: list[float] = []
        self.outputs: list[float] = []

    def __call__(self, result):
        self.stamps.append(time.perf_counter())
        self.outputs.append(float(np.ravel(self.system.outputs(result.q))[0]))

    @property
    def step_seconds(self) -> list[float]:
        return list(np.diff(self.stamps))


def _cantilever(size: str, element: str):
    """(system, near-nullspace on the free dofs, assembly seconds) of the clamped beam."""
    import scipy.sparse as sp

    from femrom.fem import (Condensation, average_rows, dirichlet_dofs, elasticity_stiffness,
                            rigid_body_modes, surface_traction, vector_mass)
    from femrom.scene import SecondOrderSystem

    mesh = _mesh(size, element)
    basis = _vector_basis(mesh, element, intorder=1)
    tic = time.perf_counter()
    condensation = Condensation.from_fixed(basis.N, dirichlet_dofs(basis, "left"))
    stiffness = condensation.matrix(elasticity_stiffness(basis, YOUNGS_MODULUS, POISSON_RATIO))
    mass = condensation.matrix(vector_mass(basis, DENSITY))
    load = condensation.vector(surface_traction(basis, "right", TIP_TRACTION))
    tip = condensation.columns(average_rows(basis, "right", 2))
    modes = condensation.vector(rigid_body_modes(basis))
    assembly_seconds = time.perf_counter() - tic
    system = SecondOrderSystem(
        mass=mass, stiffness=stiffness, input_matrix=load[:, None],
        inputs=lambda t: np.ones(1), output_matrix=sp.csr_matrix(tip),
        condensation=condensation, output_names=("tip_uz",))
    return system, modes, assembly_seconds


class _FreshEachSolve:
    """A solver that sets up a brand-new ``make_solver(A)`` for every solve (no reuse)."""

    total_iterations = None
    last_iterations = None

    def __init__(self, A, make):
        self.shape = A.shape
        self._A = A
        self._make = make
        self.name = "fresh"
        self.setup_seconds = 0.0
        self.n_factorizations = 0  # counted per solve in ``fresh_setups``
        self.fresh_setups = 0
        self.fresh_setup_seconds = 0.0
        self.n_solves = 0

    def solve(self, b, x0=None):
        solver = self._make(self._A)
        self.fresh_setups += 1
        self.fresh_setup_seconds += solver.setup_seconds
        self.n_solves += 1
        x = solver.solve(b, x0=x0)
        if solver.total_iterations is not None:
            self.total_iterations = (self.total_iterations or 0) + solver.total_iterations
        close = getattr(solver, "close", None)
        if callable(close):
            close()
        return x


def _solver_facts(solver) -> dict:
    """What a built solver says about itself (PARDISO: factor size from iparm)."""
    facts = {"name": getattr(solver, "name", "?"), "n": int(solver.shape[0]),
             "setup_seconds": float(getattr(solver, "setup_seconds", 0.0))}
    iparm = getattr(solver, "_iparm", None)  # private: read only for the report
    if iparm is not None:
        # MKL iparm (1-based): 15 peak analysis memory, 16 permanent memory,
        # 17 factorisation memory (kB), 18 nonzeros in the factor.
        facts["factor_nnz"] = int(iparm[17])
        facts["pardiso_peak_kb"] = int(max(iparm[14], iparm[15] + iparm[16]))
    if hasattr(solver, "n_levels"):
        facts["amg_levels"] = int(solver.n_levels)
    if getattr(solver, "total_iterations", None) is not None:
        facts["iterations"] = int(solver.total_iterations)
        facts["n_solves"] = int(solver.n_solves)
    return facts


def _warm_up(strategy: str) -> float:
    """Seconds of a first tiny solve: imports and library loading (MKL for PARDISO, ~1-3 s).

    Paid once per process, not per factorisation, so it is kept out of the
    setup times below and reported on its own.
    """
    import scipy.sparse as sp

    from femrom.solvers import make_solver

    tic = time.perf_counter()
    A = sp.diags(np.arange(1.0, 31.0)) + sp.eye(30, k=1) * 0.1 + sp.eye(30, k=-1) * 0.1
    make_solver(A.tocsr(), strategy=strategy, near_nullspace=np.ones((30, 1))).solve(np.ones(30))
    return time.perf_counter() - tic


def _newmark_run(system, make, fresh: bool, n_steps: int) -> dict:
    """One ``integrate(..., Newmark(), solver=factory)`` run; timings, counts and the tip output."""
    from femrom.integrators import Newmark, integrate

    built: list = []

    def factory(A, spd=True):
        solver = _FreshEachSolve(A, functools.partial(make, spd=spd)) if fresh \
            else make(A, spd=spd)
        built.append(solver)
        return solver

    clock = _StepClock(system)
    summary = integrate(system, Newmark(), np.zeros(system.n_dofs), np.zeros(system.n_dofs),
                        DT, n_steps, consumers=[clock], solver=factory, progress=False)
    steps = clock.step_seconds
    run = {
        "n_steps": summary.n_steps, "dt": summary.dt,
        "setup_seconds": summary.setup_seconds,
        "factorization_seconds": summary.factorization_seconds,
        "stepping_seconds": summary.stepping_seconds,
        "step_seconds_mean": summary.stepping_seconds / max(summary.n_steps, 1),
        "step_seconds_median": statistics.median(steps) if steps else None,
        "step_seconds": steps,
        "n_factorizations": summary.n_factorizations,
        "linear_iterations": summary.linear_iterations,
        "solver": summary.solver,
        "tip_uz": clock.outputs,
    }
    if fresh:
        run["fresh_setups"] = int(sum(s.fresh_setups for s in built))
        run["fresh_setup_seconds"] = float(sum(s.fresh_setup_seconds for s in built))
    else:
        run["solvers"] = [_solver_facts(s) for s in built]
    return run


def task_newmark(size: str, element: str, strategy: str, fresh: bool, n_steps: int) -> dict:
    """Newmark on the cantilever with one solver set up per matrix (or one per solve).

    Repeated ``NEWMARK_REPEATS[size]`` times in this process (each run sets up
    its own solvers; the previous ones are freed first, so the peak memory is
    that of one run); the reported numbers are medians over the runs.
    """
    from femrom.solvers import make_solver

    warm_up_seconds = _warm_up(strategy)
    system, modes, assembly_seconds = _cantilever(size, element)
    near_nullspace = modes if strategy == "amg-cg" else None
    make = functools.partial(make_solver, strategy=strategy, near_nullspace=near_nullspace)
    runs = []
    for _ in range(1 if fresh else NEWMARK_REPEATS[size]):
        gc.collect()  # frees the previous run's factors (the driver holds a reference cycle)
        runs.append(_newmark_run(system, make, fresh, n_steps))
    gc.collect()
    reuse = None
    if fresh:
        # The same steps with the factor reused, right after and in the same
        # process, so that both sides of the ratio see the same machine load.
        reuse = _newmark_run(system, make, False, n_steps)
        reuse.pop("tip_uz")
        gc.collect()
    median = {key: statistics.median(run[key] for run in runs)
              for key in ("setup_seconds", "factorization_seconds", "stepping_seconds",
                          "step_seconds_mean", "step_seconds_median")}
    result = {**runs[0], **median, "runs": runs, "n_runs": len(runs),
              "n_free": int(system.n_dofs), "system_assembly_seconds": assembly_seconds,
              "warm_up_seconds": warm_up_seconds, "tip_uz_final": runs[0]["tip_uz"][-1]}
    if not fresh:  # per-solver setup times: median over the runs, solver by solver
        result["solvers"] = [
            {**facts, "setup_seconds": statistics.median(run["solvers"][i]["setup_seconds"]
                                                          for run in runs)}
            for i, facts in enumerate(runs[0]["solvers"])]
    for run in runs[1:]:
        run.pop("tip_uz")  # identical to the first run's
    if reuse is not None:
        result["reuse_run"] = reuse
    return result


def task_naive_superlu(size: str, element: str, n_steps: int) -> dict:
    """The naive baseline: scipy's SuperLU factorising ``A_eff`` afresh at every step.

    What ``scipy.sparse.linalg.spsolve`` does per call; femrom's ``superlu``
    strategy refuses this size (:data:`femrom.solvers.SUPERLU_MAX_DOFS`),
    so the limit is lifted for these solves only. No reused SuperLU run here: the
    reuse side of the ratio is PARDISO's, measured in the same ladder run.
    """
    from femrom.solvers import make_solver

    system, _, assembly_seconds = _cantilever(size, element)

    def make(A, spd=True):  # the initial acceleration's mass solve is not what is measured
        return make_solver(A, "pardiso" if A is system.mass else "superlu", spd=spd, max_dofs=10**9)

    gc.collect()
    run = _newmark_run(system, make, True, n_steps)
    return {**run, "runs": [run], "n_runs": 1, "n_free": int(system.n_dofs),
            "system_assembly_seconds": assembly_seconds, "tip_uz_final": run["tip_uz"][-1]}


def run_single(spec: str) -> dict:
    size, element, task, n_steps = spec.split(",")
    n_steps = int(n_steps)
    tic = time.perf_counter()
    if task == "mesh":
        result = task_mesh(size, element)
    elif task == "assemble":
        result = task_assemble(size, element)
    elif task == "stock":
        result = task_stock(size, element)
    elif task == "naive-superlu":
        result = task_naive_superlu(size, element, n_steps)
    elif task.startswith("fresh-"):
        result = task_newmark(size, element, task.removeprefix("fresh-"), True, n_steps)
    else:
        result = task_newmark(size, element, task, False, n_steps)
    result.update(size=size, element=element, task=task, status="ok",
                  wall_seconds=time.perf_counter() - tic, peak_rss_gb=_peak_rss_gb())
    return result


# =============================================================================
# Parent side: run the ladder, one subprocess per configuration
# =============================================================================
#: Environment variables that set the thread count of MKL (PARDISO), OpenMP and OpenBLAS.
THREAD_VARIABLES = ("MKL_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def _child_environment(threads: int | None) -> dict:
    env = dict(os.environ)
    if threads is not None:
        env.update({name: str(threads) for name in THREAD_VARIABLES})
    return env


def _run_child(spec: str, memory_limit_gb: float, timeout: float,
               threads: int | None = None) -> dict:
    """Run ``--single spec`` in a subprocess; kill it above ``memory_limit_gb`` RSS."""
    import psutil

    size, element, task, _ = spec.split(",")
    command = [sys.executable, os.path.abspath(__file__), "--single", spec]
    tic = time.perf_counter()
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env=_child_environment(threads))
    sampled_peak, killed = [0.0], [None]

    def watch():
        try:
            process = psutil.Process(child.pid)
            while child.poll() is None:
                rss = process.memory_info().rss / 2**30
                sampled_peak[0] = max(sampled_peak[0], rss)
                if rss > memory_limit_gb:
                    killed[0] = f"killed: RSS {rss:.1f} GB above --memory-limit-gb {memory_limit_gb}"
                    child.kill()
                elif time.perf_counter() - tic > timeout:
                    killed[0] = f"killed: over the {timeout:.0f} s timeout"
                    child.kill()
                time.sleep(0.2)
        except psutil.NoSuchProcess:
            pass

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    stdout, stderr = child.communicate()
    watcher.join()
    wall = time.perf_counter() - tic
    for line in stdout.splitlines():
        if line.startswith("RESULT "):
            result = json.loads(line[len("RESULT "):])
            result["process_seconds"] = wall
            result["sampled_peak_rss_gb"] = sampled_peak[0]
            return result
    reason = killed[0] or f"failed (exit {child.returncode}): {stderr.strip().splitlines()[-1:]}"
    return {"size": size, "element": element, "task": task, "status": reason,
            "process_seconds": wall, "sampled_peak_rss_gb": sampled_peak[0],
            "stderr_tail": stderr.strip().splitlines()[-5:]}


def _available_strategies() -> list[str]:
    from femrom.solvers import is_available

    return [s for s in STRATEGY_ORDER if is_available(s)]


def _stock_estimate(results: list[dict], size: str, element: str, n_elements: int):
    """(seconds, GB) estimate of the stock form from the largest smaller size run so far."""
    measured = [r for r in results if r["element"] == element and r["task"] == "stock"
                and r["status"] == "ok"]
    meshes = {r["size"]: r for r in results if r["element"] == element and r["task"] == "mesh"
              and r["status"] == "ok"}
    if measured and measured[-1]["size"] in meshes:
        last = measured[-1]
        scale = n_elements / meshes[last["size"]]["n_elements"]
        # time and memory both grow linearly with the number of elements
        return (last["stock_seconds"] + last["basis_seconds"]) * scale, last["peak_rss_gb"] * scale
    return (STOCK_SECONDS_PER_ELEMENT[element] * n_elements,
            STOCK_GB_PER_ELEMENT[element] * n_elements)


def _plan(size: str, element: str, strategies: list[str], naive: bool = False) -> list[str]:
    tasks = ["mesh", "assemble", "stock"]
    for strategy in strategies:
        if strategy == "superlu" and size != "small":
            continue  # SuperLU is unusable on 3D elasticity beyond ~2e4 dofs
        tasks.append(strategy)
    if size in FRESH_SIZES:
        tasks += [f"fresh-{s}" for s in strategies if s != "superlu" or size == "small"]
    if naive and size == "medium":
        tasks.append("naive-superlu")
    return tasks


def _steps_for(task: str, size: str, steps: int, amg_steps: int | None) -> int:
    if task == "naive-superlu":
        return 1  # one SuperLU factorisation of A_eff: 18-31 s and 1.7-2.3 GB at 1e5 dofs (docs/benchmarks.md, 4b)
    if task.startswith("fresh-"):
        return FRESH_STEPS[size]
    if task == "amg-cg":
        return AMG_STEPS[size] if amg_steps is None else amg_steps
    return steps


def run_ladder(sizes, elements, memory_limit_gb: float, timeout: float, log, *,
               steps: int = STEPS, amg_steps: int | None = None,
               stock_max_seconds: float = STOCK_MAX_SECONDS,
               threads: int | None = None, naive: bool = False) -> list[dict]:
    strategies = _available_strategies()
    results: list[dict] = []
    for size in sizes:
        for element in elements:
            for task in _plan(size, element, strategies, naive):
                if task == "stock":
                    mesh = next(r for r in results if r["size"] == size
                                and r["element"] == element and r["task"] == "mesh")
                    seconds, gigabytes = _stock_estimate(results, size, element,
                                                         mesh.get("n_elements", 0))
                    if seconds > stock_max_seconds or gigabytes > memory_limit_gb:
                        results.append({"size": size, "element": element, "task": "stock",
                                        "status": "skipped", "estimated_seconds": seconds,
                                        "estimated_peak_rss_gb": gigabytes})
                        log(f"{size:6s} {element} stock    skipped: estimated {seconds:.0f} s, "
                            f"{gigabytes:.1f} GB")
                        continue
                n_steps = _steps_for(task, size, steps, amg_steps)
                result = _run_child(f"{size},{element},{task},{n_steps}", memory_limit_gb,
                                    timeout, threads)
                results.append(result)
                log(f"{size:6s} {element} {task:14s} {result['status']:4s} "
                    f"{result['process_seconds']:7.1f} s  peak {result.get('peak_rss_gb', result['sampled_peak_rss_gb']):.2f} GB")
    for strategy in ("cholmod",):
        if strategy not in strategies:
            results.append({"size": "-", "element": "-", "task": strategy,
                            "status": "not installed (scikit-sparse)"})
    return results


# -- tables ---------------------------------------------------------------------
def _find(results, size, element, task):
    return next((r for r in results if r["size"] == size and r["element"] == element
                 and r["task"] == task), None)


def _fmt(value, digits=3):
    if value is None:
        return "-"
    if isinstance(value, (int, np.integer)):
        return f"{value:,}"
    if value == 0:
        return "0"
    if abs(value) >= 100:
        return f"{value:.0f}"
    return f"{value:.{digits}g}"


def assembly_table(results, sizes, elements) -> str:
    lines = ["| size | element | dofs | tets | K femrom [s] | K stock [s] | stock/femrom | "
             "max rel. diff | M femrom [s] | peak RSS femrom [GB] | peak RSS stock [GB] |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for size in sizes:
        for element in elements:
            mesh = _find(results, size, element, "mesh") or {}
            asm = _find(results, size, element, "assemble") or {}
            stock = _find(results, size, element, "stock") or {}
            if stock.get("status") == "ok":
                k_stock = _fmt(stock["stock_seconds"])
                ratio = f"{stock['ratio']:.1f}x"
                diff = f"{stock['max_relative_difference']:.1e}"
                stock_rss = _fmt(stock["peak_rss_gb"])
            elif stock.get("status") == "skipped":
                k_stock = f"skipped (est. {stock['estimated_seconds']:.0f} s)"
                ratio = "-"
                diff = "-"
                stock_rss = f"est. {stock['estimated_peak_rss_gb']:.1f}"
            else:
                k_stock, ratio, diff, stock_rss = stock.get("status", "-"), "-", "-", "-"
            lines.append(
                f"| {size} | {element.upper()} | {_fmt(mesh.get('n_total'))} | "
                f"{_fmt(mesh.get('n_elements'))} | {_fmt(asm.get('stiffness_seconds'))} | "
                f"{k_stock} | {ratio} | {diff} | {_fmt(asm.get('mass_seconds'))} | "
                f"{_fmt(asm.get('peak_rss_gb'))} | {stock_rss} |")
    return "\n".join(lines)


def _tip_difference(r, reference) -> str:
    """max |y - y_ref| / max |y_ref| of the tip u_z over the steps both runs took."""
    if reference is None or reference.get("status") != "ok" or reference is r:
        return "-"
    k = min(len(r["tip_uz"]), len(reference["tip_uz"]))
    y, y_ref = np.asarray(r["tip_uz"][:k]), np.asarray(reference["tip_uz"][:k])
    return f"{np.max(np.abs(y - y_ref)) / np.max(np.abs(y_ref)):.1e}"


def stepping_table(results, sizes, elements) -> str:
    lines = ["| size | element | free dofs | strategy | setup [s] | factor M [s] | "
             "factor A_eff [s] | step mean [s] | step median [s] | CG it./step | steps | "
             "setup + steps [s] | peak RSS [GB] | nnz(L) of A_eff | tip u_z vs pardiso |",
             "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for size in sizes:
        for element in elements:
            reference = _find(results, size, element, "pardiso")
            for strategy in STRATEGY_ORDER:
                r = _find(results, size, element, strategy)
                if r is None:
                    continue
                if r["status"] != "ok":
                    lines.append(f"| {size} | {element.upper()} | - | {strategy} | "
                                 f"{r['status']} | | | | | | | | "
                                 f"{_fmt(r.get('sampled_peak_rss_gb'))} | | |")
                    continue
                mass, effective = (r["solvers"] + [{}, {}])[:2]
                its = effective.get("iterations")
                per_step = "-" if its is None else f"{its / max(effective['n_solves'], 1):.0f}"
                run = r["setup_seconds"] + r["stepping_seconds"]
                lines.append(
                    f"| {size} | {element.upper()} | {_fmt(r['n_free'])} | {strategy} | "
                    f"{_fmt(r['setup_seconds'])} | {_fmt(mass.get('setup_seconds'))} | "
                    f"{_fmt(effective.get('setup_seconds'))} | "
                    f"{_fmt(r['step_seconds_mean'])} | {_fmt(r['step_seconds_median'])} | "
                    f"{per_step} | {r['n_steps']} | {_fmt(run)} | {_fmt(r['peak_rss_gb'])} | "
                    f"{_fmt(effective.get('factor_nnz'))} | {_tip_difference(r, reference)} |")
    return "\n".join(lines)


def reuse_table(results, sizes, elements) -> str:
    lines = ["| size | element | free dofs | strategy | steps | fresh setup + solve per step [s] | "
             "reused solve per step [s] | fresh/reused | reused step, long run [s] | "
             "peak RSS [GB] |",
             "|---|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    for size in sizes:
        for element in elements:
            for strategy in STRATEGY_ORDER:
                fresh = _find(results, size, element, f"fresh-{strategy}")
                if fresh is None:
                    continue
                if fresh["status"] != "ok":
                    lines.append(f"| {size} | {element.upper()} | - | {strategy} | | "
                                 f"{fresh['status']} | | | | |")
                    continue
                reuse = fresh["reuse_run"]
                long_run = _find(results, size, element, strategy) or {}
                ratio = fresh["step_seconds_median"] / reuse["step_seconds_median"]
                lines.append(
                    f"| {size} | {element.upper()} | {_fmt(fresh['n_free'])} | {strategy} | "
                    f"{fresh['n_steps']} | {_fmt(fresh['step_seconds_median'])} | "
                    f"{_fmt(reuse['step_seconds_median'])} | {ratio:.1f}x | "
                    f"{_fmt(long_run.get('step_seconds_median'))} | "
                    f"{_fmt(fresh['peak_rss_gb'])} |")
            naive = _find(results, size, element, "naive-superlu")
            pardiso = _find(results, size, element, "fresh-pardiso")
            if naive is not None and naive["status"] == "ok" and pardiso is not None \
                    and pardiso["status"] == "ok":
                reuse = pardiso["reuse_run"]
                lines.append(
                    f"| {size} | {element.upper()} | {_fmt(naive['n_free'])} | fresh superlu (naive) "
                    f"vs reused pardiso | {naive['n_steps']} | {_fmt(naive['step_seconds_median'])} | "
                    f"{_fmt(reuse['step_seconds_median'])} | "
                    f"{naive['step_seconds_median'] / reuse['step_seconds_median']:.0f}x | | "
                    f"{_fmt(naive['peak_rss_gb'])} |")
    return "\n".join(lines)


def _femrom_version() -> dict:
    import femrom

    root = Path(__file__).resolve().parents[1]
    info = {"version": femrom.__version__}
    if "unknown" in info["version"] and (root / "pyproject.toml").is_file():
        import tomllib

        info["pyproject_version"] = tomllib.loads(
            (root / "pyproject.toml").read_text())["project"]["version"]
    try:
        info["git_commit"] = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"],
                                            capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--", "femrom"],
                               capture_output=True, text=True).stdout.strip()
        info["library_modified_since_commit"] = bool(dirty)
    except OSError:
        pass
    return info


def _parse_list(text: str, valid, what: str) -> list[str]:
    items = [s.strip() for s in text.split(",") if s.strip()]
    bad = [s for s in items if s not in valid]
    if bad or not items:
        raise SystemExit(f"unknown {what} {bad}; valid: {', '.join(valid)}")
    return items


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default="small,medium,large",
                        help="comma-separated subset of small, medium, large")
    parser.add_argument("--elements", default="p1,p2", help="comma-separated subset of p1, p2")
    parser.add_argument("--out", default="benchmarks/results/fom_ladder.json",
                        help="JSON file for the raw numbers and the tables")
    parser.add_argument("--memory-limit-gb", type=float, default=None,
                        help="kill a configuration whose RSS exceeds this (default: 85%% of RAM, "
                             "at most 20)")
    parser.add_argument("--timeout", type=float, default=1800.0,
                        help="kill a configuration running longer than this (s)")
    parser.add_argument("--steps", type=int, default=STEPS,
                        help="Newmark steps with the direct strategies")
    parser.add_argument("--amg-steps", type=int, default=None,
                        help=f"Newmark steps with amg-cg (default per size: {AMG_STEPS})")
    parser.add_argument("--stock-max-seconds", type=float, default=STOCK_MAX_SECONDS,
                        help="skip skfem's stock form where its estimated time exceeds this")
    parser.add_argument("--threads", type=int, default=None,
                        help="set MKL/OpenMP/OpenBLAS threads of every configuration "
                             "(default: leave the environment alone)")
    parser.add_argument("--naive-baseline", action="store_true",
                        help="also time scipy's SuperLU factorising afresh every step at the medium "
                             "size (measured: 18-31 s and 1.7-2.3 GB a step at 1e5 dofs), against PARDISO's reused factor")
    parser.add_argument("--single", help=argparse.SUPPRESS)  # child mode: size,element,task
    args = parser.parse_args(argv)

    try:
        import femrom  # noqa: F401
    except ImportError:
        raise SystemExit("femrom is not importable: run `pip install -e .` in the repository, "
                         "or `python -m benchmarks.fom_ladder`")

    if args.single:
        print("RESULT " + json.dumps(run_single(args.single)), flush=True)
        return 0

    import psutil

    from femrom.post import machine_description

    sizes = _parse_list(args.sizes, MESH_SIZES, "sizes")
    elements = _parse_list(args.elements, ("p1", "p2"), "elements")
    total_gb = psutil.virtual_memory().total / 2**30
    limit = args.memory_limit_gb or min(20.0, 0.85 * total_gb)
    started = datetime.now(timezone.utc)
    tic = time.perf_counter()

    def log(message):
        print(f"[{time.perf_counter() - tic:7.1f} s] {message}", file=sys.stderr, flush=True)

    log(f"sizes {sizes}, elements {elements}, strategies {_available_strategies()}, "
        f"memory limit {limit:.1f} GB")
    results = run_ladder(sizes, elements, limit, args.timeout, log, steps=args.steps,
                         amg_steps=args.amg_steps, stock_max_seconds=args.stock_max_seconds,
                         threads=args.threads, naive=args.naive_baseline)
    total_seconds = time.perf_counter() - tic
    tables = {"assembly": assembly_table(results, sizes, elements),
              "stepping": stepping_table(results, sizes, elements),
              "reuse": reuse_table(results, sizes, elements)}
    for title, table in tables.items():
        print(f"\n## {title}\n\n{table}")
    print(f"\ntotal benchmark time: {total_seconds:.0f} s")

    record = {
        "benchmark": "fom_ladder", "timestamp": started.isoformat(timespec="seconds"),
        "total_seconds": total_seconds, "machine": machine_description(),
        "femrom": _femrom_version(),
        "libraries": _library_versions(),
        "note": "timings from a shared 2-core machine (other processes may have run)",
        "problem": {"geometry": "beam_solid", **GEOMETRY, "mesh_sizes": MESH_SIZES,
                    "youngs_modulus": YOUNGS_MODULUS, "poisson_ratio": POISSON_RATIO,
                    "density": DENSITY, "clamped": "left", "tip_traction": TIP_TRACTION,
                    "load": "right, step at t = 0", "dt": DT, "scheme": "Newmark (1/4, 1/2)",
                    "steps": args.steps, "amg_steps": args.amg_steps or AMG_STEPS,
                    "stock_max_seconds": args.stock_max_seconds,
                    "fresh_steps": FRESH_STEPS},
        "threads": {name: _child_environment(args.threads).get(name)
                    for name in THREAD_VARIABLES},
        "sizes": sizes, "elements": elements, "memory_limit_gb": limit,
        "results": results, "tables": tables,
    }
    from femrom.post import write_metrics

    path = write_metrics(args.out, record)
    print(f"wrote {path}")
    return 0


def _library_versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    versions = {"python": platform.python_version()}
    for name in ("numpy", "scipy", "scikit-fem", "pyamg", "pypardiso", "mkl", "gmsh",
                 "scikit-sparse"):
        try:
            versions[name] = version(name)
        except PackageNotFoundError:
            versions[name] = None
    return versions


if __name__ == "__main__":
    sys.exit(main())
