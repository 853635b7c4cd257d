"""The Hunt-Crossley normal dashpot at the reclosed points of the clamped Iwan law (``closing_damping = lambda``,
``t_n = min(kappa k_n g_n - lambda g_n gdot_n, 0)``): the law and its derivatives, the joint force's damping tangent, the Newmark march's energy balance, harmonic balance's
exact Jacobian and its agreement with the march, and EPMC's damping against the first-order estimate."""

import numpy as np
import pytest
import scipy.sparse as sp

from femrom.fem import (
    JointForce,
    force_from_parameters,
    interface_law_from_parameters,
    transform_force,
)
from femrom.fem.interface_laws.clamped_iwan import ClampedIwanLaw
from femrom.inference import ProjectedNonlinearForce
from femrom.integrators import (
    EnergyBalance,
    HarmonicBalance,
    Newmark,
    Newton,
    epmc,
    integrate,
)
from femrom.scene import SecondOrderSystem

PAIRS = 3
KAPPA, MU_C = 0.5, 0.3


def law(lam=0.0, closing=KAPPA, **extra):
    return ClampedIwanLaw(normal_stiffness=200.0, tangential_stiffness=100.0, chi=-0.5, beta=0.2, n_sliders=8,
                          **{"closing_friction": MU_C, **extra}, closing=closing, closing_damping=lam)


def preload_state(L):
    """Point 0 closed at the preload (macro-slip traction 1), points 1 and 2 open: they reclose."""
    N = L.n_elements
    state = np.zeros((PAIRS, N + 1, 2))
    state[0, N] = (1.0, 1.0)
    return state


def joint(L, gaps=(-0.005, 0.005, 0.01)):
    n = 3 * PAIRS
    return JointForce(L, -np.ones((PAIRS, 3), dtype=int), np.arange(n).reshape(PAIRS, 3),
                      np.tile([0.0, 0.0, 1.0], (PAIRS, 1)), np.linspace(1.0, 1.5, PAIRS), n,
                      initial_gap=np.array(gaps), first_tangents=[1.0, 0.0, 0.0])


def stiffness():
    n = 3 * PAIRS
    A = 0.1 * np.random.default_rng(1).standard_normal((n, n))
    return 40.0 * np.eye(n) + 10.0 * A @ A.T


def system(force, damping=0.01, basis=None):
    """Three nodes over a rigid ground through the joint, coupled by springs, forced in 3-D."""
    n = 3 * PAIRS
    K = stiffness()
    b = np.zeros((n, 1))
    b[[0, 4, 3 * PAIRS - 1], 0] = (1.0, 0.6, -0.4)
    C = None if damping is None else damping * K
    if basis is None:
        return SecondOrderSystem(mass=sp.identity(n, format="csr"), stiffness=sp.csr_matrix(K),
                                 damping=None if C is None else sp.csr_matrix(C), input_matrix=b, nonlinear=force)
    V = basis
    return SecondOrderSystem(mass=V.T @ V, stiffness=V.T @ K @ V, damping=None if C is None else V.T @ C @ V,
                             input_matrix=V.T @ b, nonlinear=force)


def reclosed_gap(L):
    """(gap, state) of two points: closed at the preload, and reclosed in partial slip (its friction active)."""
    N = L.n_elements
    state = np.zeros((2, N + 1, 2))
    state[0, N] = (1.0, 1.0)
    gap = np.array([[1e-3, -2e-3, -1e-3], [2e-4, 1e-4, -4e-3]])
    return gap, state


# -- the law --------------------------------------------------------------------------------------------
def test_without_damping_the_law_and_the_joint_are_unchanged():
    plain = ClampedIwanLaw(200.0, 100.0, -0.5, 0.2, n_sliders=8, closing=KAPPA, closing_friction=MU_C)
    zero = law(0.0)
    assert zero == plain and zero.closing_damping == 0.0 and not zero.velocity_dependent
    assert law(2.0).velocity_dependent and not ClampedIwanLaw(200.0, 100.0, -0.5, 0.2, closing_damping=2.0) \
        .velocity_dependent                                   # no reclosing, no dashpot
    gap, state = reclosed_gap(zero)
    t, D = plain.evaluate(gap, state)
    t0, D0, C0 = zero.evaluate_rate(gap, np.ones((2, 3)), state)
    assert np.array_equal(t, t0) and np.array_equal(D, D0) and C0 is None
    force = joint(zero)
    assert not force.velocity_dependent and force.local_tangent(np.zeros(9), np.ones(9), preload_state(zero))[1] \
        is None
    x, v = 1e-3 * np.arange(9.0), np.ones(9)
    assert np.array_equal(force.local_force(x, v, preload_state(zero)), joint(plain).local_force(x, None,
                                                                                                preload_state(zero)))
    with pytest.raises(ValueError, match=r"ClampedIwanLaw: closing_damping must be >= 0, got -1\.0"):
        law(-1.0)


