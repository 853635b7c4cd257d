"""Cost of one reduced step of an SpML ROM (discrete-gradient scheme): the fused compiled step against
the numpy step and against a linear ROM step, and the compiled kernels' first-call cost.

The model: the default networks (potential: monomials of degree 3 and 4 and a tanh MLP 32 x 32;
dissipation: convex powers and a softplus network of width 16), random weights exported from the
training module (``spml_module(r).export()`` after a random perturbation, as ``spml_step.py``),
a random SPD stiffness and light damping, ringing down from a random state; r = 4, 8, 12.
Three paths, ``--steps`` steps each, in alternating blocks (``--repeats``) in one process:

- ``linear``: the same ROM without the learned terms (the midpoint rule, one solve a step);
- ``numpy``: the reference (``use_compiled_laws(False)``): the terms' numpy value, gradient and
  Hessian at the two Gauss nodes, the Newton loop in Python;
- ``compiled``: the whole step in one numba call (:class:`femrom.integrators._fused.FusedDiscreteGradientStep`).

Reported: the median over blocks of the stepping time per step (``predict``'s ``stepping_seconds``),
its spread (min-max over blocks), the Newton iterations per step, and the ratios numpy / compiled and
compiled / linear. The compile cost: the first ``predict`` of one step in a fresh process with an empty
numba cache directory (cold) and again in a second fresh process on that cache (warm).

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


def per_step(rom, q0, v0, steps: int, compiled: bool | None):
    from femrom.fem import use_compiled_laws

    previous = use_compiled_laws(bool(compiled) if compiled is not None else True)
    try:
        s = rom.predict(DT * np.arange(steps + 1), initial=(q0, v0), scheme="discrete_gradient")
    finally:
        use_compiled_laws(previous)
    iterations = s.info.get("newton_iterations", 0)
    return s.info["stepping_seconds"] / steps, float(np.sum(iterations)) / steps, s


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
        fast, _, s_fast = per_step(rom, q0, v0, 5, True)           # compile / load before timing
        _, _, s_ref = per_step(rom, q0, v0, args.steps, False)
        _, _, s_fast = per_step(rom, q0, v0, args.steps, True)
        difference = float(np.abs(s_fast.q - s_ref.q).max() / np.abs(s_ref.q).max())
        same_iterations = s_fast.info["newton_iterations"] == s_ref.info["newton_iterations"]
        times = {"linear": [], "numpy": [], "compiled": []}
        iterations = {}
        for _ in range(args.repeats):
            for name, rom_, compiled in (("linear", linear, None), ("numpy", rom, False), ("compiled", rom, True)):
                seconds, its, _ = per_step(rom_, q0, v0, args.steps, compiled)
                times[name].append(seconds)
                iterations[name] = its
        med = {k: float(np.median(v)) for k, v in times.items()}
        row = {"r": r, "learned_terms": n_terms, "newton_iterations_per_step": iterations["compiled"],
               "same_iterations": bool(same_iterations), "max_relative_q_difference": difference,
               **{f"{k}_us": med[k] * 1e6 for k in med},
               **{f"{k}_spread_us": [min(v) * 1e6, max(v) * 1e6] for k, v in times.items()},
               "numpy_over_compiled": med["numpy"] / med["compiled"],
               "compiled_over_linear": med["compiled"] / med["linear"]}
        row["first_call_s"] = first_call(r)
        rows.append(row)
        print(f"r = {r:2d}: linear {row['linear_us']:6.1f} us, numpy {row['numpy_us']:7.1f} us, compiled "
              f"{row['compiled_us']:6.1f} us [{row['compiled_spread_us'][0]:.1f}, {row['compiled_spread_us'][1]:.1f}]"
              f" ({iterations['compiled']:.2f} Newton it./step), numpy/compiled {row['numpy_over_compiled']:5.1f}, "
              f"compiled/linear {row['compiled_over_linear']:4.1f}; q equal to {difference:.1e}, same iterations "
              f"{same_iterations}; first call cold {row['first_call_s']['cold']:.1f} s, warm "
              f"{row['first_call_s']['warm']:.2f} s", flush=True)
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
