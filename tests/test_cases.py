"""The case scripts and the command line, run end to end at small sizes."""

import json
import subprocess
import sys

import numpy as np
import pytest

from femrom.cases import beam
from femrom.cli import CaseError, available_cases, load_case, main


@pytest.fixture(scope="module")
def beam_metrics(tmp_path_factory):
    out = tmp_path_factory.mktemp("beam")
    return beam.run(out, quick=True), out


def test_beam_case_writes_its_report(beam_metrics):
    metrics, out = beam_metrics
    for name in ("metrics.json", "report.md", "response.png", "fom_response.png", "accuracy_cost_dt.png",
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
    dt_errors = [r["output_error"] for r in metrics["time_step_ladder"]]
    assert all(a > b for a, b in zip(dt_errors, dt_errors[1:])), dt_errors


def _rows(metrics, study, method):
    return {row["r"]: row for row in metrics[study]["rows"] if row["method"] == method}


def _report_tables(text: str) -> list[list[dict]]:
    """Every markdown table of a report, as rows of {column: cell}."""
    tables, header = [], None
    for line in text.splitlines() + [""]:
        if not line.startswith("|"):
            header = None
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if header is None:
            header = cells
            tables.append([])
        elif not set(line) <= set("|-"):
            tables[-1].append(dict(zip(header, cells)))
    return tables


def test_beam_case_writes_its_rom_report(beam_metrics):
    metrics, out = beam_metrics
    for name in ("rom_state_error.png", "rom_energy_error.png", "rom_tip_end.png", "accuracy_cost_rom.png",
                 "coarse_rom_state_error.png", "coarse_accuracy_cost_rom.png"):
        assert (out / name).stat().st_size > 0, name
    # the report's two ROM tables hold one row per (method, r) of each study, in order, with the
    # test errors of metrics.json (printed to 4 digits: rel 1e-3)
    tables = [t for t in _report_tables((out / "report.md").read_text()) if t and "test_error" in t[0]]
    assert len(tables) == 2
    for table, study in zip(tables, ("rom", "rom_coarse_data")):
        rows = metrics[study]["rows"]
        assert [(t["method"], int(t["r"])) for t in table] == [(row["method"], row["r"]) for row in rows]
        assert {row["method"] for row in rows} == {"galerkin", "lopinf", "plain_opinf"}
        for t, row in zip(table, rows):
            if np.isfinite(row["test_error"]):
                assert float(t["test_error"]) == pytest.approx(row["test_error"], rel=1e-3), (study, t)


def test_beam_lopinf_energy_error_stays_bounded_over_20_training_windows(beam_metrics):
    """Quick beam (40 dofs), trained on [0, 0.1] s, predicted to 2 s (20x)."""
    metrics, _ = beam_metrics
    assert metrics["rom"]["settings"]["extension"] == 20.0
    for study in ("rom", "rom_coarse_data"):
        for r, row in _rows(metrics, study, "lopinf").items():
            # K^ > 0, C^ >= 0 and Newmark average acceleration: the learned energy cannot grow
            # (1e-9: round-off of the linear step map over 20000 steps)
            assert row["rom_energy_growth"] <= 1 + 1e-9, (study, r, row["rom_energy_growth"])
            assert row["blowup_time"] is None and row["stiffness_asymmetry"] == 0.0
            assert row["stiffness_min_eig"] > 0 and row["damping_min_eig"] >= -1e-12
    gal = _rows(metrics, "rom", "galerkin")
    for r, row in _rows(metrics, "rom", "lopinf").items():
        # the Galerkin ROM conserves its energy exactly: its FOM-energy error is the energy of the
        # initial state the basis misses (4.6e-3 at r = 2). L-OpInf adds what its small learned
        # damping dissipates over 20 windows: observed 3.3e-4, 1.1e-4, 2.6e-4 more (r = 2, 4, 6).
        # The run is deterministic, so 1e-3 (3x the largest excess) is not room for noise: it is
        # the size of error a wrong model makes. A K^ whose scale is off by 0.1 % alone moves the
        # FOM energy of the ROM state by up to 1e-3 E0 (released from rest, the ROM keeps its own
        # energy, which differs from the FOM's by that fraction of the potential energy); the
        # coarse data's dissipation is 7.6e-2
        assert row["energy_error_max"] <= gal[r]["energy_error_max"] + 1e-3, (r, row["energy_error_max"])
    for r, row in _rows(metrics, "rom_coarse_data", "lopinf").items():
        # coarse data (dt = 4e-4): wrong accelerations of the high modes are fitted as damping, the
        # energy decays (observed 0.24 at r = 8) but stays bounded
        assert row["energy_error_max"] < 0.5, (r, row["energy_error_max"])


def test_beam_rom_state_error_against_the_projection_error(beam_metrics):
    metrics, _ = beam_metrics
    for r, row in _rows(metrics, "rom", "galerkin").items():
        # Galerkin with the FOM's own scheme and step: the error is the projection error
        # (observed ratio 1.00-1.006)
        assert row["test_error"] <= 1.05 * row["projection_error"], (r, row)
    for r, row in _rows(metrics, "rom", "lopinf").items():
        # L-OpInf at every r against the projection error combined with d(r), the a priori phase
        # error of a model that learned the data's *discrete* Newmark frequencies exactly and is
        # stepped by Newmark once more (femrom/cases/beam.py: dispersion_error; no fitted constant).
        # The ratio to the projection error alone runs from 1.03 (r = 2) to 33 (r = 6); the ratio
        # to sqrt(projection^2 + d^2) is 0.999-1.000 here (0.998-1.002 for r = 2..12 in the
        # default run). 5 %: a uniform relative error of 3e-5 in the learned frequencies already
        # moves the error by 11 % (mode 2 carries 2.5 % of ||q|| and turns through 660 rad over
        # 2 s), so the test fails for any K^ that is not the data's own; the lower side fails if
        # the floor stops being the derivative data's time discretisation (then update the page)
        ratio = row["test_error"] / row["predicted_learned_error"]
        assert 0.95 < ratio < 1.05, (r, ratio, row["test_error"], row["projection_error"], row["dispersion_error"])
    # the floor is real: at r = 6 the dispersion, not the basis, sets the error
    assert _rows(metrics, "rom", "lopinf")[6]["dispersion_error"] > 10 * _rows(metrics, "rom", "lopinf")[6][
        "projection_error"]


def test_beam_plain_opinf_is_harmless_on_fine_data_and_blows_up_on_coarse_data(beam_metrics):
    """What plain OpInf does, as observed (the seed shows energy growth and blow-up)."""
    metrics, _ = beam_metrics
    lop, plain = _rows(metrics, "rom", "lopinf"), _rows(metrics, "rom", "plain_opinf")
    for r in plain:
        # fine data (dt = 1e-4): no blow-up, no drift beyond 1e-4 over 20 windows, the same test
        # error as L-OpInf (observed within 0.2 %) ...
        assert plain[r]["blowup_time"] is None and plain[r]["rom_energy_growth"] < 1 + 1e-4
        assert plain[r]["test_error"] == pytest.approx(lop[r]["test_error"], rel=0.02)
    # ... although nothing keeps its C^ semidefinite (observed min eigenvalue -9.7e-3 at r = 4)
    assert min(row["damping_min_eig"] for r, row in plain.items() if r >= 4) < 0
    coarse_lop, coarse_plain = _rows(metrics, "rom_coarse_data", "lopinf"), _rows(metrics, "rom_coarse_data",
                                                                                  "plain_opinf")
    # coarse data (dt = 4e-4): at r = 8 plain OpInf's negative damping (observed -970) blows up
    # within the first training window (observed at 0.09 s), L-OpInf stays finite
    assert coarse_plain[8]["blowup_time"] is not None and coarse_plain[8]["blowup_time"] < 0.2
    # ... and still useful: observed test error 7.2e-2. Mode 1 carries 99.97 % of ||q||, so the
    # error is mostly its phase drift, ~ omega_1 |delta| t_rms with t_rms ~ 1.2 s over the test
    # window; 0.2 (2.8x the observed) bounds the learned first frequency to ~0.3 % of
    # omega_1 = 52.5 rad/s, where a model that is merely finite could be off by O(1)
    assert coarse_lop[8]["blowup_time"] is None and coarse_lop[8]["test_error"] < 0.2


def test_cli_lists_cases(capsys):
    cases = available_cases()
    assert list(cases) == ["beam", "fishtail", "jointed_beam", "jointed_beam_measured", "jointed_beam_prestress",
                           "jointed_beam_rom", "nls", "sine_gordon", "soft_robot"]
    assert cases["beam"].startswith("Euler-Bernoulli cantilever")
    assert main(["cases"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in cases)


def test_cli_imports_a_case_by_name_and_names_the_valid_ones_otherwise(capsys):
    assert load_case("beam") is beam
    with pytest.raises(CaseError, match=r"unknown case 'wobble'; available: beam, fishtail, .*soft_robot$"):
        load_case("wobble")
    with pytest.raises(CaseError):
        load_case("femrom")     # a name that imports but is no case
    assert main(["run", "wobble"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("femrom: unknown case 'wobble'; available: beam")


def test_every_case_takes_the_same_output_option(capsys):
    """``-o DIR`` and ``--out DIR`` for every case (``femrom run fishtail -o DIR`` was refused)."""
    for name in available_cases():
        with pytest.raises(SystemExit) as info:
            load_case(name).main(["--help"])
        assert info.value.code == 0
        assert "-o OUT, --out OUT" in capsys.readouterr().out, name


def test_every_case_ships_its_scene_file_beside_it():
    from femrom.cases import scene_file
    from femrom.scene import Scene

    for name in ("beam", "fishtail", "jointed_beam", "sine_gordon", "soft_robot"):
        assert Scene.from_toml(scene_file(name)).name == name
    assert "[initial_condition]" in scene_file("nls").read_text()     # the NLS case's own format
    with pytest.raises(CaseError, match="no scene file 'wobble'"):
        scene_file("wobble")


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


def test_cli_reports_an_unknown_integrator_before_building(tmp_path, capsys, monkeypatch):
    import femrom.scene

    def forbidden(*args, **kwargs):
        raise AssertionError("the scene was built before its integrator was checked")

    monkeypatch.setattr(femrom.scene, "build", forbidden)
    scene = tmp_path / "rk4.toml"
    scene.write_text('[structure]\ngeometry = "beam_line"\nelement = "hermite"\n[material]\n'
                     'youngs_modulus = 1.0\ndensity = 1.0\narea = 1.0\nsecond_moment = 1.0\n'
                     '[effects]\ninertia = {}\nbending = {}\n[time]\nt_end = 1.0\ndt = 0.1\n'
                     'integrator = "rk4"\n')
    assert main(["run", str(scene), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "rk4.toml: unknown integrator 'rk4' in [time]; valid: central_difference" in err
    assert not (tmp_path / "out").exists()


def _clearly_faster(a: dict, b: dict, factor: float) -> bool:
    """``a``'s step is cheaper than ``b``'s beyond both spreads (a's upper quartile below b's fastest
    block) and by more than ``factor``."""
    return a["q75"] < b["minimum"] and factor * a["minimum"] < b["minimum"]


@pytest.mark.slow
def test_beam_rom_costs_hold_on_a_loaded_machine(tmp_path):
    """Two default runs of the beam case (ROM studies; ladders off), the second beside a CPU
    burner: no pair of ROMs is clearly ordered one way in one run and clearly the other way
    in the other, and no ROM is clearly cheaper at a larger r than at a smaller one.

    "Clearly" is a factor 2 beyond the spreads: that is what this machine (two vCPUs of a
    shared host) resolves under load. Measured 2026-11-24: quiet, the L-OpInf step rose
    from 0.70 to 0.79 us over r = 2 ... 12 (fastest of 5 blocks); beside the burner, ROMs of
    equal work measured 0.89-1.62 us, in groups that followed the moment they were timed,
    although every block is 5 slices spread over the round. One timing per model, as
    before the study layer, once showed the same r = 12 step at 1.5e-5 and 1.5e-6 s in one
    report: a factor 10.
    """
    quiet = beam.run(tmp_path / "quiet", ladders=False)
    burner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        loaded = beam.run(tmp_path / "loaded", ladders=False)
    finally:
        burner.kill()
        burner.wait()
    for study in ("rom", "rom_coarse_data"):
        costs = [{(row["method"], row["r"]): row["cost"] for row in m[study]["rows"]} for m in (quiet, loaded)]
        for one, other in ((costs[0], costs[1]), (costs[1], costs[0])):
            for a in one:
                for b in one:
                    if _clearly_faster(one[a], one[b], 2.0):
                        assert not _clearly_faster(other[b], other[a], 2.0), (study, a, b, one[a], other[b])
        for run in costs:
            for (method, r1) in run:
                for (method2, r2) in run:
                    if method2 == method and r2 > r1:
                        assert not _clearly_faster(run[method, r2], run[method, r1], 2.0), (study, method, r1, r2)
        # the costs measure work: a 100-dof Newmark step (27 us) against a (3r x 3r) product (about 1 us)
        for m in (quiet, loaded):
            assert all(row["speedup"] > 5 for row in m[study]["rows"]), study


def _imports(path):
    """Every module a file imports (``from x import y`` gives ``x`` and ``x.y``)."""
    import ast

    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            yield node.module
            yield from (f"{node.module}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)


def test_no_case_imports_another_and_cases_use_public_names():
    from pathlib import Path

    import femrom.cases

    package = Path(femrom.cases.__file__).parent
    cases = set(available_cases())
    for path in package.glob("*.py"):
        for module in _imports(path):
            parts = module.split(".")
            if parts[0] != "femrom":
                continue
            assert not (len(parts) >= 3 and parts[1] == "cases" and parts[2] in cases), f"{path.name} imports {module}"
            # public names of the library only: femrom.<package>, never femrom.<package>._<module>
            assert not any(part.startswith("_") for part in parts[1:-1]), f"{path.name} imports {module}"
    # and the library below imports no case
    for path in package.parent.rglob("*.py"):
        if package in path.parents:
            continue
        assert not any(m.startswith("femrom.cases") for m in _imports(path)), path


def test_nothing_edits_the_import_path_or_loads_a_module_from_a_file():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    for folder in ("femrom", "tests", "benchmarks"):
        for path in (root / folder).rglob("*.py"):
            text = path.read_text()
            for forbidden in ("sys.path.insert", "sys.path.append", "spec_from_file_location", "SourceFileLoader"):
                assert forbidden not in text or path == Path(__file__), f"{path.relative_to(root)}: {forbidden}"