def test_the_dashpot_traction_is_compressive_and_its_tangents_are_the_derivatives():
    lam = 750.0                                          # lambda p = 3 at the reclosed point's 4 mm penetration
    L = law(lam)
    gap, state = reclosed_gap(L)
    state = L.commit(0.3 * gap, state)                   # then away from it: sliders clearly stuck or slipping
    rate = np.array([[0.5, 0.2, -0.3], [0.1, -0.2, -0.02]])
    elastic, D0 = L.evaluate(gap, state)
    t, D, C = L.evaluate_rate(gap, rate, state)
    # closed at the preload: unchanged; reclosed: kappa k_n g_n - lambda g_n gdot_n, friction at the elastic pressure
    assert np.array_equal(t[0], elastic[0]) and np.array_equal(t[1, :2], elastic[1, :2])
    assert t[1, 2] == pytest.approx(KAPPA * 200.0 * -4e-3 - lam * -4e-3 * -0.02, rel=1e-14)
    # the tangents: kappa k_n - lambda gdot_n (115 against the penalty's 100) and -lambda g_n = lambda p
    assert D[1, 2, 2] == pytest.approx(KAPPA * 200.0 + lam * 0.02, rel=1e-14)
    assert np.array_equal(np.delete(D.reshape(-1), 2 * 9 - 1), np.delete(D0.reshape(-1), 2 * 9 - 1))
    assert C[1, 2, 2] == pytest.approx(lam * 4e-3, rel=1e-14) and np.count_nonzero(C) == 1
    assert L.damping_power(gap, rate, state)[1] == pytest.approx(lam * 4e-3 * 0.02**2, rel=1e-14)
    h = 1e-9
    for k in range(3):
        e = np.zeros((2, 3))
        e[:, k] = h
        fd_gap = (L.evaluate_rate(gap + e, rate, state, False)[0] - L.evaluate_rate(gap - e, rate, state, False)[0])
        fd_rate = (L.evaluate_rate(gap, rate + e, state, False)[0] - L.evaluate_rate(gap, rate - e, state, False)[0])
        assert np.allclose(D[:, :, k], fd_gap / (2 * h), rtol=1e-6, atol=1e-6)
        assert np.allclose(C[:, :, k], fd_rate / (2 * h), rtol=1e-6, atol=1e-6)
    # continuous at a touch: closing fast (gdot_n = -10), the traction tends to zero with the penetration
    touch = gap.copy()
    for p in (1e-4, 1e-6, 1e-8):
        touch[1, 2] = -p
        fast = rate.copy()
        fast[1, 2] = -10.0
        assert L.evaluate_rate(touch, fast, state)[0][1, 2] == pytest.approx(-(KAPPA * 200.0 + lam * 10.0) * p)
    # separating faster than kappa k_n / lambda = 0.133 (at any penetration): no pull, zero traction and zero
    # normal derivatives
    pulling = rate.copy()
    pulling[1, 2] = 0.2
    t, D, C = L.evaluate_rate(gap, pulling, state)
    assert t[1, 2] == 0.0 and D[1, 2, 2] == 0.0 and C[1, 2, 2] == 0.0 and np.array_equal(t[1, :2], elastic[1, :2])
    e = np.zeros((2, 3))
    e[1, 2] = 1e-9
    assert L.evaluate_rate(gap + e, pulling, state)[0][1, 2] == 0.0 == L.evaluate_rate(gap, pulling + e, state)[0][1, 2]
    # then it dissipates -kappa k_n g_n gdot_n (less than -lambda g_n gdot_n^2), never a negative power
    assert L.damping_power(gap, pulling, state)[1] == pytest.approx(KAPPA * 200.0 * 4e-3 * 0.2, rel=1e-14)
    assert L.damping_power(gap, pulling, state)[1] < lam * 4e-3 * 0.2**2
    rates = np.random.default_rng(0).standard_normal((200, 2, 3))
    assert min(L.damping_power(gap, r, state).min() for r in rates) >= 0.0
    # the step derivative with the rate's derivative, and its gap part alone (no drate)
    rng = np.random.default_rng(2)
    dgap, drate = rng.standard_normal((2, 3, 3)), rng.standard_normal((2, 3, 3))
    dstate = np.zeros(state.shape + (3,))
    for r in (rate, pulling):
        _, D, C = L.evaluate_rate(gap, r, state)
        dt, _ = L.step_derivative(gap, state, dgap, dstate, rate=r, drate=drate)
        assert np.allclose(dt, np.einsum("sij,sjm->sim", D, dgap) + np.einsum("sij,sjm->sim", C, drate),
                           rtol=1e-12, atol=1e-12)
        dt, _ = L.step_derivative(gap, state, dgap, dstate, rate=r)
        assert np.allclose(dt, np.einsum("sij,sjm->sim", D, dgap), rtol=1e-12, atol=1e-12)
    dt, _ = L.step_derivative(gap, state, dgap, dstate)                  # no rate: the penalty's
    assert np.allclose(dt, np.einsum("sij,sjm->sim", D0, dgap), rtol=1e-12, atol=1e-12)


