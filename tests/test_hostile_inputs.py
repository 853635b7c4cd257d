"""More of the hostile-input corpus (tests/test_hostile_corpus.py has the first part): the command
line's flags, initial-condition expressions, every field of a snapshot store, integer arguments,
identification data and the MPC's settings. Each entry gets one clear error naming its culprit,
or is a valid input that must be accepted.
"""

from __future__ import annotations

import copy
import re
import tomllib
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest

from femrom import cli
from femrom.cases import scene_file
from femrom.scene import Scene, SceneError, build

BEAM = tomllib.loads(scene_file("beam").read_text())
ACCEPT = None


def _beam(**sections) -> dict:
    data = copy.deepcopy(BEAM)
    data.update(sections)
    return data


def _beam_file(path: Path, *replacements: tuple[str, str]) -> Path:
    """The beam's scene file with each ``(old, new)`` text replaced (each must occur)."""
    text = scene_file("beam").read_text()
    for old, new in replacements:
        assert old in text, old
        text = text.replace(old, new)
    path.write_text(text)
    return path


SHORT = ("t_end = 2.0\ndt = 2.0e-4", "t_end = 2.0e-3\ndt = 2.0e-4")


# -- initial-condition expressions ---------------------------------------------------------------
# (id, displacement expression, message fragment or ACCEPT)
EXPRESSIONS = [
    ("unbounded-power", "9**9**9*x", "overflows"),                  # was an integer of 370 million digits
    ("power-of-power", "(10**10)**(10**10)", "overflows"),
    ("float-overflow", "exp(1000*x+1000)", "is not finite at"),
    ("log-of-negative", "log(x-2)", "is not finite at"),
    ("division-by-zero", "1/x", "is not finite at"),
    ("string", "'a'*10", "'a' is not allowed"),
    ("bytes", "b'a'", "b'a' is not allowed"),
    ("list", "[x]*10**9", "list is not allowed"),
    ("comprehension", "[v for v in x]", "listcomp is not allowed"),
    ("lambda", "(lambda: x)()", "is not allowed"),
    ("attribute", "x.__class__", "attribute is not allowed"),
    ("subscript", "x[0]", "subscript is not allowed"),
    ("dunder-name", "__import__('os')", "unknown name '__import__'"),
    ("unknown-name", "sin(t)", "unknown name 't'"),
    ("unknown-function", "erf(x)", "unknown name 'erf'"),
    ("keyword-argument", "where(x > 0.5, x, y=0)", "call is not allowed"),
    ("syntax", "sin(x", "cannot parse expression"),
    ("empty", "", "cannot parse expression"),
    ("table-value", {"a": 1}, "dict is not allowed"),
    ("list-value", [1, 2], "list is not allowed"),
    ("complex", "1j*x", "1j is not allowed"),
    ("array-truth", "x if x > 0.5 else 0", "cannot be evaluated"),
    ("walrus", "(a := x)", "namedexpr is not allowed"),
    ("valid-number", 1e-3, ACCEPT),
    ("valid-sine", "1e-3*sin(pi*x)", ACCEPT),
    ("valid-where", "where(x > 0.5, 1e-3*(x-0.5), 0)", ACCEPT),
    ("valid-power", "1e-3*x**2", ACCEPT),
    ("valid-comparison-product", "1e-3*(x > 0.5)", ACCEPT),
]


@pytest.mark.parametrize("text, fragment", [e[1:] for e in EXPRESSIONS], ids=[e[0] for e in EXPRESSIONS])
def test_initial_condition_expressions(text, fragment):
    data = _beam(initial_conditions={"kind": "expression", "displacement": text})
    if fragment is ACCEPT:
        model = build(Scene.from_dict(data))
        assert np.all(np.isfinite(model.initial_displacement)) and np.any(model.initial_displacement)
        return
    with pytest.raises(SceneError) as info:
        build(Scene.from_dict(data))
    assert fragment in str(info.value) and str(info.value).startswith("[initial_conditions]"), str(info.value)


