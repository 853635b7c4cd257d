"""Linear-solver strategies: agreement, factor reuse, strategy choice, errors."""


import numpy as np
import pytest
import scipy.sparse as sp

from _required import EXTRAS, PARDISO_REQUIRED
from femrom.solvers import (STRATEGIES, SUPERLU_MAX_DOFS, LinearSolverError, choose_strategy, is_available,
                            make_solver)

# where FEMROM_REQUIRE_EXTRAS asks for PARDISO (x86_64) the tests run without it, and fail
needs_pardiso = pytest.mark.skipif(not is_available("pardiso") and not PARDISO_REQUIRED,
                                   reason="pypardiso not installed")


def poisson_2d(m: int) -> sp.csr_matrix:
    """5-point Laplacian on an m x m interior grid (Dirichlet), unscaled."""
    T = sp.diags([2.0 * np.ones(m), -np.ones(m - 1), -np.ones(m - 1)], [0, 1, -1])
    eye = sp.identity(m)
    return (sp.kron(T, eye) + sp.kron(eye, T)).tocsr()


def poisson_condition_number(m: int) -> float:
    # eigenvalues of the 1D factor are 2 - 2 cos(k pi / (m + 1)), k = 1..m
    lam = 2.0 - 2.0 * np.cos(np.pi * np.array([1, m]) / (m + 1))
    return lam[1] / lam[0]


def clamped_elasticity(nx: int = 3):
    """3D P1 elasticity of a 4:1:1 bar clamped at x = 0 (E = 1, nu = 0.3).

    Returns K on the free dofs and its six rigid-body modes (the near null
    space of the unclamped operator).
    """
    from skfem import Basis, ElementTetP1, ElementVector, MeshTet, asm
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    mesh = MeshTet.init_tensor(np.linspace(0, 4, 4 * nx + 1), np.linspace(0, 1, nx + 1),
                               np.linspace(0, 1, nx + 1))
    basis = Basis(mesh, ElementVector(ElementTetP1()))
    K = asm(linear_elasticity(*lame_parameters(1.0, 0.3)), basis)
    component = np.empty(basis.N, dtype=int)
    for c in range(3):
        component[basis.nodal_dofs[c]] = c
    x, y, z = basis.doflocs
    modes = np.zeros((basis.N, 6))
    for c in range(3):
        modes[component == c, c] = 1.0  # translations
    rotations = [(-y, x, 0 * x), (0 * x, -z, y), (z, 0 * x, -x)]  # about z, x, y
    for j, rotation in enumerate(rotations):
        for c in range(3):
            modes[component == c, 3 + j] = rotation[c][component == c]
    fixed = basis.get_dofs(lambda p: p[0] < 1e-12).all()
    free = np.setdiff1d(np.arange(basis.N), fixed)
    return K[free][:, free].tocsr(), modes[free]


def test_unknown_strategy_lists_the_valid_ones():
    with pytest.raises(ValueError, match="unknown linear-solver strategy 'lu'.*superlu.*amg-cg"):
        make_solver(sp.identity(3, format="csr"), "lu")


def test_auto_reports_its_choice():
    assert make_solver(sp.diags([1.0, 2.0, 3.0], format="csr")).name == "diagonal"
    assert make_solver(poisson_2d(10)).name == "superlu"  # 100 dofs: small
    # A large problem (simulated by lowering the thresholds): pardiso, then cholmod, then AMG.
    A = poisson_2d(10)
    available = {"pardiso": True, "cholmod": True, "amg-cg": True}
    rule = dict(small=50, direct_threshold=50, available=lambda s: available.get(s, True))
    assert choose_strategy(A, **rule) == "pardiso"
    available["pardiso"] = False
    assert choose_strategy(A, **rule) == "cholmod"
    assert choose_strategy(A, spd=False, **rule) == "amg-cg"  # cholmod needs SPD
    available["cholmod"] = False
    assert choose_strategy(A, **rule) == "amg-cg"


def test_auto_decides_by_size_and_availability_not_dimension():
    # the documented rule (module docstring, "Size, not dimension"): a 1D chain and a 3D
    # elasticity matrix of the same size get the same strategy, whatever is installed
    K3, _ = clamped_elasticity(3)
    n = K3.shape[0]
    K1 = sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
    available = {}
    for small, direct, expected in [(n + 1, n + 1, "superlu"), (n, n, "pardiso"),
                                    (n, n + 1, "cholmod"), (n, n - 1, "amg-cg")]:
        rule = dict(small=small, direct_threshold=direct, available=lambda s: available.get(s, True))
        available.update(pardiso=expected == "pardiso", cholmod=expected == "cholmod")
        assert choose_strategy(K1, **rule) == choose_strategy(K3, **rule) == expected


def test_superlu_refuses_large_problems():
    with pytest.raises(ValueError, match="superlu is limited to 50 dofs"):
        make_solver(poisson_2d(10), "superlu", max_dofs=50)


