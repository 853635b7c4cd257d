r"""Which extra dissipation could close the measured-range joint's damping gap at 50-80 m/s^2?

The default measured-range model (:class:`femrom.study.MeasuredRangeJoint` on the 10-mode model of the
jointed-beam case, every pair, shaker mass attached) reproduces the response-controlled frequencies but
its damping levels off at about 0.37 % where the measurement reaches 0.66 % at 80 m/s^2
(docs/cases/jointed_beam.md). This probe takes the model's own EPMC periodic motions (H = 1, mode 1,
``--points`` amplitudes over 1-95 m/s^2 at acc3) and evaluates, per cycle, the work of candidate
mechanisms that the model leaves out, each for a unit coefficient, as an added damping ratio
``zeta = W / (2 pi omega^2 a^2)`` (``a``: the motion's modal amplitude in the mass norm, so that EPMC's
own ``xi`` gives ``zeta = xi / (2 omega)`` the same way). First-order: the mechanisms' forces are not fed
back into the motion, which is right while the added damping is small beside the stiffness.

Candidates, on the interface pairs open at the preload (the ones that re-close in bending):

- ``dashpot``: a normal dashpot while a point is in contact, traction ``c_n d(pen)/dt``, per unit
  ``c_n`` [Pa s/m];
- ``hunt_crossley``: Hunt and Crossley's penetration-weighted dashpot, traction ``lambda pen d(pen)/dt``
  (the law's ``closing_damping``), per unit ``lambda`` [Pa s/m^2];
- ``loss_factor``: a hysteretic (loss-factor) normal contact on the re-closing penalty
  ``kappa k_n``, ``W = pi eta sum_i A_i kappa k_n |pen_i1|^2`` (``pen_i1``: the first harmonic of the
  penetration), per unit ``eta``;
- ``squeeze_g0``: an air squeeze film between the open faces, traction ``c g_n' / (max(g_n, 0) + g0)^3``
  with a roughness floor ``g0``, per unit ``c`` [Pa s m^2] (for a strip of width ``b`` in air
  ``c ~ mu_air b^2 / 12``).

For each candidate the best single coefficient (least squares on the logs of the damping ratios over the
eight measured levels, as the fit's misfit weighs them) and the damping errors it leaves. Also the
re-closing points' tangential amplitude over their peak penetration (what their Coulomb friction can
dissipate depends on it).

Run ``python -m benchmarks.range_dissipation_probe`` from the checkout's root with the jointed beam's
data (``FEMROM_BRB_DATA``); about 2 minutes plus the beam's setup. Writes
``benchmarks/results/range_dissipation_probe.json`` and prints a table.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

RESULTS = Path(__file__).resolve().parent / "results" / "range_dissipation_probe.json"
SAMPLES = 256                      # time samples per period for the work integrals
ROUGHNESS = (0.1e-6, 0.2e-6, 0.5e-6)


def periodic_local(force, Z, samples=SAMPLES):
    """(samples, pairs, 3) local gaps over one period of the H = 1 motion with coefficients ``Z`` (3, n)."""
    theta = 2 * np.pi * np.arange(samples) / samples
    z = Z[0][None] + np.cos(theta)[:, None] * Z[1][None] + np.sin(theta)[:, None] * Z[2][None]
    local, joint = force.transformed, force.transformed.force_model
    return np.stack([joint.gaps(local._shifted(local.localize(zi))) for zi in z]), theta


def unit_dampings(force, joint_law, kappa, areas, reclosing, Z, omega, a):
    """Added damping ratios per unit coefficient of each candidate at one periodic motion, and the
    re-closing points' tangential amplitude over penetration."""
    gaps, theta = periodic_local(force, Z)
    period = 2 * np.pi / omega
    scale = 2 * np.pi * omega**2 * a**2
    g = gaps[:, reclosing, 2]
    A = areas[reclosing]
    pen = np.maximum(-g, 0.0)
    rate = np.gradient(pen, theta, axis=0) * omega
    out = {"dashpot": float(np.sum(A[None] * rate**2) * period / SAMPLES / scale),
           "hunt_crossley": float(np.sum(A[None] * pen * rate**2) * period / SAMPLES / scale)}
    first = 2.0 / SAMPLES * np.abs(np.fft.rfft(pen, axis=0)[1])
    out["loss_factor"] = float(np.pi * np.sum(A * kappa * joint_law["normal_stiffness"] * first**2) / scale)
    g_rate = np.gradient(g, theta, axis=0) * omega
    for g0 in ROUGHNESS:
        w = np.sum(A[None] * g_rate**2 / (np.maximum(g, 0.0) + g0) ** 3) * period / SAMPLES
        out[f"squeeze_{1e6 * g0:g}um"] = float(w / scale)
    touching = pen.max(axis=0) > 0
    tangential = np.linalg.norm(gaps[:, reclosing, :2].max(axis=0) - gaps[:, reclosing, :2].min(axis=0), axis=1) / 2
    out["pairs_touching"] = int(touching.sum())
    out["tangential_over_penetration"] = (float(np.sum(tangential[touching] * pen.max(axis=0)[touching])
                                          / np.sum(pen.max(axis=0)[touching] ** 2)) if touching.any() else None)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=24, help="EPMC amplitudes over 1-95 m/s^2 at acc3")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)

    from femrom.cases.jointed_beam import SCENE, JointedBeamCase
    from femrom.integrators import HarmonicBalance, epmc, linear_mode
    from femrom.post import phase_resonance_backbone, read_response_controlled
    from femrom.study import MeasuredRangeJoint

    tic = time.perf_counter()
    measured = phase_resonance_backbone(read_response_controlled(os.environ.get("FEMROM_BRB_DATA")))
    config = JointedBeamCase()
    setup = config.calibrated(config.scene(SCENE))
    joint = MeasuredRangeJoint()
    damping = 0.00138
    model, z0 = config.measured_range(setup, joint, damping)
    force = model.nonlinear_forces[0] if isinstance(model.nonlinear_forces, (list, tuple)) else model.nonlinear_forces
    law = force.transformed.force_model.law.parameters()
    areas = force.transformed.force_model.areas
    n_sliders = z0.shape[1] - 1
    reclosing = z0[:, n_sliders, 1] < 0.5                   # open at the preload
    setup_seconds = time.perf_counter() - tic

    hb = HarmonicBalance(model, None, harmonics=1, state=z0)
    omega0, phi = linear_mode(hb, 0)
    per_modal = omega0**2 * abs(float(hb.output_matrix[2] @ phi))
    modes = epmc(model, np.geomspace(1.0, 95.0, args.points) / per_modal, mode=0, harmonics=1, state=z0)
    acc3 = modes.omega**2 * np.hypot(modes.outputs[:, 1, 2], modes.outputs[:, 2, 2])
    zeta_model = modes.xi / (2 * modes.omega)
    points = [unit_dampings(force, law, joint.closing, areas, reclosing, modes.coefficients[k], modes.omega[k],
                            modes.modal_amplitude[k]) for k in range(len(modes))]

    la, lm = np.log(acc3), np.log(measured.amplitude)
    at = lambda values: np.interp(lm, la, np.asarray(values, dtype=float))  # noqa: E731
    base = at(zeta_model)
    candidates = {}
    for name in [k for k in points[0] if k not in ("pairs_touching", "tangential_over_penetration")]:
        unit = at([p[name] for p in points])

        def misfit(log_c, unit=unit):
            return float(np.sum(np.log((base + np.exp(log_c) * unit) / measured.damping_ratio) ** 2))
        centre = np.log(max(np.max(measured.damping_ratio - base), 1e-12) / max(unit[-1], 1e-300))
        best = minimize_scalar(misfit, bounds=(centre - 12.0, centre + 4.0), method="bounded")
        c = float(np.exp(best.x))
        candidates[name] = {"coefficient": c, "unit_damping_at_levels": unit.tolist(),
                            "damping_error_at_levels": ((base + c * unit) / measured.damping_ratio - 1).tolist()}

    result = {
        "benchmark": "range_dissipation_probe", "machine": platform.platform(), "python": platform.python_version(),
        "joint": joint.parameters(), "linear_damping_ratio": damping,
        "levels_m_s2": measured.amplitude.tolist(), "measured_damping": measured.damping_ratio.tolist(),
        "model_damping_at_levels": base.tolist(),
        "model_damping_error": (base / measured.damping_ratio - 1).tolist(),
        "epmc_acc3_m_s2": acc3.tolist(), "epmc_frequency_hz": modes.frequency_hz.tolist(),
        "epmc_damping": zeta_model.tolist(), "points": points, "candidates": candidates,
        "pairs": int(areas.size), "open_at_preload": int(reclosing.sum()),
        "seconds": {"setup": setup_seconds, "total": time.perf_counter() - tic},
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    print("levels [m/s^2]        ", " ".join(f"{a:7.1f}" for a in measured.amplitude))
    print("measured damping [%]  ", " ".join(f"{100 * z:7.3f}" for z in measured.damping_ratio))
    print("model error           ", " ".join(f"{100 * e:+6.0f}%" for e in result["model_damping_error"]))
    for name, c in candidates.items():
        print(f"+ {name:18s}   ", " ".join(f"{100 * e:+6.0f}%" for e in c["damping_error_at_levels"]),
              f"  coefficient {c['coefficient']:.3g}")
    print("tangential / penetration at the re-closing points:",
          [None if p["tangential_over_penetration"] is None else round(p["tangential_over_penetration"], 2)
           for p in points])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
