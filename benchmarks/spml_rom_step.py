"""Cost of one reduced step of an SpML ROM (discrete-gradient scheme): the compiled march (the chord
iteration and Newton), the fused compiled step called step by step, the numpy step and a linear ROM step,
and the compiled kernels' first-call cost.

The model: the default networks (potential: monomials of degree 3 and 4 and a tanh MLP 32 x 32;
dissipation: convex powers and a softplus network of width 16), random weights exported from the
training module (``spml_module(r).export()`` after a random perturbation, as ``spml_step.py``),
a random SPD stiffness and light damping, ringing down from a random state; r = 4, 8, 12.
Five paths, ``--steps`` steps each, in alternating blocks (``--repeats``) in one process, each through
:func:`femrom.integrators.march` (what ``predict`` calls):

- ``linear``: the same ROM without the learned terms (the midpoint rule's linear map);
- ``numpy``: the reference (``use_compiled_laws(False)``): the terms' numpy value, gradient and
  Hessian at the two Gauss nodes, the Newton loop in Python;
- ``step``: the fused compiled step (:class:`femrom.integrators._fused.FusedDiscreteGradientStep`), one
  numba call a step from the Python loop (``march(..., whole=False)``; the path before the march);
- ``newton``: the whole trajectory in one compiled call, Newton at every iterate (``Newton(refactor_ratio=0)``:
  the reference's iteration);
- ``march``: the default, the whole trajectory in one compiled call by the chord iteration (one Jacobian a
  step or fewer, the predictor from the extrapolated learned force).

Reported: the median over blocks of the stepping time per step (``march``'s ``stepping_seconds``), its
spread (min-max over blocks), the Newton iterations (updates) and Jacobians per step (a Jacobian: the
potential's Hessian at the two Gauss nodes and the dissipation's at ``v_m``), the ratios, the largest
difference of the chord march's ``q`` from the numpy reference's relative to its largest entry, and
whether the Newton march takes the reference's iterations. The compile cost: the first ``predict`` of
one step in a fresh process with an empty numba cache directory (cold) and again in a second fresh
process on that cache (warm).

Run ``python -m benchmarks.spml_rom_step``; writes ``benchmarks/results/spml_rom_step.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DT = 0.01


def spml_rom(r: int, seed: int = 0):
    """``(rom, linear rom, q0, v0)`` of the default SpML shape at ``r``."""
    import torch

    from femrom.inference import LearnedDissipation, LearnedPotential, ReducedOperators, SpMLConfig, spml_module
    from femrom.rom import SecondOrderROM

    torch.set_num_threads(1)
    module = spml_module(r, SpMLConfig(learn_dissipation=True), seed=seed)
    with torch.no_grad():
        generator = torch.Generator().manual_seed(1)
        for p in module.parameters():
            p.add_(0.1 * torch.randn(p.shape, dtype=p.dtype, generator=generator))
    mass, _, polynomial, u_network, powers, f_network = module.export()
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((r, r))
    K = A @ A.T / r + np.diag(np.linspace(1.0, 10.0, r)) ** 2
    C = 0.01 * np.eye(r)
    linear = ReducedOperators.from_matrices(K, mass=mass, damping=C)
    terms = [LearnedPotential(r, polynomial, u_network)]
    if powers is not None or f_network is not None:
        terms.append(LearnedDissipation(r, powers, f_network))
    q0 = 0.3 * rng.standard_normal(r) / np.sqrt(r)
    return SecondOrderROM(linear.with_terms(*terms)), SecondOrderROM(linear), q0, np.zeros(r), len(terms)


PATHS = ("linear", "numpy", "step", "newton", "march")


def per_step(rom, linear, q0, v0, steps: int, path: str):
    """``(seconds, iterations, jacobians)`` per step and the run (``march``'s dict) of one path."""
    from femrom.fem import use_compiled_laws
    from femrom.integrators import DiscreteGradient, Newton, march

    scheme = DiscreteGradient(newton=Newton(refactor_ratio=0.0)) if path == "newton" else DiscreteGradient()
    previous = use_compiled_laws(path != "numpy")
    try:
        model = (linear if path == "linear" else rom).model
        run = march(model, scheme, DT * np.arange(steps + 1), q0, v0, whole=path != "step")
    finally:
        use_compiled_laws(previous)
    iterations = float(np.sum(run["newton_iterations"]))
    jacobians = float(run.get("jacobians", iterations))      # Newton forms one an iteration
    return run["stepping_seconds"] / steps, iterations / steps, jacobians / steps, run


FIRST_CALL = """
import time
from benchmarks.spml_rom_step import spml_rom
import numpy as np
rom, _, q0, v0, _ = spml_rom({r})
tic = time.perf_counter()
rom.predict(np.array([0.0, 0.01]), initial=(q0, v0), scheme="discrete_gradient")
print(time.perf_counter() - tic)
"""


def first_call(r: int) -> dict:
    """Seconds of the first one-step ``predict`` in a fresh process: empty numba cache, then warm."""
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(ROOT))
        for name in ("cold", "warm"):
            run = subprocess.run([sys.executable, "-c", FIRST_CALL.format(r=r)], env=env, cwd=ROOT,
                                 capture_output=True, text=True, check=True)
            out[name] = float(run.stdout.strip().splitlines()[-1])
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[4, 8, 12])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "spml_rom_step.json")
    args = parser.parse_args(argv)
    load_before = os.getloadavg()
    rows = []
    for r in args.sizes:
        rom, linear, q0, v0, n_terms = spml_rom(r)
        for path in PATHS:                                          # compile / load before timing
            per_step(rom, linear, q0, v0, 5, path)
        runs = {path: per_step(rom, linear, q0, v0, args.steps, path)[3] for path in ("numpy", "newton", "march")}
        reference = runs["numpy"]
        difference = float(np.abs(runs["march"]["q"] - reference["q"]).max() / np.abs(reference["q"]).max())
        same_iterations = runs["newton"]["newton_iterations"] == reference["newton_iterations"]
        times = {path: [] for path in PATHS}
        counts = {}
        for _ in range(args.repeats):
            for path in PATHS:
                seconds, its, jacobians, _ = per_step(rom, linear, q0, v0, args.steps, path)
                times[path].append(seconds)
                counts[path] = {"iterations": its, "jacobians": jacobians}
        med = {k: float(np.median(v)) for k, v in times.items()}
        row = {"r": r, "learned_terms": n_terms,
               "newton_iterations_per_step": {p: counts[p]["iterations"] for p in PATHS if p != "linear"},
               "jacobians_per_step": {p: counts[p]["jacobians"] for p in PATHS if p != "linear"},
               "potential_hessians_per_step": {p: 2 * counts[p]["jacobians"] for p in PATHS if p != "linear"},
               "newton_march_same_iterations_as_numpy": bool(same_iterations),
               "march_max_relative_q_difference": difference,
               **{f"{k}_us": med[k] * 1e6 for k in med},
               **{f"{k}_spread_us": [min(v) * 1e6, max(v) * 1e6] for k, v in times.items()},
               "numpy_over_march": med["numpy"] / med["march"], "step_over_march": med["step"] / med["march"],
               "march_over_linear": med["march"] / med["linear"]}
        row["first_call_s"] = first_call(r)
        rows.append(row)
        print(f"r = {r:2d}: " + ", ".join(f"{p} {row[p + '_us']:.1f} us [{row[p + '_spread_us'][0]:.1f}, "
                                          f"{row[p + '_spread_us'][1]:.1f}]" for p in PATHS), flush=True)
        print(f"        iterations/step " + ", ".join(f"{p} {counts[p]['iterations']:.2f}" for p in PATHS[1:])
              + "; Jacobians/step " + ", ".join(f"{p} {counts[p]['jacobians']:.2f}" for p in PATHS[1:])
              + f"; march q equal to {difference:.1e}, Newton march same iterations {same_iterations}; first call "
              f"cold {row['first_call_s']['cold']:.1f} s, warm {row['first_call_s']['warm']:.2f} s", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                                    "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                                                "load_average_before": load_before,
                                                "load_average_after": os.getloadavg()},
                                    "dt": DT, "steps": args.steps, "repeats": args.repeats, "rows": rows},
                                   indent=1))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
