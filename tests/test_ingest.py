"""Another solver's displacement series into femrom: read, check, stream into a store, learn, predict.

The foreign data are not femrom's own Newmark runs: the L-bracket of ``tests/data`` on a
coarser mesh (mesh_size 0.016: 750 free dofs, against 1,179 at the scene's 0.012),
integrated by generalized-alpha with spectral radius 0.8 at dt = 5e-5 (half the
scene's step), saved every 2nd step, written as a ParaView ``.pvd`` series (training,
the scene's sigmoid push) and an XDMF file (an unseen, slower push of the other sign),
with the inputs as CSV tables. Displacements only: no velocities, accelerations or matrices.
"""

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

from femrom.basis import POD
from femrom.inference import LagrangianOpInf, alternating_fill, reduce_snapshots
from femrom.integrators import Trajectory, simulate
from femrom.post import mesh_arrays, vertex_displacements, write_vtu_series
from femrom.rom import SecondOrderROM
from femrom.scene import Scene, Signal, build
from femrom.snapshots import IngestError, SnapshotStore, TabulatedInputs, ingest, ingested_model, \
    read_input_table, read_series
from femrom.post import relative_error

DATA = Path(__file__).parent / "data"
EVERY = 2
UNSEEN = {"kind": "sigmoid", "amplitude": -7.0e4, "midpoint": 0.009, "width": 0.001}


def _write_foreign(folder: Path):
    """Run the foreign solver and write its two series and input tables into ``folder``."""
    scene = Scene.from_toml(DATA / "bracket.toml").with_geometry(mesh_size=0.016) \
        .with_time(integrator="generalized_alpha", spectral_radius=0.8, dt=5e-5)
    model = build(scene)
    points, cells = mesh_arrays(model.space.mesh)
    runs = {}
    for name, signal, t_end in (("train", scene.inputs[0].signal, 0.02), ("test", Signal.from_dict(UNSEEN), 0.03)):
        system = dataclasses.replace(model.system, inputs=lambda t, s=signal: np.atleast_1d(s(t)))
        trajectory = Trajectory(fields=("q",))
        simulate(dataclasses.replace(model, system=system), t_end=t_end, consumers=[trajectory])
        U = np.array([vertex_displacements(model.space.basis, model.system.condensation.expand(q))
                      for q in trajectory.q.T])[::EVERY]
        t = trajectory.t[::EVERY]
        table = np.linspace(0.0, t_end, 2001)
        np.savetxt(folder / f"{name}_inputs.csv", np.column_stack([table, [signal(x) for x in table]]),
                   delimiter=",", header="t,push", comments="")
        runs[name] = (t, U)
    write_vtu_series(folder / "train.pvd", points, cells, runs["train"][0], {"displacement": runs["train"][1]})
    cwd = os.getcwd()
    os.chdir(folder)          # meshio's XDMF writer puts its HDF5 file in the working folder
    try:
        with meshio.xdmf.TimeSeriesWriter("test.xdmf") as writer:
            writer.write_points_cells(points, [("tetra", cells)])
            for tk, Uk in zip(*runs["test"]):
                writer.write_data(tk, point_data={"displacement": Uk})
    finally:
        os.chdir(cwd)
    return model, runs, points


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    folder = tmp_path_factory.mktemp("foreign")
    model, runs, points = _write_foreign(folder)
    probe = tuple(points[np.argmax(points[:, 0] + 1e-3 * points[:, 2])])      # a vertex at the arm's end
    series = read_series(folder / "train.pvd")
    ingested = ingested_model(series, density=2700.0, inputs=folder / "train_inputs.csv",
                              outputs=[("end_z", probe, "z")])
    ingest(series, ingested, folder / "train_store.h5")
    unseen = dataclasses.replace(ingested, system=dataclasses.replace(
        ingested.system, inputs=TabulatedInputs(*read_input_table(folder / "test_inputs.csv"))))
    ingest(read_series(folder / "test.xdmf"), unseen, folder / "test_store.h5")
    return folder, model, runs, ingested


