"""femrom.rom.HamiltonianROM and the error split of femrom.inference.HamiltonianOpInf.

Two canonical systems, both small enough for seconds:

- a linear wave ``q' = p``, ``p' = -K q`` (K the Dirichlet finite-difference
  Laplacian, n = 64) with an exact six-mode solution and exact derivatives;
- a cubic NLS ``H = q^T K q / 2 + p^T K p / 2 - gamma/4 sum (q^2 + p^2)^2`` on 32
  periodic points (K = -Laplacian), FOM by the implicit midpoint rule.
"""

import numpy as np
import pytest

from femrom.inference import CanonicalData, HamiltonianOperators, HamiltonianOpInf
from femrom.fem import QuarticPotential
from femrom.integrators import CanonicalSystem, Newton, integrate_canonical
from femrom.integrators import time_scheme
from femrom.rom import HamiltonianROM, HamiltonianSolution


def relative(A, B):
    return np.linalg.norm(A - B) / np.linalg.norm(B)


def wave(steps=2000, T=2.0, n=64):
    """Exact solution of the linear wave on [0, T]: (K, t, Q, P, Q', P')."""
    h = 1.0 / (n + 1)
    K = (np.diag(2.0 * np.ones(n)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1)) / h**2
    lam, E = np.linalg.eigh(K)
    w = np.sqrt(lam[:6])
    t = np.linspace(0.0, T, steps + 1)
    a = np.array([1.0, 0.5, 0.3, 0.2, 0.1, 0.05])
    Q = E[:, :6] @ (a[:, None] * np.cos(np.outer(w, t)))
    P = E[:, :6] @ (-(w * a)[:, None] * np.sin(np.outer(w, t)))
    return K, t, Q, P, P.copy(), -K @ Q


def lift(Q, P, r):
    """Cotangent-lift POD basis Phi (n, r) of [Q, P]: orthonormal columns."""
    return np.linalg.svd(np.hstack([Q, P]), full_matrices=False)[0][:, :r]


@pytest.fixture(scope="module")
def linear():
    K, t, Q, P, dQ, dP = wave()
    return K, t, Q, P, dQ, dP, lift(Q, P, 6)


@pytest.fixture(scope="module")
def nls():
    n, gamma = 32, 1.0
    dx = 2 * np.pi / n
    K = (2 * np.eye(n) - np.roll(np.eye(n), 1, 0) - np.roll(np.eye(n), -1, 0)) / dx**2
    potential = QuarticPotential(gamma)
    fom = CanonicalSystem(K, K, potential)
    x = dx * np.arange(n)
    q0, p0 = 1.2 / np.cosh(2 * (x - np.pi)), 0.3 * np.sin(x)
    dt = 2e-3
    run = integrate_canonical(fom, q0, p0, dt, 300)
    return fom, potential, dt, run, lift(run.q, run.p, 8)


# -- fit and predict ------------------------------------------------------------
def test_fit_and_predict_reproduce_the_hopinf_model(linear):
    K, t, Q, P, dQ, dP, Phi = linear
    rom = HamiltonianROM(basis=Phi, learner=HamiltonianOpInf()).fit_snapshots(Q, P, ddt_q=dQ, ddt_p=dP)
    reference = HamiltonianOpInf().fit_snapshots(Phi, Q, P, ddt_q=dQ, ddt_p=dP)
    # the same computation on the same data: bitwise
    np.testing.assert_array_equal(rom.operators_.position, reference.operators_.position)
    np.testing.assert_array_equal(rom.operators_.momentum, reference.operators_.momentum)
    # ... and it is the intrusive model: exact derivatives in span(Phi), so the
    # Lyapunov solution is Phi^T K Phi up to cond(Gram) ~ 1e6 times eps
    galerkin = HamiltonianROM.galerkin(CanonicalSystem(K, np.eye(K.shape[0])), Phi)
    assert relative(rom.operators_.position, galerkin.operators_.position) < 1e-8
    assert relative(rom.operators_.momentum, np.eye(6)) < 1e-8
    assert rom.metadata_["method"] == "hamiltonian_opinf" and galerkin.metadata_["method"] == "galerkin"

    solution = rom.predict(t, initial=(Phi.T @ Q[:, 0], Phi.T @ P[:, 0]))
    assert isinstance(solution, HamiltonianSolution) and solution.info["scheme"] == "midpoint"
    # predict is the learned operators' step matrix applied k times (the same
    # products in the same order)
    S = time_scheme("midpoint").canonical_step_matrix(reference.operators_.position, reference.operators_.momentum,
                                                      t[1] - t[0])
    y = np.concatenate([Phi.T @ Q[:, 0], Phi.T @ P[:, 0]])
    for k in range(1, 4):
        y = S @ y
        np.testing.assert_array_equal(np.concatenate([solution.q[:, k], solution.p[:, k]]), y)
    # full initial conditions are reduced by Phi^T: the same trajectory
    full = rom.predict(t, initial=(Q[:, 0], P[:, 0]))
    np.testing.assert_array_equal(full.q, solution.q)
    # against the exact solution: the midpoint rule's second-order phase error,
    # (w_max dt)^2 = 3.5e-4 per radian at most, measured 5.7e-5 over the window
    assert relative(Phi @ solution.q, Q) < 3.5e-4
    # old callers unpack the result as (Q, P, H)
    q, p, H = solution
    assert q is solution.q and p is solution.p and H is solution.hamiltonian


