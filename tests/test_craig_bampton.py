"""Craig-Bampton reduction that keeps a nonlinear force, on small free-free systems.

References: the full model's generalized eigenvalues (dense ``eigh``), its static solution,
its nonlinear force evaluated at the expanded state, and its own Newmark run.
"""

import numpy as np
import pytest
import scipy.linalg as sl
import scipy.sparse as sp

from femrom.fem import JointForce, TransformedForce, force_from_parameters, interface_law
from femrom.integrators import EnergyBalance, Newmark, Newton, Trajectory, integrate
from femrom.scene import SecondOrderSystem, Signal, craig_bampton

N = 60
JOINT_A, JOINT_B, LOAD_DOF, OUTPUT_DOF = [10, 11, 12], [30, 31, 32], 50, 55
ALPHA, BETA = 0.5, 2e-5


def springs(n, pairs):
    """Sparse stiffness (or mass-coupling) of two-point springs ``(i, j, k)``: rows sum to zero."""
    rows, cols, values = [], [], []
    for i, j, k in pairs:
        rows += [i, j, i, j]
        cols += [i, j, j, i]
        values += [k, k, -k, -k]
    return sp.csr_matrix((values, (rows, cols)), shape=(n, n))


def chain(n=N, seed=3, law=None):
    """A free-free chain: springs to the next and the next-but-one mass (one rigid-body mode, the
    uniform translation), a non-diagonal SPD mass, Rayleigh damping, one input at LOAD_DOF, one
    output at OUTPUT_DOF, and a joint pair between dofs JOINT_A and JOINT_B (tilted normal)."""
    rng = np.random.default_rng(seed)
    K = springs(n, [(i, i + 1, k) for i, k in enumerate(rng.uniform(1e4, 2e4, n - 1))]
                + [(i, i + 2, k) for i, k in enumerate(rng.uniform(1e3, 5e3, n - 2))])
    M = (sp.diags(rng.uniform(1.0, 2.0, n)) + springs(n, [(i, i + 1, 0.05) for i in range(n - 1)])).tocsr()
    law = law or interface_law("jenkins", tangential_stiffness=2e4, slip_traction=0.1, normal_stiffness=2e4)
    joint = JointForce(law, np.array([JOINT_A]), np.array([JOINT_B]), np.array([[0.3, 0.2, 1.0]]),
                       np.array([0.5]), n, name="joint")
    B = np.zeros((n, 1))
    B[LOAD_DOF] = 1.0
    E = sp.csr_matrix(([1.0], ([0], [OUTPUT_DOF])), shape=(1, n))
    pulse = Signal.from_dict({"kind": "impulse", "amplitude": 40.0, "duration": 2e-3, "start": 1e-3})
    return SecondOrderSystem(mass=M, stiffness=K, damping=(ALPHA * M + BETA * K).tocsr(), input_matrix=B,
                             inputs=lambda t: np.atleast_1d(pulse(t)), output_matrix=E, nonlinear=[joint])


def eigenvalues(system):
    return sl.eigh(system.stiffness.toarray(), system.mass.toarray(), eigvals_only=True)


@pytest.fixture(scope="module")
def system():
    return chain()


def test_boundary_is_the_joint_the_load_and_the_output(system):
    cb = craig_bampton(system, 4)
    assert cb.boundary_dofs.tolist() == sorted(JOINT_A + JOINT_B + [LOAD_DOF, OUTPUT_DOF])
    assert cb.system.n_dofs == 8 + 4 and cb.transformation.shape == (N, 12)
    # the boundary dofs stay physical: T[b] = [I 0] exactly
    assert np.array_equal(cb.transformation[cb.boundary_dofs], np.eye(8, 12))
    assert cb.coordinate(LOAD_DOF) == 6
    with pytest.raises(ValueError, match="dof 3 is not a boundary dof"):
        cb.coordinate(3)