def test_the_damping_travels_with_the_parameters_and_the_restricted_joint():
    L = law(500.0)
    assert L.parameters()["closing_damping"] == 500.0
    assert interface_law_from_parameters({k: np.asarray(v) for k, v in L.parameters().items()}) == L
    force = joint(L)
    again = force_from_parameters(force.parameters())
    assert again.law == L and again.velocity_dependent
    part = force.restricted(np.array([1, 2]), np.array([1.0, 2.0]))
    assert part.velocity_dependent and part.law.closing_damping == 500.0
    shifted = transform_force(force, None, reference=1e-3 * np.ones(9))
    assert shifted.velocity_dependent and shifted.step_derivative_rates
    basis = np.linalg.qr(np.random.default_rng(0).standard_normal((9, 4)))[0]
    projected = ProjectedNonlinearForce(force, basis)
    assert projected.velocity_dependent
    h5py = pytest.importorskip("h5py")
    with h5py.File("in_memory.h5", "w", driver="core", backing_store=False) as file:
        projected.save(file.create_group("term"))
        loaded = ProjectedNonlinearForce.load(file["term"], basis=basis)
    assert loaded.force_model.law == L and loaded.velocity_dependent
    # the joint's tangents at the damped normal entries: A_i lambda p (damping) and A_i (kappa k_n - lambda gdot_n)
    x = np.zeros(9)
    x[5] = -0.01                                          # pair 1 pressed 5 mm through its 5 mm gap
    xdot = np.zeros(9)
    xdot[5] = -0.1                                        # and closing
    K, C = force.local_tangent(x, xdot, preload_state(L))
    assert sp.issparse(C) and np.count_nonzero(C.toarray()) == 1 and C[5, 5] == pytest.approx(1.25 * 500 * 0.005)
    assert K[5, 5] == pytest.approx(1.25 * (KAPPA * 200 + 500 * 0.1))
    assert force.local_force(x, xdot, preload_state(L))[5] == pytest.approx(1.25 * (KAPPA * 200 * -0.005 - 0.25))


# -- harmonic balance --------------------------------------------------------------------------------------
def motion(hb, seed=0):
    rng = np.random.default_rng(seed)
    Z = 0.01 * rng.standard_normal((hb.basis.size, hb.n_dofs))
    Z[1:3] += 0.03 * rng.standard_normal((2, hb.n_dofs))
    return Z.reshape(-1)


def aft_differences(hb, z, omega, h):
    def F(z, omega):
        return hb.aft(z, omega, jacobian=False).coefficients.reshape(-1)
    J = np.array([(F(z + h * e, omega) - F(z - h * e, omega)) / (2 * h) for e in np.eye(z.size)]).T
    return J, (F(z, omega + h) - F(z, omega - h)) / (2 * h)


