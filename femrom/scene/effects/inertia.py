"""``inertia``: the mass matrix ``M`` (consistent or lumped)."""

from femrom.scene._effects import Effect, register_effect


@register_effect
class Inertia(Effect):
    """``M q''`` with the consistent mass or its lumped diagonal (HRZ on beams, row sums on solids)."""

    name = "inertia"
    options = {"mass": "consistent"}
    choices = {"mass": ("consistent", "lumped")}
    provides = "mass"
    stage = 0

    def assemble(self, build, options):
        with build.timed("mass"):
            build.mass = build.condensation.matrix(
                build.space.mass(build.material, lumped=options["mass"] == "lumped"))
