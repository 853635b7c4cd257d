"""Hostile and extreme inputs: one clear error naming the culprit, or the correct acceptance.

Each case is what a user can do by mistake or on purpose; the error must name the key,
argument or file, and nothing may be left half-written.
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from femrom.cases import scene_file
from femrom.integrators import Newmark, integrate
from femrom.scene import Scene, SceneError, SecondOrderSystem
from femrom.snapshots import SnapshotStore, SnapshotStoreError

ROOT = Path(__file__).parents[1]


def _chain(n=6) -> SecondOrderSystem:
    K = sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
    return SecondOrderSystem(mass=sp.identity(n, format="csr"), stiffness=K)


# -- stores: two writers in one process ------------------------------------------------------
def test_a_second_store_object_in_this_process_cannot_take_a_writer(tmp_path):
    """Two SnapshotStore objects on one file, both asking for a writer: the second is refused like a
    second process, and the first one's trajectory is intact and readable afterwards."""
    system = _chain()
    path = tmp_path / "s.h5"
    first = SnapshotStore.create(path, system, dt=0.1, n_steps=20)
    writer = first.writer(chunk_steps=4)
    integrate(system, Newmark(), np.ones(6), np.zeros(6), 0.1, 10, consumers=[writer])   # closes it
    writer = first.writer(chunk_steps=4)              # a second trajectory, still open
    second = SnapshotStore.open(path, system=system)  # reading beside a writer is fine (SWMR)
    assert second.trajectories == ("000", "001")
    with pytest.raises(SnapshotStoreError, match=r"s\.h5: is open for writing by another SnapshotStore of "
                                                 r"this process \(trajectory '001'\)"):
        second.writer()
    integrate(system, Newmark(), np.ones(6), np.zeros(6), 0.1, 12, consumers=[writer])
    first.close()
    with SnapshotStore.open(path) as store:
        assert store.trajectories == ("000", "001")
        assert store.read("000", "q").shape == (6, 11) and store.read("001", "q").shape == (6, 13)
    # once the first writer is closed the second object may write
    integrate(system, Newmark(), np.ones(6), np.zeros(6), 0.1, 5, consumers=[second.writer()])
    second.close()
    with SnapshotStore.open(path) as store:
        assert store.trajectories == ("000", "001", "002")


def _store_with_trajectory(path, system, steps=10):
    store = SnapshotStore.create(path, system, dt=0.1, n_steps=20)
    integrate(system, Newmark(), np.ones(6), np.zeros(6), 0.1, steps, consumers=[store.writer(chunk_steps=4)])
    store.close()


def _forged_journal(path, *, old_size=0, pid=2**31 - 5, fingerprint=bytes(16), old=bytes(8)):
    """A journal of a dead process beside ``path``: one record (``old`` at offset 0), old size ``old_size``."""
    import socket
    import struct

    from femrom.snapshots import _journal

    host = socket.gethostname().encode()
    header = _journal._HEADER.pack(_journal.MAGIC, _journal.VERSION, pid, old_size, 0, 0, fingerprint,
                                   len(host)) + host
    record = struct.pack("<QQ", 0, len(old)) + old
    _journal.journal_path(path).write_bytes(header + record)
    return _journal.journal_path(path)


def test_a_forged_journal_changes_nothing_for_a_reader_and_is_discarded_by_a_writer(tmp_path):
    """A journal of a dead process that does not belong to the file (its fingerprint does not match the
    file's bytes with the records written back): a reader reads the store as it is and writes nothing (it
    used to truncate the store to 0 bytes); a writer discards the journal as stale."""
    system = _chain()
    path = tmp_path / "s.h5"
    _store_with_trajectory(path, system)
    original = path.read_bytes()
    journal = _forged_journal(path)
    with SnapshotStore.open(path) as store:
        assert store.read("000", "q").shape == (6, 11)
    assert path.read_bytes() == original and journal.exists()
    store = SnapshotStore.open(path, system=system)
    integrate(system, Newmark(), np.ones(6), np.zeros(6), 0.1, 4, consumers=[store.writer()])
    store.close()
    assert not journal.exists()
    with SnapshotStore.open(path) as store:
        assert store.trajectories == ("000", "001") and store.read("000", "q").shape == (6, 11)


