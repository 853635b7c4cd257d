"""One registry class for every extension point (effects, terms, learners, schemes, solvers).

A registry maps names to classes. Built-in entries live one per module of a
package and are imported the first time the registry is read (so a new entry
is one file, with no list to edit); entries elsewhere join by the decorator
when their module is imported.
"""

from __future__ import annotations

import importlib
import pkgutil
from typing import Callable

from femrom._errors import FemromValueError


class Registry:
    """Name -> class, discovered from ``package`` on first read.

    Parameters
    ----------
    kind : str
        What the entries are, for error messages (``"effect"``, ``"reduced term"``).
    package : str, optional
        Dotted name of the package whose modules hold the built-in entries.
    order : callable, optional
        Sort key ``(name, entry) -> key`` of :meth:`items` (default: registration order).
    valid : str
        The word before the list of names in an error message.
    """

    def __init__(self, kind: str, package: str | None = None, *, order: Callable | None = None,
                 valid: str = "valid"):
        self.kind, self.package, self.order, self.valid = kind, package, order, valid
        self._entries: dict[str, object] = {}
        self._discovered = package is None

    def add(self, name: str, entry) -> None:
        """Register ``entry`` as ``name`` (a later entry of the same name replaces it)."""
        if not name:
            raise FemromValueError(f"a {self.kind} needs a name")
        self._entries[name] = entry

    def remove(self, name: str):
        """Unregister ``name``; returns its entry."""
        return self._entries.pop(name)

    def decorator(self, name: str | None = None):
        """A class decorator registering the class as ``name`` (default: its ``name`` attribute)."""

        def decorate(cls):
            self.add(name or getattr(cls, "name", ""), cls)
            return cls

        return decorate

    def items(self) -> dict:
        """Every entry by name (the package's modules imported once), in :attr:`order`."""
        if not self._discovered:
            self._discovered = True
            package = importlib.import_module(self.package)
            for module in pkgutil.iter_modules(package.__path__):
                importlib.import_module(f"{self.package}.{module.name}")
        entries = dict(self._entries)
        if self.order is not None:
            entries = dict(sorted(entries.items(), key=lambda item: self.order(*item)))
        return entries

    def get(self, name: str):
        """The entry ``name``, or one FemromValueError naming it and listing the registered ones."""
        entries = self.items()
        if name not in entries:
            raise FemromValueError(f"unknown {self.kind} {name!r}; {self.valid}: {', '.join(entries)}")
        return entries[name]

    def __contains__(self, name: str) -> bool:
        return name in self.items()

    def __iter__(self):
        return iter(self.items())

    def __len__(self) -> int:
        return len(self.items())
