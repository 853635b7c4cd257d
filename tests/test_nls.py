"""Cubic NLS: canonical integrators, H-OpInf with a known quartic Hamiltonian, and the case.

The FOM is ``i psi_t + psi_xx + gamma |psi|^2 psi = 0``, ``psi = q + i p``, on
64 periodic points (2n = 128, cases/nls.py): ``H = q^T K q / 2 + p^T K p / 2
- gamma/4 sum (q^2 + p^2)^2`` with ``K = -Laplacian``.
"""

import dataclasses
import json

import numpy as np
import pytest

from femrom.basis import CotangentLiftPSD
from femrom.cli import load_case
from femrom.inference import HamiltonianOperators, HamiltonianOpInf, ProjectedPotential
from femrom.integrators import CanonicalSystem, QuarticPotential, integrate_canonical
from femrom.rom import HamiltonianROM

nls = load_case("nls")


def relative(A, B):
    return np.linalg.norm(A - B) / np.linalg.norm(B)


@pytest.fixture(scope="module")
def setup():
    cfg = dataclasses.replace(nls.NLSConfig.from_toml(nls.SCENE), dt=4e-3)
    fom = nls.full_model(cfg)
    q0, p0 = nls.initial_condition(cfg)
    run = integrate_canonical(fom, q0, p0, cfg.dt, 500)   # [0, 2]: the training window
    return cfg, fom, run


# -- the integrators -----------------------------------------------------------
def test_fom_midpoint_conserves_mass_exactly_and_energy_without_drift(setup):
    cfg, fom, run = setup
    inv = nls.invariants(cfg, run.q, run.p)
    # mass is a quadratic invariant of the semi-discrete NLS (K symmetric, the
    # quartic term phase-invariant) and the midpoint rule keeps quadratic
    # invariants exactly: what is left is the Newton tolerance (rtol 1e-12)
    assert np.ptp(inv["mass"]) / inv["mass"][0] < 1e-10
    # a quartic H is not conserved by the midpoint rule, only up to a bounded
    # O(h^2) oscillation (measured ptp 3e-2 of |H0| at dt = 4e-3 with the
    # focusing peaks, omega_max dt = 1.7): bounded, and at dt / 2 four times smaller
    H = run.hamiltonian
    spread = np.ptp(H) / abs(H[0])
    assert spread < 0.1
    half = integrate_canonical(fom, run.q[:, 0], run.p[:, 0], cfg.dt / 2, 1000)
    ratio = spread / (np.ptp(half.hamiltonian) / abs(H[0]))
    assert 3.0 < ratio < 5.0, ratio                       # second order: 4


def test_avf_conserves_a_quartic_hamiltonian_to_the_newton_tolerance(setup):
    cfg, fom, run = setup
    avf = integrate_canonical(fom, run.q[:, 0], run.p[:, 0], cfg.dt, 250, scheme="avf")
    H = avf.hamiltonian
    # AVF with 2 Gauss points integrates the cubic gradient exactly, so
    # H(y1) - H(y0) = h G^T J G = 0 up to the Newton residual (rtol 1e-12) and
    # round-off of H (~|H_quad| eps, |H_quad| / |H| ~ 10 here)
    assert np.ptp(H) / abs(H[0]) < 1e-10
    # ... and it is second order: it stays within O(h^2) of the midpoint rule
    assert relative(avf.q[:, -1], run.q[:, 250]) < 0.05


# -- H-OpInf with the known nonlinear term ----------------------------------------
@pytest.fixture(scope="module")
def rich_data():
    """Broadband snapshots (every Fourier mode excited) with exact derivatives J grad H."""
    cfg = nls.NLSConfig.from_toml(nls.SCENE)
    fom = nls.full_model(cfg)
    rng = np.random.default_rng(5)
    q0, p0 = 0.5 * rng.standard_normal((2, cfg.n))
    run = integrate_canonical(fom, q0, p0, 1e-3, 300)
    dY = np.column_stack([fom.rhs(y) for y in np.vstack([run.q, run.p]).T])
    return cfg, fom, run.q, run.p, dY[: cfg.n], dY[cfg.n:]