def test_a_journal_left_beside_a_replaced_store_is_stale(tmp_path):
    """A crashed store's journal next to another store copied over it (same path, other content): neither
    the same file nor a copy of the one it protects, so it is not applied."""
    from femrom.snapshots import _journal, recover

    system = _chain()
    path, other = tmp_path / "s.h5", tmp_path / "other.h5"
    _store_with_trajectory(path, system)
    _store_with_trajectory(other, system, steps=14)
    data = path.read_bytes()
    fingerprint = _journal._fingerprint(lambda a, b: data[a:b], len(data))
    _forged_journal(path, old_size=len(data), fingerprint=fingerprint, old=data[:8])   # s.h5's ...
    assert _journal.PendingChange.load(path).belongs()                    # (a copy of it would roll back)
    replacement = other.read_bytes()
    path.write_bytes(replacement)                                         # ... then another store over it
    with SnapshotStore.open(path) as store:
        assert store.read("000", "q").shape == (6, 15)
    assert recover(path) is False and path.read_bytes() == replacement


# -- scene keys: wrong types, non-finite and out-of-range values, valid extremes ------------
def _beam(**material):
    text = scene_file("beam").read_text()
    import tomllib

    data = tomllib.loads(text)
    data["material"] |= material
    return data


@pytest.mark.parametrize("key, value, fragment", [
    ("youngs_modulus", True, "[material] youngs_modulus must be a finite positive number, got True"),
    ("youngs_modulus", "steel", "[material] youngs_modulus must be a finite positive number, got 'steel'"),
    ("youngs_modulus", float("inf"), "[material] youngs_modulus must be a finite positive number, got inf"),
    ("density", float("nan"), "[material] density must be a finite positive number, got nan"),
    ("density", -7850.0, "[material] density must be a finite positive number, got -7850.0"),
    ("area", 0.0, "[material] area must be a finite positive number, got 0.0"),
    ("poisson_ratio", 0.5, "[material] poisson_ratio must lie in (-1, 0.5), got 0.5"),
    ("poisson_ratio", -1.0, "[material] poisson_ratio must lie in (-1, 0.5), got -1.0"),
    ("poisson_ratio", "0.3", "[material] poisson_ratio must lie in (-1, 0.5), got '0.3'"),
])
def test_bad_material_values_are_one_clear_error(key, value, fragment):
    with pytest.raises(SceneError) as info:
        Scene.from_dict(_beam(**{key: value}))
    assert str(info.value) == fragment


@pytest.mark.parametrize("time, fragment", [
    ({"dt": 1e-14, "t_end": 0.01}, "[time] t_end / dt = 1e+12 steps, more than femrom runs in one go (1e+08)"),
    ({"dt": True}, "[time] dt must be a finite number, got True"),
    ({"t_end": float("inf")}, "[time] t_end must be a finite number, got inf"),
    ({"dt": "1e-3"}, "[time] dt must be a finite number, got '1e-3'"),
    ({"dt": 0.0}, "[time] needs 0 < dt <= t_end"),
])
def test_bad_time_windows_are_one_clear_error(time, fragment):
    data = _beam()
    data["time"] |= time
    with pytest.raises(SceneError) as info:
        Scene.from_dict(data)
    assert fragment in str(info.value)


@pytest.mark.parametrize("nu", [0.0, -0.3, 0.49])
def test_valid_poisson_ratios_are_accepted(nu):
    """-1 < nu < 0.5 is the range where the elasticity form is positive definite (auxetic nu < 0 too)."""
    assert Scene.from_dict(_beam(poisson_ratio=nu)).material.poisson_ratio == nu


# -- the CLI: every femrom error is one line and exit 2 (a traceback only with --debug) --------
def _femrom(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "femrom", *args], capture_output=True, text=True,
                          timeout=300, cwd=cwd)


