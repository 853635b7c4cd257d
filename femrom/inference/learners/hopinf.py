"""Hamiltonian operator inference (canonical Hamiltonian ROMs)."""

from __future__ import annotations

import numpy as np

from femrom._errors import FemromTypeError, FemromValueError
from femrom.inference._hamiltonian import (
    CanonicalData,
    canonical_from_second_order,
    HamiltonianErrorSplit,
    HamiltonianOperators,
    ProjectedPotential,
    reduce_canonical_snapshots,
    symmetric_lyapunov_fit,
)
from femrom.inference._learner import Learner, register_learner


@register_learner("hopinf")
class HamiltonianOpInf(Learner):
    r"""Learn ``D^_q``, ``D^_p`` (symmetric) from reduced canonical data.

    Minimises ``||Q^' - F^_q - D^_p P^||_F`` and ``||-P^' - F^_p - D^_q Q^||_F``
    over symmetric matrices by their Lyapunov optimality conditions
    (:mod:`femrom.inference._hamiltonian`; Sharma, Wang & Kramer, Physica D
    431, 2022).

    Parameters
    ----------
    regularization : float
        Relative Tikhonov weight: ``lambda = rho * trace(X X^T) / r``.
    shared : bool
        Fit one symmetric ``D^ = D^_q = D^_p`` to both residuals.
    outputs_of : {"state", "position"}
        What the output map ``E^`` acts on: ``[q^; p^]`` (2r columns), or ``q^`` alone
        (``E^ = [E^_q, 0]``) for outputs known to be displacements, ``y = E q``: the
        momentum columns would otherwise fit the training outputs' projection residual.

    Attributes
    ----------
    operators_ : HamiltonianOperators
    output_matrix_ : (m, 2r) ndarray or None
        ``E^`` by least squares when the data carry outputs.
    residual_ : float
        Relative residual of both regressions together (``error_split_.optimization``).
    error_split_ : HamiltonianErrorSplit
        Projection, derivative and optimisation errors (the first two from
        the data's diagnostics, when they came from full snapshots).
    """

    method = "hamiltonian_opinf"
    model = "canonical"

    OUTPUTS_OF = ("state", "position")

    def __init__(self, regularization: float = 0.0, shared: bool = False, outputs_of: str = "state"):
        if not regularization >= 0:
            raise FemromValueError(f"regularization must be >= 0, got {regularization}")
        if outputs_of not in self.OUTPUTS_OF:
            raise FemromValueError(f"outputs_of must be one of {self.OUTPUTS_OF}, got {outputs_of!r}")
        self.regularization = float(regularization)
        self.shared = bool(shared)
        self.outputs_of = outputs_of

    @staticmethod
    def _relative_residual(data, Dq, Dp) -> float:
        Rp = data.ddt_q - (0.0 if data.forces_q is None else data.forces_q)
        Rq = -data.ddt_p - (0.0 if data.forces_p is None else data.forces_p)
        num = np.linalg.norm(Rp - Dp @ data.states_p) ** 2 + np.linalg.norm(Rq - Dq @ data.states_q) ** 2
        den = np.linalg.norm(Rp) ** 2 + np.linalg.norm(Rq) ** 2
        return float(np.sqrt(num / den)) if den > 0 else 0.0

    @classmethod
    def for_training(cls, training, r: int, **options):
        """H-OpInf on a study's second-order runs seen canonically (``p^ = q^'`` on a mass-orthonormal
        basis, :func:`~femrom.inference.canonical_from_second_order`); outputs of the positions
        unless ``outputs_of`` says otherwise."""
        options.setdefault("outputs_of", "position")
        return cls(**options), canonical_from_second_order(training.reduced(r)), None

    def fit(self, data: CanonicalData, *, validation=None) -> "HamiltonianOpInf":
        """Fit from reduced data ``Q^, P^, Q^', P^'`` and the known ``F^_q, F^_p``; ``validation``
        (CanonicalData): the fitted operators' relative residual there is ``validation_residual_``."""
        if not isinstance(data, CanonicalData):
            raise FemromTypeError(f"HamiltonianOpInf.fit takes CanonicalData, got {type(data).__name__}")
        states_q, states_p = np.asarray(data.states_q, float), np.asarray(data.states_p, float)
        Rp = data.ddt_q - (0.0 if data.forces_q is None else data.forces_q)
        Rq = -data.ddt_p - (0.0 if data.forces_p is None else data.forces_p)
        lam_p = self.regularization * np.sum(states_p**2) / states_p.shape[0]
        lam_q = self.regularization * np.sum(states_q**2) / states_q.shape[0]
        if self.shared:
            Dp = Dq = symmetric_lyapunov_fit(np.hstack([states_p, states_q]), np.hstack([Rp, Rq]),
                                             lam_p + lam_q)
        else:
            Dp = symmetric_lyapunov_fit(states_p, Rp, lam_p)
            Dq = symmetric_lyapunov_fit(states_q, Rq, lam_q)
        self.operators_ = HamiltonianOperators(position=Dq, momentum=Dp)
        # from the data columns, not from the Gram matrices (cancellation below sqrt(eps))
        num = np.linalg.norm(Rp - Dp @ states_p) ** 2 + np.linalg.norm(Rq - Dq @ states_q) ** 2
        den = np.linalg.norm(Rp) ** 2 + np.linalg.norm(Rq) ** 2
        self.residual_ = float(np.sqrt(num / den)) if den > 0 else 0.0
        diag = data.diagnostics
        self.error_split_ = HamiltonianErrorSplit(
            projection=diag.get("projection_error"), derivative=diag.get("derivative_error"),
            position_derivative=diag.get("position_derivative_error"),
            momentum_derivative=diag.get("momentum_derivative_error"), optimization=self.residual_)
        self.validation_residual_ = None
        if validation is not None:
            if not isinstance(validation, CanonicalData):
                raise FemromTypeError(f"validation must be CanonicalData, got {type(validation).__name__}")
            self.validation_residual_ = self._relative_residual(validation, Dq, Dp)
        self.output_matrix_ = None
        if data.outputs is not None:
            X = states_q if self.outputs_of == "position" else np.vstack([states_q, states_p])
            E = np.linalg.lstsq(X.T, data.outputs.T, rcond=None)[0].T
            self.output_matrix_ = np.hstack([E, np.zeros_like(E)]) if self.outputs_of == "position" else E
        self.data_ = {"forces": data.forces_q is not None or data.forces_p is not None,
                      "n_samples": int(data.n_samples),
                      **{k: diag[k] for k in ("derivative_source", "gradient_data", "order", "dt") if k in diag}}
        return self

    def fit_snapshots(self, basis: np.ndarray, Q: np.ndarray, P: np.ndarray, dt: float | None = None,
                      *, potential=None, **options) -> "HamiltonianOpInf":
        r"""Project full snapshots (:func:`reduce_canonical_snapshots`) and fit.

        Attributes set besides :meth:`fit`'s: ``basis_`` (n, r) and
        ``potential_`` (a :class:`ProjectedPotential` or ``None``).
        """
        self.fit(reduce_canonical_snapshots(basis, Q, P, dt, potential=potential, **options))
        self.basis_ = np.asarray(basis, dtype=float)
        self.potential_ = None if potential is None else ProjectedPotential(potential, self.basis_)
        return self

    def describe(self) -> dict:
        """What was fitted how (stored with a saved :class:`~femrom.rom.HamiltonianROM`)."""
        out = {"method": self.method, "regularization": self.regularization,
               "shared": self.shared, "outputs_of": self.outputs_of}
        if hasattr(self, "error_split_"):
            out["residual"] = self.residual_
            out["error_split"] = {k: getattr(self.error_split_, k)
                                  for k in self.error_split_.__dataclass_fields__}
            out["data"] = dict(self.data_)
        return out
