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
from femrom.integrators import DiscreteGradient, Newton, march
from femrom.integrators import _fused
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


def predicted(rom, q0, v0, compiled, inputs=None, **newton):
    use_compiled_laws(compiled)
    try:
        t = DT * np.arange(STEPS + 1)
        scheme = DiscreteGradient(newton=Newton(**{"rtol": 1e-10, **newton}))
        return rom.predict(t, inputs, initial=(q0, v0), scheme=scheme)
    finally:
        use_compiled_laws(True)


def _sine(inputs):
    return np.sin(2.0 * DT * np.arange(STEPS + 1))[None, :] if inputs else None


@pytest.mark.parametrize("r, damped, inputs", [(3, True, True), (5, False, False), (8, True, False)])
def test_the_fused_discrete_gradient_step_is_the_numpy_step(r, damped, inputs):
    """Newton at every iterate (``refactor_ratio = 0``): the compiled march and the compiled step called
    step by step are the numpy reference's steps, iteration for iteration."""
    rom, q0, v0 = model(r, damped, inputs)
    u = _sine(inputs)
    fast, reference = predicted(rom, q0, v0, True, u, refactor_ratio=0.0), predicted(rom, q0, v0, False, u)
    assert fast.info["newton_iterations"] == reference.info["newton_iterations"] > 2 * STEPS
    assert fast.info["newton_jacobians"] == fast.info["newton_iterations"]     # one a Newton iteration
    t = DT * np.arange(STEPS + 1)
    stepped = march(rom.model, DiscreteGradient(newton=Newton(rtol=1e-10)), t, q0, v0,
                    inputs=u, whole=False)
    assert stepped["path"] == "steps" and stepped["newton_iterations"] == reference.info["newton_iterations"]
    for name in ("q", "v", "a", "energy"):
        _close(getattr(fast, name), getattr(reference, name))
    for name in ("q", "v", "a"):
        _close(stepped[name], getattr(reference, name))
    assert np.abs(reference.q).max() > 0.1


#: How far the chord march's trajectory may be from the reference's, relative to its largest entry: each
#: step's solution is within ``rtol`` (relative) of the same fixed point on both paths (the update test, with
#: the chord's contraction at most ``refactor_ratio``), and the stable step map carries each step's difference
#: on: at most ``STEPS * rtol`` over the run.
def _chord_tolerance(rtol):
    return STEPS * rtol


@pytest.mark.parametrize("r, damped, inputs", [(3, True, True), (5, False, False), (8, True, False)])
@pytest.mark.parametrize("rtol", [1e-10, 1e-7])
def test_the_chord_march_converges_to_the_numpy_steps(r, damped, inputs, rtol):
    """The default march: the chord iteration (the Jacobian formed once a step or held, the predictor from the
    extrapolated learned force) reaches the reference's fixed point to the Newton tolerance, with fewer
    Jacobians (the Hessians at the Gauss nodes) than the reference's one a Newton iteration."""
    rom, q0, v0 = model(r, damped, inputs)
    u = _sine(inputs)
    fast, reference = predicted(rom, q0, v0, True, u, rtol=rtol), predicted(rom, q0, v0, False, u, rtol=rtol)
    tolerance = _chord_tolerance(rtol)
    for name in ("q", "v", "a"):
        x, y = getattr(fast, name), getattr(reference, name)
        np.testing.assert_allclose(x, y, rtol=0.0, atol=tolerance * np.abs(y).max())
    np.testing.assert_allclose(fast.energy, reference.energy, rtol=0.0, atol=tolerance * reference.energy.max())
    # honest counts: at least one update a step, at most one Jacobian an update, and far fewer than Newton's
    its, jacobians = fast.info["newton_iterations"], fast.info["newton_jacobians"]
    assert its >= STEPS and 1 <= jacobians <= its
    assert jacobians < 0.5 * reference.info["newton_iterations"]


