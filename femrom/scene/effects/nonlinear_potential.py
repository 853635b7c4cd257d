"""``nonlinear_potential``: an on-site potential ``int phi(u) dx`` on every node."""

import numpy as np

from femrom import fem
from femrom.scene._effects import Effect, register_effect
from femrom.scene._errors import SceneError

#: Scene names of the densities (``quartic`` is the hardening ``c u^4 / 4``).
KINDS = {"sine_gordon": "sine_gordon", "quartic": "quartic"}


@register_effect
class NonlinearPotential(Effect):
    r"""``f = w * phi'(q)`` with ``U = sum_i w_i phi(q_i)``, ``w`` the lumped nodal weights times ``coefficient``.

    Lines: every value dof, ``w_i = int phi_i dx``. Solids: the dofs of one
    ``component`` (required), ``w_i`` the lumped mass diagonal divided by the
    density (a nodal volume, positive for P1 and P2).
    ``kind``: ``sine_gordon`` (``phi = 1 - cos u``) or ``quartic`` (``phi = u^4 / 4``).
    """

    name = "nonlinear_potential"
    options = {"kind": "sine_gordon", "coefficient": 1.0, "component": None}
    choices = {"kind": tuple(KINDS)}
    provides = "nonlinear"
    stage = 4

    def assemble(self, build, options):
        space, condensation = build.space, build.condensation
        with build.timed("nonlinear"):
            if hasattr(space, "nodal_weights"):
                weights = space.nodal_weights()
            else:
                if options["component"] is None:
                    raise SceneError("[effects.nonlinear_potential] a solid needs 'component' (x, y or z)")
                dofs, _ = space.coordinates(options["component"])
                material = build.material
                if np.ndim(material.density):      # per element: the lumped mass of unit density
                    lumped = space.mass(material.with_unit_density(), lumped=True).diagonal()
                    density = 1.0
                else:
                    lumped = space.mass(material, lumped=True).diagonal()
                    density = material.density
                weights = 0.0 * lumped
                weights[dofs] = lumped[dofs] / density
            weights = options["coefficient"] * condensation.vector(weights)
            on = (np.abs(weights) > 1e-12 * np.abs(weights).max()).nonzero()[0]
            placement = {} if on.size == weights.size else {"dofs": on, "n_dofs": weights.size}
            kind = KINDS[options["kind"]]
            if kind == "sine_gordon":
                force = fem.LocalPotential.sine_gordon(weights[on], name=self.name, **placement)
            else:
                force = fem.LocalPotential.cubic(weights[on], 1.0, name=self.name, **placement)
            build.nonlinear_forces.append(force)
