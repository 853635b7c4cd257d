"""What every reduced model shares: the basis, reduction of full vectors, the time grid, lazy fields.

A reduced model of femrom follows one protocol: it is built from operators or
fitted by a learner (``fit(data) -> self``), and offers ``predict`` (a whole
trajectory), ``stepper`` (one step at a time, for a controller in the loop),
``save``/``load`` (HDF5) and, when linear, ``to_state_space(dt)``.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

from femrom.inference import reduced_coordinates
from femrom.integrators import uniform_step  # noqa: F401  (the time grid every reduced model checks)


class ReducedModel:
    """Base of the reduced models: a basis ``V`` (n, r) with its product ``W`` (``V^T W V = I``)."""

    basis: np.ndarray | None = None
    product = None

    @property
    def r(self) -> int:  # pragma: no cover - interface
        raise NotImplementedError

    def reduce(self, x: np.ndarray) -> np.ndarray:
        """(r,) or (r, k) reduced coordinates ``V^T W x`` of full (n,) or (n, k) vectors."""
        if self.basis is None:
            raise ValueError("a full-order vector needs the basis to be reduced")
        return reduced_coordinates(self.basis, np.asarray(x, dtype=float), self.product)

    def _initial(self, x, name: str, *, default_zero: bool = True) -> np.ndarray:
        """A reduced (r,) initial vector from a reduced or full one (``None``: zeros)."""
        r = self.r
        if x is None:
            if not default_zero:
                raise ValueError(f"{name} is required")
            return np.zeros(r)
        x = np.asarray(x, dtype=float).ravel()
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{name} is not finite (NaN or inf at index {int(np.flatnonzero(~np.isfinite(x))[0])})")
        if x.size == r:
            return x
        if self.basis is not None and x.size == self.basis.shape[0]:
            return self.reduce(x)
        raise ValueError(f"{name} has {x.size} entries: expected r = {r} (reduced) "
                         f"or n = {None if self.basis is None else self.basis.shape[0]} (full)")


class LazyFields:
    """Full fields ``V x(t_k)`` of a reduced solution, rebuilt only on request.

    For dataclasses with ``t`` (k,) (also :attr:`times`), ``basis`` (n, r) or
    ``None`` and the (r, k) coordinate arrays named in ``FIELDS``.
    """

    FIELDS: tuple[str, ...] = ("q",)

    @property
    def times(self) -> np.ndarray:
        """(k,) ndarray, the solution's times (``t``): the name full-order results use too."""
        return self.t

    def _coordinates(self, which: str) -> np.ndarray:
        if self.basis is None:
            raise ValueError("this model has no basis: full fields cannot be reconstructed")
        if which not in self.FIELDS:
            raise ValueError(f"unknown field {which!r}; valid: {self.FIELDS}")
        return getattr(self, which)

    def field(self, k: int, which: str = "q") -> np.ndarray:
        """(n,) ndarray ``V x(t_k)``, ``x`` one of :attr:`FIELDS`."""
        return self.basis @ self._coordinates(which)[:, k]

    def fields(self, block: int = 256, which: str = "q") -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Yield ``(t_block, V X_block)``, ``X`` one of :attr:`FIELDS`, ``block`` steps at a time.

        Memory stays at (n, block) whatever the trajectory's length.
        """
        X = self._coordinates(which)
        for start in range(0, X.shape[1], block):
            stop = min(start + block, X.shape[1])
            yield self.t[start:stop], self.basis @ X[:, start:stop]
