r"""The first harmonic of a sampled period, and a tested criterion for a periodic steady state.

A response sampled ``N`` times per forcing period, ``y_j = y(t_0 + j T / N)`` for
``j = 1 .. N``, has the first-harmonic phasor (the least-squares fit of a sine and a
cosine over the whole period, which for equally spaced samples is DFT bin 1)

.. math::

    Y = \frac{2 i}{N} \sum_{j=1}^{N} y_j\, e^{-2\pi i j / N},
    \qquad y(t) \approx \operatorname{Im}\big(Y e^{i \omega (t - t_0)}\big)
    = |Y| \sin(\omega (t - t_0) + \arg Y),

so a force ``F sin(omega (t - t_0))`` has phasor ``F`` and ``Y / F`` is the
(first-harmonic) frequency response: ``|Y|`` the amplitude, ``arg Y`` the phase
relative to the force. Harmonic ``h`` aliases onto bin 1 only for ``h = N +- 1``.

Steady state
------------
Period ``k`` gives the phasors ``Y_k`` (p,) of the p outputs and the change
``d_k = Y_k - Y_{k-1}``. A linear transient that decays as ``exp(lambda t)`` makes
``Y_k - Y_inf`` a geometric sequence with the complex ratio ``rho = exp(lambda T)``,
so what is left of it after period ``k`` is

.. math::

    Y_k - Y_\infty = -d_k \frac{\rho}{1 - \rho}, \qquad
    \hat\rho_k = \frac{d_{k-1}^H d_k}{d_{k-1}^H d_{k-1}}.

Near resonance with light damping ``|rho| -> exp(-2 pi zeta)`` and the change per period
understates the remaining transient by ``1 / (2 pi zeta)`` (122 times at ``zeta = 0.13 %``):
a plain "consecutive periods agree" test stops far too early there. The criterion used
here (:class:`SteadyStateCriterion`) therefore accepts period ``k`` when ``k >= min_periods``
and the estimated remaining transient

.. math::

    e_k = \|d_k\| \max\!\Big(1, \frac{|\hat\rho_k|}{|1 - \hat\rho_k|}\Big)
    \le \text{tolerance}\; \|Y_k\|,

with ``|rho_k| < 1`` (a transient that does not shrink is never accepted), or when the
change is at round-off (``||d_k|| <= 1e-12 ||Y_k||``). Norms are Euclidean over the outputs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError

#: A change this small relative to the response is round-off: steady whatever the ratio.
ROUNDOFF_CHANGE = 1e-12


def first_harmonic(samples) -> np.ndarray:
    r"""(p,) complex ndarray ``Y``: the first-harmonic phasors of one whole sampled period.

    Parameters
    ----------
    samples : (p, N) or (N,) array_like
        ``y_j`` at ``t_0 + j T / N``, ``j = 1 .. N`` (the period's last sample is at ``t_0 + T``).

    Returns
    -------
    (p,) complex ndarray (a 0-d array for (N,) input)
        ``Y = (2 i / N) sum_j y_j exp(-2 pi i j / N)``: ``y ~ |Y| sin(omega (t - t_0) + arg Y)``.
    """
    y = np.asarray(samples, dtype=float)
    n = y.shape[-1]
    if n < 3:
        raise FemromValueError(f"samples need at least 3 points per period, got {n}")
    kernel = np.exp(-2j * np.pi * np.arange(1, n + 1) / n)
    return (2j / n) * (y @ kernel)


@dataclass(frozen=True)
class SteadyStateCriterion:
    """When a forced response has settled: see the module docstring for the test.

    Attributes
    ----------
    tolerance : float
        Relative bound on the estimated transient left in the last period's phasors
        (``0 < tolerance < 1``). The amplitude then errs by at most about ``tolerance``
        and the phase by about ``tolerance`` radians.
    max_periods : int
        Cap on the periods at one frequency; a run that reaches it is flagged
        (``converged = False``) and warned about.
    min_periods : int
        Periods always run (at least 3: the ratio needs two changes).
    """

    tolerance: float = 1e-4
    max_periods: int = 3000
    min_periods: int = 3

    def __post_init__(self):
        if not (isinstance(self.tolerance, (int, float)) and 0.0 < self.tolerance < 1.0):
            raise FemromValueError(f"tolerance must lie in (0, 1), got {self.tolerance!r}")
        if not (isinstance(self.min_periods, (int, np.integer)) and self.min_periods >= 3):
            raise FemromValueError(f"min_periods must be an integer >= 3, got {self.min_periods!r}")
        if not (isinstance(self.max_periods, (int, np.integer)) and self.max_periods >= self.min_periods):
            raise FemromValueError(f"max_periods must be an integer >= min_periods = {self.min_periods}, "
                             f"got {self.max_periods!r}")

    def monitor(self) -> "SteadyStateMonitor":
        """A fresh monitor for one frequency."""
        return SteadyStateMonitor(self)


class SteadyStateMonitor:
    """Feeds one period's phasors at a time to a :class:`SteadyStateCriterion`.

    Attributes
    ----------
    periods : int
        Periods seen.
    phasors : (p,) complex ndarray or None
        The last period's phasors.
    relative_change : float
        ``||d_k|| / ||Y_k||`` (inf before the second period).
    ratio : complex
        The estimated per-period ratio ``rho_k`` of the transient (nan until known).
    remaining : float
        The estimated remaining transient ``e_k / ||Y_k||`` (inf until known).
    converged : bool
    """

    def __init__(self, criterion: SteadyStateCriterion):
        self.criterion = criterion
        self.periods = 0
        self.phasors: np.ndarray | None = None
        self._change: np.ndarray | None = None
        self.relative_change = math.inf
        self.ratio: complex = complex(math.nan, math.nan)
        self.remaining = math.inf
        self.converged = False

    def update(self, phasors) -> bool:
        """Take period ``k``'s (p,) phasors; return whether the response is steady now."""
        Y = np.atleast_1d(np.asarray(phasors, dtype=complex))
        self.periods += 1
        previous, previous_change, self.phasors = self.phasors, self._change, Y
        if previous is None:
            return False
        change = Y - previous
        self._change = change
        size = float(np.linalg.norm(Y))
        change_norm = float(np.linalg.norm(change))
        self.relative_change = change_norm / size if size > 0 else (0.0 if change_norm == 0 else math.inf)
        if previous_change is not None:
            denominator = complex(np.vdot(previous_change, previous_change))
            if denominator != 0:
                self.ratio = complex(np.vdot(previous_change, change)) / denominator
        rho = self.ratio
        if self.relative_change <= ROUNDOFF_CHANGE:
            self.remaining = self.relative_change
        elif math.isfinite(abs(rho)) and abs(rho) < 1.0:
            self.remaining = self.relative_change * max(1.0, abs(rho) / abs(1.0 - rho))
        else:
            self.remaining = math.inf
        self.converged = (self.periods >= self.criterion.min_periods
                          and self.remaining <= self.criterion.tolerance)
        return self.converged