def test_the_chord_counts_are_per_step_and_the_jacobian_once_a_step_when_not_held(monkeypatch):
    """The march's per-step counts: the sums ``march`` reports; at least one Jacobian a step (formed at each
    step's first iterate), fewer when it is held across steps."""
    rom, q0, v0 = model(3, True, True)
    u = _sine(True)
    t = DT * np.arange(STEPS + 1)
    cache = DiscreteGradient().init(rom.model, DT, None, lambda: None, 0.0, q0, v0, None, None)
    fused = cache.fused
    forcing = rom.model.input_matrix @ (0.5 * (u[:, 1:] + u[:, :-1]))     # at t_k + h/2, as march samples it
    ends = rom.model.input_matrix @ u[:, 1:]
    system = rom.model
    a0 = np.linalg.solve(system.mass, system.input_matrix @ u[:, 0] - system.damping @ v0 - system.stiffness @ q0
                         - system.nonlinear.force(q0, v0, system.nonlinear.initial_state()))
    out = march(rom.model, DiscreteGradient(), t, q0, v0, inputs=u)
    Q, V, A, _, its, jacs = fused.march(q0, v0, a0, None, forcing, STEPS, forces_end=ends)
    assert its.shape == jacs.shape == (STEPS,) and np.all(its >= 1) and np.all(jacs <= its)
    assert its.sum() == out["newton_iterations"] and jacs.sum() == out["jacobians"]
    np.testing.assert_allclose(Q, out["q"], rtol=0.0, atol=1e-13 * np.abs(Q).max())
    # by default at least one a step (more where a step contracts slowly and turns to Newton: the opening
    # transient)
    assert np.all(jacs >= 1) and np.mean(jacs == 1) > 0.8
    monkeypatch.setattr(_fused, "HOLD_UPDATES", 2)
    Q2, _, _, _, its2, jacs2 = fused.march(q0, v0, a0, None, forcing, STEPS, forces_end=ends)
    assert np.all(jacs2 <= its2) and np.any(jacs2 == 0) and jacs2.sum() < jacs.sum()   # held across steps
    np.testing.assert_allclose(Q2, Q, rtol=0.0, atol=_chord_tolerance(1e-10) * np.abs(Q).max())


def test_the_chord_march_keeps_the_energy_balance():
    """Multiplying the step by ``q_{k+1} - q_k = h v_m``: ``E_{k+1} - E_k = h v_m . (F_{k+1/2} - C v_m - grad
    F(v_m))`` up to the Newton residual, on the chord march as on the reference; without input and damping,
    ``E`` is conserved."""
    for damped, inputs in ((True, True), (False, False)):
        rom, q0, v0 = model(4, damped, inputs)
        u = _sine(inputs)
        s = predicted(rom, q0, v0, True, u)
        system = rom.model
        vm = 0.5 * (s.v[:, 1:] + s.v[:, :-1])
        power = np.zeros(STEPS)
        if inputs:
            power += np.einsum("ik,ik->k", vm, system.input_matrix @ (0.5 * (u[:, 1:] + u[:, :-1])))
        if damped:
            power -= np.einsum("ik,ik->k", vm, system.damping @ vm)
            dissipation = [f for f in system.nonlinear.terms if not f.conservative][0]
            power -= np.array([vm[:, k] @ dissipation.force(None, vm[:, k]) for k in range(STEPS)])
        balance = np.diff(s.energy) - DT * power
        assert np.abs(balance).max() <= 1e-11 * np.abs(s.energy).max(), np.abs(balance).max()
        if not damped and not inputs:
            assert np.abs(s.energy - s.energy[0]).max() <= 1e-11 * s.energy[0]


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


def test_the_kernels_lu_factors_solve_with_row_exchanges():
    """The chord march solves with factors formed once (``_lu_factor``, ``_lu_back``): a matrix that needs
    row exchanges at every column, against numpy."""
    from femrom.fem import _scalar_kernels_numba as kernels

    rng = np.random.default_rng(3)
    for n in (1, 4, 9):
        A = rng.standard_normal((n, n)) + np.diag(np.linspace(1e-3, 1e-2, n))
        A = A[::-1].copy()
        b = rng.standard_normal(n)
        LU, pivots = A.copy(), np.zeros(n, dtype=np.int64)
        assert kernels._lu_factor(LU, pivots)
        x = b.copy()
        kernels._lu_back(LU, pivots, x)
        np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)
    assert not kernels._lu_factor(np.zeros((2, 2)), np.zeros(2, dtype=np.int64))


@pytest.mark.parametrize("refactor_ratio", [0.1, 0.0])
def test_a_march_that_cannot_converge_raises_the_reference_error(refactor_ratio):
    """A chord step that fails is redone by Newton; one that still fails raises the reference's error."""
    from femrom.integrators import ConvergenceError

    rom, q0, v0 = model(3)
    for compiled in (True, False):
        with pytest.raises(ConvergenceError, match=r"step 1 \(t = 0.05\): Newton did not converge in 1 iterations"):
            predicted(rom, q0, v0, compiled, max_iterations=1, refactor_ratio=refactor_ratio)
