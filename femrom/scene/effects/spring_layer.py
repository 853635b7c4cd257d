"""``spring_layer``: a Duffing (linear + cubic) spring layer on a named boundary."""

import numpy as np

from femrom import fem
from femrom.scene._conditions import LoadConfig
from femrom.scene._effects import Effect, register_effect
from femrom.scene._errors import SceneError


@register_effect
class SpringLayer(Effect):
    r"""An elastic foundation with a cubic term on one displacement component of a boundary.

    .. math::

        U = \int_\Gamma \Big(\frac{k_1}{2} u_c^2 + \frac{k_3}{4} u_c^4\Big)\, dA
          \approx \sum_{i \in \Gamma} w_i \Big(\frac{k_1}{2} q_i^2 + \frac{k_3}{4} q_i^4\Big),

    ``w_i = int_Gamma phi_i dA`` (row-sum lumping; on P2 triangles only the
    edge nodes carry weight, a valid quadrature). On a line, ``at`` is a
    boundary node and ``w = 1``: a discrete spring of stiffnesses ``k_1, k_3``.
    The force acts on the layer's own dofs only (implicit schemes run Newton
    on those alone).

    Options: ``at`` (boundary name), ``component``, ``linear`` ``k_1 >= 0``,
    ``cubic`` ``k_3`` (N/m^3 per unit area; per node on a line).
    """

    name = "spring_layer"
    options = {"at": None, "component": None, "linear": 0.0, "cubic": 0.0}
    provides = "nonlinear"
    stage = 4

    @classmethod
    def check(cls, options):
        super().check(options)
        if not isinstance(options["at"], str):
            raise SceneError("[effects.spring_layer] needs 'at', the name of a boundary")
        if not float(options["linear"]) >= 0:
            raise SceneError(f"[effects.spring_layer] linear must be >= 0, got {options['linear']}")
        if float(options["linear"]) == 0 and float(options["cubic"]) == 0:
            raise SceneError("[effects.spring_layer] linear = cubic = 0: remove the effect instead")

    def assemble(self, build, options):
        space, condensation = build.space, build.condensation
        with build.timed("nonlinear"):
            component = options["component"] or space.components[0]
            if component not in space.components:
                raise SceneError(f"[effects.spring_layer] unknown component {component!r}; "
                                 f"valid: {', '.join(space.components)}")
            if isinstance(space, fem.SolidSpace):   # the layer's face integrals
                direction = tuple(float(c == component) for c in space.components)
                load = LoadConfig("surface_traction", options["at"], direction=direction)
            else:                                   # a line: the boundary node's value dof
                load = LoadConfig("point_load", options["at"], component=component)
            weights = condensation.vector(space.load_vector(load))
            # quadrature weights of the face's dofs; what the assembly leaves elsewhere is round-off
            on = np.flatnonzero(np.abs(weights) > 1e-12 * np.abs(weights).max())
            if on.size == 0:
                raise SceneError(f"[effects.spring_layer] boundary {options['at']!r} has no free dof "
                                 f"in component {options['component']!r}")
            build.nonlinear_forces.append(fem.LocalPotential.of_density(
                "duffing", weights[on], dofs=on, n_dofs=weights.size, name=self.name,
                linear=float(options["linear"]), cubic=float(options["cubic"])))
