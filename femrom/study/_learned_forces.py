r"""How close a learned nonlinear force is to a reference (e.g. the Galerkin-projected one).

A learned model and the reference may split the same dynamics differently
between their terms (a learned ``K^`` carries part of the nonlinear force,
``M^`` need not be the identity), so they are compared through what the
motion sees: the conservative acceleration

.. math::

    g(\hat q) = \hat M^{-1} \big(\hat K \hat q + \hat f(\hat q, 0)\big),

and the error is taken relative to the reference's nonlinear part:

.. math::

    e = \frac{\| g(\hat Q) - g_{\text{ref}}(\hat Q) \|_F}
             {\| \hat M_{\text{ref}}^{-1} \hat f_{\text{ref}}(\hat Q, 0) \|_F},

so ``e = 1`` is what a linear model's error would be if it left the
nonlinear force out, and ``e -> 0`` means the nonlinearity is learned.
"""

from __future__ import annotations

import numpy as np

from femrom._errors import FemromValueError


def nonlinear_forces(operators, Q: np.ndarray, Vel: np.ndarray | None = None) -> np.ndarray:
    """(r, K) ``f^(q_k, v_k)`` of a model's nonlinear terms at columns (zeros for a linear model).

    Velocity-dependent terms see ``Vel`` (zero velocity when it is ``None``); stateful
    terms are evaluated from their initial state at every column.
    """
    Q = np.asarray(Q, dtype=float)
    terms = getattr(operators.nonlinear, "terms", None) or ([] if operators.nonlinear is None
                                                            else [operators.nonlinear])
    out = np.zeros(Q.shape)
    for term in terms:
        if Vel is None and term.velocity_dependent and not term.conservative:
            continue
        if hasattr(term, "forces") and not term.stateful:
            out += term.forces(Q, Vel)
        else:
            state = term.initial_state()
            out += np.column_stack([term.lhs(Q[:, k], None if Vel is None else Vel[:, k], state=state)
                                    for k in range(Q.shape[1])])
    return out


def conservative_acceleration(operators, Q: np.ndarray) -> np.ndarray:
    """(r, K) ``M^^-1 (K^ q + f^(q, 0))`` at the columns of ``Q``."""
    return np.linalg.solve(operators.mass_matrix, operators.stiffness @ Q + nonlinear_forces(operators, Q))


def force_error(operators, reference, Q: np.ndarray) -> float:
    """Relative error of ``operators``' conservative acceleration against ``reference``'s at ``Q``
    (module docstring), normalised by the reference's nonlinear part."""
    scale = np.linalg.norm(np.linalg.solve(reference.mass_matrix, nonlinear_forces(reference, Q)))
    if scale == 0:
        raise FemromValueError("the reference model has no nonlinear force at these states: nothing to compare with")
    return float(np.linalg.norm(conservative_acceleration(operators, Q) - conservative_acceleration(reference, Q))
                 / scale)
