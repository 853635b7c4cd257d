"""The case scripts and the command line, run end to end at small sizes."""

import json

import numpy as np
import pytest

from femrom.cli import available_cases, load_case, main


@pytest.fixture(scope="module")
def beam_metrics(tmp_path_factory):
    out = tmp_path_factory.mktemp("beam")
    return load_case("beam").run(out, quick=True), out


def test_beam_case_writes_its_report(beam_metrics):
    metrics, out = beam_metrics
    for name in ("metrics.json", "report.md", "response.png", "accuracy_cost_dt.png",
                 "accuracy_cost_mesh.png", "scene.toml"):
        assert (out / name).stat().st_size > 0, name
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["n_dofs"] == metrics["n_dofs"] == 100


def test_beam_case_conserves_energy_and_matches_analytic_frequencies(beam_metrics):
    metrics, _ = beam_metrics
    # Newmark average acceleration conserves the energy of a linear undamped
    # system exactly; what remains is the direct solver's round-off per step.
    assert metrics["energy_relative_drift"] < 1e-8
    # 50 Hermite elements: the 4th cantilever frequency is 1.6e-6 off (error ~ (beta_n h)^4);
    # 1e-5 holds that with margin and still catches an O(h^2) error (~1e-3 here)
    np.testing.assert_allclose(metrics["frequencies_hz"], metrics["analytic_frequencies_hz"], rtol=1e-5)


def test_beam_case_accuracy_falls_with_cost(beam_metrics):
    metrics, _ = beam_metrics
    mesh = metrics["mesh_ladder"]
    errors = np.array([r["frequency_error"] for r in mesh])
    sizes = np.array([r["mesh_size"] for r in mesh])
    rate = np.polyfit(np.log(sizes), np.log(errors), 1)[0]
    # frequency error of cubic Hermite beams falls as h^4
    assert abs(rate - 4.0) < 0.3, rate
    dt_errors = [r["tip_error"] for r in metrics["time_step_ladder"]]
    assert all(a > b for a, b in zip(dt_errors, dt_errors[1:])), dt_errors


def test_cli_lists_cases(capsys):
    assert "beam" in available_cases()
    assert main(["cases"]) == 0
    assert "beam" in capsys.readouterr().out


def test_cli_runs_a_scene_file(tmp_path, capsys):
    scene = tmp_path / "pluck.toml"
    scene.write_text("""
name = "pluck"
[structure]
geometry = "beam_line"
element = "p1"
parameters = { length = 1.0, mesh_size = 0.05 }
[material]
youngs_modulus = 1.0
density = 1.0
area = 1.0
[effects]
inertia = { mass = "lumped" }
elasticity = {}
damping = { alpha = 0.5 }
[boundary]
clamped = ["left", "right"]
[initial_conditions]
kind = "expression"
displacement = "0.1 * sin(pi * x)"
[time]
t_end = 2.0
dt = 0.01
integrator = "central_difference"
[outputs]
probes = [{ name = "middle", at = "probe" }]
""")
    out = tmp_path / "out"
    assert main(["run", str(scene), "-o", str(out)]) == 0
    data = np.load(out / "outputs.npz")
    assert data["y"].shape == (1, 201) and data["y"][0, 0] == pytest.approx(0.1)
    # a damped string (alpha = 0.5): the energy decays as exp(-alpha t) and never grows
    energy = data["energy"]
    assert np.all(np.diff(energy) <= 1e-12 * energy[0])
    assert energy[-1] / energy[0] == pytest.approx(np.exp(-0.5 * 2.0), rel=0.05)
    assert json.loads((out / "metrics.json").read_text())["scheme"] == "CentralDifference"


def test_cli_reports_a_bad_scene_in_one_line(tmp_path, capsys):
    scene = tmp_path / "bad.toml"
    scene.write_text('[structure]\ngeometry = "beam_line"\n[material]\nyoungs_modulus = 1.0\ndensity = 1.0\n'
                     '[effects]\ninertia = {}\nwobble = {}\n[time]\nt_end = 1.0\ndt = 0.1\n')
    assert main(["run", str(scene), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "unknown effect 'wobble'" in err
    assert not (tmp_path / "out").exists()  # nothing written half-way