def test_symplectic_schemes_conserve_the_reduced_hamiltonian(linear):
    K, t, Q, P, dQ, dP, Phi = linear
    rom = HamiltonianROM(basis=Phi).fit_snapshots(Q, P, ddt_q=dQ, ddt_p=dP)
    times = np.arange(10001) * 1e-3                          # 5 training windows
    q0, p0 = Phi.T @ Q[:, 0], Phi.T @ P[:, 0]
    H = rom.predict(times, initial=(q0, p0), scheme="midpoint").hamiltonian
    # quadratic invariant, kept exactly by the midpoint rule: 1e4 steps of round-off (~1e-16 each)
    assert np.ptp(H) / H[0] < 1e-11
    # without a potential AVF is the midpoint rule
    np.testing.assert_array_equal(rom.predict(times, initial=(q0, p0), scheme="avf").q,
                                  rom.predict(times, initial=(q0, p0)).q)
    for scheme in ("symplectic_euler_a", "symplectic_euler_b", "verlet"):
        H = rom.predict(times, initial=(q0, p0), scheme=scheme).hamiltonian
        # a modified Hamiltonian is conserved: H oscillates by O(w_max dt) = 1.9e-2
        # (Euler; O((w_max dt)^2) for Verlet), no drift. Measured: ptp 7.0e-3 (Euler A, B),
        # 1.8e-5 (Verlet); change of the mean over 10 windows 2e-6, 4e-9
        assert np.ptp(H) / H[0] < 0.05, scheme
        assert abs(H[-1000:].mean() - H[:1000].mean()) / H[0] < 1e-4, scheme
    with pytest.raises(ValueError, match="scheme 'rk4' does not step canonical models; valid: central_difference, "
                                         "discrete_gradient, implicit_midpoint, symplectic_euler_a"):
        rom.predict(times, initial=(q0, p0), scheme="rk4")


def test_nls_rom_with_a_known_potential_conserves_h_and_mass(nls):
    fom, potential, dt, run, Phi = nls
    rom = HamiltonianROM(basis=Phi, potential=potential,
                         learner=HamiltonianOpInf(shared=True)).fit_snapshots(run.q, run.p, dt)
    times = dt * np.arange(301)
    q0, p0 = Phi.T @ run.q[:, 0], Phi.T @ run.p[:, 0]
    avf = rom.predict(times, initial=(q0, p0), scheme="avf")
    # AVF conserves the quartic H^ exactly up to the Newton residual: each step
    # may leave rtol = 1e-12 of it (about one iteration a step here), so over
    # 300 steps H^ may move by 300 rtol = 3e-10 relative; measured 1.4e-10
    assert np.ptp(avf.hamiltonian) / abs(avf.hamiltonian[0]) < 1e-9
    np.testing.assert_allclose(avf.hamiltonian, rom.hamiltonian(avf.q, avf.p), rtol=1e-13)
    # ... which is the Newton tolerance, not the scheme: at rtol 1e-14 only round-off
    # of H^ (~|H_quad| eps, |H_quad| / |H^| = 1.5) is left, measured 1.3e-15
    tight = HamiltonianROM(rom.operators_, Phi, potential, Newton(rtol=1e-14))
    H = tight.predict(times, initial=(q0, p0), scheme="avf").hamiltonian
    assert np.ptp(H) / abs(H[0]) < 1e-13
    assert avf.info["newton_iterations"] > 0
    mid = rom.predict(times, initial=(q0, p0))
    mass = np.sum(mid.q**2 + mid.p**2, axis=0)
    # shared D^ and a phase-invariant potential: the reduced mass is a quadratic
    # invariant of the ROM, kept by the midpoint rule to the Newton tolerance
    # (300 steps of rtol 1e-12 as above; measured 1.1e-11)
    assert np.ptp(mass) / mass[0] < 1e-9
    # the ROM follows the FOM on its training window (r = 8 of 32; measured 4.6e-3)
    assert relative(Phi @ mid.q, run.q) < 2e-2
    with pytest.raises(ValueError, match="separable"):
        rom.predict(times, initial=(q0, p0), scheme="verlet")


