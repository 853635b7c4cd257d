"""A reduced model with a joint steps in one compiled call per step; the numpy step is the reference.

A small Galerkin model of two chains joined pair by pair (the lap joint of
``tests/test_hyper_joint.py``, fewer pairs), about a reference displacement and with initial
gaps so that every offset of the projected joint is exercised, takes a shear blow that slips
part of the joint. It steps twice from the same state: with the compiled laws on, the Newmark
family hands the whole step to the fused kernel (the force offers a compiled joint), and with
them off the numpy step runs (dense Newton on the projected force). Both solve the same
equations with the same tests in the same order; they differ only in the order of
floating-point sums (loops against BLAS), about 1e-16 relative per operation, carried
through Newton's solves and the steps. Tolerance: 1e-10 of the run's largest value (measured
differences are about 1e-15; one changed term of the step, e.g. the tangent's weight or the
point the state is committed at, moves them by 1e-6 or more). The Newton iterations must be
the same at every step.
"""

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from femrom.fem import ClampedIwanLaw, JointForce, compiled_laws, interface_law, use_compiled_laws
from femrom.inference import galerkin
from femrom.integrators import GeneralizedAlpha, IntegrationError, Newmark, Newton, StepResult, iterate
from femrom.scene import SecondOrderSystem, Signal, SignalVector
from tests._required import extra

extra("numba")

S = 10                     # interface pairs
MODES = 5
DT, STEPS = 2e-4, 300
ROUND_OFF = 1e-10          # see the module docstring


@pytest.fixture(autouse=True)
def _compiled_on():
    previous = use_compiled_laws(True)
    yield
    use_compiled_laws(previous)


def _law(name):
    if name == "clamped_iwan":
        return ClampedIwanLaw(1e9, 2e8, chi=-0.5, beta=0.5, n_sliders=12)
    if name == "iwan":
        return interface_law("iwan", slip_traction=2e4, tangential_stiffness=2e8, chi=-0.5, beta=0.3,
                             normal_stiffness=1e9, n_sliders=8)
    return interface_law("jenkins", tangential_stiffness=2e8, slip_traction=3e4, normal_stiffness=1e9)


def lap_joint(name: str, blow: float = 3000.0):
    """``(reduced system under the blow, rest state)``: two grounded chains of S nodes joined by
    ``name`` pairs (initial gaps -1e-6 m), Galerkin on the stuck joint's lowest modes about a small
    reference displacement."""
    n = 6 * S
    a = np.arange(3 * S).reshape(S, 3)
    b = 3 * S + a
    rows, cols, values = [], [], []
    for side in (a, b):
        for m in range(S - 1):
            for c in range(3):
                i, j = side[m, c], side[m + 1, c]
                rows += [i, j, i, j]
                cols += [i, j, j, i]
                values += [5e8, 5e8, -5e8, -5e8]
    ground = np.full(n, 1e6)
    ground[a[0]] = 1e10
    K = sp.coo_matrix((values, (rows, cols)), shape=(n, n)).tocsr() + sp.diags(ground)
    M = sp.diags(np.full(n, 0.01))
    law = _law(name)
    joint = JointForce(law, a, b, np.tile([0.0, 0.0, 1.0], (S, 1)), np.full(S, 1e-4), n, initial_gap=-1e-6)
    z0 = law.initial_state(S)
    if name == "clamped_iwan":
        z0[:, -1, 0] = np.linspace(2e4, 2e5, S)     # mu p_0 [Pa]
        z0[:, -1, 1] = 1.0                           # closed ...
        z0[0, -1, 1] = 0.0                           # ... but one
    B = np.zeros((n, 1))
    B[b[-1, 0], 0] = 1.0
    pulse = SignalVector([Signal.from_dict({"kind": "impulse", "amplitude": blow, "start": 0.0,
                                            "duration": 2e-3})])
    system = SecondOrderSystem(mass=M, stiffness=K, input_matrix=B, inputs=pulse, nonlinear=joint)
    stuck = (K + joint.tangent(np.zeros(n), None, z0)[0]).toarray()
    V = sla.eigh(stuck, M.toarray())[1][:, :MODES]
    q0 = 1e-7 * np.sin(np.arange(n))               # a reference: the projected joint's local offset
    model = galerkin(system, V, reference=q0, reference_state=z0, damping_ratios=0.005)
    return dataclasses.replace(model.system, inputs=pulse), z0


