"""The full contact law in time stepping: the discrete energy balance of every step.

``dry_friction`` (unilateral penalty, elastic Coulomb sliders) has an energy-consistent step
traction (:meth:`DryFrictionLaw.step_traction`) that :class:`DiscreteGradient` balances: the
step's input work minus its dissipation minus the change of kinetic, elastic and joint stored
energy is never negative (the step may dissipate numerically, never create energy). The
trapezoidal rule (Newmark average acceleration) creates energy when a penalty pair opens or
closes within a step; these tests show both, on two masses that bounce and slide on the
ground, for the full (sparse) model and for a Galerkin model of it, and that in pure stick the
new step is the old one to round-off.
"""

import numpy as np
import pytest
import scipy.sparse as sp

from femrom.fem import DryFrictionLaw, JointForce
from femrom.inference import galerkin
from femrom.integrators import DiscreteGradient, EnergyBalance, Newmark, Newton, integrate
from femrom.scene import SecondOrderSystem, Signal, SignalVector

LAW = DryFrictionLaw(normal_stiffness=1e5, tangential_stiffness=3e4, friction_coefficient=0.5)
#: Newton to 1e-13: the balance's round-off and Newton floor is then ~1e-15 of the energy scale
NEWTON = Newton(rtol=1e-13)


def random_steps(law, n=4000, seed=0):
    """Gap pairs ``(g0, g1)`` from small to large steps, sliders committed at ``g0``: stick, slip,
    opening, closing and open points all occur."""
    rng = np.random.default_rng(seed)
    g0 = rng.normal(size=(n, 3)) * 1e-3
    g1 = g0 + rng.normal(size=(n, 3)) * 1e-3 * rng.choice([1e-3, 0.1, 1.0, 3.0], size=(n, 1))
    z = law.commit(g0, rng.normal(size=(n, 2)) * 1e-3)
    return g0, g1, z


def law_balance(law, traction, g0, g1, z):
    """Per point: ``t . (g1 - g0) - Delta stored - dissipation`` and the scale ``stored + dissipation``."""
    z1 = law.commit(g1, z)
    stored0, stored1, dissipated = law.stored_energy(g0, z), law.stored_energy(g1, z1), law.dissipation(g1, z)
    work = np.einsum("si,si->s", traction, g1 - g0)
    return work - (stored1 - stored0) - dissipated, stored0 + stored1 + dissipated


def test_the_step_traction_never_does_less_work_than_the_law_stores_and_dissipates():
    """Pointwise, the step traction's work bounds the stored energy's change plus the dissipation
    (a perfect square, so zero only where it must be); the trapezoidal mean of the end tractions does
    not, by orders of magnitude, when points open or close (the old treatment)."""
    g0, g1, z = random_steps(LAW)
    closed0, closed1 = g0[:, 2] < 0, g1[:, 2] < 0
    assert np.sum(closed0 != closed1) > 100 and np.sum(closed0 & closed1) > 100    # both kinds present
    new, _ = LAW.step_traction(g0, g1, z, tangent=False)
    residual, scale = law_balance(LAW, new, g0, g1, z)
    # round-off: the balance subtracts energies of size `scale`, each exact to ~1e-16 of it
    assert residual.min() >= -1e-13 * scale.max()
    t0, _ = LAW.evaluate(g0, z, tangent=False)
    t1, _ = LAW.evaluate(g1, z, tangent=False)
    old, _ = law_balance(LAW, 0.5 * (t0 + t1), g0, g1, z)
    assert old.min() < -1e-2 * scale.max()


def test_in_stick_the_step_traction_is_the_midpoint_traction_and_conserves():
    """Closed and stuck at both ends: the traction is the law's at the midpoint gap (the law is linear
    there), and its work is exactly the stored energy's change (no dissipation)."""
    rng = np.random.default_rng(1)
    g0 = np.column_stack([rng.normal(size=(50, 2)) * 1e-6, -1e-3 + rng.normal(size=50) * 1e-5])
    g1 = g0 + rng.normal(size=(50, 3)) * 1e-6
    z = np.zeros((50, 2))
    new, D = LAW.step_traction(g0, g1, z)
    mid, Dmid = LAW.evaluate(0.5 * (g0 + g1), z)
    assert np.allclose(new, mid, rtol=1e-14, atol=1e-14 * np.abs(mid).max())
    assert np.allclose(D, 0.5 * Dmid, rtol=1e-14)        # d/dg1 of the midpoint's traction
    residual, scale = law_balance(LAW, new, g0, g1, z)
    assert np.abs(residual).max() <= 1e-12 * scale.max()


