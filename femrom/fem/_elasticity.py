r"""Isotropic linear elasticity on tetrahedra: fast stiffness and mass assembly.

The operators act on a vector basis ``skfem.Basis(mesh, ElementVector(E))``
with ``E`` = ``ElementTetP1()`` or ``ElementTetP2()`` on a straight-sided
``skfem.MeshTet``, and use skfem's own dof numbering, so that
``basis.get_dofs('left')`` and every other skfem tool stay valid. skfem's
``ElementVector`` interleaves the components: the global dof of component
``c`` of scalar node ``s`` is ``3 s + c`` (checked at run time).

Assembly never calls a weak form. On an affine tetrahedron
:math:`x = A_e X + b_e`, the gradients are
:math:`\nabla \phi_a = A_e^{-T} \hat\nabla \hat\phi_a`, so every element matrix
is a fixed reference tensor contracted with a few numbers per element:

.. math::

    K^e_{ai,bj} = |\det A_e| \sum_{k,l} R_{ak,bl}\,
        \bigl(\lambda G_{ki} G_{lj} + \mu G_{kj} G_{li}
        + \mu\,\delta_{ij}\, G_{k\cdot} \cdot G_{l\cdot}\bigr),
    \qquad G = A_e^{-1},
    \qquad R_{ak,bl} = \int_{\hat T} \partial_k \hat\phi_a\, \partial_l \hat\phi_b,

    M^e_{ai,bj} = \rho_e |\det A_e|\, \delta_{ij} \int_{\hat T} \hat\phi_a \hat\phi_b .

Per chunk of elements this is one matrix product ``R (n_local^2, 9) @ F (9, 9 n_e)``
and one scatter (``np.add.at``) of whole 3x3 blocks into the block sparsity
pattern of the scalar element, found once by sorting; the block matrix is
converted once to CSR. For the P2 stiffness at 1e5 dofs this is ~20-40x faster
than skfem's ``linear_elasticity`` form and 2x faster than building full COO
triplets and calling ``coo_matrix(...).tocsr()``, with 9x smaller index arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import skfem
from skfem.quadrature import get_quadrature
from skfem.refdom import RefTet

from femrom._errors import FemromRuntimeError, FemromTypeError, FemromValueError

__all__ = [
    "elasticity_stiffness",
    "lame_parameters",
    "vector_mass",
]

_SUPPORTED_ELEMENTS = (skfem.ElementTetP1, skfem.ElementTetP2)

# Temporary memory per chunk of elements (element values and their int64
# scatter targets, ~27 n_local^2 words per element): small next to the result
# (P2 at 5e5 dofs: 479 MB CSR), and chunking costs nothing measurable.
_CHUNK_BYTES = 64 * 2**20


# -- material ---------------------------------------------------------------
def lame_parameters(youngs_modulus, poisson_ratio) -> tuple:
    r"""Lame parameters of an isotropic material.

    .. math::

        \lambda = \frac{E \nu}{(1 + \nu)(1 - 2\nu)}, \qquad
        \mu = \frac{E}{2 (1 + \nu)}

    Parameters
    ----------
    youngs_modulus : float or (n_elements,) array_like
        Young's modulus ``E > 0`` (Pa).
    poisson_ratio : float or (n_elements,) array_like
        Poisson ratio, strictly inside ``(-1, 0.5)``: ``nu -> 0.5`` sends
        ``lambda`` to infinity (incompressible; use a mixed formulation).

    Returns
    -------
    lam, mu : float or ndarray
        First and second Lame parameters (Pa), with the input shapes.
    """
    E = np.asarray(youngs_modulus, dtype=float)
    nu = np.asarray(poisson_ratio, dtype=float)
    if not np.all(np.isfinite(E)) or np.any(E <= 0.0):
        raise FemromValueError(f"youngs_modulus must be finite and > 0, got min {E.min()}")
    if not np.all(np.isfinite(nu)) or np.any(nu <= -1.0) or np.any(nu >= 0.5):
        raise FemromValueError("poisson_ratio must lie strictly inside (-1, 0.5) "
                               f"(0.5 is incompressible), got [{nu.min()}, {nu.max()}]")
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    if lam.ndim == 0:
        return float(lam), float(mu)
    return lam, mu


# -- basis checks and geometry ----------------------------------------------
def _scalar_element(basis) -> skfem.Element:
    """The scalar element of a 3D ``ElementVector`` basis on a straight ``MeshTet``."""
    elem = getattr(basis, "elem", None)
    if not isinstance(elem, skfem.ElementVector) or elem.dim != 3:
        raise FemromTypeError("expected a skfem.Basis with ElementVector(ElementTetP1() or "
                              f"ElementTetP2()), got element {type(elem).__name__}")
    if type(elem.elem) not in _SUPPORTED_ELEMENTS:
        raise FemromTypeError("supported scalar elements are ElementTetP1 and ElementTetP2, "
                              f"got {type(elem.elem).__name__}")
    if type(basis.mesh) is not skfem.MeshTet1:
        raise FemromTypeError(f"expected a straight-sided skfem.MeshTet, got {type(basis.mesh).__name__}")
    return elem.elem


def _element_indices(basis) -> np.ndarray:
    """(n_e,) int ndarray: mesh elements covered by ``basis`` (all unless restricted)."""
    if basis.tind is None:
        return np.arange(basis.mesh.nelements)
    return np.asarray(basis.tind)


def _scalar_element_dofs(basis) -> np.ndarray:
    """(n_e, n_local) int64 ndarray: scalar node of each local node, from the vector dofs.

    Raises if skfem's vector numbering is not the interleaved ``3 s + c``.
    """
    dofs = np.asarray(basis.element_dofs)
    scalar = dofs[0::3]
    if not (np.array_equal(dofs[1::3], scalar + 1) and np.array_equal(dofs[2::3], scalar + 2)
            and not np.any(scalar % 3)):
        raise FemromRuntimeError("skfem's ElementVector dofs are not interleaved (3 s + c); "
                                 "femrom's fast assembly relies on that ordering")
    return np.ascontiguousarray((scalar // 3).T, dtype=np.int64)


def _affine_maps(mesh, elements) -> tuple[np.ndarray, np.ndarray]:
    """Inverse Jacobians and volume factors of straight tetrahedra.

    Returns
    -------
    inv_jacobian : (n_e, 3, 3) ndarray
        ``A_e^{-1}`` with ``A_e = [x_1 - x_0, x_2 - x_0, x_3 - x_0]``.
    abs_det : (n_e,) ndarray
        ``|det A_e|`` (six times the element volume).
    """
    p = mesh.p.T
    t = mesh.t[:, elements]
    x0 = p[t[0]]
    c0, c1, c2 = p[t[1]] - x0, p[t[2]] - x0, p[t[3]] - x0  # columns of A_e
    # Rows of A^{-1} are the cross products of the columns over det A
    # (cofactor formula; cheaper than batched LU for 3x3).
    adj = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=1)
    det = np.einsum("ej,ej->e", c0, adj[:, 0])
    if np.any(det == 0.0):
        raise FemromValueError(f"{int(np.sum(det == 0.0))} degenerate (zero-volume) tetrahedra")
    return adj / det[:, None, None], np.abs(det)


def _reference_gradient_tensor(elem) -> np.ndarray:
    r"""(n_local^2, 9) ndarray ``R[(a, b), (k, l)] = \int \partial_k \phi_a \partial_l \phi_b``.

    Exact: gradients have degree ``p - 1``, integrated with a degree ``2 p - 2`` rule.
    """
    X, W = get_quadrature(RefTet, max(2 * (elem.maxdeg - 1), 1))
    nl = elem.doflocs.shape[0]
    dphi = np.stack([elem.lbasis(X, a)[1] for a in range(nl)])  # (a, k, q)
    R = np.einsum("akq,blq,q->abkl", dphi, dphi, W)
    return R.reshape(nl * nl, 9)


def _reference_mass_matrix(elem) -> np.ndarray:
    r"""(n_local, n_local) ndarray ``\int_{\hat T} \phi_a \phi_b`` (exact, degree ``2 p`` rule)."""
    X, W = get_quadrature(RefTet, 2 * elem.maxdeg)
    nl = elem.doflocs.shape[0]
    phi = np.stack([elem.lbasis(X, a)[0] for a in range(nl)])  # (a, q)
    return (phi * W) @ phi.T


def _per_element(value, n_elements: int, name: str) -> np.ndarray:
    """(n_elements,) float ndarray from a scalar or a per-element array."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return np.full(n_elements, float(arr))
    if arr.shape != (n_elements,):
        raise FemromValueError(f"{name} must be a scalar or have shape ({n_elements},), got {arr.shape}")
    return arr


