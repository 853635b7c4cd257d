"""What the interface laws' compiled kernels cost against numpy: a law evaluation, and the first call.

1. **First call.** A fresh Python process imports femrom, then evaluates a ``clamped_iwan`` and an
   ``iwan`` law once (traction and tangent, then a commit): the first ``compiled_laws()`` (it
   imports numba), the first evaluation and commit of each law (compilation, or loading from the
   on-disk cache), and a second evaluation (the steady cost). ``cold``: numba's cache directory
   (``NUMBA_CACHE_DIR``) is a new empty folder, so every kernel compiles; ``warm``: the same folder
   again, so every kernel loads. ``--processes`` of each, alternating.
2. **A law evaluation.** ``s`` points x the law's sliders at random states (a third of the points
   sliding, the clamped law with a fifth of its points open), as the hyper-reduced jointed beam
   evaluates them (46 sampled pairs, 21 sliders): ``evaluate`` with the tangent, and ``commit``,
   numpy against compiled in alternating blocks of ``--calls`` calls, ``--repeats`` blocks each;
   medians of the blocks' mean call times and their spread (min-max).

Run ``python -m benchmarks.law_kernels`` (about a minute); it prints tables and writes
``benchmarks/results/law_kernels.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from femrom.fem import ClampedIwanLaw, compiled_laws, interface_law, use_compiled_laws

RESULTS = Path(__file__).resolve().parent / "results" / "law_kernels.json"

FIRST_CALL = r"""
import json, time
tic = time.perf_counter()
import numpy as np
from femrom.fem import ClampedIwanLaw, compiled_laws, interface_law
out = {"import_femrom": time.perf_counter() - tic}
tic = time.perf_counter()
assert compiled_laws()
out["import_numba"] = time.perf_counter() - tic
rng = np.random.default_rng(0)
for name, law, state in (
        ("clamped_iwan", ClampedIwanLaw(1e12, 1e11, -0.5, 0.4), None),
        ("iwan", interface_law("iwan", slip_traction=1e5, tangential_stiffness=1e11, chi=-0.5, beta=0.4,
                               normal_stiffness=1e12, n_sliders=20), None)):
    state = law.initial_state(46)
    gap = rng.normal(0.0, 1e-6, (46, 3))
    tic = time.perf_counter(); law.evaluate(gap, state); out[name + "_first_evaluate"] = time.perf_counter() - tic
    tic = time.perf_counter(); law.commit(gap, state); out[name + "_first_commit"] = time.perf_counter() - tic
    tic = time.perf_counter(); law.evaluate(gap, state); out[name + "_second_evaluate"] = time.perf_counter() - tic
