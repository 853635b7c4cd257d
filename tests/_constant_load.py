"""A reduced term written outside femrom, as a user would: a constant load ``- f^_0``.

This one class is all it takes: the registry makes it known to ``galerkin``
(which projects the system's ``load``), to the learners (by name, learned from
a data block of ones), to the reduced schemes (a constant forcing) and to
``save``/``load`` (one dataset).
"""

from femrom.inference import LinearTerm, register_term


@register_term
class ConstantLoad(LinearTerm):
    r"""``- f^_0``: a constant force (gravity, a preload), ``V^T f_0`` intrusively; data block ``-1``."""

    name = "constant_load"
    effect = "load"
    structure = "free"
    learnable = True
    variable = "1"
    sign = -1.0
    order = 50

    @classmethod
    def galerkin(cls, system, basis):
        return None if system.load is None else cls(basis.T @ system.load)
