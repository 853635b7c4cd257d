"""A corpus of hostile inputs: each gets one clear error that names its culprit, or is accepted.

Every entry is something a user can write or pass by mistake: a scene key of the wrong type,
a value out of range, a missing file, data with NaNs, a shape that does not fit. The test
asserts the error's type (a femrom error the command line reports in one line: ``ValueError``
and its subclasses ``SceneError``, ``MeshError``, ``SnapshotStoreError``, or
``FileNotFoundError``) and a fragment of its message that names the key, argument or file and,
where there is one, what is valid. Entries marked ``ACCEPT`` are valid inputs that must run.
"""

from __future__ import annotations

import copy
import tomllib
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.sparse as sp

from femrom.cases import scene_file
from femrom.mesh import MeshError, generate_mesh, load_mesh
from femrom.scene import Scene, SceneError, SecondOrderSystem, build
from femrom.snapshots import SnapshotStore, SnapshotStoreError

BEAM = tomllib.loads(scene_file("beam").read_text())
FISH = tomllib.loads(scene_file("fishtail").read_text())
ACCEPT = None


def _edit(base: dict, path: str, value=None, *, delete: bool = False) -> dict:
    """``base`` with the key at dotted ``path`` set to ``value`` (or removed)."""
    data = copy.deepcopy(base)
    node = data
    keys = path.split(".")
    for key in keys[:-1]:
        node = node.setdefault(key, {})
    if delete:
        node.pop(keys[-1], None)
    else:
        node[keys[-1]] = value
    return data