@pytest.mark.parametrize("shared", [False, True])
def test_hopinf_with_the_full_basis_recovers_the_fom_operator(rich_data, shared):
    cfg, fom, Q, P, dQ, dP = rich_data
    V = CotangentLiftPSD(cfg.n, method="svd").fit(Q, P).phi_      # r = n: an orthogonal change of basis
    learner = HamiltonianOpInf(shared=shared).fit_snapshots(V, Q, P, ddt_q=dQ, ddt_p=dP,
                                                             potential=fom.potential)
    ops = learner.operators_
    assert np.array_equal(ops.position, ops.position.T) and np.array_equal(ops.momentum, ops.momentum.T)
    K = fom.position
    # exact derivatives, full basis: the regression is consistent, so D^ = V^T K V
    # up to the conditioning of the data Gram matrix (cond 1.5e8 here) times eps:
    # measured 2e-11 (separate) and 5e-12 (shared)
    assert relative(V @ ops.position @ V.T, K) < 1e-8
    assert relative(V @ ops.momentum @ V.T, K) < 1e-8
    assert learner.residual_ < 1e-10


@pytest.mark.parametrize("wrong", ["omitted", "q_and_p_swapped", "sign_flipped"])
def test_a_wrongly_projected_nonlinear_term_spoils_the_recovery(rich_data, wrong):
    """The recovery above fails when the known term enters wrongly: the check can fail."""
    cfg, fom, Q, P, dQ, dP = rich_data
    V = CotangentLiftPSD(cfg.n, method="svd").fit(Q, P).phi_
    gq, gp = fom.potential.gradient(Q, P)                 # dH_nl/dq, dH_nl/dp
    Fq, Fp = {"omitted": (0 * gp, 0 * gq), "q_and_p_swapped": (gq, gp),
              "sign_flipped": (-gp, -gq)}[wrong]
    learner = HamiltonianOpInf().fit(V.T @ Q, V.T @ P, V.T @ dQ, V.T @ dP, V.T @ Fq, V.T @ Fp)
    assert relative(V @ learner.operators_.position @ V.T, fom.position) > 1e-3
    assert learner.residual_ > 1e-3     # measured 2.7e-3 to 7e-3; 1e-14 with the right term


