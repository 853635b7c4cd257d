"""Learned Jenkins sliders (``LearnedHysteresis``) step in one compiled call, and march a whole trajectory in one.

A reduced model ``M q'' + C q' + K q + a sum_i k_i e_i = B u`` (r = 3, eight sliders along a
direction ``a``, a half-sine blow that slips most of them and reverses) steps from rest with the
compiled laws on (the Newmark family hands each step to the fused kernel; ``march`` hands it the
whole trajectory) and with them off (the numpy step of the term). Both solve the same equations
with the same tests; sums run in loops against BLAS, about 1e-16 relative per operation, carried
through Newton's solves and the steps. Tolerance 1e-10 of the run's largest value (measured
about 1e-15; one changed term, e.g. the tangent's weight or the commit point, moves it by 1e-6 or
more), and the same Newton iterations.
"""

import dataclasses

import numpy as np
import pytest

from femrom.fem import compiled_laws, use_compiled_laws
from femrom.inference import LearnedHysteresis, ReducedOperators
from femrom.integrators import Newmark, Newton, StepResult, iterate, march
from femrom.scene import Signal, SignalVector
from tests._required import extra

extra("numba")

R, DT, STEPS = 3, 1e-3, 400
ROUND_OFF = 1e-10          # see the module docstring


@pytest.fixture(autouse=True)
def _compiled_on():
    previous = use_compiled_laws(True)
    yield
    use_compiled_laws(previous)


def model():
    """The reduced system (with its blow) and the hysteresis term."""
    rng = np.random.default_rng(3)
    X = rng.normal(size=(R, R))
    K = X @ X.T + R * np.eye(R)
    K *= (2 * np.pi * 20.0) ** 2 / np.linalg.eigvalsh(K)[0]
    C = 2 * 0.01 * 2 * np.pi * 20.0 * np.eye(R)
    term = LearnedHysteresis(rng.normal(size=R), np.geomspace(1e-4, 3e-2, 8), np.geomspace(2e4, 1e3, 8))
    ops = ReducedOperators.from_matrices(K, damping=C, input_matrix=np.ones((R, 1)), nonlinear=term)
    blow = SignalVector([Signal.from_dict({"kind": "impulse", "amplitude": 400.0, "start": 0.0,
                                           "duration": 2e-2})])
    return dataclasses.replace(ops.system, inputs=blow), term


def _close(x, reference):
    np.testing.assert_allclose(x, reference, rtol=0.0, atol=ROUND_OFF * np.abs(reference).max())


def stepped(system, compiled):
    """``((q, stretches, coordinates, iterations per step), summary)`` of the run from rest; for a model whose
    state is the tuple of its terms' (sliders beside a potential), the sliders' part."""
    terms = getattr(system.nonlinear, "terms", None)
    slot = None if terms is None else [i for i, t in enumerate(terms) if hasattr(t, "compiled_sliders")][0]
    use_compiled_laws(compiled)
    try:
        steps = iterate(system, Newmark(newton=Newton(rtol=1e-12)), None, None, DT, STEPS,
                        start=StepResult.at_rest(R), progress=False)
        rows, done = [], 0
        for result in steps:
            sliders = result.state if slot is None else result.state[slot]
            rows.append((result.q, sliders.stretch, sliders.coordinate, steps.newton_iterations - done))
            done = steps.newton_iterations
        return [np.array(column) for column in zip(*rows)], steps.summary()
    finally:
        use_compiled_laws(True)


def test_the_fused_slider_step_is_the_numpy_step():
    system, term = model()
    assert compiled_laws() and term.compiled_sliders() is not None
    (q, e, x, its), summary = stepped(system, True)
    (q_ref, e_ref, x_ref, its_ref), summary_ref = stepped(system, False)
    assert summary.details.get("compiled_step") is True and "compiled_step" not in summary_ref.details
    np.testing.assert_array_equal(its, its_ref)
    assert its_ref.mean() > 1.0                                   # sliders slip: Newton works
    slipping = np.abs(e_ref) >= term.thresholds                   # at their limit at some step
    assert slipping.any(axis=0).sum() >= 4
    _close(q, q_ref)
    _close(e, e_ref)
    _close(x, x_ref)