def run(system, z0, scheme, compiled: bool, steps: int = STEPS):
    """``(q, v, a, states, iterations per step, summary)`` of ``steps`` steps from rest."""
    use_compiled_laws(compiled)
    try:
        steps_ = iterate(system, scheme, None, None, DT, steps, start=StepResult.at_rest(system.n_dofs, state=z0),
                         progress=False)
        q, v, a, states, iterations, done = [], [], [], [], [], 0
        for result in steps_:
            q.append(result.q)
            v.append(result.v)
            a.append(result.a)
            states.append(np.array(result.state))
            iterations.append(steps_.newton_iterations - done)
            done = steps_.newton_iterations
        return (np.array(q), np.array(v), np.array(a), np.array(states), np.array(iterations),
                steps_.summary())
    finally:
        use_compiled_laws(True)


def _close(x, reference, scale=None):
    scale = np.abs(reference).max() if scale is None else scale
    np.testing.assert_allclose(x, reference, rtol=0.0, atol=ROUND_OFF * scale)


@pytest.mark.parametrize("name", ["clamped_iwan", "iwan", "jenkins"])
@pytest.mark.parametrize("scheme", [Newmark(newton=Newton(rtol=1e-12)), GeneralizedAlpha(0.8)],
                         ids=["newmark", "generalized_alpha"])
def test_the_fused_step_is_the_numpy_step(name, scheme):
    system, z0 = lap_joint(name)
    assert compiled_laws() and system.nonlinear.compiled_joint() is not None
    *fused, fused_summary = run(system, z0, scheme, True)
    *reference, reference_summary = run(system, z0, scheme, False)
    assert fused_summary.details.get("compiled_step") is True
    assert "compiled_step" not in reference_summary.details
    q, v, a, states, iterations = fused
    q_ref, v_ref, a_ref, states_ref, iterations_ref = reference
    np.testing.assert_array_equal(iterations, iterations_ref)
    assert iterations_ref.mean() > 1.0                     # the joint is nonlinear on this run
    sliders = slice(None, -1 if name == "clamped_iwan" else None)
    assert np.abs(states_ref[-1, :, sliders] - z0[:, sliders]).max() > 1e-6   # and slipped micrometres
    for x, x_ref in ((q, q_ref), (v, v_ref), (a, a_ref)):
        _close(x, x_ref)
    _close(states[:, :, sliders], states_ref[:, :, sliders])
    if name == "clamped_iwan":                              # the clamp row is carried unchanged
        np.testing.assert_array_equal(states[:, :, -1], np.broadcast_to(z0[:, -1], states[:, :, -1].shape))


def test_switching_the_compiled_laws_off_switches_the_fused_step_off():
    system, z0 = lap_joint("clamped_iwan")
    use_compiled_laws(False)
    try:
        assert system.nonlinear.compiled_joint() is None
    finally:
        use_compiled_laws(True)
    # off in the middle of a run: the remaining steps take the numpy path
    scheme = Newmark(newton=Newton(rtol=1e-12))
    steps = iterate(system, scheme, None, None, DT, 60, start=StepResult.at_rest(system.n_dofs, state=z0),
                    progress=False)
    assert steps.summary().details.get("compiled_step") is True
    calls = {"law": 0}
    law = system.nonlinear.transformed.force_model.law
    evaluate = law.evaluate

    def counted(*args, **kwargs):
        calls["law"] += 1
        return evaluate(*args, **kwargs)

    object.__setattr__(law, "evaluate", counted)
    try:
        results = [next(steps) for _ in range(30)]
        assert calls["law"] == 0                               # fused: the law's Python method is not called
        use_compiled_laws(False)
        results += list(steps)
        assert calls["law"] > 0
    finally:
        object.__delattr__(law, "evaluate")
        use_compiled_laws(True)
    q_ref, *_ = run(system, z0, scheme, False, steps=60)
    _close(np.array([r.q for r in results]), q_ref)