def test_the_step_traction_tangent_is_its_derivative():
    """Central differences (step 1e-6 of the gap's 1e-3 scale: error ~1e-12 relative, far from the
    kinks, whose points are dropped) agree with the analytic tangent within 1e-6 of its largest entry,
    in stick, slip, opening and closing steps."""
    g0, g1, z = random_steps(LAW, n=600, seed=2)
    eps = 1e-9
    t, D = LAW.step_traction(g0, g1, z)
    numeric = np.empty_like(D)
    for j in range(3):
        plus, minus = g1.copy(), g1.copy()
        plus[:, j] += eps
        minus[:, j] -= eps
        numeric[:, :, j] = (LAW.step_traction(g0, plus, z, False)[0] - LAW.step_traction(g0, minus, z, False)[0]) \
            / (2 * eps)
    # away from the kinks: the status (open/closed, stick/slip) is the same at g1 +- 10 eps
    trial = LAW.tangential_stiffness * (g1[:, :2] - z)
    limit = LAW.friction_coefficient * LAW.normal_stiffness * np.maximum(-g1[:, 2], 0)
    smooth = (np.abs(g1[:, 2]) > 1e-7) & (np.abs(g1[:, 2] - g0[:, 2]) > 1e-7) \
        & (np.abs(np.hypot(*trial.T) - limit) > 1e-3 * limit.max())
    assert smooth.sum() > 400
    scale = np.abs(D).max()
    assert np.abs(D - numeric)[smooth].max() <= 1e-6 * scale


def two_masses(input_amplitude=0.0):
    """Two point masses (1 and 0.5 kg) joined by springs of 2e3 N/m, tied tangentially to the ground by
    50 N/m, falling under gravity onto it from 2 and 1 mm with a tangential throw; each meets the
    ground through one dry-friction pair (area 1 m^2, normals tilted off z). With
    ``input_amplitude``, a tangential sine force (30 Hz) on the first mass. Contact lasts about
    ``pi / sqrt(k_n / m) = 10`` ms, five steps of 2 ms: pairs open and close within steps."""
    ground = -np.ones((2, 3), dtype=np.int64)
    joint = JointForce(LAW, ground, np.array([[0, 1, 2], [3, 4, 5]]), np.array([[0.1, 0.0, 1.0], [0.0, -0.1, 1.0]]),
                       np.ones(2), 6, initial_gap=np.array([2e-3, 1e-3]), name="contact")
    M = sp.diags([1.0, 1.0, 1.0, 0.5, 0.5, 0.5], format="csr")
    K = sp.csr_matrix(np.kron(np.array([[1.0, -1.0], [-1.0, 1.0]]), np.eye(3)) * 2e3
                      + np.diag([50.0, 50.0, 0.0, 50.0, 50.0, 0.0]))
    load = np.array([0.0, 0.0, -9.81, 0.0, 0.0, -0.5 * 9.81])
    B = np.zeros((6, 1))
    B[0, 0] = 1.0
    signal = SignalVector([Signal.from_dict({"kind": "sine", "amplitude": input_amplitude, "frequency": 30.0})])
    system = SecondOrderSystem(mass=M, stiffness=K, nonlinear=[joint], load=load, input_matrix=B, inputs=signal)
    return system, np.zeros(6), np.array([0.4, 0.1, -0.6, -0.3, 0.2, -0.2])


def galerkin_of(system, q0, v0, r=4, seed=3):
    """A Galerkin model on ``r`` random mass-orthonormal vectors, and the projected initial state."""
    V = np.linalg.qr(np.random.default_rng(seed).standard_normal((system.n_dofs, r)))[0]
    V = V @ np.linalg.inv(np.linalg.cholesky(V.T @ (system.mass @ V))).T
    return galerkin(system, V).system, V.T @ (system.mass @ q0), V.T @ (system.mass @ v0)


