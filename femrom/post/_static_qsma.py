r"""QSMA of a model with a stateful (frictional) force: static solves along one monotonic loading path.

:func:`~femrom.post.quasi_static_modal_analysis` takes any ``solve(F) -> q``. For a joint with
sliders the static state under ``F_i = alpha_i M phi`` depends on the path: each solve starts
from the previous load's displacement and committed force state (:func:`femrom.scene.solve_static`),
so that the loads ``alpha_1 < alpha_2 < ...`` are one monotonic loading from the preload
``(q_0, z_0)``. The loads are set by the amplitudes wanted at one output: ``alpha_i = A_i / |E_o phi|``
(``phi`` mass-normalised), the load at which output ``o`` of the linear mode reaches the
acceleration amplitude ``A_i`` (``omega^2 |E_o phi| a = |E_o phi| alpha`` for a linear mode).
"""

from __future__ import annotations

import numpy as np

from femrom.post._qsma import QuasiStaticBackbone, quasi_static_modal_analysis
from femrom.scene import solve_static


def static_qsma(system, amplitudes, *, reference, state, mode, output: int = 0, supports=(), rigid_modes=None,
                progress=None) -> QuasiStaticBackbone:
    """QSMA of ``mode`` by static solves of ``system`` continued along the loading path (module docstring).

    Parameters
    ----------
    system : SecondOrderSystem
        With its stateful force and its constant load ``system.load`` (e.g. a preload; ``None``: none),
        to which each ``alpha M phi`` is added.
    amplitudes : (s,) array
        Increasing output amplitudes ``A_i`` [output units / s^2] at which the loads are set.
    reference, state
        The preloaded state ``q_0`` (n,) and its committed force state: the path starts there.
    mode : (n,) ndarray
        ``phi``, mass-normalised (``phi^T M phi = 1``).
    output : int
        The output ``o`` whose amplitudes set the loads (``system.output_matrix`` row).
    supports : int array, optional
        Free-dof indices held in the static solves (a free structure's statically determinate supports).
    rigid_modes : (n, k) ndarray, optional
        The free structure's mass-orthonormal rigid-body modes, removed from what the outputs read.
    progress : callable, optional
        One line per load.
    """
    E = system.output_matrix
    current = {"q": reference, "z": state}

    def solve(force):
        load = force if system.load is None else system.load + force
        solution = solve_static(system, load, supports=supports, state=current["z"],
                                initial_displacement=current["q"], closed_start=False)
        current["q"], current["z"] = solution.displacement, solution.state
        return solution.displacement

    alphas = np.asarray(amplitudes, dtype=float) / abs(float(np.asarray(E @ mode).ravel()[output]))
    return quasi_static_modal_analysis(solve, system.mass, mode, alphas, reference=reference, output_matrix=E,
                                       rigid_modes=rigid_modes, progress=progress)