def test_the_series_gives_femrom_its_own_model_of_the_data(foreign):
    folder, model, runs, ingested = foreign
    # the clamped foot is the only place where the displacement is zero throughout: 13 nodes x 3
    # components, exactly the foreign model's Dirichlet dofs
    np.testing.assert_array_equal(ingested.fixed, model.system.condensation.fixed)
    # femrom's P1 mass on the series' mesh is the foreign model's (same mesh, same density, P1)
    M = ingested.system.mass
    assert abs(M - model.system.mass).max() < 1e-12 * abs(model.system.mass).max()
    with SnapshotStore.open(folder / "train_store.h5") as store:
        q = store.read("000", "q")
        t = store.times("000")
        np.testing.assert_allclose(t, runs["train"][0], rtol=1e-8)       # the .pvd keeps 9 digits
        # the stored free dofs are the series' displacements, in femrom's dof order
        full = ingested.system.condensation.expand(q[:, -1])
        np.testing.assert_allclose(vertex_displacements(model.space.basis, full), runs["train"][1][-1], rtol=1e-12,
                                   atol=1e-15)
        u = store.read("000", "u")
        assert u.shape == (1, t.size) and u[0, -1] == pytest.approx(1.0e5, rel=1e-3)   # the sigmoid at its top


def test_learning_from_the_foreign_displacements_predicts_its_unseen_trajectory(foreign):
    """L-OpInf from the ingested displacements alone, integrator-consistent differences at the
    snapshot spacing h = 2 dt, predicts the foreign scheme's own trajectory under the unseen push."""
    folder, model, runs, ingested = foreign
    M = ingested.system.mass
    with SnapshotStore.open(folder / "train_store.h5") as train, SnapshotStore.open(folder / "test_store.h5") as test:
        Q, U, Y, t = train.read("000", "q"), train.read("000", "u"), train.read("000", "y"), train.times("000")
        Qt, Ut, Yt, tt = test.read("000", "q"), test.read("000", "u"), test.read("000", "y"), test.times("000")
    h = t[1] - t[0]
    assert h == pytest.approx(EVERY * 5e-5, rel=1e-6)
    basis = POD(rank=8, product=M, method="svd").fit(Q).basis_
    raw = reduce_snapshots(basis, Q, h, product=M, inputs=U, outputs=Y)
    errors = {}
    for label, data in (("integrator", raw.integrator_consistent()), ("fd4", raw.with_finite_differences(4))):
        rom = SecondOrderROM(basis=basis, product=M, learner=LagrangianOpInf(["damping"])).fit(data)
        prediction = rom.predict(tt, Ut, initial=np.zeros(M.shape[0]))
        E = Qt - basis @ prediction.q
        errors[label] = (float(np.sqrt(np.sum(E * (M @ E)) / np.sum(Qt * (M @ Qt)))),
                         relative_error(Yt, prediction.outputs))
    # measured: field error 8.7e-5 (integrator) against 7.6e-4 (4th-order differences), output errors
    # 6.7e-5 and 5.8e-4; the basis' own projection error of the test run is 1.7e-9, so what is left is
    # the time step: the ROM steps with h = 1e-4, the foreign scheme with 5e-5 and its own dissipation.
    # 1e-3 is 10x the measured; the integrator-consistent data must beat the differences by 3x (8.7x)
    assert errors["integrator"][0] < 1e-3 and errors["integrator"][1] < 1e-3
    assert errors["integrator"][0] < errors["fd4"][0] / 3

    # the foreign solver's dt (5e-5) known and the inputs at every dt (the tables): the states between the
    # snapshots filled in and refined with the learner (alternating_fill), the ROM steps dt. Measured 1.7e-5
    # (the spline fill alone 1.65e-5; the same at r = 4, 8, 12): 5x below stepping h; what is left is the
    # foreign scheme's own numerical dissipation, which no Newmark model has. Asserted: 2x below stepping h
    learner = LagrangianOpInf(["damping"])
    alternating_fill(learner, raw, EVERY, inputs=_sampled(folder / "train_inputs.csv", (t.size - 1) * EVERY + 1, h))
    fine_times = np.arange((tt.size - 1) * EVERY + 1) * (h / EVERY)
    prediction = SecondOrderROM(learner.operators_, basis, product=M).predict(fine_times, _sampled(folder / "test_inputs.csv", fine_times.size, h), initial=np.zeros(M.shape[0]))
    E = Qt - basis @ prediction.q[:, ::EVERY]
    refined = float(np.sqrt(np.sum(E * (M @ E)) / np.sum(Qt * (M @ Qt))))
    assert refined < errors["integrator"][0] / 2, (refined, errors)

    # back out: the prediction on the series' mesh with its error field, the outputs as CSV
    from femrom.post import export_prediction

    rom = SecondOrderROM(basis=basis, product=M, learner=LagrangianOpInf(["damping"])).fit(raw.integrator_consistent())
    prediction = rom.predict(tt, Ut, initial=np.zeros(M.shape[0]))
    written = export_prediction(folder / "prediction.pvd", ingested.space, ingested.system.condensation, tt, basis,
                                prediction.q, reference=lambda k: Qt[:, k], outputs=prediction.outputs,
                                output_names=ingested.system.output_names, every=10)
    assert written["written_times"] == 31
    back = read_series(written["pvd"], field="displacement")
    k, t, U = list(back.steps())[7]
    assert t == pytest.approx(tt[70], rel=1e-8)
    expected = ingested.free_values(U)          # the written field, read back into femrom's free dofs
    np.testing.assert_allclose(expected, basis @ prediction.q[:, 70], rtol=1e-12, atol=1e-18)
    error = ingested.free_values(read_series(written["pvd"], field="error").steps().__iter__().__next__()[2])
    np.testing.assert_allclose(error, basis @ prediction.q[:, 0] - Qt[:, 0], atol=1e-18)
    t_csv, y_csv, names = read_input_table(written["csv"])
    assert names == ("end_z",)
    np.testing.assert_allclose(y_csv, prediction.outputs, rtol=1e-12)


