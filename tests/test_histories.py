"""The study's helpers for judging ROMs over time, the scene's own run, ladders and report sections."""

import time
from types import SimpleNamespace

import numpy as np
import pytest

from femrom.cases import scene_file
from femrom.post import table_section
from femrom.scene import Derivatives, Scene, build
from femrom.study import HYPER_COLUMNS, call_cost, invariant_drift, extrapolation_config, extrapolation_scene, \
    final_state, final_state_ladders, final_state_section, hyper_reduced_rows, mass_norm, observed_order, \
    reconstructed_energy_error, rom_table, run_study, scene_run, state_energy


@pytest.fixture(scope="module")
def chain():
    """The sine-Gordon scene at 60 nodes over a short window: a nonlinear conservative system."""
    scene = Scene.from_toml(scene_file("sine_gordon"))
    return scene.with_geometry(mesh_size=40.0 / 61, probe_position=30 / 61).with_time(dt=0.05, t_end=1.0)


def test_state_energy_is_the_systems_energy_column_by_column(chain):
    system = build(chain).system
    rng = np.random.default_rng(0)
    Q, Qdot = rng.standard_normal((2, system.n_dofs, 7))
    direct = [system.energy(q, v) for q, v in zip(Q.T, Qdot.T)]    # kinetic + K + U_nl, one state at a time
    # the same sums in another order: round-off of ~n terms of size O(1), relative 1e-12 with margin
    np.testing.assert_allclose(state_energy(system, Q, Qdot), direct, rtol=1e-12)


def test_reconstructed_energy_error_of_a_reduced_solution(chain):
    system = build(chain).system
    n, r = system.n_dofs, 3
    rng = np.random.default_rng(1)
    V = np.linalg.qr(rng.standard_normal((n, 5)))[0]
    solution = SimpleNamespace(q=rng.standard_normal((r, 4)), v=rng.standard_normal((r, 4)))
    E0 = 2.5
    expected = [abs(system.energy(V[:, :r] @ q, V[:, :r] @ v) - E0) / E0 for q, v in zip(solution.q.T, solution.v.T)]
    # only the first r columns of the basis count; round-off as above
    np.testing.assert_allclose(reconstructed_energy_error(system, V, solution, E0), expected, rtol=1e-12)
    solution.q[0, 2] = np.inf            # a ROM that blew up: not finite there, no warning
    assert not np.isfinite(reconstructed_energy_error(system, V, solution, E0)[2])


def _linear_system(stiffness):
    """M = I, K = diag(stiffness), no force: E = (|v|^2 + sum k q^2) / 2."""
    import scipy.sparse as sp

    return SimpleNamespace(mass=sp.identity(len(stiffness), format="csr"), stiffness=sp.diags(stiffness).tocsr(),
                           nonlinear=None, load=None)


def test_rom_table_scores_after_the_training_window_and_keeps_failures():
    system = _linear_system([1.0, 4.0])
    times = np.linspace(0.0, 2.0, 5)                  # training window [0, 1]: columns 0..2
    amplitude = np.array([1.0, 1.0, 1.1, 1.3, 1.2])   # energy 0.5 a^2: error a^2 - 1
    solution = SimpleNamespace(q=np.vstack([amplitude, 0 * times]), v=np.zeros((2, 5)),
                               energy=0.5 * amplitude**2, outputs=None)
    run = SimpleNamespace(name="test", times=times, energy=np.full(5, 0.5))
    ev = SimpleNamespace(solution=solution, field_error=0.2, projection_error=0.1, energy_growth=1.69,
                         blowup_time=None)
    K = np.array([[1.0, 0.5], [0.0, 4.0]])
    rom = SimpleNamespace(operators_=SimpleNamespace(stiffness=K))
    rows = [{"learner": "a", "r": 2, "_rom": rom, "seconds_per_step": 1e-6, "speedup": 30.0, "cost": None,
             "fit_seconds": 2.0},
            {"learner": "b", "r": 2, "failed": "test: Newton did not converge"}]
    evaluations = {(2, "a", "test"): ev, (2, "a", "train"): SimpleNamespace(field_error=0.01, projection_error=0.005)}
    table, histories = rom_table(system, np.eye(2), run, rows, evaluations, train="train", score_after=1.0,
                                 carry=("fit_seconds",))
    a, b = table
    np.testing.assert_allclose(histories[(2, "a")], amplitude**2 - 1, atol=1e-15)
    assert a["energy_error_max"] == pytest.approx(0.69) and a["energy_error_train_max"] == pytest.approx(0.21)
    assert a["energy_error_test_max"] == pytest.approx(0.69) and a["rom_energy_drift"] == pytest.approx(0.69)
    assert (a["train_error"], a["test_error"], a["error_over_projection"]) == (0.01, 0.2, 2.0)
    assert a["online_seconds"] == pytest.approx(4e-6)                  # 4 steps
    assert a["stiffness_asymmetry"] == pytest.approx(np.linalg.norm(K - K.T) / np.linalg.norm(K))
    # symmetric part [[1, 1/4], [1/4, 4]]: smallest eigenvalue (5 - sqrt(9 + 1/4)) / 2; no damping
    assert a["stiffness_min_eig"] == pytest.approx((5 - np.sqrt(9.25)) / 2, rel=1e-14) and a["damping_min_eig"] is None
    assert a["fit_seconds"] == 2.0 and "fit_seconds" not in b          # carried, failed rows aside
    assert b == {"method": "b", "r": 2, "failed": "test: Newton did not converge", "test_error": float("inf")}


