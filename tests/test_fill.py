"""Snapshots every k-th step: the states between them solved from a model, and refined with the learner.

A reduced linear system with known operators, stepped by femrom's Newmark ROM, is
the exact reference: its trajectory satisfies the integrator-consistent equations
at every step, so the states left out are determined by the ones kept.
"""

import numpy as np
import pytest

from femrom.inference import (
    LagrangianOpInf,
    ProjectedNonlinearForce,
    ReducedOperators,
    SecondOrderData,
    alternating_fill,
    fill_between_snapshots,
)
from femrom.rom import SecondOrderROM

DT = 1e-3


def _system(r=6, seed=0):
    """Frequencies 20-160 Hz (omega dt up to 1: only just resolved, as the fishtail's r = 12), 1 % damping."""
    rng = np.random.default_rng(seed)
    Qr, _ = np.linalg.qr(rng.standard_normal((r, r)))
    omega = 2 * np.pi * np.linspace(20.0, 160.0, r)
    K = Qr @ np.diag(omega**2) @ Qr.T
    C = Qr @ np.diag(0.02 * omega) @ Qr.T
    B = rng.standard_normal((r, 1))
    E = rng.standard_normal((2, r))
    return ReducedOperators.from_matrices(K, damping=C, input_matrix=B, output_matrix=E)


def _signal(t, kind):
    if kind == "train":   # a chirp-like push: excites every mode
        return (np.sin(2 * np.pi * 15 * t) + 0.5 * np.sin(2 * np.pi * 90 * t ** 1.2 * 3))[None, :] * 1e3
    return np.where(t >= 0.0405, 1e3, 0.0)[None, :]


def _run(ops, kind, n=600):
    t = np.arange(n + 1) * DT
    u = _signal(t, kind)
    rom = SecondOrderROM(ops)
    sol = rom.predict(t, u, initial=np.zeros(ops.r))
    return t, u, sol.q, sol.outputs


def _data(q, u, y, k, dt=DT):
    keep = slice(None, None, k)
    z = np.zeros_like(q[:, keep])
    return SecondOrderData(states=q[:, keep], velocities=z, accelerations=z, inputs=u[:, keep], outputs=y[:, keep],
                           diagnostics={"dt": k * dt, "n_trajectories": 1})


def _test_error(ops):
    true = _system()
    _, u, q, _ = _run(true, "test")
    t = np.arange(q.shape[1]) * DT
    pred = SecondOrderROM(ops).predict(t, u, initial=np.zeros(ops.r)).q
    return np.linalg.norm(pred - q) / np.linalg.norm(q)


@pytest.mark.parametrize("k", [2, 5])
def test_the_true_model_recovers_the_states_left_out_exactly(k):
    """A Newmark trajectory zeroes the residual at every step, and the kept states fix the others:
    the least-squares fill from a spline start gives them back to round-off (spline alone: 1e-3-1e-1 off)."""
    ops = _system()
    _, u, q, y = _run(ops, "train")
    n = (q.shape[1] - 1) // k * k
    fine = _data(q[:, :n + 1], u[:, :n + 1], y[:, :n + 1], k).upsampled(k, u[:, :n + 1])
    spline_error = np.linalg.norm(fine.states - q[:, :n + 1]) / np.linalg.norm(q[:, :n + 1])
    filled = fill_between_snapshots(ops, fine, np.arange(0, n + 1, k))
    error = np.linalg.norm(filled.states - q[:, :n + 1]) / np.linalg.norm(q[:, :n + 1])
    assert error < 1e-9, error                       # round-off of a banded solve of (n r) unknowns
    assert spline_error > 1e-4                       # the spline start really was off
    np.testing.assert_array_equal(filled.states[:, ::k], fine.states[:, ::k])   # the data held


def test_alternating_fill_learns_from_every_2nd_state_what_every_state_gives():
    """L-OpInf from every 2nd state of the true model's run: the spline fill's model, the refined fill's and the
    model from every state, scored on an unseen step input against the true model's trajectory. Measured:
    every state 1.0e-12, spline 2.5e-1 (omega dt up to 1: a spline through every 2nd state misses the
    fast modes' curvature), refined 3.4e-12 after 24 sweeps (the residual 0.19 -> 2.5e-12)."""
    true = _system()
    _, u, q, y = _run(true, "train")
    every = LagrangianOpInf(["damping"]).fit(_data(q, u, y, 1).integrator_consistent())
    spline = LagrangianOpInf(["damping"]).fit(_data(q, u, y, 2).upsampled(2, u).integrator_consistent())
    refined = LagrangianOpInf(["damping"])
    fine, history = alternating_fill(refined, _data(q, u, y, 2), 2, inputs=u, sweeps=60)
    e_every, e_spline, e_refined = (_test_error(m.operators_) for m in (every, spline, refined))
    assert e_every < 1e-9, e_every                 # the data satisfy the regression exactly
    assert e_spline > 0.05, e_spline               # the start really is poor
    assert e_refined < 1e-8, e_refined             # the true model found from half the states
    residuals = [h.residual for h in history]
    assert residuals[-1] < 1e-9 * residuals[0], residuals
    assert 1 < len(history) < 61                   # stopped by rtol, not by the sweep limit
    assert history[0].sweep == 0 and np.isnan(history[0].change)
    np.testing.assert_array_equal(fine.states[:, ::2], q[:, ::2])        # the data held
    np.testing.assert_allclose(fine.states, q, rtol=0, atol=1e-9 * np.abs(q).max())


def test_fill_refuses_a_nonlinear_model_and_a_wrong_rank():
    ops = _system()
    _, u, q, y = _run(ops, "train", n=40)
    fine = _data(q, u, y, 2).upsampled(2, u)
    nonlinear = ops.with_terms(ProjectedNonlinearForce(object(), np.eye(ops.r)))   # any known force
    with pytest.raises(ValueError, match="linear reduced models"):
        fill_between_snapshots(nonlinear, fine, np.arange(0, fine.n_samples, 2))
    smaller = ReducedOperators.from_matrices(np.eye(3))
    with pytest.raises(ValueError, match="r = 3, the data r = 6"):
        fill_between_snapshots(smaller, fine, np.arange(0, fine.n_samples, 2))
