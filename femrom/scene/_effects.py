"""Effects: what a scene may list under ``[effects]``, one registered class each.

An effect is one :class:`Effect` subclass in one module of
:mod:`femrom.scene.effects` (found there by :func:`registered_effects`), or anywhere else
once decorated with :func:`register_effect`. It declares its TOML options
with their defaults (and the choices of the enumerated ones), the part of
the system it provides, and :meth:`Effect.assemble`, which adds exactly that
part to an :class:`Assembly`. The builder runs the listed effects in order of
:attr:`Effect.stage` and nothing else, so an effect a scene does not list is
never assembled.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from femrom._errors import FemromValueError
from femrom._registry import Registry
from femrom.scene._errors import SceneError

#: What an effect provides to the system (``mass``: exactly one effect; ``stiffness``: at least one, their
#: contributions summed, :meth:`Assembly.add_stiffness`).
PROVIDES = ("mass", "stiffness", "damping", "inputs", "load", "nonlinear")

#: The effects by name, in assembly order (stage, then name).
EFFECTS = Registry("effect", "femrom.scene.effects", order=lambda name, cls: (cls.stage, name),
                   valid="valid effects")


class Effect:
    """One physical effect of a scene (a term of ``M q'' + C q' + K q + f_nl = B u + f_0``).

    Class attributes
    ----------------
    name : str
        The key under ``[effects]``.
    options : dict
        Option names and defaults (the only keys the scene may give).
    choices : dict
        For enumerated options, the valid values (checked when the scene is read).
    provides : str
        One of :data:`PROVIDES`.
    stage : int
        Assembly order: 0 mass, 1 stiffness, 2 what needs them (damping),
        3 forcing, 4 nonlinear forces.
    """

    name: ClassVar[str] = ""
    options: ClassVar[dict[str, Any]] = {}
    choices: ClassVar[dict[str, tuple]] = {}
    provides: ClassVar[str] = ""
    stage: ClassVar[int] = 0

    @classmethod
    def check(cls, options: dict) -> None:
        """Raise :class:`SceneError` for a bad option value (called when the scene is read)."""
        for key, valid in cls.choices.items():
            if options.get(key) not in valid:
                raise SceneError(f"[effects.{cls.name}] unknown {key} {options.get(key)!r}; "
                                 f"valid: {', '.join(map(str, valid))}")

    def assemble(self, build: "Assembly", options: dict) -> None:
        """Add this effect's part to ``build``."""
        raise NotImplementedError


def register_effect(cls: type[Effect]) -> type[Effect]:
    """Class decorator: a scene may list ``cls.name`` under ``[effects]``."""
    if not cls.name:
        raise FemromValueError(f"effect class {cls.__name__} has no name")
    if cls.provides not in PROVIDES:
        raise FemromValueError(f"effect {cls.name!r} provides {cls.provides!r}; valid: {', '.join(PROVIDES)}")
    EFFECTS.add(cls.name, cls)
    return cls


def registered_effects() -> dict[str, type[Effect]]:
    """The registered effects by name, in assembly order (the built-in modules are imported once)."""
    return EFFECTS.items()


def effect_class(name: str) -> type[Effect]:
    """The effect registered as ``name``, or a SceneError listing the valid ones."""
    try:
        return EFFECTS.get(name)
    except ValueError as exc:
        raise SceneError(str(exc)) from None


@dataclass(eq=False)
class Assembly:
    """The system under construction: what the effects fill in, on the free dofs.

    Attributes
    ----------
    scene : Scene
    material : MaterialConfig or ElementMaterial
        What the effects read as the material: the scene's ``[material]``, or the
        constants per element of its ``[materials]`` (:func:`femrom.scene.element_materials`).
    space : LineSpace or SolidSpace
        Operators, loads and boundary data in the full dof numbering.
    condensation : Condensation
        Maps full-numbering matrices and vectors to the free dofs.
    timings : dict
        Seconds per stage (filled by :meth:`timed`).
    mass, stiffness, damping : (n, n) sparse or None
    input_matrix : (n, m) ndarray or None
    inputs : callable or None
    load : (n,) ndarray or None
    nonlinear_forces : list of NonlinearForce
    """

    scene: Any
    space: Any
    condensation: Any
    timings: dict = field(default_factory=dict)
    mass: Any = None
    stiffness: Any = None
    damping: Any = None
    input_matrix: Any = None
    inputs: Any = None
    load: np.ndarray | None = None
    material: Any = None
    nonlinear_forces: list = field(default_factory=list)

    def __post_init__(self):
        if self.material is None:       # an assembly made by hand: the scene's one material
            self.material = getattr(self.scene, "material", None)

    @property
    def n_free(self) -> int:
        return self.condensation.n_free

    @contextlib.contextmanager
    def timed(self, name: str):
        """Add the wall time of the block to ``timings[name]``."""
        tic = time.perf_counter()
        try:
            yield
        finally:
            self.timings[name] = self.timings.get(name, 0.0) + time.perf_counter() - tic

    def add_stiffness(self, K) -> None:
        """Add ``K`` (free dofs) to the stiffness: every stiffness effect's contribution sums."""
        self.stiffness = K if self.stiffness is None else self.stiffness + K

    def require(self, what: str, by: str):
        """The already assembled ``mass`` or ``stiffness`` that effect ``by`` needs."""
        value = getattr(self, what)
        if value is None:
            raise SceneError(f"the {by!r} effect needs the {what} (list its effect)")
        return value
