"""Public test data fetched on request (femrom.post.fetch_dataset, ``femrom data``), without internet.

A local HTTP server stands in for GitHub: it serves small ``.mat`` files written here in the
layout of the BRBtesting originals, and the registry entry ``brb`` is pointed at it with
their SHA-256. Checked: the download lands in the cache and is checked, the derived files
are femrom's arrays, a corrupted download is refused in one line naming the file and both
hashes, ``$FEMROM_BRB_DATA`` wins over the cache, missing data is one error saying how to get
them, and the command line. With the offline copy of the real data (``brb_data``), the
fetched path reproduces its ``hammer_impact.npz`` and ``stepped_sine_response_control.csv``.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import http.server
import shutil
import socket
import threading
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.io

from femrom import FemromError
from femrom.cli import main
from femrom.post import (DATASETS, DatasetError, DatasetNotFoundError, brb_data_dir, dataset, dataset_dir,
                         fetch_dataset, read_hammer_impact)

PINNED = DATASETS["brb"]
ORIGINALS = ("HammerImpact.mat", "ForcedFrequencyResponses.mat")
FORCED_FIELDS = ("frequency", "force", "amplitude", "phase", "units")


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_hammer_impact(path: Path, t: np.ndarray, acc: np.ndarray) -> None:
    """``HIdata`` as in HammerImpact.mat: ``time`` and ``acc1..3`` as (1, k) rows."""
    scipy.io.savemat(path, {"HIdata": {"time": t[None, :], "acc1": acc[0][None, :], "acc2": acc[1][None, :],
                                       "acc3": acc[2][None, :], "units": "s, m/s^2"}})


def write_forced_responses(path: Path, table: np.ndarray) -> None:
    """``FRdata.ResponseControl`` as in ForcedFrequencyResponses.mat: a 1 x levels struct array,
    ``frequency`` a (1, n) row and the others (n, 1) columns; ``table`` rows as in the CSV."""
    levels = np.unique(table[:, 0]).astype(int)
    control = np.empty((1, levels.size), dtype=[(name, object) for name in FORCED_FIELDS])
    for level in levels:
        rows = table[table[:, 0] == level]
        control[0, level] = (rows[:, 1][None, :], rows[:, 2][:, None], rows[:, 3][:, None], rows[:, 4][:, None],
                             "Hz, N, m/s^2, rad")
    scipy.io.savemat(path, {"FRdata": {"ResponseControl": control, "ForceControl": control}})


def read_table(path: Path) -> np.ndarray:
    with open(path, newline="") as stream:
        rows = list(csv.reader(stream))
    assert rows[0] == ["level_index", "frequency_Hz", "force_amp_N", "accel3_amp_mps2", "phase_rad"]
    return np.array(rows[1:], dtype=float)


class Server:
    """A folder served over HTTP on 127.0.0.1; ``requests`` lists the paths asked for."""

    def __init__(self, folder: Path):
        self.folder, self.requests = folder, []
        server = self

        class Handler(http.server.SimpleHTTPRequestHandler):
            def __init__(self, *args, **kwargs):
                super().__init__(*args, directory=str(folder), **kwargs)

            def log_message(self, *args):
                server.requests.append(self.path)

        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self.thread.start()

    def close(self):
        self.httpd.shutdown()
        self.httpd.server_close()
        self.thread.join()


@pytest.fixture
def env(tmp_path, monkeypatch):
    """An empty cache, no offline copy, no proxy for the local server."""
    monkeypatch.setenv("FEMROM_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("FEMROM_BRB_DATA", raising=False)
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")
    monkeypatch.setenv("no_proxy", "127.0.0.1,localhost")
    return tmp_path / "cache" / "data" / "brb"


@pytest.fixture
def served(tmp_path, monkeypatch, env):
    """Synthetic originals on a local server, the ``brb`` entry pinned to their hashes."""
    folder = tmp_path / "served"
    folder.mkdir()
    rng = np.random.default_rng(0)
    t = -0.01 + np.arange(256) / 12800.0
    acc = rng.standard_normal((3, t.size))
    write_hammer_impact(folder / "HammerImpact.mat", t, acc)
    table = np.array([[level, 79.0 + 0.05 * k, 0.3 + 0.01 * k, 5.0 + 10 * level, -0.1 - 0.07 * k]
                      for level in range(3) for k in range(4)])
    write_forced_responses(folder / "ForcedFrequencyResponses.mat", table)
    server = Server(folder)
    monkeypatch.setitem(DATASETS, "brb", dataclasses.replace(
        PINNED, base_url=server.url, files={name: sha256(folder / name) for name in ORIGINALS}))
    yield SimpleNamespace(server=server, folder=folder, cache=env, t=t, acc=acc, table=table)
    server.close()


def test_the_registry_pins_the_public_repository_at_one_commit():
    assert dataset("brb") is PINNED and set(PINNED.files) == set(ORIGINALS)
    assert PINNED.url("HammerImpact.mat") == ("https://raw.githubusercontent.com/mattiacenedese/BRBtesting/"
                                              "2d42d3a618206da58642674d3287ae34dfc7d5e5/HammerImpact.mat")
    assert all(len(digest) == 64 and int(digest, 16) >= 0 for digest in PINNED.files.values())


def test_fetch_downloads_into_the_cache_checks_and_derives_then_reuses_the_cache(served):
    folder = fetch_dataset("brb")
    assert folder == served.cache
    for name in ORIGINALS:
        assert sha256(folder / name) == sha256(served.folder / name)
    with np.load(folder / "hammer_impact.npz") as arrays:
        assert np.array_equal(arrays["t"], served.t) and np.array_equal(arrays["acc"], served.acc)
        assert list(arrays["channels"]) == ["acc1", "acc2", "acc3"] and float(arrays["fs"]) == 12800.0
    table = read_table(folder / "stepped_sine_response_control.csv")
    # the CSV keeps six significant digits
    assert np.allclose(table, served.table, rtol=5e-6, atol=0)
    # the readers find the fetched copy
    assert brb_data_dir() == folder and dataset_dir("brb") == folder
    assert read_hammer_impact().sample_rate == 12800.0
    assert sorted(served.server.requests) == sorted(f"/{name}" for name in ORIGINALS)
    # a second fetch finds both files with their checksums and downloads nothing
    assert fetch_dataset("brb") == folder and len(served.server.requests) == 2
    # a cached original altered afterwards is downloaded again
    (folder / "HammerImpact.mat").write_bytes(b"not the file")
    fetch_dataset("brb")
    assert served.server.requests[2:] == ["/HammerImpact.mat"]
    assert sha256(folder / "HammerImpact.mat") == sha256(served.folder / "HammerImpact.mat")


def test_the_derived_files_are_rewritten_from_cached_originals(served):
    folder = fetch_dataset("brb")
    (folder / "hammer_impact.npz").unlink()
    assert brb_data_dir() == folder      # the originals are there: derived again, nothing downloaded
    assert (folder / "hammer_impact.npz").is_file() and len(served.server.requests) == 2


def test_a_corrupted_download_is_refused_in_one_line_naming_the_file_and_both_hashes(served):
    good = DATASETS["brb"].files["ForcedFrequencyResponses.mat"]
    corrupted = served.folder / "ForcedFrequencyResponses.mat"
    corrupted.write_bytes(corrupted.read_bytes()[:-7] + b"garbage")
    with pytest.raises(DatasetError) as error:
        fetch_dataset("brb")
    message = str(error.value)
    assert "\n" not in message and isinstance(error.value, FemromError)
    assert message.startswith("ForcedFrequencyResponses.mat: ")
    assert good in message and sha256(corrupted) in message and good != sha256(corrupted)
    # nothing half-checked is kept, and the readers still say the data are missing
    assert not (served.cache / "ForcedFrequencyResponses.mat").exists()
    assert not (served.cache / "stepped_sine_response_control.csv").exists()
    with pytest.raises(DatasetNotFoundError):
        brb_data_dir()


def test_no_network_is_one_line_that_names_the_way_around(env, monkeypatch):
    with socket.socket() as probe:        # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    monkeypatch.setitem(DATASETS, "brb", dataclasses.replace(PINNED, base_url=f"http://127.0.0.1:{port}"))
    with pytest.raises(DatasetError) as error:
        fetch_dataset("brb")
    message = str(error.value)
    assert "\n" not in message and message.startswith("HammerImpact.mat: could not download")
    assert "FEMROM_BRB_DATA" in message


def test_the_environment_variable_wins_over_the_cache(served, tmp_path, monkeypatch):
    fetched = fetch_dataset("brb")
    offline = tmp_path / "offline"
    offline.mkdir()
    monkeypatch.setenv("FEMROM_BRB_DATA", str(offline))
    assert brb_data_dir() == offline and fetched != offline
    with pytest.raises(DatasetNotFoundError, match="hammer_impact.npz"):
        read_hammer_impact()          # the offline folder is read, not the cache
    # a variable naming no folder is an error, never a silent fall-back to the cache
    monkeypatch.setenv("FEMROM_BRB_DATA", str(tmp_path / "nowhere"))
    with pytest.raises(DatasetNotFoundError) as error:
        brb_data_dir()
    assert "FEMROM_BRB_DATA" in str(error.value) and str(tmp_path / "nowhere") in str(error.value)
    monkeypatch.setenv("FEMROM_BRB_DATA", "")           # set but empty: unset
    assert brb_data_dir() == fetched


def test_missing_data_is_one_error_saying_how_to_get_them(env, tmp_path, capsys):
    with pytest.raises(DatasetNotFoundError) as error:
        brb_data_dir()
    message = str(error.value)
    assert isinstance(error.value, FileNotFoundError) and isinstance(error.value, FemromError)
    assert "femrom data fetch brb" in message and "FEMROM_BRB_DATA" in message and str(env) in message
    with pytest.raises(DatasetNotFoundError, match="femrom data fetch brb"):
        read_hammer_impact()
    # the case that needs them stops in one line
    assert main(["run", "jointed_beam_measured", "-o", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("femrom: ") and "femrom data fetch brb" in lines[0]
    assert not (tmp_path / "out").exists()


def test_an_unknown_name_lists_the_known_ones(env, capsys):
    with pytest.raises(DatasetError, match=r"unknown data set 'nope'; known: brb"):
        fetch_dataset("nope")
    for command in ("fetch", "path"):
        assert main(["data", command, "nope"]) == 2
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err == "femrom: unknown data set 'nope'; known: brb\n"


def test_the_command_line_fetches_and_prints_the_folder(served, monkeypatch, capsys):
    monkeypatch.setenv("FEMROM_PROGRESS_SECONDS", "0")     # every progress line, in a log
    monkeypatch.delenv("FEMROM_NO_PROGRESS", raising=False)
    assert main(["data", "fetch", "brb"]) == 0
    captured = capsys.readouterr()
    assert captured.out.strip().endswith(f"in {served.cache}") and "SHA-256 checked" in captured.out
    size = (served.folder / "HammerImpact.mat").stat().st_size
    assert f"femrom: HammerImpact.mat: downloading {served.server.url}/HammerImpact.mat" in captured.err
    assert f"HammerImpact.mat [bytes]: {size}/{size}" in captured.err       # the byte count, to the end
    assert main(["data", "path", "brb"]) == 0
    assert capsys.readouterr().out == f"{served.cache}\n"
    assert main(["data", "list"]) == 0
    assert capsys.readouterr().out.startswith("brb  jointed-beam test data: HammerImpact.mat")
    # fetching while the variable is set says which copy femrom will read
    monkeypatch.setenv("FEMROM_BRB_DATA", str(served.folder))
    assert main(["data", "fetch", "brb"]) == 0
    assert f"FEMROM_BRB_DATA is set, so femrom reads {served.folder}" in capsys.readouterr().err


def test_the_fetched_path_reproduces_the_offline_copy(brb_data, tmp_path, monkeypatch, env):
    """The offline copy's original HammerImpact.mat, served, has the pinned SHA-256, and femrom's
    own code makes the offline copy's hammer_impact.npz from it, array for array. The offline copy
    holds only the CSV of ForcedFrequencyResponses.mat (its GPL-3.0 original stays out of this
    repository): a .mat of the same layout written from that CSV gives back the CSV byte for byte."""
    folder = tmp_path / "served"
    folder.mkdir()
    shutil.copyfile(brb_data / "HammerImpact.mat", folder / "HammerImpact.mat")
    assert sha256(folder / "HammerImpact.mat") == PINNED.files["HammerImpact.mat"]
    write_forced_responses(folder / "ForcedFrequencyResponses.mat",
                           read_table(brb_data / "stepped_sine_response_control.csv"))
    server = Server(folder)
    try:
        monkeypatch.setitem(DATASETS, "brb", dataclasses.replace(PINNED, base_url=server.url, files={
            "HammerImpact.mat": PINNED.files["HammerImpact.mat"],
            "ForcedFrequencyResponses.mat": sha256(folder / "ForcedFrequencyResponses.mat")}))
        fetched = fetch_dataset("brb")
    finally:
        server.close()
    with np.load(fetched / "hammer_impact.npz") as mine, np.load(brb_data / "hammer_impact.npz") as offline:
        assert set(mine.files) == set(offline.files)
        for key in offline.files:
            assert np.array_equal(mine[key], offline[key]), key
    assert ((fetched / "stepped_sine_response_control.csv").read_bytes()
            == (brb_data / "stepped_sine_response_control.csv").read_bytes())
