"""femrom.study.force_error, the number behind every "the learned force approaches Galerkin" claim,
against values worked out by hand on a two-coordinate model."""

import numpy as np
import pytest

from femrom import FemromError
from femrom.inference import LearnedPotential, ReducedOperators, SymmetricPolynomial
from femrom.study import force_error, nonlinear_forces

#: two states as columns: q = (1, 0) and q = (2, 1)
STATES = np.array([[1.0, 2.0], [0.0, 1.0]])


def quartic(c):
    """``U(q) = c q_1^4``: the force ``grad U = (4 c q_1^3, 0)``."""
    return LearnedPotential(2, SymmetricPolynomial(2, {4: (np.zeros((1, 4), dtype=int), np.array([c]))}))


def reference():
    """``M = diag(2, 1)``, ``K = diag(2, 4)``, ``U = q_1^4``: the conservative acceleration
    ``g(q) = M^-1 (K q + grad U) = (q_1 + 2 q_1^3, 4 q_2)``, its nonlinear part ``(2 q_1^3, 0)``
    (a mass other than 1 on the nonlinear coordinate, so the normalisation must solve with M)."""
    return ReducedOperators.from_matrices(np.diag([2.0, 4.0]), mass=np.diag([2.0, 1.0]), nonlinear=quartic(1.0))


def test_the_force_is_the_gradient_written_by_hand():
    np.testing.assert_allclose(nonlinear_forces(reference(), STATES), [[4.0, 32.0], [0.0, 0.0]], rtol=1e-15)


def test_the_same_dynamics_split_differently_have_no_error():
    """The reference itself, and the reference with every term doubled (M^ = 2 M, K^ = 2 K, U^ = 2 U:
    the motion is the same): exactly 0 (scaling by 2 is exact in floating point)."""
    ref = reference()
    doubled = ReducedOperators.from_matrices(np.diag([4.0, 8.0]), mass=np.diag([4.0, 2.0]), nonlinear=quartic(2.0))
    assert force_error(ref, ref, STATES) == 0.0
    assert force_error(doubled, ref, STATES) == 0.0


def test_a_linear_model_with_the_reference_stiffness_has_error_one():
    """Leaving the nonlinear force out leaves exactly the normaliser: e = 1 (module docstring)."""
    linear = ReducedOperators.from_matrices(np.diag([2.0, 4.0]), mass=np.diag([2.0, 1.0]))
    assert abs(force_error(linear, reference(), STATES) - 1.0) < 1e-15


def test_a_model_off_in_mass_stiffness_and_force_has_the_hand_computed_error():
    """M^ = I, K^ = diag(1.1, 4.1), U^ = q_1^4 / 4: g^ = (1.1 q_1 + q_1^3, 4.1 q_2), so g^ - g =
    (0.1 q_1 - q_1^3, 0.1 q_2), at the two states (-0.9, 0) and (-7.8, 0.1), against the reference's
    nonlinear accelerations (2, 0) and (16, 0): e = sqrt(61.66 / 260) = 0.48698... (to round-off)."""
    learned = ReducedOperators.from_matrices(np.diag([1.1, 4.1]), nonlinear=quartic(0.25))
    assert abs(force_error(learned, reference(), STATES) - np.sqrt(61.66 / 260.0)) < 1e-14


def test_a_reference_without_nonlinear_force_is_refused():
    linear = ReducedOperators.from_matrices(np.diag([2.0, 4.0]))
    with pytest.raises(FemromError, match="no nonlinear force"):
        force_error(linear, linear, STATES)
