"""Many runs of one reduced joint model stepped together equal their single runs.

``march_batch`` steps ``B`` runs of the small lap-joint model of ``tests/test_fused_step.py``
(the same matrices and pairs) with different sine inputs on the one input column (amplitudes
from nearly stuck to slipping, two frequencies), one run from a moved start and one from a
slipped force state. On the compiled path all runs go through one compiled call, each with its
own Newton. The reference is each run alone, stepped by :class:`~femrom.integrators.Stepper`
(the single-run fused step, one call a step), whose per-step Newton iterations and force
states are at hand. Both paths call the same compiled step on the same numbers, so they agree
to round-off (measured: bit for bit); tolerance 1e-10 of each run's largest value, as in
``tests/test_fused_step.py``. A run that used another run's forcing or state would differ by
1e-3 or more. Newton iterations must be equal step by step.
"""

import numpy as np
import pytest

from femrom import FemromValueError
from femrom.fem import compiled_laws, use_compiled_laws
from femrom.integrators import ConvergenceError, Newmark, Newton, Stepper, march_batch
from tests._required import extra
from tests.test_fused_step import DT, ROUND_OFF, lap_joint

extra("numba")

STEPS = 240
CHECKS = (80, 160, 240)             # steps at which the slider states are compared


@pytest.fixture(autouse=True)
def _compiled_on():
    previous = use_compiled_laws(True)
    yield
    use_compiled_laws(previous)


def _batch(name):
    """``(system, z0, times, inputs (B, 1, k), q0 (B, r), states (B, ...))``."""
    system, z0 = lap_joint(name)
    times = DT * np.arange(STEPS + 1)
    cases = [(300.0, 400.0), (2000.0, 400.0), (8000.0, 400.0), (4000.0, 650.0)]
    inputs = np.array([[a * np.sin(2 * np.pi * f * times)] for a, f in cases])
    q0 = np.zeros((len(cases), system.n_dofs))
    q0[1] = 1e-3 * np.linspace(-1.0, 1.0, system.n_dofs)        # a moved start
    slipped = march_batch(system, Newmark(), times[:41], inputs=[5 * inputs[2, :, :41]], state0=z0)["state"][0]
    states = np.array([z0, z0, z0, slipped])                     # one run from a slipped joint
    return system, z0, times, inputs, q0, states


def _single(system, scheme, inputs, q0, state):
    """``(q (r, k), iterations (k - 1,), {step: state})`` of one run, step by step."""
    stepper = Stepper(system, scheme, DT, q0=q0, u0=inputs[:, 0], state=state)
    q, iterations, states = [stepper.q], [], {}
    for k in range(1, inputs.shape[1]):
        done = stepper.iterations
        stepper.step(inputs[:, k])
        q.append(stepper.q)
        iterations.append(stepper.iterations - done)
        if k in CHECKS:
            states[k] = np.array(stepper.state)
    return np.array(q).T, np.array(iterations), states


def _close(x, reference):
    np.testing.assert_allclose(x, reference, rtol=0.0, atol=ROUND_OFF * np.abs(reference).max())


@pytest.mark.parametrize("name", ["clamped_iwan", "iwan", "jenkins"])
def test_each_batched_run_is_its_single_run(name):
    system, z0, times, inputs, q0, states = _batch(name)
    scheme = Newmark(newton=Newton(rtol=1e-12))
    assert compiled_laws() and system.nonlinear.compiled_joint() is not None
    out = march_batch(system, scheme, times, q0, inputs=inputs, state0=states)
    assert out["path"] == "compiled batch"
    assert out["q"].shape == (4, system.n_dofs, STEPS + 1) and out["newton_iterations"].shape == (4, STEPS)
    partial = {k: march_batch(system, scheme, times[:k + 1], q0, inputs=inputs[:, :, :k + 1], state0=states)
               for k in CHECKS[:-1]}
    partial[STEPS] = out
    totals = []
    for b in range(4):
        q, iterations, single_states = _single(system, scheme, inputs[b], q0[b], states[b])
        np.testing.assert_array_equal(out["newton_iterations"][b], iterations)
        _close(out["q"][b], q)
        for k in CHECKS:
            _close(partial[k]["state"][b], single_states[k])
        totals.append(iterations.sum())
    assert max(totals) > min(totals)                              # the runs converge differently
    assert np.abs(out["state"][2] - states[2]).max() > 1e-6       # and the strong run slips


def test_the_reference_path_steps_each_run_alone():
    system, z0, times, inputs, q0, states = _batch("iwan")
    scheme = Newmark(newton=Newton(rtol=1e-12))
    compiled = march_batch(system, scheme, times, q0, inputs=inputs, state0=states)
    use_compiled_laws(False)
    reference = march_batch(system, scheme, times, q0, inputs=inputs, state0=states)
    assert reference["path"] == "steps"
    np.testing.assert_array_equal(compiled["newton_iterations"], reference["newton_iterations"])
    for key in ("q", "v", "a", "state"):
        for b in range(4):
            _close(compiled[key][b], reference[key][b])


def test_a_failing_run_is_named():
    system, z0, times, inputs, q0, states = _batch("jenkins")
    scheme = Newmark(newton=Newton(rtol=1e-14, max_iterations=1))
    messages = []
    for compiled in (True, False):
        use_compiled_laws(compiled)
        with pytest.raises(ConvergenceError) as failure:
            march_batch(system, scheme, times, q0, inputs=inputs, state0=states)
        messages.append(str(failure.value).split(":")[0])
    assert messages[0] == messages[1] and messages[0].startswith("run ")


def test_one_start_and_state_serve_every_run():
    system, z0, times, inputs, q0, states = _batch("jenkins")
    shared = march_batch(system, Newmark(), times[:21], inputs=inputs[:, :, :21], state0=z0)
    each = march_batch(system, Newmark(), times[:21], np.zeros((4, system.n_dofs)), inputs=inputs[:, :, :21],
                       state0=np.array([z0] * 4))
    np.testing.assert_array_equal(shared["q"], each["q"])
    with pytest.raises(FemromValueError, match="q0 must be"):
        march_batch(system, Newmark(), times[:21], np.zeros((3, system.n_dofs)), inputs=inputs[:, :, :21])


def test_a_batch_continues_another():
    system, z0, times, inputs, q0, states = _batch("clamped_iwan")
    scheme = Newmark(newton=Newton(rtol=1e-12))
    whole = march_batch(system, scheme, times, q0, inputs=inputs, state0=states)
    half = STEPS // 2
    first = march_batch(system, scheme, times[:half + 1], q0, inputs=inputs[:, :, :half + 1], state0=states)
    second = march_batch(system, scheme, times[half:], first["q"][:, :, -1], first["v"][:, :, -1],
                         inputs=inputs[:, :, half:], state0=first["state"], a0=first["a"][:, :, -1])
    for key in ("q", "v", "a"):
        joined = np.concatenate([first[key], second[key][:, :, 1:]], axis=2)
        for b in range(4):
            _close(joined[b], whole[key][b])
    for b in range(4):
        _close(second["state"][b], whole["state"][b])
    np.testing.assert_array_equal(np.hstack([first["newton_iterations"], second["newton_iterations"]]),
                                  whole["newton_iterations"])
