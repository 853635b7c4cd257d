"""Function spaces of the structures femrom knows: what a scene needs of a basis.

A space answers, in its own dof numbering (``n_total`` dofs before Dirichlet
condensation): its operators, the dofs on a named boundary, the load vector of
a named or located load, the output row of a probe, and the nodal coordinates
of a displacement component. The scene layer maps a scene file onto these
calls and never touches skfem directly.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from skfem import Basis, LinearForm

from femrom._errors import FemromValueError
from femrom.fem import _constraints, _elasticity, _line, _loads, _outputs
from femrom.mesh import boundary_facets, subdomain_elements


class SpaceError(FemromValueError):
    """A request a space cannot serve (unknown component, unsupported load)."""


@LinearForm
def _unit_integral(v, w):
    return v


class LineSpace:
    """Beam (Hermite: components ``w`` and ``slope``) or bar/string (P1: ``u``) on a line."""

    def __init__(self, mesh, element: str):
        self.mesh = mesh
        self.element = element
        self.basis = _line.line_basis(mesh, element)
        self.components = ("w", "slope") if element == "hermite" else ("u",)

    # -- sizes -----------------------------------------------------------
    @property
    def n_total(self) -> int:
        return self.basis.N

    @property
    def length(self) -> float:
        return float(self.mesh.p[0].max() - self.mesh.p[0].min())

    # -- operators -------------------------------------------------------
    def stiffness(self, effect: str, material) -> sp.csr_matrix:
        if effect == "bending":
            if self.element != "hermite":
                raise SpaceError("the 'bending' effect needs element = 'hermite' on a line")
            _need(material, "second_moment", "bending")
            return _line.bending_stiffness(self.basis, material.youngs_modulus * material.second_moment)
        if effect == "elasticity":
            if self.element != "p1":
                raise SpaceError("'elasticity' on a line is the axial/string operator: use element = 'p1' "
                                 "(or the 'bending' effect with 'hermite')")
            _need(material, "area", "elasticity")
            return _line.axial_stiffness(self.basis, material.youngs_modulus * material.area)
        raise SpaceError(f"a line space has no stiffness effect {effect!r}")

    def mass(self, material, *, lumped: bool) -> sp.csr_matrix:
        _need(material, "area", "inertia")
        return _line.line_mass(self.basis, material.density * material.area, lumped=lumped)

    def nodal_weights(self) -> np.ndarray:
        """(n_total,) ``int phi_i dx`` on value dofs (zero on slopes): lumped quadrature."""
        weights = np.zeros(self.n_total)
        values = _line.translational_dofs(self.basis)
        weights[values] = np.asarray(_unit_integral.assemble(self.basis))[values]
        return weights

    # -- boundaries ------------------------------------------------------
    def boundary_dofs(self, name: str, *, clamped: bool) -> np.ndarray:
        facets = boundary_facets(self.mesh, name)
        dofs = self.basis.get_dofs(facets)
        return dofs.all() if clamped or self.element == "p1" else dofs.all(["u"])

    # -- loads and outputs -------------------------------------------------
    def _row(self, at, component) -> sp.csr_matrix:
        """(1, n_total) functional: value (or slope) of the field at ``at``."""
        component = self._component(component)
        if isinstance(at, str):
            facets = boundary_facets(self.mesh, at)
            nodal = self.basis.get_dofs(facets).nodal
            key = "u_x" if component == "slope" else "u"
            dofs = np.asarray(nodal[key])
            if dofs.size != 1:
                raise SpaceError(f"boundary {at!r} has {dofs.size} nodes; a line load or probe needs one")
            return sp.csr_matrix((np.ones(1), (np.zeros(1, int), dofs)), shape=(1, self.n_total))
        x = float(at[0])
        lo, hi = self.mesh.p[0].min(), self.mesh.p[0].max()
        if not lo <= x <= hi:
            raise SpaceError(f"point x = {x} lies outside the beam [{lo}, {hi}]")
        if component == "slope":
            raise SpaceError("a slope probe or moment load must sit on a named boundary node")
        return sp.csr_matrix(self.basis.probes(np.array([[x]])))

    def load_vector(self, load) -> np.ndarray:
        """(n_total,) consistent load of a point force (``w``/``u``) or moment (``slope``)."""
        if load.kind != "point_load":
            raise SpaceError(f"a line structure takes point loads only, not {load.kind!r}")
        return load.magnitude * np.asarray(self._row(load.at, load.component).todense()).ravel()

    def output_row(self, probe) -> sp.csr_matrix:
        if getattr(probe, "nodes", 0):
            raise SpaceError("nearest-node outputs are for solids; a line probe reads the field at its point")
        if probe.average:
            if not isinstance(probe.at, str):
                raise SpaceError("an average output needs a subdomain name in 'over'")
            self._component(probe.component)
            elements = subdomain_elements(self.mesh, probe.at)
            basis = Basis(self.mesh, self.basis.elem, elements=elements,
                          intorder=_line.LINE_ELEMENTS[self.element][1])
            row = np.asarray(_unit_integral.assemble(basis))
            values = np.zeros_like(row)
            idx = _line.translational_dofs(self.basis)
            values[idx] = row[idx]
            return sp.csr_matrix(values / values.sum())
        return self._row(probe.at, probe.component)

    def coordinates(self, component=None) -> tuple[np.ndarray, np.ndarray]:
        """Dofs of ``component`` and their (1, k) coordinates."""
        component = self._component(component)
        key = 1 if component == "slope" else 0
        dofs = np.asarray(self.basis.nodal_dofs[key])
        return dofs, self.mesh.p[:, :]

    def interpolate(self, function, component=None) -> np.ndarray:
        """(n_total,) nodal interpolant of ``function(x, y, z)`` (Hermite: values and slopes)."""
        q = np.zeros(self.n_total)
        x = self.mesh.p[0]
        zeros = np.zeros_like(x)
        q[self.basis.nodal_dofs[0]] = function(x, zeros, zeros)
        if self.element == "hermite":
            h = 1e-6 * max(self.length, 1e-300)
            q[self.basis.nodal_dofs[1]] = (function(x + h, zeros, zeros) - function(x - h, zeros, zeros)) / (2 * h)
        return q

    def _component(self, component):
        component = component or self.components[0]
        if component not in self.components:
            raise SpaceError(f"unknown component {component!r}; valid: {', '.join(self.components)}")
        return component


class SolidSpace:
    """Displacement field on tetrahedra (P1 or P2); components ``x``, ``y``, ``z``."""

    components = ("x", "y", "z")

    def __init__(self, mesh, element: str):
        from skfem import ElementTetP1, ElementTetP2, ElementVector

        scalar = {"p1": ElementTetP1, "p2": ElementTetP2}.get(element)
        if scalar is None:
            raise SpaceError(f"unknown solid element {element!r}; valid: p1, p2")
        self.mesh = mesh
        self.element = element
        # The fast assembly, loads and probes use only the mesh, element and dof
        # numbering of this basis (they build their own facet/cell bases), so the
        # lowest quadrature keeps its precomputed values small: skfem's default
        # order would hold ~4 GB of basis values for vector P2 at 5e5 dofs.
        self.basis = Basis(mesh, ElementVector(scalar()), intorder=1)
        self._node_tree = None

    @property
    def n_total(self) -> int:
        return self.basis.N

    def stiffness(self, effect: str, material) -> sp.csr_matrix:
        """Elasticity stiffness of ``material``: one material (floats ``youngs_modulus``,
        ``poisson_ratio``) or an :class:`~femrom.fem.ElementMaterial` (one value per element)."""
        if effect != "elasticity":
            raise SpaceError(f"a solid takes the 'elasticity' effect, not {effect!r}")
        _need(material, "poisson_ratio", "elasticity")
        return _elasticity.elasticity_stiffness(self.basis, material.youngs_modulus, material.poisson_ratio)

    def mass(self, material, *, lumped: bool) -> sp.csr_matrix:
        """Mass of ``material.density`` (a float, or one value per element)."""
        return _elasticity.vector_mass(self.basis, material.density, lumped=lumped)

    def boundary_dofs(self, name: str, *, clamped: bool) -> np.ndarray:
        boundary_facets(self.mesh, name)  # one clear error for an unknown name
        return _constraints.dirichlet_dofs(self.basis, name)

    def rigid_body_modes(self) -> np.ndarray:
        """(n_total, 6) translations and rotations: the near-nullspace for AMG."""
        return _constraints.rigid_body_modes(self.basis)

    def load_vector(self, load) -> np.ndarray:
        """(n_total,) load: point force, constant traction or normal pressure."""
        if load.kind == "surface_pressure":
            return _loads.surface_pressure(self.basis, _name(load.at, load.kind), load.magnitude)
        vector = self._direction(load) * load.magnitude
        if load.kind == "surface_traction":
            return _loads.surface_traction(self.basis, _name(load.at, load.kind), vector)
        if isinstance(load.at, str):
            raise SpaceError("a solid point_load needs a point [x, y, z] in 'at' (use surface_traction "
                             "for a load on a named boundary)")
        return _loads.point_load(self.basis, load.at, vector)

    def output_row(self, probe) -> sp.csr_matrix:
        """(1, n_total) row of a probe: the component at a point (interpolated, or averaged over
        the ``probe.nodes`` nearest nodes when that is >= 1), or its mean over a named region."""
        component = self.components.index(self._component(probe.component))
        nodes = getattr(probe, "nodes", 0)
        if nodes:
            if isinstance(probe.at, str):
                raise SpaceError(f"a nearest-node probe needs a point [x, y, z], got {probe.at!r}")
            if self._node_tree is None:     # built once, for the many points of a line of probes
                self._node_tree = _outputs.node_tree(self.basis)
            try:
                return _outputs.nearest_node_rows(self.basis, [probe.at], component, nodes, tree=self._node_tree)
            except ValueError as exc:       # a point outside the mesh, too many nodes
                raise SpaceError(str(exc)) from None
        if probe.average:
            return _outputs.average_rows(self.basis, _name(probe.at, "average"), component)
        if isinstance(probe.at, str):
            raise SpaceError(f"a solid probe needs a point [x, y, z]; to average over {probe.at!r} "
                             "list it under outputs.averages")
        return _outputs.probe_rows(self.basis, [probe.at], component)

    def coordinates(self, component=None) -> tuple[np.ndarray, np.ndarray]:
        """Dofs of ``component`` and their (3, k) locations (vertices, P2 edge midpoints)."""
        c = self.components.index(self._component(component))
        dofs = np.flatnonzero(np.arange(self.n_total) % 3 == c)
        return dofs, self.basis.doflocs[:, dofs]

    def interpolate(self, function, component=None) -> np.ndarray:
        """(n_total,) Lagrange interpolant of ``function(x, y, z)`` in one component."""
        dofs, x = self.coordinates(component)
        q = np.zeros(self.n_total)
        q[dofs] = function(*x)
        return q

    def _direction(self, load) -> np.ndarray:
        if load.direction is not None:
            direction = np.asarray(load.direction, dtype=float)
            if direction.shape != (3,):
                raise SpaceError(f"a solid load direction needs 3 components, got {load.direction}")
            return direction
        direction = np.zeros(3)
        direction[self.components.index(self._component(load.component))] = 1.0
        return direction

    def _component(self, component):
        component = component or "x"
        if component not in self.components:
            raise SpaceError(f"unknown component {component!r}; valid: {', '.join(self.components)}")
        return component


def _name(at, what):
    if not isinstance(at, str):
        raise SpaceError(f"a {what} needs a boundary name, got {at}")
    return at


def _need(material, key, effect):
    if getattr(material, key) is None:
        raise SpaceError(f"the {effect!r} effect needs [material] {key}")


__all__ = ["LineSpace", "SolidSpace", "SpaceError"]
