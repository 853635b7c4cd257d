"""The normal dashpot at the reclosed points of the clamped Iwan law (``closing_damping``): the law and its
derivatives, the joint force's damping tangent, the Newmark march's energy balance, harmonic balance's
exact Jacobian and its agreement with the march, and EPMC's damping against the first-order estimate."""

import numpy as np
import pytest
import scipy.sparse as sp

from femrom.fem import JointForce, force_from_parameters, interface_law_from_parameters, transform_force
from femrom.fem.interface_laws.clamped_iwan import ClampedIwanLaw
from femrom.inference import ProjectedNonlinearForce
from femrom.integrators import EnergyBalance, HarmonicBalance, Newmark, Newton, epmc, integrate
from femrom.scene import SecondOrderSystem

PAIRS = 3
KAPPA, MU_C = 0.5, 0.3


def law(c_n=0.0, **extra):
    return ClampedIwanLaw(normal_stiffness=200.0, tangential_stiffness=100.0, chi=-0.5, beta=0.2, n_sliders=8,
                          closing=KAPPA, closing_friction=MU_C, closing_damping=c_n, **extra)


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
    c = 3.0
    L = law(c)
    gap, state = reclosed_gap(L)
    state = L.commit(0.3 * gap, state)                   # then away from it: sliders clearly stuck or slipping
    rate = np.array([[0.5, 0.2, -0.3], [0.1, -0.2, -0.02]])
    elastic, _ = L.evaluate(gap, state)
    t, D, C = L.evaluate_rate(gap, rate, state)
    # closed at the preload: unchanged; reclosed: kappa k_n g_n + c_n gdot_n, friction at the elastic pressure
    assert np.array_equal(t[0], elastic[0]) and np.array_equal(t[1, :2], elastic[1, :2])
    assert t[1, 2] == pytest.approx(KAPPA * 200.0 * -4e-3 + c * -0.02, rel=1e-14)
    assert C[1, 2, 2] == c and np.count_nonzero(C) == 1
    assert L.damping_power(gap, rate, state)[1] == pytest.approx(c * 0.02**2, rel=1e-14)
    h = 1e-9
    for k in range(3):
        e = np.zeros((2, 3))
        e[:, k] = h
        fd_gap = (L.evaluate_rate(gap + e, rate, state, False)[0] - L.evaluate_rate(gap - e, rate, state, False)[0])
        fd_rate = (L.evaluate_rate(gap, rate + e, state, False)[0] - L.evaluate_rate(gap, rate - e, state, False)[0])
        assert np.allclose(D[:, :, k], fd_gap / (2 * h), rtol=1e-6, atol=1e-6)
        assert np.allclose(C[:, :, k], fd_rate / (2 * h), rtol=1e-6, atol=1e-6)
    # separating faster than kappa k_n (-g_n) / c_n = 0.133: no pull, zero traction and zero normal derivatives
    pulling = rate.copy()
    pulling[1, 2] = 0.2
    t, D, C = L.evaluate_rate(gap, pulling, state)
    assert t[1, 2] == 0.0 and D[1, 2, 2] == 0.0 and C[1, 2, 2] == 0.0 and np.array_equal(t[1, :2], elastic[1, :2])
    # then it dissipates -kappa k_n g_n gdot_n (less than c_n gdot_n^2), never a negative power
    assert L.damping_power(gap, pulling, state)[1] == pytest.approx(KAPPA * 200.0 * 4e-3 * 0.2, rel=1e-14)
    rates = np.random.default_rng(0).standard_normal((200, 2, 3))
    assert min(L.damping_power(gap, r, state).min() for r in rates) >= 0.0
    # the step derivative with the rate's derivative
    rng = np.random.default_rng(2)
    dgap, drate = rng.standard_normal((2, 3, 3)), rng.standard_normal((2, 3, 3))
    dstate = np.zeros(state.shape + (3,))
    dt, _ = L.step_derivative(gap, state, dgap, dstate, rate=rate, drate=drate)
    assert np.allclose(dt, np.einsum("sij,sjm->sim", D_at(L, gap, rate, state), dgap)
                       + np.einsum("sij,sjm->sim", L.evaluate_rate(gap, rate, state)[2], drate), rtol=1e-12,
                       atol=1e-12)


def D_at(L, gap, rate, state):
    return L.evaluate_rate(gap, rate, state)[1]


def test_the_damping_travels_with_the_parameters_and_the_restricted_joint():
    L = law(2.5)
    assert L.parameters()["closing_damping"] == 2.5
    assert interface_law_from_parameters({k: np.asarray(v) for k, v in L.parameters().items()}) == L
    force = joint(L)
    again = force_from_parameters(force.parameters())
    assert again.law == L and again.velocity_dependent
    part = force.restricted(np.array([1, 2]), np.array([1.0, 2.0]))
    assert part.velocity_dependent and part.law.closing_damping == 2.5
    shifted = transform_force(force, None, reference=1e-3 * np.ones(9))
    assert shifted.velocity_dependent and shifted.step_derivative_rates
    projected = ProjectedNonlinearForce(force, np.linalg.qr(np.random.default_rng(0).standard_normal((9, 4)))[0])
    assert projected.velocity_dependent
    # the joint's damping tangent: A_i c_n at the damped normal entries
    x = np.zeros(9)
    x[5] = -0.01                                          # pair 1 pressed 5 mm through its 5 mm gap
    xdot = np.zeros(9)
    xdot[5] = -0.1
    K, C = force.local_tangent(x, xdot, preload_state(L))
    assert sp.issparse(C) and np.count_nonzero(C.toarray()) == 1 and C[5, 5] == pytest.approx(1.25 * 2.5)
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
    """Measured (H = 3, N = 16): the exact Jacobian 4e-11 (full) of the largest entry off the central
    differences, the Omega column 2e-9 of the column; the dashpot changes the Jacobian by 0.1 of it."""
    omega = 7.0
    out = {}
    for c in (0.0, 3.0):
        L = law(c)
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
        out[c] = J_fd, dW_fd
        scale = np.abs(J_fd).max()
        assert np.abs(aft.jacobian - J_fd).max() < 1e-8 * scale
        assert np.abs(aft.omega_derivative - dW_fd).max() < 1e-7 * max(np.abs(dW_fd).max(), 1e-300)
    assert np.abs(out[3.0][0] - out[0.0][0]).max() > 1e-2 * np.abs(out[0.0][0]).max()
    assert np.all(out[0.0][1] == 0) and np.abs(out[3.0][1]).max() > 1e-2
