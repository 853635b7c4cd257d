r"""The bolted half Brake-Reuss beam: its facts and its model chain, shared by the jointed-beam cases.

The beam (Chen et al., MSSP 166:108401, 2022; geometry ``meshes/jointed_beam.geo``, the scene
``femrom/cases/jointed_beam.toml``: P2 solid, free-free, three bolts at 12 kN, dry-friction
interface elements on the lap joint's node pairs) is modelled in steps that two cases share
(``jointed_beam``: QSMA, ring-down, stepped sine; ``jointed_beam_rom``: ROMs trained on the
hyper-reduced model), each a library function and the settings here:

1. :meth:`JointedBeamModel.scene`: the scene file with mesh (and joint-law) parameters set;
2. :meth:`JointedBeamModel.calibrated`: build, preload on the statically determinate supports of
   :data:`JOINTED_BEAM` (:func:`~femrom.scene.prestressed_model`), the tangential stiffness ``k_t``
   calibrated so that the first elastic mode, checked to be the first vertical bending mode, is the
   measured ``f_1 = 80.5`` Hz (:func:`~femrom.scene.calibrate_law_parameter`), and the modes about
   the preload (6 rigid-body modes, then ``n_modes`` elastic ones);
3. :meth:`JointedBeamModel.iwan_joint`: the ``clamped_iwan`` joint about the preload at its static
   equilibrium (:func:`~femrom.scene.clamped_iwan_joint`), held 3-2-1 on the left end face;
4. :meth:`JointedBeamModel.reduced`: Galerkin on the ``n_modes`` elastic modes about that
   equilibrium (:func:`~femrom.inference.galerkin`, the joint on every pair), linear modal damping,
   the inputs hammer (a half-sine of ``impact_peak``, ``impact_width``) and shaker (silent);
6. :func:`modal_qsma` (QSMA of a modal model's mode 1) and :meth:`JointedBeamModel.fit_iwan_on` (the Iwan
   joint's ``chi``, ``beta`` fitted on a measured backbone by it);
5. :meth:`JointedBeamModel.hyper_reduced`: ECSW trained on short all-pair ring-downs
   (:func:`ecsw_training`, :func:`~femrom.rom.ecsw_joint`): the joint's slip remainder sampled on
   a few weighted pairs (:func:`~femrom.rom.hyper_reduced_system`);

with the step ``dt = 1 / (steps_per_period f_1)`` (:meth:`JointedBeamModel.dt`).
"""

from __future__ import annotations

import dataclasses
import time
import tomllib
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from femrom._errors import FemromError, FemromValueError
from femrom.inference import galerkin
from femrom.integrators import HarmonicBalance, epmc, linear_mode
from femrom.post import epmc_backbone, static_qsma, with_linear_damping
from femrom.rom import ecsw_joint, hyper_reduced_system
from femrom.scene import (
    Scene,
    Signal,
    SignalVector,
    beam_mode_shapes,
    calibrate_law_parameter,
    clamped_iwan_joint,
    linearized_modes,
    point_supports,
    prestressed_model,
    with_law_parameters,
)
from femrom.study._impacts import ImpactTraining, ecsw_training, output_ring_down, with_impulse


@dataclass(frozen=True)
class BrakeReussBeam:
    """Facts of the half Brake-Reuss beam: dimensions [m], bolt axes, the measured modal frequencies
    (low-amplitude peaks of acc3's spectrum, data/brb/README.md) [Hz] and the calibration's bracket of
    ``k_t`` [Pa/m] (``f_1`` = 72.9 and 86.0 Hz at its ends on the coarse mesh)."""

    length: float = 0.720
    width: float = 0.0254
    thickness: float = 0.0127
    bolt_spacing: float = 0.030
    measured_f1: float = 80.5
    measured_next: tuple = (221.7, 297.7)
    stiffness_bracket: tuple = (1e10, 1e13)

    @property
    def bolts_x(self) -> np.ndarray:
        """(3,) x of the bolt axes (at z = 0)."""
        return self.length / 2 + self.bolt_spacing * np.array([-1.0, 0.0, 1.0])

    @property
    def supports(self) -> list:
        """Statically determinate supports of the free beam for the preload (:func:`~femrom.scene.point_supports`):
        3-2-1 on the left end face (the six rigid-body modes) and three on the right end face (the
        right half's sliding in x, z and turning about y, free under frictionless contact); far from
        the joint."""
        w, t, length = self.width, self.thickness, self.length
        return [((0.0, 0.0, -w / 2), "xyz"), ((0.0, 0.0, w / 2), "xy"), ((0.0, t, -w / 2), "x"),
                ((length, 0.0, -w / 2), "xz"), ((length, 0.0, w / 2), "x")]

    @property
    def left_face(self) -> list:
        """The 3-2-1 supports on the left end face alone: no mechanism once the joint carries friction."""
        return self.supports[:3]