print(json.dumps(out))
"""


def first_calls(processes: int) -> dict:
    """Seconds of each first call in fresh processes, cold and warm cache (lists, one per process)."""
    runs = {"cold": [], "warm": []}
    root = Path(__file__).resolve().parents[1]
    for _ in range(processes):
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "NUMBA_CACHE_DIR": cache, "FEMROM_COMPILED_LAWS": "1",
                   "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
            for kind in ("cold", "warm"):
                out = subprocess.run([sys.executable, "-c", FIRST_CALL], env=env, capture_output=True, text=True,
                                     check=True, cwd=root)
                runs[kind].append(json.loads(out.stdout))
    return {kind: {key: [run[key] for run in values] for key in values[0]} for kind, values in runs.items()}


def law_states(s: int, rng):
    """``{name: (law, gap, state)}`` at the jointed beam's sizes, a third of the points sliding."""
    clamped = ClampedIwanLaw(1e12, 1e11, -0.5, 0.4)                 # 20 + 1 sliders, as the case
    iwan = interface_law("iwan", slip_traction=1e5, tangential_stiffness=1e11, chi=-0.5, beta=0.4,
                         normal_stiffness=1e12, n_sliders=20)
    jenkins = interface_law("jenkins", tangential_stiffness=1e11, slip_traction=1e5, normal_stiffness=1e12)
    scale = 1e5 / 1e11
    out = {}
    for name, law in (("clamped_iwan", clamped), ("iwan", iwan), ("jenkins", jenkins)):
        gap = rng.normal(0.0, 0.3 * scale, (s, 3))
        gap[: s // 3, :2] *= 10.0                                    # these points slide
        state = law.initial_state(s)
        n = law.slider_stiffness.size
        state[:, :n] = rng.normal(0.0, 0.1 * scale, (s, n, 2))
        if name == "clamped_iwan":
            state[:, n, 0] = 1e5 * rng.uniform(0.5, 1.5, s)
            state[:, n, 1] = rng.uniform(size=s) > 0.2
        out[name] = (law, gap, state)
    return out


def mean_call(call, n_calls: int) -> float:
    tic = time.perf_counter()
    for _ in range(n_calls):
        call()
    return (time.perf_counter() - tic) / n_calls


def evaluations(s: int, n_calls: int, repeats: int) -> dict:
    cases = law_states(s, np.random.default_rng(1))
    for law, gap, state in cases.values():                           # compile (or load) before timing
        law.evaluate(gap, state), law.commit(gap, state)
    seconds = {}
    for _ in range(repeats):
        for compiled in (False, True):
            use_compiled_laws(compiled)
            path = "compiled" if compiled else "numpy"
            for name, (law, gap, state) in cases.items():
                for what, call in (("evaluate", lambda: law.evaluate(gap, state)),
                                   ("commit", lambda: law.commit(gap, state))):
                    seconds.setdefault((name, what, path), []).append(mean_call(call, n_calls))
    use_compiled_laws(True)
    out = {}
    for (name, what, path), values in seconds.items():
        entry = out.setdefault(name, {"sliders": int(cases[name][0].slider_stiffness.size)}).setdefault(what, {})
        entry[path] = {"median_us": 1e6 * statistics.median(values), "min_us": 1e6 * min(values),
                       "max_us": 1e6 * max(values), "all_us": [1e6 * v for v in values]}
    for entry in out.values():
        for what in ("evaluate", "commit"):
            entry[what]["speedup"] = entry[what]["numpy"]["median_us"] / entry[what]["compiled"]["median_us"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, default=46)
    parser.add_argument("--calls", type=int, default=500)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--processes", type=int, default=3)
    args = parser.parse_args()
    if not compiled_laws():
        raise SystemExit("the compiled kernels are off (numba missing or FEMROM_COMPILED_LAWS=0)")
    first = first_calls(args.processes)
    law = evaluations(args.points, args.calls, args.repeats)
    print("| first call (fresh process) | cold cache [s] | warm cache [s] |\n|---|---|---|")
    for key in first["cold"]:
        cold, warm = first["cold"][key], first["warm"][key]
        print(f"| {key} | {statistics.median(cold):.3f} ({min(cold):.3f}-{max(cold):.3f}) "
              f"| {statistics.median(warm):.3f} ({min(warm):.3f}-{max(warm):.3f}) |")
    print(f"\n| law ({args.points} points) | sliders | call | numpy [us] | compiled [us] | speed-up |"
          "\n|---|---|---|---|---|---|")
    for name, entry in law.items():
        for what in ("evaluate", "commit"):
            n, c = entry[what]["numpy"], entry[what]["compiled"]
            print(f"| {name} | {entry['sliders']} | {what} | {n['median_us']:.1f} ({n['min_us']:.1f}-{n['max_us']:.1f}) "
                  f"| {c['median_us']:.1f} ({c['min_us']:.1f}-{c['max_us']:.1f}) | {entry[what]['speedup']:.1f} |")
    result = {"machine": platform.platform(), "points": args.points, "calls_per_block": args.calls,
              "repeats": args.repeats, "processes": args.processes, "first_call_seconds": first,
              "law_call": law}
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=1))
    print(f"written: {RESULTS}")


if __name__ == "__main__":
    main()