def test_cli_errors_are_one_line_and_debug_shows_the_traceback(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(scene_file("beam").read_text().replace("density = 7850.0", "density = true"))
    for command in (["info", str(bad)], ["run", str(bad), "-o", str(tmp_path / "out")]):
        proc = _femrom(*command)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1, proc.stderr
        assert "density must be a finite positive number, got True" in lines[0] and str(bad) in lines[0]
    proc = _femrom("--debug", "info", str(bad))
    assert proc.returncode != 0 and "Traceback" in proc.stderr and "density must be" in proc.stderr
    missing = _femrom("info", str(tmp_path / "nowhere.toml"))
    assert missing.returncode == 2 and missing.stderr.strip().splitlines() == [
        f"femrom: scene file not found: {tmp_path / 'nowhere.toml'}"]
    not_a_store = tmp_path / "x.h5"
    not_a_store.write_text("not hdf5")
    proc = _femrom("ingest", str(tmp_path / "series.npz"), "--mesh", str(not_a_store))
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1


def test_a_scene_that_is_not_a_text_file_or_not_a_file_is_one_line_naming_it(tmp_path):
    """Random bytes, a directory and an upper-case suffix: each is a scene path (never a case name),
    and what is wrong with it is one line that names it (it was a bare codec error, "[Errno 21] Is a
    directory", and "unknown case 'scene.TOML'")."""
    noise = tmp_path / "noise.toml"
    noise.write_bytes(bytes([0x81, 0xE1, 0x00, 0xFF]) * 50)
    upper = tmp_path / "BEAM.TOML"
    upper.write_text(scene_file("beam").read_text().replace("density = 7850.0", "density = -1.0"))
    for target, fragment in ((noise, f"{noise}: not a text (UTF-8) scene file: byte 0 is 0x81"),
                             (tmp_path, f"{tmp_path}: is a directory, not a scene file"),
                             (upper, f"{upper}: [material] density must be a finite positive number")):
        proc = _femrom("run", str(target), "-o", str(tmp_path / "out"))
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and fragment in lines[0], proc.stderr
    assert not (tmp_path / "out").exists()


# -- reduced models: non-finite initial states -------------------------------------------------
def test_a_nan_initial_state_is_refused_by_name():
    from femrom.inference import ReducedOperators
    from femrom.rom import SecondOrderROM

    rom = SecondOrderROM(ReducedOperators.from_matrices(np.diag([1.0, 4.0])))
    with pytest.raises(ValueError, match=r"q0 is not finite"):
        rom.predict(np.linspace(0, 1, 11), initial=np.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match=r"v0 is not finite"):
        rom.predict(np.linspace(0, 1, 11), initial=(np.zeros(2), np.array([0.0, np.inf])))


# -- results appear whole or not at all -------------------------------------------------------
def test_an_output_path_that_is_a_file_is_refused_before_anything_runs(tmp_path):
    out = tmp_path / "out"
    out.write_text("a file")
    proc = _femrom("run", str(scene_file("beam")), "-o", str(out))
    assert proc.returncode == 2 and proc.stderr.strip().splitlines() == [f"femrom: {out}: exists and is not a folder"]
    assert out.read_text() == "a file"


def test_a_failed_run_keeps_the_previous_results_and_leaves_no_staging(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "metrics.json").write_text("{\"old\": true}")
    bad = tmp_path / "bad.toml"
    bad.write_text(scene_file("beam").read_text().replace('clamped = ["left"]', 'clamped = ["nowhere"]'))
    proc = _femrom("run", str(bad), "-o", str(out))
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "nowhere" in proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json"]
    assert (out / "metrics.json").read_text() == "{\"old\": true}"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml", "out"]       # no staging, no lock left


def test_a_second_run_into_the_same_folder_at_once_is_refused(tmp_path):
    from femrom.post import staged_output

    out = tmp_path / "out"
    with staged_output(out) as staging:          # a run in progress (this process holds the folder)
        (staging / "partial.txt").write_text("x")
        proc = _femrom("run", str(scene_file("beam")), "-o", str(out))
        assert proc.returncode == 2 and proc.stderr.strip().splitlines() == [
            f"femrom: {out}: another run is writing its results there now"]
    assert (out / "partial.txt").read_text() == "x"   # the first run's results, whole


def test_a_rerun_replaces_the_folder_whole(tmp_path):
    from femrom.post import staged_output

    out = tmp_path / "out"
    with staged_output(out) as staging:
        (staging / "old_only.txt").write_text("old")
    with staged_output(out) as staging:
        (staging / "new.txt").write_text("new")
    assert sorted(p.name for p in out.iterdir()) == ["new.txt"]          # no mix of old and new files
    with pytest.raises(RuntimeError, match="disk full"):
        with staged_output(out) as staging:
            (staging / "half.txt").write_text("half")
            raise RuntimeError("disk full")
    assert sorted(p.name for p in out.iterdir()) == ["new.txt"]


# -- physics that refuses nonsense -------------------------------------------------------------
def test_a_static_load_on_an_unsupported_model_is_refused():
    """The cantilever without its clamp: K is singular (rigid-body modes); the static solve used to
    return a tip deflection of -4.75e9 m under 10 N with exit 0."""
    from femrom.scene import build

    data = _beam()
    del data["boundary"]
    with pytest.raises(SceneError, match=r"static_load needs supports: the model has no \[boundary\] conditions"):
        build(Scene.from_dict(data))


def test_a_near_singular_stiffness_is_detected_by_its_condition_estimate():
    """A chain held by a spring of 1e-14 x its own stiffness: exactly solvable, numerically a mechanism
    (condition ~1e16 > 1/(1e4 eps)); held by a spring of 1e-3 it is accepted."""
    from femrom.scene._build import _checked_static

    n = 50
    for ground, refused in ((1e-14, True), (1e-3, False)):
        K = sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="lil")
        K[0, 0] = K[-1, -1] = 1.0
        K[0, 0] += ground
        K = K.tocsc()
        f = np.zeros(n)
        f[-1] = 1.0
        q = sp.linalg.spsolve(K, f)
        if refused:
            with pytest.raises(SceneError, match="stiffness is \\(near\\) singular"):
                _checked_static(K, f, q)
        else:
            np.testing.assert_array_equal(_checked_static(K, f, q), q)


