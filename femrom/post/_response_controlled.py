r"""The jointed beam's stepped sine at constant response amplitude, read where it lies, and its backbone.

The file ``stepped_sine_response_control.csv`` (:data:`~femrom.post._datasets.STEPPED_SINE_FILE`,
derived by ``femrom data fetch brb`` from ``FRdata.ResponseControl`` of the public repository
``mattiacenedese/BRBtesting``; Chen et al., MSSP 166:108401, 2022) holds, per level of the
controlled acc3 amplitude (5-80 m/s^2) and frequency step, the fundamental harmonics of the
shaker force and of acc3 and their phase. Columns: ``level_index``, ``frequency_Hz``,
``force_amp_N``, ``accel3_amp_mps2``, ``phase_rad`` (response relative to force).

:func:`phase_resonance_backbone` reads the amplitude-dependent mode off each level, the way a
response-controlled test is meant to be read (phase resonance at constant amplitude: the
system is then quasi-linear at that amplitude). A single mode of viscous damping has the phase

.. math::

    \tan\varphi(f) = -\frac{2 \zeta f f_n}{f_n^2 - f^2}
    \quad\Longleftrightarrow\quad
    f_n^2 \sin\varphi + 2 \zeta f_n\, f \cos\varphi = f^2 \sin\varphi,

linear in ``a = f_n^2`` and ``b = 2 zeta f_n``: a least-squares fit over the steps within
``half_width`` of the ``-pi/2`` crossing gives ``f_n = sqrt(a)`` and ``zeta = b / (2 f_n)``, exact
for such a mode whatever the window (a straight line through the phase is not: its slope at
``f_n`` is ``-1 / (zeta f_n)``, but over a window comparable to the half-power band it is biased).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom._errors import FemromValueError
from femrom.post._backbone import Backbone
from femrom.post._datasets import STEPPED_SINE_FILE, DatasetNotFoundError, dataset_dir

COLUMNS = ("level_index", "frequency_Hz", "force_amp_N", "accel3_amp_mps2", "phase_rad")


@dataclass(frozen=True)
class SteppedSineLevel:
    """One level of a response-controlled stepped sine: per frequency step (k,) arrays.

    Attributes
    ----------
    frequency_hz, force_n, amplitude_m_s2, phase_rad : (k,) ndarray
        Excitation frequency, fundamental force amplitude, fundamental response amplitude (the
        controlled quantity), response phase relative to the force.
    """

    frequency_hz: np.ndarray
    force_n: np.ndarray
    amplitude_m_s2: np.ndarray
    phase_rad: np.ndarray

    @property
    def level_m_s2(self) -> float:
        """The controlled amplitude: the median of the response amplitudes."""
        return float(np.median(self.amplitude_m_s2))


def read_response_controlled(path=None) -> list[SteppedSineLevel]:
    """The levels of the jointed beam's response-controlled stepped sine, lowest level first.

    Parameters
    ----------
    path : str or Path, optional
        The ``.csv`` file or a folder holding it; default the jointed-beam data folder
        (:func:`~femrom.post.brb_data_dir`).

    Raises
    ------
    DatasetNotFoundError
        (a ``FileNotFoundError``) No such file or no data folder.
    FemromValueError
        Wrong columns, non-finite values, or a level whose frequencies do not increase.
    """
    path = Path(path) if path is not None else dataset_dir("brb")
    if path.is_dir():
        path = path / STEPPED_SINE_FILE
    if not path.is_file():
        raise DatasetNotFoundError(f"stepped-sine file {path} not found")
    with open(path, encoding="utf-8") as stream:
        header = tuple(stream.readline().strip().split(","))
        if header != COLUMNS:
            raise FemromValueError(f"{path}: columns must be {','.join(COLUMNS)}, got {','.join(header)}")
        try:
            table = np.loadtxt(stream, delimiter=",", ndmin=2)
        except ValueError as exc:
            raise FemromValueError(f"{path}: not a table of numbers ({exc})") from None
    if table.shape[1] != len(COLUMNS) or not np.all(np.isfinite(table)):
        raise FemromValueError(f"{path}: expected {len(COLUMNS)} finite columns, got shape {table.shape}")
    levels = []
    for index in np.unique(table[:, 0]):
        rows = table[table[:, 0] == index]
        if rows.shape[0] < 3 or np.any(np.diff(rows[:, 1]) <= 0):
            raise FemromValueError(f"{path}: level {index:g} needs at least 3 increasing frequencies")
        levels.append(SteppedSineLevel(*(np.array(rows[:, j]) for j in range(1, 5))))
    return sorted(levels, key=lambda level: level.level_m_s2)


def phase_resonance(level: SteppedSineLevel, *, half_width: float = 0.3) -> tuple[float, float]:
    """``(f_n [Hz], zeta)`` of one level (module docstring); ``half_width`` [Hz] of the fit's window about the
    ``-pi/2`` crossing.

    Raises FemromValueError when the phase does not cross ``-pi/2``, the window holds fewer than 3 steps
    or the fit gives no positive ``f_n^2`` and ``zeta``.
    """
    f, phase = level.frequency_hz, level.phase_rad
    offset = phase + np.pi / 2
    crossing = np.flatnonzero((offset[:-1] > 0) & (offset[1:] <= 0))
    if crossing.size == 0:
        raise FemromValueError(f"the phase of the level at {level.level_m_s2:.3g} m/s^2 does not cross -pi/2")
    k = int(crossing[0])
    f_cross = float(f[k] + (f[k + 1] - f[k]) * offset[k] / (offset[k] - offset[k + 1]))
    near = np.abs(f - f_cross) <= half_width
    if near.sum() < 3:
        raise FemromValueError(f"half_width {half_width!r} Hz holds fewer than 3 steps around {f_cross:.3f} Hz")
    fw, s, c = f[near], np.sin(phase[near]), np.cos(phase[near])
    (a, b), *_ = np.linalg.lstsq(np.column_stack([s, fw * c]), fw * fw * s, rcond=None)
    if not (a > 0 and b > 0):
        raise FemromValueError(f"the phase near {f_cross:.3f} Hz fits no damped mode (f_n^2 {a:.3g}, 2 zeta f_n {b:.3g})")
    f_n = float(np.sqrt(a))
    return f_n, float(b / (2.0 * f_n))


def phase_resonance_backbone(levels, *, half_width: float = 0.3) -> Backbone:
    """The backbone of a response-controlled stepped sine: per level its controlled amplitude, the
    phase-resonance frequency and the phase-slope damping ratio (:func:`phase_resonance`), as a
    :class:`Backbone` of method ``"phase_resonance"`` (``time`` holds the level index)."""
    levels = list(levels)
    rows = [(level.level_m_s2, *phase_resonance(level, half_width=half_width)) for level in levels]
    amplitude, frequency, damping = (np.array(column) for column in zip(*rows))
    return Backbone(np.arange(len(rows), dtype=float), amplitude, frequency, damping, method="phase_resonance")


def resonance_force(level: SteppedSineLevel) -> tuple[float, float]:
    """``(f [Hz], F [N])`` of the level's smallest force: the force a force-controlled test needs to reach
    the level's amplitude at resonance (linear interpolation is not used: the step's own values)."""
    k = int(np.argmin(level.force_n))
    return float(level.frequency_hz[k]), float(level.force_n[k])
