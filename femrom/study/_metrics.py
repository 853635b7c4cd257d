"""Error metrics of a reduced model against a full-order run."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom.post import relative_error  # noqa: F401  (the study's metrics are functions of post)


def invariant_drift(values, window: slice = slice(None)) -> float:
    """``max |I(t) - I(0)| / |I(0)|`` over ``window`` of a (k,) history (``I(0)``: its first value;
    ``inf`` once a value in the window is not finite: a model that blew up)."""
    values = np.asarray(values, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        change = np.abs(values[window] - values[0]) / abs(values[0])
    return float(np.max(change)) if np.all(np.isfinite(change)) else float("inf")


def mass_norm(M, X) -> float:
    """Frobenius norm of ``X`` (n, k) in the product ``M``: ``sqrt(trace(X^T M X))``."""
    return float(np.sqrt(max(np.sum(X * (M @ X)), 0.0)))


@dataclass(frozen=True, eq=False)
class Projection:
    r"""A run's displacements in a nested basis, column by column: what exact field errors need.

    Attributes
    ----------
    coordinates : (R, k) ndarray
        ``X^ = V^T W Q`` in the largest basis ``V`` (R columns).
    residual2 : (k,) ndarray
        ``||q_j - V x^_j||_W^2`` of every column (exact: computed in the projection pass).
    norm2 : (k,) ndarray
        ``||q_j||_W^2``.

    Errors over a window of columns (``columns``, a slice; all by default) are
    Frobenius norms over those columns, relative to ``||Q||_W`` over them.
    """

    coordinates: np.ndarray
    residual2: np.ndarray
    norm2: np.ndarray

    def _rom_error2(self, q_rom: np.ndarray) -> np.ndarray:
        r"""(k,) ndarray ``||q_j - V_r q^_j||_W^2`` by the split of :meth:`field_error`."""
        X = self.coordinates
        r = q_rom.shape[0]
        with np.errstate(over="ignore", invalid="ignore"):
            return self.residual2 + np.sum(X[r:] ** 2, axis=0) + np.sum((X[:r] - q_rom) ** 2, axis=0)

    def field_error(self, q_rom: np.ndarray, columns: slice = slice(None)) -> float:
        r"""Relative error ``||Q - V_r Q^_rom||_W / ||Q||_W`` of a ROM trajectory (r, k), exactly.

        With ``V`` orthonormal in ``W`` and ``V_r`` its first r columns,
        ``||q - V_r q^||_W^2 = ||q - V x^||_W^2 + ||x^_{r:}||^2 + ||x^_{:r} - q^||^2``:
        the largest basis's residual, the coordinates the r-basis drops, and the
        ROM's own error; no pass over the full fields.
        """
        err2 = float(np.sum(self._rom_error2(q_rom)[columns]))
        return float(np.sqrt(err2 / np.sum(self.norm2[columns]))) if np.isfinite(err2) else float("inf")

    def column_errors(self, q_rom: np.ndarray) -> np.ndarray:
        """(k,) ndarray ``||q_j - V_r q^_j||_W`` (absolute; ``inf`` where the ROM is not finite)."""
        err2 = self._rom_error2(q_rom)
        return np.where(np.isfinite(err2), np.sqrt(np.maximum(err2, 0.0)), np.inf)

    def projection_error(self, r: int, columns: slice = slice(None)) -> float:
        """The best any r-dimensional model in this basis can do: ``||Q - V_r V_r^T W Q||_W / ||Q||_W``."""
        err2 = self.residual2[columns] + np.sum(self.coordinates[r:, columns] ** 2, axis=0)
        return float(np.sqrt(np.sum(err2) / np.sum(self.norm2[columns])))

    def column_projection_errors(self, r: int) -> np.ndarray:
        """(k,) ndarray ``||q_j - V_r V_r^T W q_j||_W``."""
        return np.sqrt(np.maximum(self.residual2 + np.sum(self.coordinates[r:] ** 2, axis=0), 0.0))

    def norm(self, columns: slice = slice(None)) -> float:
        """``||Q||_W`` over ``columns``."""
        return float(np.sqrt(np.sum(self.norm2[columns])))


def project_run(basis: np.ndarray, X, product=None) -> Projection:
    """One pass over the columns of ``X`` (an array or block source): its :class:`Projection` in ``basis``."""
    from femrom.inference import project_columns

    return Projection(*project_columns(basis, X, product, per_column=True))


def energy_ratio(rom_energy: np.ndarray, fom_energy: np.ndarray | None) -> tuple[float, float]:
    """``(max |E_rom| / max E_fom, |E_rom(end)| / max E_fom)``: bounded energy over a long window.

    ``nan`` without a FOM energy; ``inf`` for a ROM whose energy is not finite.
    """
    if fom_energy is None or not np.max(fom_energy) > 0:
        return float("nan"), float("nan")
    peak = float(np.max(fom_energy))
    if not np.all(np.isfinite(rom_energy)):
        return float("inf"), float("inf")
    return float(np.max(np.abs(rom_energy)) / peak), float(abs(rom_energy[-1]) / peak)


def diverged_at(values, reference, times, factor: float = 1e6):
    """The first of ``times`` (k,) at which a model's ``values`` (p, k) are not finite or exceed ``factor``
    times the largest ``|reference|`` (p, k); ``None`` when they never do."""
    values = np.asarray(values, dtype=float)
    with np.errstate(all="ignore"):
        scale = float(np.max(np.abs(reference))) if np.size(reference) else 0.0
        bad = ~np.all(np.isfinite(values), axis=0)
        if scale > 0:
            bad |= np.max(np.abs(values), axis=0) > factor * scale
    return float(np.asarray(times)[np.argmax(bad)]) if bad.any() else None
