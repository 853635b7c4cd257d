r"""Reduced terms: each term of a reduced second-order model is one object.

A reduced model in ``r`` coordinates is the balance

.. math::

    \sum_{\text{terms } T} T(\hat q, \dot{\hat q}, \ddot{\hat q}, u, t; s) = 0, \qquad
    \text{e.g.}\quad \hat M \ddot{\hat q} + \hat C \dot{\hat q} + \hat K \hat q
        + \hat f(\hat q, \dot{\hat q}; s) - \hat B u - \hat f_0 = 0,

plus the output map ``y = E^ q^``. A term class knows (as in opinf, with the
second-order structure added):

- ``galerkin(system, V)``: its intrusive projection from a
  :class:`~femrom.scene.SecondOrderSystem` (``None`` when the system lacks it);
- ``datablock(data)``: its rows ``D_j`` in the regression ``|| Y + X D ||``,
  and ``from_coefficients(X_j)`` for the block the regression returns
  (learnable terms);
- ``structure``: what a structure-preserving learner asks of it (``"spd"``:
  symmetric ``>= eps I``; ``"psd"``; ``"symmetric"``; ``"free"``; ``"known"``
  for a given term that moves to the regression's target; ``"gradient"`` for
  a force that is the gradient of a potential);
- ``lhs`` and ``tangent``: its value and derivatives in a reduced step;
- ``save(group)`` / ``load(group, ...)``: its HDF5 form.

Terms are registered by name (:func:`register_term`): the built-in ones are
the modules of :mod:`femrom.inference.terms` (found automatically), and a
term written anywhere else joins by the decorator. :func:`galerkin` asks every
registered term for its projection, learners build their regression from the
terms they are given, reduced steppers and save/load iterate over a model's
terms: a new term is one class in one file.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from femrom._errors import FemromValueError
from femrom._registry import Registry

#: Data variables a linear term multiplies (``"1"``: a constant).
VARIABLES = ("q", "v", "a", "u", "1")
#: Structures a term can declare.
STRUCTURES = ("spd", "psd", "symmetric", "free", "known", "gradient", "dissipative")

#: The reduced terms by name, in equation order.
TERMS = Registry("reduced term", "femrom.inference.terms", order=lambda name, cls: (cls.order, name),
                 valid="registered")


class ReducedTerm:
    """One term of a reduced second-order model (see the module docstring).

    Class attributes
    ----------------
    name : str
        Registry key; a model holds at most one term of each name.
    effect : str or None
        The :attr:`SecondOrderSystem.effects` entry this term reduces.
    structure : str
        One of :data:`STRUCTURES`.
    learnable : bool
        Whether a learner fits it from a data block.
    role : {"balance", "output"}
        ``"output"`` for ``y = E^ q^`` (fitted by its own least squares).
    order : int
        Position when a model lists its terms (mass 0, damping 10, stiffness 20,
        forces 30, inputs 40, constant loads 50, outputs 90).
    """

    name: ClassVar[str] = ""
    effect: ClassVar[str | None] = None
    structure: ClassVar[str] = "free"
    learnable: ClassVar[bool] = False
    role: ClassVar[str] = "balance"
    order: ClassVar[int] = 60
    variable: ClassVar[str | None] = None

    # -- the two views ------------------------------------------------------------
    @classmethod
    def galerkin(cls, system, basis: np.ndarray) -> "ReducedTerm | None":
        """Intrusive projection onto ``V`` (n, r); ``None`` when ``system`` lacks the term."""
        return None

    @classmethod
    def datablock(cls, data) -> np.ndarray:
        """(p, K) ndarray: this term's rows of the regression's data ``D``."""
        raise NotImplementedError(f"term {cls.name!r} is not learned from data")

    @classmethod
    def from_coefficients(cls, coefficients: np.ndarray) -> "ReducedTerm":
        """The term whose operator is the regression's block ``X_j`` (r, p)."""
        raise NotImplementedError(f"term {cls.name!r} is not learned from data")

    def target(self, data) -> np.ndarray:
        """(r, K) ndarray: a known term's value on the data columns (moved to the target)."""
        raise NotImplementedError(f"term {self.name!r} is not a known term")

    # -- in a reduced step -------------------------------------------------------------
    def lhs(self, q, v=None, a=None, u=None, state: Any = None) -> np.ndarray:
        """(r,) ndarray: the term's contribution to the balance."""
        raise NotImplementedError

    def tangent(self, q, v=None, state: Any = None):
        """``(d lhs / dq, d lhs / dv)``: (r, r) ndarrays or ``None``."""
        return None, None

    def force(self, q, v=None, state: Any = None) -> np.ndarray:
        """(r,) ndarray: a nonlinear term as the force of its model's system (:meth:`lhs`, no
        accelerations or inputs), so that a term written with ``lhs`` and ``tangent`` alone steps."""
        return self.lhs(q, v, state=state)

    def potential(self, q) -> float:
        """The term's share of the potential energy (0 for a non-conservative term)."""
        return 0.0

    @property
    def stateful(self) -> bool:
        return False

    @property
    def conservative(self) -> bool:
        """Whether ``lhs`` is the gradient of :meth:`potential` (no velocity, no state)."""
        return False

    @property
    def velocity_dependent(self) -> bool:
        return False

    def initial_state(self) -> Any:
        """The term's internal state at t = 0 (``None`` for a stateless term)."""
        return None

    def commit(self, q, v, state: Any) -> Any:
        """The state after a converged reduced step ending at (q, v)."""
        return state

    # -- storage ------------------------------------------------------------------------
    def save(self, group) -> None:
        """Write the term into an HDF5 group (its class name is written by the model)."""
        raise NotImplementedError(f"term {self.name!r} cannot be saved")

    @classmethod
    def load(cls, group, **context) -> "ReducedTerm":
        """Inverse of :meth:`save`; ``context`` holds ``basis`` and what the caller passed."""
        raise NotImplementedError(f"term {cls.name!r} cannot be loaded")

    def describe(self) -> dict:
        """What the term is, for metadata."""
        return {"term": self.name, "structure": self.structure}


