"""The output-error refinement (``femrom.inference._output_error``): its sensitivities are the
discrete-gradient march's exact derivatives, and from the truth on noisy data it ends at the
noise's expected cost and near the truth."""

import numpy as np
import pytest

from benchmarks.spml_systems import SYSTEMS, polynomial_potential
from femrom.inference import ConvexPowers, LearnedDissipation, ReducedOperators, SecondOrderData
from femrom.inference._output_error import (OutputError, _Model, _prepare, _Problem, field_noise,
                                            output_error_refinement)
from femrom.study import spml_error_split


def _forced_model():
    """Two coordinates, a non-identity mass, damping, one input, a quartic-plus-cubic potential and a
    fixed convex dissipation (powers of ``v``): every kind of free parameter the refinement has, and a
    fixed term it differentiates through."""
    duffing = SYSTEMS["duffing2"]().operators
    M = np.array([[1.2, 0.1], [0.1, 0.9]])
    model = ReducedOperators.from_matrices(duffing.stiffness, mass=M, damping=np.array([[0.05, 0.01], [0.01, 0.04]]),
                                           input_matrix=np.array([[1.0], [0.3]]),
                                           nonlinear=duffing.term("learned_potential"))
    powers = ConvexPowers(np.array([[0.3, -0.2]]), np.array([[0.2, 0.1]]))
    return model.with_terms(LearnedDissipation(2, powers))


def _trajectory(operators, n=60, dt=0.05, noise=0.0, seed=0):
    """A forced run of ``operators`` (the discrete-gradient march at dt / 16), sampled every ``dt``."""
    from femrom.integrators import march

    t = dt * np.arange(n + 1)
    fine = (dt / 16) * np.arange(16 * n + 1)
    u = np.sin(1.3 * fine)[None, :]
    out = march(operators.system, "discrete_gradient", fine, np.array([0.8, -0.4]), np.array([0.1, 0.2]), inputs=u)
    Q, V = out["q"][:, ::16], out["v"][:, ::16]
    A = _Problem._acceleration(operators, Q, V, u[:, ::16])
    rng = np.random.default_rng(seed)
    Q, V, A = (x + noise * np.sqrt(np.mean(x * x)) * rng.standard_normal(x.shape) for x in (Q, V, A))
    return SecondOrderData(Q, V, A, inputs=u[:, ::16], times=t)


def test_the_sensitivities_are_the_marchs_derivatives():
    """The Jacobian of the weighted residual (parameters linear in the balance, then the initial state)
    against central differences of the residual itself: the recursion differentiates the discrete
    step exactly (a quartic potential: the two-point quadrature is exact, Gonzalez's term vanishes),
    so they agree to the differences' own error (step 1e-6; observed at most 6e-9 of a column's
    norm, median 1e-9)."""
    operators = _forced_model()
    data = _trajectory(operators, noise=1e-3)
    free = ("mass", "stiffness", "damping", "input", "learned_potential")
    model = _Model(operators, free)
    # the mass keeps tr M fixed (2 of 3 entries), K and C 3 each, B 2, monomials 4 + 5
    assert model.size == 2 + 3 + 3 + 2 + 9
    problem = _Problem(model, [_prepare(data)], OutputError(substeps=4))
    rng = np.random.default_rng(1)
    theta = 1e-3 * rng.standard_normal(model.size)
    y0 = np.array([0.79, -0.41, 0.12, 0.19])
    r0, J = problem.evaluate(theta, [y0], jacobian=True)
    assert J.shape == (r0.size, model.size + 4)
    x = np.concatenate([theta, y0])
    worst = 0.0
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = 1e-6 * max(1.0, abs(x[j]))
        plus = problem.evaluate((x + e)[:model.size], [(x + e)[model.size:]])
        minus = problem.evaluate((x - e)[:model.size], [(x - e)[model.size:]])
        fd = (plus - minus) / (2 * e[j])
        worst = max(worst, float(np.linalg.norm(J[:, j] - fd) / np.linalg.norm(fd)))
    assert worst < 1e-6, worst


def test_the_trace_gauge_and_a_wrong_start_shape_are_handled():
    operators = _forced_model()
    model = _Model(operators, ("mass",))
    theta = np.array([0.3, -0.2])
    M = model.at(theta).mass_matrix
    assert np.isclose(np.trace(M), np.trace(operators.mass_matrix)) and np.allclose(M, M.T)
    data = _trajectory(operators)
    with pytest.raises(Exception, match="start data"):
        output_error_refinement(operators, data, ("stiffness",), start_from=[data, data])


def test_from_the_truth_it_ends_at_the_noise_floor():
    """Noise of 1 % on every field, the true operators as the start: the maximum-likelihood fit ends at
    the noise's expected cost (a chi-square with ~n degrees of freedom: within a few sqrt(n) of n / 2)
    and its parameters stay near the truth (the force within 2e-3, the data's own determination;
    a fit that ignored the dynamics would not lower the cost below the truth's)."""
    system = SYSTEMS["duffing2"]()
    train, validation = system.training(noise=0.01, seed=2)
    truth = system.operators
    result = output_error_refinement(truth, train, ("stiffness", "damping", "learned_potential"),
                                     validation=validation, settings=OutputError(iterations=10))
    n = 2 * result["expected"]
    assert abs(result["cost"] - result["expected"]) < 3 * np.sqrt(n), result
    assert result["cost"] < result["cost_before"], result
    split = spml_error_split(result["operators"], truth, train, system.test(1.0))
    # observed 4.1e-4 (the maximum-likelihood fit of benchmarks/spml_noise_floor.py: 4.4e-4 on this seed)
    assert 1e-5 < split.potential < 2e-3, split
    # the noise estimates the weights come from: 1 % of each field's RMS within 10 % (observed 0.94-1.07)
    d = train[0]
    for field, x in enumerate((d.states, d.velocities, d.accelerations)):
        assert 0.9 < field_noise(d, field) / (0.01 * np.sqrt(np.mean(x * x))) < 1.1