@pytest.mark.parametrize("model", ["full", "projected"])
def test_the_exact_aft_jacobian_carries_the_dashpot(model):
    """The AFT's exact Jacobian (the state's and the rates' derivatives carried through the march) and its Omega
    column against central differences, a closed point and two reclosing ones. Measured (H = 3, N = 16,
    lambda = 150): 4e-11 (full) and 7e-11 (projected about a reference) of the largest entry, the Omega column
    2.3e-8 and 3.3e-8 of its largest; the dashpot changes the Jacobian by 0.19 and 0.18 of it."""
    omega = 7.0
    out = {}
    for lam in (0.0, 150.0):                             # lambda p about 3 at the motion's 2 cm penetrations
        L = law(lam)
        if model == "full":
            sysm = system(joint(L))
        else:
            V = np.linalg.qr(np.random.default_rng(3).standard_normal((3 * PAIRS, 5)))[0]
            shifted = transform_force(joint(L), None, reference=1e-3 * np.ones(3 * PAIRS))
            sysm = system(ProjectedNonlinearForce(shifted, V), basis=V)
        hb = HarmonicBalance(sysm, 0, harmonics=3, samples=16, state=preload_state(L), tangent="exact")
        z = motion(hb)
        aft = hb.aft(z, omega)
        J_fd, dW_fd = aft_differences(hb, z, omega, 1e-7)
        out[lam] = J_fd, dW_fd
        scale = np.abs(J_fd).max()
        assert np.abs(aft.jacobian - J_fd).max() < 1e-8 * scale
        assert np.abs(aft.omega_derivative - dW_fd).max() < 1e-7 * max(np.abs(dW_fd).max(), 1e-300)
    assert np.abs(out[150.0][0] - out[0.0][0]).max() > 1e-2 * np.abs(out[0.0][0]).max()
    assert np.all(out[0.0][1] == 0) and np.abs(out[150.0][1]).max() > 1e-2


# -- time march -------------------------------------------------------------------------------------------
def ring_down(lam, dt=1e-3, steps=1500):
    """A free ring-down of the three-pair model, every pair open at the preload (they all reclose), no Rayleigh
    damping: the energy ledger, and per step the dashpot's power and ``sum_i A_i (-lambda g_n gdot_n^2)`` where it
    presses."""
    L = law(lam)
    force = joint(L, gaps=(0.004, 0.005, 0.01))
    model = system(force, damping=None)
    ledger = EnergyBalance(model)
    power, pressing = [], []

    def record(result):
        power.append(force.damping_power(result.q, result.v, result.state))
        if lam:
            gap, rate = force.gaps(force.localize(result.q)), force.rates(force.localize(result.v))
            damped = L._dashpot(gap, rate, result.state)[2]
            pressing.append(float(force.areas @ np.where(damped, -lam * gap[:, 2] * rate[:, 2] ** 2, 0.0)))
    v0 = np.zeros(9)
    v0[[0, 2, 4, 5, 8]] = (0.2, -0.3, -0.1, -0.25, -0.2)
    integrate(model, Newmark(newton=Newton(rtol=1e-12)), np.zeros(9), v0, dt, steps, consumers=[ledger, record],
              progress=False)

    def trapezoid(p):
        p = np.asarray(p)
        return dt * float(np.sum(0.5 * (p[1:] + p[:-1]))) if p.size else 0.0
    return ledger, trapezoid(power), trapezoid(pressing)


def test_the_march_balances_the_dashpot_work_and_decays_faster():
    """Newmark (average acceleration) balances, per step, the joint force's work against the change of its
    stored energy, the friction and the dashpot: the remainder is the scheme's (the penalty's kink when a
    point opens or closes inside a step). Measured (1.5 s, dt 1 ms, lambda = 150: lambda p about 1.8 at the
    12 mm mean penetration): the joint work less stored energy and friction 0.03947 against the dashpot's
    0.03930 (4e-3; with lambda = 0 the same remainder is 1.9e-3 of the initial energy 0.121); all of it is
    ``-lambda g_n gdot_n^2`` where the dashpot presses (the clamp acts only where a point separates faster than
    ``kappa k_n / lambda = 0.67``, which this motion never does); the energy left 0.062 against 0.100 without
    the dashpot."""
    plain, none, _ = ring_down(0.0)
    damped, work, pressing = ring_down(150.0)              # lambda p about 1.8 at the 12 mm mean penetration
    assert none == 0.0
    energy0 = plain.kinetic[0] + plain.strain[0] + plain.joint_energy[0]

    def remainder(ledger):
        return ledger.nonlinear_work[-1] - (ledger.joint_energy[-1] - ledger.joint_energy[0]) - ledger.friction[-1]
    assert abs(remainder(plain)) < 5e-3 * energy0
    assert abs(remainder(damped) - work) < 1e-2 * work
    # the ledger's own dashpot column is the same trapezoid of the same power; it closes the joint's balance
    # to the scheme's kink remainder (observed 1.4e-3 of the initial energy, 1.9e-3 without the dashpot;
    # without the column 0.33)
    assert damped.joint_damping[-1] == pytest.approx(work, rel=1e-12) and np.all(plain.joint_damping == 0.0)
    assert abs(np.sum(damped.joint_residual)) < 5e-3 * energy0 < abs(np.sum(damped.joint_residual) + work)
    assert work > 0.2 * energy0 and pressing == pytest.approx(work, rel=1e-12)
    assert np.all(np.abs(damped.scheme_residual) < 1e-9 * energy0)

    def left(ledger):
        return ledger.kinetic[-1] + ledger.strain[-1] + ledger.joint_energy[-1]
    assert left(damped) < 0.7 * left(plain)


