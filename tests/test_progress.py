"""Progress reports: steps / rate / time left, redrawn on a terminal, a line every 30 s in a log."""

import io
import re
import types

import numpy as np
import pytest
import scipy.sparse as sp

from femrom.cases import scene_file
from femrom import _progress
from femrom._progress import Progress, Stage, Steps


class FakeTTY(io.StringIO):
    """A text stream that says it is a terminal."""

    def isatty(self):
        return True


class FakeClock:
    """``perf_counter`` that advances only when told: no real time in the assertions."""

    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


@pytest.fixture
def clock(monkeypatch):
    fake = FakeClock()
    monkeypatch.setattr(_progress, "time", types.SimpleNamespace(perf_counter=fake))
    return fake


@pytest.fixture
def terminal(monkeypatch):
    """An interactive session: CI and FEMROM_NO_PROGRESS unset."""
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.delenv("FEMROM_NO_PROGRESS", raising=False)


def run_bar(stream, clock, seconds_per_step=0.5, steps=20, stop_after=None):
    bar = Progress(steps, "Newmark", stream=stream, min_interval=0.0)
    for _ in range(stop_after or steps):
        clock.now += seconds_per_step
        bar.update()
    return bar


def test_fake_terminal_shows_steps_rate_and_time_left(terminal, clock):
    stream = FakeTTY()
    bar = run_bar(stream, clock, seconds_per_step=0.5, stop_after=5)
    # 5 of 20 steps in 2.5 s: 2 steps/s, 15 steps left = 7.5 s, rounded to 0:08
    assert stream.getvalue().endswith("\rNewmark: 5/20  2/s  0:08 left   ")
    for _ in range(15):
        clock.now += 0.5
        bar.update()
    bar.close()
    assert stream.getvalue().rstrip().endswith("Newmark: 20/20 in 0:10")
    assert stream.getvalue().endswith("\n")  # the final line is terminated


def test_slow_steps_show_a_fractional_rate(terminal, clock):
    # 1.6 s per step (the large fishtail FOM): the rate must not round to "1/s" or "0/s"
    stream = FakeTTY()
    run_bar(stream, clock, seconds_per_step=1.6, steps=100, stop_after=10)
    # 10 steps in 16 s: 0.625 steps/s; 90 steps left = 144 s
    assert stream.getvalue().endswith("\rNewmark: 10/100  0.625/s  2:24 left   ")


def test_redraws_are_throttled(terminal, clock):
    stream = FakeTTY()
    bar = Progress(1000, "x", stream=stream, min_interval=1.0)
    for _ in range(999):
        clock.now += 0.01  # 100 steps per redraw interval
        bar.update()
    # 9.99 s of work, one redraw per second (the first at once): 10, +-1 for float rounding
    assert 9 <= stream.getvalue().count("\r") <= 11


def test_opting_out_silences_everything(monkeypatch, clock):
    monkeypatch.setenv("FEMROM_NO_PROGRESS", "1")
    stream = FakeTTY()
    bar = run_bar(stream, clock)
    bar.close()
    with Stage("meshing", stream=stream):
        clock.now += 3.0
    assert stream.getvalue() == ""
    assert bar.done == 20  # counting still happens


