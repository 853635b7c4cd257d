"""Per-call cost of SpML's learned force and tangent: exported numpy against torch autograd.

A reduced Newton iteration needs ``dU^/dq^`` and ``d^2U^/dq^2`` at one point. Two ways:

- ``numpy``: the exported :class:`femrom.inference.LearnedPotential` (analytic gradient and
  Hessian of the monomials and the network, :mod:`femrom.inference._networks`);
- ``torch``: the training module's scalar ``U^`` differentiated by autograd at the point
  (``torch.func.grad`` and ``torch.func.hessian``, one thread), what stepping with torch in
  the inner loop would cost.

Both for the default settings (monomials of degree 3 and 4, MLP 32 x 32) at r = 4, 8, 12,
random weights (the cost does not depend on their values). Reported: the fastest of
``--repeats`` blocks of ``--calls`` calls, microseconds per call, and the ratio torch / numpy,
measured in the same process one after the other.

Run ``python -m benchmarks.spml_step``; writes ``benchmarks/results/spml_step.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
import torch

from femrom.inference import LearnedPotential, SpMLConfig, spml_module

ROOT = Path(__file__).resolve().parents[1]


def best(function, calls: int, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        tic = time.perf_counter()
        for _ in range(calls):
            function()
        times.append((time.perf_counter() - tic) / calls)
    return min(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[4, 8, 12])
    parser.add_argument("--calls", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "spml_step.json")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    rows = []
    for r in args.sizes:
        config = SpMLConfig()
        module = spml_module(r, config, seed=0)
        with torch.no_grad():
            for p in module.parameters():
                p.add_(0.1 * torch.randn(p.shape, dtype=p.dtype, generator=torch.Generator().manual_seed(1)))
        _, _, polynomial, network, _, _ = module.export()
        term = LearnedPotential(r, polynomial, network)
        x = np.random.default_rng(0).standard_normal(r)
        xt = torch.tensor(x)[None, :]

        def numpy_call():
            term._at.x = None                   # no cache: a new point every call
            term.force(x)
            term.tangent(x)

        def scalar(z):
            return module.potential(z[None, :])[0]

        gradient, hessian = torch.func.grad(scalar), torch.func.hessian(scalar)

        def torch_call():
            gradient(xt[0])
            hessian(xt[0])

        n, t = best(numpy_call, args.calls, args.repeats), best(torch_call, max(args.calls // 10, 5), args.repeats)
        rows.append({"r": r, "numpy_us": n * 1e6, "torch_us": t * 1e6, "torch_over_numpy": t / n})
        print(f"r = {r:2d}: numpy {n * 1e6:8.1f} us, torch autograd {t * 1e6:8.1f} us, ratio {t / n:6.1f}", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                                                "load_average": os.getloadavg()}, "rows": rows}, indent=1))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
