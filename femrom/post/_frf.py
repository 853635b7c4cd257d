r"""The frequency response of a model linearised about a committed state (a stuck joint).

A model ``M q'' + C q' + K q + f(q, z) = B u`` in a committed force state ``z_0`` at ``q = q_0``
behaves, for small motions, as the linear model of tangent stiffness
``K_t = K + df/dq (q_0, z_0)`` (a frictional joint: every pair stuck). Under a harmonic force
``F f e^{i omega t}`` its outputs' acceleration amplitudes per newton are

    H(omega) = | -omega^2 E (K_t - omega^2 M + i omega C)^{-1} f |,

the small-force limit of a stepped-sine response of the nonlinear model at the same frequencies.
"""

from __future__ import annotations

import numpy as np


def _dense(A) -> np.ndarray:
    return A.toarray() if hasattr(A, "toarray") else np.asarray(A, dtype=float)


def linear_accelerance(system, state, force, frequencies_hz, *, displacement=None) -> np.ndarray:
    """(p, k) ``|omega^2 E (K_t - omega^2 M + i omega C)^-1 f|`` (module docstring) at the ``k`` frequencies.

    Parameters
    ----------
    system : SecondOrderSystem
        A small (dense-solvable) model; its force's tangent is taken at ``displacement`` (default ``q = 0``,
        a reduced model's preloaded reference) in the committed ``state``.
    force : (n,) array
        The load vector ``f`` of one newton (e.g. a column of the input matrix).
    frequencies_hz : (k,) array
    """
    n = system.n_dofs
    q = np.zeros(n) if displacement is None else np.asarray(displacement, dtype=float)
    D0 = None if system.nonlinear is None else system.nonlinear.tangent(q, None, state)[0]
    K = _dense(system.stiffness if D0 is None else system.stiffness + D0)
    M, C = _dense(system.mass), _dense(system.damping)
    E = _dense(system.output_matrix)
    columns = []
    for f in frequencies_hz:
        w = 2 * np.pi * f
        columns.append(np.abs(w * w * (E @ np.linalg.solve(K - w * w * M + 1j * w * C, force))))
    return np.column_stack(columns)
