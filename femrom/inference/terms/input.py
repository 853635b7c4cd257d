"""``- B^ u``: the inputs."""

import numpy as np

from femrom.inference._terms import LinearTerm, register_term
from femrom.inference.terms._projection import dense


@register_term
class Input(LinearTerm):
    r"""``- B^ u`` (``B^`` (r, m) unconstrained, ``V^T B``); data block ``-U``."""

    name = "input"
    effect = "inputs"
    structure = "free"
    learnable = True
    variable = "u"
    sign = -1.0
    order = 40

    @classmethod
    def galerkin(cls, system, basis):
        if system.input_matrix is None:
            return None
        return cls(np.asarray(basis.T @ dense(system.input_matrix)))
