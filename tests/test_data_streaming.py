"""Reduced training data from snapshots that are not in memory, and nested truncation.

``reduce_snapshots`` reads its full-order arguments as block sources in one
pass; the results must equal the in-memory projection to round-off.
``SecondOrderData.truncated`` must equal projecting onto the first r POD
vectors directly, projection error included.
"""

import numpy as np
import pytest
import scipy.sparse as sp

from femrom.basis import POD
from femrom.inference import reduce_snapshots
from femrom.inference._data import project_columns


@pytest.fixture(scope="module")
def snapshots():
    """A decaying-spectrum snapshot set, a diagonal SPD 'mass', and its W-orthonormal POD."""
    rng = np.random.default_rng(3)
    n, K, dt = 400, 120, 1e-2
    t = dt * np.arange(K)
    modes = np.linalg.qr(rng.standard_normal((n, 10)))[0]
    amplitudes = 10.0 ** -np.arange(10)
    frequencies = 1.0 + np.arange(10)
    Q = modes @ (amplitudes[:, None] * np.sin(frequencies[:, None] * t))
    Qv = modes @ (amplitudes[:, None] * frequencies[:, None] * np.cos(frequencies[:, None] * t))
    Qa = -modes @ (amplitudes[:, None] * frequencies[:, None] ** 2 * np.sin(frequencies[:, None] * t))
    W = sp.diags(rng.uniform(0.5, 2.0, n)).tocsr()
    V = POD(8, product=W).fit(Q).basis_
    return Q, Qv, Qa, W, V, dt


def _blocks(X, b=7):
    return lambda: (X[:, j:j + b] for j in range(0, X.shape[1], b))


def test_streamed_projection_equals_the_in_memory_one(snapshots):
    Q, Qv, Qa, W, V, dt = snapshots
    memory = reduce_snapshots(V, Q, dt, product=W, velocities=Qv, accelerations=Qa, derivatives="stored")
    streamed = reduce_snapshots(V, _blocks(Q), dt, product=W, velocities=_blocks(Qv),
                                accelerations=_blocks(Qa), derivatives="stored")
    for name in ("states", "velocities", "accelerations"):
        # the same products summed in another grouping: round-off only
        np.testing.assert_allclose(getattr(streamed, name), getattr(memory, name), rtol=0,
                                   atol=1e-13 * np.abs(getattr(memory, name)).max())
    # the projection error against the explicit residual ||Q - V V^T W Q||_W / ||Q||_W
    E = Q - V @ (V.T @ (W @ Q))
    exact = np.sqrt(np.sum(E * (W @ E)) / np.sum(Q * (W @ Q)))
    assert streamed.diagnostics["projection_error"] == pytest.approx(exact, rel=1e-8)
    assert memory.diagnostics["projection_error"] == pytest.approx(exact, rel=1e-8)


def test_one_shot_iterators_are_read_once(snapshots):
    Q, _, _, W, V, _ = snapshots
    coords, residual, norm = project_columns(V, iter([Q[:, :50], Q[:, 50:]]), W)
    np.testing.assert_allclose(coords, V.T @ (W @ Q), atol=1e-13 * np.abs(coords).max())
    assert 0 < residual < norm


def test_truncation_equals_projecting_on_the_smaller_basis(snapshots):
    Q, Qv, Qa, W, V, dt = snapshots
    full = reduce_snapshots(V, Q, dt, product=W, velocities=Qv, accelerations=Qa, derivatives="stored")
    for r in (2, 5, 8):
        direct = reduce_snapshots(V[:, :r], Q, dt, product=W, velocities=Qv, accelerations=Qa,
                                  derivatives="stored")
        cut = full.truncated(r)
        assert cut.r == r
        np.testing.assert_array_equal(cut.states, full.states[:r])
        np.testing.assert_allclose(cut.accelerations, direct.accelerations,
                                   atol=1e-13 * np.abs(direct.accelerations).max())
        # Pythagoras in the W-product: exact up to round-off of the two routes (here the
        # projection errors span 1e-1 ... 1e-8; 1e-6 relative is far above round-off)
        assert cut.diagnostics["projection_error"] == pytest.approx(
            direct.diagnostics["projection_error"], rel=1e-6)
    with pytest.raises(ValueError, match="r = 9"):
        full.truncated(9)


def test_finite_differences_from_reduced_data_match_reducing_with_them(snapshots):
    Q, Qv, Qa, W, V, dt = snapshots
    stored = reduce_snapshots(V, Q, dt, product=W, velocities=Qv, accelerations=Qa, derivatives="stored")
    direct = reduce_snapshots(V, Q, dt, product=W, velocities=Qv, accelerations=Qa, order=4)
    fd = stored.with_finite_differences(4)
    np.testing.assert_array_equal(fd.accelerations, direct.accelerations)
    assert fd.diagnostics["derivative_source"] == "finite_difference"
    for key in ("velocity_error", "acceleration_error"):
        # fourth-order differences at dt = 1e-2 of modes up to 10 rad/s: small, nonzero
        assert fd.diagnostics[key] == pytest.approx(direct.diagnostics[key], rel=1e-12)
        assert 0 < fd.diagnostics[key] < 1e-2