# -- scene files: parsed (and built where the culprit is only known to the mesh or space) ------
# (id, dotted path, value, build it?, expected message fragment or ACCEPT)
SCENE_CASES = [
    ("name-int", "name", 5, False, "name must be a non-empty string without path separators, got 5"),
    ("name-empty", "name", "", False, "name must be a non-empty string"),
    ("name-path", "name", "../evil", False, "without path separators, got '../evil'"),
    ("unknown-section", "bogus", {}, False, "unknown section 'bogus'; valid sections: name,"),
    ("geometry-unknown", "structure.geometry", "nope", True, "unknown geometry 'nope'; available: beam_line"),
    ("geometry-int", "structure.geometry", 3, False, "[structure] geometry must be a geometry name, got 3"),
    ("element-unknown", "structure.element", "p7", False, "unknown element 'p7'; valid: hermite, p1, p2"),
    ("mesh-size-negative", "structure.parameters.mesh_size", -0.1, True, "length and mesh_size must be positive"),
    ("mesh-size-string", "structure.parameters.mesh_size", "fine", False,
     "[structure.parameters] mesh_size must be a finite number, got 'fine'"),
    ("length-nan", "structure.parameters.length", float("nan"), False,
     "[structure.parameters] length must be a finite number, got nan"),
    ("geometry-parameter-unknown", "structure.parameters.colour", 3.0, True,
     "geometry 'beam_line.geo' has no parameter 'colour'; valid: length, mesh_size"),
    ("parameters-not-table", "structure.parameters", [1, 2], False,
     "[structure] parameters must be a table of numbers, got [1, 2]"),
    ("no-structure", "structure", None, False, "missing section [structure]"),
    ("no-material", "material", None, False, "missing section [material]"),
    ("no-youngs-modulus", "material.youngs_modulus", None, False, "missing key 'youngs_modulus' in [material]"),
    ("material-unknown-key", "material.colour", 1.0, False, "unknown key 'colour' in [material]; valid keys:"),
    ("second-moment-negative", "material.second_moment", -1.0, False,
     "[material] second_moment must be a finite positive number, got -1.0"),
    ("effect-unknown", "effects.magic", {}, False, "unknown effect 'magic'; valid effects: inertia"),
    ("mass-kind-unknown", "effects.inertia", {"mass": "heavy"}, False,
     "[effects.inertia] unknown mass 'heavy'; valid: consistent, lumped"),
    ("effect-not-table", "effects.inertia", 5, False, "[effects.inertia] must be a table, got int"),
    ("effect-option-unknown", "effects.bending", {"stiff": 2}, False, "unknown key 'stiff' in [effects.bending]"),
    ("no-effects", "effects", {}, False, "[effects] must list at least 'inertia' and a stiffness effect"),
    ("boundary-unknown", "boundary.clamped", ["nowhere"], True,
     "[boundary] mesh has no boundary 'nowhere'; available: left, probe, right"),
    ("boundary-string", "boundary.clamped", "left", False, "[boundary] clamped must be a list of names, got 'left'"),
    ("boundary-kind-unknown", "boundary.sliding", ["left"], False,
     "unknown key 'sliding' in [boundary]; valid keys: clamped, pinned"),
    ("initial-kind-unknown", "initial_conditions.kind", "teleport", False,
     "unknown initial condition kind 'teleport'; valid: zero, static_load"),
    ("load-kind-unknown", "initial_conditions.load.kind", "laser", False,
     "unknown load kind in [initial_conditions.load] 'laser'; valid: point_load"),
    ("load-component-unknown", "initial_conditions.load.component", "q", True,
     "[initial_conditions.load] unknown component 'q'; valid: w, slope"),
    ("load-magnitude-string", "initial_conditions.load.magnitude", "ten", False,
     "[initial_conditions.load] magnitude must be a finite number, got 'ten'"),
    ("load-magnitude-inf", "initial_conditions.load.magnitude", float("inf"), False,
     "[initial_conditions.load] magnitude must be a finite number, got inf"),
    ("load-at-unknown", "initial_conditions.load.at", "middle", True,
     "[initial_conditions.load] mesh has no boundary 'middle'"),
    ("load-at-outside", "initial_conditions.load.at", [5.0, 0.0, 0.0], True,
     "[initial_conditions.load] point x = 5.0 lies outside the beam [0.0, 1.0]"),
    ("load-at-strings", "initial_conditions.load.at", ["a", "b"], False,
     "[initial_conditions.load] at must be a finite number, got 'a'"),
    ("load-at-point-1d", "initial_conditions.load.at", [0.5], True, ACCEPT),
    ("mode-index-zero", "initial_conditions", {"kind": "mode", "index": 0}, False,
     "[initial_conditions] index must be a mode number (1-based), got 0"),
    ("mode-index-float", "initial_conditions", {"kind": "mode", "index": 1.5}, False,
     "[initial_conditions] index must be a mode number (1-based), got 1.5"),
    ("mode-amplitude-nan", "initial_conditions", {"kind": "mode", "amplitude": float("nan")}, False,
     "[initial_conditions] amplitude must be a finite number, got nan"),
    ("solver-unknown", "time.solver", "magic", False, "[time] unknown solver 'magic'; valid: auto,"),
    ("t-end-negative", "time.t_end", -1.0, False, "[time] needs 0 < dt <= t_end, got dt=0.0002, t_end=-1.0"),
    ("dt-beyond-window", "time.dt", 5.0, False, "[time] needs 0 < dt <= t_end, got dt=5.0, t_end=2.0"),
    ("time-key-unknown", "time.extra", 1, False, "unknown key 'extra' in [time]; valid keys: t_end, dt"),
    ("spectral-radius-2", "time.spectral_radius", 2.0, False, "[time] spectral_radius must lie in [0, 1], got 2.0"),
    ("integrator-empty", "time.integrator", "", False, "[time] integrator must be a scheme name, got ''"),
    ("probe-component-unknown", "outputs.probes", [{"name": "tip", "at": "right", "component": "z"}], True,
     "[outputs.probes[0] (tip)] unknown component 'z'; valid: w, slope"),
    ("probe-names-repeat", "outputs.probes",
     [{"name": "tip", "at": "right", "component": "w"}, {"name": "tip", "at": "left", "component": "w"}], False,
     "[outputs] output names must be unique, got ['tip', 'tip']"),
    ("probe-name-int", "outputs.probes", [{"name": 7, "at": "right", "component": "w"}], False,
     "[outputs.probes[0]] name must be a non-empty string, got 7"),
    ("probe-unnamed", "outputs.probes", [{"at": "right", "component": "w"}], True, ACCEPT),
    ("probes-string", "outputs.probes", "tip", False, "[outputs.probes[0]] must be a table, got str"),
    ("energy-string", "outputs.energy", "yes", False, "[outputs] energy must be true or false, got 'yes'"),
    ("save-every-zero", "outputs.save_every", 0, False, "[outputs] save_every must be a whole number >= 1, got 0"),
    ("save-every-fraction", "outputs.save_every", 2.5, False,
     "[outputs] save_every must be a whole number >= 1, got 2.5"),
    ("field-unknown", "outputs.fields", ["temperature"], False,
     "unknown output field 'temperature'; valid: displacement, velocity, acceleration"),
    ("fields-string", "outputs.fields", "displacement", False,
     "[outputs] fields must be a list of names, got 'displacement'"),
    ("outputs-key-unknown", "outputs.unknown", 1, False, "unknown key 'unknown' in [outputs]; valid keys: probes"),
    ("sweep-key-unknown", "sweep", {"youngs": [1, 2]}, False, "unknown key 'youngs' in [sweep]; valid keys:"),
    ("sweep-path-unknown", "sweep", {"parameters": {"material.colour": [1.0, 2.0]}}, False,
     "[sweep.parameters] 'material.colour': [material] has no number 'colour'"),
    ("sweep-values-empty", "sweep", {"parameters": {"material.youngs_modulus": []}}, False,
     "'material.youngs_modulus' must be a non-empty array of numbers, got []"),
    ("sweep-value-negative", "sweep", {"parameters": {"material.youngs_modulus": [-1.0]}}, False,
     "'material.youngs_modulus' = -1: material constants must be positive"),
    ("sweep-mode-unknown", "sweep", {"mode": "cartesian", "parameters": {"material.youngs_modulus": [1e6]}},
     False, "[sweep] unknown mode 'cartesian'; valid: grid, zip"),
    ("sweep-zip-lengths", "sweep", {"mode": "zip", "parameters": {"material.youngs_modulus": [1e6, 2e6],
                                                                  "material.density": [1e3]}},
     False, "[sweep] mode 'zip' needs arrays of one length"),
    ("sweep-valid", "sweep", {"parameters": {"material.youngs_modulus": [2.0e11, 2.1e11]}}, False, ACCEPT),
]