def test_all_interior_modes_reproduce_the_full_frequencies(system):
    full = eigenvalues(system)
    cb = craig_bampton(system, N - 8)
    reduced = eigenvalues(cb.system)
    # T square and invertible: the same pencil in other coordinates. Measured 2.6e-14 relative
    # (elastic) and |lambda_0| 2.6e-14 (full: 3.1e-12; rigid, against lambda_1 = 47); 1e-10 is
    # round-off of eigh on a pencil with condition ~1e5.
    assert np.abs(reduced[1:] / full[1:] - 1).max() < 1e-10
    assert abs(reduced[0]) < 1e-10 * full[1] and abs(full[0]) < 1e-10 * full[1]


def test_fewer_modes_bound_the_frequencies_from_above_and_converge_monotonically(system):
    full = eigenvalues(system)[1:7]                               # the six lowest elastic modes
    errors = []
    for n_modes in (1, 2, 4, 8, 16):
        reduced = eigenvalues(craig_bampton(system, n_modes).system)[1:7]
        # Rayleigh-Ritz: each reduced eigenvalue is an upper bound (to round-off, 1e-12)
        assert np.all(reduced >= full * (1 - 1e-12))
        errors.append(reduced / full - 1)
    errors = np.array(errors)
    # nested subspaces: no eigenvalue gets worse as modes are added, the largest error strictly falls
    assert np.all(np.diff(errors, axis=0) <= 1e-12)
    assert np.all(np.diff(errors.max(axis=1)) < 0)
    # measured largest relative errors of omega^2: 3.3, 1.9, 0.31, 3.8e-2, 2.2e-3 (the sixth mode;
    # the first: 2.5e-2 ... 5.9e-5); the bound leaves room for round-off, the floor shows a real error
    assert errors[-1].max() < 5e-3 and errors[0].max() > 1.0


def test_a_static_load_on_boundary_dofs_is_reproduced_exactly(system):
    # grounded at two interior dofs so that K is regular (the static condensation needs no rigid mode)
    ground = sp.csr_matrix(([5e3, 5e3], ([3, 40], [3, 40])), shape=(N, N))
    grounded = SecondOrderSystem(mass=system.mass, stiffness=(system.stiffness + ground).tocsr(),
                                 nonlinear=system.nonlinear)
    cb = craig_bampton(grounded, 3, boundary_dofs=[LOAD_DOF])
    rng = np.random.default_rng(0)
    f = np.zeros(N)
    f[cb.boundary_dofs] = rng.standard_normal(cb.n_boundary)
    q = sp.linalg.spsolve(grounded.stiffness.tocsc(), f)
    q_hat = np.linalg.solve(cb.system.stiffness.toarray(), cb.transformation.T @ f)
    # exact whatever the number of modes; measured 2e-15 relative (round-off of two solves)
    assert np.linalg.norm(cb.expand(q_hat) - q) < 1e-12 * np.linalg.norm(q)
    assert np.abs(q_hat[cb.n_boundary:]).max() < 1e-12 * np.abs(q_hat).max()  # no modal response


def test_free_free_rigid_motion_lies_in_the_constraint_modes(system):
    cb = craig_bampton(system, 5)
    rigid = np.ones(N)                                            # K 1 = 0: the chain's rigid mode
    assert np.linalg.norm(system.stiffness @ rigid) < 1e-9 * sp.linalg.norm(system.stiffness)
    rigid_hat = np.zeros(cb.system.n_dofs)
    rigid_hat[:cb.n_boundary] = 1.0
    # the constraint modes carry the interior along (Psi 1 = 1 since K_ii 1 + K_ib 1 = 0): measured 5e-15
    assert np.abs(cb.expand(rigid_hat) - rigid).max() < 1e-12
    K_hat = cb.system.stiffness
    assert np.linalg.norm(K_hat @ rigid_hat) < 1e-10 * np.abs(K_hat).max()


