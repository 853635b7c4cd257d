"""``damping``: Rayleigh damping ``C = alpha M + beta K``."""

from femrom import fem
from femrom.scene._effects import Effect, register_effect
from femrom.scene._errors import SceneError


@register_effect
class Damping(Effect):
    """``C q'`` with ``C = alpha M + beta K`` (modal ratios ``alpha / (2 w) + beta w / 2``)."""

    name = "damping"
    options = {"kind": "rayleigh", "alpha": 0.0, "beta": 0.0}
    choices = {"kind": ("rayleigh",)}
    provides = "damping"
    stage = 2

    def assemble(self, build, options):
        mass, stiffness = build.require("mass", self.name), build.require("stiffness", self.name)
        with build.timed("damping"):
            try:
                build.damping = fem.rayleigh_damping(mass, stiffness, options["alpha"], options["beta"])
            except ValueError as exc:
                raise SceneError(f"[effects.damping] {exc}") from None