@pytest.mark.parametrize("path, value, built, fragment", [c[1:] for c in SCENE_CASES],
                         ids=[c[0] for c in SCENE_CASES])
def test_scene_entries(path, value, built, fragment):
    data = _edit(BEAM, path, value, delete=value is None)
    if fragment is ACCEPT:
        scene = Scene.from_dict(data)
        if built:
            assert build(scene).system.n_dofs > 0
        return
    with pytest.raises((SceneError, MeshError)) as info:
        scene = Scene.from_dict(data)
        if built:
            build(scene)
    assert fragment in str(info.value), str(info.value)
    assert len(str(info.value).splitlines()) == 1


# -- inputs, signals, damping and [rom] on the fishtail's scene (parsed only) -------------------
def _signal(**signal):
    return lambda d: d["inputs"][0].__setitem__("signal", signal)


ROM = {"learners": ["galerkin", "lopinf"], "basis": {"ranks": [2, 4]}, "train": [{"name": "a"}],
       "test": [{"name": "s", "signals": [{"kind": "step", "amplitude": 1.0}]}]}


def _rom(**changes):
    return lambda d: d.__setitem__("rom", {**copy.deepcopy(ROM), **changes})


FISH_CASES = [
    ("signal-amplitude-string", _signal(kind="sigmoid", amplitude="big", midpoint=0.05, width=0.005),
     "inputs[0].signal: amplitude must be a finite number, got 'big'"),
    ("signal-amplitude-nan", _signal(kind="sigmoid", amplitude=float("nan"), midpoint=0.05, width=0.005),
     "inputs[0].signal: amplitude must be a finite number, got nan"),
    ("signal-width-zero", _signal(kind="sigmoid", amplitude=1.0, midpoint=0.05, width=0.0),
     "inputs[0].signal: width must be positive, got 0.0"),
    ("signal-width-string", _signal(kind="sigmoid", amplitude=1.0, midpoint=0.05, width="w"),
     "inputs[0].signal: width must be a finite number, got 'w'"),
    ("signal-kind-missing", _signal(amplitude=1.0),
     "inputs[0].signal: unknown signal kind None; valid: step, sigmoid, sine, impulse, array"),
    ("signal-key-unknown", _signal(kind="step", amplitude=1.0, delay=0.1),
     "inputs[0].signal: unknown key 'delay' for a step signal"),
    ("sine-frequency-inf", _signal(kind="sine", amplitude=1.0, frequency=float("inf")),
     "inputs[0].signal: frequency must be a finite number, got inf"),
    ("sine-frequency-negative", _signal(kind="sine", amplitude=1.0, frequency=-2.0),
     "inputs[0].signal: frequency must be positive (Hz), got -2.0"),
    ("array-times-unsorted", _signal(kind="array", times=[0.0, 0.2, 0.1], values=[0, 1, 2]),
     "array signal needs increasing 'times' and 'values' of the same length >= 2"),
    ("array-lengths-differ", _signal(kind="array", times=[0.0, 0.2], values=[0, 1, 2]),
     "array signal needs increasing 'times' and 'values' of the same length >= 2"),
    ("array-file-missing", _signal(kind="array", file="/nonexistent/u.npz"),
     "cannot read signal file /nonexistent/u.npz"),
    ("impulse-duration-negative", _signal(kind="impulse", amplitude=1.0, duration=-1.0),
     "inputs[0].signal: duration must be positive, got -1.0"),
    ("input-without-load", lambda d: d["inputs"][0].pop("load"), "missing key 'load' in [inputs[0]]"),
    ("input-load-int", lambda d: d["inputs"][0].__setitem__("load", 5), "[inputs[0].load] must be a table, got int"),
    ("input-names-repeat", lambda d: d["inputs"].append(copy.deepcopy(d["inputs"][0])),
     "[[inputs]] names must be unique, got ['pressure', 'pressure']"),
    ("input-key-unknown", lambda d: d["inputs"][0].__setitem__("gain", 2),
     "unknown key 'gain' in [inputs[0]]; valid keys: name, load, signal"),
    ("inputs-without-actuation", lambda d: d["effects"].pop("actuation"),
     "the scene lists [[inputs]] but not the 'actuation' effect"),
    ("damping-kind-unknown", lambda d: d["effects"].__setitem__("damping", {"kind": "viscous"}),
     "[effects.damping] unknown kind 'viscous'; valid: rayleigh"),
    ("potential-kind-unknown", lambda d: d["effects"].__setitem__("nonlinear_potential", {"kind": "magic"}),
     "[effects.nonlinear_potential] unknown kind 'magic'; valid: sine_gordon, quartic"),
    ("rom-rank-zero", _rom(basis={"ranks": [0, 2]}), "[rom.basis.ranks] must be a positive integer, got 0"),
    ("rom-ranks-string", _rom(basis={"ranks": "4"}),
     "[rom.basis] ranks must be a non-empty array of positive integers, got '4'"),
    ("rom-product-unknown", _rom(basis={"product": "l3", "ranks": [2]}),
     "[rom.basis] unknown product 'l3'; valid: mass, euclidean"),
    ("rom-derivatives-unknown", _rom(derivatives="spline"),
     "[rom.derivatives] unknown derivative kind 'spline'; valid: stored, finite_differences, integrator"),
    ("rom-fd-order-3", _rom(derivatives={"kind": "finite_differences", "order": 3}),
     "[rom.derivatives] finite-difference order must be one of (2, 4, 6), got 3"),
    ("rom-signals-per-input", _rom(test=[{"name": "s", "signals": [{"kind": "step"}, {"kind": "step"}]}]),
     "[rom.test[0]] signals: the scene has 1 input(s), got 2 signal(s)"),
    ("rom-t-end-negative", _rom(test=[{"name": "s", "t_end": -1.0}]),
     "[rom.test[0].t_end] must be a positive number, got -1.0"),
    ("rom-extension-zero", _rom(extension=0), "[rom.extension] must be a positive number, got 0"),
    ("rom-run-names-repeat", _rom(train=[{"name": "a"}, {"name": "a"}]),
     "[rom] run names must be unique across train and test, got ['a', 'a', 's']"),
    ("rom-valid", _rom(), ACCEPT),
]