# -- lazy fields -------------------------------------------------------------------
def test_fields_are_rebuilt_only_when_asked(linear):
    K, t, Q, P, dQ, dP, Phi = linear
    rom = HamiltonianROM(basis=Phi.copy()).fit_snapshots(Q, P, ddt_q=dQ, ddt_p=dP)
    solution = rom.predict(t, initial=(Phi.T @ Q[:, 0], Phi.T @ P[:, 0]))
    n = Phi.shape[0]
    # nothing of full size was computed: every array held has r or fewer rows
    arrays = [v for v in vars(solution).values() if isinstance(v, np.ndarray) and v is not solution.basis]
    assert arrays and all(a.shape[0] <= 6 for a in arrays if a.ndim == 2)
    assert solution.basis is rom.basis                     # a reference, not a copy
    blocks = list(solution.fields(block=512))
    assert [x.shape for _, x in blocks] == [(n, 512), (n, 512), (n, 512), (n, 465)]
    # block products equal the whole one up to BLAS's choice of kernel for each shape
    # (measured: 8 of 128,064 entries differ, in the last bit); 1e-14 of the peak is that
    whole_q, whole_p = Phi @ solution.q, Phi @ solution.p
    np.testing.assert_allclose(np.hstack([x for _, x in blocks]), whole_q, rtol=0,
                               atol=1e-14 * np.abs(whole_q).max())
    np.testing.assert_allclose(np.hstack([x for _, x in solution.fields(which="p")]), whole_p, rtol=0,
                               atol=1e-14 * np.abs(whole_p).max())
    np.testing.assert_array_equal(solution.field(7, "p"), Phi @ solution.p[:, 7])
    # computed on request from the basis as it is then: scaling it in place after
    # predict changes the fields (an eager reconstruction would not see it)
    rom.basis *= 2.0
    np.testing.assert_array_equal(solution.field(10), (2.0 * Phi) @ solution.q[:, 10])
    with pytest.raises(ValueError, match="unknown field"):
        solution.field(0, "v")
    nobasis = HamiltonianROM(rom.operators_).predict(t[:3], initial=(np.ones(6), np.zeros(6)))
    with pytest.raises(ValueError, match="no basis"):
        nobasis.field(0)


# -- save / load -------------------------------------------------------------------
def test_save_load_predicts_bit_identically(linear, tmp_path):
    K, t, Q, P, dQ, dP, Phi = linear
    Y = Q[:3] + 0.5 * P[10:13]                                 # three outputs linear in [q; p]
    rom = HamiltonianROM(basis=Phi, learner=HamiltonianOpInf(regularization=1e-12),
                         scheme="verlet").fit_snapshots(Q, P, t[1] - t[0], order=6, outputs=Y)
    path = tmp_path / "wave.h5"
    rom.save(path)
    loaded = HamiltonianROM.load(path)
    assert loaded.scheme == "verlet" and loaded.newton == rom.newton
    np.testing.assert_array_equal(loaded.basis, Phi)
    np.testing.assert_array_equal(loaded.output_matrix_, rom.output_matrix_)
    meta = loaded.metadata_
    assert meta["method"] == "hamiltonian_opinf" and meta["regularization"] == 1e-12
    assert meta["data"]["derivative_source"] == "finite_difference" and meta["data"]["order"] == 6
    assert set(meta["error_split"]) == {"projection", "derivative", "position_derivative",
                                        "momentum_derivative", "optimization"}
    a = rom.predict(t, initial=(Q[:, 0], P[:, 0]))
    b = loaded.predict(t, initial=(Q[:, 0], P[:, 0]))
    for name in ("q", "p", "hamiltonian", "outputs"):
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
    assert b.info["scheme"] == "verlet"
    # Y is linear in [q; p] and the snapshots lie in span(Phi): the least-squares
    # output map is exact up to round-off (measured 1.2e-15) ...
    X = np.vstack([Phi.T @ Q, Phi.T @ P])
    assert relative(rom.output_matrix_ @ X, Y) < 1e-12
    # ... and the predicted outputs carry Verlet's O((w dt)^2) phase error, measured 5.6e-5
    assert relative(a.outputs, Y) < 3.5e-4
    rom.save(tmp_path / "nobasis.h5", include_basis=False)
    assert HamiltonianROM.load(tmp_path / "nobasis.h5").basis is None
    with pytest.raises(ValueError, match="without a potential"):
        HamiltonianROM.load(path, potential=QuarticPotential(1.0))
    with pytest.raises(ValueError, match="not a femrom HamiltonianROM"):
        import h5py
        with h5py.File(tmp_path / "other.h5", "w") as f:
            f.attrs["format"] = "something else"
        HamiltonianROM.load(tmp_path / "other.h5")


