"""The learner protocol, the registry of learners and relative regularisation weights.

A learner is an estimator: ``learner.fit(data, *, validation=None) -> learner`` leaves the fitted
operators in ``learner.operators_`` (a :class:`ReducedOperators` for
second-order models, a :class:`HamiltonianOperators` for canonical ones, a
:class:`StateSpaceOperators` for identified first-order models: DMDc, ERA,
OKID) and ``learner.describe()`` says what was fitted how. A ROM of
:mod:`femrom.rom` takes a learner of its kind (``SecondOrderROM(learner=...)``,
``StateSpaceROM(learner=...)``, ``.fit(data)``) and adds ``predict``,
``stepper`` and ``save``/``load``.

Learners are registered by short name (:func:`register_learner`): the
built-in ones are the modules of the package ``femrom.inference.learners``
(found by :func:`registered_learners`), so scene files and studies can name them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from femrom._errors import FemromValueError
from femrom._registry import Registry

#: The learners by short name (sorted).
LEARNERS = Registry("learner", "femrom.inference.learners", order=lambda name, cls: name, valid="registered")


def refuse_validation(learner, validation) -> None:
    """One clear error when a learner that has nothing to judge on validation data is given some."""
    if validation is not None:
        raise FemromValueError(f"{type(learner).__name__} does not use validation data: give validation=None")


class Learner:
    """Base of femrom's learners: ``fit(data, *, validation=None) -> self``, ``operators_``, ``describe()``.

    Class attributes
    ----------------
    method : str
        What the learner is called in metadata and reports.
    model : str
        The kind of model it fits: ``"second_order"``, ``"canonical"`` or ``"state_space"``.
    needs : tuple of str
        What it reads of a study's training set (:meth:`for_training`).
    """

    method: ClassVar[str] = ""
    model: ClassVar[str] = "second_order"
    #: What it reads of a study's :class:`~femrom.inference.TrainingSet` (``"reduced_data"``,
    #: ``"system"``: the full operators, intrusive; ``"markov"``).
    needs: ClassVar[tuple[str, ...]] = ("reduced_data",)
    operators_: Any

    @classmethod
    def for_training(cls, training, r: int, **options) -> tuple["Learner", Any, Any]:
        """``(learner, data, validation)``: an unfitted learner for size ``r`` of ``training`` (a
        :class:`~femrom.inference.TrainingSet`) and the data it fits and judges itself on.

        How a study builds every model: one call for every registered learner. The default is
        ``cls(**options)`` on the first ``r`` coordinates of the reduced runs; learners that
        read more (the system's effects, Markov parameters) override it.
        """
        return cls(**options), training.reduced(r), training.reduced(r, validation=True)

    def fit(self, data, *, validation=None) -> "Learner":  # pragma: no cover - interface
        """Fit on ``data``; ``validation`` (data of the same kind) is what the learner judges itself on:
        a learner that chooses (when to stop, which fit) chooses on it, a regression reports its
        residual there (``validation_residual_``), and a learner with nothing to judge refuses it."""
        raise NotImplementedError

    def describe(self) -> dict:
        """What was fitted how (stored with a saved ROM)."""
        return {"method": self.method}

    @property
    def is_fitted(self) -> bool:
        return getattr(self, "operators_", None) is not None


def register_learner(name: str):
    """Class decorator: the learner is known by ``name`` (``learner_class(name)``)."""

    return LEARNERS.decorator(name)


def registered_learners() -> dict[str, type[Learner]]:
    """The registered learners by name (the built-in modules are imported once)."""
    return LEARNERS.items()


def learner_class(name: str) -> type[Learner]:
    """The learner registered as ``name``, or a clear error listing the registered ones."""
    return LEARNERS.get(name)


class Regularization(Mapping):
    """Relative Tikhonov weights by term name (``stiffness``, ``damping``, ``input``, ``output``, ...).

    A weight ``rho_j`` becomes ``lambda_j = rho_j * trace(D_j D_j^T) / size_j``
    (the mean eigenvalue of the term's data-block Gram matrix), so a value
    means the same for every data set and unit system.

    Parameters
    ----------
    default : float
        The weight of every term not named.
    **weights : float
        Per term.
    """

    def __init__(self, default: float = 0.0, **weights: float):
        values = {"default": default, **weights}
        for name, value in values.items():
            if not float(value) >= 0:
                raise FemromValueError(f"regularization {name} must be >= 0, got {value}")
        self.default = float(default)
        self._weights = {k: float(v) for k, v in weights.items()}

    @classmethod
    def uniform(cls, value: float) -> "Regularization":
        """The same weight for every term."""
        return cls(default=value)

    @classmethod
    def of(cls, value) -> "Regularization":
        """A Regularization from a float (uniform), a mapping by term name, or itself."""
        if isinstance(value, Regularization):
            return value
        if isinstance(value, Mapping):
            return cls(**{str(k): float(v) for k, v in value.items()})
        return cls.uniform(float(value))

    def __getitem__(self, name: str) -> float:
        return self._weights.get(name, self.default)

    def __iter__(self):
        return iter(self._weights)

    def __len__(self) -> int:
        return len(self._weights)

    def to_dict(self) -> dict:
        return {"default": self.default, **self._weights}

    def __repr__(self) -> str:
        return f"Regularization({', '.join(f'{k}={v:g}' for k, v in self.to_dict().items())})"