#: The beam of the jointed-beam cases.
JOINTED_BEAM = BrakeReussBeam()


@dataclass(frozen=True, eq=False)
class CalibratedBeam:
    """The preloaded beam with ``k_t`` calibrated, and its modes about the preload.

    Attributes
    ----------
    beam : PrestressedModel
    system : SecondOrderSystem
        The full model with the calibrated ``k_t`` (dry-friction joint).
    tangential_stiffness : float
        ``k_t`` [Pa/m].
    evaluations : int
        Eigensolves of the calibration.
    modes : Modes
        6 rigid-body modes, then the elastic ones.
    shapes : list of BeamModeShape
        Of the elastic modes.
    seconds : float
    """

    beam: object
    system: object
    tangential_stiffness: float
    evaluations: int
    modes: object
    shapes: list
    seconds: float

    @property
    def f1(self) -> float:
        """The first elastic frequency [Hz]."""
        return float(self.modes.frequencies[6])

    @property
    def left_face(self) -> np.ndarray:
        """Free-dof indices of :attr:`BrakeReussBeam.left_face`."""
        return point_supports(self.beam.fom.space, self.system.condensation, JOINTED_BEAM.left_face)

    def linear_predictions(self) -> dict:
        """The elastic frequencies and shapes, and the modes nearest the measured next two
        (:attr:`BrakeReussBeam.measured_next`) with their relative errors."""
        frequencies = self.modes.frequencies[6:]
        predictions = []
        for measured in JOINTED_BEAM.measured_next:
            j = int(np.argmin(np.abs(frequencies - measured)))
            shape = self.shapes[j]
            predictions.append({"measured_hz": measured, "model_hz": float(frequencies[j]),
                                "error": float(frequencies[j] / measured - 1),
                                "shape": f"{shape.kind} bending, {shape.sign_changes} sign changes"
                                if shape.kind in ("vertical", "in-plane") else shape.kind})
        return {"linear_frequencies_hz": [float(f) for f in frequencies],
                "mode_shapes": [f"{s.kind} {s.sign_changes}" for s in self.shapes],
                "predictions": predictions}


