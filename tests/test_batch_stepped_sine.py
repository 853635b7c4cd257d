"""A stepped sine with its force levels stepped together equals the level-by-level one.

``SteppedSine.run_batched`` marches every level on its own branch as ``SteppedSine.run`` does
(each frequency until that level is steady, the next one from where it stopped), but each period
of all the levels still running at a frequency is one ``march_batch`` call (one compiled call on
this reduced joint model). The model is the clamped-Iwan lap joint of ``tests/test_fused_step.py``
with 5 % modal damping so that the levels settle, two reduced coordinates as outputs, three
levels from nearly stuck to slipping, three frequencies about the first mode, 32 steps a period.
The levels settle after different numbers of periods (14 and 15 at one frequency), so a steady
level must wait while the others run. Both paths call the same compiled step on the same
numbers (the batch's grid starts at 0 so that its step is the shaker's ``dt``), so the phasors
agree bit for bit; tolerance 1e-10 of the largest phasor (a level that ran one period more or
took another level's force differs by 1e-4 or more). Periods and convergence flags must be equal.
"""

import dataclasses
import warnings

import numpy as np
import pytest
import scipy.linalg as sla

from femrom.fem import use_compiled_laws
from femrom.integrators import Shaker, SteadyStateCriterion, SteppedSine, StepResult
from tests._required import extra
from tests.test_batch_march import ROUND_OFF
from tests.test_fused_step import lap_joint

extra("numba")


@pytest.fixture(autouse=True)
def _compiled_on():
    previous = use_compiled_laws(True)
    yield
    use_compiled_laws(previous)


def _sweep_and_plant():
    system, z0 = lap_joint("clamped_iwan")
    r = system.n_dofs
    f1 = np.sqrt(sla.eigh(np.asarray(system.stiffness), np.asarray(system.mass), eigvals_only=True)[0]) / (2 * np.pi)
    system = dataclasses.replace(system, output_matrix=np.eye(r)[:2], output_names=("y0", "y1"), inputs=None,
                                 damping=10.0 * np.asarray(system.damping))
    plant = Shaker(system, 0, rest=StepResult.at_rest(r, state=z0))
    sweep = SteppedSine(f1 * np.array([0.9, 1.0, 1.1]), steps_per_period=32,
                        steady_state=SteadyStateCriterion(tolerance=1e-2, max_periods=80))
    return sweep, plant


def test_the_batched_stepped_sine_is_the_level_by_level_one():
    sweep, plant = _sweep_and_plant()
    levels = [300.0, 3000.0, 9000.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        reference = sweep.run(plant, levels)
        plant.reset()
        batched = sweep.run_batched(plant, levels)
    periods = np.array([level.periods for level in reference.levels])
    assert np.any(periods.min(axis=0) < periods.max(axis=0))   # the levels settle at different periods
    for level, ref in zip(batched.levels, reference.levels):
        assert level.force_n == ref.force_n
        np.testing.assert_array_equal(level.periods, ref.periods)
        np.testing.assert_array_equal(level.converged, ref.converged)
        np.testing.assert_allclose(level.phasors, ref.phasors, rtol=0.0,
                                   atol=ROUND_OFF * np.abs(ref.phasors).max())
    assert batched.rows() == reference.rows()


def test_an_unsettled_level_is_flagged_and_warned_as_in_the_single_run():
    sweep, plant = _sweep_and_plant()
    sweep = dataclasses.replace(sweep, steady_state=SteadyStateCriterion(tolerance=1e-2, max_periods=14))
    results = []
    for run in (sweep.run, sweep.run_batched):
        plant.reset()
        with pytest.warns(Warning) as caught:
            results.append(run(plant, [300.0, 3000.0]))
        results[-1] = (results[-1], sorted(str(w.message) for w in caught))
    (reference, ref_warnings), (batched, batched_warnings) = results
    assert ref_warnings == batched_warnings and ref_warnings
    for level, ref in zip(batched.levels, reference.levels):
        np.testing.assert_array_equal(level.converged, ref.converged)
        np.testing.assert_allclose(level.phasors, ref.phasors, rtol=0.0,
                                   atol=ROUND_OFF * np.abs(ref.phasors).max())
