"""The harmonic-balance Jacobian of a joint (Iwan and clamped Iwan interface laws) against central
finite differences: exact with the laws' step derivative carried over the sampled period, a few
per cent off with the frozen-state tangent; directly, projected about a reference (the reduced
and hyper-reduced models' term), and Newton's iteration counts with either."""

import numpy as np
import pytest
import scipy.sparse as sp

from femrom.fem import JointForce, interface_law, transform_force
from femrom.fem.interface_laws.clamped_iwan import ClampedIwanLaw
from femrom.inference import ProjectedNonlinearForce
from femrom.integrators import HarmonicBalance, HarmonicBalanceError
from femrom.scene import SecondOrderSystem

PAIRS = 3
IWAN = interface_law("iwan", slip_traction=1.0, tangential_stiffness=100.0, chi=-0.5, beta=0.2,
                     normal_stiffness=200.0, n_sliders=8)
CLAMPED = ClampedIwanLaw(normal_stiffness=200.0, tangential_stiffness=100.0, chi=-0.5, beta=0.2, n_sliders=8)


class FrozenJoint(JointForce):
    """The same joint without the step derivative: the AFT uses the per-sample tangent, state frozen."""
    local_step_derivative = None


def joint(law, cls=JointForce):
    n = 3 * PAIRS
    return cls(law, -np.ones((PAIRS, 3), dtype=int), np.arange(n).reshape(PAIRS, 3),
               np.tile([0.0, 0.0, 1.0], (PAIRS, 1)), np.linspace(1.0, 1.5, PAIRS), n, first_tangents=[1.0, 0.0, 0.0])


def system(force, basis=None):
    """Three nodes on a rigid ground through the joint, coupled by springs, forced in 2-D."""
    n = 3 * PAIRS
    A = 0.1 * np.random.default_rng(1).standard_normal((n, n))
    K = 40.0 * np.eye(n) + 10.0 * A @ A.T
    b = np.zeros((n, 1))
    b[[0, 4, 3 * PAIRS - 2], 0] = (1.0, 0.6, -0.4)
    if basis is None:
        return SecondOrderSystem(mass=sp.identity(n, format="csr"), stiffness=sp.csr_matrix(K),
                                 damping=sp.csr_matrix(0.01 * K), input_matrix=b, nonlinear=force)
    V = basis
    return SecondOrderSystem(mass=V.T @ V, stiffness=V.T @ K @ V, damping=0.01 * V.T @ K @ V, input_matrix=V.T @ b,
                             nonlinear=force)


def clamped_state():
    """Two closed points (macro-slip tractions 1 and 0.7) and an open one."""
    N = CLAMPED.n_elements
    state = np.zeros((PAIRS, N + 1, 2))
    state[:, N, 0] = (1.0, 0.7, 1.0)
    state[:, N, 1] = (1.0, 1.0, 0.0)
    return state


def aft_finite_differences(hb, z, omega, h):
    columns = []
    for i in range(z.size):
        e = np.zeros(z.size)
        e[i] = h
        columns.append((hb.aft(z + e, omega, jacobian=False).coefficients
                        - hb.aft(z - e, omega, jacobian=False).coefficients).reshape(-1) / (2 * h))
    return np.array(columns).T


def motion(hb, amplitude, seed=0):
    rng = np.random.default_rng(seed)
    Z = 0.15 * amplitude * rng.standard_normal((hb.basis.size, hb.n_dofs))
    Z[0] = 0.0
    Z[1:3] += amplitude * rng.standard_normal((2, hb.n_dofs))
    return Z.reshape(-1)


# the weakest slider's slip displacement (unit traction) and the full slip one
WEAKEST, FULL = IWAN.slider_nodes[1], IWAN.phi_max


@pytest.mark.parametrize("law, state", [(IWAN, None), (CLAMPED, "clamped")], ids=["iwan", "clamped_iwan"])
@pytest.mark.parametrize("regime, amplitude, step", [("stick", 0.035 * WEAKEST, 1e-3), ("micro", 0.3 * FULL, 1e-7),
                                                     ("macro", 4.0 * FULL, 1e-7)])
