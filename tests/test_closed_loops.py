"""MPC closed loops on a full-order model, one row per (controller, reference) (femrom.study.closed_loop_rows),
and the table of the linear models' rows (femrom.study.linear_model_table), against direct computations."""

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg as sla

from _control_chain import chain as control_chain
from femrom.control import FullOrderPlant, KalmanObserver, LinearMPC, closed_loop, open_loop
from femrom.rom import SecondOrderROM
from femrom.study import closed_loop_rows
from femrom.study._closed_loops import open_loop_error
from femrom.study._linear_model_figures import linear_model_table

DT = 0.01


def chain(n=10):
    """The control tests' chain with ten masses."""
    return control_chain(n)


def test_each_controller_on_each_reference_as_a_direct_closed_loop():
    system = chain()
    fom = SimpleNamespace(system=system, scene=SimpleNamespace(time=SimpleNamespace(solver="auto")))
    _, modes = sla.eigh(system.stiffness.toarray(), system.mass.toarray())
    model = SecondOrderROM.galerkin(system, modes[:, :6], mass_orthonormal=True).to_state_space(DT)
    t = DT * np.arange(81)
    U = 0.04 * np.vstack([np.sin(2 * np.pi * 2 * t), np.sin(2 * np.pi * 3 * t + 1)])
    feasible = open_loop(FullOrderPlant(system, DT), U)
    references = {"feasible": feasible, "half": 0.5 * feasible}
    horizon, n_steps, bound = 20, 60, 0.1
    rows, results = closed_loop_rows(fom, DT, {("rom", 6): model}, [("rom", 6), ("dmdc", 4)], references, n_steps,
                                     horizon=horizon, input_bound=bound, rate_weight=1e-3, measurement_noise=1e-2,
                                     disturbance="output", record=("rom", 6, "half"))
    assert [(r["controller"], r["reference"]) for r in rows] == [("rom", "feasible"), ("rom", "half"), ("dmdc", "-")]
    assert rows[2]["failed"] == "the model did not fit"
    # the first loop again, by hand: weights scaled by the reference's RMS s and the bound b
    reference = references["feasible"]
    s = float(np.sqrt(np.mean(reference ** 2)))
    mpc = LinearMPC(model, horizon=horizon, output_weight=1 / s ** 2, input_weight=0.0,
                    input_rate_weight=1e-3 / bound ** 2, input_bound=bound)
    observer = KalmanObserver(model, measurement_noise=1e-2 * s ** 2, disturbance="output")
    direct = closed_loop(FullOrderPlant(system, DT), mpc, observer, reference, n_steps, progress=False)
    np.testing.assert_allclose(results[("rom", 6, "feasible")].inputs, direct.inputs, rtol=1e-8, atol=1e-12)
    assert rows[0]["tracking_error"] == pytest.approx(direct.metrics()["tracking_error"], rel=1e-8)
    assert rows[0]["reference_rms"] == pytest.approx(s, rel=1e-14)
    # the open-loop error: the model alone on the applied inputs against the plant's outputs
    result = results[("rom", 6, "feasible")]
    alone = model.simulate(result.inputs, np.zeros(model.n_states))[0]
    expected = np.linalg.norm(alone - result.outputs) / np.linalg.norm(result.outputs)
    assert rows[0]["model_error_on_applied_inputs"] == pytest.approx(expected, rel=1e-12)
    assert open_loop_error(model, result) == rows[0]["model_error_on_applied_inputs"]
    # the recorded loop keeps the FOM's displacements at every sample, the others none
    assert results[("rom", 6, "half")].plant_states.shape == (system.n_dofs, results[("rom", 6, "half")].n_samples)
    assert result.plant_states is None


def test_the_linear_models_table_puts_the_runs_side_by_side():
    def row(model, r, run, error, stable=True):
        return {"model": model, "r": r, "run": run, "test_output_error": error, "stable": stable, "state_order": 2 * r,
                "spectral_radius": 0.99, "fit_seconds": 0.1, "seconds_per_step": 1e-6}

    rows = [row("lopinf", 2, "a", 0.1), row("lopinf", 2, "b", 0.2, stable=False), row("era", 2, "a", 0.3),
            row("era", 2, "b", 0.4), {"model": "okid", "r": 2, "failed": "singular"}]
    table = linear_model_table(rows)
    assert [(line["model"], line["r"]) for line in table] == [("lopinf", 2), ("era", 2), ("okid", 2)]
    assert (table[0]["a"], table[0]["b"], table[0]["stable"]) == (0.1, 0.2, False)   # stable on every run
    assert (table[1]["a"], table[1]["b"], table[1]["stable"]) == (0.3, 0.4, True)
    assert table[2] == {"model": "okid", "r": 2, "stable": "fit failed: singular"}
