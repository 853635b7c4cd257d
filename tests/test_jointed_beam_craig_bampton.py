"""Craig-Bampton of the jointed beam with a JointForce on its interface pairs, and the impact
ring-down's discrete energy balance.

The joint is built directly from ``femrom.mesh.interface_pairs`` (the scene effect comes
separately); the law parameters are plausible, not calibrated. Mesh: 25.4 / 12.7 mm, P2, no
holes (7,908 dofs, 149 pairs): the Craig-Bampton set-up takes about 10 s.
"""

import dataclasses

import numpy as np
import pytest
import scipy.linalg as sl
from scipy.sparse.linalg import eigsh

import femrom.mesh as fm
from femrom.fem import JointForce, interface_law
from femrom.integrators import EnergyBalance, Newmark, Newton, integrate
from femrom.scene import Scene, build, craig_bampton

E, NU, RHO = 2.0e11, 0.29, 7800.0
PATCH = 0.00635                                    # the sensor / hammer patch side (geometry default)
PEAK, WIDTH = 300.0, 3e-4                          # hammer: 300 N, 0.3 ms (docs/jointed_beam.md)
N_MODES = 30
PARAMETERS = {"mesh_size": 0.0254, "joint_mesh_size": 0.0127, "bonded": 0, "holes": 0}


def jointed_beam(cache):
    """The free-free jointed beam: Rayleigh damping, the hammer on the `impact` patch (a uniform
    traction of total force u(t) downwards), acc3 (mean y displacement of its patch), and an Iwan
    joint on the P2 interface pairs."""
    scene = Scene.from_dict({
        "name": "jointed_brb",
        "structure": {"geometry": "jointed_beam", "element": "p2", "parameters": PARAMETERS},
        "material": {"youngs_modulus": E, "poisson_ratio": NU, "density": RHO},
        "effects": {"inertia": {}, "elasticity": {}, "damping": {"alpha": 0.5, "beta": 2e-7}, "actuation": {}},
        "inputs": [{"name": "hammer", "load": {"kind": "surface_traction", "at": "impact", "direction": [0, -1, 0],
                                              "magnitude": 1 / PATCH**2},
                    "signal": {"kind": "impulse", "amplitude": PEAK, "duration": WIDTH, "start": 1e-4}}],
        "outputs": {"averages": [{"name": "acc3", "over": "acc3", "component": "y"}]},
        "time": {"t_end": 0.01, "dt": 5e-5}})
    mesh = fm.build_mesh("jointed_beam", PARAMETERS, cache_dir=cache)
    linear = build(scene, mesh=mesh).system
    pairs = fm.interface_pairs(mesh, "interface_left", "interface_right", order=2)
    dofs = pairs.dofs()                               # free-free: the free dofs are all the dofs
    law = interface_law("iwan", slip_traction=1e7, tangential_stiffness=1e12, chi=-0.5, beta=0.1,
                        normal_stiffness=1e13, n_sliders=20)
    joint = JointForce(law, dofs[:, 0], dofs[:, 1], pairs.normals, pairs.areas, linear.n_dofs, name="joint")
    return dataclasses.replace(linear, nonlinear=joint), pairs


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    system, pairs = jointed_beam(tmp_path_factory.mktemp("jointed-cb"))
    return system, pairs, craig_bampton(system, N_MODES, solver="superlu")


def stuck(system):
    """The joint's tangent at rest (stuck, closed) added to K: the linearised jointed beam."""
    joint = system.nonlinear
    D0 = joint.local_tangent(np.zeros(joint.n_local), None, joint.initial_state())[0]
    return system.stiffness + joint.local_map.T @ D0 @ joint.local_map


def test_the_boundary_is_the_interface_the_hammer_and_acc3(model):
    system, pairs, cb = model
    # 149 pairs x 2 sides x 3 + the impact and acc3 patches' y dofs (13 each, disjoint)
    assert pairs.n_pairs == 149 and cb.n_boundary == 6 * 149 + 26
    assert cb.system.n_dofs == cb.n_boundary + N_MODES
    # the hammer's column still sums to one newton down, now on physical boundary coordinates
    assert cb.system.input_matrix.sum() == pytest.approx(-1.0, rel=1e-12)