def test_a_boundary_that_leaves_a_free_body_inside_is_refused():
    # two chains not connected: the boundary dofs all on the first leave the second free
    one = springs(20, [(i, i + 1, 1.0) for i in range(9)] + [(i, i + 1, 1.0) for i in range(10, 19)])
    system = SecondOrderSystem(mass=sp.identity(20, format="csr"), stiffness=one)
    with pytest.raises(ValueError, match=r"K_ii is singular.*do not hold the 18 interior dofs"):
        craig_bampton(system, 2, boundary_dofs=[0, 5])
    with pytest.raises(ValueError, match=r"n_modes must lie in \[0, 18\]"):
        craig_bampton(system, 19, boundary_dofs=[0, 15])
    with pytest.raises(ValueError, match="needs boundary dofs"):
        craig_bampton(system, 2)


def test_inputs_outputs_and_rayleigh_damping_are_carried_over(system):
    cb = craig_bampton(system, 6)
    T, reduced = cb.transformation, cb.system
    assert np.array_equal(reduced.input_matrix, T.T @ system.input_matrix)
    # E reads a boundary dof: E T is a unit row at its coordinate, exactly
    assert np.array_equal(reduced.output_matrix.toarray(), np.eye(1, 14, cb.coordinate(OUTPUT_DOF)))
    # Rayleigh stays Rayleigh: C^ = alpha M^ + beta K^ (measured 4e-16 of |C^|)
    rayleigh = ALPHA * reduced.mass.toarray() + BETA * reduced.stiffness.toarray()
    assert np.abs(reduced.damping.toarray() - rayleigh).max() < 1e-12 * np.abs(rayleigh).max()
    assert reduced.external_force(2e-3) == pytest.approx(T.T @ system.external_force(2e-3), rel=1e-15)


def test_the_reduced_force_is_the_full_force_at_the_expanded_state(system):
    cb = craig_bampton(system, 6)
    joint, reduced = system.nonlinear, cb.system.nonlinear
    assert isinstance(reduced, TransformedForce) and reduced.name == "joint" and reduced.stateful
    T = cb.transformation
    rng = np.random.default_rng(1)
    state = joint.initial_state()
    for scale in (1e-7, 1e-3):                                    # stuck, then sliding (slip traction 0.1 Pa)
        q_hat = scale * rng.standard_normal(cb.system.n_dofs)
        q = T @ q_hat
        # the same local coordinates (L T q^ = L q) and law: equal to round-off (measured 0 or 1e-16)
        assert np.allclose(reduced.localize(q_hat), joint.localize(q), rtol=1e-14, atol=0)
        expected = T.T @ joint.force(q, None, state)
        assert np.abs(reduced.force(q_hat, None, state) - expected).max() <= 1e-13 * np.abs(expected).max()
        tangent = T.T @ joint.tangent(q, None, state)[0].toarray() @ T
        assert np.abs(reduced.tangent(q_hat, None, state)[0].toarray() - tangent).max() \
            <= 1e-13 * np.abs(tangent).max()
        committed, expected_state = reduced.commit(q_hat, None, state), joint.commit(q, None, state)
        # the same slider positions (L T q^ and L q differ by round-off only)
        assert np.allclose(joint.checkpoint(committed)["slip"], joint.checkpoint(expected_state)["slip"],
                           rtol=1e-13, atol=1e-13 * np.abs(joint.localize(q)).max())
        assert reduced.dissipation(q_hat, state) == pytest.approx(joint.dissipation(q, state), rel=1e-13)
        assert reduced.stored_energy(q_hat, state) == pytest.approx(joint.stored_energy(q, state), rel=1e-13)
        state = committed
    assert np.abs(joint.checkpoint(state)["slip"]).max() > 0          # the larger state did slide
    rebuilt = force_from_parameters(reduced.parameters())
    assert type(rebuilt) is TransformedForce and rebuilt.force_model.law == joint.law
    assert (rebuilt.local_map != reduced.local_map).nnz == 0


