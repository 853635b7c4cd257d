"""Compare two runs' ``metrics.json`` key by key: are the model's numbers the same?

    python -m benchmarks.compare_metrics BASE NEW [--rtol 1e-10] [--timing PATTERN ...] [--show 40]

``BASE`` and ``NEW`` are ``metrics.json`` files or folders holding one (a case's output folder,
e.g. ``femrom run beam --out /tmp/after/beam``). Both are flattened to ``path -> value`` (nested
keys joined by ``/``, list positions as numbers) and compared:

- numbers: equal when ``|a - b| <= rtol max(|a|, |b|)`` (or both zero, both NaN, equal infinities);
- strings, booleans and ``None``: equal when identical;
- a path in one file only: reported as missing or added.

Paths naming a timing or a machine fact (wall times, costs per step, speed-ups, real-time
factors, memory, the machine's description; :data:`TIMING` and ``--timing``) differ from run to run and are not numbers
of the model: they are counted, not compared. The report lists the differing paths (at most
``--show``), the largest relative difference of the compared numbers, and exits 1 when anything
differs (0 otherwise).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

#: Path components (regular expressions, matched in full) of timings and machine facts.
TIMING = (
    r".*seconds.*", r"(.*_)?ms_.*", r"steps_per_(second|block)", r".*speedup.*", r".*timings?", r"(.*_)?costs?",
    r"wall.*", r"realtime.*", r".*rss.*", r".*memory.*", r"machine.*", r"platform", r"processor", r"python", r"date",
    r"load_average", r"threads", r"cpu_count",
)


def load(path) -> dict:
    """The metrics of a ``metrics.json`` file, or of the one in a folder."""
    path = Path(path)
    if path.is_dir():
        path = path / "metrics.json"
    return json.loads(path.read_text())


def flatten(value, prefix: str = "") -> dict:
    """``{path: leaf}`` of nested dicts and lists (paths ``a/b/0/c``)."""
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, list):
        items = ((str(i), v) for i, v in enumerate(value))
    else:
        return {prefix: value}
    flat = {}
    for key, item in items:
        flat.update(flatten(item, f"{prefix}/{key}" if prefix else str(key)))
    return flat


def is_timing(path: str, patterns=TIMING) -> bool:
    """Whether a component of ``path`` is a timing or machine fact (matches a pattern in full)."""
    compiled = [re.compile(p) for p in patterns]
    return any(c.fullmatch(part) for part in path.split("/") for c in compiled)


def relative_difference(a, b) -> float:
    """``|a - b| / max(|a|, |b|)``; 0 for equal values (NaN and NaN, inf and inf), inf for NaN against a number."""
    a, b = float(a), float(b)
    if a == b or (math.isnan(a) and math.isnan(b)):
        return 0.0
    if math.isnan(a) or math.isnan(b) or math.isinf(a) or math.isinf(b):
        return math.inf
    return abs(a - b) / max(abs(a), abs(b))


def _number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def compare(base: dict, new: dict, *, rtol: float = 1e-10, timing=TIMING) -> dict:
    """Compare flattened metrics (module docstring).

    Returns ``{"compared", "timings", "max_relative_difference", "max_at", "differing": [(path, base,
    new, relative difference or None)], "missing": [...], "added": [...]}``."""
    a, b = flatten(base), flatten(new)
    report = {"compared": 0, "timings": 0, "max_relative_difference": 0.0, "max_at": None, "differing": [],
              "missing": sorted(p for p in a if p not in b and not is_timing(p, timing)),
              "added": sorted(p for p in b if p not in a and not is_timing(p, timing))}
    for path in a:
        if path not in b:
            continue
        if is_timing(path, timing):
            report["timings"] += 1
            continue
        report["compared"] += 1
        x, y = a[path], b[path]
        if _number(x) and _number(y):
            d = relative_difference(x, y)
            if d > report["max_relative_difference"]:
                report["max_relative_difference"], report["max_at"] = d, path
            if d > rtol:
                report["differing"].append((path, x, y, d))
        elif x != y:
            report["differing"].append((path, x, y, None))
    return report


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("base", type=Path, help="metrics.json, or the folder holding it")
    parser.add_argument("new", type=Path, help="metrics.json, or the folder holding it")
    parser.add_argument("--rtol", type=float, default=1e-10, help="relative tolerance of numbers (default 1e-10)")
    parser.add_argument("--timing", action="append", default=[],
                        help="another path component (regular expression) to treat as a timing")
    parser.add_argument("--show", type=int, default=40, help="differing paths listed at most (default 40)")
    args = parser.parse_args(argv)
    report = compare(load(args.base), load(args.new), rtol=args.rtol, timing=TIMING + tuple(args.timing))
    print(f"{report['compared']} values compared, {report['timings']} timings and machine facts skipped; "
          f"largest relative difference {report['max_relative_difference']:.3g}"
          + (f" at {report['max_at']}" if report["max_at"] else ""))
    for kind in ("missing", "added"):
        if report[kind]:
            print(f"{len(report[kind])} {kind} in NEW: " + ", ".join(report[kind][:args.show]))
    if report["differing"]:
        print(f"{len(report['differing'])} differ beyond rtol {args.rtol:g}:")
        for path, x, y, d in report["differing"][:args.show]:
            print(f"  {path}: {x!r} -> {y!r}" + ("" if d is None else f" (relative {d:.3g})"))
    same = not (report["differing"] or report["missing"] or report["added"])
    print("same" if same else "different")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
