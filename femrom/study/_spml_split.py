r"""Where a learned nonlinear Lagrangian model's error comes from, against a known true model.

For a model whose class contains the truth (a reduced Duffing system, a chain with
polynomial springs), SpML's prediction error has four possible sources, and each
reaches the prediction by its own route:

- **optimisation**: the training loss the fit ended at against the loss of the true
  parameters on the same data (0 for exact data; the noise's floor otherwise). A fit
  that stops above the truth's loss has not converged;
- **potential**: the conservative acceleration ``M^^-1 (K^ q + grad U^(q))`` against the
  truth's on test states (:func:`force_error`); it sets the frequencies, so it becomes a
  **phase** error that grows linearly in time (``linear_frequency``: the largest relative
  error of the frequencies at rest);
- **dissipation**: the dissipative acceleration ``M^^-1 (C^ v + grad F^(v))`` against the
  truth's on test states, relative to the truth's; it sets how fast the energy decays, so it
  becomes an **amplitude** error (``energy``: the true energy along the predicted trajectory
  against along the true one, at the end);
- **mass**: ``||M^ - M||_F / ||M||_F`` after the gauge (with no input the mass only acts
  through the accelerations above).

``prediction_conservative`` and ``prediction_dissipative`` attribute the prediction error:
the learned conservative part with the true dissipation, and the true conservative part
with the learned dissipation (the swapped part's dissipative or conservative force carried
over as an acceleration: ``M^ M^-1 C`` symmetrised, exact when ``M^ = M``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from femrom.study._learned_forces import conservative_acceleration, nonlinear_forces


def acceleration_residual(operators, data) -> float:
    r"""``||M^-1 (M Q'' + C Q' + K Q + f(Q, Q') - B U)||_F^2 / ||Q''||_F^2``: SpML's loss of any model on ``data``."""
    Q, V, A = data.states, data.velocities, data.accelerations
    R = operators.mass_matrix @ A + operators.stiffness @ Q + nonlinear_forces(operators, Q, V)
    if operators.damping is not None:
        R = R + operators.damping @ V
    if operators.input_matrix is not None and data.inputs is not None:
        R = R - operators.input_matrix @ data.inputs
    R = np.linalg.solve(operators.mass_matrix, R)
    return float(np.sum(R * R) / max(np.sum(A * A), np.finfo(float).tiny))


def _velocity_forces(operators, Q, V) -> np.ndarray:
    """(r, K) the velocity-dependent nonlinear forces (the learned dissipation)."""
    return nonlinear_forces(operators, Q, V) - nonlinear_forces(operators, Q, None)


def dissipative_acceleration(operators, Q: np.ndarray, V: np.ndarray) -> np.ndarray:
    """(r, K) ``M^-1 (C v + f(q, v) - f(q, 0))``."""
    f = _velocity_forces(operators, Q, V)
    if operators.damping is not None:
        f = f + operators.damping @ V
    return np.linalg.solve(operators.mass_matrix, f)


def _linearised(operators) -> tuple:
    """``(K_eff, C_eff)`` at rest: the Hessians of the nonlinear terms at 0 added (a network has one)."""
    r = operators.r
    K, C = operators.stiffness.copy(), np.zeros((r, r)) if operators.damping is None else operators.damping.copy()
    nonlinear = operators.nonlinear
    if nonlinear is not None:
        Jq, Jv = nonlinear.tangent(np.zeros(r), np.zeros(r), nonlinear.initial_state())
        K = K + (0 if Jq is None else Jq)
        C = C + (0 if Jv is None else Jv)
    return K, C