# -- data: complex, bytes, NaN and all-zero snapshots ------------------------------------------
@pytest.mark.parametrize("X, fragment", [
    (np.zeros((12, 6)), "every snapshot is zero"),
    (np.where(np.eye(12, 6) > 0, np.nan, 1.0), "snapshot column 0 is not finite"),
    (np.ones((12, 6)) * (1 + 1j), "snapshots must be real numbers, got dtype complex128"),
    (np.full((12, 6), b"1.0"), "snapshots must be real numbers, got dtype |S3"),
])
def test_pod_refuses_data_it_cannot_decompose(X, fragment):
    from femrom.basis import POD

    with pytest.raises(ValueError, match=fragment.replace("(", "\\(").replace("|", "\\|")):
        POD(rank=2, method="svd").fit(X)


def test_streamed_blocks_with_nan_or_complex_values_are_refused_by_entry():
    from femrom.basis import POD
    from femrom.linalg import as_block_source

    X = np.random.default_rng(0).standard_normal((30, 12))
    X[4, 9] = np.inf
    with pytest.raises(ValueError, match=r"not finite: entry \(4, 1\) of the block is inf"):
        POD(rank=2, method="randomized").fit(as_block_source(lambda: iter([X[:, :8], X[:, 8:]])))
    with pytest.raises(ValueError, match="must hold real numbers, got dtype complex128"):
        POD(rank=2, method="randomized").fit(as_block_source(lambda: iter([X[:, :8] * 1j])))