def test_linearised_frequencies_approach_the_full_ones_from_above(model):
    system, _, cb = model
    full, _ = eigsh(stuck(system).tocsc(), k=14, M=system.mass.tocsc(), sigma=-(2 * np.pi * 10) ** 2, which="LM")
    full = np.sort(full)
    reduced = sl.eigh(stuck(cb.system).toarray(), cb.system.mass.toarray(), eigvals_only=True,
                      subset_by_index=(0, 13))
    # six rigid-body modes in both (free-free): measured |omega^2| < 0.02 (reduced) and < 2e-5 (full)
    # rad^2/s^2 against omega_7^2 = 4.5e5, round-off amplified by the stiff joint
    assert np.abs(reduced[:6]).max() < 1e-6 * full[6] and np.abs(full[:6]).max() < 1e-6 * full[6]
    # the eight lowest elastic modes (106.5 to 1402 Hz): Rayleigh-Ritz upper bounds, measured
    # relative errors of omega^2 from 1.3e-6 (first bending) to 2.7e-4 with 30 fixed-interface modes
    error = reduced[6:] / full[6:] - 1
    assert np.all(error > -1e-9) and error.max() < 1e-3
    assert error[0] < 1e-5


def test_the_reduced_joint_is_the_full_joint_at_the_expanded_state(model):
    system, _, cb = model
    joint, reduced = system.nonlinear, cb.system.nonlinear
    T = cb.transformation
    q_hat = 1e-6 * np.random.default_rng(2).standard_normal(cb.system.n_dofs)
    state = joint.initial_state()
    expected = T.T @ joint.force(T @ q_hat, None, state)
    # the same local coordinates and law (L only reads boundary dofs): round-off, measured 2e-16
    assert np.abs(reduced.force(q_hat, None, state) - expected).max() <= 1e-12 * np.abs(expected).max()
    assert reduced.stored_energy(q_hat, state) == pytest.approx(joint.stored_energy(T @ q_hat, state), rel=1e-12)


def test_impact_ring_down_balances_energy_every_step(model):
    """300 N half-sine hammer blow (0.3 ms) at the impact patch, 10 ms of the ring-down (200 steps of
    50 us, Newmark average acceleration, Newton condensed onto the joint's 447 coordinates)."""
    _, _, cb = model
    ledger = EnergyBalance(cb.system)
    summary = integrate(cb.system, Newmark(newton=Newton(rtol=1e-10, method="condensed")),
                        np.zeros(cb.system.n_dofs), np.zeros(cb.system.n_dofs), 5e-5, 200,
                        consumers=[ledger], progress=False)
    assert summary.details["newton"] == "condensed" and summary.details["condensed_coordinates"] == 447
    work = ledger.external_work[-1]
    # the blow's work: 5.1 mJ measured (impulse 2 P tau / pi = 0.057 N s on 1.6 kg)
    assert 1e-3 < work < 2e-2
    # Newmark's identity, to the Newton tolerance (rtol 1e-10 of the balanced forces): measured 2.8e-9
    assert np.abs(ledger.scheme_residual).max() < 1e-7 * work
    # with friction: the stick/slip switches' O(dt^2); the worst step measured 4.4e-5 of the work
    assert np.abs(ledger.residual).max() < 3e-4 * work
    # the joint dissipated (measured 5.1 % of the work in 10 ms) and Rayleigh damping too (13 %)
    assert ledger.friction[-1] > 0.01 * work and ledger.rayleigh[-1] > 0.01 * work
    # over the run: what is left vibrating is the work minus what was dissipated, to the sum of the
    # steps' residuals (measured 2.6e-3 of the work after 200 steps: they add up with one sign)
    left = ledger.kinetic[-1] + ledger.strain[-1] + ledger.joint_energy[-1]
    assert left == pytest.approx(work - ledger.rayleigh[-1] - ledger.friction[-1], rel=1e-2)
