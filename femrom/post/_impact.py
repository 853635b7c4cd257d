r"""The hammer-impact ring-down of the jointed (half Brake-Reuss) beam, read where it lies.

The measured data (Chen et al., MSSP 166:108401, 2022; public repository
``mattiacenedese/BRBtesting``, GPL-3.0) stay outside the repository: code takes
their path as a parameter, by default :func:`brb_data_dir` (``$FEMROM_BRB_DATA``, else
the copy ``femrom data fetch brb`` put in the cache: :mod:`femrom.post._datasets`). The file
``hammer_impact.npz`` holds ``t`` (k,) [s], sampled at 12,800 Hz from -0.01 s
(10 ms pre-trigger), and ``acc`` (3, k) [m/s^2], rows acc1, acc2, acc3
(see the README.md next to it).

:func:`measured_backbone` applies the processing of femrom issue 16 to one channel:
the post-trigger record (``t >= 0``), band 60-100 Hz around the first bending mode
(about 80.5 Hz), 0.2 s windows, :func:`~femrom.post.hilbert_backbone` with its
default trim (0.25 s at each end, the band-pass transients).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom._errors import FemromValueError
from femrom.post._backbone import Backbone, hilbert_backbone, peak_backbone, spectral_peaks
from femrom.post._datasets import HAMMER_IMPACT_FILE, DatasetNotFoundError, dataset_dir

#: The mode-1 band and window of femrom issue 16 [Hz], [s].
MODE1_BAND = (60.0, 100.0)
MODE1_WINDOW = 0.2


def brb_data_dir() -> Path:
    """Folder of the jointed-beam data: ``$FEMROM_BRB_DATA`` (an offline copy) if set, else the
    copy ``femrom data fetch brb`` put in the cache (:func:`~femrom.post.dataset_dir`).

    Raises
    ------
    DatasetNotFoundError
        (a ``FileNotFoundError``) The variable names no folder, or nothing was fetched; the message
        says to run ``femrom data fetch brb`` or to set the variable.
    """
    return dataset_dir("brb")


@dataclass(frozen=True)
class ImpactRecord:
    """One hammer-impact test: accelerations at the sensors over time.

    Attributes
    ----------
    time : (k,) ndarray
        Seconds; the impact at ``t = 0`` (pre-trigger samples have ``t < 0``).
    acceleration : (c, k) ndarray
        [m/s^2], one row per channel.
    channels : tuple of str
        Row names ("acc1", "acc2", "acc3").
    sample_rate : float
        [Hz].
    source : str
        File read.
    """

    time: np.ndarray
    acceleration: np.ndarray
    channels: tuple
    sample_rate: float
    source: str = ""

    def channel(self, name: str) -> np.ndarray:
        """(k,) samples of channel ``name``."""
        if name not in self.channels:
            raise FemromValueError(f"channel must be one of {', '.join(self.channels)}, got {name!r}")
        return self.acceleration[self.channels.index(name)]

    def post_trigger(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(t, a)`` of channel ``name`` from the impact on (``t >= 0``), each (k0,)."""
        keep = self.time >= 0
        return self.time[keep], self.channel(name)[keep]


def read_hammer_impact(path=None) -> ImpactRecord:
    """Read the jointed beam's hammer-impact record.

    Parameters
    ----------
    path : str or Path, optional
        The ``.npz`` file, or a folder holding ``hammer_impact.npz``; default
        :func:`brb_data_dir`.

    Raises
    ------
    DatasetNotFoundError
        (a ``FileNotFoundError``) No such file, or no data folder (:func:`brb_data_dir`).
    FemromValueError
        The file lacks ``t``/``acc``, their shapes disagree, samples are non-finite or
        the times are not uniformly increasing.
    """
    path = Path(path) if path is not None else brb_data_dir()
    if path.is_dir():
        path = path / HAMMER_IMPACT_FILE
    if not path.is_file():
        raise DatasetNotFoundError(f"hammer-impact file {path} not found")
    with np.load(path, allow_pickle=False) as data:
        missing = [key for key in ("t", "acc") if key not in data.files]
        if missing:
            raise FemromValueError(f"{path}: missing arrays {missing} (has {data.files})")
        time = np.array(data["t"], dtype=float)
        acceleration = np.atleast_2d(np.array(data["acc"], dtype=float))
        channels = (tuple(str(c) for c in data["channels"]) if "channels" in data.files
                    else tuple(f"acc{i + 1}" for i in range(acceleration.shape[0])))
    if time.ndim != 1 or acceleration.shape[1:] != time.shape or len(channels) != acceleration.shape[0]:
        raise FemromValueError(f"{path}: t {time.shape}, acc {acceleration.shape} and {len(channels)} channel "
                               "names do not match (expected t (k,), acc (c, k))")
    if not (np.all(np.isfinite(time)) and np.all(np.isfinite(acceleration))):
        raise FemromValueError(f"{path}: non-finite samples")
    steps = np.diff(time)
    step = float(np.mean(steps))
    if time.size < 2 or not (step > 0 and np.ptp(steps) <= 1e-9 * step):
        raise FemromValueError(f"{path}: t must be uniformly increasing (steps {steps.min():g}..{steps.max():g} s)")
    for array in (time, acceleration):
        array.setflags(write=False)
    return ImpactRecord(time=time, acceleration=acceleration, channels=channels,
                        sample_rate=float(round(1 / step, 6)), source=str(path))


def measured_backbone(record: ImpactRecord | None = None, *, channel: str = "acc1", band=MODE1_BAND,
                      window: float = MODE1_WINDOW, overlap: float = 0.0, trim: float | None = None,
                      method: str = "hilbert", cycles: int = 16) -> Backbone:
    """Backbone of the beam's first bending mode at one sensor (issue 16's processing).

    Parameters
    ----------
    record : ImpactRecord, optional
        Default: :func:`read_hammer_impact` of the default folder.
    channel : str
    band, window, overlap, trim
        As in :func:`~femrom.post.hilbert_backbone` (window and overlap only for
        ``method="hilbert"``); default 60-100 Hz, 0.2 s windows without overlap,
        the default trim.
    method : {"hilbert", "peaks"}
        The estimator; "peaks" is :func:`~femrom.post.peak_backbone` with ``cycles``.

    Returns
    -------
    Backbone
        Amplitudes in m/s^2, times from the impact.
    """
    record = read_hammer_impact() if record is None else record
    t, a = record.post_trigger(channel)
    if method == "hilbert":
        return hilbert_backbone(a, record.sample_rate, band, window=window, overlap=overlap, trim=trim,
                                start_time=float(t[0]))
    if method == "peaks":
        return peak_backbone(a, record.sample_rate, band, cycles=cycles, trim=trim, start_time=float(t[0]))
    raise FemromValueError(f"method must be 'hilbert' or 'peaks', got {method!r}")


def measured_spectral_peaks(record: ImpactRecord | None = None, *, channel: str = "acc1", **options) -> np.ndarray:
    """(p,) peak frequencies [Hz] of one channel's post-trigger record
    (:func:`~femrom.post.spectral_peaks` with ``options``)."""
    record = read_hammer_impact() if record is None else record
    _, a = record.post_trigger(channel)
    return spectral_peaks(a, record.sample_rate, **options)
