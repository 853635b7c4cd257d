"""Skip a test whose data or optional package is missing, or fail it where a run requires them.

On a developer's machine a test that needs the jointed beam's measured data or an optional
extra (torch, dask.distributed, python-control, opinf, pydmd, PARDISO) is skipped without them.
CI (``.ci/run``) sets ``FEMROM_REQUIRE_DATA=1`` and ``FEMROM_REQUIRE_EXTRAS=1``: there the same
test fails, so a run that silently tested less cannot pass (``FEMROM_REQUIRE_RENDER`` does the
same for off-screen rendering).
"""

from __future__ import annotations

import importlib
import os
import platform

import pytest

DATA = "FEMROM_REQUIRE_DATA"
EXTRAS = "FEMROM_REQUIRE_EXTRAS"


def required(variable: str) -> bool:
    """Whether ``variable`` (:data:`DATA` or :data:`EXTRAS`) asks for failures instead of skips."""
    return os.environ.get(variable, "") not in ("", "0")


def missing(reason: str, variable: str):
    """Skip with ``reason``; fail instead when ``variable`` is set (at module level too)."""
    if required(variable):
        pytest.fail(f"{variable} is set but {reason}", pytrace=False)
    pytest.skip(reason, allow_module_level=True)


def extra(module: str):
    """``pytest.importorskip(module)`` that fails when :data:`EXTRAS` is set."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        reason = f"could not import {module!r} ({exc})"
    missing(reason, EXTRAS)         # outside the handler: the report shows the reason, not a chain


#: PARDISO ships with the pardiso extra on x86_64 only: there CI has it.
PARDISO_REQUIRED = required(EXTRAS) and platform.machine() in ("x86_64", "AMD64")


def brb_data():
    """The jointed beam's data folder (:func:`femrom.post.brb_data_dir`), or skip / fail."""
    from femrom.post import DatasetNotFoundError, brb_data_dir

    try:
        return brb_data_dir()
    except DatasetNotFoundError as exc:
        reason = f"jointed-beam data absent: {exc}"
    missing(reason, DATA)
