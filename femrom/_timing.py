"""Per-step costs that hold on a shared machine: timed blocks, repeated, their minimum and spread.

A single timing of a microsecond ROM step is dominated by whatever else the
machine does at that moment (a default fishtail run once showed the same r = 12
step at 1.5e-5 s and at 1.5e-6 s). Here every cost is a :class:`Cost`: several
timed blocks, each long enough (``min_block_seconds``, 0.1 s by default) for the
clock's resolution not to matter, made of slices spread over time
(:func:`repeated_costs`), summarised by their minimum (the cost: the machine
only ever adds time) with the quartiles and maximum as the spread.
Measured on this machine (shared, 2 cores): blocks of one beam ROM's 0.1 s
stepping fall into two groups, about 0.75 and 1.05 us per step, in no order, so
the median of 5 blocks jumps between them (0.77-1.07 us over six ROMs of equal
work) while the minimum stays within 0.69-0.79 us. Speedups are ratios of costs
measured in the same run.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from femrom._errors import FemromValueError


@dataclass(frozen=True)
class Cost:
    """Seconds per step from ``blocks`` timed blocks of ``steps_per_block`` steps each.

    :attr:`seconds` (the ``minimum`` over the blocks) is the cost; ``q25``,
    ``median``, ``q75`` and ``maximum`` its spread.
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
            raise FemromValueError("no timed blocks")
        q25, median, q75 = np.percentile(x, [25, 50, 75])
        return cls(float(median), float(q25), float(q75), float(x.min()), float(x.max()), int(x.size),
                   float(steps_per_block))

    @property
    def seconds(self) -> float:
        """The cost per step: the least disturbed block's."""
        return self.minimum

    @property
    def relative_spread(self) -> float:
        """Interquartile range over the median."""
        return (self.q75 - self.q25) / self.median if self.median > 0 else 0.0

    def scaled(self, factor: float) -> "Cost":
        """The cost of ``factor`` steps (every statistic times ``factor``; blocks unchanged)."""
        f = float(factor)
        if f == 1.0:
            return self
        return Cost(self.median * f, self.q25 * f, self.q75 * f, self.minimum * f, self.maximum * f, self.blocks,
                    self.steps_per_block / f)

    def to_dict(self) -> dict:
        return asdict(self)


def blocked_cost(step_seconds: np.ndarray, min_block_seconds: float = 0.1, *, min_blocks: int = 3) -> Cost:
    """Per-step cost of consecutive step timings grouped into blocks of at least ``min_block_seconds``."""
    s = np.asarray(step_seconds, dtype=float)
    if s.size == 0:
        raise FemromValueError("no steps were timed")
    mean = max(float(np.mean(s)), 1e-12)
    per_block = max(1, math.ceil(min_block_seconds / mean - 1e-9))
    per_block = min(per_block, max(1, s.size // min_blocks))
    n_blocks = max(1, s.size // per_block)
    blocks = s[:n_blocks * per_block].reshape(n_blocks, per_block).sum(axis=1) / per_block
    return Cost.from_blocks(blocks, per_block)


def repeated_costs(blocks: dict, n_steps: int, *, repeats: int = 5, slices: int = 5,
                   min_block_seconds: float = 0.1, max_steps: int = 2_000_000) -> dict:
    """Per-step costs of several ``block(n) -> seconds`` (the timed part of ``n`` steps), interleaved.

    One calibration call per entry on ``n_steps`` steps gives its step cost. Each
    timed block of an entry lasts at least ``min_block_seconds`` and is made of
    ``slices`` equal slices spread over the round: the round visits every entry
    ``slices`` times, a slice each time. So every block samples the machine at
    ``slices`` moments a round apart, and a disturbance that lasts seconds (another
    tenant, a CPU burner) falls on all entries alike instead of on the one timed
    then; ``repeats`` rounds give ``repeats`` blocks per entry. Measured beside a
    CPU burner on this 2-core machine with whole 0.1 s blocks in turn: a block took
    either about 0.7 us per step or 1.3-1.6 us, and the fastest of 5 blocks of
    equal ROMs ranged over 0.70-1.57 us.

    Returns
    -------
    dict of key -> Cost
    """
    slices = max(int(slices), 1)
    sizes = {}
    for key, block in blocks.items():
        per_step = max(float(block(n_steps)) / max(n_steps, 1), 1e-12)
        sizes[key] = int(min(math.ceil(min_block_seconds / per_step / slices - 1e-9), max_steps))
        sizes[key] = max(sizes[key], 1)
    samples = {key: [] for key in blocks}
    for _ in range(repeats):
        spent = dict.fromkeys(blocks, 0.0)
        for _ in range(slices):
            for key, block in blocks.items():
                spent[key] += float(block(sizes[key]))
        for key in blocks:
            samples[key].append(spent[key] / (slices * sizes[key]))
    return {key: Cost.from_blocks(np.array(samples[key]), slices * sizes[key]) for key in blocks}


def repeated_cost(block, n_steps: int, **options) -> Cost:
    """:func:`repeated_costs` of one ``block(n) -> seconds``."""
    return repeated_costs({0: block}, n_steps, **options)[0]


def call_cost(fn, *args, repeats: int = 5, min_block_seconds: float = 0.1) -> Cost:
    """Seconds per call of ``fn(*args)`` (e.g. a reduced force at one state): :func:`repeated_cost`
    of blocks of consecutive calls, each block at least ``min_block_seconds`` long (sized from a
    first block of 100 calls), the fastest of ``repeats`` blocks the cost."""
    import time

    def block(n: int) -> float:
        tic = time.perf_counter()
        for _ in range(n):
            fn(*args)
        return time.perf_counter() - tic

    return repeated_cost(block, 100, repeats=repeats, min_block_seconds=min_block_seconds)
