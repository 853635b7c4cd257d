"""An effect written outside femrom, as a user would: gravity as a constant load.

One class: the registry makes ``gravity`` a key a scene may list under
``[effects]`` (with its options checked), and the builder assembles it only
for scenes that list it.
"""

import numpy as np

from femrom.scene import Effect, register_effect


@register_effect
class Gravity(Effect):
    r"""``f_0 = -g M e``: the consistent weight of the structure along ``component``.

    ``e`` is the unit displacement field in that component (value 1, zero slopes),
    so ``M e`` integrates the density against every shape function.
    """

    name = "gravity"
    options = {"g": 9.81, "component": None}
    provides = "load"
    stage = 3

    def assemble(self, build, options):
        space = build.space
        unit = space.interpolate(lambda x, y, z: np.ones_like(x), options["component"])
        if space.element == "hermite":
            unit[space.basis.nodal_dofs[1]] = 0.0            # a uniform translation has no slope
        with build.timed("load"):
            mass = space.mass(build.material, lumped=False)
            build.load = -float(options["g"]) * build.condensation.vector(mass @ unit)