@pytest.mark.parametrize("change, fragment", [c[1:] for c in FISH_CASES], ids=[c[0] for c in FISH_CASES])
def test_inputs_signals_and_rom_sections(change, fragment):
    data = copy.deepcopy(FISH)
    change(data)
    if fragment is ACCEPT:
        assert Scene.from_dict(data).rom is not None
        return
    with pytest.raises(SceneError) as info:
        Scene.from_dict(data)
    assert fragment in str(info.value), str(info.value)


@pytest.mark.parametrize("options, fragment", [
    ({"kind": "rayleigh", "alpha": -1.0, "beta": 0.0}, "Rayleigh coefficients must be non-negative"),
    ({"kind": "rayleigh", "alpha": "a", "beta": 0.0}, "Rayleigh alpha must be a finite number, got 'a'"),
    ({"kind": "rayleigh", "alpha": 1.0, "beta": float("nan")}, "Rayleigh beta must be a finite number, got nan"),
], ids=["negative", "string", "nan"])
def test_rayleigh_coefficients_are_checked_when_the_damping_is_built(options, fragment):
    data = copy.deepcopy(BEAM)
    data["effects"]["damping"] = options
    with pytest.raises(SceneError, match=r"\[effects.damping\]") as info:
        build(Scene.from_dict(data))
    assert fragment in str(info.value)