def test_energy_drift_and_observed_order():
    assert invariant_drift(np.array([2.0, 2.2, 1.9])) == pytest.approx(0.1)
    assert invariant_drift(np.array([2.0, np.inf])) == np.inf
    h = np.array([0.1, 0.05, 0.025])
    assert observed_order(h, 3.0 * h**2) == pytest.approx(2.0, abs=1e-12)       # an exact power law
    assert observed_order(1 / h, 3.0 * h**2) == pytest.approx(-2.0, abs=1e-12)  # counts, not sizes


def test_call_cost_times_blocks_of_calls():
    cost = call_cost(time.sleep, 2e-3, repeats=3, min_block_seconds=0.02)
    # a sleep lasts at least what it asks for; a loaded machine only adds, so no upper bound but a loose one
    assert cost.blocks == 3 and 2e-3 <= cost.seconds < 0.1


def test_final_state_is_the_last_state_of_the_run(chain):
    from femrom.integrators import Trajectory, simulate

    model = build(chain.with_geometry(mesh_size=40.0 / 31, probe_position=15 / 31))
    q, row = final_state(model, 0.1, 1.0)
    assert (row["n"], row["steps"], row["dt"]) == (30, 10, 0.1)
    # every state of the same run (scene's scheme and solver, same steps): its last is the final state
    every = Trajectory(every=1, fields=("q",))
    simulate(model, dt=0.1, t_end=1.0, consumers=[every], progress=False)
    assert every.t[-1] == pytest.approx(1.0)
    np.testing.assert_allclose(q, every.q[:, -1], rtol=0, atol=1e-12 * np.abs(every.q[:, -1]).max())
    with pytest.raises(ValueError, match="does not divide"):
        final_state(model, 0.3, 1.0)


def test_extrapolation_config_trains_on_whole_steps_and_scores_after_them():
    config = extrapolation_config(0.02, 5.01, 25.0, (2, 4), derivatives=Derivatives("finite_differences", 2),
                                  terms=("damping",))
    T = 250 * 0.02                                  # 5.01 s is 250.5 steps: rounded to 250
    assert config.train[0].t_end == T and config.test[0].score_after == T and config.test[0].t_end == 25.0
    assert [(s.label, s.learner, s.terms) for s in config.learners] == [
        ("galerkin", "galerkin", ()), ("lopinf", "lopinf", ("damping",)), ("plain_opinf", "opinf", ("damping",))]
    assert config.basis.ranks == (2, 4) and config.learners[1].derivatives.order == 2


def test_table_section_and_scene_run(chain, tmp_path):
    text = table_section("Ladder", [{"dt": 0.1, "error": 0.25}], ["dt", "error"], note="Order 2.")
    assert text == "## Ladder\n\n| dt | error |\n|---|---|\n| 0.1 | 0.25 |\n\nOrder 2."
    run = scene_run(chain, tmp_path / "response.png")
    energy = run.result.energy
    assert (tmp_path / "response.png").stat().st_size > 0
    assert run.energy_drift == pytest.approx(np.max(np.abs(energy - energy[0])) / energy[0], rel=1e-14)
    assert run.metrics()["n_dofs"] == 60 and "60 free dofs, 20 steps of 0.05 s" in run.section()


def _breather(x, t, w=0.8, centre=20.0):
    """The exact breather the sine-Gordon scene releases (docs/cases/sine_gordon.md)."""
    s = np.sqrt(1.0 - w * w)
    return 4.0 * np.arctan(s / w * np.sin(w * t) / np.cosh(s * (x - centre)))


