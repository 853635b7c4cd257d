"""The intrusive Galerkin reference, under the learner protocol."""

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference._learner import Learner, refuse_validation, register_learner
from femrom.inference._operators import galerkin


@register_learner("galerkin")
class GalerkinProjection(Learner):
    r"""The intrusive Galerkin ROM as a learner: ``fit`` projects the system's operators.

    ``V^T M V``, ``V^T C V``, ``V^T K V``, ``V^T B``, ``E V``, ``V^T f(V q)``
    and every other registered term (:func:`femrom.inference.galerkin`). The
    data are not needed (``fit()`` or ``fit(data)``): it reads the full-order
    operators, which is what makes it the reference and not a learner.

    Parameters
    ----------
    system : SecondOrderSystem
    basis : (n, r) ndarray
    mass_orthonormal : bool
        Check ``V^T M V = I`` and keep the identity mass.
    """

    method = "galerkin"

    def __init__(self, system, basis: np.ndarray, *, mass_orthonormal: bool = False):
        self.system = getattr(system, "system", system)
        self.basis = np.asarray(basis, dtype=float)
        self.mass_orthonormal = bool(mass_orthonormal)

    needs = ("system",)

    @classmethod
    def for_training(cls, training, r: int, **options):
        """The projection on the first ``r`` basis columns of the training system (intrusive: it reads
        the full operators, no data); the identity mass when the basis is mass-orthonormal."""
        if options:
            raise FemromValueError(f"galerkin takes no options, got {', '.join(options)}")
        return cls(training.system, training.basis_at(r), mass_orthonormal=training.mass_orthonormal), None, None

    def fit(self, data=None, *, validation=None) -> "GalerkinProjection":
        refuse_validation(self, validation)
        self.operators_ = galerkin(self.system, self.basis, mass_orthonormal=self.mass_orthonormal)
        return self

    def describe(self) -> dict:
        return {"method": self.method, "mass_orthonormal": self.mass_orthonormal}
