"""The soft-robotic fishtail: geometry, chamber loads, P1 locking, the pipeline, renders.

The pipeline test runs ``femrom/cases/fishtail.py`` on the ``tiny`` mesh (about 4.8e3
dofs) over a 0.12 s window; the bounds below were measured on that
configuration (see each assertion) and are stated with their margin.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from femrom.fem import Condensation, SolidSpace, average_rows, surface_pressure, surface_traction
from femrom.solvers import make_solver
from femrom.mesh import build_mesh
from femrom.basis import POD
from femrom.inference import reduce_snapshots
from femrom.rom import SecondOrderROM
from femrom.scene import InputConfig, MaterialConfig, SceneError, SignalVector, build
from femrom.study import mass_norm
from femrom.study._metrics import project_run
from femrom.cases import fishtail

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def tiny_model():
    return build(fishtail.load_scene("tiny"))


# -- geometry and loads ----------------------------------------------------------------
def test_geometry_has_the_named_groups_and_closed_chambers(tiny_model):
    mesh = tiny_model.space.mesh
    assert {"clamp", "tip", "chamber_left", "chamber_right", "skin"} <= set(mesh.boundaries)
    assert "body" in mesh.subdomains
    septum = 0.004  # fishtail.geo default
    for name, sign in (("chamber_left", 1), ("chamber_right", -1)):
        facets = mesh.boundaries[name]
        y = mesh.p[1, mesh.facets[:, facets]]
        assert np.all(sign * y >= 0.5 * septum - 1e-9), name  # each chamber on its own side
        # a uniform pressure on a closed cavity has no resultant: sum_I f_I = -p \oint n ds = 0
        f = surface_pressure(tiny_model.space.basis, name, 1.0)
        resultant = np.array([f[c::3].sum() for c in range(3)])
        assert np.max(np.abs(resultant)) < 1e-12 * np.abs(f).sum()
    x = mesh.p[0, mesh.facets[:, mesh.boundaries["clamp"]]]
    assert np.allclose(x, 0.0)


def test_one_input_drives_both_chambers_with_opposite_signs(tiny_model):
    space, cond = tiny_model.space, tiny_model.system.condensation
    left = cond.vector(surface_pressure(space.basis, "chamber_left", 1.0))
    right = cond.vector(surface_pressure(space.basis, "chamber_right", 1.0))
    B = np.asarray(tiny_model.system.input_matrix)
    assert B.shape == (tiny_model.system.n_dofs, 1)
    np.testing.assert_allclose(B[:, 0], left - right, rtol=0, atol=1e-15 * np.abs(left).max())
    # the antagonistic pair bends the tail sideways (-y for +p on the left): the tip moves in y
    q = make_solver(tiny_model.system.stiffness).solve(B[:, 0])
    tip = tiny_model.system.output_matrix @ q
    assert tip[1] < 0 and abs(tip[1]) > 20 * max(abs(tip[0]), abs(tip[2]))


def test_two_input_option_gives_one_column_per_chamber(tiny_model):
    scene = fishtail.load_scene("tiny", n_inputs=2)
    model = build(scene)
    B = np.asarray(model.system.input_matrix)
    np.testing.assert_allclose(B[:, 0] - B[:, 1], np.asarray(tiny_model.system.input_matrix)[:, 0],
                               atol=1e-15 * np.abs(B).max())
    u = SignalVector(fishtail.pressure_signals(scene, "step"))
    assert np.allclose(u(1.0), [2.0e4, -2.0e4])
    assert np.allclose(SignalVector(s.signal for s in scene.inputs)(1.0), [2.0e4, -2.0e4])   # the scene's own


def test_step_input_is_seen_at_the_same_steps_by_the_fom_clock_and_the_rom_grid():
    scene = fishtail.load_scene("tiny")
    step = fishtail.pressure_signal(scene, "step")
    dt, t, fom, rom = scene.time.dt, 0.0, [], []
    for k in range(1, scene.time.n_steps + 1):
        t += dt  # the integrators' clock
        fom.append(float(step(t)))
        rom.append(float(step(k * dt)))  # a reduced model's uniform grid
    assert fom == rom
    assert 0 < sum(v > 0 for v in rom) < len(rom)


def test_input_load_arrays_are_checked():
    load = {"kind": "surface_pressure", "at": "chamber_left"}
    signal = {"kind": "step"}
    config = InputConfig.from_dict({"load": [load, dict(load, magnitude=-2.0)], "signal": signal}, 0)
    assert [x.magnitude for x in config.loads] == [1.0, -2.0]
    assert InputConfig.from_dict({"load": load, "signal": signal}, 0).loads == (config.load,)
    with pytest.raises(SceneError, match="empty"):
        InputConfig.from_dict({"load": [], "signal": signal}, 0)
    with pytest.raises(SceneError, match=r"inputs\[0\].load\[1\]"):
        InputConfig.from_dict({"load": [load, dict(load, oops=1)], "signal": signal}, 0)


# -- locking -----------------------------------------------------------------------------
def _cantilever_ratio(mesh, element, nu):
    """Tip deflection of a clamped 0.5 x 0.05 x 0.05 m block under an end shear force,
    over the Timoshenko beam value F L^3 / (3 E I) + F L / (kappa G A), kappa = 5/6."""
    length, width, height = 0.5, 0.05, 0.05
    space = SolidSpace(mesh, element)
    E, F = 1.0e6, 1.0
    K = space.stiffness("elasticity", MaterialConfig(youngs_modulus=E, density=1000.0, poisson_ratio=nu))
    cond = Condensation.from_fixed(space.n_total, space.boundary_dofs("left", clamped=True))
    f = surface_traction(space.basis, "right", [0.0, 0.0, -F / (width * height)])
    q = make_solver(cond.matrix(K)).solve(cond.vector(f))
    deflection = -(cond.columns(average_rows(space.basis, "right", 2)) @ q)[0]
    inertia, area, shear = width * height**3 / 12, width * height, E / (2 * (1 + nu))
    return deflection / (F * length**3 / (3 * E * inertia) + F * length / (5 / 6 * shear * area))


def test_p1_locks_near_incompressibility_and_p2_does_not():
    mesh = build_mesh("beam_solid", {"length": 0.5, "width": 0.05, "height": 0.05, "mesh_size": 0.025})
    p1 = {nu: _cantilever_ratio(mesh, "p1", nu) for nu in (0.3, 0.499)}
    p2 = {nu: _cantilever_ratio(mesh, "p2", nu) for nu in (0.3, 0.499)}
    # P2 on 2 elements through the depth: within 6 % of beam theory at both nu (measured
    # 0.991 and 0.957; at nu -> 0.5 the clamped face also blocks the Poisson contraction
    # at the root, which beam theory ignores: 0.969 on the mesh refined twice).
    for nu, ratio in p2.items():
        assert abs(ratio - 1) < 0.06, (nu, ratio)
    # P1 on the same mesh: already stiff at nu = 0.3 (measured 0.53), and at nu = 0.499
    # it locks: measured 0.078 of the beam deflection, 0.15 of its own nu = 0.3 value.
    assert p1[0.499] < 0.2
    assert p1[0.499] / p1[0.3] < 0.3
    assert p2[0.499] / p2[0.3] > 0.9  # P2 hardly notices nu -> 0.5


# -- the pipeline -------------------------------------------------------------------------
@pytest.fixture(scope="module")
def pipeline(tmp_path_factory):
    out = tmp_path_factory.mktemp("fishtail")
    metrics = fishtail.run(out, quick=True, level="tiny", ranks=(2, 4), ladders=False, render=True,
                           t_end=0.12, extension=20.0, keep_snapshots=True)
    return out, metrics


def _row(metrics, r, learner):
    return next(x for x in metrics["roms"] if x["r"] == r and x["learner"] == learner)


def test_pipeline_writes_its_report(pipeline):
    out, metrics = pipeline
    for name in ("metrics.json", "report.md", "response.png", "rom_error.png", "energy.png",
                 "accuracy_cost.png", "scene.toml", "paraview/fishtail.pvd"):
        assert (out / name).is_file(), name
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["n_dofs"] == metrics["n_dofs"] > 1000
    assert saved["train"] == ["sigmoid"] and saved["test"] == ["step"]
    from femrom.post import render_available

    if render_available()[0]:        # where it cannot draw, the case says why and skips the PNG
        assert (out / "render.png").stat().st_size > 0
        assert metrics["renders"]["render"] == "render.png"
    pvd = (out / "paraview" / "fishtail.pvd").read_text()
    assert pvd.count("<DataSet") == len(list((out / "paraview").glob("fishtail_*.vtu"))) > 5
    assert "| r | learner |" in (out / "report.md").read_text()


def test_snapshots_stream_to_the_store_and_the_factor_is_shared(pipeline):
    from femrom.snapshots import SnapshotStore

    out, metrics = pipeline
    with SnapshotStore.open(out / "snapshots.h5") as store:
        assert set(store.trajectories) == {"sigmoid", "step"} and set(store.fields) >= {"q", "v", "a"}
        steps = metrics["fom"]["sigmoid"]["n_steps"]
        assert store.length("sigmoid") == store.length("step") == steps + 1
        assert store.n_dofs == metrics["n_dofs"]
    # one PARDISO factorisation of the effective matrix for both runs; the mass by Jacobi-CG
    assert metrics["fom"]["sigmoid"]["n_factorizations"] == 1
    assert metrics["fom"]["step"]["n_factorizations"] == 0
    assert metrics["fom"]["sigmoid"]["solver_cache"] == {"hits": 1, "misses": 1}


def test_field_errors_from_reduced_coordinates_equal_the_full_fields(pipeline):
    """The case scores full-field errors without reading the snapshots again (``V^T M V = I``);
    the same error computed the long way, from every stored field, must agree."""
    from femrom.snapshots import SnapshotStore

    out, metrics = pipeline
    model = build(fishtail.load_scene("tiny", quick=True))
    scene = fishtail.with_time(model.scene, t_end=0.12)
    M = model.system.mass
    with SnapshotStore.open(out / "snapshots.h5") as store:
        Q = {k: store.read(k, "q") for k in ("sigmoid", "step")}
    pod = POD(rank=4, product=M, method="svd").fit(Q["sigmoid"])
    V = pod.basis_
    data = reduce_snapshots(V, Q["sigmoid"], scene.time.dt, product=M)
    projection = project_run(V, Q["step"], M)
    rng = np.random.default_rng(4)
    X = projection.coordinates
    q_rom = X + 1e-3 * rng.standard_normal(X.shape) * np.abs(X).max()
    for r in (2, 4):
        fast = projection.field_error(q_rom[:r])
        slow = mass_norm(M, Q["step"] - V[:, :r] @ q_rom[:r]) / mass_norm(M, Q["step"])
        assert fast == pytest.approx(slow, rel=1e-9)   # exact identity; round-off only
    # the projection pass computes the residual directly; POD reports sqrt(1 - retained energy), which
    # cancels: at 2.7e-5 its relative accuracy is ~eps / err^2 = 3e-7 times the sums' round-off
    # (observed difference 1.6e-6); 1e-4 checks the two routes, not the cancellation
    assert data.diagnostics["projection_error"] == pytest.approx(pod.projection_error_, rel=1e-4)
    for r in (2, 4):
        row = _row(metrics, r, "galerkin")
        # the case's Galerkin error from the randomized basis, recomputed here from the LAPACK basis
        # and full fields: equal to 1e-3 relative (the bases agree to ~1e-9, the ROM amplifies little)
        rom = SecondOrderROM.galerkin(model.system, V[:, :r], product=M, mass_orthonormal=True)
        u = SignalVector(fishtail.pressure_signals(scene, "step"))
        times = scene.time.dt * np.arange(Q["step"].shape[1])
        solution = rom.predict(times, u, initial=np.zeros(r))
        slow = mass_norm(M, Q["step"] - V[:, :r] @ solution.q) / mass_norm(M, Q["step"])
        assert row["test_field_error"] == pytest.approx(slow, rel=1e-3), r


def test_pipeline_with_a_subset_of_learners(tmp_path):
    """What the mesh ladder runs (benchmarks/fishtail_ladder.py): no finite-difference learners,
    no reverse study, no renders or ladders; every plot must still be drawn."""
    metrics = fishtail.run(tmp_path, level="tiny", ranks=(2, 3), t_end=0.06, ladders=False, render=False,
                           reverse=False, learners=("galerkin", "lopinf", "opinf"))
    assert {row["learner"] for row in metrics["roms"]} == {"galerkin", "lopinf", "opinf"}
    assert metrics["roms_reverse"] == []
    for name in ("response.png", "rom_error.png", "energy.png", "report.md"):
        assert (tmp_path / name).stat().st_size > 0, name
    assert not (tmp_path / "snapshots.h5").exists()   # deleted unless kept
    with pytest.raises(ValueError, match="learners"):
        fishtail.run(tmp_path, level="tiny", learners=("galerkin", "opinf"))


def test_rom_output_error_on_the_unseen_step_input(pipeline):
    _, metrics = pipeline
    gal, lop = _row(metrics, 4, "galerkin"), _row(metrics, 4, "lopinf")
    # Measured on this configuration at r = 4: Galerkin 1.77e-3, L-OpInf 1.75e-3 (field
    # errors 2.7e-3 and 2.6e-3; training output error 3.6e-5). Bound: about twice the
    # measured value (timing-independent; a different gmsh may move the tiny mesh), and
    # L-OpInf within 25 % of the intrusive ROM in the same basis. (With the step
    # on a grid point, a rounding shift of the input by one step gave 5.7e-2 for every
    # ROM: the check that caught it is the Galerkin ROM's error in its own training basis.)
    assert lop["test_output_error"] < 4e-3
    # measured 0.99 of Galerkin's; 25 % leaves room for a gmsh or BLAS that moves the mesh
    assert lop["test_output_error"] < 1.25 * gal["test_output_error"]
    # it is learned, and it learned the training data far better than it generalises
    assert lop["train_output_error"] < 0.2 * lop["test_output_error"]
    # fewer modes, larger error on the unseen input: r = 2 measured 1.6e-2
    assert _row(metrics, 2, "lopinf")["test_output_error"] > 3 * lop["test_output_error"]


def test_lopinf_operators_keep_their_structure(pipeline):
    _, metrics = pipeline
    for r in (2, 4):
        row = _row(metrics, r, "lopinf")
        assert row["stiffness_symmetric"] and row["stiffness_min_eig"] > 0
        assert row["damping_min_eig"] > -1e-10


def test_lopinf_energy_stays_bounded_over_the_extended_window(pipeline):
    _, metrics = pipeline
    for r in (2, 4):
        for learner in ("lopinf", "lopinf_fd"):
            row = _row(metrics, r, learner)
            # 20 windows under the held step pressure: a damped, forced, stable model
            # settles at its static energy, below the FOM's overshoot peak (measured
            # ratios 0.07-0.6); a model with a negative stiffness or damping eigenvalue
            # grows without bound (plain OpInf from finite differences: 1e285 on the
            # small mesh at r = 8).
            assert np.isfinite(row["test_energy_ratio"]) and row["test_energy_ratio"] < 1.5, (r, learner)


# -- renders -------------------------------------------------------------------------------
def test_render_is_a_non_blank_image_of_the_requested_size(tmp_path, tiny_model):
    from femrom.post import mesh_arrays, render_available, render_grid, vertex_displacements

    ok, reason = render_available()
    if not ok:
        if os.environ.get("FEMROM_REQUIRE_RENDER"):      # set by .ci/run: a missing EGL fails
            pytest.fail(f"FEMROM_REQUIRE_RENDER is set but PyVista cannot render: {reason}")
        pytest.skip(f"PyVista cannot render off-screen here: {reason}")
    import matplotlib.image

    space, cond = tiny_model.space, tiny_model.system.condensation
    points, cells = mesh_arrays(space.mesh)
    q = make_solver(tiny_model.system.stiffness).solve(np.asarray(tiny_model.system.input_matrix)[:, 0])
    u = vertex_displacements(space.basis, cond.expand(q))
    path = render_grid(tmp_path / "r.png", points, cells, [[u, 2 * u]], titles=["a", "b"],
                       window_size=(400, 240))
    image = matplotlib.image.imread(path)
    assert image.shape[:2] == (240, 400)
    gray = image[..., :3].mean(axis=2)
    assert gray.std() > 0.05  # a blank frame has std 0; this one measured 0.36
    # the tail covers a real part of the frame (measured 27 %), and the colour map is
    # used: many distinct colours, not one flat shade
    background = np.isclose(gray, np.median(gray[:5, :5]), atol=0.02)
    assert 0.05 < 1 - background.mean() < 0.95
    colours = np.unique((image[..., :3].reshape(-1, 3) * 255).round(), axis=0)
    assert len(colours) > 50


# -- the main job: README's first command ----------------------------------------------------
def non_finite(value, path=()):
    """Every entry of a metrics tree that is not a finite number: ``(path, value)`` for NaN and
    infinities, whether JSON holds them as numbers or as strings (``write_metrics`` writes
    neither: a quantity without a finite value is ``null``, see :func:`nulls`)."""
    if isinstance(value, dict):
        return [bad for key, item in value.items() for bad in non_finite(item, path + (key,))]
    if isinstance(value, list):
        return [bad for i, item in enumerate(value) for bad in non_finite(item, path + (i,))]
    if isinstance(value, float) and not np.isfinite(value):
        return [(path, value)]
    if isinstance(value, str) and value.strip().lower().lstrip("+-") in ("nan", "inf", "infinity"):
        return [(path, value)]
    return []


def nulls(row: dict, keys=("test_output_error", "test_field_error", "test_energy_ratio",
                            "train_output_error", "train_energy_ratio")) -> list[str]:
    """The error columns of a model's row that hold no finite value (``null`` in metrics.json)."""
    return [key for key in keys if key in row and row[key] is None]