def test_with_all_modes_the_reduced_run_is_the_full_run(system):
    """Newmark is invariant under a fixed invertible change of coordinates: with every interior mode
    kept, the Craig-Bampton run expanded by T is the full run, up to the Newton tolerance."""
    cb = craig_bampton(system, N - 8)
    runs = []
    for model in (system, cb.system):
        trajectory = Trajectory()
        integrate(model, Newmark(newton=Newton(rtol=1e-12, method="condensed")), np.zeros(model.n_dofs),
                  np.zeros(model.n_dofs), 2e-4, 400, consumers=[trajectory], progress=False)
        runs.append(trajectory)
    full, reduced = runs[0].q, cb.expand(runs[1].q)
    # measured 9.7e-15 of the largest displacement; 1e-9 allows the Newton tolerance (1e-12) times
    # the conditioning of T
    assert np.abs(reduced - full).max() < 1e-9 * np.abs(full).max()
    assert np.abs(full).max() > 1e-4                              # the pulse moved the chain


@pytest.mark.parametrize("nonlinear", [False, True])
def test_the_energy_balance_holds_every_step(system, nonlinear):
    """Average acceleration balances work, kinetic, strain and Rayleigh energy exactly; with the
    joint, the trapezoidal work on it equals the interface springs' energy plus the friction
    dissipated, up to the stick/slip switches' O(dt^2)."""
    model = craig_bampton(system if nonlinear else SecondOrderSystem(
        mass=system.mass, stiffness=system.stiffness, damping=system.damping, input_matrix=system.input_matrix,
        inputs=system.inputs, output_matrix=system.output_matrix), 10,
        boundary_dofs=JOINT_A + JOINT_B).system
    errors = []
    for dt in (4e-4, 2e-4):
        ledger = EnergyBalance(model)
        integrate(model, Newmark(newton=Newton(rtol=1e-12, method="condensed")), np.zeros(model.n_dofs),
                  np.zeros(model.n_dofs), dt, int(round(0.2 / dt)), consumers=[ledger], progress=False)
        work = ledger.external_work[-1]
        assert work > 0 and ledger.rayleigh[-1] > 0.05 * work      # energy went in; Rayleigh took 13.6 %
        # the scheme's identity: measured 1.5e-15 of the work (with the joint and without)
        assert np.abs(ledger.scheme_residual).max() < 1e-11 * work
        if nonlinear:
            assert ledger.friction[-1] > 0.01 * work               # the joint slid: measured 2.8 % of the work
            errors.append(np.abs(ledger.residual).max() / work)
        else:
            assert np.abs(ledger.residual).max() < 1e-11 * work
    if nonlinear:
        # the worst step: measured 1.6e-6 (dt = 4e-4) and 3.6e-7 (2e-4) of the input work, ratio 4.5
        # (second order: 4); the bound is 6x the coarse value, the ratio band excludes first order (2)
        assert errors[0] < 1e-5
        assert 3.0 < errors[0] / errors[1] < 6.0


def test_the_half_sine_pulse_spectrum_is_its_fourier_transform():
    """The ``impulse`` signal's closed-form spectrum against a direct quadrature of its Fourier
    integral (the hammer: 300 N, 0.3 ms)."""
    from femrom.scene import half_sine_spectrum

    peak, width = 300.0, 3e-4
    pulse = Signal.from_dict({"kind": "impulse", "amplitude": peak, "duration": width, "start": 0.0})
    t = np.linspace(0.0, width, 200_001)
    u = pulse(t)
    for f in (0.0, 845.6, 0.5 / width, 1.98e3, 1.5 / width, 7e3):
        integrand = u * np.exp(-2j * np.pi * f * t)
        numeric = abs(np.sum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(t)))
        # trapezoid on 2e5 intervals: error ~1e-10 of the impulse 2 P tau / pi = 0.0573 N s
        assert half_sine_spectrum(f, peak, width) == pytest.approx(numeric, abs=1e-9 * 2 * peak * width / np.pi)
    # the band the width sets: 3 dB at f tau = 0.594, zero at 1.5
    assert half_sine_spectrum(0.594 / width, peak, width) / half_sine_spectrum(0.0, peak, width) \
        == pytest.approx(2 ** -0.5, abs=1e-3)