# -- the library's entry points: arrays, systems, learners, reduced models ----------------------
def _chain(n=6, **matrices):
    K = sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
    return SecondOrderSystem(**{"mass": sp.identity(n, format="csr"), "stiffness": K, **matrices})


def _data(r=3, k=20, **changes):
    from femrom.inference import SecondOrderData

    rng = np.random.default_rng(1)
    arrays = {"states": rng.standard_normal((r, k)), "velocities": rng.standard_normal((r, k)),
              "accelerations": rng.standard_normal((r, k))}
    return SecondOrderData(**{**arrays, **changes})


def _pod(X, **options):
    from femrom.basis import POD

    return POD(**{"method": "svd", **options}).fit(X)


def _rsvd(X, rank, **options):
    from femrom.linalg import randomized_svd

    return randomized_svd(X, rank, **options)


def _integrate(dt=0.1, n_steps=10, q0=None):
    from femrom.integrators import Newmark, integrate

    system = _chain()
    q0 = np.ones(6) if q0 is None else q0
    return integrate(system, Newmark(), q0, np.zeros(6), dt, n_steps, progress=False)


def _rom_predict(q0, times, **kwargs):
    from femrom.inference import ReducedOperators
    from femrom.rom import SecondOrderROM

    return SecondOrderROM(ReducedOperators.from_matrices(np.diag([1.0, 4.0]))).predict(times, initial=q0, **kwargs)


def _learn(learner, data):
    from femrom import inference

    return getattr(inference, learner)().fit(data)


