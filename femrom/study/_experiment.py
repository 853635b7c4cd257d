r"""Experiments: what every model of a comparison is put through, one class in one file each.

An :class:`Experiment` holds its reference (a full-order run, a reference model's
ring-down, a stepped sine of the reference) and scores a model against it:
``experiment.run(model) -> dict`` of metrics (numbers, flags, notes; keys starting
with ``_`` hold arrays and objects that stay out of JSON). The models are the
reduced models a :class:`~femrom.study.ModelSpec` fits (second-order ROMs, the
Galerkin one included); metrics are plain functions of (reference, prediction)
(:func:`~femrom.post.relative_error`, :func:`~femrom.study.backbone_errors`, ...).

The built-in experiments are the modules of ``femrom.study.experiments``
(:func:`registered_experiments`); one registered elsewhere with
:func:`register_experiment` joins every comparison and every scene's ``[rom]``
study (``[[rom.experiments]] kind = "..."``) without an edit here. A scene's study
builds it with :meth:`Experiment.for_study` from the study's state (its runs,
their projections, the built model).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from femrom._errors import FemromValueError
from femrom._registry import Registry
from femrom.integrators import StepResult

#: The experiments by name.
EXPERIMENTS = Registry("experiment", "femrom.study.experiments", order=lambda name, cls: name, valid="registered")


def register_experiment(name: str):
    """Class decorator: the experiment is known by ``name`` (``[[rom.experiments]] kind = name``)."""
    return EXPERIMENTS.decorator(name)


def registered_experiments() -> dict:
    """The registered experiments by name (the built-in modules imported once)."""
    return EXPERIMENTS.items()


class Experiment:
    """Base of the experiments: ``run(model) -> dict`` of metrics against the experiment's reference.

    Attributes
    ----------
    label : str
        The experiment's name in tables (a row per model and experiment).
    """

    name: ClassVar[str] = ""
    label: str = ""

    def run(self, model) -> dict:  # pragma: no cover - interface
        """Metrics of ``model`` against the reference."""
        raise NotImplementedError

    @classmethod
    def for_study(cls, state, **options) -> list["Experiment"]:
        """The experiments a scene's ``[rom]`` study runs (``[[rom.experiments]] kind = name``, the
        table's other keys as ``options``), from the study's state (a :class:`~femrom.study.StudyState`:
        its runs, their projections, the built model). Default: refused, with the experiment named."""
        raise FemromValueError(f"experiment {cls.name!r} cannot be built from a scene's [rom] study; "
                               "construct it with its reference and run it on the models")


def starts_at_reference_rest(model) -> bool:
    """Whether ``model`` projects the reference itself (its learner reads the full operators): its
    stateful force is the reference's, on the reference's committed rest state."""
    learner = getattr(model, "learner", None)
    return learner is not None and "system" in getattr(type(learner), "needs", ())


def rest_start(model, rest_state):
    """The initial step of ``model`` at rest: the reference's committed force state for a projection
    of the reference (:func:`starts_at_reference_rest`), its own rest state (``None``) otherwise."""
    if rest_state is not None and starts_at_reference_rest(model):
        return StepResult.at_rest(model.r, state=rest_state)
    return None


def dense(A) -> np.ndarray:
    """``A`` (sparse or array) as a dense float array."""
    return A.toarray() if hasattr(A, "toarray") else np.asarray(A, dtype=float)


def finite(signal) -> bool:
    return bool(np.all(np.isfinite(signal)))