def test_a_step_that_does_not_converge_fails_as_the_numpy_one_does():
    system, z0 = lap_joint("jenkins")
    scheme = Newmark(newton=Newton(rtol=1e-14, max_iterations=1))
    messages = []
    for compiled in (True, False):
        with pytest.raises(IntegrationError) as failure:
            run(system, z0, scheme, compiled, steps=40)
        messages.append((failure.value.step, str(failure.value).split(":")[0]))
    assert messages[0] == messages[1]


def test_the_environment_switches_the_fused_step_off():
    code = ("from tests.test_fused_step import lap_joint\n"
            "from femrom.integrators import Newmark, StepResult, integrate\n"
            "system, z0 = lap_joint('jenkins')\n"
            "summary = integrate(system, Newmark(), None, None, 2e-4, 3, progress=False,\n"
            "                    start=StepResult.at_rest(system.n_dofs, state=z0))\n"
            "print(system.nonlinear.compiled_joint() is None, 'compiled_step' in summary.details)\n")
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "FEMROM_COMPILED_LAWS": "0",
           "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True, cwd=root)
    assert out.stdout.split() == ["True", "False"]


def test_a_galerkin_model_of_a_galerkin_model_keeps_the_compiled_joint():
    """Reducing a reduced model again (the jointed-beam ROM study projects its 10-mode reference on a few POD
    directions) gives one transformed joint with the map ``L V_1 V_2`` about the first reduction's ``q_0``: the
    compiled step is offered and runs, and force, tangent and a run equal the twice-projected force
    ``V_2^T f_1(V_2 q~)`` evaluated through the once-reduced model (round-off). A second reference ``x_0``
    in the once-reduced coordinates composes too (``transform_force``: about ``q_0 + V_1 x_0``)."""
    from femrom.fem import transform_force

    system, z0 = lap_joint("clamped_iwan")
    once = system.nonlinear
    V2 = np.linalg.qr(np.random.default_rng(4).standard_normal((MODES, 3)))[0]
    twice = galerkin(system, V2).system
    force = twice.nonlinear
    assert force.compiled_joint() is not None
    assert type(force.transformed.force_model).__name__ == "JointForce"
    q = 1e-7 * np.array([1.0, -2.0, 0.5])
    for x0 in (np.zeros(MODES), 1e-8 * np.arange(1.0, MODES + 1)):
        composed = transform_force(once.transformed, V2, reference=x0)
        assert type(composed.force_model).__name__ == "JointForce"
        f_ref = V2.T @ once.force(x0 + V2 @ q, None, z0)
        D_ref = V2.T @ np.asarray(once.tangent(x0 + V2 @ q, None, z0)[0]) @ V2
        f, D = composed.force(q, None, z0), composed.tangent(q, None, z0)[0].toarray()
        np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-12 * np.abs(f_ref).max())
        np.testing.assert_allclose(D, D_ref, rtol=0, atol=1e-12 * np.abs(D_ref).max())
    generic = dataclasses.replace(twice, nonlinear=_generic(once, V2))
    scheme = Newmark(newton=Newton(rtol=1e-12))
    *fused, summary = run(twice, z0, scheme, True, steps=120)
    *reference, reference_summary = run(generic, z0, scheme, True, steps=120)
    assert summary.details.get("compiled_step") is True and "compiled_step" not in reference_summary.details
    assert np.abs(fused[3][-1][:, :-1] - z0[:, :-1]).max() > 1e-8        # the sliders moved (observed 1.4e-7 m)
    for x, x_ref in zip(fused[:4], reference[:4]):
        _close(x, x_ref)


def _generic(once, V2):
    """The twice-reduced force as ``V_2^T f_1(V_2 q~)`` on the once-reduced model's force (no composed map)."""
    from femrom.fem import NonlinearForce

    class Generic(NonlinearForce):
        stateful = True

        def __init__(self):
            super().__init__(V2.shape[1], name="generic")

        def initial_state(self):
            return once.initial_state()

        def force(self, q, v=None, state=None):
            return V2.T @ once.force(V2 @ q, None if v is None else V2 @ v, state)

        def tangent(self, q, v=None, state=None):
            D = once.tangent(V2 @ q, None if v is None else V2 @ v, state)[0]
            return V2.T @ np.asarray(D) @ V2, None

        def commit(self, q, v, state):
            return once.commit(V2 @ q, None if v is None else V2 @ v, state)

    return Generic()
