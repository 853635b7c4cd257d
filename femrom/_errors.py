"""The errors femrom raises for a user to read, and their one base class.

Every error a user can cause (a bad argument, scene key, file, or data) or meet
(a Newton iteration or a solver that fails, a model that diverges) is a
:class:`FemromError`: one line that names the culprit. The three kinds below
also derive from the matching built-in exception, so ``except ValueError``
keeps working for code written against the built-ins:

- :class:`FemromValueError`: an input that cannot be used (value, shape, range, file);
- :class:`FemromTypeError`: an input of the wrong kind;
- :class:`FemromRuntimeError`: a computation that could not be completed.

A package's own error classes (``SceneError``, ``MeshError``, ``IntegrationError``, ...)
derive from one of them.
"""

from __future__ import annotations

import numbers


class FemromError(Exception):
    """Base of every error femrom raises for a user; the message is one line naming the culprit."""


class FemromValueError(FemromError, ValueError):
    """An argument, setting, file or data set that cannot be used as given."""


class FemromTypeError(FemromError, TypeError):
    """An argument of the wrong kind."""


class FemromRuntimeError(FemromError, RuntimeError):
    """A computation that could not be completed (no convergence, a failed solve, divergence)."""


def nonnegative_integer(value, name: str):
    """``value`` as an int >= 0, or one FemromValueError naming ``name`` (the rule of
    :func:`positive_integer` with 0 allowed: counts of extra columns, passes, seeds)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 0:
        raise FemromValueError(f"{name} must be a non-negative integer, got {value!r}")
    return int(value)


def positive_integer(value, name: str, *, optional: bool = False):
    """``value`` as an int >= 1, or one FemromValueError naming ``name`` (the one rule for integer
    arguments: an int or a numpy integer, never a float such as ``2.5`` or ``20.0``, never a bool);
    ``None`` passes through when ``optional``."""
    if value is None and optional:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise FemromValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)
