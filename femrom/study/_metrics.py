"""Error metrics of a reduced model against a full-order run."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def relative_error(reference: np.ndarray, approximation: np.ndarray) -> float:
    """``||approximation - reference||_F / ||reference||_F`` (``inf`` if the approximation is not finite)."""
    reference, approximation = np.asarray(reference, float), np.asarray(approximation, float)
    if not np.all(np.isfinite(approximation)):
        return float("inf")
    return float(np.linalg.norm(approximation - reference) / np.linalg.norm(reference))


def mass_norm(M, X) -> float:
    """Frobenius norm of ``X`` (n, k) in the product ``M``: ``sqrt(trace(X^T M X))``."""
    return float(np.sqrt(max(np.sum(X * (M @ X)), 0.0)))


@dataclass(frozen=True, eq=False)
class Projection:
    r"""A run's displacements in a nested basis: what exact field errors need.

    Attributes
    ----------
    coordinates : (R, k) ndarray
        ``X^ = V^T W Q`` in the largest basis ``V`` (R columns).
    residual : float
        ``||Q - V X^||_W`` (Frobenius, exact: computed in the projection pass).
    norm : float
        ``||Q||_W``.
    """

    coordinates: np.ndarray
    residual: float
    norm: float

    def field_error(self, q_rom: np.ndarray) -> float:
        r"""Relative error ``||Q - V_r Q^_rom||_W / ||Q||_W`` of a ROM trajectory (r, k), exactly.

        With ``V`` orthonormal in ``W`` and ``V_r`` its first r columns,
        ``||Q - V_r Q^||_W^2 = ||Q - V X^||_W^2 + ||X^_{r:}||^2 + ||X^_{:r} - Q^||^2``:
        the largest basis's residual, the coordinates the r-basis drops, and the
        ROM's own error; no pass over the full fields.
        """
        X = self.coordinates
        r = q_rom.shape[0]
        with np.errstate(over="ignore", invalid="ignore"):
            err2 = self.residual**2 + np.sum(X[r:] ** 2) + np.sum((X[:r] - q_rom) ** 2)
        return float(np.sqrt(err2) / self.norm) if np.isfinite(err2) else float("inf")

    def projection_error(self, r: int) -> float:
        """The best any r-dimensional model in this basis can do: ``||Q - V_r V_r^T W Q||_W / ||Q||_W``."""
        return float(np.sqrt(self.residual**2 + np.sum(self.coordinates[r:] ** 2)) / self.norm)


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
