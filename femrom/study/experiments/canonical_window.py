r"""A canonical Hamiltonian model released from the full run's initial state, scored on its training and test windows."""

from __future__ import annotations

import numpy as np

from femrom.study._experiment import Experiment, register_experiment
from femrom.study._metrics import invariant_drift


def state_error(Q, P, Qr, Pr, window: slice = slice(None)) -> float:
    """``||[Qr - Q; Pr - P]||_F / ||[Q; P]||_F`` over ``window`` (``inf`` if not finite)."""
    num = np.linalg.norm(Qr[:, window] - Q[:, window]) ** 2 + np.linalg.norm(Pr[:, window] - P[:, window]) ** 2
    den = np.linalg.norm(Q[:, window]) ** 2 + np.linalg.norm(P[:, window]) ** 2
    return float(np.sqrt(num / den)) if np.isfinite(num) else float("inf")


def mass_generator(A: np.ndarray) -> float:
    """``||A + A^T||_F / (2 ||A||_F)``: the part of ``y' = A y`` that changes ``|y|^2`` (0: skew, |y| kept)."""
    return float(np.linalg.norm(A + A.T) / (2 * np.linalg.norm(A)))


def linear_operator(model) -> np.ndarray:
    """(2r, 2r) linear part of a canonical ROM: ``[[0, D^_p], [-D^_q, 0]]``, or a first-order model's ``A^``."""
    ops = model.operators_
    if isinstance(ops, np.ndarray):
        return ops
    Z = np.zeros_like(ops.position)
    return np.block([[Z, ops.momentum], [-ops.position, Z]])


def window_metrics(system, Q, P, Qr, Pr, train: slice, test: slice, dt: float, invariants=None) -> dict:
    """Errors, blow-up time and drifts of a reconstructed trajectory ``(Qr, Pr)`` (n, k) against the FOM's.

    ``invariants(Q, P) -> {name: (k,) values}`` adds ``<name>_drift_train`` and
    ``<name>_drift_test``; the FOM's ``H`` of the reconstruction gives
    ``hamiltonian_drift_test``. Anything over a window where the trajectory is not
    finite is ``inf``.
    """
    finite_at = np.all(np.isfinite(Qr), axis=0) & np.all(np.isfinite(Pr), axis=0)
    finite, finite_train = bool(np.all(finite_at)), bool(np.all(finite_at[train]))
    bad = np.flatnonzero(~finite_at)
    out = {"train_error": state_error(Q, P, Qr, Pr, train) if finite_train else float("inf"),
           "test_error": state_error(Q, P, Qr, Pr, test) if finite else float("inf"),
           "finite": finite, "blowup_time": float(dt * bad[0]) if bad.size else None}
    if bad.size:     # when, and why: the errors and drifts after it are not finite
        out["diverged"] = f"at t = {dt * bad[0]:.4g} (reconstructed state not finite)"
    with np.errstate(all="ignore"):
        values = {} if invariants is None else invariants(Qr, Pr)
        H = system.hamiltonian(Qr, Pr)
    for name, v in values.items():
        out[f"{name}_drift_train"] = invariant_drift(v, train) if finite_train else float("inf")
        out[f"{name}_drift_test"] = invariant_drift(v, test) if finite else float("inf")
    out["hamiltonian_drift_test"] = invariant_drift(H, test) if finite else float("inf")
    return out


def predict_from(model, q0, p0, times):
    """``model`` (canonical or first-order, basis ``V``) from ``(V^T q0, V^T p0)`` over ``times``."""
    V = model.basis
    with np.errstate(all="ignore"):
        return model.predict(times, initial=(V.T @ q0, V.T @ p0))


@register_experiment("canonical_window")
class CanonicalWindow(Experiment):
    r"""A canonical FOM run (:class:`~femrom.study.CanonicalRun`: ``q``, ``p`` (n, k)) split at ``train_window``:
    the model released from the projection of the run's initial state over the whole run, its
    reconstruction ``(V q^, V p^)`` scored on both windows (:func:`window_metrics`: errors, blow-up,
    the drifts of ``invariants`` and of the FOM's ``H``), with the structure of its linear part
    (:func:`mass_generator`, the largest real part of its eigenvalues). The reconstruction and the
    reduced solution come back under ``_Q``, ``_P``, ``_solution``."""

    def __init__(self, system, run, train_window: float, *, invariants=None, label: str = "extrapolation"):
        self.system, self.reference, self.invariants, self.label = system, run, invariants, label
        k_train = int(round(train_window / run.dt)) + 1
        self.train, self.test = slice(0, k_train), slice(k_train, None)

    def run(self, model) -> dict:
        fom = self.reference
        solution = predict_from(model, fom.q[:, 0], fom.p[:, 0], fom.times)
        Qf, Pf = model.basis @ solution.q, model.basis @ solution.p
        A = linear_operator(model)
        return {**window_metrics(self.system, fom.q, fom.p, Qf, Pf, self.train, self.test, fom.dt, self.invariants),
                "mass_generator": mass_generator(A), "max_real_eigenvalue": float(np.max(np.linalg.eigvals(A).real)),
                "_Q": Qf, "_P": Pf, "_solution": solution}
