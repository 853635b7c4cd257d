"""Quasi-static modal analysis against closed forms: Jenkins (Masing exact), a smooth softening
curve (trapezoidal O(h^2)), and a two-dof system with a Jenkins element on one dof."""

import numpy as np
import pytest
import scipy.linalg as sla

from femrom.post import QuasiStaticBackbone, masing_damping, quasi_static_modal_analysis

K_LIN, K_T, F_S = 1.0, 0.5, 0.1  # spring, Jenkins stick stiffness, slip force: slip at x_s = 0.2
X_S = F_S / K_T


def jenkins_curve(alpha):
    """Monotonic loading of k a + min(k_t a, F_s) = alpha, solved for a."""
    alpha = np.asarray(alpha, dtype=float)
    return np.where(alpha <= (K_LIN + K_T) * X_S, alpha / (K_LIN + K_T), (alpha - F_S) / K_LIN)


def test_jenkins_loading_curve_gives_the_closed_form_dissipation():
    # the kink at alpha = 0.3 is a sample: the trapezoidal rule is exact on the piecewise-linear curve
    alpha = np.linspace(0.01, 1.0, 100)
    a = jenkins_curve(alpha)
    omega, dissipation, zeta = masing_damping(a, alpha)
    slipping = a > X_S + 1e-12
    exact = np.where(slipping, 4 * F_S * (a - X_S), 0.0)   # 4 F_s (a - F_s / k_t) beyond slip
    assert np.max(np.abs(dissipation - exact)) < 1e-12
    assert np.allclose(omega[~slipping], np.sqrt(K_LIN + K_T), rtol=1e-13)   # stuck: k + k_t
    assert np.allclose(omega[slipping] ** 2, K_LIN + F_S / a[slipping], rtol=1e-13)  # secant
    assert np.allclose(zeta, exact / (2 * np.pi * omega ** 2 * a ** 2), rtol=1e-13)
    assert np.max(np.abs(zeta[~slipping])) < 1e-12 and np.all(zeta[slipping][1:] > 0)  # 0 up to round-off


def test_a_smooth_softening_curve_converges_at_second_order():
    # alpha = k a + F (1 - exp(-a / x)): D = 8 F [a/2 - x (1 - e^{-a/x}) + (a/2) e^{-a/x}]
    k, F, x = 1.0, 0.3, 0.05

    def error(n):
        a = np.linspace(0.2 / n, 0.2, n)
        alpha = k * a + F * (1 - np.exp(-a / x))
        _, D, _ = masing_damping(a, alpha)
        exact = 8 * F * (a / 2 - x * (1 - np.exp(-a / x)) + a / 2 * np.exp(-a / x))
        return abs(D[-1] - exact[-1]) / exact[-1]

    e1, e2 = error(100), error(200)
    # measured 1.7e-4 and 4.3e-5: ratio 3.99 (trapezoidal rule, O(h^2))
    assert 3.6 < e1 / e2 < 4.4
    assert e2 < 1e-3


def test_two_dofs_with_a_jenkins_element_on_one_dof():
    M = np.diag([1.0, 2.0])
    K = np.array([[3.0, -1.0], [-1.0, 1.0]])
    e1 = np.array([1.0, 0.0])
    K_stuck = K + K_T * np.outer(e1, e1)

    def solve(F):  # monotonic loading from rest: stuck while k_t |q_1| <= F_s, then slipping
        q = np.linalg.solve(K_stuck, F)
        return q if K_T * abs(q[0]) <= F_S else np.linalg.solve(K, F - np.sign(q[0]) * F_S * e1)

    lam, modes = sla.eigh(K_stuck, M)
    phi = modes[:, 0]
    E = np.array([[0.0, 1.0]])
    alphas = np.linspace(0.005, 0.5, 100)
    result = quasi_static_modal_analysis(solve, M, 3.0 * phi, alphas, output_matrix=E)
    assert isinstance(result, QuasiStaticBackbone)
    stuck = np.abs(result.modal_amplitude * (phi / np.sqrt(phi @ M @ phi))[0]) * K_T < F_S
    assert 10 < np.count_nonzero(stuck) < alphas.size - 10  # both regimes are sampled
    # below slip the structure is linear: the QSMA frequency is the stuck mode's to round-off
    assert np.allclose(2 * np.pi * result.frequency_hz[stuck], np.sqrt(lam[0]), rtol=1e-12)
    # D is a difference of O(a alpha) terms: zero up to round-off (measured 2e-16 of a alpha)
    assert np.max(np.abs(result.dissipation[stuck])) < 1e-13 * np.max(result.modal_amplitude * alphas)
    # beyond: softer and more damped with amplitude
    assert np.all(np.diff(result.frequency_hz[~stuck]) < 0)
    assert np.all(np.diff(result.damping_ratio[~stuck]) > 0) and result.damping_ratio[-1] > 0
    # the output's acceleration amplitude omega^2 |E q| equals alpha |E phi| while linear
    backbone = result.backbone(0)
    phi_unit = phi / np.sqrt(phi @ M @ phi)
    assert np.allclose(backbone.amplitude[stuck], alphas[stuck] * abs(phi_unit[1]), rtol=1e-12)
    assert backbone.method == "qsma" and len(backbone.rows()) == alphas.size


@pytest.mark.parametrize("a, f, fragment", [
    ([0.1, 0.05], [1.0, 2.0], "positive and increasing"),
    ([0.0, 0.1], [1.0, 2.0], "positive and increasing"),
    ([0.1, 0.2], [1.0], "need one shape"),
    ([0.1, np.nan], [1.0, 2.0], "must be finite"),
    ([0.1, 0.2], [1.0, -2.0], "modal_force must be positive"),
])
def test_bad_curves_are_refused(a, f, fragment):
    with pytest.raises(ValueError, match=fragment):
        masing_damping(a, f)


def test_bad_loads_are_refused():
    with pytest.raises(ValueError, match="modal_forces must be positive, finite and increasing"):
        quasi_static_modal_analysis(lambda F: F, np.eye(2), np.ones(2), [0.2, 0.1])
    with pytest.raises(ValueError, match="positive modal mass"):
        quasi_static_modal_analysis(lambda F: F, np.eye(2), np.zeros(2), [0.1, 0.2])


def test_rigid_motion_from_the_supports_is_removed_from_the_outputs():
    # a free two-mass chain held at dof 0: the static deflection under alpha M phi carries the
    # rigid translation that brings dof 0 to zero; the outputs must read the elastic part alone
    M = np.diag([1.0, 1.0])
    K = np.array([[1.0, -1.0], [-1.0, 1.0]])
    values, modes = sla.eigh(K, M)
    rigid, phi = modes[:, :1], modes[:, 1]

    def solve(F):  # dof 0 held: K_11 q_1 = F_1
        return np.array([0.0, F[1] / K[1, 1]])

    alphas = np.array([0.5, 1.0])
    result = quasi_static_modal_analysis(solve, M, phi, alphas, output_matrix=np.eye(2), rigid_modes=rigid)
    assert np.allclose((2 * np.pi * result.frequency_hz) ** 2, values[1], rtol=1e-12)
    # elastic deflection alpha phi / omega^2 at both dofs (with the supports' rigid motion: 0 at dof 0)
    assert np.allclose(result.output_amplitude, np.abs(np.outer(alphas, phi)) / values[1], rtol=1e-12)