def test_joint_aft_jacobian_is_the_exact_derivative(law, state, regime, amplitude, step):
    state = clamped_state() if state == "clamped" else None
    omega = 2 * np.pi
    hb = HarmonicBalance(system(joint(law)), 0, harmonics=3, samples=32, state=state)
    frozen = HarmonicBalance(system(joint(law)), 0, harmonics=3, samples=32, state=state, tangent="frozen")
    assert hb._hook is not None and frozen._hook is None
    z = motion(hb, amplitude)
    J_fd = aft_finite_differences(hb, z, omega, step * amplitude)
    scale = np.max(np.abs(J_fd))
    exact = np.max(np.abs(hb.aft(z, omega).jacobian - J_fd)) / scale
    stale = np.max(np.abs(frozen.aft(z, omega).jacobian - J_fd)) / scale
    # measured: stick 3e-13 / 4e-13 (both: the law is linear there); micro 2.1e-9 / 2.0e-9 exact against
    # 0.2 / 0.11 frozen; macro 2.6e-9 / 3.2e-9 against 0.10 / 0.066 (iwan / clamped_iwan)
    assert exact < 1e-8
    if regime == "stick":
        assert stale < 1e-8
    else:
        assert stale > 1e-2


def test_projected_joint_about_a_reference_takes_the_exact_path():
    """A joint shifted to a reference and projected on a basis (the reduced and the hyper-reduced
    model's term) offers the derivative through its force on the reduced coordinates."""
    V = np.linalg.qr(np.random.default_rng(3).standard_normal((3 * PAIRS, 5)))[0]
    shifted = transform_force(joint(IWAN), None, reference=1e-3 * np.ones(3 * PAIRS))
    hb = HarmonicBalance(system(ProjectedNonlinearForce(shifted, V), V), 0, harmonics=3, samples=32)
    assert hb._hook is not None
    omega = 2 * np.pi
    z = motion(hb, 0.02)
    J_fd = aft_finite_differences(hb, z, omega, 1e-7 * 0.02)
    # measured 4.4e-9
    assert np.max(np.abs(hb.aft(z, omega).jacobian - J_fd)) < 1e-8 * np.max(np.abs(J_fd))


def test_newton_on_a_joint_converges_in_few_iterations():
    """Measured (H = 3, N = 32, 1.2 Hz, from the linear guess): force 0.5: 4 iterations exact, 20
    frozen; force 2, 5, 20: 8, 8, 5 exact, the frozen tangent not converged in 300."""
    omega = 2 * np.pi * 1.2
    hb = HarmonicBalance(system(joint(IWAN)), 0, harmonics=3, samples=32)
    frozen = HarmonicBalance(system(joint(IWAN, FrozenJoint)), 0, harmonics=3, samples=32)
    exact, stale = hb.solve(omega, 0.5), frozen.solve(omega, 0.5)
    assert exact.iterations <= 6 and stale.iterations >= 3 * exact.iterations
    assert np.allclose(exact.coefficients, stale.coefficients, rtol=0, atol=1e-8 * np.max(np.abs(exact.coefficients)))
    assert hb.solve(omega, 2.0).iterations <= 12
    with pytest.raises(HarmonicBalanceError):
        frozen.solve(omega, 2.0)


def test_the_tangent_option_is_checked_and_exact_is_refused_where_the_force_gives_no_derivative():
    with pytest.raises(ValueError, match="tangent must be one of auto, exact, frozen, got 'secant'"):
        HarmonicBalance(system(joint(IWAN)), 0, harmonics=1, tangent="secant")
    with pytest.raises(ValueError, match="tangent='exact': FrozenJoint gives no local_step_derivative"):
        HarmonicBalance(system(joint(IWAN, FrozenJoint)), 0, harmonics=1, tangent="exact")
    assert HarmonicBalance(system(joint(IWAN)), 0, harmonics=1, tangent="exact")._hook is not None
