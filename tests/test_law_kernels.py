"""The compiled return maps of the slider laws against their numpy reference.

Every law here evaluates twice on the same inputs, once with the compiled kernels and once
with numpy (``use_compiled_laws(False)``): tractions, consistent tangents and committed
slider states must agree to round-off, on random states that mix stick, partial slip and
full slip, on a loading path that reverses, and for the clamped law at open and closed
points. Tolerance: the kernels add the sliders' contributions one by one where numpy sums
arrays (pairwise, BLAS), so results differ in the last bits only; 1e-12 of the array's
largest entry leaves room for that and nothing else.
"""

import os
import subprocess
import sys

import numpy as np
import pytest

from femrom.fem import ClampedIwanLaw, compiled_laws, interface_law, use_compiled_laws
from tests._required import extra

extra("numba")

ROUND_OFF = 1e-12


@pytest.fixture(autouse=True)
def _compiled_on():
    previous = use_compiled_laws(True)
    yield
    use_compiled_laws(previous)


def _both(call):
    """``call()`` with the compiled kernels and with numpy."""
    assert compiled_laws()
    compiled = call()
    use_compiled_laws(False)
    try:
        assert not compiled_laws()
        reference = call()
    finally:
        use_compiled_laws(True)
    return compiled, reference


def _close(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape
    scale = max(np.abs(b).max(initial=0.0), 1e-300)
    np.testing.assert_allclose(a, b, rtol=0.0, atol=ROUND_OFF * scale)


def _check(law, gap, state):
    """Traction, tangent, traction without tangent, and the committed state: compiled == numpy."""
    (t, D), (t_ref, D_ref) = _both(lambda: law.evaluate(gap, state))
    _close(t, t_ref)
    _close(D, D_ref)
    (t_only, none), (t_only_ref, _) = _both(lambda: law.evaluate(gap, state, tangent=False))
    assert none is None
    _close(t_only, t_only_ref)
    new, new_ref = _both(lambda: law.commit(gap, state))
    _close(new, new_ref)
    return D_ref, new_ref


LAWS = {
    "iwan": lambda: interface_law("iwan", slip_traction=1e5, tangential_stiffness=1e11, chi=-0.5, beta=0.3,
                                  normal_stiffness=1e12, n_sliders=20, alpha=1.3),
    "iwan_no_delta": lambda: interface_law("iwan", slip_traction=1e5, tangential_stiffness=1e11, chi=-0.2,
                                           beta=0.0, n_sliders=7),
    "jenkins": lambda: interface_law("jenkins", tangential_stiffness=1e11, slip_traction=1e5, normal_stiffness=1e12),
}

SLIP = 1e5 / 1e11         # F_S / K_T: the tangential displacement scale of the laws above


def _slider_state(law, s, rng, spread):
    """(s, N, 2) random slider positions of amplitude ``spread * SLIP``."""
    return rng.normal(0.0, spread * SLIP, (s, law.slider_stiffness.size, 2))


@pytest.mark.parametrize("name", sorted(LAWS))
@pytest.mark.parametrize("amplitude", [0.05, 0.5, 2.0, 20.0])
def test_parallel_sliders_match_numpy_from_stick_to_full_slip(name, amplitude):
    law = LAWS[name]()
    rng = np.random.default_rng(int(amplitude * 100) + len(name))
    s = 40
    gap = rng.normal(0.0, amplitude * SLIP, (s, 3))
    state = _slider_state(law, s, rng, 0.5 * amplitude)
    D, new = _check(law, gap, state)
    moved = np.abs(new - state).max(axis=2) > 1e-9 * SLIP
    if amplitude == 0.05 and name != "jenkins":
        assert moved.any() and not moved.all()       # micro-slip: weak sliders slip, strong ones stick
    if amplitude == 20.0:
        assert moved.all()                           # macro-slip: every slider slips


@pytest.mark.parametrize("name", sorted(LAWS))
def test_parallel_sliders_match_numpy_along_a_reversing_path(name):
    """Load, reverse, reload in both tangential directions: each path commits its own states, which stay equal.

    The path repeats its turning points, so sliders committed in slip are evaluated again on their slip
    limit (``|t^tr| = f_m`` to round-off), where an ulp in the norm would flip the tangent's branch."""
    law = LAWS[name]()
    s = 12
    rng = np.random.default_rng(7)
    direction = rng.normal(size=(s, 2))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    path = SLIP * np.concatenate([np.linspace(0, 1.5, 8), np.linspace(1.5, -0.7, 12), np.linspace(-0.7, 0.4, 6)])
    compiled = reference = law.initial_state(s)
    for u in path:
        gap = np.column_stack([u * direction, rng.normal(0, SLIP, s)])
        compiled, reference = _step_both(law, gap, compiled, reference)
    assert np.abs(reference).max() > 0.1 * SLIP           # the path slipped


def _step_both(law, gap, compiled, reference):
    """One step of a load path on both paths: the evaluation checked, each path committing its own state."""
    _check(law, gap, compiled)
    compiled = law.commit(gap, compiled)
    use_compiled_laws(False)
    reference = law.commit(gap, reference)
    use_compiled_laws(True)
    _close(compiled, reference)
    return compiled, reference


def _clamped(s, rng, *, open_share=0.3):
    law = ClampedIwanLaw(normal_stiffness=1e12, tangential_stiffness=1e11, chi=-0.5, beta=0.4, n_sliders=12)
    N = law.n_elements
    state = np.zeros((s, N + 1, 2))
    state[:, N, 0] = 1e5 * rng.uniform(0.2, 2.0, s)                  # tau_s = mu p_0
    state[:, N, 1] = rng.uniform(size=s) > open_share                 # closed flag
    return law, state


@pytest.mark.parametrize("amplitude", [0.02, 0.3, 1.0, 10.0])
def test_clamped_iwan_matches_numpy_at_open_and_closed_points(amplitude):
    rng = np.random.default_rng(int(amplitude * 1000))
    s = 40
    law, state = _clamped(s, rng)
    N = law.n_elements
    state[:, :N] = rng.normal(0.0, 0.3 * amplitude * SLIP, (s, N, 2))
    gap = rng.normal(0.0, amplitude * SLIP, (s, 3))
    gap[:3, :2] = 0.0                                                   # zero trial traction at a few points
    state[:3, :N] = 0.0
    D, new = _check(law, gap, state)
    closed = state[:, N, 1] > 0.5
    assert closed.any() and not closed.all()
    assert np.all(D[~closed] == 0.0)                                    # an open point carries nothing
    np.testing.assert_array_equal(new[:, N], state[:, N])               # the preload row is kept


def test_clamped_iwan_matches_numpy_along_a_reversing_path():
    rng = np.random.default_rng(3)
    s = 16
    law, state = _clamped(s, rng, open_share=0.2)
    compiled = reference = state
    for u in SLIP * np.concatenate([np.linspace(0, 2.0, 8), np.linspace(2.0, -1.0, 12), np.linspace(-1.0, 0.5, 6)]):
        gap = np.column_stack([np.full(s, u), np.full(s, -0.3 * u), rng.normal(0, SLIP, s)])
        compiled, reference = _step_both(law, gap, compiled, reference)


def test_inputs_the_kernels_do_not_take_go_to_numpy():
    """Non-contiguous and integer inputs are converted; a mismatched state takes numpy's path (its error)."""
    law = LAWS["iwan"]()
    rng = np.random.default_rng(11)
    wide = rng.normal(0.0, SLIP, (10, 6))
    state = _slider_state(law, 20, rng, 1.0)[::2]
    _check(law, wide[:, ::2], state)
    _check(law, np.zeros((10, 3), dtype=int), np.zeros(state.shape, dtype=int))
    with pytest.raises(ValueError):
        law.evaluate(wide[:, :3], state[:, :3])
    clamped, clamped_state = _clamped(10, rng)
    with pytest.raises(ValueError, match="clamped_iwan state"):
        clamped.evaluate(wide[:, :3], clamped_state[:, 1:])


def test_the_environment_switches_the_kernels_off():
    code = "from femrom.fem import compiled_laws; print(compiled_laws())"
    env = {**os.environ, "FEMROM_COMPILED_LAWS": "0"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
