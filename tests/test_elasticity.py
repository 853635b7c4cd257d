"""Linear elasticity on tetrahedra: operators, loads, outputs, constraints, convergence."""

import numpy as np
import pytest
import scipy.sparse as sp
import skfem
from skfem.helpers import dot
from skfem.models.elasticity import linear_elasticity

from femrom.fem._elasticity import elasticity_stiffness, lame_parameters, vector_mass
from femrom.fem import (average_rows, dirichlet_dofs, point_load, probe_rows, rigid_body_modes,
                        surface_pressure, surface_traction)
from femrom.mesh import MeshError

ELEMENTS = {"P1": skfem.ElementTetP1, "P2": skfem.ElementTetP2}


def unit_cube(n: int) -> skfem.MeshTet:
    """Unit cube, n cells per side, six default named faces and a 'half' subdomain."""
    grid = np.linspace(0.0, 1.0, n + 1)
    mesh = skfem.MeshTet.init_tensor(grid, grid, grid).with_defaults()
    return mesh.with_subdomains({"half": lambda x: x[0] < 0.5})


def distorted_box(seed: int = 0) -> skfem.MeshTet:
    """A 2 x 1 x 0.5 box with randomly moved interior nodes (generic element shapes)."""
    mesh = unit_cube(4)
    rng = np.random.default_rng(seed)
    p = mesh.p.copy()
    interior = np.all((p > 1e-12) & (p < 1 - 1e-12), axis=0)
    # 0.06 h at h = 0.25: elements stay positively oriented (checked below).
    p[:, interior] += 0.015 * rng.uniform(-1.0, 1.0, (3, int(interior.sum())))
    p *= np.array([[2.0], [1.0], [0.5]])
    return skfem.MeshTet(p, mesh.t).with_defaults()


def vector_basis(mesh, degree: str, **kwargs) -> skfem.CellBasis:
    return skfem.Basis(mesh, skfem.ElementVector(ELEMENTS[degree]()), **kwargs)


def relative_difference(A, B) -> float:
    return abs(A - B).max() / abs(B).max()


# -- operators against skfem's stock forms --------------------------------------
@pytest.mark.parametrize("degree", ["P1", "P2"])
def test_stiffness_matches_stock_form(degree):
    mesh = distorted_box()
    basis = vector_basis(mesh, degree)
    assert np.all(np.abs(basis.mapping.detDF(np.zeros((3, 1)))) > 0)
    E, nu = 210e9, 0.3
    K = elasticity_stiffness(basis, E, nu)
    K_stock = skfem.asm(linear_elasticity(*lame_parameters(E, nu)), basis)
    assert isinstance(K, sp.csr_matrix) and K.shape == K_stock.shape
    # Both are exact integrals of the same polynomials: only rounding differs.
    assert relative_difference(K, K_stock) < 1e-12


@pytest.mark.parametrize("degree", ["P1", "P2"])
def test_stiffness_per_element_material_and_chunks(degree):
    mesh = distorted_box(1)
    basis = vector_basis(mesh, degree)
    rng = np.random.default_rng(2)
    E = rng.uniform(1.0, 3.0, mesh.nelements)
    nu = rng.uniform(-0.2, 0.45, mesh.nelements)
    lam, mu = lame_parameters(E, nu)
    K_stock = skfem.asm(linear_elasticity(lam[:, None], mu[:, None]), basis)
    # Tiny chunks exercise the chunked scatter (13 elements does not divide 384).
    K = elasticity_stiffness(basis, E, nu, chunk_size=13)
    assert relative_difference(K, K_stock) < 1e-12  # rounding only


@pytest.mark.parametrize("degree", ["P1", "P2"])
def test_consistent_mass_matches_stock_form(degree):
    basis = vector_basis(distorted_box(), degree)
    rho = 7800.0
    M = vector_mass(basis, rho)
    M_stock = skfem.BilinearForm(lambda u, v, w: rho * dot(u, v)).assemble(basis)
    assert relative_difference(M, M_stock) < 1e-12  # exact quadrature in both


@pytest.mark.parametrize("degree", ["P1", "P2"])
@pytest.mark.parametrize("lumped", [False, True])
def test_mass_total_per_component(degree, lumped):
    mesh = distorted_box()
    basis = vector_basis(mesh, degree)
    rho = 7800.0
    volume = 2.0 * 1.0 * 0.5  # node moves are interior: the box is unchanged
    M = vector_mass(basis, rho, lumped=lumped)
    ones = np.ones(basis.N)
    for c in range(3):
        e_c = np.zeros(basis.N)
        e_c[c::3] = 1.0
        # 1^T M e_c = rho V: a uniform translation carries the whole mass.
        assert ones @ (M @ e_c) == pytest.approx(rho * volume, rel=1e-12)
    if lumped:
        d = M.diagonal()
        assert M.nnz == basis.N and np.all(d > 0.0)  # HRZ keeps P2 vertex masses positive