@dataclass(frozen=True)
class JointedBeamModel:
    """Settings of the model chain (module docstring); the defaults are the cases'."""

    mesh: tuple = ()                            #: geometry parameter overrides, e.g. (("joint_mesh_size", 0.003175),)
    n_modes: int = 10                           #: elastic modes of the reduced model
    impact_peak: float = 300.0                  #: hammer peak force [N]
    impact_width: float = 3.0e-4                #: half-sine width [s]
    steps_per_period: int = 128                 #: of mode 1: dt = 1 / (f1 N)
    friction_coefficient: float = 0.6           #: mu of the Iwan joint's macro-slip traction mu p_0 (textbook)
    iwan_chi: float = -0.5                      #: the Iwan density's exponent (the fit's result on the default mesh)
    iwan_beta: float = 0.94                     #: the weight of its delta (idem)
    training_impacts: tuple = (300.0, 1500.0)   #: blows [N] of the all-pair ring-downs ECSW trains on
    training_window: float = 0.15               #: their length [s]
    ecsw_tolerance: float = 3e-3                #: relative residual of the sampled slip remainder

    def scene(self, path, **joint_parameters) -> Scene:
        """The scene file at ``path`` with :attr:`mesh`'s geometry parameters and ``joint_parameters``
        (the joint law's, e.g. ``normal_stiffness``) set."""
        data = tomllib.loads(Scene.from_toml(path).source_text)
        data["structure"]["parameters"].update(dict(self.mesh))
        data["effects"]["joint"]["parameters"].update(joint_parameters)
        return Scene.from_dict(data)

    def calibrated(self, scene: Scene) -> CalibratedBeam:
        """Build, preload, calibrate ``k_t`` on the measured ``f_1``, and the ``6 + n_modes`` modes about
        the preload."""
        tic = time.perf_counter()
        beam = prestressed_model(scene, JOINTED_BEAM.supports)
        k_t, evaluations = calibrate_law_parameter(beam, "tangential_stiffness", JOINTED_BEAM.measured_f1,
                                                   JOINTED_BEAM.stiffness_bracket, mode=6, shape=("vertical", 2))
        system = with_law_parameters(beam.fom.system, tangential_stiffness=k_t)
        modes = linearized_modes(system, beam.preload.displacement, beam.preload.state,
                                 n_modes=6 + self.n_modes)
        shapes = beam_mode_shapes(beam.fom.space, system.condensation, modes.shapes[:, 6:6 + self.n_modes])
        return CalibratedBeam(beam, system, k_t, evaluations, modes, shapes, time.perf_counter() - tic)

    def iwan_joint(self, calibrated: CalibratedBeam, *, chi: float | None = None, beta: float | None = None):
        """``(system, q0, z0)``: the full model with the ``clamped_iwan`` joint (``mu``: :attr:`friction_coefficient`;
        ``chi``, ``beta``: these settings' unless given) at its static equilibrium about the preload."""
        beam = calibrated.beam
        return clamped_iwan_joint(calibrated.system, beam.preload.displacement, beam.preload.state,
                                  calibrated.left_face, friction_coefficient=self.friction_coefficient,
                                  chi=self.iwan_chi if chi is None else chi,
                                  beta=self.iwan_beta if beta is None else beta)

    def reduced(self, calibrated: CalibratedBeam, system, q0, z0, damping_ratio: float):
        """Galerkin on the ``n_modes`` elastic modes about ``(q0, z0)``, the joint on every pair, modal damping
        ``damping_ratio``; inputs: the hammer (peak :attr:`impact_peak`) and the shaker (amplitude 0: set by a
        stepped sine)."""
        hammer = Signal.from_dict({"kind": "impulse", "amplitude": self.impact_peak, "start": 0.0,
                                   "duration": self.impact_width})
        shaker = Signal.from_dict({"kind": "sine", "amplitude": 0.0, "frequency": 80.5})
        V = calibrated.modes.shapes[:, 6:6 + self.n_modes]
        model = galerkin(system, V, reference=q0, reference_state=z0, damping_ratios=damping_ratio).system
        return dataclasses.replace(model, inputs=SignalVector([hammer, shaker]), output_names=system.output_names)

    def dt(self, calibrated: CalibratedBeam) -> float:
        """``1 / (steps_per_period f_1)``."""
        return 1.0 / (calibrated.f1 * self.steps_per_period)

    def hyper_reduced(self, reduced, z0, dt: float, *, progress=None, scheme=None):
        """``(training, sampling, hyper, z_hyper)``: :func:`ecsw_training` at :attr:`training_impacts` over
        :attr:`training_window` (every 4th step; ``scheme``: default Newmark), ECSW at :attr:`ecsw_tolerance`,
        the hyper-reduced model and its rest state."""
        training: ImpactTraining = ecsw_training(reduced, z0, self.training_impacts, width=self.impact_width,
                                                 window=self.training_window, dt=dt, progress=progress,
                                                 scheme=scheme)
        sampling = ecsw_joint(reduced, training.snapshots, z0, tolerance=self.ecsw_tolerance)
        hyper, z_hyper = hyper_reduced_system(reduced, sampling, z0)
        return training, sampling, hyper, z_hyper

    def hyper_validation(self, training: ImpactTraining, hyper, z_hyper, dt: float) -> dict:
        """The hyper-reduced model against the all-pair runs ECSW trained on: per blow, the largest
        difference of acc1 over its largest value (``"<peak>_n_acc1_max_error"``)."""
        out = {}
        for peak, run in training.runs.items():
            acc = run.accelerations[0]
            acc_hyper = output_ring_down(with_impulse(hyper, peak, self.impact_width), z_hyper,
                                         self.training_window, dt).accelerations[0]
            out[f"{peak:g}_n_acc1_max_error"] = float(np.max(np.abs(acc_hyper - acc)) / np.max(np.abs(acc)))
        return out

    def measured_range(self, calibrated: CalibratedBeam, joint: "MeasuredRangeJoint", damping_ratio: float, *,
                       attached: bool = True):
        """``(reduced, z0)``: the full model with the ``clamped_iwan`` joint of ``joint`` (reclosing points
        included, with their normal dashpot ``joint.closing_damping``) at its static equilibrium about the preload, Galerkin on the modes (:meth:`reduced`, every
        pair), and with ``attached`` the shaker's mass on input 1 (:func:`with_attached_mass`)."""
        beam = calibrated.beam
        model, q0, z0 = clamped_iwan_joint(calibrated.system, beam.preload.displacement, beam.preload.state,
                                           calibrated.left_face, friction_coefficient=joint.friction_coefficient,
                                           chi=joint.chi, beta=joint.beta, closing=joint.closing,
                                           closing_friction=joint.friction_coefficient,
                                           closing_damping=joint.closing_damping)
        reduced = self.reduced(calibrated, model, q0, z0, damping_ratio)
        return (with_attached_mass(reduced, 1, joint.shaker_mass) if attached else reduced), z0

    def measured_range_backbone(self, reduced, z0, *, harmonics: int = 1, samples: int | None = None,
                                top: float = 90.0):
        """The EPMC backbone (:func:`~femrom.integrators.epmc`) of mode 1 of a modal model at acc3 (output 2)
        from about 1 m/s^2 to ``top`` m/s^2 (16 modal amplitudes set from the linear mode's acc3 amplitude):
        ``(modes, backbone)``."""
        hb = HarmonicBalance(reduced, None, harmonics=1, state=z0)
        omega, phi = linear_mode(hb, 0)
        per_modal = omega**2 * abs(float(hb.output_matrix[2] @ phi))       # acc3 [m/s^2] per unit modal amplitude
        amplitudes = np.geomspace(1.0, top, 16) / per_modal
        modes = epmc(reduced, amplitudes, mode=0, harmonics=harmonics, samples=samples, state=z0)
        return modes, epmc_backbone(modes, quantity="acceleration", output=2)

    def fit_measured_range(self, calibrated: CalibratedBeam, response_controlled, hammer, damping_ratio: float, *,
                           start: MeasuredRangeJoint | None = None, evaluations: int = 45, progress=print,
                           parameters=("friction_coefficient", "chi", "closing"), samples: int | None = None,
                           norm: str = "squares") -> dict:
        """The :class:`MeasuredRangeJoint`'s ``parameters`` (default ``mu``, ``chi``, ``kappa``; the others, ``beta``
        and the shaker mass as in ``start``) fitted on two measured backbones at acc3 together: the
        response-controlled stepped sine's (:func:`~femrom.post.phase_resonance_backbone`, with the shaker's mass)
        and the hammer's (:func:`~femrom.post.measured_backbone` of acc3 at 2.5, 5, 10 and 14 m/s^2, without it).

        ``parameters``: any of ``friction_coefficient``, ``chi``, ``closing`` and ``closing_damping``
        (:data:`RANGE_FIT_PARAMETERS`), fitted as ``log mu``, ``logit((chi + 1) / 2)`` (``-1 < chi < 1``),
        ``log kappa`` and ``log lambda`` (``closing`` and ``closing_damping`` must then start above 0); the
        initial simplex steps ``mu``, ``kappa`` and ``lambda`` by a factor 0.5 and the logit by 1. ``samples``: EPMC's
        samples per period (default 8, :func:`~femrom.integrators.default_samples`); the dashpot acts over the short
        contacts of the reclosing points, which 8 samples resolve poorly: ask for 16 with ``closing_damping``
        (measured on the default model with ``closing_damping = 6e12``: the backbone's damping at 36-90 m/s^2 is
        within 2 % of 64 samples' with 16, within 8 % with 8; a backbone costs about 10 s with 8 samples, 43 s with
        16 and 112 s with 64 on 2 cores).

        Each evaluation re-solves the full model's equilibrium under the joint, projects it on the modes
        (every pair) and runs EPMC (H = 1) of mode 1 on the modal model, with and without the shaker's
        mass (:meth:`measured_range_backbone`; about 15-40 s on 2 cores). The misfit: frequency errors
        over 0.1 Hz and logs of the damping ratios' quotients over ``log 1.2`` (the issue's tolerances),
        one sum of squares (``norm="squares"``) or the largest of their absolute values (``norm="max"``:
        the form the tolerances are stated in, every level within them exactly when the misfit is at most 1);
        Nelder-Mead from ``start``, at most ``evaluations`` evaluations. Returns the best
        joint, its misfit, the history, the per-level errors and the fitted ``parameters``."""
        names = _range_fit_parameters(parameters)
        if norm not in RANGE_FIT_NORMS:
            raise FemromValueError(f"fit_measured_range: norm must be one of {', '.join(RANGE_FIT_NORMS)}, "
                                   f"got {norm!r}")
        start = start or MeasuredRangeJoint()
        for name in names:
            if name in ("closing", "closing_damping") and not getattr(start, name) > 0:
                raise FemromValueError(f"fit_measured_range: {name} is fitted on a log scale; start it above 0, "
                                       f"got {getattr(start, name)!r}")
        a_rc = np.asarray(response_controlled.amplitude)
        a_h = np.array([2.5, 5.0, 10.0, 14.0])
        f_h, z_h = hammer.at_amplitude(a_h)
        history = []

        def at(backbone, amplitudes):
            la = np.log(backbone.amplitude)
            return (np.interp(np.log(amplitudes), la, backbone.frequency_hz),
                    np.interp(np.log(amplitudes), la, backbone.damping_ratio))

        def misfit(x):
            joint = dataclasses.replace(start, **{name: RANGE_FIT_PARAMETERS[name][1](value)
                                                  for name, value in zip(names, x)})
            free, z0 = self.measured_range(calibrated, joint, damping_ratio, attached=False)
            shaker = with_attached_mass(free, 1, joint.shaker_mass)
            try:
                f, z = at(self.measured_range_backbone(shaker, z0, samples=samples)[1], a_rc)
                f0, z0h = at(self.measured_range_backbone(free, z0, samples=samples)[1], a_h)
            except FemromError as exc:
                progress(f"  fit {len(history) + 1}: {joint} failed ({exc})")
                return 1e6
            residual = np.concatenate([(f - response_controlled.frequency_hz) / 0.1,
                                       np.log(z / response_controlled.damping_ratio) / np.log(1.2),
                                       (f0 - f_h) / 0.1, np.log(z0h / z_h) / np.log(1.2)])
            value = float(residual @ residual) if norm == "squares" else float(np.max(np.abs(residual)))
            history.append({"misfit": value, **joint.parameters(), "frequency_hz": f.tolist(),
                            "damping_ratio": z.tolist(), "hammer_frequency_hz": f0.tolist(),
                            "hammer_damping_ratio": z0h.tolist()})
            shown = ", ".join(f"{RANGE_FIT_PARAMETERS[name][3]} {getattr(joint, name):.4g}" for name in names)
            progress(f"  fit {len(history)}: {shown}: misfit {value:.2f}")
            return value

        tic = time.perf_counter()
        x0 = np.array([RANGE_FIT_PARAMETERS[name][0](getattr(start, name)) for name in names])
        simplex = [x0] + [x0 + step for step in np.diag([RANGE_FIT_PARAMETERS[name][2] for name in names])]
        minimize(misfit, x0, method="Nelder-Mead",
                 options={"maxfev": evaluations, "xatol": 1e-2, "fatol": 1e-2, "initial_simplex": simplex})
        best = min(history, key=lambda h: h["misfit"])
        joint = dataclasses.replace(start, **{name: best[name] for name in names})
        return {"joint": joint, "misfit": best["misfit"], "evaluations": len(history), "history": history,
                "seconds": time.perf_counter() - tic, "parameters": list(names), "norm": norm,
                "fitted_on": f"response-controlled stepped sine at acc3 {a_rc.min():.3g}-{a_rc.max():.3g} m/s^2 "
                             f"and the hammer backbone at acc3 {a_h[0]:g}-{a_h[-1]:g} m/s^2"}

    def fit_iwan_on(self, calibrated: CalibratedBeam, measured, damping_ratio: float, amplitudes, *,
                    start=(-0.5, 0.5), evaluations: int = 50, progress=print) -> dict:
        """``chi`` and ``beta`` of the Iwan joint fitted on a measured backbone (``mu`` fixed).

        Each evaluation re-equilibrates the full model under the law, projects it on the modes and
        runs QSMA on the modal model at ``amplitudes`` (:func:`modal_qsma`, a fraction of a second).
        The misfit at the measured windows between 1 and 24 m/s^2: the frequency drop from the first
        window over the measured total drop, and the log of the damping ratios' quotient, in one sum
        of squares (Nelder-Mead on ``logit(chi + 1)``, ``log beta`` from ``start``, at most
        ``evaluations`` QSMA runs)."""
        a = np.asarray(measured.amplitude)
        a = np.sort(a[(a >= 1.0) & (a <= 24.0)])
        f_measured, z_measured = measured.at_amplitude(a)
        drop = f_measured[0] - f_measured
        history = []

        def misfit(p):
            chi, beta = -1.0 + 1.0 / (1.0 + np.exp(-p[0])), float(np.exp(p[1]))
            model, q0, z0 = self.iwan_joint(calibrated, chi=chi, beta=beta)
            curve = modal_qsma(self.reduced(calibrated, model, q0, z0, damping_ratio), z0, amplitudes, damping_ratio)
            f, z = curve.at_amplitude(a)
            residual = np.concatenate([(f[0] - f - drop) / drop[-1], np.log(z / z_measured)])
            value = float(residual @ residual)
            history.append((value, chi, beta))
            progress(f"  fit {len(history)}: chi {chi:+.3f}, beta {beta:.3f}, misfit {value:.4f}")
            return value

        tic = time.perf_counter()
        chi0, beta0 = start
        minimize(misfit, [np.log((chi0 + 1.0) / -chi0), np.log(beta0)], method="Nelder-Mead",
                 options={"xatol": 1e-2, "fatol": 1e-4, "maxfev": evaluations})
        value, chi, beta = min(history)
        return {"chi": chi, "beta": beta, "misfit": value, "evaluations": len(history),
                "seconds": time.perf_counter() - tic,
                "fitted_on": f"measured backbone at acc1, {a[0]:.3g}-{a[-1]:.3g} m/s^2"}