def ratio(value) -> float:
    """An energy ratio as a number: ``null`` (no finite value: a diverged model) is infinite."""
    return float("inf") if value is None else float(value)


def run_main_command(out, *options):
    """``python3 -m femrom run fishtail`` as the README runs it, in a subprocess."""
    done = subprocess.run([sys.executable, "-m", "femrom", "run", "fishtail", "--out", str(out), *options],
                          capture_output=True, text=True, cwd=ROOT, timeout=1800)
    assert done.returncode == 0, done.stderr[-2000:]
    return out, done.stdout, json.loads((out / "metrics.json").read_text())


@pytest.fixture(scope="module")
def light_job(tmp_path_factory):
    """The README's command on a light setting (tiny mesh, half window, r = 2 and 4, no ladders, no
    reverse study): the command line, the streamed snapshots, the report and the renders end to end
    in 17 s on a quiet machine (90 s on a loaded one; the README setting below, 160-180 s, is slow)."""
    return run_main_command(tmp_path_factory.mktemp("light_job"), "--quick", "--level", "tiny", "--ranks", "2", "4",
                            "--no-ladders", "--no-reverse")


def test_the_main_command_runs_end_to_end_on_a_light_setting(light_job):
    out, stdout, metrics = light_job
    assert f"report: {out / 'report.md'}" in stdout       # it says where the report is
    assert metrics["level"] == "tiny" and metrics["quick"] and metrics["ranks"] == [2, 4]
    for name in ("report.md", "response.png", "rom_error.png", "energy.png", "scene.toml", "paraview/fishtail.pvd"):
        assert (out / name).stat().st_size > 0, name
    assert not (out / "snapshots.h5").exists()            # streamed, scored, deleted
    assert non_finite(metrics) == []                      # every model is stable at r = 2, 4 on this window
    rows = {(x["r"], x["learner"]): x for x in metrics["roms"]}
    assert set(rows) == {(r, learner) for r in (2, 4) for learner in metrics["learners"]}
    lop, galerkin = rows[4, "lopinf"], rows[4, "galerkin"]
    # measured (tiny mesh, 0.12 s): L-OpInf at r = 4 on the unseen step 1.63e-3 in the output, 2.48e-3 in
    # the field, Galerkin 1.68e-3 and 2.58e-3, r = 2 about 1.5e-2: 3x the measured value leaves room for
    # another gmsh or BLAS, not for a model that stops following the step
    assert lop["test_output_error"] < 5e-3 and lop["test_field_error"] < 7.5e-3
    assert lop["test_output_error"] < 2 * galerkin["test_output_error"]
    assert lop["test_output_error"] < 0.3 * rows[2, "lopinf"]["test_output_error"]   # more modes help
    for row in rows.values():   # no model beats the projection of the FOM on its basis (a lower side)
        assert row["test_field_error"] >= 0.99 * row["test_projection_error"] > 0, (row["r"], row["learner"])
    assert 0.1 < lop["test_energy_ratio"] < 1.5               # settles below the FOM's overshoot peak (0.56)