def balance(system, scheme, q0, v0, dt=2e-3, n_steps=300):
    """Per-step residuals over the energy scale (the largest kinetic energy), and the normal gaps."""
    record = EnergyBalance(system, scheme)
    gaps = []
    local = getattr(system.nonlinear, "transformed", system.nonlinear)     # a Galerkin model's: the same pairs
    pairs = getattr(local, "force_model", local)

    def gap(result):
        gaps.append(pairs.gaps(local.localize(result.q))[:, 2])             # no reference: no offset

    integrate(system, scheme, q0, v0, dt, n_steps, consumers=[record, gap], progress=False)
    return record.residual / record.kinetic.max(), np.array(gaps), record


@pytest.mark.parametrize("model", ["full", "galerkin"])
@pytest.mark.parametrize("forced", [False, True])
def test_bouncing_and_sliding_never_creates_energy_with_the_step_force(model, forced):
    """Per step: input work - Rayleigh - friction - Delta(kinetic + strain + joint stored) >= -1e-9 of
    the energy scale with DiscreteGradient and the step force (measured -1e-15: Newton and round-off),
    over 0.6 s of bouncing and sliding with ~20 contact changes within steps; Newmark's trapezoid on
    the same runs creates energy at several percent of the scale in a step (the old treatment: the
    test fails with it)."""
    system, q0, v0 = two_masses(40.0 if forced else 0.0)
    if model == "galerkin":
        system, q0, v0 = galerkin_of(system, q0, v0)
    new, gaps, record = balance(system, DiscreteGradient(newton=NEWTON), q0, v0)
    closed = gaps < 0
    assert np.sum(closed[1:] != closed[:-1]) >= 10            # pairs open and close, within steps
    assert record.friction[-1] > 0.05 * record.kinetic.max()  # and slide
    assert new.min() >= -1e-9
    old, _, _ = balance(system, Newmark(newton=NEWTON), q0, v0)
    assert old.min() < -1e-3


def test_in_pure_stick_the_new_step_is_the_trapezoidal_rule():
    """Both masses pressed 1 mm into the ground by 100 N each and held there (normals along z, friction 10),
    struck at 2 cm/s (amplitudes ~1e-4 m: no pair opens or slips):
    the law is linear along the run, the step force is the midpoint's, and the discrete-gradient run
    equals Newmark average acceleration (the trapezoidal rule) to round-off (1e-12 of the motion:
    Newton to 1e-13 and ~1e3 steps of round-off), as the midpoint and trapezoidal rules coincide on a
    linear model."""
    law = DryFrictionLaw(normal_stiffness=1e5, tangential_stiffness=3e4, friction_coefficient=10.0)
    system, _, _ = two_masses()
    joint = JointForce(law, -np.ones((2, 3), dtype=np.int64), np.array([[0, 1, 2], [3, 4, 5]]),
                       np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]), np.ones(2), 6,
                       initial_gap=np.array([-1e-3, -1e-3]), name="contact")
    load = np.array([0.0, 0.0, -100.0, 0.0, 0.0, -100.0])            # q = 0 is the equilibrium
    system = SecondOrderSystem(mass=system.mass, stiffness=system.stiffness, nonlinear=[joint], load=load)
    q0, v0 = np.zeros(6), np.array([0.02, 0.01, -0.01, -0.02, 0.01, 0.01])
    runs = {}
    for name, scheme in (("old", Newmark(newton=NEWTON)), ("new", DiscreteGradient(newton=NEWTON))):
        qs, states = [], []
        integrate(system, scheme, q0, v0, 1e-3, 1000, consumers=[lambda r: (qs.append(r.q), states.append(r.state))],
                  progress=False)
        runs[name] = np.array(qs)
        gaps = np.array([joint.gaps(joint.localize(q)) for q in qs])
        assert np.all(gaps[..., 2] < 0)                                          # never opens
        trial = law.tangential_stiffness * np.hypot(*(gaps[..., :2] - states[0]).transpose(2, 0, 1))
        assert np.all(trial < 0.1 * law.friction_coefficient * law.normal_stiffness * -gaps[..., 2])  # never slips
    scale = np.abs(runs["old"]).max()
    assert np.abs(runs["new"] - runs["old"]).max() <= 1e-12 * scale


