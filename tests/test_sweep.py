"""FOM sweeps on Dask: a LocalCluster of 2 workers, one of them killed in the middle of a run."""

import json
import os
import signal
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

from _required import extra
from femrom.scene import Scene, SceneError, build
from femrom.snapshots import SnapshotStore
from femrom.snapshots import run_fom
from femrom.study import run_sweep, sweep_runs

extra("distributed")

DATA = Path(__file__).parent / "data"


def _bracket(t_end) -> dict:
    data = tomllib.loads((DATA / "bracket.toml").read_text())
    data["structure"]["geometry"] = str(DATA / "bracket.geo")
    data["time"]["t_end"] = t_end
    del data["rom"]
    return data


def _scene(t_end=0.02, **sweep) -> Scene:
    data = _bracket(t_end)
    data["sweep"] = {"parameters": {"inputs.0.signal.amplitude": [5.0e4, 1.0e5, 1.5e5],
                                    "material.youngs_modulus": [6.0e10, 7.0e10]}, **sweep}
    return Scene.from_dict(data)


def test_sweep_points_form_a_grid_or_zip():
    runs = sweep_runs(_scene())
    assert [r.name for r in runs] == [f"p{i:03d}" for i in range(6)]
    assert dict(runs[3].values) == {"inputs.0.signal.amplitude": 1.0e5, "material.youngs_modulus": 7.0e10}
    assert runs[3].model_values == (("material.youngs_modulus", 7.0e10),)   # the signal needs no new model
    zipped = _scene(mode="zip", parameters={"inputs.0.signal.amplitude": [1.0, 2.0],
                                            "effects.damping.alpha": [3.0, 4.0]})
    assert [dict(r.values) for r in sweep_runs(zipped)] == [
        {"inputs.0.signal.amplitude": 1.0, "effects.damping.alpha": 3.0},
        {"inputs.0.signal.amplitude": 2.0, "effects.damping.alpha": 4.0}]
    scene = zipped.with_parameters(sweep_runs(zipped)[1].values)
    assert dict(scene.effect("damping").options)["alpha"] == 4.0
    assert dict(scene.inputs[0].signal.parameters)["amplitude"] == 2.0


@pytest.mark.parametrize("sweep, fragment", [
    ({"parameters": {"material.colour": [1.0]}}, "[material] has no number 'colour'"),
    ({"parameters": {"inputs.1.signal.amplitude": [1.0]}}, "the scene has 1 input(s)"),
    ({"parameters": {"inputs.0.signal.width": [-1.0]}}, "width must be positive"),
    ({"parameters": {"effects.gravity.g": [1.0]}}, "the scene lists no effect 'gravity'"),
    ({"parameters": {"structure.mesh_size": [0.01]}}, "unknown path 'structure.mesh_size'"),
    ({"parameters": {"material.density": []}}, "must be a non-empty array of numbers"),
    ({"parameters": {"material.density": [1.0, 2.0], "material.youngs_modulus": [1.0]}, "mode": "zip"},
     "mode 'zip' needs arrays of one length"),
    ({"parameters": {"material.density": [1.0]}, "fields": ["v"]}, "fields must list 'q'"),
])
def test_bad_sweep_is_one_clear_error(sweep, fragment):
    with pytest.raises(SceneError) as info:
        _scene(**sweep)
    assert fragment in str(info.value)


def _reference(t_end, run):
    """The same point run here, sequentially, without Dask, and without the sweep's own
    ``with_parameters``: the point's values written into the scene's dictionary by hand."""
    values = dict(run.values)
    assert set(values) == {"inputs.0.signal.amplitude", "material.youngs_modulus"}
    data = _bracket(t_end)
    data["inputs"][0]["signal"]["amplitude"] = values["inputs.0.signal.amplitude"]
    data["material"]["youngs_modulus"] = values["material.youngs_modulus"]
    scene = Scene.from_dict(data)
    model = build(scene)
    store_path = Path(os.environ.get("TMPDIR", "/tmp")) / f"femrom_sweep_reference_{os.getpid()}.h5"
    store = SnapshotStore.create(store_path, model, fields=("q",), overwrite=True)
    try:
        run_fom(model, tuple(i.signal for i in scene.inputs), name=run.name, store=store)
        return store.read(run.name, "q")
    finally:
        store.close()
        store_path.unlink()