def test_harmonic_balance_is_the_marched_steady_state():
    """A forced response (Rayleigh damping 0.05 K, force 2 at omega 6) with two pairs reclosing over part of the
    period: H = 7 against Newmark at 256 steps a period after 10 periods. Measured: fundamental phasors 3.3e-4
    apart (of the largest), the dashpot moving them by 7.2e-3 (lambda 200 against 100)."""
    import dataclasses

    from femrom.integrators import first_harmonic
    from femrom.scene import Signal, SignalVector

    omega, F = 6.0, 2.0
    phasors = {}
    for lam in (100.0, 200.0):                          # lambda p about 0.6 and 1.2 at the 6 mm mean penetration
        L = law(lam)
        force = joint(L, gaps=(0.002, 0.003, 0.004))
        model = system(force, damping=0.05)
        hb = HarmonicBalance(model, 0, harmonics=7, samples=112)
        Z = hb.solve(omega, F).coefficients
        phasors[lam] = Z[2] + 1j * Z[1]
    gaps = np.array([force.gaps(force.localize(q))[:, 2] for q in hb.basis.synthesis @ Z])
    assert np.sum(np.any(gaps < 0, axis=0)) >= 2
    period_steps, periods = 256, 10
    signal = SignalVector([Signal.from_dict({"kind": "sine", "amplitude": F, "frequency": omega / (2 * np.pi)})])
    q = []
    integrate(dataclasses.replace(model, inputs=signal), Newmark(newton=Newton(rtol=1e-12)), np.zeros(9), np.zeros(9),
              2 * np.pi / omega / period_steps, period_steps * periods, consumers=[lambda r: q.append(r.q.copy())],
              progress=False)
    marched = first_harmonic(np.array(q[-period_steps:]).T)
    scale = np.abs(phasors[200.0]).max()
    assert np.abs(marched - phasors[200.0]).max() < 1e-3 * scale
    assert np.abs(phasors[200.0] - phasors[100.0]).max() > 3e-3 * scale


# -- EPMC ----------------------------------------------------------------------------------------------------
def normal_model(lam):
    """Two nodes over the ground, their normal motion the first mode (about 0.8 Hz); pair 0 touches at rest, pair 1
    1 mm away: both reclose over part of the period (kappa k_n = 20, no friction)."""
    L = ClampedIwanLaw(200.0, 100.0, -0.5, 0.2, n_sliders=8, closing=0.1, closing_damping=lam)
    force = JointForce(L, -np.ones((2, 3), dtype=int), np.arange(6).reshape(2, 3), np.tile([0.0, 0.0, 1.0], (2, 1)),
                       np.array([1.0, 1.5]), 6, initial_gap=np.array([0.0, 1e-3]), first_tangents=[1.0, 0.0, 0.0])
    K = np.diag([60.0, 60.0, 30.0, 60.0, 60.0, 30.0])
    K[2, 5] = K[5, 2] = -10.0
    K[0, 2] = K[2, 0] = 3.0
    K[3, 5] = K[5, 3] = -2.0
    return force, SecondOrderSystem(mass=sp.identity(6, format="csr"), stiffness=sp.csr_matrix(K),
                                    damping=sp.csr_matrix(0.01 * K), nonlinear=force)


LAM_SMALL, LAM_LARGE = 2.0, 50.0