def test_concatenated_trajectories_are_split_at_their_starts():
    """One data set of four runs side by side (no times, the sampling step in its diagnostics) is the
    same problem as the list of runs: the same costs to round-off."""
    from femrom.inference import concatenate

    system = SYSTEMS["duffing2"]()
    train, _ = system.training(noise=0.01, seed=3)
    settings = OutputError(iterations=1)
    free = ("stiffness", "learned_potential")
    listed = output_error_refinement(system.operators, train, free, settings=settings)
    joined = output_error_refinement(system.operators, concatenate(train), free, settings=settings)
    assert concatenate(train).times is None
    assert joined["cost_before"] == pytest.approx(listed["cost_before"], rel=1e-12)
    assert joined["cost"] == pytest.approx(listed["cost"], rel=1e-9)


def test_bad_settings_and_impossible_requests_are_refused_in_one_line():
    from _required import extra

    extra("torch")
    from femrom._errors import FemromValueError
    from femrom.inference import SpML, SpMLConfig

    with pytest.raises(FemromValueError, match="output_error must be True, False or 'auto'"):
        SpMLConfig(output_error="yes")
    with pytest.raises(FemromValueError, match="OutputError.substeps"):
        OutputError(substeps=0)
    with pytest.raises(FemromValueError, match="output_error_iterations"):
        SpMLConfig(output_error_iterations=0)
    # sliders carry a state the sensitivities do not follow: refused before the fit, not after it
    system = SYSTEMS["duffing2"]()
    train, _ = system.training()
    learner = SpML(["damping", "hysteresis"], config=SpMLConfig(output_error=True), smoothing=None, progress=False)
    with pytest.raises(FemromValueError, match="output_error=True is not possible with sliders"):
        learner.fit(train)


def test_spml_refines_a_forced_model_and_its_input_map():
    """SpML's defaults on forced runs with 1 % noise (the Duffing pair driven through ``B = (1, 0.5)`` by
    sines of four amplitudes and frequencies, from rest): the output-error stage (inputs interpolated to
    its substeps, ``B^`` among its parameters) against the smoothing alone. Observed: force 3.4e-4
    against 2.1e-3, an unseen forcing predicted within 3.6e-4 against 1.7e-3, ``B^`` within 8e-4
    against 7e-3."""
    from _required import extra

    extra("torch")
    from femrom.inference import SpML, SpMLConfig
    from femrom.integrators import march
    from femrom.rom import SecondOrderROM

    duffing = SYSTEMS["duffing2"]().operators
    B = np.array([[1.0], [0.5]])
    truth = ReducedOperators.from_matrices(duffing.stiffness, damping=duffing.damping, input_matrix=B,
                                           nonlinear=duffing.term("learned_potential"))
    dt, n, sub = 0.05, 400, 32

    def run(amplitude, frequency, noise=0.0, seed=0):
        fine = (dt / sub) * np.arange(sub * n + 1)
        u = amplitude * np.sin(frequency * fine)[None, :]
        out = march(truth.system, "discrete_gradient", fine, np.zeros(2), np.zeros(2), inputs=u)
        Q, V, U = out["q"][:, ::sub], out["v"][:, ::sub], u[:, ::sub]
        A = _Problem._acceleration(truth, Q, V, U)
        rng = np.random.default_rng(seed)
        Q, V, A = (x + noise * np.sqrt(np.mean(x * x)) * rng.standard_normal(x.shape) for x in (Q, V, A))
        return SecondOrderData(Q, V, A, inputs=U, times=dt * np.arange(n + 1))

    train = [run(a, w, 0.01, i) for i, (a, w) in enumerate([(0.5, 0.9), (1.0, 1.3), (1.5, 0.7), (0.8, 1.7)])]
    validation, test = run(1.2, 1.1, 0.01, 10), run(1.3, 1.0)
    t = (dt / 8) * np.arange(8 * n + 1)
    results = {}
    for name, options in (("smoothed", {"output_error": False}), ("default", {})):
        learner = SpML(["damping", "input"], config=SpMLConfig(seed=0, **options), progress=False).fit(
            train, validation=validation)
        q = SecondOrderROM(learner.operators_).predict(t, inputs=1.3 * np.sin(t)[None, :], initial=(np.zeros(2),
                                                       np.zeros(2)), scheme="discrete_gradient").q[:, ::8]
        results[name] = {"force": spml_error_split(learner.operators_, truth, train, test).potential,
                         "prediction": np.linalg.norm(q - test.states) / np.linalg.norm(test.states),
                         "input": np.linalg.norm(learner.operators_.input_matrix - B) / np.linalg.norm(B),
                         "stages": [s["stage"] for s in learner.stages_ if s.get("kept")]}
    assert "output error" in results["default"]["stages"], results
    for key in ("force", "prediction", "input"):
        assert results["default"][key] < 0.5 * results["smoothed"][key], (key, results)
    assert results["default"]["force"] < 1e-3 and results["default"]["input"] < 2e-3, results
