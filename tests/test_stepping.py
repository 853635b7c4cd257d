"""Reduced models one step at a time and as discrete state spaces: the same trajectory as
``predict``, cross-checked against python-control."""

import numpy as np
import pytest
import scipy.sparse as sp

from _required import extra
from femrom.fem import JenkinsForce, LocalPotential
from femrom.inference import ProjectedNonlinearForce, ReducedOperators
from femrom.integrators import registered_schemes
from femrom.rom import DiscreteStateSpace, SecondOrderROM
from femrom.scene import SecondOrderSystem


def relative(A, B):
    return float(np.linalg.norm(A - B) / np.linalg.norm(B))


def linear_rom(r=8, m=2, p=3, seed=0, load=True):
    """A random stable second-order ROM: K SPD, C PSD, non-identity M, inputs, outputs, f_0."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((r, r))
    K = A @ A.T + r * np.eye(r)
    L = rng.standard_normal((r, r)) / np.sqrt(r)
    M = np.eye(r) + 0.1 * L @ L.T
    C = 0.02 * K + 0.01 * np.eye(r)
    ops = ReducedOperators.from_matrices(K, mass=M, damping=C, input_matrix=rng.standard_normal((r, m)),
                                         output_matrix=rng.standard_normal((p, r)),
                                         load=rng.standard_normal(r) if load else None)
    return SecondOrderROM(ops), rng


# the bounds below: two exact implementations of one linear recurrence, 400 steps of round-off
# (~1e-16 per step, amplified at most by the step map's norm ~1): 1e-12 relative leaves room.
@pytest.mark.parametrize("scheme", ["newmark", "midpoint", "verlet"])
def test_state_space_form_equals_predict(scheme):
    rom, rng = linear_rom(load=False)
    times = 0.01 * np.arange(401)
    U = np.vstack([np.sin(3 * times), np.cos(7 * times) ** 2])
    q0, v0 = rng.standard_normal(8), rng.standard_normal(8)
    solution = rom.predict(times, U, initial=(q0, v0), scheme=scheme)
    ss = rom.to_state_space(0.01, scheme)
    assert (ss.n_states, ss.n_inputs, ss.n_outputs) == (16, 2, 3)
    z0 = ss.initial_state(np.concatenate([q0, v0]), U[:, 0])
    Y, Z = ss.simulate(U, z0)
    assert relative(Y, solution.outputs) < 1e-12
    # the state is [q; v] shifted by E u: unshifted it is the reduced trajectory
    X = Z + ss.input_offset @ U
    assert relative(X[:8], solution.q) < 1e-12 and relative(X[8:], solution.v) < 1e-12
    # python-control, an independent simulator of (A, B, C, D, dt), gives the same outputs
    control = extra("control")
    response = control.forced_response(ss.to_control(), T=times, U=U, X0=z0)
    assert relative(np.atleast_2d(response.outputs), solution.outputs) < 1e-12


def test_a_constant_load_is_a_constant_input_channel_of_the_state_space():
    rom, rng = linear_rom()
    times = 0.01 * np.arange(301)
    U = np.vstack([np.sin(3 * times), np.ones_like(times)])
    solution = rom.predict(times, U, initial=np.zeros(8))
    ss = rom.to_state_space(0.01)
    assert ss.metadata["constant_input"] and ss.n_inputs == 3
    Ua = np.vstack([U, np.ones_like(times)])
    Y, _ = ss.simulate(Ua, ss.initial_state(np.zeros(16), Ua[:, 0]))
    assert relative(Y, solution.outputs) < 1e-12


@pytest.mark.parametrize("scheme", sorted(name for name, cls in registered_schemes().items()
                                           if "second_order" in cls.models))
def test_stepper_follows_predict_one_input_at_a_time(scheme):
    """``y = stepper.step(u_{k+1})`` with the input samples of ``predict``: the same outputs;
    the state space's own stepper too."""
    rom, rng = linear_rom()
    times = 0.01 * np.arange(301)
    U = np.vstack([np.sin(3 * times), np.cos(5 * times)])
    q0 = rng.standard_normal(8)
    solution = rom.predict(times, U, initial=q0, scheme=scheme)
    stepper = rom.stepper(0.01, initial=q0, u0=U[:, 0], scheme=scheme)
    Y = np.column_stack([stepper.outputs] + [stepper.step(U[:, k]) for k in range(1, times.size)])
    assert relative(Y, solution.outputs) < 1e-12
    if scheme == "generalized_alpha":      # its acceleration is a state of its own: no [q; v] state space
        with pytest.raises(ValueError, match=r"no \[q; v\] state space"):
            rom.to_state_space(0.01, scheme)
        return
    ss = rom.to_state_space(0.01, scheme)
    Ua = np.vstack([U, np.ones_like(times)])
    plant = ss.stepper(initial=ss.initial_state(np.concatenate([q0, np.zeros(8)]), Ua[:, 0]), u0=Ua[:, 0])
    Y2 = np.column_stack([plant.output] + [plant.step(Ua[:, k]) for k in range(1, times.size)])
    assert relative(Y2, solution.outputs) < 1e-12


