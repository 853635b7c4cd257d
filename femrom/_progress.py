"""Progress of long loops: a live line on a terminal, silence in logs and CI.

Used by every layer that runs long work (mesh generation, assembly, time
stepping). Shows steps done, steps per second and the estimated time left on
``stderr`` when it is a TTY and ``CI`` is not set; otherwise prints nothing.
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
            f"\r{self.label}: {self.done}/{self.total}  {rate:,.0f}/s  "
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


def _format_seconds(seconds: float) -> str:
    if seconds == float("inf"):
        return "?"
    seconds = int(round(seconds))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"