def modal_rates(operators) -> tuple:
    """``(frequencies, decay rates)`` at rest, ascending in frequency: ``-Re`` and ``Im`` of the
    linearised first-order model's eigenvalues with positive imaginary part."""
    K, C = _linearised(operators)
    M = operators.mass_matrix
    r = M.shape[0]
    A = np.block([[np.zeros((r, r)), np.eye(r)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    lam = np.linalg.eigvals(A)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(lam.imag)]
    return lam.imag, -lam.real


@dataclass(frozen=True)
class SpMLErrorSplit:
    """The error sources of a learned model against a true one (module docstring); every
    error relative. ``None`` where it was not asked for."""

    loss: float                      # the fitted model's training loss (acceleration residual)
    truth_loss: float                # the true model's on the same data
    potential: float                 # conservative acceleration (force_error)
    dissipation: float               # dissipative acceleration
    mass: float
    linear_frequency: float          # max relative error of the frequencies at rest
    linear_decay: float              # max relative error of the modal decay rates at rest
    prediction: float | None = None                  # over the test run
    prediction_conservative: float | None = None     # learned conservative part, true dissipation
    prediction_dissipative: float | None = None      # true conservative part, learned dissipation
    energy: float | None = None      # |E(pred) - E(true)| / E_0 at the end of the test run (true energy)

    def as_dict(self) -> dict:
        return asdict(self)


def _hybrid(conservative, dissipative):
    """``conservative``'s mass, stiffness and potential with ``dissipative``'s damping and dissipation,
    carried over as an acceleration (``M_c M_d^-1 C_d``, symmetrised)."""
    from femrom.inference import ReducedOperators

    Mc, Md = conservative.mass_matrix, dissipative.mass_matrix
    C = None
    if dissipative.damping is not None:
        C = Mc @ np.linalg.solve(Md, dissipative.damping)
        C = 0.5 * (C + C.T)
    keep = [t for t in conservative.terms if t.name not in ("damping", "learned_dissipation")]
    terms = keep + [t for t in dissipative.terms if t.name == "learned_dissipation"]
    ops = ReducedOperators(tuple(terms), dict(conservative.metadata))
    if C is not None:
        from femrom.inference import term_class
        ops = ops.with_terms(term_class("damping")(C))
    return ops


def spml_error_split(operators, truth, data, test=None, *, predict=None) -> SpMLErrorSplit:
    """The error split of ``operators`` (a learned model) against ``truth`` (both ReducedOperators).

    ``data``: the training data (SecondOrderData, or a list) for the two losses; ``test``: a true
    run (SecondOrderData) for the accelerations and, with ``predict`` (a function ``(operators, test)
    -> (Q, V)``, (r, K) states and velocities at test's samples), the prediction errors.
    """
    from femrom.inference import concatenate
    from femrom.study._learned_forces import force_error

    data = concatenate(data) if isinstance(data, (list, tuple)) else data
    test = data if test is None else test
    Q, V = test.states, test.velocities
    dis_true = dissipative_acceleration(truth, Q, V)
    dissipation = float(np.linalg.norm(dissipative_acceleration(operators, Q, V) - dis_true) /
                        max(np.linalg.norm(dis_true), np.finfo(float).tiny))
    M, Mt = operators.mass_matrix, truth.mass_matrix
    M = M * (np.trace(Mt) / np.trace(M))
    w, d = modal_rates(operators)
    wt, dt = modal_rates(truth)
    out = dict(loss=acceleration_residual(operators, data), truth_loss=acceleration_residual(truth, data),
               potential=force_error(operators, truth, Q), dissipation=dissipation,
               mass=float(np.linalg.norm(M - Mt) / np.linalg.norm(Mt)),
               linear_frequency=float(np.max(np.abs(w - wt) / wt)) if w.size == wt.size else float("inf"),
               linear_decay=float(np.max(np.abs(d - dt) / np.maximum(dt, np.finfo(float).tiny)))
               if d.size == dt.size else float("inf"))
    if predict is not None:
        def error(model):
            P, W = predict(model, test)
            return float(np.linalg.norm(P - Q) / np.linalg.norm(Q)), P, W

        out["prediction"], P, W = error(operators)
        out["prediction_conservative"] = error(_hybrid(operators, truth))[0]
        out["prediction_dissipative"] = error(_hybrid(truth, operators))[0]
        E = truth.energy(np.column_stack([Q[:, [0, -1]], P[:, [-1]]]), np.column_stack([V[:, [0, -1]], W[:, [-1]]]))
        out["energy"] = float(abs(E[2] - E[1]) / E[0])
    return SpMLErrorSplit(**out)


__all__ = ["SpMLErrorSplit", "acceleration_residual", "conservative_acceleration", "dissipative_acceleration",
           "modal_rates", "spml_error_split"]