def _nodes(scene, n):
    """The scene with n interior nodes (n + 1 elements; the probe on a node)."""
    return scene.with_geometry(mesh_size=40.0 / (n + 1), probe_position=(n + 1) // 2 / (n + 1))


def test_final_state_ladders_converge_at_the_schemes_orders(chain, tmp_path):
    seen = []

    def exact(model, t):
        seen.append(t)
        _, (x,) = model.free_coordinates()
        return _breather(x, t)

    model = build(_nodes(chain, 60))
    meshes = (build(_nodes(chain, n)) for n in (60, 120, 240))
    rows = final_state_ladders(model, 1.0, (0.2, 0.1, 0.05), 0.0125, meshes, exact, exact_name="breather")
    time_rows, mesh_rows = rows[:3], rows[3:]
    assert [r["ladder"] for r in rows] == ["time step"] * 3 + ["mesh"] * 3
    assert [r["label"] for r in mesh_rows] == ["n=60", "n=120", "n=240"] and seen == [1.0, 1.0, 1.0]
    # the first error, recomputed: the final state at dt = 0.2 against the one at 0.0125, mass norm
    q, _ = final_state(model, 0.2, 1.0)
    reference, _ = final_state(model, 0.0125, 1.0)
    M = model.system.mass
    assert time_rows[0]["error"] == pytest.approx(mass_norm(M, q - reference) / mass_norm(M, reference), rel=1e-12)
    # Newmark average acceleration is second order in dt; P1 with a lumped mass second order in h
    # (n ~ 1/h in 1D). Observed 2.03 and 1.95 (n = 60-240: the breather's width 1/0.6 spans 2.5-10
    # elements); 0.2 tells 2 from 1 or 3, and a sign error in the mesh order from either.
    assert abs(time_rows[0]["observed_order"] - 2.0) < 0.2 and abs(mesh_rows[0]["observed_order"] - 2.0) < 0.2
    section = final_state_section(tmp_path / "ladder.png", rows, note="Both second order.")
    assert (tmp_path / "ladder.png").stat().st_size > 0
    # one order per ladder, in the rows' order
    assert (f"Observed order: time step {time_rows[0]['observed_order']:.2f}, mesh "
            f"{mesh_rows[0]['observed_order']:.2f}. Both second order.") in section


def test_hyper_reduced_rows_are_study_rows_of_a_sampled_potential(chain, tmp_path):
    """A small sine-Gordon study (60 nodes, trained on [0, 1] s, tested to 2 s, L-OpInf at r = 2, 3)
    and its ECSW hyper-reduction, with a tight tolerance."""
    import dataclasses

    from femrom.scene import TimingSpec

    scene = extrapolation_scene(chain, 0.05, 1.0, 2.0, (2, 3), learners={"lopinf": "lopinf"})
    assert (scene.time.dt, scene.time.t_end) == (0.05, 2.0)
    assert scene.rom == extrapolation_config(0.05, 1.0, 2.0, (2, 3), learners={"lopinf": "lopinf"})
    scene = dataclasses.replace(scene, rom=dataclasses.replace(scene.rom, timing=TimingSpec(3, 0.005)))
    seen = {}

    def extend(state):
        rows, evaluations = hyper_reduced_rows(state, tolerance=1e-8, stride=1)
        table, _ = rom_table(state.model.system, state.basis, state.runs["extrapolation"],
                             [*state.rows, *rows], state.evaluations | evaluations, train="train",
                             score_after=1.0, carry=HYPER_COLUMNS)
        seen.update(state=state, rows=rows, evaluations=evaluations, table=table)
        return {}, []

    run_study(scene, tmp_path, extend=extend, progress=None)
    state, rows = seen["state"], seen["rows"]
    assert [(row["learner"], row["r"]) for row in rows] == [("lopinf_hyper", 2), ("lopinf_hyper", 3)]
    assert set(seen["evaluations"]) == {(r, "lopinf_hyper", run) for r in (2, 3) for run in ("train", "extrapolation")}
    nl = state.model.system.nonlinear
    train = state.projections["train"].coordinates
    for row, study_row in zip(rows, state.rows):
        r = row["r"]
        # the sampled force against the unsampled projection V^T f(V q^) on the training states,
        # computed here from the full force: ECSW at 1e-8 matches it to ~1e-8 (relative, Frobenius)
        Vr = state.basis[:, :r]
        hyper = row["_rom"].operators_.term("hyper_reduced_potential")
        exact = np.column_stack([Vr.T @ nl.force(Vr @ q) for q in train[:r].T])
        sampled = hyper.forces(train[:r])
        assert np.linalg.norm(sampled - exact) <= 1e-6 * np.linalg.norm(exact)
        assert 0 < row["samples"] < state.model.system.n_dofs and row["nodes"].size == row["samples"]
        # so the hyper-reduced ROM predicts what the unsampled one does (observed: equal to 1e-9)
        ev = seen["evaluations"][(r, "lopinf_hyper", "extrapolation")]
        full = state.evaluations[(r, "lopinf", "extrapolation")]
        assert ev.field_error == pytest.approx(full.field_error, rel=1e-4)
        # timed in the same rounds as the L-OpInf ROM; the ratio is the two costs' ratio
        assert row["speedup_over_lopinf"] == pytest.approx(row["lopinf_seconds_per_step"] / row["seconds_per_step"])
        assert row["seconds_per_step"] == row["cost"]["minimum"] > 0
    # the table carries the hyper columns of the hyper rows only
    assert all("samples" in t for t in seen["table"][2:]) and not any("samples" in t for t in seen["table"][:2])