@pytest.mark.parametrize("index, fragment", [
    (500, "mode index 500 exceeds the 99 modes computable on this model (100 free dofs)"),
    (100, "mode index 100 exceeds the 99 modes"),
    (99, ACCEPT),
    (1, ACCEPT),
])
def test_mode_index_beyond_the_model(index, fragment):
    data = _beam(initial_conditions={"kind": "mode", "index": index, "amplitude": 1e-3})
    if fragment is ACCEPT:
        assert np.any(build(Scene.from_dict(data)).initial_displacement)
        return
    with pytest.raises(SceneError, match=re.escape(fragment)):
        build(Scene.from_dict(data))


# -- the command line: every subcommand's flags ---------------------------------------------------
def _run_cli(argv, capsys) -> tuple[int, str]:
    try:
        code = cli.main(argv)
    except SystemExit as exc:        # argparse: usage line and error, exit 2
        code = exc.code
    return code, capsys.readouterr().err


CLI_CASES = [
    ("unknown-command", ["explode"], "invalid choice: 'explode'"),
    ("unknown-case", ["run", "nosuchcase"], "unknown case 'nosuchcase'; available: beam"),
    ("case-flag-unknown", ["run", "beam", "--bogus"], "unrecognized arguments: --bogus"),
    ("case-ranks-not-int", ["run", "beam", "--ranks", "two"], "argument --ranks: invalid int value: 'two'"),
    ("case-out-missing-value", ["run", "beam", "-o"], "argument -o/--out: expected one argument"),
    ("fishtail-level-unknown", ["run", "fishtail", "--level", "huge"], "argument --level: invalid choice: 'huge'"),
    ("fishtail-inputs-3", ["run", "fishtail", "--inputs", "3"], "argument --inputs: invalid choice: 3"),
    ("fishtail-train-unknown", ["run", "fishtail", "--train", "ramp"], "argument --train: invalid choice: 'ramp'"),
    ("sine-gordon-ranks-float", ["run", "sine_gordon", "--ranks", "2.5"], "invalid int value: '2.5'"),
    ("prestress-kn-text", ["run", "jointed_beam_prestress", "--normal-stiffness", "hard"],
     "invalid float value: 'hard'"),
    ("scene-missing", ["run", "nowhere.toml"], "nowhere.toml"),
    ("scene-flag-unknown", ["run", "SCENE", "--level", "large"], "unrecognized arguments: --level large"),
    ("info-missing", ["info", "nowhere.toml"], "scene file not found: nowhere.toml"),
    ("info-directory", ["info", "DIR"], "is a directory, not a scene file"),
    ("info-no-argument", ["info"], "the following arguments are required: scene"),
    ("sweep-without-section", ["sweep", "SCENE"], "no [sweep] section"),
    ("sweep-workers-text", ["sweep", "SCENE", "--workers", "two"], "argument --workers: invalid int value: 'two'"),
    ("ingest-missing", ["ingest", "nowhere.pvd"], "nowhere.pvd: series file not found"),
    ("ingest-density-text", ["ingest", "nowhere.pvd", "--density", "heavy"],
     "argument --density: invalid float value: 'heavy'"),
    ("ingest-every-text", ["ingest", "nowhere.pvd", "--every", "2.5"], "argument --every: invalid int value: '2.5'"),
    ("ingest-output-format", ["ingest", "nowhere.pvd", "--output", "tip"], "--output 'tip': expected NAME:X,Y,Z:COMPONENT"),
    ("ingest-output-point", ["ingest", "nowhere.pvd", "--output", "tip:1,2:z"],
     "--output 'tip:1,2:z': expected NAME:X,Y,Z:COMPONENT"),
    ("ingest-length-scale-text", ["ingest", "nowhere.pvd", "--length-scale", "mm"],
     "argument --length-scale: invalid float value: 'mm'"),
]


@pytest.mark.parametrize("argv, fragment", [c[1:] for c in CLI_CASES], ids=[c[0] for c in CLI_CASES])
def test_command_line_flags(tmp_path, capsys, argv, fragment):
    scene = _beam_file(tmp_path / "scene.toml", SHORT)
    argv = [str(scene) if a == "SCENE" else str(tmp_path) if a == "DIR" else a for a in argv]
    code, err = _run_cli(argv, capsys)
    assert code == 2, err
    assert fragment in err, err
    assert "Traceback" not in err


