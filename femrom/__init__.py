"""femrom: structure-preserving reduced-order models of large mechanical structures.

Layers import downward only::

    solvers -> mesh -> fem -> scene -> integrators -> snapshots -> linalg -> basis
         -> inference -> rom -> control -> post -> study      (cli and cases on top)
"""

from importlib.metadata import PackageNotFoundError, version

from femrom._errors import FemromError, FemromRuntimeError, FemromTypeError, FemromValueError

try:
    __version__ = version("femrom")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = ["FemromError", "FemromRuntimeError", "FemromTypeError", "FemromValueError", "__version__"]
