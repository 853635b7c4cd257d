"""``bending``: Euler-Bernoulli bending of a line (Hermite elements)."""

from femrom.scene._effects import Effect, register_effect


@register_effect
class Bending(Effect):
    """``K q`` of Euler-Bernoulli bending, ``int E I w'' v'' dx`` (element ``hermite``)."""

    name = "bending"
    provides = "stiffness"
    stage = 1

    def assemble(self, build, options):
        with build.timed("stiffness"):
            build.stiffness = build.condensation.matrix(build.space.stiffness(self.name, build.scene.material))
