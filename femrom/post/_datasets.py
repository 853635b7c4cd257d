r"""Public test data femrom fetches on request: pinned, checksummed, cached, never in the repository.

A data set is a few files of a public repository at one commit (:class:`Dataset`), each
with its SHA-256. :func:`fetch_dataset` downloads them with pooch into the user's cache
(``$FEMROM_CACHE/data/<name>``, default ``~/.cache/femrom/data/<name>``, beside the mesh
cache), refuses a file whose checksum differs, and writes the arrays femrom reads
(:attr:`Dataset.derived`) from the originals with femrom's own code.
:func:`dataset_dir` finds a data set: the folder named by its environment variable (an
offline copy) if that is set, else the fetched copy in the cache, else one error saying
how to get it (``femrom data fetch NAME``).

The one data set, ``brb``: the jointed (half Brake-Reuss) beam's tests, public repository
``mattiacenedese/BRBtesting`` (GPL-3.0; Chen et al., MSSP 166:108401, and Jin et al.,
MSSP 166:108402, 2022). femrom is MIT: the files stay in the user's cache.

- ``HammerImpact.mat`` (``HIdata``: ``time``, ``acc1``..``acc3``) -> ``hammer_impact.npz``:
  ``t`` (k,) [s], ``acc`` (3, k) [m/s^2], ``fs`` [Hz], ``channels``, ``units``
  (read by :func:`~femrom.post.read_hammer_impact`).
- ``ForcedFrequencyResponses.mat`` (``FRdata.ResponseControl``, 1 x 8 levels of a stepped
  sine at constant acc3 amplitude) -> ``stepped_sine_response_control.csv``: columns
  ``level_index, frequency_Hz, force_amp_N, accel3_amp_mps2, phase_rad``, one row per step.
"""

from __future__ import annotations

import hashlib
import logging
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femrom._errors import FemromValueError
from femrom._progress import Progress

#: Environment variable naming an offline copy of the jointed-beam data (a folder).
BRB_DATA_ENV = "FEMROM_BRB_DATA"
#: The impact record's file name inside that folder.
HAMMER_IMPACT_FILE = "hammer_impact.npz"
#: The response-controlled stepped sine's file name inside that folder.
STEPPED_SINE_FILE = "stepped_sine_response_control.csv"
#: Seconds pooch waits for the server before it gives up.
DOWNLOAD_TIMEOUT = 60


class DatasetError(FemromValueError):
    """A data set that cannot be used: an unknown name, a download that failed or whose
    checksum differs, an original that does not hold what femrom expects."""


class DatasetNotFoundError(DatasetError, FileNotFoundError):
    """A data set (or one of its files) that is not on this machine; the message says how to get it."""


@dataclass(frozen=True)
class Dataset:
    """Files of one public repository at one commit, and what femrom makes of them.

    Attributes
    ----------
    name : str
        What ``femrom data fetch NAME`` calls it.
    title : str
        What it is, for messages.
    repository : str
        ``owner/name`` on GitHub.
    commit : str
        The pinned commit (40 hex digits).
    licence : str
        The data's licence (they are never copied into femrom).
    files : mapping of str to str
        Repository path -> SHA-256 of its bytes at that commit.
    environment : str
        Variable naming an offline copy (a folder holding :attr:`derived`).
    derived : tuple of str
        The files femrom writes from the originals, in the same folder.
    derive : callable
        ``derive(folder)`` writes :attr:`derived` from the originals in ``folder``.
    base_url : str, optional
        Where the files are served; default the commit's raw GitHub address.
    """

    name: str
    title: str
    repository: str
    commit: str
    licence: str
    files: Mapping[str, str]
    environment: str
    derived: tuple
    derive: Callable[[Path], None]
    base_url: str | None = None

    def url(self, file: str) -> str:
        base = self.base_url or f"https://raw.githubusercontent.com/{self.repository}/{self.commit}"
        return f"{base.rstrip('/')}/{file}"

    @property
    def source(self) -> str:
        return f"github.com/{self.repository} at {self.commit[:7]}, {self.licence}"