@pytest.fixture(scope="module")
def main_job(tmp_path_factory):
    """``python3 -m femrom run fishtail`` exactly as the README runs it (small level, 2e4 dofs,
    300 steps, ladders and renders on; 70-160 s), in a subprocess: the slow tests below."""
    return run_main_command(tmp_path_factory.mktemp("main_job"))


@pytest.mark.slow
def test_main_job_runs_the_small_fishtail_end_to_end(main_job):
    out, stdout, metrics = main_job
    assert f"report: {out / 'report.md'}" in stdout       # it says where the report is
    assert metrics["level"] == "small" and 1.5e4 < metrics["n_dofs"] < 2.5e4  # "about 2e4"
    for name in ("report.md", "response.png", "rom_error.png", "energy.png", "accuracy_cost.png",
                 "accuracy_cost_dt.png", "accuracy_cost_mesh.png", "scene.toml",
                 "paraview/fishtail.pvd"):
        assert (out / name).stat().st_size > 0, name
    if "render" in metrics["renders"]:
        assert (out / "render.png").stat().st_size > 0
    elif os.environ.get("FEMROM_REQUIRE_RENDER"):
        pytest.fail(f"no render in the main job: {metrics['renders']}")
    assert not (out / "snapshots.h5").exists()            # streamed, scored, deleted
    # Newmark is second order: the dt ladder against dt = 1 ms (measured 1.98)
    assert 1.8 < metrics["time_step_ladder"][0]["observed_order"] < 2.2
    # strict JSON: nothing is NaN or infinite; an error without a finite value is null, and only plain
    # OpInf's unstable models have one, each labelled diverged (docs/cases/fishtail.md)
    assert non_finite(metrics) == []
    for row in metrics["roms"] + metrics["roms_reverse"]:
        if row["learner"] in ("galerkin", "lopinf", "lopinf_fd"):
            assert nulls(row) == [] and "diverged" not in row, (row["r"], row["learner"])
        elif nulls(row):
            assert row["learner"] in ("opinf", "opinf_fd") and "diverged" in row, (row["r"], row["learner"])