def test_epmc_damping_rises_with_the_dashpot_as_its_first_order_work():
    """EPMC (H = 1, 128 samples) at modal amplitudes 2-20 mm. The added damping ratio over lambda tends to the
    first-order estimate ``W / (2 pi omega^2 a^2)`` with ``W`` the dashpot's work per unit lambda (``sum_i A_i p
    pdot^2`` over the contact, ``p = -g_n``) on the motions at lambda = 0. Measured: lambda = 2: 0.9987-1.0022 of
    the estimate on the AFT's samples, 0.9984-1.0025 of the period's integral (4096 samples: the traction is
    continuous at a touch, so 128 samples resolve the integral); lambda = 50: 0.9984-1.0025 still; the damping
    ratio 1.9-2.0 % at lambda = 0, 2.1-2.7 % at lambda = 50."""
    from femrom.integrators import FourierBasis

    amplitudes = np.geomspace(2e-3, 2e-2, 5)
    damping = {}
    for lam in (0.0, LAM_SMALL, LAM_LARGE):
        force, model = normal_model(lam)
        modes = epmc(model, amplitudes, mode=0, harmonics=1, samples=128)
        damping[lam] = modes.xi / (2 * modes.omega)
        if lam == 0.0:
            rest = modes
    assert np.all(damping[LAM_SMALL] > damping[0.0]) and np.all(damping[LAM_LARGE] > damping[LAM_SMALL])
    force, _ = normal_model(1e-6)                          # per unit lambda, the clamp never acting
    for samples, tolerance in ((128, 3e-3), (4096, 4e-3)):
        basis = FourierBasis(1, samples)
        estimate = []
        for a, omega, Z in zip(amplitudes, rest.omega, rest.coefficients):
            q, v = basis.synthesis @ Z, omega * (basis.synthesis_derivative @ Z)
            work = np.mean([force.damping_power(qj, vj, force.initial_state()) for qj, vj in zip(q, v)]) / 1e-6
            estimate.append(work * 2 * np.pi / omega / (2 * np.pi * omega**2 * a**2))
        ratio = (damping[LAM_SMALL] - damping[0.0]) / (LAM_SMALL * np.array(estimate))
        assert np.all(np.abs(ratio - 1) < tolerance), ratio
    assert np.all(np.abs((damping[LAM_LARGE] - damping[0.0]) / (LAM_LARGE * np.array(estimate)) - 1) < 1e-2)


# -- reduced and hyper-reduced models --------------------------------------------------------------------------
def test_galerkin_and_ecsw_models_run_the_dashpot():
    """A Galerkin model keeps the velocity-dependent joint (its projected damping tangent ``W^T C W``), and the
    ECSW model with every pair at weight one is it: force and both tangents equal to round-off at a reclosing
    motion; both with an exact harmonic-balance Jacobian (the reduced coordinates carried)."""
    from femrom.inference import galerkin
    from femrom.rom import JointSampling, hyper_reduced_system

    L = law(200.0)
    state = preload_state(L)
    force = joint(L, gaps=(0.002, 0.003, 0.004))
    V = np.linalg.qr(np.random.default_rng(4).standard_normal((9, 5)))[0]
    reduced = galerkin(system(force), V, reference=np.zeros(9), reference_state=state).system
    hyper, z_hyper = hyper_reduced_system(reduced, JointSampling.all_pairs(PAIRS), state)
    assert reduced.nonlinear.velocity_dependent and hyper.nonlinear.velocity_dependent
    for seed in range(100):                              # a motion where a reclosed point's dashpot presses
        rng = np.random.default_rng(seed)
        q, v = 0.02 * rng.standard_normal(5), 0.3 * rng.standard_normal(5)
        x, xdot = V @ q, V @ v
        if L._dashpot(force.gaps(x), force.rates(xdot), state)[2].any():
            break
    C_full = force.tangent(x, xdot, state)[1].toarray()
    f_r, _, C_r = reduced.nonlinear.dense_force_and_tangent(q, v, state)
    assert np.allclose(C_r, V.T @ C_full @ V, rtol=0, atol=1e-12) and np.abs(C_r).max() > 0.1
    assert np.allclose(f_r, V.T @ force.force(x, xdot, state), rtol=0, atol=1e-12)
    f_h, _, C_h = hyper.nonlinear.dense_force_and_tangent(q, v, z_hyper)
    assert np.allclose(f_h - hyper.load, f_r - (0.0 if reduced.load is None else reduced.load), rtol=0, atol=1e-12)
    assert np.allclose(C_h, C_r, rtol=0, atol=1e-12)
    for model, start in ((reduced, state), (hyper, z_hyper)):
        hb = HarmonicBalance(model, 0, harmonics=2, samples=16, state=start, tangent="exact")
        z = 0.02 * np.random.default_rng(6).standard_normal(hb.n_unknowns)
        J_fd, dW_fd = aft_differences(hb, z, 7.0, 1e-7)
        aft = hb.aft(z, 7.0)
        assert np.abs(aft.jacobian - J_fd).max() < 1e-7 * np.abs(J_fd).max()
        assert np.abs(aft.omega_derivative - dW_fd).max() < 1e-6 * np.abs(dW_fd).max()