def _sampled(table: Path, n: int, h: float) -> np.ndarray:
    """(1, n) the input table at every foreign step ``h / EVERY``."""
    u = TabulatedInputs(*read_input_table(table))
    return np.array([u(x) for x in np.arange(n) * (h / EVERY)]).T


# -- a bad series is one line naming the file and step ----------------------------------------
def _copy_pvd(folder: Path, target: Path, edit=None):
    target.mkdir()
    for file in folder.glob("train*.vtu"):
        (target / file.name).write_bytes(file.read_bytes())
    text = (folder / "train.pvd").read_text()
    (target / "train.pvd").write_text(text if edit is None else edit(text))
    return target / "train.pvd"


def test_a_missing_step_file_names_it(foreign, tmp_path):
    folder = foreign[0]
    pvd = _copy_pvd(folder, tmp_path / "s")
    (tmp_path / "s" / "train_0007.vtu").unlink()
    with pytest.raises(IngestError, match=r"train\.pvd: step 7 file .*train_0007\.vtu is missing"):
        read_series(pvd)


def test_a_nan_step_names_the_file_and_step(foreign, tmp_path):
    folder = foreign[0]
    pvd = _copy_pvd(folder, tmp_path / "s")
    piece = tmp_path / "s" / "train_0005.vtu"
    m = meshio.read(piece)
    m.point_data["displacement"][3, 1] = np.nan
    meshio.write(piece, m)
    with pytest.raises(IngestError, match=r"train_0005\.vtu \(step 5\): field 'displacement' is not finite"):
        for _ in read_series(pvd).steps():
            pass


def test_a_mismatched_mesh_names_the_file(foreign, tmp_path):
    folder = foreign[0]
    pvd = _copy_pvd(folder, tmp_path / "s")
    piece = tmp_path / "s" / "train_0004.vtu"
    m = meshio.read(piece)
    meshio.write(piece, meshio.Mesh(m.points[:-1], [("vertex", np.arange(m.points.shape[0] - 1)[:, None])],
                                    point_data={"displacement": m.point_data["displacement"][:-1]}))
    with pytest.raises(IngestError, match=r"train_0004\.vtu \(step 4\): its mesh differs .*mismatched meshes"):
        for _ in read_series(pvd).steps():
            pass


