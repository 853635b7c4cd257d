"""SERPENT-like soft robot: L-OpInf against DMDc, ERA, OKID and Galerkin; MPC closed loops on the FOM.

The eel-like robot of ``soft_robot.toml`` (``docs/soft_robot.md``; the study and its numbers:
``docs/cases/soft_robot.md``), end to end: the six chambers driven as three antagonistic pairs
(``v_i``: ``+v_i`` left, ``-v_i`` right, 100 kPa per unit), trained on phased sinusoids and a
band-limited random run, tested on unseen phased sines, a chirp and another random input (every
input from rest through a raised-cosine onset); the study (:func:`femrom.study.run_study`:
Galerkin and L-OpInf at every r); the linear models as discrete state spaces
(:func:`femrom.study.linear_model_rows`: Galerkin, L-OpInf, DMDc, ERA on the FOM's impulse
response, OKID), and MPC (horizon 50, ``|v| <= 0.1``, a Kalman observer) in closed loops on
the FOM, tracking a feasible reference and an eel-like travelling wave
``y(x, t) = a(x) sin(k x - omega t)``.

Run ``python -m femrom run soft_robot [--out DIR] [--quick] [--full]``; tests import :func:`run`.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom.cases import case_parser
from femrom import FemromValueError
from femrom.control import travelling_wave
from femrom.post import staged_output
from femrom.scene import BasisSpec, Derivatives, InputConfig, LearnerSpec, ReportSpec, RomConfig, RunSpec, Scene, \
    TimingSpec, band_limited_noise, chirp, multisine, onset
from femrom.study import ModelSpec, closed_loop_rows, closed_loop_section, linear_model_rows, linear_model_section, \
    run_study

SCENE = Path(__file__).with_suffix(".toml")
SEGMENTS = 3
#: the linear models of the comparison (docs/cases/soft_robot.md)
MODELS = {"galerkin": ModelSpec("galerkin"), "lopinf": ModelSpec("lopinf"), "dmdc": ModelSpec("dmdc"),
          "era": ModelSpec("era"), "okid": ModelSpec("okid", options={"observer_order": 10})}


@dataclass(frozen=True)
class SoftRobotCase:
    """The case's settings (defaults: the default run; :meth:`quick`: the test's).

    Inputs are the three antagonistic pair inputs ``v_i`` (non-dimensional, 100 kPa per
    unit); windows in seconds; frequencies in Hz.
    """

    mesh_size: float = 0.045                      # the small level, 23,325 dofs
    amplitude: float = 0.1                        # the published input bound |u| <= 0.1
    ramp: float = 0.5                             # raised-cosine onset of every input
    train_frequencies: tuple = (0.2, 0.5, 0.9, 1.4)
    train_window: float = 10.0                    # the published 10 s at dt = 0.01 s
    random_train_window: float = 5.0              # 0: no random training run
    random_band: tuple = (0.1, 2.0)
    test_window: float = 3.0
    test_frequency: float = 0.7
    test_phase_lag: float = -math.pi / 2          # segment i lags by i * 90 degrees (training: 120)
    chirp_band: tuple = (0.1, 1.5)
    test_random_band: tuple = (0.1, 1.5)
    ranks: tuple = (2, 4, 6, 10, 16, 20)
    models: tuple = ("galerkin", "lopinf", "dmdc", "era", "okid")
    era_samples: int = 201                        # Y_0 .. Y_200 from one FOM run per input (2 s)
    extension: float = 10.0                       # the long window, in test windows
    controllers: tuple = (("lopinf", 10), ("era", 10))
    control_window: float = 2.5
    horizon: int = 50
    rate_weight: float = 1e-3                     # S = rate_weight / b^2
    measurement_noise: float = 1e-2               # V = this * mean(y_ref^2) I (process noise W = I)
    disturbance: str | None = "output"            # offset-free: a constant output disturbance per output
    wave_tip_amplitude: float = 0.015             # a(x) = this (x / L)^2 [m]
    wave_frequency: float = 0.5
    wave_length: float = 1.5                      # [m]: k = 2 pi / wave_length
    timing_repeats: int = 5                       # ROM step costs: timed blocks (interleaved) ...
    timing_block_seconds: float = 0.1             # ... of at least this long each
    render: bool = True
    seed: int = 0

    @classmethod
    def quick(cls, **changes) -> "SoftRobotCase":
        """A coarse mesh (9,414 dofs), short test and control windows (tests): about a minute on 2 cores.

        The training runs keep their default length: with 4 s + 2 s of training on this mesh, L-OpInf
        at r = 6-10 was off by 0.2-0.8 (a near-zero eigenvalue of K^), with 10 s + 5 s by 5e-4.
        """
        settings = dict(mesh_size=0.09, test_window=1.5, ranks=(2, 4, 6, 10), era_samples=101, extension=5.0,
                        control_window=0.8, timing_repeats=3, timing_block_seconds=0.02)
        return cls(**(settings | changes))

    @classmethod
    def full(cls, **changes) -> "SoftRobotCase":
        """Every model as a controller at r = 10 and r = 20."""
        controllers = tuple((m, r) for r in (10, 20) for m in ("lopinf", "galerkin", "dmdc", "era", "okid"))
        return cls(**({"controllers": controllers} | changes))


# -- scene and signals ----------------------------------------------------------------------
def pair_scene(config: SoftRobotCase, scene_path=SCENE) -> Scene:
    """The scene with three inputs, one per chamber pair: ``v_i`` drives the left chamber with
    ``+1e5 v_i`` Pa and the right with ``-1e5 v_i`` (the antagonism ``u_{2i} = -u_{2i+1}``)."""
    scene = Scene.from_toml(scene_path)
    by_name = {i.name: i for i in scene.inputs}
    inputs = []
    for s in range(1, SEGMENTS + 1):
        left, right = by_name[f"chamber_{s}_left"], by_name[f"chamber_{s}_right"]
        right_load = dataclasses.replace(right.load, magnitude=-right.load.magnitude)
        inputs.append(InputConfig(f"chamber_pair_{s}", left.load, left.signal, (right_load,)))
    params = dict(scene.structure.parameters) | {"mesh_size": config.mesh_size}
    return dataclasses.replace(scene, inputs=tuple(inputs), structure=dataclasses.replace(
        scene.structure, parameters=tuple(sorted(params.items()))))


def phased_sines(config: SoftRobotCase, frequencies, lag: float, window: float, dt: float) -> tuple:
    """``v_i(t) = w(t) sum_f a sin(2 pi f t + i lag)``, ``a = amplitude / len(frequencies)`` (peak <= the bound)."""
    a = config.amplitude / len(frequencies)
    return tuple(multisine(a, frequencies, [i * lag] * len(frequencies), window, dt, ramp=config.ramp)
                 for i in range(SEGMENTS))


def random_inputs(config: SoftRobotCase, band, window: float, dt: float, seed: int) -> tuple:
    """Independent band-limited random ``v_i`` with RMS ``amplitude / 3`` (peaks near the bound)."""
    return tuple(band_limited_noise(config.amplitude / 3, band, window, dt, seed=seed * SEGMENTS + i,
                                    ramp=config.ramp) for i in range(SEGMENTS))


def chirps(config: SoftRobotCase, window: float, dt: float) -> tuple:
    """Phased chirps: ``v_i`` sweeps ``chirp_band`` with segment i lagging by 120 degrees."""
    return tuple(chirp(config.amplitude, *config.chirp_band, window, dt, phase=-2 * math.pi * i / 3,
                       ramp=config.ramp) for i in range(SEGMENTS))


def rom_config(config: SoftRobotCase, dt: float) -> RomConfig:
    train = [RunSpec("train_sines", phased_sines(config, config.train_frequencies, -2 * math.pi / 3,
                                                 config.train_window, dt), config.train_window)]
    if config.random_train_window > 0:
        train.append(RunSpec("train_random", random_inputs(config, config.random_band, config.random_train_window,
                                                           dt, config.seed), config.random_train_window))
    w = config.test_window
    test = (RunSpec("test_sines", phased_sines(config, (config.test_frequency,), config.test_phase_lag, w, dt), w),
            RunSpec("test_chirp", chirps(config, w, dt), w),
            RunSpec("test_random", random_inputs(config, config.test_random_band, w, dt, config.seed + 1), w))
    stored = Derivatives("stored")
    learners = tuple(LearnerSpec(m, m, stored) for m in ("galerkin", "lopinf") if m in config.models)
    return RomConfig(train=tuple(train), test=test, learners=learners, basis=BasisSpec(tuple(config.ranks)),
                     extension=config.extension, report=ReportSpec(render=config.render, paraview=False),
                     timing=TimingSpec(config.timing_repeats, config.timing_block_seconds))


# -- control ----------------------------------------------------------------------------------
def control_rows(state, config: SoftRobotCase, models: dict, progress) -> tuple[list[dict], dict]:
    """Closed loops on the FOM (:func:`femrom.study.closed_loop_rows`): each controller model on the
    feasible reference (the FOM's response to the unseen phased sines) and the travelling wave; the
    first controller's wave loop keeps the FOM's displacements for the render. The wave is on the z
    outputs (x outputs zero: they alternate x, z along the centreline), with the inputs' onset."""
    dt = state.scene.time.dt
    n_steps = int(round(config.control_window / dt))
    K = n_steps + 1 + config.horizon
    times = dt * np.arange(K)
    x = state.scene.outputs.lines[0].locations()[:, 0]
    wave = np.zeros((2 * x.size, K))
    wave[1::2] = onset(times, config.ramp)[None, :] * travelling_wave(
        x, times, lambda s: config.wave_tip_amplitude * (s / x[-1]) ** 2, 2 * np.pi / config.wave_length,
        2 * np.pi * config.wave_frequency)
    references = {"feasible": state.runs["test_sines"].outputs[:, :K], "travelling_wave": wave}
    return closed_loop_rows(state.model, dt, models, config.controllers, references, n_steps, horizon=config.horizon,
                            input_bound=config.amplitude, rate_weight=config.rate_weight,
                            measurement_noise=config.measurement_noise, disturbance=config.disturbance,
                            record=(*config.controllers[0], "travelling_wave") if config.controllers else None,
                            progress=progress)


# -- the case ---------------------------------------------------------------------------------
def run(out_dir, config: SoftRobotCase = SoftRobotCase(), *, progress=None, scene_path=SCENE) -> dict:
    """Run the case; return its metrics (also written to ``out_dir/metrics.json``)."""
    out_dir = Path(out_dir)
    say = progress or (lambda message: print(f"soft_robot: {message}", file=sys.stderr, flush=True))
    unknown = [m for m in config.models if m not in MODELS]
    if unknown or "lopinf" not in config.models:
        raise FemromValueError(f"models must include 'lopinf' and be among {', '.join(MODELS)}; got {config.models}")
    bad = [(m, r) for m, r in config.controllers if m not in config.models or r not in config.ranks]
    if bad:
        raise FemromValueError(f"controllers {bad} are not among the compared models {config.models} at r = {config.ranks}")
    scene = pair_scene(config, scene_path)
    needed = config.control_window + config.horizon * scene.time.dt
    if config.controllers and config.test_window < needed - 1e-9:
        raise FemromValueError(f"test_window {config.test_window} s is shorter than control_window + horizon steps "
                         f"({needed:g} s): the feasible reference (the FOM's response on test_sines) needs the "
                         "horizon beyond the loop")
    scene = dataclasses.replace(scene, rom=rom_config(config, scene.time.dt))

    def extend(state):
        metrics, sections = {"case": "soft_robot", "case_config": dataclasses.asdict(config)}, []
        system, dt = state.model.system, scene.time.dt
        tests = {s.name: state.runs[s.name] for s in state.config.test}
        say(f"linear models {', '.join(config.models)} at r = {', '.join(map(str, config.ranks))}")
        tic = time.perf_counter()
        rows, models = linear_model_rows(
            [MODELS[m] for m in config.models], config.ranks, tests, system=system, basis=state.basis,
            product=state.product, data=state.data, markov_samples=config.era_samples, extension=config.extension,
            repeats=config.timing_repeats, min_block_seconds=config.timing_block_seconds, progress=say)
        metrics.update(comparison=rows, linear_models_seconds=time.perf_counter() - tic)
        sections.append(linear_model_section(out_dir, rows, tests, extension=config.extension,
                                             title=f"soft robot: {system.n_dofs} dofs, unseen inputs"))
        tic = time.perf_counter()
        control, results = control_rows(state, config, models, say)
        metrics.update(control_seconds=time.perf_counter() - tic, control=control)
        section, metrics["renders_control"] = closed_loop_section(
            out_dir, control, results, state.model, dt, bound=config.amplitude, horizon=config.horizon,
            shown=(*config.controllers[0], "travelling_wave") if config.controllers else None, render=config.render,
            output=-1, output_label="tail tip z", scale=1e3, unit="mm", input_label="pair inputs v_i")
        sections.append(section)
        return metrics, sections

    from threadpoolctl import threadpool_limits
    # one MKL / BLAS thread: on the shared 2-core machine a PARDISO solve at 9.4e3 dofs took 12 ms on
    # one thread and 61 ms on two under load (the threads wait on each other), the small dense fits alike
    with threadpool_limits(1):
        return run_study(scene, out_dir, extend=extend, progress=say)


def main(argv=None) -> int:
    parser = case_parser("soft_robot", __doc__, quick="coarse mesh, short windows (tests; about a minute)")
    parser.add_argument("--full", action="store_true",
                        help="every model as an MPC controller at r = 10 and 20 (20 closed loops on the FOM)")
    parser.add_argument("--ranks", type=int, nargs="+", help="sizes r (default 2 4 6 10 16 20)")
    parser.add_argument("--no-render", action="store_true", help="skip the PyVista renders")
    args = parser.parse_args(argv)
    changes = {"controllers": SoftRobotCase.full().controllers} if args.full else {}
    changes |= ({"ranks": tuple(args.ranks)} if args.ranks else {}) | ({"render": False} if args.no_render else {})
    config = dataclasses.replace(SoftRobotCase.quick() if args.quick else SoftRobotCase(), **changes)
    with staged_output(args.out) as out:    # the results appear whole, or the old ones stay
        metrics = run(out, config)
    rows = [row for row in metrics["comparison"] if row.get("r") == 10 and "failed" not in row]
    for model in (m for m in config.models if any(row["model"] == m for row in rows)):
        print(f"soft robot r=10 {model}: unseen-input output errors "
              + ", ".join(f"{row['test_output_error']:.2e}" for row in rows if row["model"] == model))
    for row in (row for row in metrics["control"] if "failed" not in row):
        print(f"MPC {row['controller']} r={row['r']} on {row['reference']}: tracking {row['tracking_error']:.3f}, "
              f"QP {row['qp_seconds_per_step'] * 1e3:.1f} ms/step")
    print(f"report: {args.out / 'report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
