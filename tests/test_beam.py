"""Euler-Bernoulli Hermite beam: natural frequencies against the analytic roots."""

import numpy as np
import pytest
import scipy.linalg as sl
from skfem import MeshLine

from femrom.fem import Condensation, line_basis, bending_stiffness, line_mass

# Roots beta_n L of the frequency equations (Blevins, "Formulas for natural
# frequency and mode shape", 1979, table 8-1; also ../shared/DESIGN.md).
CANTILEVER = np.array([1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349])
FREE_FREE = np.array([4.7300407449, 7.8532046241, 10.9956078380])

LENGTH, RIGIDITY, MASS_PER_LENGTH = 1.3, 350.0, 1.57


def _frequencies(n_elements, fixed_left, lumped=False):
    mesh = MeshLine(np.linspace(0.0, LENGTH, n_elements + 1))
    basis = line_basis(mesh, "hermite")
    K = bending_stiffness(basis, RIGIDITY)
    M = line_mass(basis, MASS_PER_LENGTH, lumped=lumped)
    fixed = basis.get_dofs(np.array([0])).all() if fixed_left else []
    c = Condensation.from_fixed(basis.N, fixed)
    w2 = sl.eigh(c.matrix(K).toarray(), c.matrix(M).toarray(), eigvals_only=True)
    return np.sqrt(np.abs(w2))


def _exact(roots):
    return roots**2 * np.sqrt(RIGIDITY / (MASS_PER_LENGTH * LENGTH**4))


def test_cantilever_frequencies_match_analytic_roots():
    omega = _frequencies(120, fixed_left=True)[:4]
    # Hermite cubics converge as h^4 in frequency; at 120 elements the 4th mode
    # is ~1e-7 off, so 1e-6 is the bound with margin.
    np.testing.assert_allclose(omega, _exact(CANTILEVER), rtol=1e-6)


def test_free_free_frequencies_match_analytic_roots():
    omega = _frequencies(120, fixed_left=False)
    # two rigid-body modes (translation, rotation) come first: omega^2 is zero up
    # to round-off eps * omega_max^2, so omega <= sqrt(eps) * omega_max
    assert np.all(omega[:2] < np.sqrt(np.finfo(float).eps) * omega.max())
    np.testing.assert_allclose(omega[2:5], _exact(FREE_FREE), rtol=1e-6)


def test_hermite_frequency_converges_at_fourth_order():
    sizes = np.array([4, 8, 16])
    errors = [abs(_frequencies(n, True)[1] / _exact(CANTILEVER)[1] - 1) for n in sizes]
    rate = -np.polyfit(np.log(sizes), np.log(errors), 1)[0]
    # eigenvalue error of cubic Hermite elements is O(h^{2(p-1)}) = O(h^4)
    assert abs(rate - 4.0) < 0.25, rate


def test_hrz_lumped_mass_keeps_total_mass_and_converges():
    mesh = MeshLine(np.linspace(0.0, LENGTH, 21))
    basis = line_basis(mesh, "hermite")
    M = line_mass(basis, MASS_PER_LENGTH, lumped=True)
    w = basis.nodal_dofs[0]
    assert M.nnz == basis.N and np.all(M.diagonal() > 0)
    assert M.diagonal()[w].sum() == pytest.approx(MASS_PER_LENGTH * LENGTH, rel=1e-12)
    errors = [abs(_frequencies(n, True, lumped=True)[0] / _exact(CANTILEVER)[0] - 1) for n in (10, 20, 40)]
    rate = np.log2(errors[0] / errors[1]), np.log2(errors[1] / errors[2])
    # lumping drops the frequency accuracy to O(h^2)
    assert all(abs(r - 2.0) < 0.2 for r in rate), rate