@pytest.mark.slow
def test_main_job_learns_from_displacements_alone_every_kth_step(main_job):
    """The report's every-k-th-step rows (femrom.study.subsampled_rows). Measured at r = 12: every
    step, displacements alone 9.7e-5 (the projection floor 9.0e-5), stored q', q'' 7.0e-4, 4th-order
    differences 1.06e-2; at k = 2, 4.0e-2 for all three stepping h = 2 dt (Galerkin too: h limits), 2.8e-3
    from the displacements filled in to dt by splines, stepping dt."""
    _, _, metrics = main_job
    rows = {(x["every"], x["derivatives"]): x for x in metrics["subsampled"]}
    assert {k for k, _ in rows} == {1, 2, 5, 10}
    one = {source: rows[1, source]["test_field_error"] for source in ("integrator", "stored", "fd4")}
    # the bar: within 2x of the stored-derivative model (measured 7x better); above the floor
    assert one["integrator"] < 2 * one["stored"] and one["integrator"] < one["fd4"] / 10
    assert one["integrator"] >= rows[1, "integrator"]["test_projection_error"]
    for k in (2, 5, 10):      # at equal k the displacements alone are never worse than the stored data (+5 %)
        assert rows[k, "integrator"]["test_field_error"] < 1.05 * rows[k, "stored"]["test_field_error"], k
    # filled in to dt and stepping dt (measured at k = 2: 2.8e-3, against 4.0e-2 stepping h = 2 dt)
    assert rows[2, "integrator_dt"]["test_field_error"] < 0.2 * rows[2, "integrator"]["test_field_error"]


