"""``elasticity``: linear elasticity of a solid, or the axial/string operator of a line."""

from femrom.scene._effects import Effect, register_effect


@register_effect
class Elasticity(Effect):
    """``K q`` of linear elasticity (solids: ``E``, ``nu``; lines: ``E A``, element ``p1``)."""

    name = "elasticity"
    provides = "stiffness"
    stage = 1

    def assemble(self, build, options):
        with build.timed("stiffness"):
            build.add_stiffness(build.condensation.matrix(build.space.stiffness(self.name, build.material)))
