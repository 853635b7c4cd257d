r"""The models of a comparison as specs, built only through the learner registry.

A :class:`ModelSpec` names a registered learner (``galerkin``, ``lopinf``, ``spml``,
``iwan_lopinf``, ``dmdc``, a learner registered by the user, ...), its options and a
label. :meth:`ModelSpec.fit` builds it at size ``r`` from a study's
:class:`~femrom.inference.TrainingSet` in one way for every learner:

1. ``learner_class(name).for_training(training, r, **options)`` gives the unfitted
   learner and the data (and validation data) it fits on: the class declares
   what it reads (:attr:`~femrom.inference.Learner.needs`);
2. the reduced model of the learner's kind wraps it (:func:`reduced_model`):
   a :class:`~femrom.rom.SecondOrderROM` on the basis (every second-order learner,
   the intrusive projection included), a :class:`~femrom.rom.StateSpaceROM`
   (identified models), a Hamiltonian ROM called like a second-order one
   (canonical learners);
3. ``rom.fit(data, validation=...)``, timed.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, replace

from femrom._errors import FemromValueError
from femrom.inference import ForcePotential, learner_class
from femrom.rom import HamiltonianROM, SecondOrderROM, StateSpaceROM
from femrom.study._canonical import SceneHamiltonianROM


@dataclass(frozen=True)
class ModelSpec:
    """One model of a comparison: a registered ``learner`` with keyword ``options``, under ``label``.

    Parameters
    ----------
    learner : str
        A name of :func:`~femrom.inference.registered_learners`.
    label : str, optional
        The row name in tables (default: the learner's name).
    options : mapping or tuple of (name, value) pairs
        Keyword options of the learner's ``for_training`` (its constructor's, and ``terms``,
        ``extra_terms``, ...).
    derivatives : optional
        The derivative data it fits on (a :class:`~femrom.scene.Derivatives`; default: the training set's).
    """

    learner: str
    label: str = ""
    options: tuple = ()
    derivatives: object = None

    def __post_init__(self):
        learner_class(self.learner)   # one error naming the unknown learner and listing the registered ones
        options = self.options
        if isinstance(options, Mapping):
            options = tuple(options.items())
        try:
            options = tuple((str(k), v) for k, v in options)
        except (TypeError, ValueError):
            raise FemromValueError(f"model {self.name!r}: options must be a mapping or (name, value) pairs, "
                                   f"got {self.options!r}") from None
        object.__setattr__(self, "options", options)
        if not self.label:
            object.__setattr__(self, "label", self.learner)

    @property
    def name(self) -> str:
        return self.label or self.learner

    @property
    def kind(self) -> str:
        """The kind of model the learner fits (``second_order``, ``state_space``, ``canonical``)."""
        return learner_class(self.learner).model

    @property
    def intrusive(self) -> bool:
        """Whether it reads the full-order operators (the Galerkin reference)."""
        return "system" in learner_class(self.learner).needs

    def fit(self, training, r: int):
        """The fitted reduced model at size ``r`` (module docstring), with ``fit_seconds_`` set."""
        if self.derivatives is not None:
            training = replace(training, derivatives=self.derivatives)
        tic = time.perf_counter()
        cls = learner_class(self.learner)
        learner, data, validation = cls.for_training(training, r, **dict(self.options))
        rom = reduced_model(learner, training, r)
        rom = rom.fit(data, validation=validation)
        if isinstance(rom, HamiltonianROM):
            rom = SceneHamiltonianROM(rom, training.product)
        rom.fit_seconds_ = time.perf_counter() - tic
        return rom


def reduced_model(learner, training, r: int):
    """The unfitted reduced model that carries ``learner`` (by its ``model`` kind) at size ``r``."""
    kind = learner.model
    if kind == "second_order":
        return SecondOrderROM(basis=training.basis_at(r), product=training.product, learner=learner)
    if kind == "state_space":
        return StateSpaceROM(learner=learner)
    if kind == "canonical":
        nonlinear = getattr(training.system, "nonlinear", None)
        rom = HamiltonianROM(basis=training.basis_at(r), learner=learner, scheme="midpoint",
                             potential=None if nonlinear is None else ForcePotential(nonlinear))
        rom.product = training.product          # reduce(x) = V^T M x
        return rom
    raise FemromValueError(f"learner {type(learner).__name__} fits {kind!r} models; a study compares "
                           "second_order, state_space and canonical ones")