def test_save_load_with_a_known_potential(nls, tmp_path):
    fom, potential, dt, run, Phi = nls
    rom = HamiltonianROM(basis=Phi, potential=potential).fit_snapshots(run.q, run.p, dt)
    path = tmp_path / "nls.h5"
    rom.save(path)
    # the potential is code: the file names it and asks for it back
    with pytest.raises(ValueError, match=r"QuarticPotential\(gamma=1.0\).*pass potential="):
        HamiltonianROM.load(path)
    with pytest.raises(ValueError, match="does not match"):
        HamiltonianROM.load(path, potential=QuarticPotential(2.0))
    loaded = HamiltonianROM.load(path, potential=QuarticPotential(1.0))
    times = dt * np.arange(101)
    a = rom.predict(times, initial=(run.q[:, 0], run.p[:, 0]))
    b = loaded.predict(times, initial=(run.q[:, 0], run.p[:, 0]))
    np.testing.assert_array_equal(b.q, a.q)
    np.testing.assert_array_equal(b.hamiltonian, a.hamiltonian)
    with pytest.raises(ValueError, match="include_basis=True"):
        rom.save(tmp_path / "x.h5", include_basis=False)


# -- the error split -----------------------------------------------------------------
def test_projection_error_matches_a_direct_computation():
    K, t, Q, P, dQ, dP = wave(steps=1000)
    Phi = lift(Q, P, 4)                                       # 4 of 6 modes: a real projection error
    learner = HamiltonianOpInf().fit_snapshots(Phi, Q, P, ddt_q=dQ, ddt_p=dP)
    split = learner.error_split_
    Y = np.vstack([Q, P])
    direct = np.linalg.norm(Y - np.vstack([Phi @ (Phi.T @ Q), Phi @ (Phi.T @ P)])) / np.linalg.norm(Y)
    assert direct > 0.1                                       # measured 0.29
    # the same sums of squares in another order: round-off
    assert split.projection == pytest.approx(direct, rel=1e-12)
    # stored derivatives were the training data
    assert split.derivative == 0.0 and split.position_derivative == 0.0
    # the optimisation residual is the data-column residual, and residual_ is it
    Dq, Dp = learner.operators_.position, learner.operators_.momentum
    Qh, Ph = Phi.T @ Q, Phi.T @ P
    R = np.vstack([Phi.T @ dQ - Dp @ Ph, -Phi.T @ dP - Dq @ Qh])
    assert split.optimization == learner.residual_
    assert split.optimization == pytest.approx(
        np.linalg.norm(R) / np.linalg.norm(np.vstack([Phi.T @ dQ, Phi.T @ dP])), rel=1e-12)
    # reduced data: no projection, no derivative reference
    plain = HamiltonianOpInf().fit(CanonicalData(Qh, Ph, Phi.T @ dQ, Phi.T @ dP)).error_split_
    assert plain.projection is None and plain.derivative is None
    assert HamiltonianOpInf().fit_snapshots(Phi, Q, P, t[1] - t[0]).error_split_.derivative is None


def test_a_small_projection_error_is_resolved():
    """Six modes and r = 6 plus a small component outside span(Phi): the projection
    error is ~1e-10. From the columns it is exact to round-off; the expansion
    ||X||^2 - ||Phi^T X||^2 cancels to eps ||X||^2, i.e. ~1e-8 (or 0)."""
    K, t, Q, P, dQ, dP = wave(steps=1000)
    Phi = lift(Q, P, 6)
    outside = np.linalg.eigh(K)[1][:, 20]                     # orthogonal to the six modes
    Q = Q + 1e-9 * np.linalg.norm(Q) / np.sqrt(t.size) * np.outer(outside, np.cos(t))
    split = HamiltonianOpInf().fit_snapshots(Phi, Q, P, ddt_q=dQ, ddt_p=dP).error_split_
    Y = np.vstack([Q, P])
    direct = np.linalg.norm(Y - np.vstack([Phi @ (Phi.T @ Q), Phi @ (Phi.T @ P)])) / np.linalg.norm(Y)
    assert 3e-11 < direct < 1e-8                              # measured 1.2e-10
    # the same differences, summed in another order (measured 6e-15 apart); the
    # residual's own round-off (eps ||X|| per entry, 2e-16 / 1.2e-10 relative)
    # allows 1e-5; the Gram expansion is off by O(1) here (the mutation fails)
    assert split.projection == pytest.approx(direct, rel=1e-5)