def test_sweep_survives_a_worker_killed_mid_run(tmp_path):
    """2 worker processes; the first ``.partial`` store file names the pid of a worker that
    is writing a run: that worker is killed (SIGKILL). Its run must be redone elsewhere,
    the finished runs kept, and every trajectory equal a sequential run of its point."""
    from distributed import Client, LocalCluster

    scene = _scene(t_end=0.25)     # 2,500 steps: about a second a run, long enough to be caught mid-run
    out = tmp_path / "sweep"
    parts = out / "sweep_parts"
    killed = {}

    def killer():
        deadline = time.time() + 120
        while time.time() < deadline and not killed:
            for path in parts.glob(".*.partial") if parts.is_dir() else ():
                pid = int(path.name.split(".")[-2])
                killed.update(pid=pid, run=path.name.split(".")[1], finished=sorted(
                    p.name for p in parts.glob("p*.h5")))
                os.kill(pid, signal.SIGKILL)
                return
            time.sleep(0.02)

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        thread = threading.Thread(target=killer)
        thread.start()
        summary = run_sweep(scene, out, client=client, keep_parts=True, progress=None)
        thread.join()
    assert killed, "no run was caught in progress"
    with pytest.raises(ProcessLookupError):
        os.kill(killed["pid"], 0)                      # the worker is gone
    by_name = {r["name"]: r for r in summary["runs"]}
    assert len(by_name) == 6 and all(not r.get("skipped") for r in by_name.values())
    assert by_name[killed["run"]]["pid"] != killed["pid"]      # redone by another process
    assert not list(parts.glob(".*.partial"))                  # the killed run's file was removed
    with SnapshotStore.open(out / "sweep.h5") as store:
        assert store.trajectories == tuple(f"p{i:03d}" for i in range(6))
        for run in sweep_runs(scene):
            assert store.is_complete(run.name)
            assert json.loads(store.attrs(run.name)["sweep_values"]) == dict(run.values)
        # the killed one and one that finished before the kill, against sequential runs: equal
        # up to round-off (a worker's BLAS has one thread, this process two; measured 1.1e-11
        # of the peak after 2,500 steps), while a wrong parameter would move them by percents
        for name in {killed["run"], "p000"}:
            run = next(r for r in sweep_runs(scene) if r.name == name)
            Q = store.read(name, "q")
            np.testing.assert_allclose(Q, _reference(0.25, run), rtol=0, atol=1e-9 * np.abs(Q).max())
    saved = json.loads((out / "sweep.json").read_text())
    assert saved["n_runs"] == 6 and saved["ran"] == 6


def test_a_sweep_started_again_runs_only_what_is_missing(tmp_path):
    scene = _scene()
    out = tmp_path / "sweep"
    first = run_sweep(scene, out, n_workers=2, keep_parts=True, progress=None)
    assert first["ran"] == 6
    (out / "sweep_parts" / "p004.h5").unlink()
    messages = []
    second = run_sweep(scene, out, n_workers=1, keep_parts=False, progress=messages.append)
    assert second["ran"] == 1 and [r["name"] for r in second["runs"] if not r.get("skipped")] == ["p004"]
    assert "5 of 6 runs already done" in messages[0]
    assert not (out / "sweep_parts").exists()
    with SnapshotStore.open(out / "sweep.h5") as store:
        assert len(store.trajectories) == 6 and all(store.is_complete(t) for t in store.trajectories)


def test_cli_sweep_and_its_errors(tmp_path):
    text = (DATA / "bracket.toml").read_text().split("\n[rom]\n")[0]
    (tmp_path / "bracket.geo").write_text((DATA / "bracket.geo").read_text())
    (tmp_path / "plain.toml").write_text(text)
    done = subprocess.run([sys.executable, "-m", "femrom", "sweep", str(tmp_path / "plain.toml"), "-o",
                           str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "no [sweep] section" in done.stderr and not (tmp_path / "out").exists()
    (tmp_path / "sweep.toml").write_text(text + '\n[sweep]\nparameters = { "material.density" = [2600.0, 2800.0] }\n')
    done = subprocess.run([sys.executable, "-m", "femrom", "sweep", str(tmp_path / "sweep.toml"), "-o",
                           str(tmp_path / "out"), "--workers", "2"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "2/2 runs done" in done.stderr and "2 runs in" in done.stdout
    nowhere = subprocess.run([sys.executable, "-m", "femrom", "sweep", str(tmp_path / "sweep.toml"), "-o",
                              str(tmp_path / "nowhere"), "--scheduler", "tcp://127.0.0.1:9"],
                             capture_output=True, text=True, timeout=300,   # Dask waits 30 s by default
                             env=dict(os.environ, DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT="3s"))
    lines = nowhere.stderr.strip().splitlines()
    assert nowhere.returncode == 2 and len(lines) == 1 and "Dask scheduler tcp://127.0.0.1:9" in lines[0]
    assert not (tmp_path / "nowhere").exists()
    with SnapshotStore.open(tmp_path / "out" / "sweep.h5") as store:
        assert store.trajectories == ("p000", "p001")