def test_wrong_units_and_bad_tables_are_refused(foreign, tmp_path):
    folder, _, _, _ = foreign
    series = read_series(folder / "train.pvd")
    # displacements written in micrometres on a mesh in metres: 1e6 x a 0.1 mm push is 100 m
    with pytest.raises(IngestError, match="more than 10x the structure's size .*units"):
        ingested_model(series, density=2700.0, length_scale=1e6)
    short = tmp_path / "short.csv"
    short.write_text("t,push\n0,0\n0.01,1\n")
    with pytest.raises(IngestError, match=r"short\.csv: the input table covers \[0, 0.01\], the series \[0, 0.02\]"):
        ingested_model(series, density=2700.0, inputs=short)
    with pytest.raises(IngestError, match="needs a 't' column"):
        bad = tmp_path / "bad.csv"
        bad.write_text("time,push\n0,0\n1,1\n")
        read_input_table(bad)
    with pytest.raises(IngestError, match="unknown series format '.vtk'"):
        (tmp_path / "x.vtk").write_text("")
        read_series(tmp_path / "x.vtk")
    with pytest.raises(IngestError, match="an array series needs its mesh file"):
        (tmp_path / "x.h5").write_text("")
        read_series(tmp_path / "x.h5")


def test_a_failed_ingest_leaves_no_store(foreign, tmp_path):
    folder, _, _, ingested = foreign
    pvd = _copy_pvd(folder, tmp_path / "s")
    piece = tmp_path / "s" / "train_0009.vtu"
    m = meshio.read(piece)
    m.point_data["displacement"][0, 0] = np.inf
    meshio.write(piece, m)
    with pytest.raises(IngestError, match="step 9"):
        ingest(read_series(pvd), ingested, tmp_path / "out.h5")
    assert not list(tmp_path.glob("*out.h5*"))


def test_a_series_larger_than_memory_streams(tmp_path):
    """An HDF5 array series of 400 MB ingested by a process whose peak RSS may grow by 100 MB at most:
    the series is read one step at a time (a series held in memory would add >= 400 MB)."""
    script = tmp_path / "big.py"
    script.write_text(f'''
import resource, sys
import h5py, meshio, numpy as np
from femrom.snapshots import ingest, ingested_model, read_series
from skfem import MeshTet
cube = MeshTet.init_tensor(*[np.linspace(0, 1, 6)] * 3)
grid = cube.p.T
meshio.write("{tmp_path}/cube.vtu", meshio.Mesh(grid, [("tetra", cube.t.T)]))
K = 400_000_000 // (grid.shape[0] * 3 * 8)
with h5py.File("{tmp_path}/big.h5", "w") as f:
    f["t"] = np.arange(K) * 1e-4
    u = f.create_dataset("u", (K, grid.shape[0], 3), dtype=float, chunks=(1, grid.shape[0], 3))
    for k in range(0, K, 1000):
        block = np.sin(1e-3 * np.arange(k, min(k + 1000, K)))[:, None, None] * grid[None] * 1e-3
        u[k:k + block.shape[0]] = block
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
series = read_series("{tmp_path}/big.h5", mesh="{tmp_path}/cube.vtu")
model = ingested_model(series, fixed=None)
ingest(series, model, "{tmp_path}/store.h5")
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(K, before, after)
''')
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    K, before, after = map(int, proc.stdout.split()[-3:])
    assert K * 216 * 3 * 8 >= 3.9e8
    assert (after - before) * 1024 < 100e6, (before, after)         # ru_maxrss is in KiB on Linux
    with SnapshotStore.open(tmp_path / "store.h5") as store:
        assert store.length("000") == K


def test_the_cli_ingests_a_series_and_says_what_it_holds(foreign, tmp_path):
    folder = foreign[0]
    proc = subprocess.run([sys.executable, "-m", "femrom", "ingest", str(folder / "test.xdmf"), "-o",
                           str(tmp_path / "s.h5"), "--inputs", str(folder / "test_inputs.csv"),
                           "--density", "2700"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "301 snapshots of 750 free dofs (39 fixed, auto)" in proc.stdout, proc.stdout
    with SnapshotStore.open(tmp_path / "s.h5") as store:
        assert store.read("000", "q").shape == (750, 301)
    bad = subprocess.run([sys.executable, "-m", "femrom", "ingest", str(folder / "nothing.pvd")],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and bad.stderr.strip().splitlines() == [
        f"femrom: {folder / 'nothing.pvd'}: series file not found"]
    probe = subprocess.run([sys.executable, "-m", "femrom", "ingest", str(folder / "test.xdmf"), "--output", "tip"],
                           capture_output=True, text=True, timeout=300)
    assert probe.returncode == 2 and "expected NAME:X,Y,Z:COMPONENT" in probe.stderr
