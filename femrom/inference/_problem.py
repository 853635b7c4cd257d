r"""The operator-inference regression, written on Gram matrices.

Every learner in :mod:`femrom.inference` fits unknown operators
``X = [X_1, ..., X_b]`` (an (r, p) ndarray, one column block per operator)
to a target ``Y`` (r, K) through data blocks ``D = [D_1; ...; D_b]`` (p, K):

.. math::

    \min_{X \in \mathcal{S}} \; \| Y + X D \|_F^2 + \sum_j \lambda_j \|X_j\|_F^2,

where :math:`\mathcal{S}` asks each block to be ``"free"``, ``"symmetric"``,
or symmetric with ``X_j \succeq \varepsilon_j I`` (``"psd"``, shift
``eps_j >= 0``). Expanding the square,

.. math::

    f(X) = \langle X G, X \rangle + 2 \langle X, H^\top \rangle + c, \qquad
    G = D D^\top + \Lambda, \quad H = D Y^\top, \quad c = \|Y\|_F^2,

with :math:`\Lambda = \mathrm{blockdiag}(\lambda_j I)`. Only ``G`` (p, p),
``H`` (p, r) and ``c`` enter, so the problem's size does not grow with the
number of snapshots ``K``, and several trajectories are fitted together by
adding their Gram matrices (the same as concatenating their columns).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from femrom._errors import FemromValueError

#: Block structures a regression knows.
STRUCTURES = ("free", "symmetric", "psd")


@dataclass(frozen=True)
class Block:
    """One unknown operator: a column block of ``X``.

    Attributes
    ----------
    name : str
        E.g. ``"stiffness"``.
    size : int
        Its number of columns (``r`` for a square operator, ``m`` for inputs).
    structure : {"free", "symmetric", "psd"}
        ``"psd"`` means symmetric with ``X_j - shift I`` positive semidefinite.
    shift : float
        The ``eps`` of ``X_j >= eps I`` (``"psd"`` only).
    regularization : float
        Tikhonov weight ``lambda_j >= 0`` on ``||X_j||_F^2``.
    """

    name: str
    size: int
    structure: str = "free"
    shift: float = 0.0
    regularization: float = 0.0

    def __post_init__(self):
        if self.structure not in STRUCTURES:
            raise FemromValueError(f"unknown block structure {self.structure!r}; valid: {STRUCTURES}")
        if self.regularization < 0 or self.shift < 0:
            raise FemromValueError(f"block {self.name!r}: regularization and shift must be >= 0")

    @property
    def square(self) -> bool:
        return self.structure != "free"


@dataclass(frozen=True, eq=False)
class GramProblem:
    r"""``min_{X in S} <X G, X> + 2 <X, H^T> + c`` over ``X = [X_1, ..., X_b]`` (r, p).

    Attributes
    ----------
    gram : (p, p) ndarray
        ``D D^T`` of the data blocks (without regularization).
    cross : (p, r) ndarray
        ``D Y^T``.
    target : float
        ``||Y||_F^2``.
    blocks : tuple of Block
        The column blocks of ``X``, sizes summing to ``p``.
    n_samples : int
        Number of snapshot columns ``K`` behind the Gram matrices.
    """

    gram: np.ndarray
    cross: np.ndarray
    target: float
    blocks: tuple[Block, ...]
    n_samples: int = 0

    def __post_init__(self):
        p = sum(b.size for b in self.blocks)
        if self.gram.shape != (p, p) or self.cross.shape[0] != p:
            raise FemromValueError(f"gram {self.gram.shape} / cross {self.cross.shape} do not match "
                                   f"blocks of total size {p}")
        r = self.cross.shape[1]
        for b in self.blocks:
            if b.square and b.size != r:
                raise FemromValueError(f"block {b.name!r} is {b.structure} but has {b.size} columns, "
                                       f"expected r = {r}")

    # -- construction ----------------------------------------------------
    @classmethod
    def from_data(cls, target: np.ndarray, datablocks, blocks) -> "GramProblem":
        """From ``Y`` (r, K) and the data blocks ``D_j`` (size_j, K)."""
        Y = np.asarray(target, dtype=float)
        D = np.vstack([np.asarray(d, dtype=float) for d in datablocks])
        if D.shape[1] != Y.shape[1]:
            raise FemromValueError(f"data blocks have {D.shape[1]} columns, target has {Y.shape[1]}")
        sizes = tuple(np.asarray(d).shape[0] for d in datablocks)
        blocks = tuple(replace(b, size=s) for b, s in zip(blocks, sizes))
        return cls(gram=D @ D.T, cross=D @ Y.T, target=float(np.sum(Y * Y)), blocks=blocks,
                   n_samples=Y.shape[1])

    def __add__(self, other: "GramProblem") -> "GramProblem":
        """The problem of both data sets together (columns concatenated)."""
        if [(b.name, b.size) for b in self.blocks] != [(b.name, b.size) for b in other.blocks]:
            raise FemromValueError("cannot add regressions with different operator blocks")
        return replace(self, gram=self.gram + other.gram, cross=self.cross + other.cross,
                       target=self.target + other.target,
                       n_samples=self.n_samples + other.n_samples)

    def with_blocks(self, **changes) -> "GramProblem":
        """Same data with block attributes changed, e.g. ``regularization={"stiffness": 1e-3}``."""
        blocks = []
        for b in self.blocks:
            kw = {key: value[b.name] for key, value in changes.items() if b.name in value}
            blocks.append(replace(b, **kw))
        return replace(self, blocks=tuple(blocks))

    # -- sizes and slices ------------------------------------------------
    @property
    def r(self) -> int:
        return self.cross.shape[1]

    @property
    def p(self) -> int:
        return self.gram.shape[0]

    def slices(self) -> list[slice]:
        out, start = [], 0
        for b in self.blocks:
            out.append(slice(start, start + b.size))
            start += b.size
        return out

    def regularized_gram(self) -> np.ndarray:
        """(p, p) ndarray ``G = D D^T + blockdiag(lambda_j I)``."""
        lam = np.concatenate([np.full(b.size, b.regularization) for b in self.blocks])
        return self.gram + np.diag(lam)

    # -- evaluations -----------------------------------------------------
    def objective(self, X: np.ndarray) -> float:
        """``||Y + X D||_F^2 + sum_j lambda_j ||X_j||_F^2``."""
        G = self.regularized_gram()
        return float(np.sum((X @ G) * X) + 2.0 * np.sum(X * self.cross.T) + self.target)

    def gradient(self, X: np.ndarray) -> np.ndarray:
        """(r, p) ndarray ``2 (X G + H^T)``."""
        return 2.0 * (X @ self.regularized_gram() + self.cross.T)

    def residual_norm(self, X: np.ndarray) -> float:
        """``||Y + X D||_F`` (the regularization terms left out)."""
        value = float(np.sum((X @ self.gram) * X) + 2.0 * np.sum(X * self.cross.T) + self.target)
        return float(np.sqrt(max(value, 0.0)))

    def is_feasible(self, X: np.ndarray, tol: float = 1e-10) -> bool:
        """Whether every block meets its structure (symmetry to ``tol`` relative)."""
        for b, s in zip(self.blocks, self.slices()):
            Xj = X[:, s]
            if not b.square:
                continue
            scale = max(np.linalg.norm(Xj), np.finfo(float).tiny)
            if np.linalg.norm(Xj - Xj.T) > tol * scale:
                return False
            if b.structure == "psd":
                lowest = np.linalg.eigvalsh(0.5 * (Xj + Xj.T))[0]
                if lowest < b.shift - tol * scale:
                    return False
        return True

    def factor(self, rtol: float = 1e-14):
        r"""``(L, Z, c0)`` with ``f(X) = ||X L + Z||_F^2 + c0`` (exact for ``H`` in range ``G``).

        ``G = L L^T`` from the eigendecomposition (eigenvalues below ``rtol``
        times the largest are dropped, so rank-deficient data is fine), and
        ``Z = H^T L^{+T}``.
        """
        g, W = np.linalg.eigh(self.regularized_gram())
        keep = g > rtol * max(g[-1], np.finfo(float).tiny)
        root = np.sqrt(g[keep])
        L = W[:, keep] * root
        Z = (self.cross.T @ W[:, keep]) / root
        return L, Z, float(self.target - np.sum(Z * Z))

    # -- scaling ---------------------------------------------------------
    def block_scales(self) -> np.ndarray:
        """(b,) ndarray: RMS size of each data block, ``sqrt(trace G_jj / size_j)``."""
        G = self.regularized_gram()
        scales = []
        for s in self.slices():
            size = s.stop - s.start
            value = np.sqrt(max(np.trace(G[s, s]) / max(size, 1), 0.0))
            scales.append(value if value > 0 else 1.0)
        return np.asarray(scales)

    def scaled(self):
        r"""An equivalent problem with unit-size data blocks, and the map back.

        With block scales ``s_j`` and target scale ``t``: ``D_j -> D_j / s_j``,
        ``X_j -> X_j s_j / t`` and ``f -> f / t^2``. Positive scalings keep the
        cones (``X_j >= eps I`` becomes ``X'_j >= eps s_j / t I``), so both
        problems have the same solution up to the scaling.

        Returns
        -------
        scaled : GramProblem
        unscale : callable
            ``X' -> X`` (r, p).
        objective_scale : float
            ``t^2``: ``f(X) = t^2 f'(X')``.
        """
        s = self.block_scales()
        t = np.sqrt(self.target / max(self.r, 1)) if self.target > 0 else 1.0
        col = np.concatenate([np.full(b.size, sj) for b, sj in zip(self.blocks, s)])
        blocks = tuple(replace(b, shift=b.shift * sj / t, regularization=b.regularization / sj**2)
                       for b, sj in zip(self.blocks, s))
        scaled = replace(self, gram=self.gram / np.outer(col, col),
                         cross=self.cross / (col[:, None] * t), target=self.target / t**2,
                         blocks=blocks)

        def unscale(Xs: np.ndarray) -> np.ndarray:
            return Xs * (t / col)[None, :]

        return scaled, unscale, t * t

    # -- structure helpers ------------------------------------------------
    def project(self, X: np.ndarray) -> np.ndarray:
        """Euclidean projection of ``X`` onto the feasible set (blockwise)."""
        out = X.copy()
        for b, s in zip(self.blocks, self.slices()):
            if b.square:
                out[:, s] = project_block(X[:, s], b)
        return out


def project_block(Xj: np.ndarray, block: Block) -> np.ndarray:
    """Nearest (Frobenius) feasible matrix: symmetrize, then clip eigenvalues at ``shift``."""
    S = 0.5 * (Xj + Xj.T)
    if block.structure != "psd":
        return S
    if _is_above(S, block.shift):
        return S
    g, P = np.linalg.eigh(S)
    g = np.maximum(g, block.shift)
    return (P * g) @ P.T


def _is_above(S: np.ndarray, shift: float) -> bool:
    """Whether ``S - shift I`` is positive definite (a Cholesky attempt: cheap)."""
    try:
        np.linalg.cholesky(S - shift * np.eye(S.shape[0]))
    except np.linalg.LinAlgError:
        return False
    return True
