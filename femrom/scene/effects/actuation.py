"""``actuation``: the input columns ``B`` and signals ``u(t)`` of the scene's ``[[inputs]]``."""

import numpy as np

from femrom.scene._effects import Effect, register_effect
from femrom.scene._signals import SignalVector


@register_effect
class Actuation(Effect):
    """``B u(t)``: one column per ``[[inputs]]`` entry, the sum of its load patterns."""

    name = "actuation"
    provides = "inputs"
    stage = 3

    def assemble(self, build, options):
        space, condensation = build.space, build.condensation
        with build.timed("inputs"):
            columns = [condensation.vector(sum(space.load_vector(load) for load in i.loads))
                       for i in build.scene.inputs]
            build.input_matrix = np.column_stack(columns)
            build.inputs = SignalVector(i.signal for i in build.scene.inputs)