def test_lumped_p1_is_row_sum_and_p2_hrz_ratios():
    mesh = distorted_box()
    M1 = vector_mass(vector_basis(mesh, "P1"), 2.0)
    np.testing.assert_allclose(vector_mass(vector_basis(mesh, "P1"), 2.0, lumped=True).diagonal(),
                               np.asarray(M1.sum(axis=1)).ravel(), rtol=1e-12)
    # One P2 tetrahedron: HRZ gives V/36 per vertex and 4V/27 per edge node
    # (diagonal 6:32 of the consistent P2 mass, Zienkiewicz & Taylor).
    vertices = np.array([[0.0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    tet = skfem.MeshTet(vertices, np.array([[0], [1], [2], [3]]))
    d = vector_mass(vector_basis(tet, "P2"), 1.0, lumped=True).diagonal()[0::3]
    V = 1.0 / 6.0
    np.testing.assert_allclose(d[:4], V / 36, rtol=1e-12)
    np.testing.assert_allclose(d[4:], 4 * V / 27, rtol=1e-12)


@pytest.mark.parametrize("nu", [0.5, 0.6, -1.0, np.nan])
def test_bad_poisson_ratio_raises(nu):
    basis = vector_basis(unit_cube(1), "P1")
    with pytest.raises(ValueError, match="poisson_ratio"):
        elasticity_stiffness(basis, 1.0, nu)


def test_bad_material_and_basis_raise():
    mesh = unit_cube(1)
    with pytest.raises(ValueError, match="youngs_modulus"):
        lame_parameters(-1.0, 0.3)
    with pytest.raises(ValueError, match="density"):
        vector_mass(vector_basis(mesh, "P1"), 0.0)
    with pytest.raises(ValueError, match="shape"):
        elasticity_stiffness(vector_basis(mesh, "P1"), np.ones(3), 0.3)
    with pytest.raises(TypeError, match="ElementVector"):
        elasticity_stiffness(skfem.Basis(mesh, skfem.ElementTetP1()), 1.0, 0.3)


@pytest.mark.parametrize("degree", ["P1", "P2"])
def test_rigid_body_modes_span_the_kernel(degree):
    basis = vector_basis(distorted_box(), degree, intorder=1)
    K = elasticity_stiffness(basis, 210e9, 0.3)
    modes = rigid_body_modes(basis)
    assert modes.shape == (basis.N, 6)
    assert np.linalg.matrix_rank(modes) == 6
    # K annihilates linear fields exactly; 1e-12 of ||K|| ||mode|| is rounding.
    residual = np.linalg.norm(K @ modes, axis=0)
    scale = sp.linalg.norm(K, 1) * np.linalg.norm(modes, axis=0)
    assert np.all(residual < 1e-12 * scale)
    # ...and only them: the 7th smallest eigenvalue of the free K is far from 0.
    if degree == "P1":
        w = np.linalg.eigvalsh(K.toarray())
        assert np.all(np.abs(w[:6]) < 1e-10 * w[-1]) and w[6] > 1e-4 * w[-1]


# -- loads ---------------------------------------------------------------------
@pytest.mark.parametrize("degree", ["P1", "P2"])
def test_traction_and_pressure_totals(degree):
    basis = vector_basis(distorted_box(), degree, intorder=1)
    t = np.array([3.0, -2.0, 5.0])
    f = surface_traction(basis, "right", t)  # x = 2 face, area 1 x 0.5
    np.testing.assert_allclose([f[c::3].sum() for c in range(3)], t * 0.5, rtol=1e-12)
    p = 4.0
    g = surface_pressure(basis, "top", p)  # y = 1 face (skfem 'top'), area 2 x 0.5, n = +e_y
    np.testing.assert_allclose([g[c::3].sum() for c in range(3)], [0.0, -p * 1.0, 0.0], atol=1e-12)
    # A closed surface under uniform pressure has zero resultant (int n ds = 0).
    closed = sum(surface_pressure(basis, name, p) for name in basis.mesh.boundaries)
    assert np.all(np.abs([closed[c::3].sum() for c in range(3)]) < 1e-12)


def test_pressure_rejects_interior_facets_and_unknown_names():
    mesh = unit_cube(2)
    interior = np.flatnonzero(mesh.f2t[1] >= 0)[:3]
    basis = vector_basis(mesh.with_boundaries({"cut": interior}, boundaries_only=False), "P1")
    with pytest.raises(ValueError, match="interior"):
        surface_pressure(basis, "cut", 1.0)
    with pytest.raises(MeshError, match="left"):  # lists the valid names
        surface_traction(basis, "nowhere", [1.0, 0.0, 0.0])


@pytest.mark.parametrize("degree", ["P1", "P2"])
def test_point_load(degree):
    basis = vector_basis(unit_cube(2), degree, intorder=1)
    F = np.array([1.0, -2.0, 0.5])
    f = point_load(basis, [0.49, 0.52, 1.0], F)
    nz = np.flatnonzero(f)  # the three dofs of the nearest vertex (0.5, 0.5, 1)
    assert nz.size == 3 and np.allclose(basis.doflocs[:, nz].T, [0.5, 0.5, 1.0])
    np.testing.assert_allclose(f[nz], F)
    g = point_load(basis, [0.3, 0.6, 0.9], F, snap_to_vertex=False)
    np.testing.assert_allclose([g[c::3].sum() for c in range(3)], F, rtol=1e-12)


# -- outputs -------------------------------------------------------------------
def _polynomial_field(basis, degree: str) -> tuple:
    """A field of the FE space (linear for P1, quadratic for P2) and its formula."""
    if degree == "P1":
        def u(x):
            return np.array([1 + 2 * x[0] - x[2], 3 * x[1] + x[2], -x[0] + 0.5 * x[1]])
    else:
        def u(x):
            return np.array([x[0] * x[1] + 1, x[2] ** 2 - x[0], 3 * x[1] * x[2] + x[0] ** 2])
    return basis.project(lambda x: u(x)), u


@pytest.mark.parametrize("degree", ["P1", "P2"])
def test_probe_rows_interpolate_exactly(degree):
    basis = vector_basis(distorted_box(), degree)
    q, u = _polynomial_field(basis, degree)
    points = np.random.default_rng(3).uniform([0, 0, 0], [2, 1, 0.5], (7, 3))
    for c in range(3):
        E = probe_rows(basis, points, c)
        assert E.shape == (7, basis.N)
        # A field of the FE space is reproduced up to rounding and projection solve.
        np.testing.assert_allclose(E @ q, u(points.T)[c], atol=1e-10)
    with pytest.raises(ValueError, match="outside"):
        probe_rows(basis, [[5.0, 0.0, 0.0]], 0)


@pytest.mark.parametrize("degree", ["P1", "P2"])
def test_average_rows_of_boundary_and_subdomain(degree):
    basis = vector_basis(unit_cube(2), degree)
    q, u = _polynomial_field(basis, degree)
    right = average_rows(basis, "right", 1)
    assert right.shape == (1, basis.N) and right.sum() == pytest.approx(1.0, rel=1e-12)
    half = average_rows(basis, "half", 0)
    if degree == "P1":
        # Mean of a linear field = its value at the centroid of the region.
        assert (right @ q)[0] == pytest.approx(u(np.array([1.0, 0.5, 0.5]))[1], rel=1e-10)
        assert (half @ q)[0] == pytest.approx(u(np.array([0.25, 0.5, 0.5]))[0], rel=1e-10)
    else:
        # Exact means: u_y = z^2 - x on x = 1 -> 1/3 - 1; u_x = x y + 1 on x < 1/2 -> 1/8 + 1.
        assert (right @ q)[0] == pytest.approx(1 / 3 - 1, rel=1e-10)
        assert (half @ q)[0] == pytest.approx(1.125, rel=1e-10)
    with pytest.raises(MeshError, match="subdomains: half"):
        average_rows(basis, "nowhere", 0)


# -- constraints ----------------------------------------------------------------
@pytest.mark.parametrize("degree, nodes_per_side", [("P1", 3), ("P2", 5)])
def test_dirichlet_dofs(degree, nodes_per_side):
    basis = vector_basis(unit_cube(2), degree, intorder=1)
    clamp = dirichlet_dofs(basis, "left")
    assert clamp.size == 3 * nodes_per_side ** 2
    assert np.allclose(basis.doflocs[0, clamp], 0.0)
    slide = dirichlet_dofs(basis, ["left", "bottom"], components=(2,))
    assert np.all(slide % 3 == 2)
    assert slide.size == 2 * nodes_per_side ** 2 - nodes_per_side  # shared edge once
    with pytest.raises(ValueError, match="component"):
        dirichlet_dofs(basis, "left", components=(3,))


# -- convergence on a manufactured solution ---------------------------------------
LAM, MU = lame_parameters(1.0, 0.3)
AMPLITUDE = np.array([1.0, 2.0, -1.0])


def manufactured(x: np.ndarray) -> tuple:
    r"""u = a sin(pi x) sin(pi y) sin(pi z), its gradient and f = -div sigma(u).

    With s the product of sines, ``-div sigma = -mu a lap(s) - (lam + mu) H(s) a``.
    u vanishes on the whole boundary of the unit cube.
    """
    S, C = np.sin(np.pi * x), np.cos(np.pi * x)
    s = S[0] * S[1] * S[2]
    grad_s = np.pi * np.array([C[0] * S[1] * S[2], S[0] * C[1] * S[2], S[0] * S[1] * C[2]])
    hess = np.empty((3, 3) + s.shape)
    for i in range(3):
        for j in range(3):
            hess[i, j] = -np.pi ** 2 * s if i == j else np.pi ** 2 * C[i] * C[j] * S[3 - i - j]
    a = AMPLITUDE.reshape((3,) + (1,) * s.ndim)
    u = a * s
    grad_u = a[:, None] * grad_s[None]
    laplacian = hess[0, 0] + hess[1, 1] + hess[2, 2]
    f = -MU * a * laplacian - (LAM + MU) * np.einsum("ij...,j...->i...", hess, a)
    return u, grad_u, f


def solve_sparse(A, b):
    try:
        import pypardiso
        return pypardiso.spsolve(A, b)
    except ImportError:  # pragma: no cover
        return sp.linalg.spsolve(A, b)


def manufactured_errors(n: int, degree: str) -> tuple:
    """(L2 error, energy-norm error) of the clamped cube with n cells per side."""
    mesh = unit_cube(n)
    p = ELEMENTS[degree]().maxdeg
    basis = vector_basis(mesh, degree, intorder=2 * p + 1)
    u_ex, grad_ex, f_ex = manufactured(np.asarray(basis.global_coordinates()))
    K = elasticity_stiffness(basis, 1.0, 0.3)
    f = skfem.LinearForm(lambda v, w: dot(w.f, v)).assemble(basis, f=f_ex)
    free = np.setdiff1d(np.arange(basis.N), dirichlet_dofs(basis, list(mesh.boundaries)))
    q = np.zeros(basis.N)
    q[free] = solve_sparse(K[free][:, free].tocsr(), f[free])
    uh = basis.interpolate(q)
    e = np.asarray(uh) - u_ex
    strain = 0.5 * (uh.grad - grad_ex + np.swapaxes(uh.grad - grad_ex, 0, 1))
    trace = strain[0, 0] + strain[1, 1] + strain[2, 2]
    l2 = np.sqrt(np.sum(np.einsum("i...,i...->...", e, e) * basis.dx))
    energy = np.sqrt(np.sum((2 * MU * np.einsum("ij...,ij...->...", strain, strain)
                             + LAM * trace ** 2) * basis.dx))
    return l2, energy


def fitted_rate(cells, errors) -> float:
    return np.polyfit(np.log(1.0 / np.asarray(cells)), np.log(errors), 1)[0]


def test_p1_convergence_rates():
    # Levels from 12 cells on: the L2 rate of P1 on these Kuhn meshes is still
    # 1.88 between 8 and 12 cells (pre-asymptotic), 1.94 fitted on 12-16-20.
    cells = (12, 16, 20)
    errors = np.array([manufactured_errors(n, "P1") for n in cells])
    assert abs(fitted_rate(cells, errors[:, 0]) - 2.0) < 0.1  # L2: O(h^2)
    assert abs(fitted_rate(cells, errors[:, 1]) - 1.0) < 0.1  # energy: O(h)
    # Ceilings ~20 % above the measured 0.0114 and 0.406 (|u|_L2 = 0.61).
    assert errors[-1, 0] < 0.014 and errors[-1, 1] < 0.5


def test_p2_convergence_rate():
    cells = (4, 6, 8)  # 14.7k dofs at 8 cells
    errors = np.array([manufactured_errors(n, "P2") for n in cells])
    assert abs(fitted_rate(cells, errors[:, 0]) - 3.0) < 0.1  # L2: O(h^3), fitted 3.05
    # Ceiling ~20 % above the measured 1.76e-3.
    assert errors[-1, 0] < 2.1e-3