def test_every_case_takes_the_shared_options(capsys):
    for name in cli.available_cases():
        code, _ = _run_cli(["run", name, "--help"], capsys)
        text = capsys.readouterr().out if code is None else ""
        module = cli.load_case(name)
        with pytest.raises(SystemExit) as info:
            module.main(["--help"])
        assert info.value.code == 0
        usage = capsys.readouterr().out
        for option in ("-o OUT", "--quick", "--yes", "--debug"):
            assert option in usage, (name, option, text)


def test_a_flagged_time_step_is_refused_unless_confirmed(tmp_path, capsys):
    # density 1e-30: every step is 1.4e19 radians of the stiffest dof's motion; the run "worked"
    # before and reported an energy of 1e39
    scene = _beam_file(tmp_path / "light.toml", SHORT, ("density = 7850.0 ", "density = 1e-30 "))
    code, err = _run_cli(["run", str(scene), "-o", str(tmp_path / "out")], capsys)
    assert code == 2 and "light.toml: dt = 0.0002 s is 1.4e+19 radians" in err and "pass --yes" in err, err
    assert not (tmp_path / "out").exists()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code, err = _run_cli(["run", str(scene), "-o", str(tmp_path / "out"), "--yes"], capsys)
    assert code == 0 and (tmp_path / "out" / "metrics.json").is_file()