def modal_qsma(reduced, z0, amplitudes, damping_ratio: float):
    """QSMA (:func:`~femrom.post.static_qsma`) of the first coordinate of a modal model (mode 1:
    ``V^T M V = I``) from its rest state ``z0``, with the linear modal damping ``damping_ratio`` added."""
    phi = np.zeros(reduced.n_dofs)
    phi[0] = 1.0
    result = static_qsma(reduced, amplitudes, reference=np.zeros(reduced.n_dofs), state=z0, mode=phi)
    return with_linear_damping(result.backbone(0), damping_ratio)


#: The :class:`MeasuredRangeJoint` parameters :meth:`JointedBeamModel.fit_measured_range` can fit: ``name ->
#: (to the fit's variable, back, the initial simplex's step, the label)``.
RANGE_FIT_PARAMETERS = {
    "friction_coefficient": (np.log, lambda x: float(np.exp(x)), np.log(0.5), "mu"),
    "chi": (lambda chi: np.log((1.0 + chi) / (1.0 - chi)), lambda x: float(-1.0 + 2.0 / (1.0 + np.exp(-x))), 1.0,
            "chi"),
    "closing": (np.log, lambda x: float(np.exp(x)), np.log(0.5), "kappa"),
    "closing_damping": (np.log, lambda x: float(np.exp(x)), np.log(0.5), "lambda"),
}