@pytest.mark.slow
def test_main_job_lopinf_predicts_the_unseen_step_and_stays_stable(main_job):
    """The seed's claim on femrom's own fishtail: trained on the sigmoid, L-OpInf predicts
    the step. Measured (2026-11-23): output error 2.7e-3, 1.5e-3, 1.4e-3, 5.3e-4 at r = 4, 6,
    8, 12; field error 7.0e-4 at r = 12; Galerkin 2.8e-5 at r = 12."""
    _, _, metrics = main_job
    rows = {(x["r"], x["learner"]): x for x in metrics["roms"]}
    ranks = sorted({r for r, _ in rows})
    lop = {r: rows[r, "lopinf"] for r in ranks}
    # about 3x the measured value: a different gmsh or BLAS moves the mesh and the
    # round-off, not the order of magnitude
    assert lop[12]["test_output_error"] < 1.5e-3 and lop[12]["test_field_error"] < 2e-3
    assert lop[12]["test_output_error"] < 0.5 * lop[4]["test_output_error"]   # more modes help
    for r in ranks:
        for learner in ("lopinf", "lopinf_fd"):
            row = rows[r, learner]
            assert row["stiffness_symmetric"] and row["stiffness_min_eig"] > 0, (r, learner)
            assert row["damping_min_eig"] > -1e-10, (r, learner)
            # 10 windows under the held step: a stable damped model settles below the
            # FOM's overshoot peak or near it (measured 0.10-1.014)
            assert ratio(row["test_energy_ratio"]) < 1.5, (r, learner)
    # what plain OpInf does on the same data, asserted as observed (docs/cases/fishtail.md): a
    # regression pin, not a property of OpInf: one run measured it unstable at r = 8 from the stored
    # derivatives (energy 2e123) and from finite differences at r >= 6; the threshold 1e3 sits far
    # below those and far above the stable models' <= 1.014. If this stops, the page's comparison
    # must be rewritten.
    blowups = [r for r in ranks for learner in ("opinf", "opinf_fd")
               if not ratio(rows[r, learner]["test_energy_ratio"]) < 1e3]
    assert blowups, "plain OpInf stayed stable at every r: update docs/cases/fishtail.md"


@pytest.mark.slow
def test_main_job_reverse_direction(main_job):
    """Trained on the step, tested on the sigmoid (measured: Galerkin 1.3e-6, L-OpInf
    1.1e-4 at r = 12; L-OpInf 4.3e-2 at r = 4, which the page reports as a miss)."""
    _, _, metrics = main_job
    rows = {(x["r"], x["learner"]): x for x in metrics["roms_reverse"]}
    assert rows[12, "galerkin"]["test_output_error"] < 1e-5
    assert rows[12, "lopinf"]["test_output_error"] < 1e-3      # ~10x the measured 1.1e-4
    assert all(np.isfinite(ratio(rows[r, "lopinf"]["test_energy_ratio"])) for r, _ in rows)
