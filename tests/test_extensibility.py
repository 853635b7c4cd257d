"""The extensible core: a new reduced term is one class, effects and learners are found
by registries, forces sum with their own states, and the integrators run Newton only on
a force's own coordinates."""

import numpy as np
import pytest
import scipy.sparse as sp

from femrom.fem import ForceSum, JenkinsForce, LocalPotential
from femrom.inference import (
    TERMS,
    ConstantLoad,
    LagrangianOpInf,
    ProjectedNonlinearForce,
    SecondOrderOpInf,
    galerkin,
    learner_class,
    reduce_snapshots,
    registered_learners,
    registered_terms,
)
from femrom.integrators import ImplicitMidpoint, Newmark, Newton, Trajectory, integrate
from femrom.rom import SecondOrderROM
from femrom.scene import SecondOrderSystem


def relative(A, B):
    return float(np.linalg.norm(A - B) / np.linalg.norm(B))


def chain(n=30, seed=1, damping=0.0):
    """Fixed-fixed spring-mass chain: lumped masses in [1, 1.5], springs in [1, 2]."""
    rng = np.random.default_rng(seed)
    m = 1.0 + 0.5 * rng.random(n)
    k = 1.0 + rng.random(n + 1)
    K = sp.diags([k[:-1] + k[1:], -k[1:-1], -k[1:-1]], [0, 1, -1], format="csr")
    M = sp.diags(m, format="csr")
    return M, K


def mass_orthonormal_modes(M, K):
    w2, Phi = np.linalg.eigh(np.linalg.solve(np.sqrt(M.toarray()), np.linalg.solve(np.sqrt(M.toarray()), K.toarray()).T))
    return np.sqrt(w2), np.linalg.solve(np.sqrt(M.toarray()), Phi)