def test_a_store_refuses_complex_or_non_finite_snapshots(tmp_path):
    from femrom.integrators import StepResult

    system = _chain()
    store = SnapshotStore.create(tmp_path / "s.h5", system, fields=("q", "v"), dt=0.1, n_steps=4)
    writer = store.writer(chunk_steps=2)
    writer(StepResult(0, 0.0, np.ones(6), np.zeros(6), np.zeros(6)))
    with pytest.raises(SnapshotStoreError, match=r"step 1 of trajectory '000' has 'q' with dtype complex128"):
        writer(StepResult(1, 0.1, np.ones(6) * 1j, np.zeros(6), np.zeros(6)))
    with pytest.raises(SnapshotStoreError, match=r"step 1 of trajectory '000' has 'v' with values that are not finite"):
        writer(StepResult(1, 0.1, np.ones(6), np.full(6, np.nan), np.zeros(6)))
    writer(StepResult(1, 0.1, 2 * np.ones(6), np.zeros(6), np.zeros(6)))
    writer.close()
    store.close()
    with SnapshotStore.open(tmp_path / "s.h5") as s:
        np.testing.assert_array_equal(s.read("000", "q"), np.column_stack([np.ones(6), 2 * np.ones(6)]))


def test_a_mesh_size_gmsh_does_not_honour_is_refused():
    """mesh_size = 1e-300 used to mesh at gmsh's default size with exit 0."""
    from femrom.mesh import MeshError, build_mesh

    with pytest.raises(MeshError, match=r"mesh_size = 1e-300 asked for, gmsh made elements of mean edge"):
        build_mesh(ROOT / "tests" / "data" / "bracket.geo", {"mesh_size": 1e-300})
    mesh = build_mesh(ROOT / "tests" / "data" / "bracket.geo", {"mesh_size": 0.02})    # honoured: accepted
    assert mesh.t.shape[1] > 100


def test_a_file_size_limit_while_streaming_keeps_the_committed_snapshots(tmp_path):
    """RLIMIT_FSIZE below what the run needs (a disk that fills): one SnapshotStoreError naming the
    limit, no crash at exit (it was a raw HDF5 RuntimeError, then a segmentation fault), and a store
    that opens afterwards with every committed step equal to an unlimited run's."""
    script = tmp_path / "limited.py"
    script.write_text(f"""
import resource, sys
import numpy as np, scipy.sparse as sp
from femrom.integrators import Newmark, integrate
from femrom.scene import SecondOrderSystem
from femrom.snapshots import SnapshotStore, SnapshotStoreError
n = 2000
K = sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
system = SecondOrderSystem(mass=sp.identity(n, format="csr"), stiffness=K)
for name, limit in (("free", None), ("limited", 8_000_000)):
    store = SnapshotStore.create("{tmp_path}/" + name + ".h5", system, dt=0.01, n_steps=1000)
    if limit:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    try:
        integrate(system, Newmark(), np.sin(np.arange(n)), np.zeros(n), 0.01, 1000,
                  consumers=[store.writer(chunk_steps=50)])
    except SnapshotStoreError as exc:
        print("ERROR", exc)
    store.close()
""")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-500:])
    assert "file size limit 8000000 bytes reached (RLIMIT_FSIZE)" in proc.stdout and "committed steps are kept" \
        in proc.stdout
    with SnapshotStore.open(tmp_path / "limited.h5") as limited, SnapshotStore.open(tmp_path / "free.h5") as free:
        kept = limited.length("000")
        assert 0 < kept < free.length("000") == 1001
        np.testing.assert_array_equal(limited.read("000", "q"), free.read("000", "q", 0, kept))


def test_a_named_case_into_a_folder_that_is_a_file_is_one_line(tmp_path):
    out = tmp_path / "out"
    out.write_text("a file")
    proc = _femrom("run", "nls", "--quick", "--out", str(out))
    assert proc.returncode == 2 and proc.stderr.strip().splitlines() == [f"femrom: {out}: exists and is not a folder"]


