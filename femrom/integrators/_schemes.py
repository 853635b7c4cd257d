"""The registry of full-order time schemes: a scene's ``[time] integrator`` by name.

A scheme is one class (``name``, ``order``, ``init``, ``step``: see
:mod:`._driver`) registered with :func:`register_scheme` under the name a
scene file uses, with a ``from_config(time_config)`` classmethod that reads
its options from ``[time]``.
"""

from __future__ import annotations

from femrom._registry import Registry

#: The full-order schemes by scene name (sorted); the integrators package registers its own.
SCHEMES = Registry("integrator", order=lambda name, cls: name)


def register_scheme(name: str):
    """Class decorator: scenes may name this scheme ``name`` in ``[time] integrator``."""

    def decorate(cls):
        if not hasattr(cls, "from_config"):
            raise TypeError(f"scheme {cls.__name__} needs a from_config(time_config) classmethod")
        SCHEMES.add(name, cls)
        return cls

    return decorate


def scheme_for(time_config):
    """The scheme a scene's ``[time]`` names; one clear error for an unknown name."""
    name = time_config.integrator
    if name not in SCHEMES:
        raise ValueError(f"unknown integrator {name!r} in [time]; valid: {', '.join(SCHEMES.items())}")
    return SCHEMES.get(name).from_config(time_config)