# -- 1. a new term in one class -------------------------------------------------------
def test_a_term_written_in_one_class_is_projected_learned_predicted_and_saved(tmp_path):
    """A 10-dof chain under a constant load f_0 and a sine input, released from a random
    state, Newmark's stored (v, a) over 100 s (five periods of the slowest mode: the
    data identify every mode, kappa(D) ~ 3e2): the new term's Galerkin projection is
    V^T f_0; L-OpInf and plain OpInf learn it from the data to the data's round-off
    (the stored Newmark derivatives satisfy the equation at every step); the ROM
    predicts with it and saves and loads it."""
    assert registered_terms()["constant_load"] is ConstantLoad
    M, K = chain(10)
    n = M.shape[0]
    rng = np.random.default_rng(2)
    f0 = rng.standard_normal(n)
    B = np.zeros((n, 1))
    B[n // 3, 0] = 1.0
    inputs = lambda t: np.array([np.sin(1.7 * t)])  # noqa: E731
    system = SecondOrderSystem(mass=M, stiffness=K, damping=0.02 * K, input_matrix=B, inputs=inputs,
                               load=f0, output_matrix=sp.csr_matrix(B.T))
    assert system.effects == ("inertia", "stiffness", "damping", "inputs", "load", "outputs")
    w, Phi = mass_orthonormal_modes(M, K)
    V = Phi                                                   # full basis: exact reduction
    trajectory = Trajectory()
    q0 = V @ rng.standard_normal(n)                            # every mode in the data
    integrate(system, Newmark(), q0, np.zeros(n), 0.05, 2000, consumers=[trajectory])
    U = np.column_stack([inputs(t) for t in trajectory.t])
    data = reduce_snapshots(V, trajectory.q, 0.05, product=M, velocities=trajectory.v,
                            accelerations=trajectory.a, derivatives="stored", inputs=U,
                            outputs=system.outputs(trajectory.q))
    intrusive = galerkin(system, V, mass_orthonormal=True)
    np.testing.assert_allclose(intrusive.term("constant_load").matrix[:, 0], V.T @ f0, rtol=1e-14)
    np.testing.assert_allclose(intrusive.load, V.T @ f0, rtol=1e-14)
    for learner in (LagrangianOpInf(["damping", "constant_load"]), SecondOrderOpInf(["damping", ConstantLoad]),
                    LagrangianOpInf.for_system(system)):
        ops = learner.fit(data).operators_
        # Newmark's (v, a) satisfy the equations to its solver's round-off (~1e-13 relative)
        assert relative(ops.load, intrusive.load) < 1e-9, type(learner).__name__
        assert relative(ops.stiffness, intrusive.stiffness) < 1e-9
    # without the term the constant load cannot be explained: the fit is visibly worse
    assert LagrangianOpInf(["damping"]).fit(data).error_split_.optimization > 1e-2
    # predict with the learned term reproduces the FOM (full basis, same scheme)
    rom = SecondOrderROM(learner=LagrangianOpInf.for_system(system), basis=V, product=M).fit(data)
    solution = rom.predict(trajectory.t, inputs, initial=V.T @ (M @ q0))
    assert relative(V @ solution.q, trajectory.q) < 1e-8
    # the energy includes the load's potential -f_0^T q; galerkin and learned agree
    assert relative(solution.energy, SecondOrderROM(intrusive, V).predict(trajectory.t, inputs, initial=V.T @ (M @ q0)).energy) < 1e-8
    rom.save(tmp_path / "rom.h5")
    loaded = SecondOrderROM.load(tmp_path / "rom.h5", product=M)
    np.testing.assert_array_equal(loaded.operators_.load, rom.operators_.load)
    np.testing.assert_array_equal(loaded.predict(trajectory.t, inputs, initial=V.T @ (M @ q0)).q, solution.q)


def test_galerkin_refuses_an_effect_no_term_projects():
    M, K = chain(8)

    class Gyro:  # a system effect femrom has no term for
        pass

    system = SecondOrderSystem(mass=M, stiffness=K)
    object.__setattr__(system, "metadata", {})
    ops = galerkin(system, np.eye(8))
    assert [t.name for t in ops.terms] == ["mass", "stiffness"]
    with pytest.raises(ValueError, match="no registered reduced term projects the system's load"):
        saved = TERMS.remove("constant_load")            # the registry without the test's term
        try:
            galerkin(SecondOrderSystem(mass=M, stiffness=K, load=np.ones(8)), np.eye(8))
        finally:
            TERMS.add("constant_load", saved)


def test_learners_are_found_by_name_and_fit_only_named_terms():
    assert {"galerkin", "lopinf", "opinf", "hopinf"} <= set(registered_learners())
    assert learner_class("lopinf") is LagrangianOpInf
    with pytest.raises(ValueError, match="unknown learner 'dmd'; registered: canonical_opinf, dmdc, era, galerkin, hopinf, iwan_lopinf, lopinf, okid, opinf, spml"):
        learner_class("dmd")
    with pytest.raises(ValueError, match="unknown reduced term 'gravity'; registered: mass"):
        LagrangianOpInf(["gravity"])
    assert not LagrangianOpInf().damping and LagrangianOpInf(["damping"]).damping


# -- 2. composite, stateful forces; Newton on their own coordinates ----------------------
def jointed_chain(n=40, condense="auto"):
    """The chain with a cubic spring layer on 4 dofs and grounded Jenkins elements on 3 others."""
    M, K = chain(n)
    layer = LocalPotential.of_density("duffing", np.full(4, 0.5), dofs=[3, 17, 18, 30], n_dofs=n,
                                      linear=0.3, cubic=20.0, name="layer")
    joint = JenkinsForce(np.array([2.0, 3.0, 1.5]), np.array([0.05, 0.08, 0.04]), n, dofs=[8, 9, 25],
                         name="joint")
    B = np.zeros((n, 1))
    B[-1, 0] = 1.0
    system = SecondOrderSystem(mass=M, stiffness=K, damping=0.01 * K, nonlinear=[layer, joint],
                               input_matrix=B, inputs=lambda t: np.array([0.6 * np.sin(0.9 * t)]))
    q0 = 0.4 * np.sin(np.linspace(0.0, np.pi, n))
    return system, q0


@pytest.mark.parametrize("scheme", [Newmark, ImplicitMidpoint])
def test_condensed_newton_gives_the_full_newton_trajectory_with_one_factorisation(scheme):
    """Two forces on 7 of 40 dofs, one with hysteresis: Newton condensed onto the forces'
    7 coordinates follows the same trajectory as Newton on all 40 dofs (both converge to
    rtol = 1e-13 of the balanced forces: agreement to 1e-10 leaves three orders of margin),
    with one factorisation of the linear step instead of one per iteration."""
    system, q0 = jointed_chain()
    assert isinstance(system.nonlinear, ForceSum)
    assert [f.name for f in system.nonlinear_forces] == ["layer", "joint"]
    runs = {}
    for method in ("full", "condensed"):
        trajectory = Trajectory(fields=("q", "v"))
        summary = integrate(system, scheme(newton=Newton(rtol=1e-13, method=method)), q0, np.zeros(40),
                            0.05, 600, consumers=[trajectory], progress=False)
        runs[method] = (trajectory, summary)
    full, condensed = runs["full"][1], runs["condensed"][1]
    assert relative(runs["condensed"][0].q, runs["full"][0].q) < 1e-10
    assert relative(runs["condensed"][0].v, runs["full"][0].v) < 1e-10
    assert condensed.details["newton"] == "condensed" and condensed.details["condensed_coordinates"] == 7
    assert full.n_factorizations == full.newton_iterations > 600      # one per iteration
    assert condensed.n_factorizations == 1                             # the linear step, once
    # full Newton: 1-3 iterations a step; the condensed one keeps its factorised (7, 7)
    # tangent while it contracts (measured: one factorisation in 600 steps, 4-5 chord
    # iterations a step), the same stopping test in force units
    assert 600 <= full.newton_iterations <= 3 * 600
    assert 600 <= condensed.newton_iterations <= 8 * 600
    assert 1 <= condensed.details["local_factorizations"] <= 60


def test_auto_condenses_a_force_on_few_dofs_and_not_one_on_every_dof():
    system, q0 = jointed_chain()
    summary = integrate(system, Newmark(), q0, np.zeros(40), 0.05, 3, progress=False)
    assert summary.details["newton"] == "dense"          # 40 dofs: at most dense_max, dense arrays
    sparse = Newmark(newton=Newton(dense_max=0))         # as if the chain were large
    summary = integrate(system, sparse, q0, np.zeros(40), 0.05, 3, progress=False)
    assert summary.details["newton"] == "condensed"
    M, K = chain(40)
    everywhere = SecondOrderSystem(mass=M, stiffness=K, nonlinear=LocalPotential.sine_gordon(np.ones(40)))
    summary = integrate(everywhere, sparse, q0, np.zeros(40), 0.05, 3, progress=False)
    assert summary.details["newton"] == "full"
    with pytest.raises(ValueError, match="unknown Newton method 'schur'"):
        Newton(method="schur")


def test_a_sum_of_stateful_forces_resumes_bit_identically_from_its_checkpoint(tmp_path):
    """The sum's state (the sliders of its Jenkins part) is checkpointed under the forces'
    names; a run stopped at step 150 and resumed from the store equals an unbroken run."""
    from femrom.snapshots import SnapshotStore, resume

    system, q0 = jointed_chain()
    v0 = np.zeros(40)
    reference = SnapshotStore.create(tmp_path / "ref.h5", system, fields=("q", "v", "a"), scheme=Newmark(),
                                     dt=0.05, n_steps=300)
    integrate(system, Newmark(), q0, v0, 0.05, 300, consumers=[reference.writer(chunk_steps=16)],
              progress=False)

    def stop(result):
        if result.step == 150:
            raise KeyboardInterrupt

    store = SnapshotStore.create(tmp_path / "a.h5", system, fields=("q", "v", "a"), scheme=Newmark(),
                                 dt=0.05, n_steps=300)
    with pytest.raises(KeyboardInterrupt):
        integrate(system, Newmark(), q0, v0, 0.05, 300, consumers=[store.writer(chunk_steps=16), stop],
                  progress=False)
    state = store.checkpoint(0).state
    assert state[0] is None and state[1].shape == (3,) and np.any(state[1] != 0.0)   # the sliders moved
    store.close()
    resume(tmp_path / "a.h5", system, Newmark())
    done = SnapshotStore.open(tmp_path / "a.h5")
    for field in ("q", "v", "a"):
        np.testing.assert_array_equal(done.read(0, field), reference.read(0, field))
    done.close()


def test_a_stateful_known_force_is_the_learning_target_along_the_trajectory():
    """L-OpInf with the jointed chain's known forces projected (full basis, stored Newmark
    derivatives): evaluated along each trajectory with the sliders' state, the target is
    the force the FOM felt and the linear part comes out to the Newton tolerance; evaluated
    without state (every column from a fresh slider) the same data give a visibly wrong K^."""
    system, q0 = jointed_chain()
    n = system.n_dofs
    w, V = mass_orthonormal_modes(system.mass, system.stiffness)
    trajectory = Trajectory()
    integrate(system, Newmark(newton=Newton(rtol=1e-13)), q0, np.zeros(n), 0.05, 800, consumers=[trajectory],
              progress=False)
    U = np.column_stack([system.inputs(t) for t in trajectory.t])
    data = reduce_snapshots(V, trajectory.q, 0.05, product=system.mass, velocities=trajectory.v,
                            accelerations=trajectory.a, derivatives="stored", inputs=U)
    known = ProjectedNonlinearForce(system.nonlinear, V)
    assert known.stateful
    learner = LagrangianOpInf(["damping", known]).fit(data)
    intrusive = galerkin(system, V, mass_orthonormal=True)
    # measured: residual 9e-13, K^ within 2e-9 and C^ (100x smaller) within 1e-7 of Galerkin
    assert learner.error_split_.optimization < 1e-10
    assert relative(learner.stiffness_, intrusive.stiffness) < 2e-8
    assert relative(learner.damping_, intrusive.damping) < 1e-6

    class Forgetful(ProjectedNonlinearForce):   # the same force, blind to its history
        stateful = False

    wrong = LagrangianOpInf(["damping", Forgetful(system.nonlinear, V)]).fit(data)
    # measured: residual 3e-2 and K^ off by 250 %
    assert wrong.error_split_.optimization > 1e-3 and relative(wrong.stiffness_, intrusive.stiffness) > 0.1
    # the reduced model with the stateful projected force reproduces the FOM (full basis)
    rom = SecondOrderROM(learner.operators_, V, product=system.mass)
    solution = rom.predict(trajectory.t, U, initial=rom.reduce(q0))     # r = n: reduce explicitly
    assert relative(V @ solution.q, trajectory.q) < 1e-9           # measured 8e-13


# -- 3. effects: one registered class each ----------------------------------------------
BEAM = {
    "name": "cantilever",
    "structure": {"geometry": "beam_line", "element": "hermite", "parameters": {"length": 1.0, "mesh_size": 0.05}},
    "material": {"youngs_modulus": 2.1e11, "density": 7850.0, "area": 2e-4, "second_moment": 1.6667e-9},
    "effects": {"inertia": {}, "bending": {}},
    "boundary": {"clamped": ["left"]},
    "time": {"t_end": 0.01, "dt": 1e-3},
    "outputs": {"probes": [{"name": "tip", "at": "right", "component": "w"}]},
}


def test_an_effect_written_in_one_class_is_listed_checked_assembled_and_reduced():
    """Gravity from tests/_gravity_effect.py: a scene lists it, its options are checked, the
    system gets the load (tip deflection rho A g L^4 / (8 E I): Hermite cubics are nodally
    exact for a uniform load, so to round-off), and Galerkin reduces it through the
    built-in constant-load term."""
    import _gravity_effect  # noqa: F401
    from femrom.scene import Scene, SceneError, build, registered_effects
    from femrom.solvers import make_solver

    assert "gravity" in registered_effects()
    with pytest.raises(SceneError, match=r"unknown key 'gee' in \[effects.gravity\]; valid keys: g, component"):
        Scene.from_dict({**BEAM, "effects": {"inertia": {}, "bending": {}, "gravity": {"gee": 1.0}}})
    plain = build(Scene.from_dict(BEAM))
    assert plain.system.load is None and "load" not in plain.system.effects
    model = build(Scene.from_dict({**BEAM, "effects": {"inertia": {}, "bending": {}, "gravity": {}}}))
    system = model.system
    assert system.effects == ("inertia", "stiffness", "load", "outputs") and "load" in model.timings
    tip = float(system.outputs(make_solver(system.stiffness).solve(system.load))[0])
    material = model.scene.material
    exact = -material.density * material.area * 9.81 / (8 * material.youngs_modulus * material.second_moment)
    assert tip == pytest.approx(exact, rel=1e-10)
    V = np.linalg.qr(np.random.default_rng(0).standard_normal((system.n_dofs, 4)))[0]
    reduced = galerkin(system, V)
    np.testing.assert_allclose(reduced.load, V.T @ system.load, rtol=1e-14)


def solid_scene(effects, integrator="newmark"):
    return {
        "name": "block", "structure": {"geometry": "beam_solid", "element": "p1",
                                       "parameters": {"length": 0.4, "width": 0.1, "height": 0.1,
                                                      "mesh_size": 0.05}},
        "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3, "density": 1000.0},
        "effects": {"inertia": {"mass": "lumped"}, "elasticity": {}, **effects},
        "boundary": {"clamped": ["left"]},
        "initial_conditions": {"kind": "expression", "component": "z", "displacement": "0.02 * x / 0.4"},
        "time": {"t_end": 0.2, "dt": 0.002, "integrator": integrator},
        "outputs": {"averages": [{"name": "tip", "over": "beam", "component": "z"}]},
    }


def test_nonlinear_effects_on_a_solid_sum_their_forces_and_newton_condenses_onto_them():
    """A clamped P1 block with a Duffing spring layer on its free face and a quartic
    on-site potential on its z displacements: two forces, the layer's on 1-2 % of the dofs;
    the face weights integrate the face area; Newton condensed onto the layer's
    coordinates (when alone) follows the full Newton trajectory."""
    from femrom.integrators import Newmark as NewmarkScheme
    from femrom.integrators import simulate
    from femrom.scene import Scene, build

    layer = {"spring_layer": {"at": "right", "component": "z", "linear": 2e5, "cubic": 5e9}}
    model = build(Scene.from_dict(solid_scene(
        {**layer, "nonlinear_potential": {"kind": "quartic", "coefficient": 1e7, "component": "z"}})))
    system = model.system
    assert [f.name for f in system.nonlinear_forces] == ["nonlinear_potential", "spring_layer"]
    spring = system.nonlinear_forces[1]
    # P1 row sums of the face integrals add up to the face's area, 0.1 x 0.1
    assert spring.weights.sum() == pytest.approx(0.01, rel=1e-12) and np.all(spring.weights > 0)
    assert 0.005 < spring.n_local / system.n_dofs < 0.05
    on_site = system.nonlinear_forces[0]
    assert on_site.n_local == pytest.approx(system.n_dofs / 3, abs=1)

    model = build(Scene.from_dict(solid_scene(layer)))
    results = {}
    for method in ("full", "condensed"):
        trajectory = Trajectory(fields=("q",))
        summary = integrate(model.system, NewmarkScheme(newton=Newton(rtol=1e-13, method=method)),
                            model.initial_displacement, model.initial_velocity, 0.002, 100,
                            consumers=[trajectory], progress=False)
        results[method] = (trajectory.q, summary)
    assert relative(results["condensed"][0], results["full"][0]) < 1e-10
    assert results["condensed"][1].n_factorizations == 1       # lumped mass: none; S once
    assert simulate(model, progress=False).summary["details"]["newton"] == "condensed"   # auto
