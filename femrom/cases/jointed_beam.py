"""Jointed beam: preload, calibrated modes, backbones (QSMA, ring-down, measured) and stepped sine.

The bolted half Brake-Reuss beam of ``jointed_beam.toml`` (free-free, three bolts at
12 kN, dry-friction interface elements on the lap joint's node pairs), end to end:

1. **Preload and calibration** (``femrom/cases/jointed_beam_prestress.py``): frictionless preload,
   friction on, and the one calibrated stiffness, the interface's tangential stiffness
   ``k_t``, set so that the first bending mode is the measured 80.5 Hz. The next
   modes are predictions against the measured 221.7 and 297.7 Hz.
2. **QSMA on the full model with dry friction** (:func:`femrom.post.quasi_static_modal_analysis`):
   static loads ``alpha M phi_1`` in Newton on all 24,522 dofs, Masing damping; amplitudes
   as acc1's acceleration. No joint parameter is fitted for this curve.
3. **The Iwan joint** (law ``clamped_iwan``: the preload's contact status and slip traction
   ``mu p_0`` frozen, slip spread over Segalman's Iwan element): ``mu`` the textbook 0.6,
   ``chi`` and ``beta`` fitted on the measured backbone by QSMA of the 10-mode model
   (``--no-fit`` keeps the defaults, the fit's result on the default mesh); QSMA of the full
   and the 10-mode model under it.
4. **Hyper-reduction** (:func:`femrom.rom.ecsw_joint`): short ring-downs of the 10-mode model
   with all pairs at two blows train ECSW, which samples the joint's slip remainder on a few
   weighted pairs (the stuck joint stays exact); validated against all pairs.
5. **The impact ring-down** on the hyper-reduced model: the hammer as a 0.3 ms half-sine,
   linear modal damping from the data (the measured damping at the lowest amplitude),
   acc1's band-passed backbone (60-100 Hz, Hilbert, 0.2 s windows) with Newmark's period
   error removed (``f = tan(pi f_h dt) / (pi dt)``, exact for a linear mode).
6. **The measured backbone** of the same processing (``data/brb/hammer_impact.npz``).
7. The stepped-sine forced response of the hyper-reduced model at the shaker (``shaker1``):
   by default 0.2 and 1.5 N at 79.6-80.6 Hz in 0.1 Hz steps; ``--full-sweep`` the
   issue's 0.2, 0.5, 1 and 1.5 N at 79-81.5 Hz in 0.05 Hz steps.

Run ``python -m femrom run jointed_beam [-o results/jointed_beam] [--full-sweep] [--quick] [--no-fit]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from femrom.cases import jointed_beam_prestress as prestress
from femrom.fem import ClampedIwanLaw, JointForce, clamped_iwan_state, clamped_state
from femrom.integrators import (
    Newmark,
    SteadyStateCriterion,
    SteppedSine,
    StepResult,
    SystemPlant,
    Trajectory,
    integrate,
)
from femrom.post import (
    Backbone,
    hilbert_backbone,
    measured_backbone,
    plot_backbones,
    quasi_static_modal_analysis,
    read_hammer_impact,
    staged_output,
    write_metrics,
)
from femrom.rom import ecsw_joint, hyper_reduced_system
from femrom.scene import (
    Signal,
    SignalVector,
    beam_mode_shape,
    linearized_modes,
    point_supports,
    project_system,
    solve_static,
)


BAND, WINDOW = (60.0, 100.0), 0.2


@dataclass(frozen=True)
class JointedBeamCase:
    """What the case runs (defaults: the default run, a few minutes on 2 cores)."""

    mesh: tuple = ()                            #: geometry parameter overrides, e.g. (("joint_mesh_size", 0.003175),)
    n_modes: int = 10                           #: elastic modes of the reduced model
    impact_peak: float = 300.0                  #: hammer peak force [N]
    impact_width: float = 3.0e-4                #: half-sine width [s]
    ring_down: float = 3.0                      #: simulated seconds after the blow
    steps_per_period: int = 128                 #: of mode 1: dt = 1 / (f1 N)
    qsma_amplitudes: tuple = tuple(np.round(np.logspace(0, np.log10(32.0), 16), 4))  #: acc1 [m/s^2]
    forced: bool = True
    forced_levels: tuple = (0.2, 1.5)            #: shaker force amplitudes [N] (--full-sweep: 0.2, 0.5, 1, 1.5)
    forced_frequencies: tuple = tuple(np.round(np.arange(79.6, 80.6 + 1e-9, 0.1), 3))  #: (--full-sweep: 79-81.5 by 0.05)
    forced_steps_per_period: int = 32
    forced_tolerance: float = 1e-2
    friction_coefficient: float = 0.6           #: mu of the Iwan joint's macro-slip traction mu p_0 (textbook)
    # chi, beta: used as they are without the fit (--no-fit); the fit's result on the default mesh
    iwan_chi: float = -0.5                      #: the Iwan density's exponent
    iwan_beta: float = 0.94                     #: the weight of its delta
    fit_iwan: bool = True                       #: fit chi and beta on the measured backbone (when the data are there)
    fit_start: tuple = (-0.5, 0.5)              #: (chi, beta) the fit starts from
    fit_evaluations: int = 50                   #: Nelder-Mead budget of the fit (one 10-mode QSMA each)
    training_impacts: tuple = (300.0, 1500.0)   #: blows [N] of the all-pair ring-downs ECSW trains on
    training_window: float = 0.15               #: their length [s]
    ecsw_tolerance: float = 3e-3                #: relative residual of the sampled slip remainder


def prestressed(config: JointedBeamCase) -> dict:
    """Build, preload, calibrate k_t, and the modes about the preload (dry-friction joint)."""
    tic = time.perf_counter()
    beam = prestress.prestressed_beam(dict(config.mesh))
    k_t, evaluations = prestress.calibrate(beam)
    system = prestress.with_tangential_stiffness(beam.fom.system, k_t)
    modes = linearized_modes(system, beam.preload.displacement, beam.preload.state, n_modes=6 + config.n_modes)
    points = beam.fom.space.basis.doflocs[:, ::3].T
    shapes = [beam_mode_shape(points, system.condensation.expand(modes.shapes[:, j]).reshape(-1, 3))
              for j in range(6, 6 + config.n_modes)]
    return {"beam": beam, "system": system, "k_t": k_t, "evaluations": evaluations, "modes": modes,
            "shapes": shapes, "seconds": time.perf_counter() - tic}


def qsma(system, amplitudes, *, reference, state, phi, supports=(), rigid_modes=None, progress=print):
    """QSMA of the mode ``phi`` (output 0 = acc1): acc1 amplitudes -> loads ``alpha = A / |E_0 phi|``.

    ``solve_static`` continues from the previous load's displacement and committed
    joint state (a monotonic loading path from the preload ``reference``, ``state``)."""
    E = system.output_matrix
    current = {"q": reference, "z": state}

    def solve(force):
        solution = solve_static(system, system.load + force, supports=supports, state=current["z"],
                                initial_displacement=current["q"], closed_start=False)
        current["q"], current["z"] = solution.displacement, solution.state
        return solution.displacement

    alphas = np.asarray(amplitudes, dtype=float) / abs(float(np.asarray(E @ phi).ravel()[0]))
    tic = time.perf_counter()
    result = quasi_static_modal_analysis(solve, system.mass, phi, alphas, reference=reference, output_matrix=E,
                                         rigid_modes=rigid_modes, progress=lambda line: progress(f"  {line}"))
    return result, time.perf_counter() - tic


def iwan_joint(setup: dict, supports, *, mu: float, chi: float, beta: float):
    """The full model with the ``clamped_iwan`` joint about the preload: ``(system, q0, z0)``.

    The Iwan points start from the dry-friction preload (status, ``mu p_0``, slider positions);
    the static equilibrium is re-solved under the new law (its weakest sliders carry less of the
    preload's tangential traction), so that ``q0`` is an equilibrium of the model that runs."""
    beam, system = setup["beam"], setup["system"]
    joint, q0 = system.nonlinear, beam.preload.displacement
    law = joint.law.parameters()
    gaps = joint.gaps(joint.localize(q0))
    clamped = clamped_state(gaps, beam.preload.state, normal_stiffness=law["normal_stiffness"],
                            friction_coefficient=mu)
    iwan = ClampedIwanLaw(law["normal_stiffness"], law["tangential_stiffness"], chi, beta)
    force = JointForce.from_parameters({**joint.parameters(), "law": iwan.parameters()})
    model = dataclasses.replace(system, nonlinear=force)
    static = solve_static(model, system.load, supports=supports, state=clamped_iwan_state(iwan, gaps, clamped),
                          initial_displacement=q0, closed_start=False)
    q = static.displacement
    return model, q, force.commit(q, None, static.state)


def reduced_model(setup: dict, config: JointedBeamCase, model, q0, z0, damping_ratio: float):
    """The ``n_modes`` elastic modes of the prestressed beam about ``q0``, the joint on every pair;
    inputs: the hammer (peak ``impact_peak``) and the shaker (amplitude set by the stepped sine)."""
    hammer = Signal.from_dict({"kind": "impulse", "amplitude": config.impact_peak, "start": 0.0,
                               "duration": config.impact_width})
    shaker = Signal.from_dict({"kind": "sine", "amplitude": 0.0, "frequency": 80.5})
    full = dataclasses.replace(model, inputs=SignalVector([hammer, shaker]))
    V = setup["modes"].shapes[:, 6:6 + config.n_modes]
    return project_system(full, V, reference=q0, reference_state=z0, damping_ratios=damping_ratio)


def with_blow(system, peak: float, width: float):
    """``system`` with the hammer's peak set to ``peak`` [N] (the shaker silent)."""
    hammer = Signal.from_dict({"kind": "impulse", "amplitude": float(peak), "start": 0.0, "duration": width})
    return dataclasses.replace(system, inputs=SignalVector([hammer, system.inputs.signals[1]]))


def ring_down(reduced, z0, duration: float, dt: float, keep_every: int = 0):
    """The hammer blow and the free decay: ``(acc (3, k), seconds, newton iterations, kept (q^, state))``."""
    r = reduced.n_dofs
    n_steps = int(round(duration / dt))
    trajectory = Trajectory(fields=("a",))
    kept = []

    def keep(result):
        if keep_every and result.step % keep_every == 0:
            kept.append((result.q.copy(), result.state))

    rest = StepResult(step=0, t=0.0, q=np.zeros(r), v=np.zeros(r), a=np.zeros(r), state=z0)
    tic = time.perf_counter()
    summary = integrate(reduced, Newmark(), None, None, dt, n_steps, consumers=[trajectory, keep], start=rest,
                        progress=None)
    acc = np.asarray(reduced.output_matrix @ trajectory.a)
    return acc, time.perf_counter() - tic, summary.newton_iterations, kept


def ecsw_training(reduced, z0, config: JointedBeamCase, dt: float, progress=None):
    """The all-pair ring-downs ECSW trains on (``config.training_impacts``, ``training_window``, every 4th
    step kept): ``(snapshots [(q^, state)], {peak: acc (3, k)}, seconds)``."""
    snapshots, training, seconds = [], {}, {}
    for peak in config.training_impacts:
        if progress is not None:
            progress(f"jointed beam: all {reduced.nonlinear.force_model.n_pairs} pairs, {peak:g} N blow, "
                     f"{config.training_window:g} s (ECSW training) ...")
        acc, sec, _, kept = ring_down(with_blow(reduced, peak, config.impact_width), z0,
                                      config.training_window, dt, keep_every=4)
        snapshots += kept
        training[peak] = acc
        seconds[f"training_{peak:g}_n"] = sec
        seconds.setdefault("all_pairs_ms_per_step", 1e3 * sec / max(acc.shape[1] - 1, 1))
    return snapshots, training, seconds


def reduced_qsma(reduced, z0, amplitudes, damping_ratio: float):
    """QSMA of the first reduced coordinate (mode 1: ``V^T M V = I``), linear damping added: ``(Backbone, s)``."""
    phi = np.zeros(reduced.n_dofs)
    phi[0] = 1.0
    result, seconds = qsma(reduced, amplitudes, reference=np.zeros(reduced.n_dofs), state=z0, phi=phi,
                           progress=lambda line: None)
    curve = result.backbone(0)
    return dataclasses.replace(curve, damping_ratio=curve.damping_ratio + damping_ratio), seconds


def fit_iwan(setup: dict, config: JointedBeamCase, supports, measured: Backbone, damping_ratio: float,
             progress=print) -> dict:
    """``chi`` and ``beta`` of the Iwan joint fitted on the measured backbone (``mu`` fixed).

    Each evaluation re-equilibrates the full model under the law, projects it on the modes and
    runs QSMA on the 10-mode model (a fraction of a second). The misfit at the measured windows
    between 1 and 24 m/s^2: the frequency drop from the first window over the measured total drop,
    and the log of the damping ratios' quotient, in one sum of squares (Nelder-Mead on
    ``logit(chi + 1)``, ``log beta``)."""
    a = np.asarray(measured.amplitude)
    a = np.sort(a[(a >= 1.0) & (a <= 24.0)])
    f_measured, z_measured = measured.at_amplitude(a)
    drop = f_measured[0] - f_measured
    history = []

    def misfit(p):
        chi, beta = -1.0 + 1.0 / (1.0 + np.exp(-p[0])), float(np.exp(p[1]))
        model, q0, z0 = iwan_joint(setup, supports, mu=config.friction_coefficient, chi=chi, beta=beta)
        reduced = reduced_model(setup, config, model, q0, z0, damping_ratio)
        curve, _ = reduced_qsma(reduced, z0, config.qsma_amplitudes, damping_ratio)
        f, z = curve.at_amplitude(a)
        residual = np.concatenate([(f[0] - f - drop) / drop[-1], np.log(z / z_measured)])
        value = float(residual @ residual)
        history.append((value, chi, beta))
        progress(f"  fit {len(history)}: chi {chi:+.3f}, beta {beta:.3f}, misfit {value:.4f}")
        return value

    tic = time.perf_counter()
    chi0, beta0 = config.fit_start
    start = [np.log((chi0 + 1.0) / -chi0), np.log(beta0)]
    minimize(misfit, start, method="Nelder-Mead",
             options={"xatol": 1e-2, "fatol": 1e-4, "maxfev": config.fit_evaluations})
    value, chi, beta = min(history)
    return {"chi": chi, "beta": beta, "misfit": value, "evaluations": len(history),
            "seconds": time.perf_counter() - tic, "fitted_on": f"measured backbone at acc1, {a[0]:.3g}-{a[-1]:.3g} m/s^2"}


def newmark_corrected(backbone: Backbone, dt: float) -> Backbone:
    """Average acceleration's period elongation removed: ``f = tan(pi f_h dt) / (pi dt)``."""
    frequency = np.tan(np.pi * backbone.frequency_hz * dt) / (np.pi * dt)
    return dataclasses.replace(backbone, frequency_hz=frequency)


def linear_accelerance(reduced, z0, force_vector, frequencies_hz) -> np.ndarray:
    """(p, k) ``|omega^2 E (K_t - omega^2 M + i omega C)^-1 f|``: the outputs' acceleration per newton of
    the model with its joint stuck at the preload (the small-force limit of the stepped sine)."""
    D0 = reduced.nonlinear.tangent(np.zeros(reduced.n_dofs), None, z0)[0]
    K = (reduced.stiffness + D0).toarray()
    M, C = reduced.mass.toarray(), reduced.damping.toarray()
    E = np.asarray(reduced.output_matrix)
    columns = []
    for f in frequencies_hz:
        w = 2 * np.pi * f
        columns.append(np.abs(w * w * (E @ np.linalg.solve(K - w * w * M + 1j * w * C, force_vector))))
    return np.column_stack(columns)


def linear_part(setup: dict) -> dict:
    frequencies = setup["modes"].frequencies[6:]
    predictions = []
    for measured in prestress.MEASURED_NEXT:
        j = int(np.argmin(np.abs(frequencies - measured)))
        shape = setup["shapes"][j]
        predictions.append({"measured_hz": measured, "model_hz": float(frequencies[j]),
                            "error": float(frequencies[j] / measured - 1),
                            "shape": f"{shape.kind} bending, {shape.sign_changes} sign changes"
                            if shape.kind in ("vertical", "in-plane") else shape.kind})
    return {"linear_frequencies_hz": [float(f) for f in frequencies],
            "mode_shapes": [f"{s.kind} {s.sign_changes}" for s in setup["shapes"]],
            "predictions": predictions}


def shift_and_damping(backbone: Backbone, low: float = 1.0, high: float = 30.0) -> dict:
    """Frequency shift and damping ratios between two acc1 amplitudes (inside the backbone's range)."""
    amplitude = np.asarray(backbone.amplitude)
    lo, hi = max(low, amplitude.min()), min(high, amplitude.max())
    if not hi > lo:
        return {"from_m_s2": lo, "to_m_s2": hi, "frequency_shift_hz": None}
    f_lo, z_lo = backbone.at_amplitude(lo)
    f_hi, z_hi = backbone.at_amplitude(hi)
    return {"from_m_s2": float(lo), "to_m_s2": float(hi), "frequency_shift_hz": float(f_lo - f_hi),
            "damping_low": float(z_lo), "damping_high": float(z_hi)}


def against_measured(model: Backbone, measured: Backbone, low: float = 1.0) -> dict | None:
    """The model at the measured windows' amplitudes (those inside both ranges, above ``low``): frequency
    shifts from the lowest such amplitude, damping ratios, and the worst relative damping error."""
    a = np.asarray(measured.amplitude)
    inside = (a >= max(low, np.min(model.amplitude))) & (a <= np.max(model.amplitude))
    if np.count_nonzero(inside) < 2:
        return None
    a = np.sort(a[inside])
    f_model, z_model = model.at_amplitude(a)
    f_meas, z_meas = measured.at_amplitude(a)
    return {"amplitudes_m_s2": [float(a[0]), float(a[-1])],
            "shift_model_hz": float(f_model[0] - f_model[-1]), "shift_measured_hz": float(f_meas[0] - f_meas[-1]),
            "damping_max_relative_error": float(np.max(np.abs(z_model / z_meas - 1))),
            "damping_model": [float(z) for z in z_model], "damping_measured": [float(z) for z in z_meas]}


def run(config: JointedBeamCase, out: Path, progress=print, data_dir=None) -> dict:
    tic = time.perf_counter()
    progress("jointed beam: preload and k_t calibration on f1 = 80.5 Hz ...")
    setup = prestressed(config)
    beam, system = setup["beam"], setup["system"]
    f1 = float(setup["modes"].frequencies[6])
    linear = linear_part(setup)
    progress(f"  {system.n_dofs} dofs, k_t = {setup['k_t']:.4g} Pa/m, f1 = {f1:.3f} Hz; predictions "
             + ", ".join(f"{p['measured_hz']} -> {p['model_hz']:.1f} Hz ({100 * p['error']:+.2f} %)"
                         for p in linear["predictions"]))
    backbones, notes = {}, []
    measured = None
    try:
        record = read_hammer_impact(None if data_dir is None else Path(data_dir) / "hammer_impact.npz")
        measured = measured_backbone(record)
        backbones["measured"] = measured
    except FileNotFoundError as exc:
        notes.append(f"measured data not found ({exc}); the measured backbone is left out")
    damping = float(measured.damping_ratio[np.argmin(measured.amplitude)]) if measured is not None else 0.0014
    modes, q0 = setup["modes"], beam.preload.displacement
    left_face = point_supports(beam.fom.space, system.condensation, prestress.SUPPORTS[:3])  # 3-2-1: no mechanism
    common = {"phi": modes.shapes[:, 6], "supports": left_face, "rigid_modes": modes.shapes[:, :6],
              "progress": progress}
    seconds = {}
    progress(f"jointed beam: QSMA on the full model, dry friction ({len(config.qsma_amplitudes)} static loads) ...")
    static, seconds["qsma_fom_dry"] = qsma(system, config.qsma_amplitudes, reference=q0, state=beam.preload.state,
                                          **common)

    # the Iwan joint: chi and beta fitted on the measured backbone (mu the textbook value)
    iwan = {"mu": config.friction_coefficient, "chi": config.iwan_chi, "beta": config.iwan_beta, "fitted": False}
    if config.fit_iwan and measured is not None:
        progress("jointed beam: fitting the Iwan joint's chi and beta on the measured backbone (10-mode QSMA) ...")
        fit = fit_iwan(setup, config, left_face, measured, damping, progress=progress)
        iwan.update(chi=fit["chi"], beta=fit["beta"], fitted=True, fit=fit)
        seconds["fit"] = fit["seconds"]
    model, q_iwan, z_iwan = iwan_joint(setup, left_face, mu=iwan["mu"], chi=iwan["chi"], beta=iwan["beta"])
    progress(f"jointed beam: QSMA on the full model, Iwan joint (chi {iwan['chi']:+.3f}, beta {iwan['beta']:.3f}) ...")
    static_iwan, seconds["qsma_fom_iwan"] = qsma(model, config.qsma_amplitudes, reference=q_iwan, state=z_iwan,
                                                **common)
    reduced = reduced_model(setup, config, model, q_iwan, z_iwan, damping)
    curve_reduced, seconds["qsma_reduced_iwan"] = reduced_qsma(reduced, z_iwan, config.qsma_amplitudes, damping)
    # QSMA's damping is the joint's alone: the linear modal damping of the other models adds to it
    for name, result in (("fom_qsma", static), ("fom_qsma_iwan", static_iwan)):
        curve = result.backbone(0)
        backbones[name] = dataclasses.replace(curve, damping_ratio=curve.damping_ratio + damping)
    backbones["reduced_qsma_iwan"] = curve_reduced

    # hyper-reduction: ECSW trained on short all-pair ring-downs
    dt = 1.0 / (f1 * config.steps_per_period)
    snapshots, training, training_seconds = ecsw_training(reduced, z_iwan, config, dt, progress=progress)
    seconds.update(training_seconds)
    sampling = ecsw_joint(reduced, snapshots, z_iwan, tolerance=config.ecsw_tolerance)
    hyper, z_hyper = hyper_reduced_system(reduced, sampling, z_iwan)
    progress(f"  {sampling.pairs.size} of {sampling.n_pairs} pairs, training residual {sampling.residual:.2g}")
    validation = {}
    for peak, acc in training.items():
        acc_hyper, *_ = ring_down(with_blow(hyper, peak, config.impact_width), z_hyper, config.training_window, dt)
        validation[f"{peak:g}_n_acc1_max_error"] = float(np.max(np.abs(acc_hyper[0] - acc[0])) / np.max(np.abs(acc[0])))
    curve_hyper, _ = reduced_qsma(hyper, z_hyper, config.qsma_amplitudes, damping)
    backbones["hyper_qsma_iwan"] = curve_hyper
    validation["qsma_max_frequency_difference_hz"] = float(np.max(np.abs(curve_hyper.frequency_hz
                                                                         - curve_reduced.frequency_hz)))
    validation["qsma_max_damping_difference"] = float(np.max(np.abs(curve_hyper.damping_ratio
                                                                    - curve_reduced.damping_ratio)))
    progress(f"jointed beam: hyper-reduced model, {config.impact_peak:g} N blow, {config.ring_down:g} s ring-down ...")
    acc, ring_seconds, newton, _ = ring_down(with_blow(hyper, config.impact_peak, config.impact_width), z_hyper,
                                             config.ring_down, dt)
    seconds["ring_down"] = ring_seconds
    backbones["transient"] = newmark_corrected(hilbert_backbone(acc[0], 1.0 / dt, BAND, window=WINDOW), dt)
    forced = None
    if config.forced:
        progress(f"jointed beam: stepped sine, {len(config.forced_levels)} levels x "
                 f"{len(config.forced_frequencies)} frequencies ...")
        shaker = np.asarray(hyper.input_matrix[:, 1]).ravel()
        r = hyper.n_dofs
        plant = SystemPlant(hyper, shaker, rest=StepResult(step=0, t=0.0, q=np.zeros(r), v=np.zeros(r),
                                                            a=np.zeros(r), state=z_hyper))
        sweep = SteppedSine(np.asarray(config.forced_frequencies), steps_per_period=config.forced_steps_per_period,
                            steady_state=SteadyStateCriterion(tolerance=config.forced_tolerance))
        tic_forced = time.perf_counter()
        forced = sweep.run(plant, list(config.forced_levels), progress=lambda line: progress(f"  {line}"))
        seconds["stepped_sine"] = time.perf_counter() - tic_forced

    out.mkdir(parents=True, exist_ok=True)
    plot_backbones(out / "backbone.png", backbones, title="jointed beam, mode 1 at acc1",
                   amplitude_label="acc1 amplitude [m/s^2]")
    rows = {name: [{"amplitude_m_s2": r["amplitude"], "frequency_hz": r["frequency_hz"],
                    "damping_ratio": r["damping_ratio"]} for r in b.rows()] for name, b in backbones.items()}
    metrics = {
        "case": "jointed_beam", "n_dofs": system.n_dofs, "mesh": dict(beam.fom.scene.structure.parameters),
        "calibration": {"parameter": "tangential_stiffness", "value_pa_per_m": setup["k_t"], "target_f1_hz": 80.5,
                        "f1_hz": f1, "eigensolves": setup["evaluations"]},
        **linear,
        "joint": {"law_dry_model": "dry_friction", "law_dynamics": "clamped_iwan",
                  **{k: v for k, v in system.nonlinear.law.parameters().items() if k != "name"},
                  "iwan": {k: v for k, v in iwan.items()}},
        "linear_damping_ratio": damping,
        "backbone": rows,
        "shift_1_to_30_m_s2": {name: shift_and_damping(b) for name, b in backbones.items()},
        "against_measured": {} if measured is None else {
            name: against_measured(b, measured) for name, b in backbones.items() if name != "measured"},
        "hyper_reduction": {**sampling.describe(), "training_impacts_n": list(config.training_impacts),
                            "training_window_s": config.training_window, "validation": validation},
        "transient_model": f"{config.n_modes} elastic modes of the prestressed beam (Galerkin about the preload), "
                           f"the clamped_iwan joint sampled on {sampling.pairs.size} of {sampling.n_pairs} "
                           "interface pairs (ECSW, the stuck joint exact)",
        "reduced_model": {"n_modes": config.n_modes, "dt": dt, "steps": acc.shape[1] - 1,
                          "seconds": ring_seconds, "ms_per_step": 1e3 * ring_seconds / max(acc.shape[1] - 1, 1),
                          "all_pairs_ms_per_step": seconds["all_pairs_ms_per_step"],
                          "newton_iterations": newton, "impact_peak_n": config.impact_peak,
                          "impact_width_s": config.impact_width},
        "seconds": {**seconds, "total": time.perf_counter() - tic},
        "notes": notes,
    }
    if forced is not None:
        # next to each measured point, the stuck joint's (linear) response at that force: the nonlinearity
        # is their difference; at small forces they agree to the steady-state tolerance
        per_newton = linear_accelerance(hyper, z_hyper, shaker, config.forced_frequencies)
        levels = forced.rows()
        for level in levels:
            for i, name in enumerate(hyper.output_names):
                for j, point in enumerate(level["outputs"][name]):
                    point["linear_amplitude_m_s2"] = float(level["force_n"] * per_newton[i, j])
        metrics["forced_response"] = levels
    write_metrics(out / "metrics.json", metrics)
    return metrics


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="femrom run jointed_beam", description=__doc__.split("\n")[0])
    parser.add_argument("-o", "--out", type=Path, default=Path("results") / "jointed_beam")
    parser.add_argument("--full-sweep", action="store_true",
                        help="the stepped sine at 0.2, 0.5, 1, 1.5 N over 79-81.5 Hz by 0.05 Hz (about 40 min)")
    parser.add_argument("--no-forced", action="store_true", help="skip the stepped sine")
    parser.add_argument("--quick", action="store_true", help="short ring-down and few QSMA loads (tests)")
    parser.add_argument("--no-fit", action="store_true", help="the Iwan joint's chi and beta as given, not fitted")
    parser.add_argument("--data", type=Path, help="the folder of hammer_impact.npz (default: femrom.post.brb_data_dir())")
    args = parser.parse_args(argv)
    config = JointedBeamCase(forced=not args.no_forced, fit_iwan=not args.no_fit)
    if args.full_sweep:
        config = dataclasses.replace(config, forced_levels=(0.2, 0.5, 1.0, 1.5),
                                     forced_frequencies=tuple(np.round(np.arange(79.0, 81.5 + 1e-9, 0.05), 3)))
    if args.quick:
        config = dataclasses.replace(config, ring_down=1.0, qsma_amplitudes=(1.0, 3.0, 10.0, 30.0), fit_iwan=False,
                                     training_impacts=(300.0,), training_window=0.1,
                                     forced_levels=(1.5,), forced_frequencies=(80.3, 80.4))
    with staged_output(args.out) as folder:
        metrics = run(config, folder, progress=lambda line: print(line, file=sys.stderr, flush=True),
                      data_dir=args.data)
    shift = metrics["shift_1_to_30_m_s2"]
    print(f"jointed beam: f1 {metrics['calibration']['f1_hz']:.3f} Hz (k_t {metrics['calibration']['value_pa_per_m']:.4g}); "
          + "; ".join(f"{name}: shift {s['frequency_shift_hz']:.3f} Hz" if s["frequency_shift_hz"] is not None
                      else f"{name}: -" for name, s in shift.items())
          + f"; results in {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
