"""Report pieces every case writes: metrics.json, the machine it ran on, markdown tables.

The figures are :mod:`._plots`'s."""

from __future__ import annotations

import os
import uuid
import platform
from pathlib import Path

from femrom._json import dumps


def machine_description() -> dict:
    """Where a measurement was taken (for metrics and benchmark files)."""
    import psutil

    return {"platform": platform.platform(), "processor": platform.machine(),
            "cpu_count": os.cpu_count(), "memory_gb": round(psutil.virtual_memory().total / 2**30, 1),
            "python": platform.python_version()}


def write_metrics(path, metrics: dict) -> Path:
    """Write ``metrics`` as JSON (numpy values converted); atomic replace.

    JSON has no ``nan`` or ``inf``: a quantity without a finite value (the errors of a model
    that diverged, a time that was not measured) is written as ``null``, and the record it
    belongs to says why (a model row's ``diverged`` or ``failed``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")   # never shared by two writers
    tmp.write_text(dumps(metrics, non_finite="null", indent=2) + "\n")
    os.replace(tmp, path)
    return path


def accuracy_cost_table(rows: list[dict], columns: list[str]) -> str:
    """Markdown table of ``rows`` (dicts) restricted to ``columns``."""
    def fmt(v):
        if isinstance(v, float):
            return f"{v:.3e}" if (v != 0 and (abs(v) < 1e-2 or abs(v) >= 1e4)) else f"{v:.4g}"
        return str(v)

    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(fmt(r.get(c, "")) for c in columns) + " |" for r in rows]
    return "\n".join(lines)


def table_section(heading: str, rows: list[dict], columns: list[str], *, text: str = "", note: str = "") -> str:
    """A report section in markdown: ``## heading``, an optional paragraph ``text``, the table of
    ``rows`` in ``columns`` (:func:`accuracy_cost_table`), an optional closing ``note``."""
    parts = [f"## {heading}", text, accuracy_cost_table(rows, columns), note]
    return "\n\n".join(part for part in parts if part)