X = np.random.default_rng(0).standard_normal((12, 20))
API_CASES = [
    ("pod-rank-zero", lambda: _pod(X, rank=0), "rank must be a positive integer, got 0"),
    ("pod-rank-string", lambda: _pod(X, rank="2"), "rank must be a positive integer, got '2'"),
    ("pod-rank-too-large", lambda: _pod(X, rank=50), "rank 50 is not in 1..12"),
    ("pod-energy-nan", lambda: _pod(X, energy=float("nan")), "energy must be a finite number, got nan"),
    ("pod-1d", lambda: _pod(X[:, 0], rank=2), "snapshot matrix must be 2-D (n, K), got shape (12,)"),
    ("pod-inf", lambda: _pod(np.where(X > 2, np.inf, X), rank=2), "POD: snapshot column 19 is not finite"),
    ("pod-method-unknown", lambda: _pod(X, rank=2, method="qr"), "unknown POD method 'qr'; valid: auto, svd"),
    ("rsvd-rank-zero", lambda: _rsvd(X, 0), "rank must be a positive integer, got 0"),
    ("rsvd-nan", lambda: _rsvd(np.where(X > 2, np.nan, X), 2), "a block of snapshot columns is not finite"),
    ("rsvd-oversampling-negative", lambda: _rsvd(X, 2, oversampling=-1), "oversampling must be a non-negative integer, got -1"),
    ("system-mass-not-square", lambda: _chain(mass=sp.csr_matrix(np.ones((6, 7)))),
     "mass has shape (6, 7), expected (6, 6)"),
    ("system-sizes-differ", lambda: _chain(mass=sp.identity(5, format="csr")),
     "stiffness has shape (6, 6), expected (5, 5)"),
    ("system-nan-stiffness", lambda: _chain(stiffness=sp.identity(6, format="csr") * np.nan),
     "stiffness has non-finite entries"),
    ("system-complex-mass", lambda: _chain(mass=sp.identity(6, format="csr") * (1 + 1j)),
     "mass must be a real matrix, got dtype complex128"),
    ("system-inputs-alone", lambda: _chain(inputs=lambda t: np.ones(1)),
     "inputs were given without an input_matrix"),
    ("system-nonlinear-not-a-force", lambda: _chain(nonlinear=np.ones(6)),
     "nonlinear must be a NonlinearForce, a sequence of them, or a reduced force"),
    ("integrate-dt-zero", lambda: _integrate(dt=0.0), "dt must be positive and finite, got 0.0"),
    ("integrate-dt-nan", lambda: _integrate(dt=float("nan")), "dt must be positive and finite, got nan"),
    ("integrate-steps-negative", lambda: _integrate(n_steps=-1), "n_steps must be >= 0, got -1"),
    ("integrate-q0-shape", lambda: _integrate(q0=np.ones(7)), "q0 has shape (7,), expected (6,)"),
    ("integrate-q0-nan", lambda: _integrate(q0=np.full(6, np.nan)), "q0 has non-finite entries"),
    ("data-shapes-differ", lambda: _data(velocities=np.ones((3, 19))), "velocities has shape (3, 19), expected (3, 20)"),
    ("data-nan", lambda: _data(states=np.full((3, 20), np.nan)), "states: snapshot column 0 is not finite"),
    ("data-complex", lambda: _data(accelerations=np.ones((3, 20)) * 1j),
     "accelerations must be real numbers, got dtype complex128"),
    ("data-1d", lambda: _data(states=np.ones(20)), "states must be (r, K), got shape (20,)"),
    ("data-inputs-columns", lambda: _data(inputs=np.ones((1, 19))), "inputs must be (., 20), got shape (1, 19)"),
    ("lopinf-zero-data", lambda: _learn("LagrangianOpInf", _data(states=np.zeros((3, 20)),
                                                                 velocities=np.zeros((3, 20)))),
     "LagrangianOpInf: every snapshot of the data is zero: nothing to learn from"),
    ("rom-q0-size", lambda: _rom_predict(np.zeros(3), np.linspace(0, 1, 11)), "initial q0 has 3 entries: expected r = 2"),
    ("rom-times-decreasing", lambda: _rom_predict(np.zeros(2), np.linspace(1, 0, 11)),
     "times must be uniformly spaced and increasing"),
    ("rom-times-nan", lambda: _rom_predict(np.zeros(2), np.array([0.0, np.nan, 1.0])),
     "times must be uniformly spaced and increasing"),
    ("rom-inputs-without-operator", lambda: _rom_predict(np.zeros(2), np.linspace(0, 1, 11),
                                                         inputs=np.ones((1, 11))),
     "this model has no input operator, but inputs were given"),
]


@pytest.mark.parametrize("call, fragment", [c[1:] for c in API_CASES], ids=[c[0] for c in API_CASES])
def test_library_entry_points(call, fragment):
    with pytest.raises(ValueError) as info:
        call()
    assert fragment in str(info.value), str(info.value)


@pytest.mark.parametrize("learner", ["LagrangianOpInf", "SecondOrderOpInf"])
def test_fewer_snapshots_than_unknowns_is_said(learner):
    data = _data(r=6, k=3)
    with pytest.warns(UserWarning, match=rf"{learner}: 3 snapshots for 6 unknowns per reduced equation"):
        _learn(learner, data)
    with warnings.catch_warnings():  # enough snapshots: no word
        warnings.simplefilter("error")
        _learn(learner, _data(r=3, k=40))


