"""The Galerkin model about a preloaded equilibrium: exact with the full basis, modal damping, equilibrium."""

import dataclasses

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from femrom.fem import JenkinsForce
from femrom.integrators import Newmark, StepResult, Trajectory, integrate
from femrom.inference import galerkin
from femrom.scene import SecondOrderSystem, Signal, SignalVector, solve_static

N = 8


def preloaded_chain():
    """A grounded chain, a Jenkins element on dof 3, a constant load that makes it slip."""
    K = sp.diags([200.0 * np.ones(N), -100.0 * np.ones(N - 1), -100.0 * np.ones(N - 1)], [0, 1, -1], format="csr")
    M = sp.diags(np.linspace(1.0, 2.0, N), format="csr")
    f0 = np.zeros(N)
    f0[3] = 30.0
    B = np.zeros((N, 1))
    B[5, 0] = 1.0
    pulse = SignalVector([Signal.from_dict({"kind": "impulse", "amplitude": 40.0, "start": 0.0, "duration": 0.05})])
    jenkins = JenkinsForce(50.0, 2.0, N, dofs=[3])
    system = SecondOrderSystem(mass=M, stiffness=K, damping=0.01 * K, input_matrix=B, inputs=pulse,
                               output_matrix=sp.csr_matrix(np.eye(N)[[6]]), nonlinear=jenkins, load=f0)
    static = solve_static(system)
    return system, static


def _run(system, q0, state, n=400, dt=2e-3):
    trajectory = Trajectory()
    start = StepResult.at_rest(q0.size, q=q0, state=state)
    integrate(system, Newmark(), None, None, dt, n, consumers=[trajectory], start=start, progress=False)
    return trajectory


def test_the_full_basis_about_the_preload_reproduces_the_full_run():
    system, static = preloaded_chain()
    z0 = static.state
    assert np.any(np.abs(z0[0] if isinstance(z0, tuple) else np.asarray(z0)) > 0)  # the preload made it slip
    # the model holds no signal of its own: it is driven by the full system's pulse
    reduced = dataclasses.replace(galerkin(system, np.eye(N), reference=static.displacement).system,
                                  inputs=system.inputs)
    # q^ = 0 is an equilibrium of the reduced system: K^ 0 + f^(0; z0) = load^
    assert np.allclose(reduced.nonlinear.force(np.zeros(N), None, z0), reduced.load, atol=1e-12 * 30)
    full = _run(system, static.displacement, z0)
    hat = _run(reduced, np.zeros(N), z0)
    # same equations in shifted coordinates: equal to round-off (measured 3e-15 of the motion)
    motion = np.max(np.abs(full.q - static.displacement[:, None]))
    assert motion > 1e-3  # the pulse moves the chain and re-slides the element
    assert np.max(np.abs(full.q - static.displacement[:, None] - hat.q)) < 1e-10 * motion


def test_modal_damping_on_a_mass_normalised_mode_basis():
    system, static = preloaded_chain()
    K_t = system.stiffness + system.nonlinear.tangent(static.displacement, None, static.state)[0]
    values, shapes = sla.eigh(K_t.toarray(), system.mass.toarray())
    V = shapes[:, :4]
    reduced = galerkin(system, V, reference=static.displacement, reference_state=static.state,
                       damping_ratios=0.02).system
    assert np.allclose(reduced.mass, np.eye(4), atol=1e-12)
    assert np.allclose(reduced.damping, np.diag(2 * 0.02 * np.sqrt(values[:4])), rtol=1e-10)
    assert reduced.output_matrix.shape == (1, 4) and reduced.input_matrix.shape == (4, 1)
    with pytest.raises(ValueError, match="needs a mass-normalised basis"):
        galerkin(system, 2 * V, damping_ratios=0.02)
    with pytest.raises(ValueError, match=r"basis has shape \(5, 4\), expected \(8, r\)"):
        galerkin(system, V[:5])


def test_a_static_solve_on_the_galerkin_model_commits_without_velocities():
    """``solve_static`` on the Galerkin model (the full basis about the preload) commits the joint's state with
    no velocity (a static step), as on the full model: the same displacement under an extra load."""
    system, static = preloaded_chain()
    reduced = galerkin(system, np.eye(N), reference=static.displacement).system
    extra = np.zeros(N)
    extra[3] = 5.0
    full = solve_static(system, system.load + extra, state=static.state)
    hat = solve_static(reduced, reduced.load + extra, state=static.state)
    np.testing.assert_allclose(hat.displacement + static.displacement, full.displacement, atol=1e-10)
