"""POD (Euclidean and mass-weighted) and cotangent-lift PSD on data with known structure."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from femrom.basis import POD, CotangentLiftPSD, apply_j, truncation_rank
from femrom.linalg import StreamingSketch


pytestmark = pytest.mark.usefixtures("one_blas_thread")


def synthetic(sigma: np.ndarray, n: int, k_cols: int | None = None, seed: int = 1) -> np.ndarray:
    """A = U diag(sigma) V^T (n, K) with random orthonormal U, V."""
    rng = np.random.default_rng(seed)
    k_cols = sigma.size if k_cols is None else k_cols
    u, _ = np.linalg.qr(rng.standard_normal((n, sigma.size)))
    v, _ = np.linalg.qr(rng.standard_normal((k_cols, sigma.size)))
    return (u * sigma) @ v.T


SIGMA = 0.5 ** np.arange(40)  # retained energy after r modes: 1 - 4^-r (up to 4^-40)


@pytest.fixture(scope="module")
def snapshots():
    return synthetic(SIGMA, n=600, k_cols=80)


# -- truncation --------------------------------------------------------------------

@pytest.mark.parametrize("energy, expected", [(0.9, 2), (0.999, 5), (1 - 1e-8, 14)])
def test_energy_truncation_picks_the_right_rank(snapshots, energy, expected):
    # sum_{i<r} 0.25^i / sum 0.25^i = 1 - 4^-r: 0.9 needs r = 2 (0.9375), 0.999
    # needs r = 5 (0.99902), 1 - 1e-8 needs r = 14 (1 - 3.7e-9); none is borderline.
    for method, extra in (("svd", {}), ("randomized", {"max_rank": 20}), ("streaming", {"max_rank": 20})):
        pod = POD(energy=energy, method=method, **extra).fit(snapshots)
        assert pod.rank_ == expected, method
        assert pod.retained_energy_ >= energy


def test_projection_error_is_the_tail_energy(snapshots):
    pod = POD(tolerance=1e-3).fit(snapshots)
    r = pod.rank_
    tail = np.sqrt(np.sum(SIGMA[r:] ** 2) / np.sum(SIGMA**2))
    # Smallest r with sqrt(4^-r) <= 1e-3: r = 10 (9.8e-4).
    assert r == 10
    # Eckart-Young: the projection error of the training data is the tail energy;
    # both the reported one and the one measured on the data, to round-off.
    assert pod.projection_error_ == pytest.approx(tail, rel=1e-9)
    assert pod.projection_error(snapshots) == pytest.approx(tail, rel=1e-9)
    assert np.allclose(pod.singular_values_[:40], SIGMA, rtol=1e-10, atol=1e-14)
    assert np.all(pod.singular_values_[40:] < 1e-14)  # rank 40
    randomized = POD(10, method="randomized").fit(snapshots)
    # Multi-pass: sigma_i are those of V^T A exactly, so its error report is exact too.
    assert randomized.projection_error_ == pytest.approx(tail, rel=1e-8)
    assert randomized.projection_error(snapshots) == pytest.approx(tail, rel=1e-8)
    assert randomized.svd_.passes == 4


def test_energy_not_reached_warns(snapshots):
    with pytest.warns(RuntimeWarning, match="not reached"):
        pod = POD(energy=1 - 1e-12, method="randomized", max_rank=5).fit(snapshots)
    assert pod.rank_ == 5
    with pytest.raises(ValueError, match="exactly one"):
        POD(5, energy=0.9)
    with pytest.raises(ValueError, match="max_rank"):
        POD(energy=0.9, method="randomized").fit(snapshots)
    with pytest.raises(AttributeError, match="not fitted"):
        POD(3).compress(snapshots)
    with pytest.raises(ValueError, match="exactly one"):
        truncation_rank(SIGMA, 1.0)


# -- mass-weighted POD ----------------------------------------------------------------

def test_mass_weighted_pod_is_w_orthonormal_and_w_optimal():
    n, r = 500, 8
    # A mesh whose left half is 30 times finer than its right half.
    rng = np.random.default_rng(4)
    h = np.where(np.arange(n + 1) < n // 2, 1.0, 30.0) * rng.uniform(0.8, 1.2, n + 1) / n
    mass = sp.diags([h[1:-1] / 6, (h[:-1] + h[1:]) / 3, h[1:-1] / 6], [-1, 0, 1]).tocsr()
    lumped = np.asarray(mass.sum(axis=1)).ravel()
    # Eight fields on the fine half with nodal size 1, eight on the coarse half with
    # nodal size 0.5: larger in the Euclidean norm on the left, in the mass norm
    # (x30 / 4) on the right. A rank-8 Euclidean POD picks the left ones.
    fields = rng.standard_normal((n, 16))
    fields[n // 2:, :8] = 0.0
    fields[:n // 2, 8:] = 0.0
    fields[:, 8:] *= 0.5
    amplitudes = np.tile(0.9 ** np.arange(8), 2)
    data = fields @ (np.diag(amplitudes) @ rng.standard_normal((16, 120)))
    chol = np.linalg.cholesky(mass.toarray())

    def relative_w_error(v):
        """||A - V V^T W A||_W / ||A||_W for a W-orthonormal V."""
        residual = data - v @ (v.T @ (mass @ data))
        return np.linalg.norm(chol.T @ residual) / np.linalg.norm(chol.T @ data)

    for product, w in ((mass, mass.toarray()), (lumped, np.diag(lumped))):
        for method in ("svd", "randomized"):
            pod = POD(r, product=product, method=method).fit(data)
            # W-orthonormal to 1e-12 (Householder + CholQR2, or W^{1/2} scaling).
            assert np.abs(pod.basis_.T @ w @ pod.basis_ - np.eye(r)).max() < 1e-12
            assert pod.projection_error(data) == pytest.approx(pod.projection_error_, rel=1e-8)
            assert pod.inner_product_.kind == ("matrix" if product is mass else "diagonal")
    # The Euclidean basis, W-orthonormalised (same span, so its best W-projection).
    v = POD(r).fit(data).basis_
    v = v @ np.linalg.inv(np.linalg.cholesky(v.T @ (mass @ v)).T)
    euclidean = relative_w_error(v)
    sigma = np.linalg.svd(chol.T @ data, compute_uv=False)
    optimum = np.sqrt(np.sum(sigma[r:] ** 2) / np.sum(sigma**2))
    weighted = POD(r, product=mass).fit(data)
    # Eckart-Young in the W-norm: the consistent-mass POD attains the optimum, so it
    # is no worse than the Euclidean basis; here it is far better (measured 1.9x).
    assert relative_w_error(weighted.basis_) == pytest.approx(optimum, rel=1e-9)
    assert relative_w_error(weighted.basis_) <= euclidean
    assert euclidean > 1.5 * optimum
    assert weighted.product is mass  # the basis remembers its product


def test_pod_from_a_streaming_sketch_and_methods_agree(snapshots):
    sketch = StreamingSketch(snapshots.shape[0], 6, seed=2)
    for j in range(snapshots.shape[1]):
        sketch.update(snapshots[:, j])
    exact = POD(6).fit(snapshots)
    for pod in (POD(6).fit(sketch),
                POD(6, method="randomized").fit(snapshots),
                POD(6, method="randomized").fit(lambda: (snapshots[:, j:j + 9] for j in range(0, 80, 9))),
                POD(6, method="dask", options={"scheduler": "synchronous"}).fit(snapshots)):
        # Spectrum 0.5^i. The single-pass sketch (k = 25, no power iteration) resolves
        # the first 6 directions to about sigma_26 / sigma_6 = 0.5^20 ~ 1e-6 (times a
        # random factor of order one, measured 1.7e-6); the multi-pass ones (q = 2) to
        # round-off. 1e-4 separates that from a wrong subspace (distance ~ 1).
        distance = np.linalg.norm(pod.basis_ @ (pod.basis_.T @ exact.basis_) - exact.basis_)
        assert distance < 1e-4
    assert POD(6).fit(sketch).svd_.passes == 1


def test_compress_decompress_shapes(snapshots):
    pod = POD(4).fit(snapshots)
    assert pod.compress(snapshots[:, 0]).shape == (4,)
    assert pod.compress(snapshots).shape == (4, 80)
    assert pod.decompress(np.ones(4)).shape == (600,)
    with pytest.raises(ValueError, match="rows"):
        pod.compress(np.ones(5))


# -- proper symplectic decomposition ---------------------------------------------------

@pytest.fixture(scope="module")
def hamiltonian_snapshots():
    # Linear spring chain H = p^T p / 2 + q^T K q / 2, exact flow in modal coordinates.
    n = 200
    stiffness = np.diag(2 * np.ones(n)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1)
    omega2, modes = np.linalg.eigh(stiffness)
    omega = np.sqrt(omega2)
    rng = np.random.default_rng(0)
    amplitude = np.zeros(n)
    amplitude[:6] = rng.uniform(0.5, 1.0, 6)
    t = np.linspace(0, 20, 150)
    phase = rng.uniform(0, 2 * np.pi, n)
    q = modes @ (amplitude[:, None] * np.cos(omega[:, None] * t + phase[:, None]))
    p = modes @ (-amplitude[:, None] * omega[:, None] * np.sin(omega[:, None] * t + phase[:, None]))
    return stiffness, q, p


def test_psd_is_symplectic_and_round_trips(hamiltonian_snapshots):
    stiffness, q, p = hamiltonian_snapshots
    n = q.shape[0]
    psd = CotangentLiftPSD(6).fit(q, p)
    a = psd.basis_
    assert a.shape == (2 * n, 12)
    # A^T J A = J_2r holds iff Phi^T Phi = I: round-off (~1e-15).
    assert psd.symplecticity_error_ < 1e-13
    assert np.abs(psd.symplectic_inverse_ @ a - np.eye(12)).max() < 1e-13
    # Round trip on a vector in the span.
    reduced = np.random.default_rng(1).standard_normal(12)
    assert np.allclose(psd.compress(psd.decompress(reduced)), reduced, rtol=0, atol=1e-13)
    # Six modes excited: [Q P] has rank 6, the data lie in the span.
    assert psd.projection_error(np.vstack([q, p])) < 1e-12
    # Phi is the POD of [Q, P].
    pod = POD(6).fit(np.hstack([q, p]))
    assert np.linalg.norm(psd.phi_ @ (psd.phi_.T @ pod.basis_) - pod.basis_) < 1e-10
    # The Galerkin-PSD reduced linear vector field A^+ J L A (L = blkdiag(K, I), the
    # Hessian of H) is J_2r times the symmetric reduced Hessian A^T L A: Hamiltonian.
    hessian = np.block([[stiffness, np.zeros((n, n))], [np.zeros((n, n)), np.eye(n)]])
    reduced_field = psd.compress(apply_j(hessian @ a))
    reduced_hessian = a.T @ hessian @ a
    assert np.abs(reduced_field - apply_j(reduced_hessian)).max() < 1e-12


def test_psd_from_block_sources_matches_arrays(hamiltonian_snapshots):
    _, q, p = hamiltonian_snapshots
    from_arrays = CotangentLiftPSD(4).fit(q, p)
    blocks = CotangentLiftPSD(4, method="randomized").fit(
        lambda: (q[:, j:j + 40] for j in range(0, 150, 40)),
        lambda: (p[:, j:j + 40] for j in range(0, 150, 40)))
    # Rank-6 data, rank-4 basis with a gap: both give the same Phi to round-off.
    distance = np.linalg.norm(blocks.phi_ @ (blocks.phi_.T @ from_arrays.phi_) - from_arrays.phi_)
    assert distance < 1e-8
    assert blocks.symplecticity_error_ < 1e-13
