r"""What a study hands every learner: one training set, read at any size ``r``.

A :class:`TrainingSet` holds the training runs reduced once in the largest basis
``V`` (n, R) (a :class:`SecondOrderData` per run), the validation runs alike, the
full model and, where a study has them, Markov parameters. A learner class
builds itself from it at size ``r <= R`` (:meth:`Learner.for_training`) and says
which parts it reads (:attr:`Learner.needs`):

- ``"reduced_data"``: the runs' first ``r`` coordinates ``q^, q^', q^''`` with
  their inputs and outputs (:meth:`TrainingSet.reduced`), what operator
  inference and SpML fit on; the data seen as a discrete input-output record
  (:meth:`TrainingSet.input_output`), what DMDc and OKID fit on;
- ``"system"``: the full-order operators, read by the intrusive Galerkin
  projection only (every other learner reads which effects the system has,
  never their values);
- ``"markov"``: Markov parameters (ERA).

So a study builds every model the same way, ``learner_class(name).for_training(
training, r, **options)``, and a learner registered anywhere joins every study.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference._data import SecondOrderData, concatenate
from femrom.inference._io_data import InputOutputData

#: What a learner may read from a :class:`TrainingSet`.
NEEDS = ("reduced_data", "system", "markov")


@dataclass(frozen=True, eq=False)
class TrainingSet:
    """The training (and validation) runs of a study, reduced in the largest basis.

    Parameters
    ----------
    system : SecondOrderSystem
        The full model the runs come from (``M q'' + C q' + K q + f = B u``).
    basis : (n, R) ndarray
        The nested basis ``V``; size ``r`` uses its first ``r`` columns.
    runs : mapping of name -> SecondOrderData
        Each training run's reduced data in all ``R`` coordinates.
    product : (n, n) matrix, optional
        The basis' inner product (the mass: ``V^T M V = I``), or ``None`` (Euclidean).
    validation : mapping of name -> SecondOrderData, optional
        Runs a learner that chooses (when to stop, which fit) judges itself on.
    markov : MarkovParameters or (N, p, m) ndarray, optional
        The full model's Markov parameters (for ERA).
    derivatives : optional
        The study's default derivative data (``kind``: ``"stored"``, ``"integrator"``
        or ``"finite_differences"``, with ``order``); ``None``: as reduced.
    """

    system: object
    basis: np.ndarray
    runs: Mapping[str, SecondOrderData]
    product: object = None
    validation: Mapping[str, SecondOrderData] | None = None
    markov: object = None
    derivatives: object = None

    def __post_init__(self):
        if np.ndim(self.basis) != 2:
            raise FemromValueError(f"TrainingSet: basis must be (n, R), got shape {np.shape(self.basis)}")
        if not self.runs:
            raise FemromValueError("TrainingSet: no training runs")

    @property
    def max_rank(self) -> int:
        return int(self.basis.shape[1])

    @property
    def mass_orthonormal(self) -> bool:
        """Whether the basis is orthonormal in the system's own mass (``V^T M V = I``)."""
        return self.product is not None and self.product is getattr(self.system, "mass", None)

    def basis_at(self, r: int) -> np.ndarray:
        """(n, r) the first ``r`` basis columns."""
        if int(r) != r or not 1 <= r <= self.max_rank:
            raise FemromValueError(f"TrainingSet: r must be an integer in [1, {self.max_rank}], got {r}")
        return self.basis[:, :int(r)]

    def reduced(self, r: int, derivatives=None, *, validation: bool = False) -> SecondOrderData | None:
        """The runs' first ``r`` coordinates with ``derivatives`` (default: the set's), concatenated
        (``validation``: the validation runs', ``None`` without any)."""
        self.basis_at(r)
        runs = self.validation if validation else self.runs
        if not runs:
            return None
        derivatives = self.derivatives if derivatives is None else derivatives
        return concatenate([_with_derivatives(d.truncated(r), derivatives) for d in runs.values()])

    def input_output(self, r: int, states: str = "phase", *, validation: bool = False) -> InputOutputData | None:
        """The runs' first ``r`` coordinates as one input-output record (``states``: ``"phase"``
        ``[q^; q^']``, ``"none"``: inputs and outputs only)."""
        self.basis_at(r)
        runs = self.validation if validation else self.runs
        if not runs:
            return None
        return InputOutputData.stack([InputOutputData.from_second_order(d.truncated(r), states=states)
                                      for d in runs.values()])

    def require_markov(self, who: str):
        """The Markov parameters, or one error naming the learner that needs them."""
        if self.markov is None:
            raise FemromValueError(f"{who} fits Markov parameters: the study gives none (TrainingSet.markov)")
        return self.markov


def _with_derivatives(d: SecondOrderData, derivatives) -> SecondOrderData:
    """``d`` with the derivative data ``derivatives`` asks for (``None``: as it is)."""
    if derivatives is None or derivatives.kind == "stored":
        return d
    if derivatives.kind == "integrator":
        return d.integrator_consistent()
    if derivatives.kind == "finite_differences" and (
            d.diagnostics.get("derivative_source") != "finite_difference"
            or d.diagnostics.get("order") != derivatives.order):
        return d.with_finite_differences(derivatives.order)
    return d
