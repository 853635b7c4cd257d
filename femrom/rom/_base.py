"""What every reduced model shares: the basis, reduction of full vectors, the initial state, lazy fields.

A reduced model of femrom follows one contract: it is built from operators or
fitted by a learner (``fit(data, *, validation=None) -> self``), and offers

- ``predict(times, inputs=None, *, initial=None)``: a whole trajectory on a uniform
  grid, returning a solution with ``times``, ``outputs`` and ``info`` (and its own
  coordinates; full fields rebuilt on request);
- ``stepper(...)``: one step at a time, for a controller in the loop;
- ``save``/``load`` (HDF5) and, when linear, ``to_state_space(dt)``.

``initial`` says where a prediction starts, in the model's own terms: a second-order
model takes a displacement, a ``(q, v)`` pair (each reduced or full) or a
:class:`~femrom.integrators.StepResult` (with the nonlinear force's state, e.g.
``StepResult.at_rest(r, state=...)``); a canonical one a ``(q, p)`` pair; a state space
its state ``z``. ``None`` is rest.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

from femrom._errors import FemromValueError

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
            raise FemromValueError("a full-order vector needs the basis to be reduced")
        return reduced_coordinates(self.basis, np.asarray(x, dtype=float), self.product)

    def initial_state(self, initial) -> tuple[np.ndarray, np.ndarray, object]:
        """``(q0, v0, state)`` (reduced) of a second-order model's ``initial`` (module docstring)."""
        if initial is None:
            return np.zeros(self.r), np.zeros(self.r), None
        if hasattr(initial, "q") and hasattr(initial, "v"):
            return (self._initial(initial.q, "initial.q"), self._initial(initial.v, "initial.v"),
                    getattr(initial, "state", None))
        if isinstance(initial, (tuple, list)):
            if len(initial) != 2:
                raise FemromValueError(f"initial must be q0, a (q0, v0) pair or a StepResult; got a sequence of "
                                       f"{len(initial)}")
            return self._initial(initial[0], "initial q0"), self._initial(initial[1], "initial v0"), None
        return self._initial(initial, "initial q0"), np.zeros(self.r), None

    def canonical_initial(self, initial, inputs=None) -> tuple[np.ndarray, np.ndarray]:
        """``(q0, p0)`` (reduced) of a canonical model's ``initial`` pair (each reduced or full);
        ``None`` is rest. Such a model has no inputs: ``inputs`` must be absent."""
        if inputs is not None:
            raise FemromValueError("a canonical model has no inputs: give inputs=None")
        if initial is None:
            return np.zeros(self.r), np.zeros(self.r)
        if not (isinstance(initial, (tuple, list)) and len(initial) == 2):
            raise FemromValueError("initial must be a (q0, p0) pair for a canonical model")
        return self._initial(initial[0], "initial q0"), self._initial(initial[1], "initial p0")

    def _initial(self, x, name: str, *, default_zero: bool = True) -> np.ndarray:
        """A reduced (r,) initial vector from a reduced or full one (``None``: zeros)."""
        r = self.r
        if x is None:
            if not default_zero:
                raise FemromValueError(f"{name} is required")
            return np.zeros(r)
        x = np.asarray(x, dtype=float).ravel()
        if not np.all(np.isfinite(x)):
            raise FemromValueError(f"{name} is not finite (NaN or inf at index {int(np.flatnonzero(~np.isfinite(x))[0])})")
        if x.size == r:
            return x
        if self.basis is not None and x.size == self.basis.shape[0]:
            return self.reduce(x)
        raise FemromValueError(f"{name} has {x.size} entries: expected r = {r} (reduced) "
                         f"or n = {None if self.basis is None else self.basis.shape[0]} (full)")


class Solution:
    """What every reduced model's ``predict`` returns: ``times`` (k,), ``outputs`` (p, k) or ``None``,
    ``info`` (scheme, step, timings), and the model's own coordinates."""

    t: np.ndarray
    outputs: np.ndarray | None
    info: dict

    @property
    def times(self) -> np.ndarray:
        """(k,) ndarray, the solution's times (``t``): the name full-order results use too."""
        return self.t


class LazyFields(Solution):
    """Full fields ``V x(t_k)`` of a reduced solution, rebuilt only on request.

    For dataclasses with ``t`` (k,) (also :attr:`times`), ``basis`` (n, r) or
    ``None`` and the (r, k) coordinate arrays named in ``FIELDS``.
    """

    FIELDS: tuple[str, ...] = ("q",)

    def _coordinates(self, which: str) -> np.ndarray:
        if self.basis is None:
            raise FemromValueError("this model has no basis: full fields cannot be reconstructed")
        if which not in self.FIELDS:
            raise FemromValueError(f"unknown field {which!r}; valid: {self.FIELDS}")
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