def data_cache_dir() -> Path:
    """``$FEMROM_CACHE/data``, or ``~/.cache/femrom/data`` when the variable is unset."""
    root = os.environ.get("FEMROM_CACHE") or Path.home() / ".cache" / "femrom"
    return Path(root).expanduser() / "data"


def _write_atomically(path: Path, write: Callable[[object], None]) -> None:
    """``write(stream)`` into a temporary file beside ``path``, then rename it onto ``path``:
    a reader never sees half a file."""
    tmp = path.with_name(f".{path.name}.part")
    try:
        with open(tmp, "wb") as stream:
            write(stream)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _mat_struct(path: Path, variable: str):
    """The MATLAB struct ``variable`` of a ``.mat`` file (a numpy record)."""
    import scipy.io

    try:
        return scipy.io.loadmat(path)[variable][0, 0]
    except (KeyError, IndexError, ValueError, OSError) as exc:
        raise DatasetError(f"{path}: no MATLAB struct {variable!r} ({type(exc).__name__}: {exc})") from None


def _fields(path: Path, record, names) -> list:
    """The fields ``names`` of a struct as flat float arrays; one error naming the file otherwise."""
    try:
        return [np.asarray(record[name], dtype=float).ravel() for name in names]
    except (KeyError, ValueError, TypeError) as exc:
        raise DatasetError(f"{path}: the struct lacks a field femrom reads ({type(exc).__name__}: {exc})") from None


def _derive_brb(folder: Path) -> None:
    """``hammer_impact.npz`` and ``stepped_sine_response_control.csv`` from the two ``.mat`` files."""
    impact_file, forced_file = folder / "HammerImpact.mat", folder / "ForcedFrequencyResponses.mat"
    channels = ("acc1", "acc2", "acc3")
    t, *acc = _fields(impact_file, _mat_struct(impact_file, "HIdata"), ("time",) + channels)
    _write_atomically(folder / HAMMER_IMPACT_FILE, lambda stream: np.savez_compressed(
        stream, t=t, acc=np.vstack(acc), fs=np.float64(round(1 / np.mean(np.diff(t)), 6)),
        channels=np.array(channels), units=np.array(["s", "m/s^2"])))

    levels = _mat_struct(forced_file, "FRdata")
    try:
        levels = levels["ResponseControl"]
    except (KeyError, ValueError):
        raise DatasetError(f"{forced_file}: FRdata has no ResponseControl") from None
    rows = ["level_index,frequency_Hz,force_amp_N,accel3_amp_mps2,phase_rad"]
    for level in range(levels.shape[1]):
        columns = _fields(forced_file, levels[0, level], ("frequency", "force", "amplitude", "phase"))
        if len({c.size for c in columns}) != 1:
            raise DatasetError(f"{forced_file}: ResponseControl level {level} has {[c.size for c in columns]} "
                               "frequencies, forces, amplitudes and phases")
        # the offline copy's precision: 0.1 mHz steps, six significant digits
        rows += [f"{level},{f:.4f},{force:.6g},{a:.6g},{phase:.6g}" for f, force, a, phase in zip(*columns)]
    _write_atomically(folder / STEPPED_SINE_FILE, lambda stream: stream.write(("\n".join(rows) + "\n").encode()))


#: The data sets femrom knows, by name.
DATASETS: dict[str, Dataset] = {
    "brb": Dataset(
        name="brb", title="jointed-beam test data", repository="mattiacenedese/BRBtesting",
        commit="2d42d3a618206da58642674d3287ae34dfc7d5e5", licence="GPL-3.0",
        files={"HammerImpact.mat": "26b014dac30ed69b0a97aa3bb62bfb240de83e679502c15782465cd60a339189",
               "ForcedFrequencyResponses.mat": "e4bfe248b921edbd23153c24a37c3a9e1556fb1bf59fe6d9e63ae8e2177f1100"},
        environment=BRB_DATA_ENV, derived=(HAMMER_IMPACT_FILE, STEPPED_SINE_FILE), derive=_derive_brb),
}


def dataset(name: str) -> Dataset:
    """The registered data set ``name``; one error listing the known names otherwise."""
    if name not in DATASETS:
        raise DatasetError(f"unknown data set {name!r}; known: {', '.join(sorted(DATASETS))}")
    return DATASETS[name]


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


