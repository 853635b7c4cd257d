"""Jointed beam: bolt preload, modes about the prestressed state, k_t calibrated on the measured f1.

The bolted half Brake-Reuss beam of ``jointed_beam.toml`` (free-free, three bolts at
12 kN, dry-friction interface elements) is preloaded with frictionless normal contact,
friction is switched on from that state, and the modes of the tangent ``K + df/dq``
(closed pairs stuck, open pairs free) are computed. One parameter is calibrated: the
tangential stiffness per unit area ``k_t`` of the interface, by a 1-D root find so
that the first vertical bending mode is the measured low-amplitude 80.5 Hz (acc3
spectrum, data/brb/README.md). The next two modes are predictions, compared with the
measured 221.7 and 297.7 Hz and named by the model's mode shapes.

Why ``k_t``: the first bending mode loads the lap joint in shear (the layers slide
against each other where the joint bends), so ``k_t`` is the parameter f1 is most
sensitive to; ``k_n`` (a hard-contact penalty, fixed) sets which part of the interface
stays closed under the preload, and ``k_t`` does not change that state (a frictionless
preload), so the root find needs one static solve and one eigensolve per trial.

Run ``python -m femrom run jointed_beam_prestress [--fine] [-o DIR]``; tests import the functions.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from femrom.cases import case_parser
from femrom.post import write_metrics
from femrom.scene import (
    PrestressedModel,
    beam_mode_shapes,
    calibrate_law_parameter,
    linearized_modes,
    prestressed_model,
    with_law_parameters,
)
from femrom.study import JOINTED_BEAM, JointedBeamModel

SCENE = Path(__file__).with_name("jointed_beam.toml")


def prestressed_beam(parameters: dict | None = None, *, scene_path: Path = SCENE,
                     **joint_parameters) -> PrestressedModel:
    """Build the scene (mesh ``parameters`` and the joint law's parameters overridden) and preload it on
    the beam's statically determinate supports (:data:`femrom.study.JOINTED_BEAM`)."""
    scene = JointedBeamModel(mesh=tuple((parameters or {}).items())).scene(scene_path, **joint_parameters)
    return prestressed_model(scene, JOINTED_BEAM.supports)


def calibrate(beam: PrestressedModel) -> tuple[float, int]:
    """``(k_t, evaluations)`` with the first elastic mode, checked to be the first vertical bending mode, at
    the measured f1: Brent's method on log10 k_t in the bracket (xtol 1e-5: 2.3e-5 relative in k_t, ~1e-5 Hz
    in f1, df1/dlog10 k_t ~ 7 Hz)."""
    return calibrate_law_parameter(beam, "tangential_stiffness", JOINTED_BEAM.measured_f1,
                                   JOINTED_BEAM.stiffness_bracket, mode=6, shape=("vertical", 2))


def beam_modes(beam: PrestressedModel, tangential_stiffness: float, n_modes: int = 12):
    """``(frequencies (n_modes,) Hz, shapes: list of BeamModeShape for the elastic modes)``."""
    system = with_law_parameters(beam.fom.system, tangential_stiffness=tangential_stiffness)
    modes = linearized_modes(system, beam.preload.displacement, beam.preload.state, n_modes=n_modes)
    return modes.frequencies, beam_mode_shapes(beam.fom.space, system.condensation, modes.shapes[:, 6:n_modes])


def contact_summary(beam: PrestressedModel) -> dict:
    """The preloaded interface: closed area, total normal force, and how the pressure sits around the bolts."""
    joint = beam.joint
    traction = joint.tractions(beam.preload.displacement, beam.preload.state)
    pressure = -traction[:, 2]
    closed = pressure > 0
    from femrom.mesh import interface_pairs
    pairs = interface_pairs(beam.fom.space.mesh, "interface_left", "interface_right", order=2)
    x, z = pairs.points[:, 0], pairs.points[:, 2]
    distance = np.min(np.hypot(x[:, None] - JOINTED_BEAM.bolts_x[None, :], z[:, None]), axis=1)
    bands = [(0.0, 0.0088), (0.0088, 0.0127), (0.0127, 0.018), (0.018, 1.0)]
    rings = []
    for low, high in bands:
        inside = (distance >= low) & (distance < high)
        area = pairs.areas[inside].sum()
        rings.append({"from_mm": 1e3 * low, "to_mm": 1e3 * high, "closed_area_share": float(
            pairs.areas[inside & closed].sum() / area), "mean_pressure_MPa": float(
            (pairs.areas[inside] * pressure[inside]).sum() / area / 1e6)})
    return {"pairs": int(closed.size), "closed_pairs": int(closed.sum()),
            "closed_area_share": float(pairs.areas[closed].sum() / pairs.areas.sum()),
            "closed_x_mm": (1e3 * float(x[closed].min()), 1e3 * float(x[closed].max())),
            "normal_force": float(joint.areas @ pressure), "peak_pressure_MPa": float(pressure.max() / 1e6),
            "max_reaction": float(np.abs(beam.preload.frictional.reactions).max()),
            "newton_iterations": (beam.preload.frictionless.iterations, beam.preload.frictional.iterations),
            "by_distance_from_bolt_axis": rings}


def run(parameters: dict | None = None, **joint_parameters) -> dict:
    """Preload, calibrate k_t on f1, predict the next modes; everything measured, as a dict."""
    beam = prestressed_beam(parameters, **joint_parameters)
    tic = time.perf_counter()
    k_t, evaluations = calibrate(beam)
    seconds = time.perf_counter() - tic
    frequencies, shapes = beam_modes(beam, k_t, n_modes=12)
    elastic = frequencies[6:]
    predictions = []
    for measured in JOINTED_BEAM.measured_next:
        j = int(np.argmin(np.abs(elastic - measured)))
        predictions.append({"measured": measured, "model": float(elastic[j]),
                            "error": float(elastic[j] / measured - 1),
                            "shape": f"{shapes[j].kind} bending, {shapes[j].sign_changes} sign changes"
                            if shapes[j].kind in ("vertical", "in-plane") else shapes[j].kind})
    return {"n_dofs": beam.fom.system.n_dofs, "mesh": dict(beam.fom.scene.structure.parameters),
            "tangential_stiffness": k_t, "normal_stiffness": beam.joint.law.normal_stiffness,
            "f1": float(elastic[0]), "rigid_body_max_hz": float(np.abs(frequencies[:6]).max()),
            "modes": [(float(f), s.kind, s.sign_changes, round(s.share, 4)) for f, s in zip(elastic, shapes)],
            "predictions": predictions, "contact": contact_summary(beam),
            "seconds": {"build_and_preload": beam.seconds, "calibration": seconds, "evaluations": evaluations}}


def main(argv=None) -> int:
    parser = case_parser("jointed_beam_prestress", __doc__,
                         quick="the default run: the coarse joint mesh is already this case's quickest "
                               "(accepted so that every case takes it)",
                         out="also write the results to OUT/metrics.json (default: print only)")
    parser.set_defaults(out=None)
    parser.add_argument("--fine", action="store_true",
                        help="also the finer joint mesh (12.7 / 3.175 mm): the calibrated k_t's mesh sensitivity")
    parser.add_argument("--normal-stiffness", type=float, nargs="*", default=[],
                        help="also these k_n [Pa/m]: the calibrated k_t and the predictions under each")
    args = parser.parse_args(argv)
    runs = [({}, {})]
    if args.fine:
        runs.append(({"joint_mesh_size": 0.003175}, {}))
    runs += [({}, {"normal_stiffness": k_n}) for k_n in args.normal_stiffness]
    results = []
    for mesh, joint in runs:
        result = run(mesh, **joint)
        results.append(result)
        print(f"mesh {result['mesh']}, {result['n_dofs']} dofs, k_n = {result['normal_stiffness']:.3g} Pa/m: "
              f"k_t = {result['tangential_stiffness']:.5g} Pa/m, f1 = {result['f1']:.4f} Hz "
              f"({result['seconds']['evaluations']} eigensolves, {result['seconds']['calibration']:.0f} s; "
              f"build + preload {result['seconds']['build_and_preload']:.0f} s)")
        for p in result["predictions"]:
            print(f"  measured {p['measured']} Hz -> model {p['model']:.2f} Hz ({100 * p['error']:+.2f} %), {p['shape']}")
        print("  modes:", ", ".join(f"{f:.1f} {k}{n}" for f, k, n, _ in result["modes"]))
        print("  contact:", {k: v for k, v in result["contact"].items() if k != "by_distance_from_bolt_axis"})
        for ring in result["contact"]["by_distance_from_bolt_axis"]:
            print("   ", ring)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        write_metrics(args.out / "metrics.json", {"case": "jointed_beam_prestress", "runs": results})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
