r"""A cheap look at a system's scales before a run: refuse what double precision cannot hold, warn what the step cannot resolve.

Two numbers, both from the matrices' entries (no factorisation, no eigensolver):

- the scales ``s_K = max |K_ij|`` and ``s_M = max |M_ij|``. Energies and norms
  square the states and multiply them by these entries; with ``s`` beyond
  ``1e150`` (or a largest entry below ``1e-150``) the squares leave double
  precision (``1.8e308``, ``2.2e-308``) and a run returns ``inf``, ``0`` or
  ``1e260``-sized energies. Such a system is refused (:class:`ConditioningError`):
  it comes from a modulus, density or length in the wrong units;
- the stiffest dof's frequency ``omega_diag = sqrt(max_i K_ii / M_ii)`` over the
  dofs with ``M_ii > 0``. It is a Rayleigh quotient ``e_i^T K e_i / e_i^T M e_i``,
  hence a lower bound of ``omega_max``; on finite-element matrices it is within
  a small factor of it. When ``omega_diag dt`` exceeds ``1e6`` the step is a
  million radians of the stiffest motion: an implicit scheme stays stable, but
  the run resolves only modes a million times slower than the mesh's own, which
  for a structure's usual parameters (steel, ``dt`` of a thousandth of the first
  period, ``omega_diag dt`` from 0.7 (sine-Gordon) to 150 (beam) and 920 (small fishtail)) means a
  density or modulus off by many orders of magnitude. A
  :class:`ConditioningWarning` says so before the run.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError

#: Largest (and, inverted, smallest) matrix scale whose squares double precision still holds.
SCALE_LIMIT = 1e150
#: ``omega_diag dt`` above which the step resolves nothing of the mesh's dynamics.
OMEGA_DT_LIMIT = 1e6


class ConditioningError(FemromValueError):
    """A system whose scales a double-precision run cannot carry."""


class ConditioningWarning(UserWarning):
    """A run that will compute, but whose step or scales make the result doubtful."""


@dataclass(frozen=True)
class Conditioning:
    """The scales of ``(K, M)`` and the step.

    Attributes
    ----------
    stiffness_scale, mass_scale : float
        ``max |K_ij|``, ``max |M_ij|``.
    omega_diag : float
        ``sqrt(max_i K_ii / M_ii)`` (rad/s), a lower bound of ``omega_max``.
    omega_dt : float
        ``omega_diag * dt``.
    """

    stiffness_scale: float
    mass_scale: float
    omega_diag: float
    omega_dt: float


def _scale(matrix) -> float:
    data = matrix.data if sp.issparse(matrix) else np.asarray(matrix)
    return float(np.max(np.abs(data))) if data.size else 0.0


def check_conditioning(system, dt: float, *, warn: bool = True) -> Conditioning:
    """Refuse a system double precision cannot hold; warn when ``dt`` resolves nothing.

    Parameters
    ----------
    system : SecondOrderSystem
        Its ``stiffness`` and ``mass`` (n, n).
    dt : float
        The time step (s).
    warn : bool
        Issue the :class:`ConditioningWarning` (otherwise only return the numbers).

    Raises
    ------
    ConditioningError
        Non-finite entries, or a scale outside ``[1e-150, 1e150]`` (module docstring).
    """
    scales = {}
    for name, matrix in (("stiffness", system.stiffness), ("mass", system.mass)):
        s = _scale(matrix)
        if not np.isfinite(s):
            raise ConditioningError(f"the {name} matrix has non-finite entries: check the material "
                                    f"parameters and the mesh")
        if s > SCALE_LIMIT or 0.0 < s < 1.0 / SCALE_LIMIT:
            raise ConditioningError(
                f"the {name} matrix's entries reach {s:.3g}, outside [1e-150, 1e150]: energies and norms "
                f"square them past double precision; a modulus, density or length is in the wrong units")
        scales[name] = s
    k_diag = np.asarray(system.stiffness.diagonal(), dtype=float)
    m_diag = np.asarray(system.mass.diagonal(), dtype=float)
    massive = m_diag > 0.0
    ratio = k_diag[massive] / m_diag[massive]
    omega = float(np.sqrt(max(float(ratio.max()), 0.0))) if ratio.size else 0.0
    report = Conditioning(scales["stiffness"], scales["mass"], omega, omega * float(dt))
    if warn and report.omega_dt > OMEGA_DT_LIMIT:
        warnings.warn(
            f"dt = {dt:.3g} s is {report.omega_dt:.2g} radians of the stiffest dof's motion "
            f"(omega >= {omega:.3g} rad/s): the run resolves only modes over 1e6 times slower than the "
            f"mesh's; check the units of the density and the moduli", ConditioningWarning, stacklevel=3)
    return report
