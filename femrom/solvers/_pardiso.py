"""MKL PARDISO through ``pypardiso``, driven phase by phase."""

from __future__ import annotations

import ctypes
import functools
import time

import numpy as np
import scipy.sparse as sp

from femrom.solvers._base import LinearSolver, LinearSolverError, register_strategy


@register_strategy
class PardisoSolver(LinearSolver):
    """MKL PARDISO factorised once (phase 12) and reused (phase 33).

    ``pypardiso.spsolve`` keeps one factor per matrix and compares the whole
    matrix (or its hash) on every call to decide whether to re-factorise; here
    the low-level :class:`pypardiso.PyPardisoSolver` is driven by phase
    directly, with the 1-based CSR index arrays built once. Locating MKL
    (``PyPardisoSolver()``) costs about a second here, so the library function
    is looked up once per process and each solver keeps its own handle. ``spd=True`` uses
    matrix type 2 (real SPD, upper triangle stored), otherwise 11 (real
    nonsymmetric, full matrix).
    """

    name = "pardiso"
    package = "pypardiso"

    def __init__(self, A, *, spd: bool = True, **common):
        super().__init__(A)
        self._mtype = 2 if spd else 11
        # one PARDISO handle per factor: internal pointers, parameters, permutation
        self._pt = np.zeros(64, dtype=np.int64)
        self._iparm = np.zeros(64, dtype=np.int32)  # iparm[0] = 0: MKL defaults
        self._perm = np.zeros(0, dtype=np.int32)
        A = sp.csr_matrix(A, dtype=float)
        if spd:
            A = sp.triu(A, format="csr")  # mtype 2 reads the upper triangle only
        A.sum_duplicates()
        A.sort_indices()
        if spd and np.any(A.diagonal() == 0.0):
            raise LinearSolverError("pardiso (SPD): the matrix has zero diagonal entries")
        self._data = np.ascontiguousarray(A.data, dtype=np.float64)
        self._ia = np.ascontiguousarray(A.indptr + 1, dtype=np.int32)
        self._ja = np.ascontiguousarray(A.indices + 1, dtype=np.int32)
        self._n = A.shape[0]
        self._factored = False
        #: how often each PARDISO phase ran (12: analyse + factorise, 33: solve)
        self.phase_calls = {12: 0, 33: 0, -1: 0}
        _mkl_pardiso()  # locating MKL (1-5 s once per process) is not the factorisation
        start = time.perf_counter()
        self._call(12, np.zeros((self._n, 1), order="F"))
        self._factored = True
        self.setup_seconds = time.perf_counter() - start
        self.n_factorizations = 1

    def _call(self, phase: int, b: np.ndarray) -> np.ndarray:
        self.phase_calls[phase] = self.phase_calls.get(phase, 0) + 1
        int_p = ctypes.POINTER(ctypes.c_int32)
        dbl_p = ctypes.POINTER(ctypes.c_double)
        x = np.zeros_like(b)
        error = ctypes.c_int32(0)
        nrhs = 1 if b.ndim == 1 else b.shape[1]
        _mkl_pardiso()(
            self._pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
            ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(1)),
            ctypes.byref(ctypes.c_int32(self._mtype)), ctypes.byref(ctypes.c_int32(phase)),
            ctypes.byref(ctypes.c_int32(self._n)), self._data.ctypes.data_as(dbl_p),
            self._ia.ctypes.data_as(int_p), self._ja.ctypes.data_as(int_p),
            self._perm.ctypes.data_as(int_p), ctypes.byref(ctypes.c_int32(nrhs)),
            self._iparm.ctypes.data_as(int_p), ctypes.byref(ctypes.c_int32(0)),
            b.ctypes.data_as(dbl_p), x.ctypes.data_as(dbl_p), ctypes.byref(error))
        if error.value != 0:
            hint = " (matrix not positive definite? pass spd=False)" if error.value == -4 else ""
            raise LinearSolverError(f"pardiso phase {phase} failed with error {error.value}{hint}")
        return x

    def _solve(self, b, x0):
        x = self._call(33, np.asfortranarray(b, dtype=np.float64))
        return np.ascontiguousarray(x)

    def close(self) -> None:
        """Release PARDISO's memory for this factor (also done on garbage collection)."""
        if getattr(self, "_factored", False):
            self._factored = False
            self._call(-1, np.zeros((self._n, 1), order="F"))

    def __del__(self):
        try:
            self.close()
        except Exception:  # interpreter shutdown: ctypes may already be gone
            pass


@functools.cache
def _mkl_pardiso():
    """The ctypes ``pardiso`` function of MKL, located once (pypardiso does the search)."""
    from pypardiso import PyPardisoSolver

    if ctypes.sizeof(ctypes.c_void_p) != 8:
        raise ImportError("the pardiso strategy needs a 64-bit Python")
    return PyPardisoSolver()._mkl_pardiso

