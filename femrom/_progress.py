"""Progress of long work: a live line on a terminal, silence in logs and CI.

Two reports, both on ``stderr`` and only when it is a TTY and neither ``CI``
nor ``FEMROM_NO_PROGRESS`` is set (otherwise they print nothing):

- :class:`Progress`, for loops of counted steps: steps done, steps per second
  and the estimated time left. Used by the time integrators (one unit per
  step: :func:`femrom.integrators.iterate`) and the randomized SVD (one unit
  per pass over the snapshots).
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


def _interactive(stream: TextIO) -> bool:
    if os.environ.get("CI") or os.environ.get("FEMROM_NO_PROGRESS"):
        return False
    return bool(getattr(stream, "isatty", lambda: False)())


class Progress:
    """Throttled progress line ``label: done/total  rate/s  eta``.

    Parameters
    ----------
    total : int
        Number of units of work.
    label : str
        Text in front of the counter.
    enabled : bool or None
        Force on or off; ``None`` decides from the stream (TTY and not CI).
    min_interval : float
        Seconds between two redraws.
    """

    def __init__(self, total: int, label: str = "", *, enabled: bool | None = None,
                 stream: TextIO | None = None, min_interval: float = 0.25):
        self.total = int(total)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = _interactive(self.stream) if enabled is None else enabled
        self.min_interval = min_interval
        self.done = 0
        self._start = time.perf_counter()
        self._last = -1.0

    def update(self, n: int = 1) -> None:
        self.done += n
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < self.min_interval and self.done < self.total:
            return
        self._last = now
        elapsed = max(now - self._start, 1e-12)
        rate = self.done / elapsed
        left = (self.total - self.done) / rate if rate > 0 else float("inf")
        self.stream.write(
            f"\r{self.label}: {self.done}/{self.total}  {_format_rate(rate)}/s  "
            f"{_format_seconds(left)} left   "
        )
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            elapsed = time.perf_counter() - self._start
            self.stream.write(
                f"\r{self.label}: {self.done}/{self.total} in {_format_seconds(elapsed)}"
                + " " * 20 + "\n"
            )
            self.stream.flush()

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Stage:
    """One-line report of a single long call: ``label ...``, then ``label: done in m:ss``.

    Use as a context manager; an exception leaving the block ends the line
    with ``failed after m:ss`` instead (and is not swallowed).

    Parameters
    ----------
    label : str
        What is being done.
    enabled : bool or None
        Force on or off; ``None`` decides from the stream (TTY and not CI).
    stream : text stream, optional
        Default ``sys.stderr``.
    """

    def __init__(self, label: str, *, enabled: bool | None = None,
                 stream: TextIO | None = None):
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = _interactive(self.stream) if enabled is None else enabled
        self._start = 0.0

    def __enter__(self) -> "Stage":
        self._start = time.perf_counter()
        if self.enabled:
            self.stream.write(f"{self.label} ...")
            self.stream.flush()
        return self

    def __exit__(self, exc_type, *exc) -> None:
        if self.enabled:
            elapsed = _format_seconds(time.perf_counter() - self._start)
            outcome = f"failed after {elapsed}" if exc_type is not None else f"done in {elapsed}"
            self.stream.write(f"\r{self.label}: {outcome}\n")
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
