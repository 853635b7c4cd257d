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


@pytest.fixture(scope="session")
def brb_data():
    """The folder of the jointed-beam measurements (``$FEMROM_BRB_DATA``, else the default of
    :func:`femrom.post.brb_data_dir`); the test is skipped, with the reason, when they are absent."""
    from femrom.post import brb_data_dir
    from femrom.post._impact import HAMMER_IMPACT_FILE
    try:
        folder = brb_data_dir()
    except FileNotFoundError as missing:
        pytest.skip(f"jointed-beam data absent: {missing}")
    if not (folder / HAMMER_IMPACT_FILE).is_file():
        pytest.skip(f"jointed-beam data absent: no {HAMMER_IMPACT_FILE} in {folder} (set FEMROM_BRB_DATA)")
    return folder
