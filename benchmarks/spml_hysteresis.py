"""SpML with learned sliders (its ``"hysteresis"`` term) against plain SpML and IwanLOpInf.

Two parts:

- ``oscillator``: one coordinate, ``q'' + c q' + k q + k_3 q^3 + k_s e(q) = u`` with one Jenkins slider
  on the learner's threshold grid and a cubic spring (the system of ``tests/test_spml_hysteresis.py``;
  exact data: the Newmark steps of the truth, two half-sine blows to train on, one to validate, an
  unseen one to predict). Plain ``SpML(["damping", "input"])`` and ``SpML(["damping", "input",
  "hysteresis"])`` are fitted in alternating blocks (``--blocks``, one torch thread): the fit seconds
  (median and range over the blocks; the ratio of the two measured in the same block), the training
  loss, the learned nonlinear force against the truth's and the unseen blow's prediction error (Newmark).
- ``jointed_beam``: the jointed-beam ROM study's reference and runs (``femrom/cases/jointed_beam_rom.py``:
  ring-downs after 150 and 600 N blows and a shaker run, a 400 N validation blow, the 300 N test over
  ``--horizon`` times the 0.3 s training window); IwanLOpInf, SpML, SpML with sliders as the study
  runs it (``spml_hyst``: polynomial potential, no convex dissipation) and with SpML's other
  default terms and the convex dissipation (``spml_hyst_convex``) at each rank of ``--ranks``: frequency-shift and damping errors of the test's backbone, time-domain error, fit
  seconds (one fit each), stability.

Run ``python -m benchmarks.spml_hysteresis [--parts oscillator jointed_beam] [--ranks 1 2 3]``; it prints
the tables and writes ``benchmarks/results/spml_hysteresis.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from femrom.inference import (
    LearnedHysteresis,
    LearnedPotential,
    ReducedOperators,
    SecondOrderData,
    SpML,
    SpMLConfig,
    concatenate,
    term_class,
)
from femrom.inference._networks import SymmetricPolynomial
from femrom.rom import SecondOrderROM

ROOT = Path(__file__).resolve().parents[1]
PHI = 0.1 * np.geomspace(0.02, 1.0, 12)
K_SLIDERS = np.where(np.arange(12) == 9, 10.0, 0.0)
K, C, B, K3, DT, STEPS = 10.0, 0.05, 1.0, 40.0, 5e-3, 1500


def _spring() -> LearnedPotential:
    return LearnedPotential(1, SymmetricPolynomial(1, {4: (np.zeros((1, 4), dtype=int), np.array([K3 / 4]))}), None)


def _truth() -> ReducedOperators:
    return ReducedOperators((term_class("stiffness")(np.array([[K]])), term_class("damping")(np.array([[C]])),
                             term_class("input")(np.array([[B]])), _spring(), LearnedHysteresis([1.0], PHI, K_SLIDERS)))


def _blow(peak: float) -> SecondOrderData:
    t = np.arange(STEPS) * DT
    u = np.where(t < 0.05, peak * np.sin(np.pi * t / 0.05), 0.0)[None]
    s = SecondOrderROM(_truth(), np.eye(1)).predict(t, u, initial=np.zeros(1), scheme="newmark")
    return SecondOrderData(s.q, s.v, s.a, inputs=u, times=t)


def oscillator(blocks: int, iterations: int) -> dict:
    import torch

    torch.set_num_threads(1)
    train, validation, test = [_blow(4.0), _blow(12.0)], _blow(8.0), _blow(10.0)
    data = concatenate(train)
    true = _spring().forces(data.states) + LearnedHysteresis([1.0], PHI, K_SLIDERS).forces(data.states,
                                                                                            starts=data.starts)
    config = SpMLConfig(seed=0, max_iterations=iterations, hysteresis_thresholds=tuple(PHI))
    fits = {"plain": ["damping", "input"], "sliders": ["damping", "input", "hysteresis"]}
    seconds = {name: [] for name in fits}
    learners = {}
    for _ in range(blocks):                       # alternating: plain, sliders, plain, sliders, ...
        for name, terms in fits.items():
            tic = time.perf_counter()
            learners[name] = SpML(terms, config=config, progress=False).fit(train, validation=validation)
            seconds[name].append(time.perf_counter() - tic)
    rows = []
    t = np.arange(STEPS) * DT
    for name, learner in learners.items():
        learned = learner.nonlinear_forces(data.states, data.velocities, data.starts) \
            + (learner.linear_matrices_["stiffness"] - K) @ data.states
        s = SecondOrderROM(learner.operators_, np.eye(1)).predict(t, test.inputs, initial=np.zeros(1),
                                                                  scheme="newmark")
        h = learner.hysteresis_
        rows.append({"fit": name, "seconds_median": float(np.median(seconds[name])),
                     "seconds_range": [float(min(seconds[name])), float(max(seconds[name]))],
                     "seconds": seconds[name],
                     "loss": learner.loss_,
                     "force_error": float(np.linalg.norm(learned - true) / np.linalg.norm(true)),
                     "weights_error": None if h is None else
                     float(np.abs(h.weights - K_SLIDERS).max() / K_SLIDERS.max()),
                     "prediction_error": float(np.linalg.norm(s.q - test.states) / np.linalg.norm(test.states)),
                     "stages": learner.stages_})
    ratios = [b / a for a, b in zip(seconds["plain"], seconds["sliders"])]
    return {"blocks": blocks, "iterations": iterations, "rows": rows,
            "ratio_sliders_to_plain": {"median": float(np.median(ratios)), "range": [min(ratios), max(ratios)]}}


def jointed_beam(ranks: tuple, horizon: float, iterations: int, names=("iwan", "spml", "spml_hyst", "spml_hyst_convex")) -> dict:
    from femrom.cases import jointed_beam_rom as case
    from femrom.post import period_corrected
    from femrom.study import ModelSpec, RingDownComparison, compare_ring_downs

    config = dataclasses.replace(case.JointedBeamRomCase(), horizon_factor=horizon, full_model_steps=0,
                                 spml_iterations=iterations, ranks=tuple(ranks),
                                 models=tuple(n for n in names if n != "spml_hyst_convex"))
    tic = time.perf_counter()
    models = case.reference_models(config, progress=lambda line: print(line, file=sys.stderr, flush=True))
    training, validation, tests = case.reference_runs(models, config, progress=lambda line: None)
    reference_seconds = time.perf_counter() - tic
    convex = ModelSpec("spml", "spml_hyst_convex", {"terms": ("damping", "input", "hysteresis"), "config": SpMLConfig(
        max_iterations=iterations, seed=0, learn_dissipation=True)})
    settings = RingDownComparison(ranks=config.ranks, models=case.model_specs(config) + ((convex,) if "spml_hyst_convex" in names else ()), band=case.BAND,
                                  window=case.WINDOW, range_window=0.05, range_trim=0.05)
    dt = models["dt"]
    out = compare_ring_downs(models["hyper"], models["z_hyper"], training, validation, tests, settings,
                             correction=lambda b: period_corrected(b, dt),
                             progress=lambda line: print(line, file=sys.stderr, flush=True))
    rows = []
    for row in out["rows"]:
        rom = out["models"][(row["model"], row["r"])]
        learner = getattr(rom, "learner", None)
        rows.append({k: row.get(k) for k in ("model", "r", "test", "frequency_shift_error", "damping_max_error",
                                             "time_domain_error", "fit_seconds", "seconds_per_step", "stable")}
                    | {"stages": getattr(learner, "stages_", None),
                       "sliders": None if getattr(learner, "hysteresis_", None) is None
                       else learner.hysteresis_.describe()})
    return {"horizon_factor": horizon, "test_seconds": horizon * config.training_window,
            "spml_iterations": iterations, "reference_seconds": reference_seconds, "rows": rows}


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f} %"


def tables(results: dict) -> str:
    lines = []
    if "oscillator" in results:
        o = results["oscillator"]
        lines += [f"oscillator ({o['blocks']} alternating blocks, at most {o['iterations']} L-BFGS iterations):", "",
                  "| fit | fit s (median, range) | loss | force error | weights error | prediction error |",
                  "|---|---|---|---|---|---|"]
        for row in o["rows"]:
            lo, hi = row["seconds_range"]
            w = "-" if row["weights_error"] is None else f"{row['weights_error']:.1e}"
            lines.append(f"| {row['fit']} | {row['seconds_median']:.2f} ({lo:.2f}-{hi:.2f}) | {row['loss']:.1e} | "
                         f"{row['force_error']:.2e} | {w} | {row['prediction_error']:.1e} |")
        r = o["ratio_sliders_to_plain"]
        lines += ["", f"fit seconds, sliders / plain in the same block: median {r['median']:.2f} "
                      f"(range {r['range'][0]:.2f}-{r['range'][1]:.2f})", ""]
    if "jointed_beam" in results:
        j = results["jointed_beam"]
        lines += [f"jointed beam ({j['test_seconds']:.1f} s test, SpML at most {j['spml_iterations']} iterations):",
                  "", "| model | r | shift error | damping error | time error | fit s | stable |",
                  "|---|---|---|---|---|---|---|"]
        for row in j["rows"]:
            lines.append(f"| {row['model']} | {row['r']} | {_pct(row['frequency_shift_error'])} | "
                         f"{_pct(row['damping_max_error'])} | {row['time_domain_error']:.3f} | "
                         f"{row['fit_seconds']:.1f} | {row['stable']} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", nargs="+", default=["oscillator", "jointed_beam"],
                        choices=["oscillator", "jointed_beam"])
    parser.add_argument("--blocks", type=int, default=3)
    parser.add_argument("--oscillator-iterations", type=int, default=100)
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--horizon", type=float, default=10.0, help="test length / training window (the case's 10)")
    parser.add_argument("--iterations", type=int, default=2000, help="SpML's L-BFGS budget on the jointed beam")
    parser.add_argument("--models", nargs="+", default=["iwan", "spml", "spml_hyst", "spml_hyst_convex"],
                        choices=["iwan", "spml", "spml_hyst", "spml_hyst_convex"], help="jointed-beam rows")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "spml_hysteresis.json"))
    args = parser.parse_args(argv)
    results = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
               "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                           "load_average": list(os.getloadavg())}}
    if "oscillator" in args.parts:
        results["oscillator"] = oscillator(args.blocks, args.oscillator_iterations)
    if "jointed_beam" in args.parts:
        results["jointed_beam"] = jointed_beam(tuple(args.ranks), args.horizon, args.iterations,
                                               tuple(args.models))
    results["machine"]["load_average_end"] = list(os.getloadavg())
    text = tables(results)
    print(text)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2, default=float))
    out.with_suffix(".md").write_text(f"{results['date']}, load {results['machine']['load_average']}\n\n{text}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
