"""Plain first-order operator inference on canonical data (the baseline of H-OpInf)."""

from __future__ import annotations

import numpy as np

from femrom._errors import FemromTypeError, FemromValueError
from femrom.inference._hamiltonian import CanonicalData
from femrom.inference._learner import Learner, register_learner


@register_learner("canonical_opinf")
class CanonicalOpInf(Learner):
    r"""An unconstrained linear operator for ``y = [q^; p^]`` with the known Hamiltonian term.

    .. math::

        \min_{\hat A \in \mathbb{R}^{2r \times 2r}}
        \big\| \dot{\hat Y} - \hat F - \hat A \hat Y \big\|_F^2 + \lambda \|\hat A\|_F^2, \qquad
        \hat F = \begin{bmatrix} \hat F_q \\ -\hat F_p \end{bmatrix},

    ``lambda = rho ||Y^||_F^2 / (2r)`` (relative: the mean eigenvalue of the data Gram
    matrix); ``rho = 0`` is ordinary least squares. No symmetry, no skew structure:
    the model ``y' = A^ y + F^(y)`` neither conserves ``H^`` nor, in general, the
    reduced mass ``|y|^2`` (``d|y|^2/dt = y^T (A^ + A^^T) y`` for a phase-invariant
    known term). What H-OpInf must beat (Sharma, Wang & Kramer, Physica D 431, 2022).

    Parameters
    ----------
    regularization : float
        Relative Tikhonov weight ``rho >= 0``.

    Attributes
    ----------
    operators_ : (2r, 2r) ndarray
        ``A^``.
    residual_ : float
        ``||R - A^ Y^||_F / ||R||_F`` of the fit (``R = Y^' - F^``).
    """

    method = "canonical_opinf"
    model = "first_order"

    def __init__(self, regularization: float = 0.0):
        if not regularization >= 0:
            raise FemromValueError(f"regularization must be >= 0, got {regularization}")
        self.regularization = float(regularization)

    @staticmethod
    def _regression(data):
        if not isinstance(data, CanonicalData):
            raise FemromTypeError(f"CanonicalOpInf.fit takes CanonicalData, got {type(data).__name__}")
        Y = np.vstack([data.states_q, data.states_p])
        Fq = 0.0 if data.forces_q is None else data.forces_q
        Fp = 0.0 if data.forces_p is None else data.forces_p
        return Y, np.vstack([data.ddt_q - Fq, data.ddt_p + Fp])

    def fit(self, data: CanonicalData, *, validation=None) -> "CanonicalOpInf":
        """Fit ``A^`` from ``Q^, P^, Q^', P^'`` and the known ``F^_q, F^_p``; ``validation`` (CanonicalData):
        the relative residual ``||R - A^ Y|| / ||R||`` there is ``validation_residual_``."""
        Y, R = self._regression(data)
        if self.regularization == 0.0:
            A = np.linalg.lstsq(Y.T, R.T, rcond=None)[0].T
        else:
            lam = self.regularization * np.sum(Y * Y) / Y.shape[0]
            A = np.linalg.solve(Y @ Y.T + lam * np.eye(Y.shape[0]), Y @ R.T).T
        self.operators_ = A
        den = np.linalg.norm(R)
        self.residual_ = float(np.linalg.norm(R - A @ Y) / den) if den > 0 else 0.0
        self.validation_residual_ = None
        if validation is not None:
            Yv, Rv = self._regression(validation)
            norm = np.linalg.norm(Rv)
            self.validation_residual_ = float(np.linalg.norm(Rv - A @ Yv) / norm) if norm > 0 else 0.0
        return self

    def describe(self) -> dict:
        out = {"method": self.method, "regularization": self.regularization}
        if self.is_fitted:
            out["residual"] = self.residual_
        return out