def test_a_nonlinear_stateful_rom_steps_like_it_predicts_and_has_no_state_space():
    n = 12
    K = sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
    forces = [LocalPotential.cubic(np.ones(3), 5.0, dofs=[2, 6, 9], n_dofs=n, name="springs"),
              JenkinsForce(1.0, 0.02, n, dofs=[4], name="slider")]
    B = np.zeros((n, 1))
    B[-1, 0] = 1.0
    system = SecondOrderSystem(mass=sp.identity(n, format="csr"), stiffness=K, damping=0.01 * K,
                               nonlinear=forces, input_matrix=B, inputs=lambda t: np.array([np.sin(t)]),
                               output_matrix=sp.csr_matrix(B.T))
    V = np.linalg.eigh(K.toarray())[1][:, :6]
    rom = SecondOrderROM.galerkin(system, V, mass_orthonormal=True)
    assert isinstance(rom.operators_.term("projected_force"), ProjectedNonlinearForce)
    times = 0.05 * np.arange(201)
    U = np.sin(times)[None]
    for scheme in ("newmark", "midpoint"):
        solution = rom.predict(times, U, initial=0.3 * np.ones(6), scheme=scheme)
        stepper = rom.stepper(0.05, initial=0.3 * np.ones(6), u0=U[:, 0], scheme=scheme)
        Y = np.column_stack([stepper.outputs] + [stepper.step(U[:, k]) for k in range(1, times.size)])
        # the same steps in the same order (outputs by matrix-vector instead of matrix-matrix
        # products: a last-bit difference)
        assert relative(Y, solution.outputs) < 1e-14
        assert stepper.iterations == solution.info["newton_iterations"] > 0
    with pytest.raises(ValueError, match="nonlinear terms \\(projected_force\\).*no linear state-space"):
        rom.to_state_space(0.05)


def test_state_space_save_load_and_checks(tmp_path):
    rom, _ = linear_rom(load=False)
    ss = rom.to_state_space(0.02)
    ss.save(tmp_path / "ss.h5")
    loaded = DiscreteStateSpace.load(tmp_path / "ss.h5")
    for name in ("A", "B", "C", "D", "input_offset"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(ss, name))
    assert loaded.dt == 0.02 and loaded.metadata["scheme"] == "newmark"
    # Newmark with C > 0, K > 0: every pole strictly inside the unit circle
    assert np.max(np.abs(ss.poles())) < 1.0
    with pytest.raises(ValueError, match="dt must be a finite number > 0, got 0.0"):
        DiscreteStateSpace(np.eye(2), np.zeros((2, 1)), np.eye(2), np.zeros((2, 1)), dt=0.0)
    with pytest.raises(ValueError, match="input has 3 entries, expected 2"):
        ss.stepper(initial=np.zeros(16)).step(np.ones(3))
    with pytest.raises(ValueError, match="dt must be a finite number > 0, got nan"):
        rom.to_state_space(float("nan"))


def test_a_discrete_state_space_refuses_misshapen_or_non_finite_matrices():
    """n = 4 states, m = 2 inputs, p = 3 outputs: every matrix in its place or one error naming it
    (a transposed B, C or D used to be reshaped silently into another matrix)."""
    from femrom import FemromValueError

    rng = np.random.default_rng(0)
    A, B, C, D = 0.5 * np.eye(4), rng.standard_normal((4, 2)), rng.standard_normal((3, 4)), np.zeros((3, 2))
    model = DiscreteStateSpace(A, B, C, D, dt=0.1)
    assert (model.n_states, model.n_inputs, model.n_outputs) == (4, 2, 3)
    for args, message in [((A, B.T, C, D), r"B has shape \(2, 4\), expected \(n_states, n_inputs\) = \(4, m\) "
                                            r"\(a transposed B\?\)"),
                          ((A, B, C.T, D), r"C has shape \(4, 3\), expected \(n_outputs, n_states\) = \(p, 4\) "
                                           r"\(a transposed C\?\)"),
                          ((A, B, C, D.T), r"D has shape \(2, 3\), expected \(n_outputs, n_inputs\) = \(3, 2\)"),
                          ((np.where(np.eye(4) > 0, np.nan, 0.0), B, C, D), "A has non-finite entries"),
                          ((A[:, :3], B, C, D), r"A has shape \(4, 3\), expected square"),
                          ((A, "b", C, D), "B must be a numeric array, got str")]:
        with pytest.raises(FemromValueError, match=message):
            DiscreteStateSpace(*args, dt=0.1)
    # vectors are one input column and one output row; a scalar D is every entry
    single = DiscreteStateSpace(A, B[:, 0], C[0], 0.0, dt=0.1)
    assert single.B.shape == (4, 1) and single.C.shape == (1, 4) and single.D.shape == (1, 1)
    with pytest.raises(FemromValueError, match="z0 must be a finite state of 4 entries, got 3"):
        model.simulate(np.zeros((2, 5)), np.zeros(3))


def test_hamiltonian_rom_steps_like_it_predicts():
    from femrom.inference import HamiltonianOperators
    from femrom.rom import HamiltonianROM

    rng = np.random.default_rng(4)
    A = rng.standard_normal((5, 5))
    ops = HamiltonianOperators(position=A @ A.T + np.eye(5), momentum=np.eye(5))
    rom = HamiltonianROM(ops, output_matrix=rng.standard_normal((2, 10)))
    times = 0.02 * np.arange(101)
    q0, p0 = rng.standard_normal(5), np.zeros(5)
    for scheme in ("midpoint", "verlet", "symplectic_euler_a"):
        solution = rom.predict(times, initial=(q0, p0), scheme=scheme)
        stepper = rom.stepper(0.02, initial=(q0, p0), scheme=scheme)
        Y = np.column_stack([stepper.outputs] + [stepper.step() for _ in range(100)])
        assert relative(Y, solution.outputs) < 1e-12
        ss = rom.to_state_space(0.02, scheme)
        Y2, _ = ss.simulate(None, np.concatenate([q0, p0]), n_steps=100)
        assert relative(Y2, solution.outputs) < 1e-12