def test_a_newton_failure_is_one_line_and_debug_anywhere_shows_the_traceback(tmp_path, capsys):
    scene = _beam_file(tmp_path / "soft.toml", ("t_end = 2.0\ndt = 2.0e-4", "t_end = 0.1\ndt = 2.0e-2"),
                       ("bending = {}", 'bending = {}\nspring_layer = { at = "right", component = "w", '
                                        "linear = 0.0, cubic = -1e12 }"))
    code, err = _run_cli(["run", str(scene), "-o", str(tmp_path / "out")], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith("femrom: step 1 (t = 0.02) failed: ") and "Newton did not converge" in err, err
    from femrom.integrators import IntegrationError

    with pytest.raises(IntegrationError):
        cli.main(["run", str(scene), "-o", str(tmp_path / "out"), "--debug"])


# -- snapshot stores: every field holds numbers ---------------------------------------------------
def _chain_store(path: Path):
    from femrom.integrators import Newmark, integrate
    from femrom.snapshots import SnapshotStore
    import scipy.sparse as sp
    from femrom.scene import SecondOrderSystem

    K = sp.diags([2.0 * np.ones(4), -np.ones(3), -np.ones(3)], [0, 1, -1], format="csr")
    system = SecondOrderSystem(mass=sp.identity(4, format="csr"), stiffness=K)
    store = SnapshotStore.create(path, system, fields=("q", "v", "a"))
    integrate(system, Newmark(), np.ones(4), np.zeros(4), 0.1, 6, consumers=[store.writer(chunk_steps=3)],
              progress=False)
    store.close()
    return path


def _replace_dataset(path: Path, key: str, values) -> None:
    with h5py.File(path, "r+") as f:
        group = f["trajectories/000"]
        old = group[key]
        shape, chunks = old.shape, old.chunks
        del group[key]
        group.create_dataset(key, data=values(shape), chunks=chunks, maxshape=(None,) * len(shape))


STORE_FIELDS = [
    ("q-bytes", "q", lambda s: np.full(s, b"1.0", dtype="S3"), "dataset /trajectories/000/q holds byte strings"),
    ("v-bytes", "v", lambda s: np.full(s, b"1.0", dtype="S3"), "dataset /trajectories/000/v holds byte strings"),
    ("a-bytes", "a", lambda s: np.full(s, b"1.0", dtype="S3"), "dataset /trajectories/000/a holds byte strings"),
    ("q-complex", "q", lambda s: np.ones(s, dtype=complex), "holds complex numbers"),
    ("q-bool", "q", lambda s: np.ones(s, dtype=bool), "holds booleans"),
    ("q-int", "q", lambda s: np.ones(s, dtype=np.int64), "expected floating-point numbers"),
    ("q-text", "q", lambda s: np.full(s, "1", dtype=h5py.string_dtype()), "holds objects (variable-length strings)"),
    ("t-bytes", "t", lambda s: np.full(s, b"0", dtype="S1"), "dataset /trajectories/000/t holds byte strings"),
    ("step-float", "step", lambda s: np.zeros(s), ACCEPT),          # whole numbers written as floats
    ("step-bytes", "step", lambda s: np.full(s, b"0", dtype="S1"), "step holds byte strings"),
    ("checkpoint-q-bytes", "checkpoint/q", lambda s: np.full(s, b"0", dtype="S1"), "checkpoint/q holds byte strings"),
    ("q-float32", "q", lambda s: np.ones(s, dtype=np.float32), ACCEPT),
]


@pytest.mark.parametrize("key, values, fragment", [c[1:] for c in STORE_FIELDS], ids=[c[0] for c in STORE_FIELDS])
def test_store_fields_hold_numbers(tmp_path, key, values, fragment):
    from femrom.snapshots import SnapshotStore, SnapshotStoreError

    path = _chain_store(tmp_path / "s.h5")
    _replace_dataset(path, key, values)
    if fragment is ACCEPT:
        with SnapshotStore.open(path) as store:
            assert store.read(0, "q").dtype.kind == "f"
        return
    with pytest.raises(SnapshotStoreError) as info:
        SnapshotStore.open(path)
    assert fragment in str(info.value) and "s.h5" in str(info.value), str(info.value)


def test_a_journal_that_is_not_one_is_refused_naming_it(tmp_path):
    from femrom.snapshots import SnapshotStore, SnapshotStoreError

    path = _chain_store(tmp_path / "s.h5")
    (tmp_path / "s.h5.journal").write_bytes(b"not a journal at all, but long enough to hold a header" * 4)
    with pytest.raises(SnapshotStoreError, match="s.h5.journal: not a femrom undo journal"):
        SnapshotStore.open(path)


# -- integer arguments: one rule (an int or numpy integer, never a float or a bool) ----------------
def _rsvd(rank=2, **options):
    from femrom.linalg import randomized_svd

    return randomized_svd(np.random.default_rng(0).standard_normal((30, 12)), rank, **options)


def _streaming(rank=2, **options):
    from femrom.linalg import StreamingSketch

    return StreamingSketch(30, rank, **options)


def _pod(rank):
    from femrom.basis import POD

    return POD(method="svd", rank=rank).fit(np.random.default_rng(0).standard_normal((30, 12)))


INTEGERS = [
    ("rsvd-rank-float", lambda: _rsvd(2.5), "rank must be a positive integer, got 2.5"),
    ("rsvd-rank-whole-float", lambda: _rsvd(2.0), "rank must be a positive integer, got 2.0"),
    ("rsvd-rank-bool", lambda: _rsvd(True), "rank must be a positive integer, got True"),
    ("rsvd-rank-text", lambda: _rsvd("2"), "rank must be a positive integer, got '2'"),
    ("rsvd-rank-negative", lambda: _rsvd(-3), "rank must be a positive integer, got -3"),
    ("rsvd-oversampling-float", lambda: _rsvd(oversampling=2.5), "oversampling must be a non-negative integer, got 2.5"),
    ("rsvd-power-float", lambda: _rsvd(power_iterations=1.5), "power_iterations must be a non-negative integer, got 1.5"),
    ("rsvd-power-negative", lambda: _rsvd(power_iterations=-1), "power_iterations must be a non-negative integer"),
    ("streaming-rank-float", lambda: _streaming(2.5), "rank must be a positive integer, got 2.5"),
    ("streaming-range-float", lambda: _streaming(range_size=10.0), "range_size must be a positive integer, got 10.0"),
    ("streaming-core-float", lambda: _streaming(core_size=30.5), "core_size must be a positive integer, got 30.5"),
    ("pod-rank-float", lambda: _pod(2.5), "rank must be a positive integer, got 2.5"),
    ("pod-rank-bool", lambda: _pod(True), "rank must be a positive integer, got True"),
    ("rsvd-rank-numpy", lambda: _rsvd(np.int64(2)), ACCEPT),
    ("pod-rank-numpy", lambda: _pod(np.int32(2)), ACCEPT),
]


def _refused_or_accepted(call, fragment):
    """``call()`` raises a ValueError containing ``fragment``, or runs when ``fragment`` is ACCEPT."""
    if fragment is ACCEPT:
        return call()
    with pytest.raises(ValueError) as info:
        call()
    assert fragment in str(info.value), str(info.value)


@pytest.mark.parametrize("call, fragment", [c[1:] for c in INTEGERS], ids=[c[0] for c in INTEGERS])
def test_integer_arguments(call, fragment):
    _refused_or_accepted(call, fragment)


# -- identification: Markov-parameter layouts, OKID's assumptions, large Hankel matrices ----------
def _random_system(n=6, m=3, p=4, radius=0.9, seed=11):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    A *= radius / np.max(np.abs(np.linalg.eigvals(A)))
    return A, rng.standard_normal((n, m)), rng.standard_normal((p, n)), rng.standard_normal((p, m))


def _io_data(K=300, feedthrough=True, seed=12):
    from femrom.inference import InputOutputData

    A, B, C, D = _random_system()
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((B.shape[1], K))
    X = np.zeros((A.shape[0], K))
    for k in range(K - 1):
        X[:, k + 1] = A @ X[:, k] + B @ U[:, k]
    return InputOutputData(U, C @ X + (D if feedthrough else 0 * D) @ U, 0.01)


def _markov(array, **options):
    from femrom.inference import MarkovParameters

    return MarkovParameters(array, 0.01, **options)


def _control_layout():
    """Markov parameters of a (p=3, m=2) system in python-control's (p, m, N) layout, N = 201."""
    from femrom.inference import StateSpaceOperators, markov_parameters

    A, B, C, D = _random_system(n=4, m=2, p=3, radius=0.8)
    return np.moveaxis(markov_parameters(StateSpaceOperators(A, B, C, D, 0.01), 201).parameters, 0, -1)


def _okid(**options):
    from femrom.inference import OKID

    data = options.pop("data", None) or _io_data()
    return OKID(6, options.pop("observer_order", 3), **options).fit(data)


IDENTIFICATION = [
    ("markov-control-layout", lambda: _markov(_control_layout()),
     "Markov parameters of shape (3, 2, 201) read as (N, p, m) are 3 samples of a system with 201 inputs"),
    ("markov-layout-unknown", lambda: _markov(np.zeros((5, 2, 2)), layout="mpn"),
     "Markov parameters layout must be 'npm' (N, p, m) or 'pmn'"),
    ("markov-2d", lambda: _markov(np.zeros((5, 2))), "Markov parameters"),
    ("markov-nan", lambda: _markov(np.full((5, 2, 2), np.nan)), "Markov parameters"),
    ("markov-one-sample", lambda: _markov(np.zeros((1, 2, 1))), "must be (N >= 2, p >= 1, m >= 1)"),
    ("okid-hidden-feedthrough", lambda: _okid(feedthrough=False),
     "OKID(feedthrough=False): the outputs respond to the input of the same sample"),
    ("okid-observer-order-float", lambda: _okid(observer_order=3.0), "observer_order must be a positive integer"),
    ("okid-rows-float", lambda: _okid(rows=2.5), "rows must be a positive integer, got 2.5"),
    ("okid-no-feedthrough-when-there-is-none", lambda: _okid(feedthrough=False, data=_io_data(feedthrough=False)),
     ACCEPT),
    ("markov-control-layout-said", lambda: _markov(_control_layout(), layout="pmn"), ACCEPT),
]


@pytest.mark.parametrize("call, fragment", [c[1:] for c in IDENTIFICATION], ids=[c[0] for c in IDENTIFICATION])
def test_identification_inputs(call, fragment):
    _refused_or_accepted(call, fragment)


def test_markov_parameters_in_python_controls_layout_realise_the_system():
    from femrom.inference import ERA

    markov = _markov(_control_layout(), layout="pmn")
    assert markov.parameters.shape == (201, 3, 2)
    operators = ERA(4).fit(markov).operators_
    assert operators.B.shape == (4, 2) and operators.C.shape == (3, 4)   # was B (3, 201) before


def test_an_unstable_observer_recursion_is_said_with_its_reason():
    # an observer whose output-feedback coefficient is 2 I: the system's Markov parameters, recovered
    # through it, double every step and overflow near k = 1024 (before: "Markov parameters is not
    # finite at index (1024, 0, 0)", which did not say why)
    from femrom.inference import markov_from_observer

    data = _io_data(K=50)
    p, m, l = data.n_outputs, data.n_inputs, 1
    coefficients = np.hstack([np.zeros((p, m)), np.ones((p, m)), 2.0 * np.eye(p)])   # [D, Ybar_1^(1), Ybar_1^(2)]
    with pytest.raises(ValueError, match="overflow at k = 10[0-9][0-9] of 1200: the observer is unstable"):
        markov_from_observer(data, coefficients, {"residual": 0.5}, l, 1200, feedthrough=True, at_rest=False)
    assert np.all(np.isfinite(markov_from_observer(data, coefficients, {"residual": 0.5}, l, 500,
                                                   feedthrough=True, at_rest=False).parameters))


def test_a_large_hankel_matrix_is_said_before_its_svd(monkeypatch):
    from femrom.inference import LargeHankelWarning, era_realization, markov_parameters, StateSpaceOperators
    from femrom.inference import _realization

    # the threshold (5e10 flops, several seconds) lowered to this 8000 x 400 matrix's 5.1e9
    monkeypatch.setattr(_realization, "LARGE_SVD_FLOPS", 5e9)

    A, B, C, D = _random_system(n=4, m=2, p=40, radius=0.9)
    markov = markov_parameters(StateSpaceOperators(A, B, C, D, 0.01), 401)
    with pytest.warns(LargeHankelWarning, match=r"the Hankel matrix is 8000 x 400 \(200 block rows x 40 outputs"):
        era_realization(markov, 4, rows=200, columns=200)


# -- the MPC's settings ----------------------------------------------------------------------------
def _mpc(**settings):
    from femrom.control import LinearMPC
    from femrom.rom import DiscreteStateSpace

    A, B, C, D = _random_system(n=4, m=2, p=2, radius=0.9)
    return LinearMPC(DiscreteStateSpace(A, B, C, np.zeros((2, 2)), dt=0.01),
                     **{"horizon": 5, "input_weight": 1.0, **settings})


def _qp_solver(**settings):
    from femrom.control import QPSolver

    return QPSolver(**settings)


MPC_CASES = [
    ("horizon-zero", lambda: _mpc(horizon=0), "horizon must be a positive integer, got 0"),
    ("horizon-float", lambda: _mpc(horizon=2.5), "horizon must be a positive integer, got 2.5"),
    ("on-failure-unknown", lambda: _mpc(on_failure="explode"), "on_failure must be one of shift, hold, raise"),
    ("bound-negative", lambda: _mpc(input_bound=-1.0), "input_bound must be positive"),
    ("bound-nan", lambda: _mpc(input_bound=float("nan")), "input_bound must be positive"),
    ("bound-shape", lambda: _mpc(input_bound=[1.0, 2.0, 3.0]), "input_bound has shape (3,), expected a scalar or (2,)"),
    ("output-weight-negative", lambda: _mpc(output_weight=-1.0), "output_weight is not positive semidefinite"),
    ("output-weight-shape", lambda: _mpc(output_weight=np.ones(3)), "output_weight has 3 diagonal entries, expected 2"),
    ("output-weight-asymmetric", lambda: _mpc(output_weight=[[1.0, 1.0], [0.0, 1.0]]), "output_weight is not symmetric"),
    ("input-weights-zero", lambda: _mpc(input_weight=0.0), "input_weight or input_rate_weight must be positive definite"),
    ("terminal-unknown", lambda: _mpc(input_weight=1.0, terminal_weight="lqr"),
     "terminal_weight must be None, 'dare' or a matrix, got 'lqr'"),
    ("formulation-unknown", lambda: _mpc(input_weight=1.0, formulation="dense"), "dense"),
    ("solver-tolerance-zero", lambda: _qp_solver(tolerance=0.0), "tolerance must be positive, got 0.0"),
    ("solver-tolerance-nan", lambda: _qp_solver(tolerance=float("nan")), "tolerance must be positive, got nan"),
    ("solver-iterations-float", lambda: _qp_solver(max_iterations=2.5), "max_iterations must be a positive integer, got 2.5"),
    ("solver-name-empty", lambda: _qp_solver(name=""), "a QP solver needs a cvxpy solver name, got ''"),
    ("reference-shape", lambda: _mpc(input_weight=1.0).control(np.zeros(4), np.zeros((3, 5))),
     "reference has shape (3, 5), expected (2, 5)"),
    ("reference-nan", lambda: _mpc(input_weight=1.0).control(np.zeros(4), np.full(2, np.nan)),
     "reference has non-finite entries"),
    ("state-size", lambda: _mpc(input_weight=1.0).control(np.zeros(3), np.zeros(2)), "state has 3 entries, expected 4"),
    ("previous-input-size", lambda: _mpc(input_weight=1.0).control(np.zeros(4), np.zeros(2), np.zeros(3)),
     "u_previous has 3 entries, expected 2"),
    ("valid", lambda: _mpc(input_weight=1.0).control(np.zeros(4), np.ones(2)), ACCEPT),
]


@pytest.mark.parametrize("call, fragment", [c[1:] for c in MPC_CASES], ids=[c[0] for c in MPC_CASES])
def test_mpc_settings(call, fragment):
    result = _refused_or_accepted(call, fragment)
    assert fragment is not ACCEPT or np.all(np.isfinite(result))


# -- environment variables -------------------------------------------------------------------------
ENVIRONMENT = [
    ("memory-limit-text", "FEMROM_MEMORY_LIMIT_GB", "abc", "FEMROM_MEMORY_LIMIT_GB must be a number of GB, got 'abc'"),
    ("memory-limit-negative", "FEMROM_MEMORY_LIMIT_GB", "-1", "FEMROM_MEMORY_LIMIT_GB must be positive, got '-1'"),
    ("memory-limit-nan", "FEMROM_MEMORY_LIMIT_GB", "nan", "FEMROM_MEMORY_LIMIT_GB must be positive, got 'nan'"),
    ("progress-seconds-text", "FEMROM_PROGRESS_SECONDS", "often",
     "FEMROM_PROGRESS_SECONDS must be a number of seconds, got 'often'"),
    ("progress-seconds-negative", "FEMROM_PROGRESS_SECONDS", "-5", "FEMROM_PROGRESS_SECONDS must be >= 0, got '-5'"),
    ("cache-is-a-file", "FEMROM_CACHE", "FILE", "cannot be created (FEMROM_CACHE)"),
    ("memory-limit-valid", "FEMROM_MEMORY_LIMIT_GB", "4", ACCEPT),
]


@pytest.mark.parametrize("variable, value, fragment", [c[1:] for c in ENVIRONMENT], ids=[c[0] for c in ENVIRONMENT])
def test_environment_variables(tmp_path, capsys, monkeypatch, variable, value, fragment):
    scene = _beam_file(tmp_path / "scene.toml", SHORT, ("mesh_size = 0.02", "mesh_size = 0.0201"))  # a new mesh
    if value == "FILE":
        value = str(_beam_file(tmp_path / "a_file", SHORT))
    monkeypatch.setenv(variable, value)
    code, err = _run_cli(["run", str(scene), "-o", str(tmp_path / "out")], capsys)
    if fragment is ACCEPT:
        assert code == 0, err
        return
    assert code == 2 and fragment in err and err.count("\n") == 1, err


def test_a_mesh_path_entry_that_is_not_a_folder_is_said(tmp_path, monkeypatch):
    from femrom.mesh import available_geometries

    monkeypatch.setenv("FEMROM_MESH_PATH", str(tmp_path / "nowhere"))
    with pytest.warns(UserWarning, match="FEMROM_MESH_PATH entry .*nowhere is not a folder; it is skipped"):
        assert "beam_line" in available_geometries()


def test_a_case_name_wins_over_a_folder_of_that_name_and_a_path_does_not(tmp_path, capsys, monkeypatch):
    # a case's results folder left in the working directory (femrom run beam -o beam) used to turn
    # the next `femrom run beam` into "beam: is a directory, not a scene file"
    monkeypatch.chdir(tmp_path)
    (tmp_path / "beam").mkdir()
    (tmp_path / "notacase").mkdir()
    code, err = _run_cli(["run", "beam", "--bogus"], capsys)      # reached the case's own parser
    assert code == 2 and "femrom run beam: error: unrecognized arguments: --bogus" in err, err
    code, err = _run_cli(["run", "./beam"], capsys)
    assert code == 2 and "is a directory" in err, err
    code, err = _run_cli(["run", "notacase"], capsys)
    assert code == 2 and "is a directory" in err, err