# -- numerics: scales double precision cannot carry, steps that resolve nothing ----------------
def test_a_modulus_beyond_double_precision_is_refused_naming_the_material(tmp_path):
    scene = tmp_path / "huge.toml"
    scene.write_text(scene_file("beam").read_text()
                     .replace("youngs_modulus = 2.1e11", "youngs_modulus = 1.0e300"))
    proc = _femrom("run", str(scene), "-o", str(tmp_path / "out"))
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "stiffness matrix's entries reach" in lines[0] and "youngs_modulus = 1e+300" in lines[0]
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_a_step_that_resolves_nothing_warns_before_the_run():
    from femrom.integrators import ConditioningWarning, check_conditioning, simulate
    from femrom.scene import build

    model = build(Scene.from_dict(_beam(density=1e-30)))
    with pytest.warns(ConditioningWarning, match=r"dt = 0.0002 s is .* radians .*check the units of the density"):
        simulate(model, t_end=4e-4, progress=False)
    steel = build(Scene.from_dict(_beam()))
    report = check_conditioning(steel.system, steel.scene.time.dt)  # no warning for steel
    # omega_diag is a Rayleigh quotient: below the dense omega_max (2.235e6 rad/s), within a factor
    # of 3 of it on Hermite elements (measured 7.65e5: ratio 2.92)
    import scipy.linalg as sla

    omega_max = np.sqrt(sla.eigh(steel.system.stiffness.toarray(), steel.system.mass.toarray(),
                                 eigvals_only=True)[-1])
    assert omega_max / 3.0 <= report.omega_diag <= omega_max
    assert 10 < report.omega_dt < 1e3  # measured 153: far below the 1e6 warning threshold


def test_a_full_disk_while_the_cli_writes_results_keeps_the_previous_ones(tmp_path):
    import os
    import resource
    import signal

    env = {**os.environ, "FEMROM_CACHE": str(tmp_path / "cache"), "FEMROM_NO_PROGRESS": "1"}
    out = tmp_path / "out"
    first = subprocess.run([sys.executable, "-m", "femrom", "run", str(scene_file("beam")), "-o", str(out)],
                           capture_output=True, text=True, timeout=300, env=env)
    assert first.returncode == 0, first.stderr
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def full_disk():  # files may not grow past 50 kB: outputs.npz (240 kB) hits it, as on a full disk
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (50_000, 50_000))

    second = subprocess.run([sys.executable, "-m", "femrom", "run", str(scene_file("beam")), "-o", str(out)],
                            capture_output=True, text=True, timeout=300, env=env, preexec_fn=full_disk)
    lines = second.stderr.strip().splitlines()
    assert second.returncode == 2 and len(lines) == 1, second.stderr
    assert lines[0] == f"femrom: {out}: File too large while writing the results; nothing was changed there"
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before   # the previous results, untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache", "out"]  # no staging folder, no lock left


def test_a_run_above_the_step_or_memory_bound_needs_yes(tmp_path, monkeypatch):
    from femrom.cli import check_run_size

    steps = Scene.from_dict(_beam() | {"time": {"t_end": 2.0, "dt": 1.0e-7}})
    with pytest.raises(SceneError, match=r"beam: 2e\+07 steps \(\[time\] t_end / dt\) is more than 1e\+07; pass --yes"):
        check_run_size(steps, 100, confirmed=False)
    check_run_size(steps, 100, confirmed=True)
    data = _beam()
    data["outputs"]["fields"] = ["displacement", "velocity"]
    fields = Scene.from_dict(data)
    monkeypatch.setenv("FEMROM_MEMORY_LIMIT_GB", "0.01")   # 100 dofs x 10001 x 2 x 8 B = 0.016 GB
    with pytest.raises(SceneError, match=r"fields would hold 0.016 GB in memory \(100 dofs x 10001 snapshots x 2 "):
        check_run_size(fields, 100, confirmed=False)
    monkeypatch.setenv("FEMROM_MEMORY_LIMIT_GB", "0.02")
    check_run_size(fields, 100, confirmed=False)
    monkeypatch.setenv("FEMROM_MEMORY_LIMIT_GB", "lots")
    with pytest.raises(ValueError, match="FEMROM_MEMORY_LIMIT_GB must be a number of GB, got 'lots'"):
        check_run_size(fields, 100, confirmed=False)