@pytest.mark.parametrize("strategy", [s for s in STRATEGIES if s not in ("auto", "diagonal")])
def test_strategies_agree_on_poisson(strategy):
    if not is_available(strategy):
        if strategy == "pardiso" and PARDISO_REQUIRED:
            pytest.fail(f"{EXTRAS} is set but pypardiso is not installed", pytrace=False)
        pytest.skip(f"{strategy} not installed")
    m = 40
    A = poisson_2d(m)
    b = np.random.default_rng(0).standard_normal(A.shape[0])
    reference = np.linalg.solve(A.toarray(), b)
    rtol = 1e-10
    solver = make_solver(A, strategy, near_nullspace=np.ones(A.shape[0]), rtol=rtol)
    x = solver.solve(b)
    error = np.linalg.norm(x - reference) / np.linalg.norm(reference)
    if strategy in ("amg-cg", "jacobi-cg"):
        # CG stops at ||r|| <= rtol ||b||, so the error is at most cond(A) * rtol
        # (cond = 6.6e2 for m = 40, from the closed-form eigenvalues).
        assert np.linalg.norm(b - A @ x) <= rtol * np.linalg.norm(b) * (1 + 1e-6)
        assert error <= poisson_condition_number(m) * rtol
        if strategy == "amg-cg":
            assert 0 < solver.last_iterations < 50  # AMG keeps CG short
        else:
            # a constant diagonal: Jacobi is plain CG, ~sqrt(cond) log(2/rtol) iterations (observed 143)
            assert 50 < solver.last_iterations < 300
    else:
        # backward-stable direct solve: error ~ cond(A) * eps = 1.5e-13
        assert error < 1e-12


def test_amg_warm_start_from_the_solution_needs_no_iteration():
    A = poisson_2d(30)
    b = np.random.default_rng(1).standard_normal(A.shape[0])
    solver = make_solver(A, "amg-cg", near_nullspace=np.ones(A.shape[0]))
    x = solver.solve(b)
    cold = solver.last_iterations
    solver.solve(b, x0=x)
    assert solver.last_iterations <= 1 < cold
    assert solver.total_iterations == cold + solver.last_iterations


def test_amg_gmres_for_a_nonsymmetric_matrix():
    m = 20
    A = poisson_2d(m)
    # upwind convection in x: nonsymmetric, still an M-matrix
    D = sp.kron(sp.diags([1.0, -1.0], [0, -1], shape=(m, m)), sp.identity(m))
    A = (A + 0.5 * D).tocsr()
    b = np.ones(A.shape[0])
    x = make_solver(A, "amg-cg", spd=False, rtol=1e-10).solve(b)
    assert np.linalg.norm(A @ x - b) <= 1e-9 * np.linalg.norm(b)


def test_elasticity_rigid_body_modes():
    K, modes = clamped_elasticity(nx=3)
    b = np.random.default_rng(2).standard_normal(K.shape[0])
    direct = make_solver(K, "superlu").solve(b)
    rtol = 1e-10
    with_modes = make_solver(K, "amg-cg", near_nullspace=modes, rtol=rtol)
    x = with_modes.solve(b)
    # cond(K) of this small clamped bar is ~1e3-1e4; 1e-5 leaves room for it
    assert np.linalg.norm(x - direct) <= 1e-5 * np.linalg.norm(direct)
    plain = make_solver(K, "amg-cg", rtol=rtol)  # pyamg's default: constants only
    plain.solve(b)
    # the rigid-body modes are the right near null space: fewer CG iterations
    assert with_modes.last_iterations < plain.last_iterations
    if is_available("pardiso"):
        x_pardiso = make_solver(K, "pardiso").solve(b)
        assert np.linalg.norm(x_pardiso - direct) <= 1e-10 * np.linalg.norm(direct)


@needs_pardiso
def test_pardiso_factorises_once_and_reuses():
    A = poisson_2d(120)  # 14,400 dofs
    rng = np.random.default_rng(3)
    solver = make_solver(A, "pardiso")
    errors = []
    for _ in range(5):
        b = rng.standard_normal(A.shape[0])
        x = solver.solve(b)
        errors.append(np.linalg.norm(A @ x - b) / np.linalg.norm(b))
    # the phases PARDISO really ran: one analysis + factorisation, then solves only
    # (speed of reuse is measured in benchmarks/fom_ladder.py, not asserted here)
    assert solver.phase_calls[12] == 1 and solver.phase_calls[33] == 5
    assert solver.n_factorizations == 1 and solver.n_solves == 5
    assert max(errors) < 1e-12


@needs_pardiso
def test_pardiso_nonsymmetric_and_indefinite():
    A = poisson_2d(15)
    A_nonsym = (A + 0.3 * sp.diags(np.ones(A.shape[0] - 1), 1)).tocsr()
    b = np.ones(A.shape[0])
    x = make_solver(A_nonsym, "pardiso", spd=False).solve(b)
    assert np.linalg.norm(A_nonsym @ x - b) < 1e-12 * np.linalg.norm(b) * 1e2
    # the upper triangle alone is what mtype 2 reads: the result solves the symmetric A
    x_spd = make_solver(A, "pardiso").solve(b)
    assert np.linalg.norm(A @ x_spd - b) < 1e-10 * np.linalg.norm(b)
    with pytest.raises(LinearSolverError, match="pardiso"):
        make_solver((A - 10.0 * sp.identity(A.shape[0])).tocsr(), "pardiso", spd=True)


