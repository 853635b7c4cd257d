"""The full contact law in the jointed beam's dynamics: the discrete energy balance, old against new.

The model is the jointed-beam case's 10-mode Galerkin model (default mesh, 24,522 dofs, 592
interface pairs; :meth:`femrom.study.JointedBeamModel.reduced`), but with the full ``dry_friction``
law of the preload (unilateral penalty contact, elastic Coulomb sliders, the calibrated ``k_t``)
instead of the case's frozen-contact ``clamped_iwan``, about the preloaded rest state; modal
damping 0.14 %, ``dt = 1 / (128 f_1)``. Each run starts from that rest state and records the
discrete energy balance of every step (:class:`femrom.integrators.EnergyBalance`: input work
minus the changes of kinetic, modal strain and joint stored energy, minus Rayleigh and friction
dissipation; negative = energy created by the step). The energy scale is the run's largest
kinetic energy. Runs:

- ``ring300``, ``ring1500``: the hammer (0.3 ms half-sine, 300 and 1500 N peak), ``--duration`` s;
- ``forced``: the shaker, ``--force`` N at ``--frequency`` Hz from rest, ``--forced-duration`` s;

each with the old treatment (Newmark average acceleration: the trapezoidal mean of the law's
end-of-step tractions), for the 300 N blow also Newmark at ``dt / 4`` (substepping), and the
new one (:class:`femrom.integrators.DiscreteGradient` with the law's energy-consistent step
traction, :meth:`femrom.fem.DryFrictionLaw.step_traction`). With ``--hyper`` the case's ECSW
hyper-reduction is trained on the new scheme's all-pair ring-downs and the 300 N ring-down is
repeated on it, old against new.

Reported per run: steps done (a run that blows up stops at a non-finite state or a failed
Newton step), the worst step's balance over the energy scale, the largest ``|acc1|`` in the
first and in the last 10 ms, the friction dissipation and the numerical dissipation (the
positive part of the balance) over the input, Newton iterations and seconds per step (one run
each: indicative only, not a timing benchmark).

Run ``python -m benchmarks.contact_energy`` from the checkout's root (about 4 minutes, of which
1 minute builds and calibrates the beam); it prints a table and writes
``benchmarks/results/contact_energy.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from femrom.cases.jointed_beam import SCENE
from femrom.integrators import DiscreteGradient, EnergyBalance, IntegrationError, Newmark, StepResult, integrate
from femrom.scene import Signal, SignalVector
from femrom.study import JointedBeamModel, with_impulse

RESULTS = Path(__file__).resolve().parent / "results" / "contact_energy.json"
DAMPING = 0.0014        #: the measured linear damping at the lowest amplitude (docs/cases/jointed_beam.md)
WINDOW = 0.01           #: [s] the windows of the first and last acceleration peaks


def with_shaker(system, amplitude: float, frequency: float):
    """``system`` with the hammer silent and the shaker a sine of ``amplitude`` [N] at ``frequency`` [Hz]."""
    hammer = Signal.from_dict({"kind": "impulse", "amplitude": 0.0, "start": 0.0, "duration": 3e-4})
    shaker = Signal.from_dict({"kind": "sine", "amplitude": float(amplitude), "frequency": float(frequency)})
    return dataclasses.replace(system, inputs=SignalVector([hammer, shaker]))


def balance_run(system, rest_state, scheme, dt: float, duration: float) -> dict:
    """One run from rest: the per-step energy balance and the first output's acceleration."""
    n_steps = int(round(duration / dt))
    balance = EnergyBalance(system, scheme)
    acc = []

    def output(result):
        acc.append(float((system.output_matrix @ result.a)[0]) if result.a is not None else np.nan)

    rest = StepResult.at_rest(system.n_dofs, state=rest_state)
    balance(rest)                       # step 0: the run's consumers see the steps after the start
    tic = time.perf_counter()
    failure, iterations = None, None
    try:
        summary = integrate(system, scheme, None, None, dt, n_steps, consumers=[balance, output],
                            start=rest, progress=False)
        iterations = summary.newton_iterations
    except IntegrationError as err:
        failure = str(err).split(";")[0]
    seconds = time.perf_counter() - tic
    steps = len(balance) - 1
    residual = balance.residual
    kinetic = balance.kinetic
    scale = float(kinetic.max())
    work = balance.external_work
    signed = np.asarray(acc)
    acc = np.abs(signed)
    per_window = max(int(round(WINDOW / dt)), 1)
    finite = residual[np.isfinite(residual)]
    return {
        "scheme": scheme.label, "dt": dt, "steps": steps, "steps_asked": n_steps, "failure": failure,
        "energy_scale_J": scale,
        "worst_balance_over_scale": float(finite.min() / scale) if finite.size else None,
        "largest_balance_over_scale": float(finite.max() / scale) if finite.size else None,
        "steps_creating_energy_1e-9": int(np.sum(finite < -1e-9 * scale)),
        "acc1_first_10ms": float(np.nanmax(acc[:per_window])) if acc.size else None,
        "acc1_last_10ms": float(np.nanmax(acc[-per_window:])) if acc.size else None,
        "input_work_J": float(np.nanmax(np.abs(work))) if work.size else None,
        "friction_over_input": float(balance.friction[-1] / np.nanmax(np.abs(work))) if steps > 0 else None,
        "numerical_dissipation_over_input": float(np.sum(np.clip(finite, 0, None)) / np.nanmax(np.abs(work)))
        if steps > 0 else None,
        "newton_iterations": iterations, "seconds": seconds, "ms_per_step": 1e3 * seconds / max(steps, 1),
        "acc1": signed,
    }