class LinearTerm(ReducedTerm):
    r"""``sign * A x`` for one data variable ``x`` (:data:`VARIABLES`) and a matrix ``A``.

    ``sign = -1`` puts forcing on the right side of the balance (``- B^ u``,
    ``- f^_0``); its data block is then ``-x``.

    Attributes
    ----------
    matrix : (r, p) ndarray
    """

    variable: ClassVar[str] = "q"
    sign: ClassVar[float] = 1.0

    def __init__(self, matrix):
        matrix = np.asarray(matrix, dtype=float)
        if matrix.ndim == 1 and self.variable == "1":
            matrix = matrix[:, None]
        if matrix.ndim != 2:
            raise FemromValueError(f"term {self.name!r}: matrix must be 2-d, got shape {matrix.shape}")
        self.matrix = matrix

    @property
    def r(self) -> int:
        return self.matrix.shape[0]

    @classmethod
    def data_variable(cls, data) -> np.ndarray:
        """(p, K) ndarray: the variable's data columns."""
        if cls.variable == "1":
            return np.ones((1, data.n_samples))
        value = {"q": data.states, "v": data.velocities, "a": data.accelerations, "u": data.inputs}[cls.variable]
        if value is None:
            raise FemromValueError(f"term {cls.name!r} needs data of {cls.variable!r}, which these data lack")
        return value

    @classmethod
    def datablock(cls, data) -> np.ndarray:
        D = cls.data_variable(data)
        return D if cls.sign > 0 else -D

    @classmethod
    def from_coefficients(cls, coefficients):
        return cls(coefficients)

    def target(self, data) -> np.ndarray:
        return self.sign * (self.matrix @ self.data_variable(data))

    def lhs(self, q, v=None, a=None, u=None, state=None):
        x = {"q": q, "v": v, "a": a, "u": u}.get(self.variable)
        if self.variable == "1":
            return self.sign * self.matrix[:, 0]
        if x is None:
            raise FemromValueError(f"term {self.name!r} needs {self.variable!r}")
        return self.sign * (self.matrix @ x)

    def tangent(self, q, v=None, state=None):
        A = self.sign * self.matrix
        return (A, None) if self.variable == "q" else (None, A) if self.variable == "v" else (None, None)

    def potential(self, q) -> float:
        if self.variable == "q":
            S = 0.5 * (self.matrix + self.matrix.T)
            return 0.5 * float(q @ (S @ q)) if np.ndim(q) == 1 else 0.5 * np.sum(q * (S @ q), axis=0)
        if self.variable == "1":
            return -self.sign * float(self.matrix[:, 0] @ q) if np.ndim(q) == 1 \
                else -self.sign * (self.matrix[:, 0] @ q)
        return 0.0

    def save(self, group) -> None:
        group.create_dataset("matrix", data=self.matrix)

    @classmethod
    def load(cls, group, **context):
        return cls(group["matrix"][()])

    def describe(self) -> dict:
        return {"term": self.name, "structure": self.structure, "shape": list(self.matrix.shape)}


def register_term(cls: type[ReducedTerm]) -> type[ReducedTerm]:
    """Class decorator: :func:`galerkin`, learners (by name) and ROM files know ``cls``."""
    if not cls.name:
        raise FemromValueError(f"term class {cls.__name__} has no name")
    if cls.structure not in STRUCTURES:
        raise FemromValueError(f"term {cls.name!r} has structure {cls.structure!r}; valid: {', '.join(STRUCTURES)}")
    if issubclass(cls, LinearTerm) and cls.variable not in VARIABLES:
        raise FemromValueError(f"term {cls.name!r} multiplies {cls.variable!r}; valid: {', '.join(VARIABLES)}")
    TERMS.add(cls.name, cls)
    return cls


def registered_terms() -> dict[str, type[ReducedTerm]]:
    """Every registered term class by name, in equation order (built-ins imported once)."""
    return TERMS.items()


def term_class(name: str) -> type[ReducedTerm]:
    """The term registered as ``name``, or a clear error listing the registered ones."""
    return TERMS.get(name)
