"""``y = E^ q``: the output map."""

import numpy as np

from femrom._errors import FemromTypeError
from femrom.inference._terms import LinearTerm, register_term


@register_term
class Output(LinearTerm):
    r"""``y = E^ q^`` (p, r): ``E V`` intrusively, else ``min_E ||Y - E Q^||_F^2 + lambda ||E||_F^2``."""

    name = "output"
    effect = "outputs"
    structure = "free"
    learnable = True
    role = "output"
    variable = "q"
    order = 90

    @classmethod
    def galerkin(cls, system, basis):
        if system.output_matrix is None:
            return None
        return cls(np.asarray(system.output_matrix @ basis))

    @classmethod
    def fit(cls, data, regularization: float = 0.0) -> "Output | None":
        """Least squares on the recorded outputs (``None`` without them); relative Tikhonov weight."""
        if data.outputs is None:
            return None
        Q = data.states
        G = Q @ Q.T
        lam = regularization * np.trace(G) / max(Q.shape[0], 1)
        return cls(np.linalg.lstsq(G + lam * np.eye(Q.shape[0]), Q @ data.outputs.T, rcond=None)[0].T)

    def outputs(self, q):
        """(p,) or (p, k) ``E^ q``."""
        return self.matrix @ q

    def potential(self, q):
        return 0.0

    def lhs(self, q, v=None, a=None, u=None, state=None):
        raise FemromTypeError("the output map is not a term of the balance")