def test_optimization_residual_resolves_below_sqrt_eps(linear):
    """Exact derivatives, full-rank basis of the data: the residual is at round-off
    (a Gram expansion ||R||^2 = c - ... would floor at sqrt(eps) ~ 1.5e-8)."""
    K, t, Q, P, dQ, dP, Phi = linear
    learner = HamiltonianOpInf().fit_snapshots(Phi, Q, P, ddt_q=dQ, ddt_p=dP)
    assert learner.error_split_.optimization < 1e-12          # measured 2.4e-15
    assert learner.error_split_.projection < 1e-13            # six modes, r = 6: measured 9e-16


def test_derivative_error_falls_with_the_finite_difference_order():
    """Finite differences of the reduced snapshots against the exact derivatives:
    falls with the stencil's order at fixed dt, and with dt at that order."""
    errors = {}
    for steps in (1000, 2000):
        K, t, Q, P, dQ, dP = wave(steps=steps)
        Phi = lift(Q, P, 6)
        for order in (2, 4, 6):
            learner = HamiltonianOpInf().fit_snapshots(Phi, Q, P, t[1] - t[0], ddt_q=dQ, ddt_p=dP,
                                                       derivatives="finite_difference", order=order)
            errors[order, steps] = learner.error_split_.derivative
            split = learner.error_split_
            assert split.derivative == pytest.approx(np.hypot(
                split.position_derivative * np.linalg.norm(Phi.T @ dQ),
                split.momentum_derivative * np.linalg.norm(Phi.T @ dP))
                / np.linalg.norm(np.vstack([Phi.T @ dQ, Phi.T @ dP])), rel=1e-12)
    # w_max dt = 1.9e-2 at 1000 steps: measured 1.2e-4, 2.8e-8, 1.1e-11
    assert errors[2, 1000] > 1e3 * errors[4, 1000] > 1e6 * errors[6, 1000]
    # halving dt: ratios 2^p (measured 4.01 and 16.5); order 6 is at round-off by then
    for order in (2, 4):
        slope = np.log2(errors[order, 1000] / errors[order, 2000])
        assert abs(slope - order) < 0.2, (order, slope)


# -- bad input ---------------------------------------------------------------------
def test_bad_input_gives_one_line_errors(linear):
    K, t, Q, P, dQ, dP, Phi = linear
    with pytest.raises(ValueError, match="pass basis=Phi"):
        HamiltonianROM().fit_snapshots(Q, P, ddt_q=dQ, ddt_p=dP)
    with pytest.raises(ValueError, match="not orthonormal"):
        HamiltonianROM(basis=2.0 * Phi).fit_snapshots(Q, P, ddt_q=dQ, ddt_p=dP)
    with pytest.raises(ValueError, match="not fitted"):
        HamiltonianROM(basis=Phi).predict(t, initial=(np.zeros(6), np.zeros(6)))
    rom = HamiltonianROM(HamiltonianOperators(np.eye(6), np.eye(6)), Phi)
    with pytest.raises(ValueError, match="expected r = 6"):
        rom.predict(t, initial=(np.zeros(5), np.zeros(6)))
    with pytest.raises(ValueError, match="uniformly spaced"):
        rom.predict(np.array([0.0, 1.0, 3.0]), initial=(np.zeros(6), np.zeros(6)))
    with pytest.raises(ValueError, match="need dt"):
        HamiltonianOpInf().fit_snapshots(Phi, Q, P)
    with pytest.raises(ValueError, match="expected"):
        CanonicalData(Phi.T @ Q, Phi.T @ P[:, :-1], Phi.T @ dQ, Phi.T @ dP)
    with pytest.raises(ValueError, match="unknown derivatives"):
        HamiltonianOpInf().fit_snapshots(Phi, Q, P, 1e-3, derivatives="exact")
    with pytest.raises(ValueError, match="columns"):
        HamiltonianROM(HamiltonianOperators(np.eye(5), np.eye(5)), Phi)