def test_march_runs_the_whole_trajectory_in_one_call():
    system, term = model()
    times = DT * np.arange(STEPS + 1)
    scheme = Newmark(newton=Newton(rtol=1e-12))
    fused = march(system, scheme, times, np.zeros(R), np.zeros(R), inputs=system.inputs)
    use_compiled_laws(False)
    try:
        reference = march(system, scheme, times, np.zeros(R), np.zeros(R), inputs=system.inputs)
    finally:
        use_compiled_laws(True)
    assert fused["path"] == "compiled steps" and reference["path"] == "steps"
    assert fused["newton_iterations"] == reference["newton_iterations"]
    for key in ("q", "v", "a"):
        _close(fused[key], reference[key])
    _close(fused["state"].stretch, reference["state"].stretch)
    # and the stepped fused path gives the marched trajectory
    (q, *_), _ = stepped(system, True)
    _close(fused["q"][:, 1:].T, q)


def test_a_marched_step_that_does_not_converge_fails_as_the_loop_does():
    system, _ = model()
    times = DT * np.arange(STEPS + 1)
    scheme = Newmark(newton=Newton(rtol=1e-15, max_iterations=1))
    messages = []
    for compiled in (True, False):
        use_compiled_laws(compiled)
        try:
            with pytest.raises(Exception) as failure:
                march(system, scheme, times, np.zeros(R), np.zeros(R), inputs=system.inputs)
        finally:
            use_compiled_laws(True)
        messages.append((type(failure.value).__name__, str(failure.value).split(":")[0]))
    assert messages[0] == messages[1]


def with_potential(scale: float = 1.0):
    """:func:`model` with a quartic potential ``U = c sum_m q^m`` over the degree-4 monomials beside the sliders (SpML
    with sliders, its monomials as the potential): at the blow's largest motion its force is about a quarter of
    ``K q``."""
    from femrom.inference import LearnedPotential, SymmetricPolynomial, multi_indices

    system, term = model()
    index = multi_indices(R, 4)
    coefficients = scale * 4e6 * np.random.default_rng(5).uniform(0.2, 1.0, len(index))
    potential = LearnedPotential(R, SymmetricPolynomial(R, {4: (index, coefficients)}))
    K, C = system.stiffness, system.damping
    ops = ReducedOperators.from_matrices(K, damping=C, input_matrix=np.ones((R, 1)), nonlinear=potential)
    ops = ops.with_terms(term)
    return dataclasses.replace(ops.system, inputs=system.inputs), term, potential


def test_sliders_beside_a_learned_potential_step_and_march_compiled():
    """The sum of the sliders and a learned quartic potential takes the fused step (one compiled call, the
    potential's gradient and Hessian by the scalar kernels) and the compiled march: equal to the numpy step to
    round-off, with the same Newton iterations; the potential changes the run (not a sliders-only step)."""
    system, term, potential = with_potential()
    assert potential.compiled_scalar() is not None
    times = DT * np.arange(STEPS + 1)
    scheme = Newmark(newton=Newton(rtol=1e-12))
    fused = march(system, scheme, times, np.zeros(R), np.zeros(R), inputs=system.inputs)
    (q, e, x, its), summary = stepped(system, True)
    (q_ref, e_ref, x_ref, its_ref), summary_ref = stepped(system, False)
    assert summary.details.get("compiled_step") is True and "compiled_step" not in summary_ref.details
    assert fused["path"] == "compiled steps"
    np.testing.assert_array_equal(its, its_ref)
    assert fused["newton_iterations"] == its_ref.sum()
    _close(q, q_ref)
    _close(e, e_ref)
    _close(fused["q"][:, 1:].T, q_ref)
    _close(fused["state"][[i for i, t in enumerate(system.nonlinear.terms) if t is term][0]].stretch, e_ref[-1])
    quartic = potential.forces(q_ref.T)
    linear = system.stiffness @ q_ref.T
    assert 0.05 < np.abs(quartic).max() / np.abs(linear).max() < 1.0          # observed 0.25
    (q_plain, *_), _ = stepped(model()[0], True)
    assert np.abs(q - q_plain).max() > 1e-3 * np.abs(q_plain).max()
