"""The one exception type of :mod:`femrom.mesh`."""


from femrom._errors import FemromValueError


class MeshError(FemromValueError):
    """A geometry, its parameters or a mesh file cannot be used.

    The message names the offending file, parameter, boundary or subdomain and,
    where there is a choice, lists the valid ones.
    """
