"""Per-step costs that hold on a shared machine: timed blocks, repeated, median and spread.

A single timing of a microsecond ROM step is dominated by whatever else the
machine does at that moment (a default fishtail run once showed the same r = 12
step at 1.5e-5 s and at 1.5e-6 s). Here every cost is a :class:`Cost`: several
timed blocks, each long enough (``min_block_seconds``, 0.1 s by default) for the
clock and the scheduler's noise to average out, summarised by their median and
quartiles. Speedups are ratios of costs measured in the same run.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Cost:
    """Seconds per step from ``blocks`` timed blocks of ``steps_per_block`` steps each.

    ``median`` is the cost; ``q25``, ``q75`` (quartiles), ``minimum``, ``maximum``
    its spread over the blocks.
    """

    median: float
    q25: float
    q75: float
    minimum: float
    maximum: float
    blocks: int
    steps_per_block: float

    @classmethod
    def from_blocks(cls, per_step: np.ndarray, steps_per_block: float) -> "Cost":
        x = np.asarray(per_step, dtype=float)
        if x.size == 0:
            raise ValueError("no timed blocks")
        q25, median, q75 = np.percentile(x, [25, 50, 75])
        return cls(float(median), float(q25), float(q75), float(x.min()), float(x.max()), int(x.size),
                   float(steps_per_block))

    @property
    def relative_spread(self) -> float:
        """Interquartile range over the median."""
        return (self.q75 - self.q25) / self.median if self.median > 0 else 0.0

    def to_dict(self) -> dict:
        return asdict(self)


def blocked_cost(step_seconds: np.ndarray, min_block_seconds: float = 0.1, *, min_blocks: int = 3) -> Cost:
    """Per-step cost of consecutive step timings grouped into blocks of at least ``min_block_seconds``."""
    s = np.asarray(step_seconds, dtype=float)
    if s.size == 0:
        raise ValueError("no steps were timed")
    mean = max(float(np.mean(s)), 1e-12)
    per_block = max(1, math.ceil(min_block_seconds / mean - 1e-9))
    per_block = min(per_block, max(1, s.size // min_blocks))
    n_blocks = max(1, s.size // per_block)
    blocks = s[:n_blocks * per_block].reshape(n_blocks, per_block).sum(axis=1) / per_block
    return Cost.from_blocks(blocks, per_block)


def repeated_costs(blocks: dict, n_steps: int, *, repeats: int = 5, min_block_seconds: float = 0.1,
                   max_steps: int = 2_000_000) -> dict:
    """Per-step costs of several ``block(n) -> seconds`` (the timed part of ``n`` steps), interleaved.

    One calibration call per entry on ``n_steps`` steps gives its step cost; each
    timed block then runs ``N >= n_steps`` steps, enough for ``min_block_seconds``
    (at most ``max_steps``). The blocks go round-robin, entry after entry,
    ``repeats`` times: the machine's slow drifts (another tenant, the clock
    frequency), which shift all blocks timed within a second or so alike, then
    fall on every entry instead of on the ones that happened to be timed then
    (measured: the same r = 8 ROM at 0.95 and 1.43 us per step a few seconds apart,
    each with quartiles within 10 %).

    Returns
    -------
    dict of key -> Cost
    """
    sizes = {}
    for key, block in blocks.items():
        per_step = max(float(block(n_steps)) / max(n_steps, 1), 1e-12)
        sizes[key] = int(min(max(n_steps, math.ceil(min_block_seconds / per_step - 1e-9)), max_steps))
    samples = {key: [] for key in blocks}
    for _ in range(repeats):
        for key, block in blocks.items():
            samples[key].append(float(block(sizes[key])) / sizes[key])
    return {key: Cost.from_blocks(np.array(samples[key]), sizes[key]) for key in blocks}


def repeated_cost(block, n_steps: int, **options) -> Cost:
    """:func:`repeated_costs` of one ``block(n) -> seconds``."""
    return repeated_costs({0: block}, n_steps, **options)[0]