def test_projected_potential_is_the_gradient_of_the_reduced_hamiltonian(rich_data):
    cfg, fom, Q, P, _, _ = rich_data
    V = CotangentLiftPSD(10, method="svd").fit(Q, P).phi_
    pot = ProjectedPotential(fom.potential, V)
    rng = np.random.default_rng(0)
    q, p, dq, dp = rng.standard_normal((4, 10))
    gq, gp = pot.gradient(q, p)
    step = 1e-6      # central differences: O(step^2) ~ 1e-12 relative
    fd = (pot.value(q + step * dq, p + step * dp) - pot.value(q - step * dq, p - step * dp)) / (2 * step)
    assert fd == pytest.approx(gq @ dq + gp @ dp, rel=1e-7)
    hqq, hqp, hpp = pot.hessian(q, p)
    gq2, gp2 = pot.gradient(q + step * dq, p + step * dp)
    gq1, gp1 = pot.gradient(q - step * dq, p - step * dp)
    np.testing.assert_allclose((gq2 - gq1) / (2 * step), hqq @ dq + hqp @ dp, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose((gp2 - gp1) / (2 * step), hqp.T @ dq + hpp @ dp, rtol=1e-6, atol=1e-8)


def test_reduced_model_conserves_its_hamiltonian_and_mass(setup):
    cfg, fom, run = setup
    V = CotangentLiftPSD(12, method="svd").fit(run.q, run.p).phi_
    learner = HamiltonianOpInf(shared=True).fit_snapshots(V, run.q, run.p, cfg.dt, potential=fom.potential)
    rom = HamiltonianROM(learner.operators_, V, fom.potential)
    times = cfg.dt * np.arange(501)
    q0, p0 = V.T @ run.q[:, 0], V.T @ run.p[:, 0]
    Q, P, H = rom.predict(q0, p0, times, scheme="avf")
    assert np.allclose(H, rom.hamiltonian(Q, P))
    # energy-preserving scheme: the reduced H^ to the Newton tolerance
    assert np.ptp(H) / abs(H[0]) < 1e-10
    Q, P, H = rom.predict(q0, p0, times, scheme="midpoint")
    mass = np.sum(Q**2 + P**2, axis=0)
    # shared D^: H^ is phase-invariant, the reduced mass an exact quadratic
    # invariant, kept by the midpoint rule to the Newton tolerance
    assert np.ptp(mass) / mass[0] < 1e-10
    # the symplectic midpoint rule: bounded oscillation of H^, no drift
    assert np.ptp(H) / abs(H[0]) < 0.1
    assert abs(H[-100:].mean() - H[:100].mean()) / abs(H[0]) < 0.02
    with pytest.raises(ValueError, match="separable"):
        rom.predict(q0, p0, times, scheme="verlet")


# -- the case ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def quick_case(tmp_path_factory):
    out = tmp_path_factory.mktemp("nls")
    return nls.run(out, quick=True), out


def test_nls_case_writes_its_report(quick_case):
    metrics, out = quick_case
    for name in ("metrics.json", "report.md", "nls_state_error.png", "nls_invariants.png",
                 "nls_accuracy_cost.png", "nls_solution.png", "scene.toml"):
        assert (out / name).stat().st_size > 0, name
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["fom"]["dofs"] == 128
    assert "| method | r |" in (out / "report.md").read_text()


def test_nls_hopinf_conserves_mass_and_momentum_over_the_test_window(quick_case):
    """Train on [0, 2], predict to 10 (400 % outside), r = 20."""
    metrics, _ = quick_case
    fom, rows = metrics["fom"], metrics["headline"]
    shared, paper, plain, galerkin = (rows[k] for k in ("H-OpInf-shared", "H-OpInf", "OpInf", "Galerkin"))
    # H-OpInf with one symmetric D^: the reduced mass is an exact invariant of
    # the ROM and of the midpoint rule (measured 3e-15); 1e-10 allows the Newton tolerance
    assert shared["mass_drift_test"] < 1e-10
    # the grid momentum int (p_x q - q_x p) dx is not an exact invariant of the
    # finite-difference FOM itself (the cubic term breaks discrete translation
    # invariance): the FOM's own drift is 2.0e-2. The ROM tracks it (measured 2.0e-2)
    assert 5e-3 < fom["momentum_drift_test"] < 5e-2
    assert shared["momentum_drift_test"] < 1.5 * fom["momentum_drift_test"]
    # ... and stays accurate: test error within 2x of the intrusive Galerkin ROM (both ~3e-2)
    assert shared["test_error"] < 0.1
    assert shared["test_error"] < 2.0 * galerkin["test_error"]
    # The paper's separate fits of D^_q and D^_p: the Gram matrices of Q^ and P^
    # alone are ill-conditioned (~1e10), D^_q != D^_p by ~10 %, so the mass is no
    # longer exact: measured drift 1.7e-2, momentum 4.9e-2, state error 0.7. Bounded, but no invariant.
    assert 1e-4 < paper["mass_drift_test"] < 0.1
    assert paper["momentum_drift_test"] < 0.1
    assert paper["operator_asymmetry"] > 1e-2
    # Plain first-order OpInf on the same basis and data (no structure, RK4): blows up
    assert not plain["finite"]


def test_nls_full_basis_operator_error_falls_with_the_time_step(rich_data):
    """Theorem 1 of Sharma, Wang & Kramer: with finite-difference derivatives the learned
    operator converges to the intrusive one as dt -> 0, here at the order of the stencil."""
    cfg, fom, *_ = rich_data
    rng = np.random.default_rng(5)
    q0, p0 = 0.5 * rng.standard_normal((2, cfg.n))
    errors, dts = [], [4e-4, 2e-4, 1e-4]
    T = 0.2
    for dt in dts:
        run = integrate_canonical(fom, q0, p0, dt, int(round(T / dt)))
        V = np.eye(cfg.n)
        learner = HamiltonianOpInf(shared=True).fit_snapshots(V, run.q, run.p, dt, potential=fom.potential,
                                                              order=2)
        errors.append(relative(learner.operators_.position, fom.position))
    rate = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    # the midpoint trajectory is an O(dt^2) perturbation of the exact flow and the
    # second-order differences add O(dt^2): the error falls as dt^2
    assert abs(rate - 2.0) < 0.3, (rate, errors)