def acc1_error(run: dict, reference: dict) -> float | None:
    """Largest ``|acc1 - acc1_ref|`` over the largest ``|acc1_ref|``, at the coarser run's steps (the runs'
    steps divide each other), over the steps both completed."""
    a, b = run["acc1"], reference["acc1"]
    every_a = max(int(round(reference["dt"] / run["dt"])), 1)
    every_b = max(int(round(run["dt"] / reference["dt"])), 1)
    a, b = a[every_a - 1::every_a], b[every_b - 1::every_b]
    n = min(a.size, b.size)
    if n == 0:
        return None
    return float(np.max(np.abs(a[:n] - b[:n])) / np.max(np.abs(b[:n])))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=0.1, help="ring-down length [s]")
    parser.add_argument("--forced-duration", type=float, default=0.2, help="forced run length [s]")
    parser.add_argument("--force", type=float, default=3.0, help="shaker amplitude [N]")
    parser.add_argument("--frequency", type=float, default=80.0, help="shaker frequency [Hz]")
    parser.add_argument("--hyper", action="store_true", help="also the ECSW hyper-reduced model")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)

    started = time.strftime("%Y-%m-%d %H:%M:%S %Z")
    load_start = os.getloadavg()
    model = JointedBeamModel()
    tic = time.perf_counter()
    setup = model.calibrated(model.scene(SCENE))
    preload = setup.beam.preload
    reduced = model.reduced(setup, setup.system, preload.displacement, preload.state, DAMPING)
    z0 = preload.state
    dt = model.dt(setup)
    build_seconds = time.perf_counter() - tic
    print(f"built and calibrated in {build_seconds:.0f} s: {setup.system.n_dofs} dofs, law "
          f"{setup.system.nonlinear.law.name}, {model.n_modes} modes, dt = {dt:.3e} s")

    old, new = Newmark(), DiscreteGradient()
    runs = {}
    for peak in (300.0, 1500.0):
        system = with_impulse(reduced, peak, model.impact_width)
        cases = [("newmark", old, dt), ("discrete_gradient", new, dt)]
        if peak == 300.0:
            cases += [("newmark_dt/4", old, dt / 4), ("discrete_gradient_dt/4", new, dt / 4)]
        for name, scheme, step in cases:
            key = f"ring{peak:g}_{name}"
            runs[key] = balance_run(system, z0, scheme, step, args.duration)
            print(key, json.dumps({k: runs[key][k] for k in ("steps", "failure", "worst_balance_over_scale",
                                                              "acc1_first_10ms", "acc1_last_10ms")}))
    reference = runs["ring300_discrete_gradient_dt/4"]
    for key in ("ring300_newmark", "ring300_discrete_gradient", "ring300_newmark_dt/4"):
        runs[key]["acc1_error_vs_dg_dt/4"] = acc1_error(runs[key], reference)
    forced = with_shaker(reduced, args.force, args.frequency)
    for name, scheme in (("newmark", old), ("discrete_gradient", new)):
        key = f"forced_{name}"
        runs[key] = balance_run(forced, z0, scheme, dt, args.forced_duration)
        print(key, json.dumps({k: runs[key][k] for k in ("steps", "failure", "worst_balance_over_scale",
                                                          "acc1_first_10ms", "acc1_last_10ms")}))
    hyper_info = None
    if args.hyper:
        tic = time.perf_counter()
        _, sampling, hyper, z_hyper = model.hyper_reduced(reduced, z0, dt, scheme=new, progress=print)
        hyper_info = {"pairs": int(np.size(sampling.pairs)), "seconds": time.perf_counter() - tic,
                      "trained_with": new.label, "tolerance": model.ecsw_tolerance}
        system = with_impulse(hyper, 300.0, model.impact_width)
        for name, scheme in (("newmark", old), ("discrete_gradient", new)):
            key = f"hyper_ring300_{name}"
            runs[key] = balance_run(system, z_hyper, scheme, dt, args.duration)
            print(key, json.dumps({k: runs[key][k] for k in ("steps", "failure", "worst_balance_over_scale",
                                                              "acc1_first_10ms", "acc1_last_10ms")}))

    header = (f"{'run':34s} {'steps':>11s} {'worst/scale':>12s} {'<-1e-9':>7s} {'acc1 0-10ms':>12s} "
              f"{'acc1 last':>11s} {'friction/in':>11s} {'numdiss/in':>10s} {'ms/step':>8s}")
    lines = [header, "-" * len(header)]
    for key, r in runs.items():
        worst = "n/a" if r["worst_balance_over_scale"] is None else f"{r['worst_balance_over_scale']:.2e}"
        fr = r["friction_over_input"]
        nd = r["numerical_dissipation_over_input"]
        lines.append(f"{key:34s} {r['steps']:>5d}/{r['steps_asked']:<5d} {worst:>12s} "
                     f"{r['steps_creating_energy_1e-9']:>7d} {r['acc1_first_10ms']:>12.4g} {r['acc1_last_10ms']:>11.4g} "
                     f"{(fr if fr is not None else np.nan):>11.3g} {(nd if nd is not None else np.nan):>10.3g} "
                     f"{r['ms_per_step']:>8.2f}")
    lines.append("acc1 over the 300 N ring-down against discrete_gradient at dt/4 (largest difference / largest "
                 "value): " + ", ".join(f"{key[8:]} {runs[key]['acc1_error_vs_dg_dt/4']:.3g}"
                                       for key in ("ring300_newmark", "ring300_newmark_dt/4",
                                                   "ring300_discrete_gradient")))
    table = "\n".join(lines)
    for r in runs.values():
        r.pop("acc1")
    print(table)
    result = {
        "benchmark": "contact_energy", "started": started, "loadavg_start": load_start,
        "loadavg_end": os.getloadavg(), "machine": platform.platform(), "python": platform.python_version(),
        "model": {"n_dofs": setup.system.n_dofs, "pairs": setup.system.nonlinear.n_pairs, "n_modes": model.n_modes,
                  "law": setup.system.nonlinear.law.parameters(), "dt": dt, "damping_ratio": DAMPING,
                  "build_seconds": build_seconds},
        "settings": vars(args) | {"out": str(args.out)},
        "energy_scale": "largest kinetic energy of the run",
        "runs": runs, "hyper": hyper_info, "table": table,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