class _DownloadProgress(Progress):
    """femrom's progress line as pooch's progress bar (pooch sets ``total`` and calls ``reset``)."""

    def reset(self) -> None:
        self.done = 0


def _download(data: Dataset, file: str, folder: Path, say: Callable[[str], None]) -> None:
    """One original into ``folder``, checked; pooch leaves a file whose checksum matches alone."""
    import pooch
    import requests

    url, expected = data.url(file), data.files[file]
    target = folder / file
    if target.is_file() and _sha256(target) == expected:
        return
    say(f"{file}: downloading {url}")
    http = pooch.HTTPDownloader(progressbar=_DownloadProgress(0, f"{file} [bytes]"), timeout=DOWNLOAD_TIMEOUT)
    received = {}

    def download(url, output_file, pup, check_only=False):
        http(url, output_file, pup, check_only=check_only)
        received["sha256"] = _sha256(Path(output_file))

    logger = pooch.get_logger()
    level = logger.level
    logger.setLevel(logging.WARNING)    # femrom says what it downloads itself
    try:
        pooch.retrieve(url, known_hash=f"sha256:{expected}", fname=file, path=folder, downloader=download)
    except requests.exceptions.HTTPError as exc:
        raise DatasetError(f"{file}: {url} answered HTTP {exc.response.status_code}") from None
    except requests.exceptions.RequestException as exc:
        raise DatasetError(f"{file}: could not download {url} ({type(exc).__name__}: no network?); without "
                           f"network access set {data.environment} to a folder holding an offline copy") from None
    except ValueError as exc:
        if received.get("sha256", expected) == expected:     # not the checksum: say what pooch said
            raise DatasetError(f"{file}: {url}: {str(exc).splitlines()[0]}") from None
        raise DatasetError(f"{file}: SHA-256 {received['sha256']} of the download from {url} is not the pinned "
                           f"{expected}; the file was not kept") from None
    finally:
        logger.setLevel(level)


def fetch_dataset(name: str, *, progress: Callable[[str], None] | None = None) -> Path:
    """Download the data set ``name`` into the cache, check each file's SHA-256, and write the
    derived files; files already there with the right checksum are not downloaded again.

    Parameters
    ----------
    name : str
        A key of :data:`DATASETS`.
    progress : callable, optional
        Called with one line per file downloaded (the bytes have femrom's progress line).

    Returns
    -------
    Path
        The folder, ``data_cache_dir() / name``.

    Raises
    ------
    DatasetError
        An unknown name, a failed download (no network, an HTTP error), or a checksum that
        differs (the file is not kept; the message names it and both hashes).
    """
    data = dataset(name)
    folder = data_cache_dir() / name
    folder.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda line: None)
    for file in data.files:
        _download(data, file, folder, say)
    data.derive(folder)
    return folder


def dataset_dir(name: str) -> Path:
    """The folder femrom reads the data set ``name`` from: ``$<its variable>`` if set (an
    offline copy), else the fetched copy in the cache (the derived files written if missing).

    Raises
    ------
    DatasetError
        An unknown name.
    DatasetNotFoundError
        The variable names no folder, or nothing is fetched; the message says how to get the data.
    """
    data = dataset(name)
    configured = os.environ.get(data.environment)
    if configured:
        folder = Path(configured).expanduser()
        if not folder.is_dir():
            raise DatasetNotFoundError(f"{data.environment}={configured!r} is not a folder; point it at a copy of "
                                       f"the {data.title} ({', '.join(data.derived)}) or unset it and run "
                                       f"`femrom data fetch {name}`")
        return folder
    folder = data_cache_dir() / name
    if all((folder / file).is_file() for file in data.derived):
        return folder
    if all((folder / file).is_file() and _sha256(folder / file) == digest for file, digest in data.files.items()):
        data.derive(folder)
        return folder
    raise DatasetNotFoundError(f"the {data.title} are not on this machine (looked in {folder}): run "
                               f"`femrom data fetch {name}` ({data.source}) or set {data.environment} to a "
                               "folder holding an offline copy")
