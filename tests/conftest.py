"""Shared fixtures.

Tests that need the jointed beam's measured data use the ``brb_data`` fixture; tests that
need an optional package import it with ``_required.extra``. Both skip when it is missing,
and fail instead when ``FEMROM_REQUIRE_DATA`` / ``FEMROM_REQUIRE_EXTRAS`` is set (CI sets
both: ``tests/_required.py``).
"""

import pytest
from threadpoolctl import threadpool_limits

import _required


@pytest.fixture(scope="module")
def one_blas_thread():
    """Small dense products run fastest on one BLAS thread: on the shared 2-core
    machine two OpenBLAS threads per process oversubscribe it (measured: the
    linalg and basis tests 5x slower with two)."""
    with threadpool_limits(limits=1, user_api="blas"):
        yield


@pytest.fixture(scope="session")
def brb_data():
    """The folder of the jointed beam's data (``$FEMROM_BRB_DATA`` or ``femrom data fetch brb``'s
    cache); the test is skipped without it, or fails under ``FEMROM_REQUIRE_DATA``."""
    return _required.brb_data()
