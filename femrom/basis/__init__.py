"""Reduced bases from snapshots: POD (optionally mass-weighted) and proper symplectic decomposition."""

from femrom.basis._pod import POD, exact_svd, truncation_rank
from femrom.basis._psd import CotangentLiftPSD, apply_j, apply_j_transpose

__all__ = ["POD", "CotangentLiftPSD", "apply_j", "apply_j_transpose", "exact_svd", "truncation_rank"]
