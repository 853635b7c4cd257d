"""The linear-solver interface and the registry of strategies."""

from __future__ import annotations

import importlib.util
from typing import ClassVar

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromRuntimeError, FemromValueError


class LinearSolverError(FemromRuntimeError):
    """A linear solve failed (singular/indefinite matrix, CG did not converge)."""


class LinearSolver:
    """A reusable solver of ``A x = b`` for one fixed (n, n) matrix ``A``.

    A strategy is a subclass registered with :func:`register_strategy`; its
    ``__init__(A, *, spd, **options)`` does the one-off setup and
    :meth:`_solve` the cheap solves that reuse it.

    Attributes
    ----------
    name : str
        The strategy (``"auto"`` is resolved to the one chosen).
    package : str or None
        The importable package the strategy needs (``None``: none beyond scipy).
    install : str or None
        What to ``pip install`` for it (defaults to ``package``).
    spd_only : bool
        Whether the strategy needs a symmetric positive definite matrix.
    shape : tuple of int
        Shape of ``A``.
    setup_seconds : float
        Wall time of the factorisation or preconditioner setup.
    n_factorizations : int
        Factorisations (or multigrid setups) this solver performed: 1, or 0
        for ``"diagonal"``. Reuse is the point: it never grows with solves.
    n_solves : int
        Number of calls to :meth:`solve`.
    last_iterations, total_iterations : int or None
        Krylov iterations of the last solve and of all solves (iterative
        strategies only; ``None`` for direct ones).
    """

    name: ClassVar[str] = "?"
    package: ClassVar[str | None] = None
    install: ClassVar[str | None] = None
    spd_only: ClassVar[bool] = False
    last_iterations: int | None = None
    total_iterations: int | None = None

    def __init__(self, A):
        self.shape = A.shape
        self.setup_seconds = 0.0
        self.n_factorizations = 0
        self.n_solves = 0

    @classmethod
    def available(cls) -> bool:
        """Whether the package behind the strategy can be imported here."""
        return cls.package is None or importlib.util.find_spec(cls.package) is not None

    def solve(self, b: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """(n,) or (n, k) ndarray ``x`` with ``A x = b``; ``x0`` is a warm start (iterative only)."""
        b = np.asarray(b, dtype=float)
        if b.shape[0] != self.shape[0]:
            raise FemromValueError(f"right-hand side has {b.shape[0]} rows, expected {self.shape[0]}")
        self.n_solves += 1
        return self._solve(b, x0)

    def _solve(self, b, x0):  # pragma: no cover - interface
        raise NotImplementedError

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(name={self.name!r}, n={self.shape[0]}, "
                f"setup_seconds={self.setup_seconds:.3g}, n_solves={self.n_solves})")


#: Registered strategies by name (``"auto"`` is not one: it picks among them).
STRATEGY_CLASSES: dict[str, type[LinearSolver]] = {}


def register_strategy(cls: type[LinearSolver]) -> type[LinearSolver]:
    """Class decorator: make ``cls`` a strategy :func:`make_solver` knows by ``cls.name``."""
    if not cls.name or cls.name == "auto":
        raise FemromValueError(f"strategy class {cls.__name__} needs a name other than 'auto'")
    STRATEGY_CLASSES[cls.name] = cls
    return cls


def is_available(strategy: str) -> bool:
    """Whether the package behind ``strategy`` can be imported here."""
    cls = STRATEGY_CLASSES.get(strategy)
    return True if cls is None else cls.available()


def is_diagonal(A) -> bool:
    """Whether the sparse matrix ``A`` has no stored nonzero off its diagonal."""
    if A.nnz > A.shape[0] and A.format in ("csr", "csc"):
        # cheap exit for the usual FE matrix: some row has two stored entries
        counts = np.diff(A.indptr)
        if np.any(counts > 1) and A.data.all():
            return False
    A = sp.coo_matrix(A)
    return bool(np.all((A.row == A.col) | (A.data == 0.0)))
