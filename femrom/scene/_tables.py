"""Reading scene tables: their keys checked (:func:`take_table`), their values checked
(numbers, points, lists of names, choices); each problem is one SceneError naming the key."""

from __future__ import annotations

import math

from femrom.scene._errors import SceneError


def take_table(data, section: str, allowed: dict, required: tuple = ()) -> dict:
    """Defaults ``allowed`` updated by the table ``data``; one SceneError naming an unknown or
    missing key (or a value that is not a table) of ``[section]``."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise SceneError(f"[{section}] must be a table, got {type(data).__name__}")
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise SceneError(f"unknown key {unknown[0]!r} in [{section}]; valid keys: {', '.join(allowed)}")
    missing = [k for k in required if data.get(k) is None]
    if missing:
        raise SceneError(f"missing key {missing[0]!r} in [{section}]")
    return {**allowed, **data}


def as_number(value, where: str) -> float:
    """A finite real number (not a bool or a string), or a SceneError naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SceneError(f"[{where.rsplit('.', 1)[0]}] {where.rsplit('.', 1)[-1]} must be a finite number, "
                         f"got {value!r}")
    return float(value)


def as_vector(value, where: str) -> tuple[float, ...]:
    """A point or direction: a list of finite numbers."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise SceneError(f"[{where.rsplit('.', 1)[0]}] {where.rsplit('.', 1)[-1]} must be a list of numbers, "
                         f"got {value!r}")
    return tuple(as_number(x, where) for x in value)


def as_names(value, where: str) -> tuple[str, ...]:
    """A list of names (boundaries, fields): a lone string is refused, not split into letters."""
    if isinstance(value, str) or not isinstance(value, (list, tuple)) or \
            not all(isinstance(x, str) and x for x in value):
        raise SceneError(f"[{where.rsplit('.', 1)[0]}] {where.rsplit('.', 1)[-1]} must be a list of names, "
                         f"got {value!r}")
    return tuple(value)


def one_of(value, valid, what):
    """``value`` if it is one of ``valid``, else one SceneError naming ``what`` and listing them."""
    if value not in valid:
        raise SceneError(f"unknown {what} {value!r}; valid: {', '.join(valid)}")
    return value
