"""Progress of long work: a live line on a terminal, a line every 30 s in a log.

Two reports, both on ``stderr``. On a terminal (a TTY, ``CI`` not set) the line
is redrawn in place; anywhere else (a log file, a pipe, a CI job) a plain line
is appended once every ``FEMROM_PROGRESS_SECONDS`` seconds (default 30), so a
log of a long run shows that it is alive and how far it is, and short work
writes nothing. ``FEMROM_NO_PROGRESS`` silences both.

- :class:`Progress`, for loops of counted steps: steps done, steps per second
  and the estimated time left. Used by the time integrators (one unit per
  step: :func:`femrom.integrators.iterate`) and the randomized SVD (one unit
  per pass over the snapshots).
- :class:`Steps`, for iterations whose number is not known in advance: the step
  reached, a note (e.g. the current gap) and the time so far. Used by the
  L-OpInf interior-point method on large problems
  (:func:`femrom.inference.solve_fast`: 16 min at r = 150).
- :class:`Stage`, for one long call that has no steps to count: a line
  ``label ...`` when it starts and ``label: done in m:ss`` when it ends. Used
  by mesh generation (:func:`femrom.mesh.generate_mesh`, only when gmsh
  actually runs, not on a cache hit: the large solid beam mesh takes about a
  minute) and by scene assembly (:func:`femrom.scene.build`: 6-10 s for the
  stiffness and 15-41 s for the whole benchmark system at 5e5 dofs,
  ``benchmarks/results/fom_ladder.json``).
"""

from __future__ import annotations

import os
import sys
import time
from typing import TextIO

from femrom._errors import FemromValueError


LOG_SECONDS = 30.0


def _mode(stream: TextIO) -> str | None:
    """``"live"`` (redrawn line on a terminal), ``"log"`` (appended lines) or ``None``."""
    if os.environ.get("FEMROM_NO_PROGRESS"):
        return None
    if not os.environ.get("CI") and bool(getattr(stream, "isatty", lambda: False)()):
        return "live"
    return "log"


def _log_seconds() -> float:
    text = os.environ.get("FEMROM_PROGRESS_SECONDS", "")
    try:
        seconds = float(text) if text else LOG_SECONDS
    except ValueError:
        raise FemromValueError(f"FEMROM_PROGRESS_SECONDS must be a number of seconds, got {text!r}") from None
    if not seconds >= 0.0:
        raise FemromValueError(f"FEMROM_PROGRESS_SECONDS must be >= 0, got {text!r}")
    return seconds


def _resolve(enabled: bool | None, stream: TextIO) -> str | None:
    if enabled is None:
        return _mode(stream)
    return "live" if enabled else None


