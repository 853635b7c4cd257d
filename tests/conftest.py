"""Shared fixtures."""

import pytest
from threadpoolctl import threadpool_limits


@pytest.fixture(scope="module")
def one_blas_thread():
    """Small dense products run fastest on one BLAS thread: on the shared 2-core
    machine two OpenBLAS threads per process oversubscribe it (measured: the
    linalg and basis tests 5x slower with two)."""
    with threadpool_limits(limits=1, user_api="blas"):
        yield
