"""What harmonics and AFT samples buy: harmonic balance and EPMC of a Jenkins oscillator against H and N.

The model: ``x'' + 2 zeta w0 x' + w0^2 x + g(x) = F sin(Omega t)`` with ``w0 = 2 pi`` (1 Hz),
``zeta = 0.03``, a Jenkins element ``k_t = 0.5 w0^2`` in series with a slider of slip
displacement ``x_s = 0.1`` (:class:`femrom.fem.JenkinsForce`): a Masing law whose force has a
kink at every stick-slip switch, so that its harmonics decay slowly and the AFT aliases for
any N. Two quantities per (H, N):

- ``forced``: the fundamental amplitude of the periodic response at ``F = 1`` and 1.15 Hz (on
  the resonance of the softened oscillator, the slider slipping over most of the period);
- ``epmc``: EPMC's frequency and damping ratio at modal amplitude ``a = 0.3 = 3 x_s``;

each against a reference at ``H = 31, N = 4096``, with the solve time (Newton from the model
linearised at rest for the forced point; the mode from its linear start at ``a = 0.05`` through
``a = 0.3``), the median of ``--repeats`` interleaved runs, and as a ratio to the cheapest
configuration's median.

Run ``python -m benchmarks.harmonic_balance`` (about a minute); it prints a table and writes
``benchmarks/results/harmonic_balance.json``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from femrom.fem import JenkinsForce
from femrom.integrators import HarmonicBalance, epmc
from femrom.scene import SecondOrderSystem

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "harmonic_balance.json"
W0, ZETA, KT, SLIP = 2 * np.pi, 0.03, 0.5 * (2 * np.pi) ** 2, 0.1
FORCE, FREQUENCY_HZ, MODAL_AMPLITUDE = 1.0, 1.15, 0.3
GRID = [(1, 16), (1, 64), (1, 256), (3, 16), (3, 64), (3, 256), (5, 16), (5, 32), (5, 64), (5, 128), (5, 256),
        (5, 1024), (7, 32), (7, 64), (7, 256), (11, 32), (11, 64), (11, 256), (15, 64), (15, 256), (15, 1024)]
REFERENCE = (31, 4096)


def jenkins_oscillator() -> SecondOrderSystem:
    return SecondOrderSystem(mass=sp.csr_matrix([[1.0]]), stiffness=sp.csr_matrix([[W0 ** 2]]),
                             damping=sp.csr_matrix([[2 * ZETA * W0]]), input_matrix=np.ones((1, 1)),
                             output_matrix=sp.csr_matrix([[1.0]]), output_names=("x",),
                             nonlinear=JenkinsForce(KT, KT * SLIP, 1))


def forced(system, H, N):
    hb = HarmonicBalance(system, 0, harmonics=H, samples=N)
    tic = time.perf_counter()
    solution = hb.solve(2 * np.pi * FREQUENCY_HZ, FORCE)
    seconds = time.perf_counter() - tic
    return abs(hb.phasor(solution.coefficients)[0]), solution.iterations, seconds


def mode(system, H, N):
    tic = time.perf_counter()
    modes = epmc(system, np.geomspace(0.05, MODAL_AMPLITUDE, 6), harmonics=H, samples=N)
    seconds = time.perf_counter() - tic
    return modes.frequency_hz[-1], modes.damping_ratio[-1], int(modes.iterations.sum()), seconds


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    system = jenkins_oscillator()
    amplitude_ref, _, _ = forced(system, *REFERENCE)
    frequency_ref, damping_ref, _, _ = mode(system, *REFERENCE)
    times = {key: {"forced": [], "epmc": []} for key in GRID}
    values = {}
    for _ in range(args.repeats):          # interleaved: a load change on the machine hits every row
        for H, N in GRID:
            amplitude, its, t_forced = forced(system, H, N)
            frequency, damping, its_mode, t_mode = mode(system, H, N)
            times[(H, N)]["forced"].append(t_forced)
            times[(H, N)]["epmc"].append(t_mode)
            values[(H, N)] = (amplitude, its, frequency, damping, its_mode)
    base_forced = statistics.median(times[GRID[0]]["forced"])
    base_mode = statistics.median(times[GRID[0]]["epmc"])
    rows = []
    for H, N in GRID:
        amplitude, its, frequency, damping, its_mode = values[(H, N)]
        t_f, t_m = statistics.median(times[(H, N)]["forced"]), statistics.median(times[(H, N)]["epmc"])
        rows.append({"harmonics": H, "samples": N,
                     "amplitude_error": abs(amplitude / amplitude_ref - 1),
                     "frequency_error": abs(frequency / frequency_ref - 1),
                     "damping_error": abs(damping / damping_ref - 1),
                     "newton_iterations": its, "epmc_iterations": its_mode,
                     "forced_seconds": t_f, "epmc_seconds": t_m,
                     "forced_cost_ratio": t_f / base_forced, "epmc_cost_ratio": t_m / base_mode})
    header = ("| H | N | amplitude error | EPMC frequency error | EPMC damping error | Newton its | "
              "forced solve [ms] (ratio) | EPMC 6 points [ms] (ratio) |")
    print(header)
    print("|" + "---|" * 8)
    for r in rows:
        print(f"| {r['harmonics']} | {r['samples']} | {r['amplitude_error']:.1e} | {r['frequency_error']:.1e} | "
              f"{r['damping_error']:.1e} | {r['newton_iterations']} | {1e3 * r['forced_seconds']:.1f} "
              f"({r['forced_cost_ratio']:.1f}) | {1e3 * r['epmc_seconds']:.0f} ({r['epmc_cost_ratio']:.1f}) |")
    result = {"benchmark": "harmonic_balance", "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
              "model": {"w0": W0, "zeta": ZETA, "jenkins_stiffness": KT, "slip_displacement": SLIP,
                        "force": FORCE, "frequency_hz": FREQUENCY_HZ, "modal_amplitude": MODAL_AMPLITUDE},
              "reference": {"harmonics": REFERENCE[0], "samples": REFERENCE[1], "amplitude": amplitude_ref,
                            "frequency_hz": frequency_ref, "damping_ratio": damping_ref},
              "repeats": args.repeats, "rows": rows}
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=2) + "\n")
    print(f"reference: amplitude {amplitude_ref:.6g}, frequency {frequency_ref:.6g} Hz, damping {damping_ref:.6g}")
    return result


if __name__ == "__main__":
    main()
