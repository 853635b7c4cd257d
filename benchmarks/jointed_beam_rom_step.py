"""What a step of the jointed-beam ROMs costs against the full model's: the issue's 1e3x target.

The models are those of ``femrom/cases/jointed_beam_rom.py`` (its defaults): the full model (24,522 dofs,
the ``clamped_iwan`` joint on all 592 pairs, Newmark with condensed Newton), the 10-mode reference
with the ECSW-sampled joint, and ROMs fitted on the case's training runs (the 150 and 600 N blows and
the 5 N shaker run): Iwan-L-OpInf at r = 1 and 3, SpML and L-OpInf at r = 3. In one process, blocks
alternate ``--repeats`` times, each stepping a 300 N blow from rest: ``--full-steps`` steps of the
full model (the factorisation and its first step excluded), ``--steps`` of every other model. The
ROMs are stepped once before the blocks (their compiled kernels compiled or loaded from numba's cache,
which the first call's stepping time would include). The
table gives the median over the repeats of each block's mean seconds per step and the ratio of the
full model's median to it; for the learned ROMs also the scheme and the Newton iterations (and, on
the discrete-gradient march, the Jacobians) a step.

Run ``python -m benchmarks.jointed_beam_rom_step`` (about 8 minutes); it prints a table and
writes ``benchmarks/results/jointed_beam_rom_step.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from femrom.cases import jointed_beam_rom as rom_case
from femrom.inference import IwanLOpInf, LagrangianOpInf, SpML, SpMLConfig
from femrom.integrators import Newmark, Newton, StepResult, integrate
from femrom.rom import SecondOrderROM
from femrom.study import mass_pod, ring_down_data, step_cost, with_impulse

RESULTS = Path(__file__).resolve().parent / "results" / "jointed_beam_rom_step.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--full-steps", type=int, default=12)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    config = rom_case.JointedBeamRomCase(test_blows=())
    say = lambda line: print(line, file=sys.stderr, flush=True)   # noqa: E731
    models = rom_case.reference_models(config, say)
    training, validation, _ = rom_case.reference_runs(models, config, say)
    hyper, z_hyper, dt, case = models["hyper"], models["z_hyper"], models["dt"], models["case"]
    M = hyper.mass
    V, _ = mass_pod(M, training, 3)
    blow = with_impulse(hyper, 300.0, case.impact_width)
    times = dt * np.arange(args.steps + 1)

    say("fitting the ROMs ...")
    learners = {"iwan r=1": (IwanLOpInf(["damping", "input"]), 1), "iwan r=3": (IwanLOpInf(["damping", "input"]), 3),
                "spml r=3": (SpML(["damping", "input"], config=SpMLConfig(seed=0), progress=False), 3),
                "lopinf r=3": (LagrangianOpInf(["damping", "input"]), 3)}
    roms = {}
    for name, (learner, r) in learners.items():
        data = ring_down_data(V[:, :r], M, training)
        options = {} if name.startswith("lopinf") else {"validation": ring_down_data(V[:, :r], M, validation)}
        roms[name] = SecondOrderROM(basis=V[:, :r], learner=learner).fit(data, **options)

    counts = {}

    def learned(name):
        rom = roms[name]
        ops = rom.operators_
        scheme = "newmark" if ops.stateful or ops.is_linear else "discrete_gradient"
        solution = rom.predict(times, blow.inputs, scheme=scheme)
        info = solution.info
        counts[name] = {"scheme": scheme, **{key: float(np.sum(info[key])) / args.steps
                                             for key in ("newton_iterations", "newton_jacobians") if key in info}}
        return info["stepping_seconds"] / args.steps

    def reference():
        n = hyper.n_dofs
        rest = StepResult.at_rest(n, state=z_hyper)
        tic = time.perf_counter()
        integrate(blow, Newmark(), None, None, dt, args.steps, start=rest, progress=False)
        return (time.perf_counter() - tic) / args.steps

    def full():
        cost = step_cost(with_impulse(models["model"], 300.0, case.impact_width), models["q0"], models["z0"], dt,
                         args.full_steps + 1, scheme=Newmark(newton=Newton(method="condensed")))
        return cost["seconds_per_step"]

    blocks = {"full model": full, "reference (10 modes, sampled joint)": reference,
              **{name: (lambda name=name: learned(name)) for name in roms}}
    for name in roms:                   # compile or load the compiled kernels before timing (not a block)
        learned(name)
    samples = {name: [] for name in blocks}
    for repeat in range(args.repeats):
        for name, block in blocks.items():
            samples[name].append(block())
        say(f"repeat {repeat + 1}/{args.repeats}: " + ", ".join(f"{k} {1e3 * v[-1]:.3g} ms" for k, v in samples.items()))
    medians = {name: statistics.median(values) for name, values in samples.items()}
    rows = [{"model": name, "seconds_per_step_median": medians[name], "seconds_per_step": samples[name],
             "cheaper_than_full_model": medians["full model"] / medians[name],
             **({"per_step": counts[name]} if name in counts else {})} for name in blocks]
    print(f"{'model':38s} {'ms/step (median)':>17s} {'x cheaper than the full model':>30s}")
    for row in rows:
        print(f"{row['model']:38s} {1e3 * row['seconds_per_step_median']:17.4g} {row['cheaper_than_full_model']:30.4g}"
              f"  {row.get('per_step', '')}")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({
        "benchmark": "jointed_beam_rom_step", "machine": platform.platform(), "python": platform.python_version(),
        "steps": args.steps, "full_steps": args.full_steps, "repeats": args.repeats, "dt": dt,
        "n_dofs_full": models["model"].n_dofs, "sampled_pairs": int(models["sampling"].pairs.size),
        "rows": rows}, indent=2))
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