class Progress:
    """Throttled progress line ``label: done/total  rate/s  eta``.

    Parameters
    ----------
    total : int
        Number of units of work.
    label : str
        Text in front of the counter.
    enabled : bool or None
        ``True``: the live line; ``False``: nothing; ``None`` (default): decided
        from the stream (live on a terminal, a line every ``log_seconds`` otherwise).
    min_interval : float
        Seconds between two redraws of the live line.
    log_seconds : float, optional
        Seconds between two appended lines in a log (default ``FEMROM_PROGRESS_SECONDS``
        or 30).
    """

    def __init__(self, total: int, label: str = "", *, enabled: bool | None = None,
                 stream: TextIO | None = None, min_interval: float = 0.25,
                 log_seconds: float | None = None):
        self.total = int(total)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.mode = _resolve(enabled, self.stream)
        self.min_interval = min_interval if self.mode == "live" else (
            _log_seconds() if log_seconds is None else float(log_seconds))
        self.done = 0
        self._start = time.perf_counter()
        self._last = -1.0 if self.mode == "live" else self._start
        self._logged = False

    @property
    def enabled(self) -> bool:
        return self.mode is not None

    def update(self, n: int = 1) -> None:
        self.done += n
        if self.mode is None:
            return
        now = time.perf_counter()
        if now - self._last < self.min_interval and (self.done < self.total or self.mode == "log"):
            return
        self._last = now
        elapsed = max(now - self._start, 1e-12)
        rate = self.done / elapsed
        left = (self.total - self.done) / rate if rate > 0 else float("inf")
        self._draw(f"{self.label}: {self.done}/{self.total}  {_format_rate(rate)}/s  "
                   f"{_format_seconds(left)} left")

    def close(self) -> None:
        elapsed = time.perf_counter() - self._start
        self._final(f"{self.label}: {self.done}/{self.total} in {_format_seconds(elapsed)}")

    def _draw(self, text: str) -> None:
        if self.mode == "live":
            self.stream.write(f"\r{text}   ")
        else:
            self.stream.write(f"{text}\n")
            self._logged = True
        self.stream.flush()

    def _final(self, text: str) -> None:
        if self.mode is None or (self.mode == "log" and not self._logged):
            return  # a log hears of work that outlived one interval, not of every short loop
        self.stream.write(f"\r{text}" + " " * 20 + "\n" if self.mode == "live" else f"{text}\n")
        self.stream.flush()

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Steps(Progress):
    """Throttled line ``label: step k  note  m:ss`` for an open-ended iteration.

    Parameters as :class:`Progress` without ``total``; :meth:`update` takes the
    note of the step just done. :meth:`close` writes ``label: k steps in m:ss  note``
    (in a log only if a line was written before).
    """

    def __init__(self, label: str = "", *, enabled: bool | None = None,
                 stream: TextIO | None = None, min_interval: float = 0.25,
                 log_seconds: float | None = None):
        super().__init__(0, label, enabled=enabled, stream=stream, min_interval=min_interval,
                         log_seconds=log_seconds)
        self.note = ""

    def update(self, note: str = "") -> None:
        self.done += 1
        self.note = note
        if self.mode is None:
            return
        now = time.perf_counter()
        if now - self._last < self.min_interval:
            return
        self._last = now
        self._draw(f"{self.label}: step {self.done}  {note}  {_format_seconds(now - self._start)}")

    def close(self) -> None:
        elapsed = _format_seconds(time.perf_counter() - self._start)
        self._final(f"{self.label}: {self.done} steps in {elapsed}  {self.note}")


class Stage:
    """One-line report of a single long call: ``label ...``, then ``label: done in m:ss``.

    Use as a context manager; an exception leaving the block ends the line
    with ``failed after m:ss`` instead (and is not swallowed).

    Parameters
    ----------
    label : str
        What is being done.
    enabled : bool or None
        ``True``: the live line; ``False``: nothing; ``None`` (default): decided
        from the stream (live on a terminal; in a log, one line at the end if the
        call took longer than a second).
    stream : text stream, optional
        Default ``sys.stderr``.
    """

    def __init__(self, label: str, *, enabled: bool | None = None,
                 stream: TextIO | None = None):
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.mode = _resolve(enabled, self.stream)
        self._start = 0.0

    @property
    def enabled(self) -> bool:
        return self.mode is not None

    def __enter__(self) -> "Stage":
        self._start = time.perf_counter()
        if self.mode == "live":
            self.stream.write(f"{self.label} ...")
            self.stream.flush()
        return self

    def __exit__(self, exc_type, *exc) -> None:
        seconds = time.perf_counter() - self._start
        if self.mode is None or (self.mode == "log" and seconds < 1.0):
            return
        elapsed = _format_seconds(seconds)
        outcome = f"failed after {elapsed}" if exc_type is not None else f"done in {elapsed}"
        self.stream.write(f"\r{self.label}: {outcome}\n" if self.mode == "live"
                          else f"{self.label}: {outcome}\n")
        self.stream.flush()


def _format_rate(rate: float) -> str:
    """Steps per second: three significant digits below 100 (``0.63``), whole numbers above."""
    return f"{rate:,.0f}" if rate >= 100 else f"{rate:.3g}"


def _format_seconds(seconds: float) -> str:
    if seconds == float("inf"):
        return "?"
    seconds = int(round(seconds))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"
