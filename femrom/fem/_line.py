"""One-dimensional structures: Euler-Bernoulli bending (Hermite) and axial/string (P1).

Weak forms on a :class:`skfem.MeshLine` of length ``L``:

    bending:   a(w, v) = int_0^L EI w'' v'' dx       (ElementLineHermite, dofs w, w')
    axial:     a(u, v) = int_0^L c  u'  v'  dx       (ElementLineP1; c = EA for a bar,
                                                      the tension for a string, 1 for
                                                      the wave operator of sine-Gordon)
    mass:      m(u, v) = int_0^L rho A u v dx
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from skfem import Basis, BilinearForm, ElementLineHermite, ElementLineP1, MeshLine
from skfem.helpers import dd, grad

from femrom._errors import FemromValueError

#: Line elements by scene name: (element factory, quadrature order exact for the mass).
LINE_ELEMENTS = {
    "hermite": (ElementLineHermite, 6),  # cubic x cubic = degree 6
    "p1": (ElementLineP1, 2),
}


def line_basis(mesh: MeshLine, element: str = "hermite") -> Basis:
    """Basis on a line mesh: ``"hermite"`` (w, w' per node) or ``"p1"`` (u per node)."""
    try:
        factory, intorder = LINE_ELEMENTS[element]
    except KeyError:
        raise FemromValueError(f"unknown line element {element!r}; valid: {', '.join(LINE_ELEMENTS)}") from None
    return Basis(mesh, factory(), intorder=intorder)


@BilinearForm
def _curvature_product(u, v, w):
    return w["rigidity"] * dd(u)[0, 0] * dd(v)[0, 0]


@BilinearForm
def _slope_product(u, v, w):
    return w["rigidity"] * grad(u)[0] * grad(v)[0]


@BilinearForm
def _value_product(u, v, w):
    return w["density"] * u * v


def bending_stiffness(basis: Basis, flexural_rigidity: float) -> sp.csr_matrix:
    """(N, N) Euler-Bernoulli stiffness ``int EI w'' v'' dx`` on a Hermite basis."""
    _require_element(basis, ElementLineHermite, "bending")
    return _slope_or_curvature(basis, _curvature_product, flexural_rigidity)


def axial_stiffness(basis: Basis, rigidity: float) -> sp.csr_matrix:
    """(N, N) second-order operator ``int c u' v' dx`` (bar EA, string tension, wave)."""
    _require_element(basis, ElementLineP1, "axial stiffness")
    return _slope_or_curvature(basis, _slope_product, rigidity)


def _slope_or_curvature(basis, form, rigidity):
    if not rigidity > 0:
        raise FemromValueError(f"rigidity must be positive, got {rigidity}")
    return form.assemble(basis, rigidity=float(rigidity)).tocsr()


def line_mass(basis: Basis, mass_per_length: float, *, lumped: bool = False) -> sp.csr_matrix:
    """(N, N) mass ``int rho A u v dx``; ``lumped`` gives the HRZ diagonal.

    HRZ lumping (Hinton, Rock & Zienkiewicz, Earthquake Eng. Struct. Dyn. 4, 1976):
    keep the consistent diagonal and scale it so that the translational dofs
    carry the total mass ``rho A L``; rotational dofs (Hermite ``w'``) are scaled
    by the same factor, which keeps the lumped matrix positive definite. For
    affine line elements the ratio per element is the same, so the global
    scaling equals the element-by-element one.
    """
    if not mass_per_length > 0:
        raise FemromValueError(f"mass per length must be positive, got {mass_per_length}")
    M = _value_product.assemble(basis, density=float(mass_per_length)).tocsr()
    if not lumped:
        return M
    return hrz_lumped(M, translational_dofs(basis))


def hrz_lumped(mass: sp.spmatrix, translational: np.ndarray) -> sp.csr_matrix:
    """Diagonal HRZ lumping of a consistent mass on the given translational dofs."""
    diagonal = mass.diagonal()
    rigid_translation = _indicator(mass.shape[0], translational)
    total = float(rigid_translation @ (mass @ rigid_translation))
    scale = total / diagonal[translational].sum()
    return sp.diags(diagonal * scale, format="csr")


def _indicator(n, dofs):
    e = np.zeros(n)
    e[dofs] = 1.0
    return e


def translational_dofs(basis: Basis) -> np.ndarray:
    """Dofs that carry a displacement value (Hermite: ``u``; P1: all)."""
    return np.asarray(basis.nodal_dofs[0])


def node_positions(basis: Basis) -> np.ndarray:
    """(n_nodes,) x coordinates of the mesh nodes, in ``basis.nodal_dofs`` order."""
    return basis.mesh.p[0]


def _require_element(basis, element_type, what):
    if not isinstance(basis.elem, element_type):
        raise FemromValueError(f"{what} needs {element_type.__name__}, got {type(basis.elem).__name__}")