#: How :meth:`JointedBeamModel.fit_measured_range` sums the scaled residuals: squares, or the largest.
RANGE_FIT_NORMS = ("squares", "max")


def _range_fit_parameters(parameters) -> tuple:
    """``parameters`` checked: a non-empty sequence of distinct names of :data:`RANGE_FIT_PARAMETERS`."""
    known = ", ".join(RANGE_FIT_PARAMETERS)
    names = (parameters,) if isinstance(parameters, str) else tuple(parameters)
    if not names:
        raise FemromValueError(f"fit_measured_range: parameters must name at least one of {known}")
    for name in names:
        if name not in RANGE_FIT_PARAMETERS:
            raise FemromValueError(f"fit_measured_range: parameters must be among {known}, got {name!r}")
    if len(set(names)) != len(names):
        raise FemromValueError(f"fit_measured_range: parameters must be distinct, got {list(names)}")
    return names


@dataclass(frozen=True)
class MeasuredRangeJoint:
    r"""The joint that covers the measured range, 5-80 m/s^2 at acc3, and the shaker's attachment.

    The ``clamped_iwan`` law (:class:`~femrom.fem.ClampedIwanLaw`) with three fitted parameters:
    ``friction_coefficient`` (``mu``: the macro-slip traction ``mu p_0`` of the preload's closed
    points), ``closing`` (``kappa``: the points open at the preload touch again under the penalty
    ``kappa k_n``, with Coulomb friction ``mu``) and ``closing_damping`` [Pa s/m^2] (``lambda``: the
    Hunt-Crossley normal dashpot of those re-closed points, ``t_n = min(kappa k_n g_n - lambda g_n gdot_n,
    0)``, continuous at a touch); ``chi`` (the Iwan density's exponent, 0: Mindlin-Goodman's cubic
    micro-slip) and ``beta`` (the weight of the density's delta) fixed. Fitted by
    :meth:`JointedBeamModel.fit_measured_range` on the response-controlled stepped sine and the hammer's
    backbone at acc3 together (the defaults are that fit's result on the default mesh,
    docs/cases/jointed_beam.md). ``shaker_mass`` [kg]: a rigid mass moving with the shaker patch (the
    stinger and force gauge), read off the data, not fitted: the shaker test's phase-resonance frequency
    at 5 m/s^2 lies 0.107 Hz below the hammer test's at the same acc3 amplitude, and ``Delta m = 2 m_eff
    Delta f / f`` with the modal mass at acc3 the test gives at resonance (``m_eff = F / (2 zeta A) =
    1.95`` kg) is 5.2 g.
    """

    friction_coefficient: float = 0.4267
    chi: float = 0.0
    beta: float = 0.3
    closing: float = 1.213e-4
    shaker_mass: float = 5.2e-3
    closing_damping: float = 1.307e13

    def __post_init__(self):
        for name, ok, valid in (("friction_coefficient", lambda v: v > 0, "> 0"), ("chi", lambda v: v > -1, "> -1"),
                                ("beta", lambda v: v >= 0, ">= 0"), ("closing", lambda v: v >= 0, ">= 0"),
                                ("shaker_mass", lambda v: v >= 0, ">= 0 [kg]"),
                                ("closing_damping", lambda v: v >= 0, ">= 0 [Pa s/m^2]")):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and ok(value)):
                raise FemromValueError(f"MeasuredRangeJoint: {name} must be {valid}, got {value!r}")

    def parameters(self) -> dict:
        return dataclasses.asdict(self)


def with_attached_mass(system, input: int, mass: float):
    """``system`` with a rigid ``mass`` [kg] moving with the patch that input column ``input`` loads:
    ``M + m b b^T`` (``b`` the column; for a unit total traction on a patch, ``b^T q`` is the patch's mean
    displacement along the load). A dense (reduced) model only."""
    b = np.asarray(system.input_matrix)[:, int(input)]
    mass_matrix = np.asarray(system.mass.toarray() if hasattr(system.mass, "toarray") else system.mass)
    return dataclasses.replace(system, mass=mass_matrix + float(mass) * np.outer(b, b))
