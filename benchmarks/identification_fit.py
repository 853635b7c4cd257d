"""Fit time of the identified first-order models (DMDc, ERA, OKID) at the soft robot's channel counts.

The data stand in for the SERPENT robot's training runs (6 pressure inputs, 40
centreline outputs, 10 s at dt = 0.01 s, K = 1000 samples per run): a lightly
damped modal system of 30 modes (0.3-20 Hz, 2 % damping, random 6-input and
40-output maps), sampled exactly (zero-order hold on the inputs), driven by
phased multi-sines between 0.1 and 1.5 Hz from rest; four training runs and one
unseen test run. For each model order r the script fits

- ``dmdc``: DMDc on the first r POD coefficients of the modal state (all ranks full);
- ``okid l=10``, ``okid l=20``: OKID with observer order l, ``at_rest`` (the Markov
  parameters from the inputs and outputs alone, then ERA with its default blocks,
  100 x 100 for runs of 1000 samples);
- ``era``: ERA of r on the 201 Markov parameters of the system's impulse
  response (100 x 100 blocks: a 4000 x 600 Hankel matrix), and ``era tangential``
  with the outputs reduced to 12 directions first (a 1200 x 600 Hankel matrix);

and, as the baseline measured in the same run, ``least squares``: one plain
``numpy.linalg.lstsq`` for ``[A B]`` on the same DMDc data (what DMDc is with full
ranks, without its SVDs). Each fit is repeated (``--repeats``, the median is
reported, and the ratio to the baseline's median at the same r). The output
error of each model on the unseen run (``||Y - Y^|| / ||Y||``) and its spectral
radius are reported too, so a time is never quoted for a model that does not work.

Run ``python -m benchmarks.identification_fit [--sizes 2 4 8 12 16 20]
[--repeats 3] [--out benchmarks/results]``; it prints a table and writes
``identification_fit.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
import scipy.linalg

from femrom.inference import DMDc, ERA, OKID, InputOutputData, StateSpaceOperators, markov_parameters
from femrom.rom import StateSpaceROM

SIZES = (2, 4, 8, 12, 16, 20)
DT, SAMPLES, RUNS, INPUTS, OUTPUTS, MODES = 0.01, 1000, 4, 6, 40, 30


def modal_system(seed: int = 0) -> StateSpaceOperators:
    """The sampled modal system: z = [eta; eta'] (2 MODES), zero-order hold at DT, D = 0."""
    rng = np.random.default_rng(seed)
    omega = 2 * np.pi * np.geomspace(0.3, 20.0, MODES)
    zeta = 0.02
    Ac = np.block([[np.zeros((MODES, MODES)), np.eye(MODES)],
                   [-np.diag(omega**2), -np.diag(2 * zeta * omega)]])
    Bc = np.vstack([np.zeros((MODES, INPUTS)), rng.standard_normal((MODES, INPUTS))])
    C = np.hstack([rng.standard_normal((OUTPUTS, MODES)) / omega**2 * omega[0] ** 2, np.zeros((OUTPUTS, MODES))])
    n = 2 * MODES
    augmented = scipy.linalg.expm(np.block([[Ac, Bc], [np.zeros((INPUTS, n + INPUTS))]]) * DT)
    return StateSpaceOperators(A=augmented[:n, :n], B=augmented[:n, n:], C=C, D=np.zeros((OUTPUTS, INPUTS)),
                               dt=DT, metadata={"source": "modal system, zero-order hold"})


def multisine(rng, samples: int) -> np.ndarray:
    """(INPUTS, samples): each input a sum of three sines in 0.1-1.5 Hz, phased across the inputs."""
    t = DT * np.arange(samples)
    frequencies = rng.uniform(0.1, 1.5, 3)
    U = np.zeros((INPUTS, samples))
    for j in range(INPUTS):
        for f in frequencies:
            U[j] += np.sin(2 * np.pi * f * t + 2 * np.pi * j / INPUTS + rng.uniform(0, 2 * np.pi)) \
                - np.sin(2 * np.pi * j / INPUTS)      # zero at t = 0: the runs start from rest
    return U


def run(system: StateSpaceOperators, U: np.ndarray):
    """(Y, Z) from rest."""
    Z = np.zeros((system.n_states, U.shape[1]))
    for k in range(U.shape[1] - 1):
        Z[:, k + 1] = system.A @ Z[:, k] + system.B @ U[:, k]
    return system.C @ Z, Z


def timed(fit, repeats: int):
    """(median seconds, last result) of ``repeats`` calls."""
    seconds, result = [], None
    for _ in range(repeats):
        tic = time.perf_counter()
        result = fit()
        seconds.append(time.perf_counter() - tic)
    return float(np.median(seconds)), seconds, result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    args = parser.parse_args()

    system = modal_system()
    inputs = [multisine(np.random.default_rng(10 + i), SAMPLES) for i in range(RUNS)]
    runs = [(U, *run(system, U)) for U in inputs]
    U_test = multisine(np.random.default_rng(99), SAMPLES)
    Y_test, Z_test = run(system, U_test)
    U = np.hstack([r[0] for r in runs])
    Y = np.hstack([r[1] for r in runs])
    Z = np.hstack([r[2] for r in runs])
    starts = tuple(i * SAMPLES for i in range(RUNS))
    pod = np.linalg.svd(Z, full_matrices=False)[0]
    markov = markov_parameters(system, 201)
    times = DT * np.arange(SAMPLES)

    def output_error(rom, x0=None):
        prediction = rom.predict(times, U_test, initial=None if x0 is None else rom.initial_state(x0=x0, u0=U_test[:, 0]))
        return float(np.linalg.norm(prediction.outputs - Y_test) / np.linalg.norm(Y_test))

    rows = []
    for r in args.sizes:
        V = pod[:, :r]
        data = InputOutputData(U, Y, DT, states=V.T @ Z, starts=starts)
        pairs = data.step_pairs()
        omega = np.vstack([data.states[:, pairs], U[:, pairs]])

        def least_squares():
            return np.linalg.lstsq(omega.T, data.states[:, pairs + 1].T, rcond=None)[0]

        base, base_all, _ = timed(least_squares, args.repeats)
        rows.append({"r": r, "method": "least squares", "seconds": base, "repeats": base_all, "ratio": 1.0,
                     "output_error": None, "spectral_radius": None, "shape": list(omega.T.shape),
                     "hankel_shape": None})
        methods = {
            "dmdc": (lambda: DMDc().fit(data), lambda learner: V.T @ Z_test[:, 0]),
            "okid l=10": (lambda: OKID(r, 10, at_rest=True).fit(data), None),
            "okid l=20": (lambda: OKID(r, 20, at_rest=True).fit(data), None),
            "era": (lambda: ERA(r).fit(markov), None),
            "era tangential": (lambda: ERA(r, output_directions=12).fit(markov), None),
        }
        for name, (fit, initial) in methods.items():
            median, all_seconds, learner = timed(fit, args.repeats)
            rom = StateSpaceROM(learner.operators_)
            error = output_error(rom, None if initial is None else initial(learner))
            meta = learner.operators_.metadata
            shape = meta.get("regression_shape") or meta.get("hankel_shape") or [len(pairs), r + INPUTS]
            hankel = meta.get("hankel_shape")
            rows.append({"r": r, "method": name, "seconds": median, "repeats": all_seconds,
                         "ratio": median / base, "output_error": error,
                         "spectral_radius": learner.operators_.spectral_radius, "shape": shape,
                         "hankel_shape": hankel})
            print(f"r = {r:2d}  {name:15s} {median * 1e3:9.1f} ms  x{median / base:7.1f}  "
                  f"error {error:8.2e}  rho {learner.operators_.spectral_radius:.4f}", flush=True)

    header = ("| r | method | fit (ms, median) | / least squares | least squares or Hankel shape | Hankel "
              "| output error (unseen) | spectral radius |")
    lines = [header, "|---|---|---|---|---|---|---|---|"]
    for row in rows:
        error = "" if row["output_error"] is None else f"{row['output_error']:.2e}"
        rho = "" if row["spectral_radius"] is None else f"{row['spectral_radius']:.4f}"
        lines.append(f"| {row['r']} | {row['method']} | {row['seconds'] * 1e3:.1f} | {row['ratio']:.1f} | "
                     f"{' x '.join(str(s) for s in row['shape'])} | "
                     f"{'' if row['hankel_shape'] is None else ' x '.join(str(s) for s in row['hankel_shape'])} | "
                     f"{error} | {rho} |")
    table = "\n".join(lines)
    print(table)
    args.out.mkdir(parents=True, exist_ok=True)
    result = {"benchmark": "identification_fit", "timestamp": time.strftime("%Y-%m-%dT%H:%M:%S"),
              "machine": {"platform": platform.platform(), "processor": platform.processor(),
                          "cpus": os.cpu_count(),
                          "threads": {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                                                     "MKL_NUM_THREADS")}},
              "setup": {"dt": DT, "samples_per_run": SAMPLES, "runs": RUNS, "inputs": INPUTS, "outputs": OUTPUTS,
                        "modes": MODES, "markov_parameters": markov.count, "repeats": args.repeats},
              "rows": rows, "table": table}
    (args.out / "identification_fit.json").write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