@pytest.mark.parametrize("env", [{}, {"CI": "true"}], ids=["not-a-tty", "ci"])
def test_a_log_gets_a_plain_line_every_interval_and_nothing_for_short_work(monkeypatch, clock, env):
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.delenv("FEMROM_NO_PROGRESS", raising=False)
    monkeypatch.delenv("FEMROM_PROGRESS_SECONDS", raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    stream = io.StringIO() if not env else FakeTTY()  # with CI, even a terminal gets log lines
    bar = Progress(20, "Newmark", stream=stream)
    for _ in range(20):  # 20 steps of 0.5 s: 10 s, under one 30 s interval
        clock.now += 0.5
        bar.update()
    bar.close()
    assert stream.getvalue() == ""

    bar = Progress(200, "Newmark", stream=stream)
    for _ in range(200):  # 200 steps of 1 s: lines at 30, 60, ..., 180 s, then the final one
        clock.now += 1.0
        bar.update()
    bar.close()
    lines = stream.getvalue().splitlines()
    assert "\r" not in stream.getvalue() and stream.getvalue().endswith("\n")
    assert lines[0] == "Newmark: 30/200  1/s  2:50 left"
    assert [line.split()[1] for line in lines[:-1]] == [f"{30 * k}/200" for k in range(1, 7)]
    assert lines[-1] == "Newmark: 200/200 in 3:20"

    stream = io.StringIO() if not env else FakeTTY()
    with Stage("meshing", stream=stream):
        clock.now += 0.5  # a short stage says nothing in a log
    with Stage("assembling", stream=stream):
        clock.now += 3.0
    assert stream.getvalue() == "assembling: done in 0:03\n"


def test_open_ended_steps_show_the_step_its_note_and_the_time(monkeypatch, terminal, clock):
    """An iteration of unknown length (the interior point): live, the step reached and
    its note; in a log, a line every 30 s and a final one; short work says nothing."""
    stream = FakeTTY()
    steps = Steps("L-OpInf interior point", stream=stream, min_interval=0.0)
    for k in range(3):
        clock.now += 20.0
        steps.update(f"gap {10.0 ** -k:.0e}")
    assert stream.getvalue().endswith("\rL-OpInf interior point: step 3  gap 1e-02  1:00   ")
    steps.close()
    assert stream.getvalue().endswith("L-OpInf interior point: 3 steps in 1:00  gap 1e-02" + " " * 20 + "\n")

    monkeypatch.delenv("FEMROM_PROGRESS_SECONDS", raising=False)
    stream = io.StringIO()
    with Steps("ipm", stream=stream) as short:
        for _ in range(5):
            clock.now += 1.0
            short.update("gap 1")
    assert stream.getvalue() == ""
    with Steps("ipm", stream=stream) as long:
        for k in range(1, 8):          # 7 steps of 20 s: lines at 20 + 20 > 30 s, ...
            clock.now += 20.0
            long.update(f"step note {k}")
    lines = stream.getvalue().splitlines()
    assert lines[0] == "ipm: step 2  step note 2  0:40"
    assert [line.split()[2] for line in lines[:-1]] == ["2", "4", "6"]
    assert lines[-1] == "ipm: 7 steps in 2:20  step note 7"


def test_the_log_interval_comes_from_the_environment(monkeypatch, clock):
    monkeypatch.setenv("FEMROM_PROGRESS_SECONDS", "5")
    stream = io.StringIO()
    bar = Progress(20, "rSVD", stream=stream)
    for _ in range(20):
        clock.now += 1.0
        bar.update()
    assert len(stream.getvalue().splitlines()) == 4  # at 5, 10, 15, 20 s
    monkeypatch.setenv("FEMROM_PROGRESS_SECONDS", "often")
    with pytest.raises(ValueError, match="FEMROM_PROGRESS_SECONDS must be a number of seconds, got 'often'"):
        Progress(20, "rSVD", stream=stream)


def test_stage_reports_start_end_and_failure(terminal, clock):
    stream = FakeTTY()
    with Stage("meshing beam_solid (mesh_size=0.003)", stream=stream):
        assert stream.getvalue() == "meshing beam_solid (mesh_size=0.003) ..."
        clock.now += 61.0
    assert stream.getvalue().endswith("\rmeshing beam_solid (mesh_size=0.003): done in 1:01\n")
    stream = FakeTTY()
    with pytest.raises(RuntimeError, match="gmsh"):
        with Stage("meshing", stream=stream):
            clock.now += 2.0
            raise RuntimeError("gmsh")
    assert stream.getvalue().endswith("\rmeshing: failed after 0:02\n")


def test_integrator_progress_follows_the_terminal(terminal, monkeypatch):
    from femrom.integrators import Newmark, integrate
    from femrom.scene import SecondOrderSystem

    K = sp.diags([2.0 * np.ones(5), -np.ones(4), -np.ones(4)], [0, 1, -1], format="csr")
    system = SecondOrderSystem(mass=sp.identity(5, format="csr"), stiffness=K)
    q0 = np.linspace(0.0, 1.0, 5)
    stream = FakeTTY()
    monkeypatch.setattr("sys.stderr", stream)
    integrate(system, Newmark(), q0, 0 * q0, 0.1, 30)  # progress=None: decide from stderr
    assert "Newmark" in stream.getvalue() and "30/30 in " in stream.getvalue()
    monkeypatch.setenv("CI", "1")
    stream = FakeTTY()
    monkeypatch.setattr("sys.stderr", stream)
    integrate(system, Newmark(), q0, 0 * q0, 0.1, 30)
    assert stream.getvalue() == ""


def test_mesh_generation_reports_its_stage_but_not_a_cache_hit(terminal, monkeypatch, tmp_path):
    from femrom.mesh import generate_mesh

    stream = FakeTTY()
    monkeypatch.setattr("sys.stderr", stream)
    generate_mesh("beam_line", {"length": 2.0, "mesh_size": 0.5}, cache_dir=tmp_path)
    text = stream.getvalue()
    assert text.startswith("meshing beam_line (length=2, mesh_size=0.5) ...")
    assert re.search(r"\): done in \d+:\d\d\n$", text), text
    stream = FakeTTY()
    monkeypatch.setattr("sys.stderr", stream)
    generate_mesh("beam_line", {"length": 2.0, "mesh_size": 0.5}, cache_dir=tmp_path)
    assert stream.getvalue() == ""  # cached: gmsh does not run, nothing to report


def test_scene_assembly_reports_its_stage(terminal, monkeypatch):
    from femrom.scene import Scene, build

    scene = Scene.from_toml(scene_file("beam"))
    stream = FakeTTY()
    monkeypatch.setattr("sys.stderr", stream)
    build(scene)
    lines = [x for x in stream.getvalue().splitlines() if "assembling" in x]
    assert lines and re.search(r"assembling inertia, bending.*: done in \d+:\d\d$", lines[-1]), lines
    monkeypatch.setenv("CI", "1")
    stream = FakeTTY()
    monkeypatch.setattr("sys.stderr", stream)
    build(scene)
    assert "..." not in stream.getvalue() and "\r" not in stream.getvalue()  # a log: no live line