@pytest.mark.skipif(is_available("cholmod"), reason="scikit-sparse is installed")
def test_cholmod_missing_is_a_clear_import_error():
    with pytest.raises(ImportError, match="cholmod.*scikit-sparse"):
        make_solver(poisson_2d(5), "cholmod")


@pytest.mark.skipif(not is_available("cholmod"), reason="scikit-sparse not installed")
def test_cholmod_agrees_with_superlu():
    A = poisson_2d(30)
    b = np.ones(A.shape[0])
    assert np.allclose(make_solver(A, "cholmod").solve(b), make_solver(A, "superlu").solve(b),
                       rtol=1e-12, atol=0)


# -- Jacobi-CG for mass matrices, and one factorisation shared by several runs ----------------
def _p2_mass(n_cells: int):
    from skfem import Basis, ElementTetP2, ElementVector, MeshTet, asm
    from skfem.helpers import dot
    from skfem import BilinearForm

    mesh = MeshTet.init_tensor(*(np.linspace(0, 1, n_cells + 1),) * 3)
    basis = Basis(mesh, ElementVector(ElementTetP2()))
    return asm(BilinearForm(lambda u, v, w: dot(u, v)), basis).tocsr()


def test_jacobi_cg_solves_mass_matrices_in_mesh_independent_iterations():
    """Wathen (IMA J. Numer. Anal. 7, 1987): the Jacobi-scaled consistent mass matrix has a
    spectrum bounded independently of h, so CG needs about the same iterations on every mesh."""
    rng = np.random.default_rng(0)
    iterations = []
    for n_cells in (2, 4, 8):
        M = _p2_mass(n_cells)
        b = rng.standard_normal(M.shape[0])
        solver = make_solver(M, "jacobi-cg", rtol=1e-12)
        x = solver.solve(b)
        assert np.linalg.norm(M @ x - b) <= 1e-12 * np.linalg.norm(b) * 1.01
        assert solver.n_factorizations == 0
        iterations.append(solver.last_iterations)
    # observed 39 / 53 / 57 for 375 / 2187 / 14739 dofs: the count settles as h falls (the coarsest
    # mesh is mostly boundary). Doubling the cells per direction from 4 to 8 (6.7x the dofs) may
    # add at most 25 % (observed 8 %); unpreconditioned Poisson-like conditioning would double it
    assert iterations[2] <= 1.25 * iterations[1] and max(iterations) < 80, iterations
    with pytest.raises(ValueError, match="SPD"):
        make_solver(M, "jacobi-cg", spd=False)


def test_solver_cache_factorises_a_matrix_once_for_several_runs():
    from femrom.solvers import SolverCache
    from femrom.integrators import Newmark, integrate
    from femrom.scene import SecondOrderSystem

    K = poisson_2d(12)
    M = sp.identity(K.shape[0], format="csr") * 1e-2
    system = SecondOrderSystem(mass=M, stiffness=K)
    q0 = np.sin(np.arange(K.shape[0]))
    cache = SolverCache("superlu", size=2)   # the mass (initial acceleration) and A_eff
    first = integrate(system, Newmark(), q0, 0 * q0, 1e-2, 20, solver=cache)
    second = integrate(system, Newmark(), q0, 0 * q0, 1e-2, 20, solver=cache)
    other = integrate(system, Newmark(), q0, 0 * q0, 2e-2, 20, solver=cache)
    assert first.n_factorizations == 2       # the mass (initial acceleration) and A_eff
    assert second.n_factorizations == 0      # both equal to ones already set up
    assert other.n_factorizations == 1       # a new step: a new A_eff (the mass is reused)
    assert cache.hits == 3 and cache.misses == 3
    # the same factor gives the same solutions, bit for bit
    from femrom.integrators import Trajectory
    a, b = Trajectory(fields=("q",)), Trajectory(fields=("q",))
    integrate(system, Newmark(), q0, 0 * q0, 1e-2, 20, solver=cache, consumers=[a])
    integrate(system, Newmark(), q0, 0 * q0, 1e-2, 20, consumers=[b], solver="superlu")
    np.testing.assert_array_equal(a.q, b.q)


def test_without_fast_direct_solvers_auto_keeps_superlu_up_to_its_guard():
    """Measured (docs/benchmarks.md, "Which strategy is the default"): SuperLU steps
    12-16x faster than AMG-CG from 2e4 to 5.7e4 dofs and is ahead after 4-6 steps, so
    without PARDISO or CHOLMOD ``auto`` hands it everything its guard accepts."""
    def available(s):
        return s not in ("pardiso", "cholmod")

    def chain(n):
        return sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")

    assert choose_strategy(chain(SUPERLU_MAX_DOFS), available=available) == "superlu"
    assert make_solver(chain(SUPERLU_MAX_DOFS), "superlu").name == "superlu"  # accepted
    assert choose_strategy(chain(SUPERLU_MAX_DOFS + 1), available=available) == "amg-cg"