# -- stores and meshes: files that are not what they claim to be ------------------------------
def _store(tmp_path, name="e.h5", **options):
    return SnapshotStore.create(tmp_path / name, _chain(), **options)


def _cube_surface(path: Path) -> Path:
    """The 12 triangles of a unit cube's surface: a solid meshed without its volume."""
    import meshio

    points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    triangles = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
                          [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    meshio.write(path, meshio.Mesh(points, [("triangle", triangles)]), file_format="gmsh22", binary=False)
    return path


def _write(path: Path, content) -> Path:
    path.write_bytes(content) if isinstance(content, bytes) else path.write_text(content)
    return path


FILE_CASES = [
    ("store-exists", lambda p: (_store(p).close(), _store(p)),
     SnapshotStoreError, "e.h5: file exists (pass overwrite=True to replace it)"),
    ("store-folder-missing", lambda p: _store(p, "nodir/x.h5"),
     SnapshotStoreError, "x.h5: its folder"),
    ("store-is-a-folder", lambda p: SnapshotStore.open(p), SnapshotStoreError, "is a folder, not a store file"),
    ("store-field-unknown", lambda p: _store(p, fields=("q", "w")), ValueError,
     "unknown snapshot field 'w'; valid: q, v, a"),
    ("store-dt-negative", lambda p: _store(p, dt=-1.0), SnapshotStoreError,
     "dt must be a positive finite number, got -1.0"),
    ("store-steps-fraction", lambda p: _store(p, n_steps=2.5), SnapshotStoreError,
     "n_steps must be a whole number >= 0, got 2.5"),
    ("store-not-hdf5", lambda p: SnapshotStore.open(_write(p / "g.h5", "x")), SnapshotStoreError,
     "g.h5: not an HDF5 file"),
    ("store-empty-file", lambda p: SnapshotStore.open(_write(p / "z.h5", b"")), SnapshotStoreError,
     "z.h5: not an HDF5 file"),
    ("store-foreign-hdf5", lambda p: (h5py.File(p / "f.h5", "w").close(), SnapshotStore.open(p / "f.h5")),
     SnapshotStoreError, "f.h5: not a femrom snapshot store"),
    ("store-missing", lambda p: SnapshotStore.open(p / "none.h5"), SnapshotStoreError,
     "snapshot store not found:"),
    ("store-trajectory-unknown", lambda p: (_store(p).close(), SnapshotStore.open(p / "e.h5").read("007", "q")),
     SnapshotStoreError, "no trajectory '007'"),
    ("store-field-not-stored", lambda p: (_store(p).close(), SnapshotStore.open(p / "e.h5").read("000", "w")),
     SnapshotStoreError, "no field 'w'"),
    ("mesh-file-missing", lambda p: load_mesh(p / "nowhere.msh"), FileNotFoundError, "mesh file not found:"),
    ("mesh-file-garbage", lambda p: load_mesh(_write(p / "bad.msh", "garbage")), MeshError,
     "cannot read mesh file"),
    ("mesh-surface-of-a-solid", lambda p: load_mesh(_cube_surface(p / "cube.msh")), MeshError,
     "has surface elements (triangle) only, but its points span 3D: a solid without volume elements"),
    ("geometry-unknown", lambda p: generate_mesh("spaceship", {}, cache_dir=p), MeshError,
     "unknown geometry 'spaceship'; available:"),
    ("geometry-parameter-nan", lambda p: generate_mesh("beam_line", {"length": float("nan")}, cache_dir=p),
     MeshError, "parameter 'length' of geometry 'beam_line.geo' must be a finite number, got nan"),
]


@pytest.mark.parametrize("call, kind, fragment", [c[1:] for c in FILE_CASES], ids=[c[0] for c in FILE_CASES])
def test_files_that_are_not_what_they_claim(tmp_path, call, kind, fragment):
    with pytest.raises(kind) as info:
        call(tmp_path)
    assert fragment in str(info.value), str(info.value)
    assert not list(tmp_path.glob(".*creating*"))  # nothing half-made left behind
