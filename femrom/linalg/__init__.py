"""Randomized linear algebra for snapshot matrices that do not fit in memory.

- :func:`randomized_svd`: out-of-core multi-pass randomized SVD reading column
  blocks (q + 2 passes, memory O((n + K) k)); ``scheme="pass_efficient"``
  (default) folds the last pass into one more half power step, ``"classical"``
  ends with B = Q^T W A;
- :class:`StreamingSketch`: single-pass sketch fed column by column, also as an
  integrator consumer;
- :func:`randomized_svd_dask`: the same on a ``dask.array`` (a snapshot store and a
  field, an HDF5 file, an array), on a LocalCluster by default or a real cluster;
- :class:`InnerProduct`: SPD (mass) inner products; every basis returned is
  orthonormal in the product it was given, U^T W U = I.
"""

from femrom.linalg._blocks import BlockSource, as_block_source, default_block_columns, store_source
from femrom.linalg._dask import as_dask_array, randomized_svd_dask
from femrom.linalg._lowrank import LowRankSVD
from femrom.linalg._product import InnerProduct, householder_qr
from femrom.linalg._randomized import randomized_svd
from femrom.linalg._streaming import SketchConsumer, StreamingSketch

__all__ = [
    "BlockSource", "InnerProduct", "LowRankSVD", "SketchConsumer", "StreamingSketch",
    "as_block_source", "as_dask_array", "default_block_columns", "householder_qr", "randomized_svd",
    "randomized_svd_dask", "store_source",
]
