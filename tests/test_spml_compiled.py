"""SpML's learned terms compiled: the kernels' value, gradient and Hessian against the numpy reference
(:mod:`femrom.inference._networks`), and the fused discrete-gradient step against the numpy step.

Sums run in loops where numpy calls BLAS, so the paths agree to round-off, not bit for bit:
``ROUND_OFF`` relative to the largest entry, far above the few hundred ulps a sum over the 32-wide
layers and r^4 monomial products can lose, far below any difference a wrong index or factor makes.
"""

import numpy as np
import pytest

from femrom.fem import compiled_scalar_kernels, use_compiled_laws
from femrom.inference import (ConvexPowers, LearnedDissipation, LearnedPotential, NetworkLayer, ReducedOperators,
                              ScalarNetwork, SymmetricPolynomial, LearnedHysteresis, multi_indices)
from femrom.integrators import DiscreteGradient, Newton
from femrom.integrators._fused import FusedDiscreteGradientStep
from femrom.rom import SecondOrderROM
from tests._required import extra

extra("numba")

ROUND_OFF = 1e-11
STEPS, DT = 120, 0.05


@pytest.fixture(autouse=True)
def _compiled_on():
    previous = use_compiled_laws(True)
    yield
    use_compiled_laws(previous)


def network(rng, r, widths, activation, convex=False, skip=False):
    layers, previous = [], None
    for w in widths:
        weight = None if previous is None else rng.standard_normal((w, previous)) / np.sqrt(previous)
        if convex and weight is not None:
            weight = np.abs(weight)
        inputs = rng.standard_normal((w, r)) if previous is None or skip else None
        layers.append(NetworkLayer(0.3 * rng.standard_normal(w), weight, inputs))
        previous = w
    output = rng.standard_normal(previous)
    return ScalarNetwork(layers, np.abs(output) if convex else output, activation)


def potential(rng, r, widths=(32, 32)):
    """The default shape: every cubic and quartic monomial (quartic coercive) and a tanh MLP."""
    terms = {d: (multi_indices(r, d), 0.1 * rng.standard_normal(len(multi_indices(r, d)))) for d in (3, 4)}
    index, c = terms[4]
    terms[4] = (index, np.where(np.all(index == index[:, :1], axis=1), 1.0, 0.1 * c))
    return LearnedPotential(r, SymmetricPolynomial(r, terms), network(rng, r, widths, "tanh"))


def dissipation(rng, r, widths=(16,)):
    return LearnedDissipation(r, ConvexPowers(rng.standard_normal((2, r)), rng.standard_normal((3, r))),
                              network(rng, r, widths, "softplus", convex=True, skip=True))


def _close(x, reference, floor=0.0):
    """Equal to ``ROUND_OFF`` of the largest entry (or of ``floor``: the value and gradient vanish at 0, their
    round-off is that of the network's shift by ``N(0)``, of order one here)."""
    np.testing.assert_allclose(x, reference, rtol=0.0, atol=ROUND_OFF * max(np.abs(reference).max(), floor))


@pytest.mark.parametrize("r", [1, 3, 8])
def test_kernels_are_the_numpy_value_gradient_and_hessian(r):
    rng = np.random.default_rng(r)
    terms = (potential(rng, r), dissipation(rng, r), dissipation(rng, r, widths=(6, 5)),
             LearnedPotential(r, network=network(rng, r, (7, 4, 3), "tanh", skip=True)))
    for term in terms:
        for x in (rng.standard_normal(r), np.zeros(r), 3.0 * rng.standard_normal(r)):
            use_compiled_laws(True)
            compiled = term._at(x), term._at.value(x + 0.1)
            use_compiled_laws(False)
            reference = term.function.value_gradient_hessian(x), term.function.value(x + 0.1)
            for a, b in zip(compiled[0], reference[0]):
                _close(a, b, floor=1.0)
            _close(compiled[1], reference[1], floor=1.0)


def model(r, damped=True, inputs=False, seed=0):
    rng = np.random.default_rng(seed + r)
    A = rng.standard_normal((r, r))
    K = A @ A.T + r * np.eye(r)
    G = rng.standard_normal((r, 2))
    L = np.tril(rng.standard_normal((r, r)), -1) + np.diag(rng.uniform(0.8, 1.2, r))
    ops = ReducedOperators.from_matrices(K, mass=L @ L.T, damping=0.05 * G @ G.T if damped else None,
                                         input_matrix=rng.standard_normal((r, 1)) if inputs else None)
    terms = [potential(rng, r)] + ([dissipation(rng, r)] if damped else [])
    amplitude = 0.5 / np.sqrt(r)                 # |q0|, |v0| about 0.5: nonlinear, within reach of Newton
    q0, v0 = amplitude * rng.standard_normal(r), amplitude * rng.standard_normal(r)
    return SecondOrderROM(ops.with_terms(*terms)), q0, v0


def predicted(rom, q0, v0, compiled, inputs=None):
    use_compiled_laws(compiled)
    try:
        t = DT * np.arange(STEPS + 1)
        return rom.predict(t, inputs, initial=(q0, v0), scheme=DiscreteGradient(newton=Newton(rtol=1e-10)))
    finally:
        use_compiled_laws(True)


@pytest.mark.parametrize("r, damped, inputs", [(3, True, True), (5, False, False), (8, True, False)])
def test_the_fused_discrete_gradient_step_is_the_numpy_step(r, damped, inputs):
    rom, q0, v0 = model(r, damped, inputs)
    u = np.sin(2.0 * DT * np.arange(STEPS + 1))[None, :] if inputs else None
    fast, reference = predicted(rom, q0, v0, True, u), predicted(rom, q0, v0, False, u)
    assert fast.info["newton_iterations"] == reference.info["newton_iterations"] > 2 * STEPS
    for name in ("q", "v", "a", "energy"):
        _close(getattr(fast, name), getattr(reference, name))
    assert np.abs(reference.q).max() > 0.1


def test_the_scheme_finds_the_compiled_step_and_only_when_it_can():
    rom, q0, v0 = model(3)
    scheme = DiscreteGradient()

    def fused(system):
        return scheme.init(system, DT, None, lambda: None, 0.0, q0, v0, None, None).fused

    assert isinstance(fused(rom.model), FusedDiscreteGradientStep)
    use_compiled_laws(False)
    assert compiled_scalar_kernels() is None and fused(rom.model) is None
    assert predicted(rom, q0, v0, False).info["newton_iterations"] > 0
    use_compiled_laws(True)
    # a summand without a compiled form (stateful sliders) keeps the numpy step
    rng = np.random.default_rng(1)
    sliders = LearnedHysteresis(rng.standard_normal(3), np.geomspace(1e-3, 1e-1, 4), np.ones(4))
    ops = ReducedOperators.from_matrices(np.eye(3)).with_terms(potential(rng, 3), sliders)
    assert fused(ops.system) is None