def test_the_return_map_step_derivative_is_its_derivative():
    """``step_derivative`` (what harmonic balance carries over a period) against central differences of
    one step, traction and committed sliders, along random directions of the gap and the frozen sliders
    (step 1e-9 of the 1e-3 scale: error ~1e-7 relative from round-off; points within 1e-6 of a kink are
    dropped): within 1e-6 of the largest entry, in stick, slip and open points."""
    g0, g1, z = random_steps(LAW, n=600, seed=4)
    rng = np.random.default_rng(5)
    m = 2
    dgap, dz = rng.normal(size=(600, 3, m)) * 1e-3, rng.normal(size=(600, 2, m)) * 1e-3
    dtraction, dz_new = LAW.step_derivative(g1, z, dgap, dz)
    eps = 1e-6
    for j in range(m):
        plus = (g1 + eps * dgap[..., j], z + eps * dz[..., j])
        minus = (g1 - eps * dgap[..., j], z - eps * dz[..., j])
        dt_fd = (LAW.traction(*plus) - LAW.traction(*minus)) / (2 * eps)
        dzn_fd = (LAW.commit(*plus) - LAW.commit(*minus)) / (2 * eps)
        trial = LAW.tangential_stiffness * (g1[:, :2] - z)
        limit = LAW.friction_coefficient * LAW.normal_stiffness * np.maximum(-g1[:, 2], 0)
        smooth = (np.abs(g1[:, 2]) > 1e-6) & (np.abs(np.hypot(*trial.T) - limit) > 1e-3 * limit.max())
        assert smooth.sum() > 400
        assert np.abs(dtraction[..., j] - dt_fd)[smooth].max() <= 1e-6 * np.abs(dt_fd).max()
        assert np.abs(dz_new[..., j] - dzn_fd)[smooth].max() <= 1e-6 * np.abs(dzn_fd).max()


@pytest.mark.parametrize("amplitude", [0.01, 0.05])
def test_harmonic_balance_runs_the_full_law_with_its_exact_jacobian(amplitude):
    """Three nodes on the ground through dry-friction pairs pressed 0.02 in, coupled by springs: the AFT
    Jacobian of harmonic balance, carried by ``step_derivative`` over the sampled period, against central
    differences (step 1e-7 of the amplitude): measured 3.2e-9 and 1.3e-9 (slip; at 0.05 pairs also open),
    against 0.74 and 0.21 for the frozen-state tangent."""
    from femrom.integrators import HarmonicBalance

    pairs, n = 3, 9
    law = DryFrictionLaw(normal_stiffness=200.0, tangential_stiffness=100.0, friction_coefficient=0.5)
    force = JointForce(law, -np.ones((pairs, 3), dtype=int), np.arange(n).reshape(pairs, 3),
                       np.tile([0.0, 0.0, 1.0], (pairs, 1)), np.linspace(1.0, 1.5, pairs), n,
                       first_tangents=[1.0, 0.0, 0.0], initial_gap=-0.02)
    A = 0.1 * np.random.default_rng(1).standard_normal((n, n))
    K = 40.0 * np.eye(n) + 10.0 * A @ A.T
    b = np.zeros((n, 1))
    b[[0, 4, n - 2], 0] = (1.0, 0.6, -0.4)
    system = SecondOrderSystem(mass=sp.identity(n, format="csr"), stiffness=sp.csr_matrix(K),
                               damping=sp.csr_matrix(0.01 * K), input_matrix=b, nonlinear=force)
    exact = HarmonicBalance(system, 0, harmonics=3, samples=32)
    frozen = HarmonicBalance(system, 0, harmonics=3, samples=32, tangent="frozen")
    rng = np.random.default_rng(0)
    Z = 0.15 * amplitude * rng.standard_normal((exact.basis.size, exact.n_dofs))
    Z[0] = 0.0
    Z[1:3] += amplitude * rng.standard_normal((2, exact.n_dofs))
    z, omega, h = Z.reshape(-1), 2 * np.pi, 1e-7 * amplitude
    columns = []
    for i in range(z.size):
        e = np.zeros(z.size)
        e[i] = h
        columns.append((exact.aft(z + e, omega, jacobian=False).coefficients
                        - exact.aft(z - e, omega, jacobian=False).coefficients).reshape(-1) / (2 * h))
    J_fd = np.array(columns).T
    scale = np.abs(J_fd).max()
    assert np.abs(exact.aft(z, omega).jacobian - J_fd).max() <= 1e-7 * scale
    assert np.abs(frozen.aft(z, omega).jacobian - J_fd).max() >= 1e-2 * scale