# -- block sparsity pattern --------------------------------------------------
@dataclass(frozen=True)
class _BlockPattern:
    """Sparsity of the scalar element couplings and where each local pair goes.

    Attributes
    ----------
    indptr, indices : int ndarrays
        CSR pattern of the (n_scalar, n_scalar) scalar coupling matrix.
    position : (n_local^2, n_e) int ndarray
        Index into ``indices`` of the local pair ``(a, b)`` (row ``a n_local + b``)
        of each element.
    n_scalar : int
    """

    indptr: np.ndarray
    indices: np.ndarray
    position: np.ndarray
    n_scalar: int

    @property
    def n_blocks(self) -> int:
        return int(self.indices.size)


def _block_pattern(scalar_dofs: np.ndarray, n_scalar: int) -> _BlockPattern:
    """Pattern of all local pairs of ``scalar_dofs`` ((n_e, n_local) int ndarray).

    One stable argsort of the ``row * n + col`` keys; faster than
    ``np.unique(return_inverse=True)`` here (0.45 s vs 0.65 s for 7e6 pairs).
    """
    n_e, nl = scalar_dofs.shape
    dofs = scalar_dofs.T
    key = (dofs[:, None, :] * n_scalar + dofs[None, :, :]).ravel()  # [a, b, e]
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    del key
    first = np.empty(sorted_key.size, dtype=bool)
    first[0] = True
    np.not_equal(sorted_key[1:], sorted_key[:-1], out=first[1:])
    unique_key = sorted_key[first]
    del sorted_key
    index_dtype = np.int32 if unique_key.size < 2**31 else np.int64
    group = np.cumsum(first, dtype=index_dtype) - 1
    del first
    position = np.empty(order.size, dtype=index_dtype)
    position[order] = group
    del order, group
    rows = unique_key // n_scalar
    indices = (unique_key - rows * n_scalar).astype(index_dtype)
    indptr = np.zeros(n_scalar + 1, dtype=index_dtype)
    np.cumsum(np.bincount(rows, minlength=n_scalar), out=indptr[1:])
    return _BlockPattern(indptr, indices, position.reshape(nl * nl, n_e), n_scalar)


def _chunks(n_elements: int, entries_per_element: int, chunk_size: int | None):
    size = chunk_size or max(1, _CHUNK_BYTES // (8 * entries_per_element))
    for start in range(0, n_elements, size):
        yield slice(start, min(start + size, n_elements))


# -- operators ----------------------------------------------------------------
def _stiffness_factors(inv_jac, abs_det, lam, mu) -> np.ndarray:
    r"""(9 [k, l], 9 n_e [e, i, j]) ndarray of per-element material-geometry factors.

    ``|det A| (lam G_ki G_lj + mu G_kj G_li + mu delta_ij G_k . G_l)``, ``G = A^{-1}``.
    """
    G = inv_jac
    outer = np.einsum("eki,elj->kleij", G, G)  # G_ki G_lj
    lam_w = (lam * abs_det)[:, None, None]
    mu_w = (mu * abs_det)[:, None, None]
    F = lam_w * outer
    F += mu_w * outer.transpose(0, 1, 2, 4, 3)  # G_kj G_li
    gram = np.einsum("ekm,elm->kle", G, G)  # G_k . G_l
    gram *= mu * abs_det
    for i in range(3):
        F[:, :, :, i, i] += gram
    return F.reshape(9, -1)


def elasticity_stiffness(basis, youngs_modulus, poisson_ratio, *,
                         chunk_size: int | None = None) -> sp.csr_matrix:
    r"""Stiffness of isotropic linear elasticity, assembled without quadrature loops.

    .. math::

        K_{IJ} = \int_\Omega \sigma(\phi_J) : \varepsilon(\phi_I)\,dx, \qquad
        \sigma = 2\mu\,\varepsilon + \lambda\,\mathrm{tr}(\varepsilon) I

    Equal (to rounding) to skfem's
    ``asm(linear_elasticity(*lame_parameters(E, nu)), basis)``; P2 is exact
    because the integrand is quadratic on straight tetrahedra.

    Parameters
    ----------
    basis : skfem.CellBasis
        ``Basis(mesh, ElementVector(ElementTetP1() or ElementTetP2()))`` on a
        ``MeshTet``. Only its mesh, element and dofs are used, so a basis built
        with ``intorder=1`` (cheap) gives the same matrix.
    youngs_modulus, poisson_ratio : float or (n_e,) array_like
        Material, constant or per element of ``basis`` (``n_e`` elements; a
        basis restricted with ``elements=`` leaves zero rows on the other nodes).
    chunk_size : int, optional
        Elements per chunk (bounds the temporary memory to ~64 MB by default).

    Returns
    -------
    (3 n_nodes, 3 n_nodes) scipy.sparse.csr_matrix
        Symmetric positive semidefinite, six rigid-body modes in the kernel.
    """
    elem = _scalar_element(basis)
    elements = _element_indices(basis)
    n_e = elements.size
    lam, mu = lame_parameters(_per_element(youngs_modulus, n_e, "youngs_modulus"),
                              _per_element(poisson_ratio, n_e, "poisson_ratio"))
    scalar_dofs = _scalar_element_dofs(basis)
    pattern = _block_pattern(scalar_dofs, basis.N // 3)
    Rt = _reference_gradient_tensor(elem)
    nl2 = Rt.shape[0]
    blocks = np.zeros((pattern.n_blocks, 3, 3))
    flat_blocks = blocks.reshape(-1)
    for chunk in _chunks(n_e, 9 * nl2 * 3, chunk_size):
        inv_jac, abs_det = _affine_maps(basis.mesh, elements[chunk])
        F = _stiffness_factors(inv_jac, abs_det, lam[chunk], mu[chunk])
        values = Rt @ F  # (nl2, n_chunk * 9): [ab, e, ij]
        position = pattern.position[:, chunk].astype(np.int64)
        target = (position[:, :, None] * 9 + np.arange(9)).ravel()  # [ab, e, ij]
        # One ufunc.at over whole 3x3 blocks (contiguous): as fast as bincount
        # in numpy >= 1.25, and nothing is paid per untouched block.
        np.add.at(flat_blocks, target, values.ravel())
    indptr, indices = pattern.indptr, pattern.indices
    del pattern  # frees the (n_local^2, n_e) positions before the CSR copy
    return _blocks_to_csr(indptr, indices, blocks)


def _blocks_to_csr(indptr: np.ndarray, indices: np.ndarray, blocks: np.ndarray) -> sp.csr_matrix:
    """CSR of the (3 n, 3 n) matrix with 3x3 ``blocks`` ((n_blocks, 3, 3)) on a block pattern."""
    n = 3 * (indptr.size - 1)
    return sp.bsr_matrix((blocks, indices, indptr), shape=(n, n)).tocsr()


def _scalar_mass(basis, density, *, lumped: bool):
    """Scalar consistent mass (CSR on the scalar nodes) or its HRZ-lumped diagonal."""
    elem = _scalar_element(basis)
    elements = _element_indices(basis)
    n_e = elements.size
    rho = _per_element(density, n_e, "density")
    if np.any(rho <= 0.0):
        raise FemromValueError(f"density must be > 0, got min {rho.min()}")
    Mref = _reference_mass_matrix(elem)
    scalar_dofs = _scalar_element_dofs(basis)
    scale = rho * _affine_maps(basis.mesh, elements)[1]
    n_scalar = basis.N // 3
    if lumped:
        # HRZ: diagonal of the consistent element mass, scaled so each element
        # keeps its total mass (Hinton, Rock & Zienkiewicz 1976, Earthquake Eng.
        # Struct. Dyn. 4(3), 245-249). Equals the row sum for P1.
        diag = np.diag(Mref) * (Mref.sum() / np.trace(Mref))
        weights = (scale[:, None] * diag[None, :]).ravel()
        return np.bincount(scalar_dofs.ravel(), weights=weights, minlength=n_scalar)
    pattern = _block_pattern(scalar_dofs, n_scalar)
    data = np.bincount(pattern.position.ravel(),
                       weights=(Mref.reshape(-1, 1) * scale[None, :]).ravel(),
                       minlength=pattern.n_blocks)
    return pattern, data


def vector_mass(basis, density, *, lumped: bool = False) -> sp.csr_matrix:
    r"""Mass matrix of a displacement field, consistent or HRZ-lumped.

    .. math::

        M_{IJ} = \int_\Omega \rho\, \phi_I \cdot \phi_J\,dx

    Lumped: each element's consistent diagonal scaled to keep its mass
    (HRZ; Hinton, Rock & Zienkiewicz 1976). For P1 it equals the row sum
    (``rho V_e / 4`` per vertex); for P2 the row sum gives negative vertex
    masses (``-rho V_e / 20``) while HRZ gives ``rho V_e / 36`` per vertex and
    ``4 rho V_e / 27`` per edge node, all positive.

    Parameters
    ----------
    basis : skfem.CellBasis
        Vector P1/P2 basis on a ``MeshTet`` (see :func:`elasticity_stiffness`).
    density : float or (n_e,) array_like
        ``rho > 0`` (kg/m^3), constant or per element.
    lumped : bool
        Return the HRZ-lumped diagonal matrix instead of the consistent one.

    Returns
    -------
    (3 n_nodes, 3 n_nodes) scipy.sparse.csr_matrix
        Symmetric positive definite; ``1^T M e_c = rho V`` for each component ``c``.
    """
    result = _scalar_mass(basis, density, lumped=lumped)
    if lumped:
        return sp.diags(np.repeat(result, 3), format="csr")
    pattern, data = result
    n = pattern.n_scalar
    scalar = sp.csr_matrix((data, pattern.indices, pattern.indptr), shape=(n, n))
    # Interleaved numbering 3 s + c is exactly M_s (x) I_3 (as fast as a hand-made CSR).
    return sp.kron(scalar, sp.identity(3), format="csr")
