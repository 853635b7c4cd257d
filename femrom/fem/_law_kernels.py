r"""Compiled return maps of the slider interface laws: one loop over points and sliders.

The numpy implementations of :class:`~femrom.fem.ParallelSliderLaw` (the ``iwan`` and
``jenkins`` laws) and :class:`~femrom.fem.ClampedIwanLaw` build (s, N, 2) temporaries and
(s, N, 2, 2) tangent blocks a dozen array operations deep; on the few dozen sampled pairs
of a hyper-reduced joint their cost is numpy's per-call overhead, not arithmetic. These
kernels do the same radial return slider by slider in one compiled loop (numba,
``cache=True``: compiled once per machine, loaded from the on-disk cache in later
processes) and return what the numpy code returns, equal to round-off: the traction, the
consistent tangent ``dt/dDelta`` and the committed slider positions.

The numpy code stays the reference and the fallback. The laws call these kernels through
:func:`compiled_kernels`, which answers ``None`` (use numpy) when numba is not importable,
when ``FEMROM_COMPILED_LAWS=0`` is set in the environment, or after
:func:`use_compiled_laws(False) <use_compiled_laws>`. This module imports numba only on
the first call of :func:`compiled_kernels`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

_ENVIRONMENT = "FEMROM_COMPILED_LAWS"
_enabled = os.environ.get(_ENVIRONMENT, "1").strip().lower() not in ("0", "false", "no", "off", "numpy")
_kernels = None        # the compiled module after the first successful import, False when numba is missing
_scalar_kernels = None  # the same for :mod:`femrom.fem._scalar_kernels_numba`


def use_compiled_laws(enabled: bool) -> bool:
    """Switch the interface laws between the compiled kernels and numpy; returns the previous setting.

    With ``enabled`` the compiled kernels run where numba is importable (numpy otherwise).
    The default is on unless the environment sets ``FEMROM_COMPILED_LAWS=0``.
    """
    global _enabled
    previous, _enabled = _enabled, bool(enabled)
    return previous


def compiled_laws() -> bool:
    """Whether the interface laws evaluate with the compiled kernels (switched on and numba importable)."""
    return compiled_kernels() is not None


def compiled_kernels():
    """The kernel module (:mod:`femrom.fem._law_kernels_numba`), or ``None`` when the laws use numpy."""
    global _kernels
    if not _enabled:
        return None
    if _kernels is None:
        try:
            from femrom.fem import _law_kernels_numba as module
        except ImportError:
            module = False
        _kernels = module
    return _kernels or None


def compiled_scalar_kernels():
    """The kernels of learned scalar functions and of the fused discrete-gradient step
    (:mod:`femrom.fem._scalar_kernels_numba`), or ``None`` when the compiled laws are off (the same switch,
    :func:`use_compiled_laws`, ``FEMROM_COMPILED_LAWS``) or numba is missing."""
    global _scalar_kernels
    if not _enabled:
        return None
    if _scalar_kernels is None:
        try:
            from femrom.fem import _scalar_kernels_numba as module
        except ImportError:
            module = False
        _scalar_kernels = module
    return _scalar_kernels or None


@dataclass(frozen=True, eq=False)
class CompiledScalar:
    r"""A learned scalar function ``phi`` of ``q^`` (a potential) or of ``q^'`` (a dissipation function), as
    compiled kernels take it.

    ``phi(x) = T3[x,x,x] + T4[x,x,x,x] + sum_k |a_k . x|^3 / 3 + sum_k (b_k . x)^4 / 4 + N(x) - N(0)
    - grad N(0) . x``, each part optional. What :meth:`femrom.inference.LearnedPotential.compiled_scalar`
    and :meth:`femrom.inference.LearnedDissipation.compiled_scalar` return; ``parts`` is the tuple the
    kernels ``scalar_vgh`` and ``discrete_gradient_step`` of :func:`compiled_scalar_kernels` read:
    ``(T3 (r,r,r), T4 (r,r,r,r), A (n3, r), B (n4, r), widths, has_weight, has_input, bias_offsets,
    weight_offsets, input_offsets, biases, weights, input_weights, output, activation, N(0), grad N(0))``
    (``T3``, ``T4`` symmetric, as :class:`~femrom.inference.SymmetricPolynomial` forms them: the kernels
    contract them on their first index; empty arrays for an absent part; the layers' matrices flattened row by row; activation 0 tanh,
    1 softplus). The numpy functions (:mod:`femrom.inference._networks`) are the reference.

    Attributes
    ----------
    r : int
    argument : {"q", "v"}
        ``"q"``: a conservative potential ``U^(q^)``; ``"v"``: a dissipation function ``F^(q^')``.
    parts : tuple
    """

    r: int
    argument: str
    parts: tuple


@dataclass(frozen=True, eq=False)
class CompiledJoint:
    r"""A projected joint ``f^(q^; z) = W^T g(W q^ + x_0; z)`` as compiled step kernels take it.

    What :meth:`femrom.fem.TransformedForce.compiled_joint` returns for a joint whose law has
    compiled kernels: the pair gaps are ``Delta = (W q^ + local_offset).reshape(s, 3) +
    gap_offset``, the pair forces ``A_i t_i(Delta_i; z_i)`` and their tangent blocks come from
    the law's kernel ``kind`` (``PARALLEL_SLIDERS`` or ``CLAMPED_IWAN`` of :mod:`femrom.fem._law_kinds`), and a
    compiled caller (an integrator's fused step) projects them back with ``W``. The kernels
    are the functions ``joint_gaps``, ``joint_law``, ``joint_project_force``,
    ``joint_project_tangent`` and ``joint_commit`` of :func:`compiled_kernels`; the numpy path
    (:meth:`~femrom.fem.TransformedForce.dense_force_and_tangent`, the law's ``evaluate`` and
    ``commit``) is the reference they reproduce to round-off.

    Attributes
    ----------
    kind : int
    dense_map : (3 s, k) ndarray
        ``W = L T``, C-contiguous.
    local_offset : (3 s,) ndarray
        ``L q_0`` of the reference (zeros without one).
    gap_offset : (s, 3) ndarray
        The joint's initial gaps (normal components).
    areas : (s,) ndarray
    stiffness, strength : (N,) ndarray
        The sliders' stiffnesses and slip limits (unit limits for the clamped law).
    normal_stiffness : float
    """

    kind: int
    dense_map: np.ndarray
    local_offset: np.ndarray
    gap_offset: np.ndarray
    areas: np.ndarray
    stiffness: np.ndarray
    strength: np.ndarray
    normal_stiffness: float

    @property
    def n_pairs(self) -> int:
        """``s``."""
        return self.areas.size


@dataclass(frozen=True, eq=False)
class CompiledSliders:
    r"""Jenkins sliders along one reduced direction, ``f^(q^; e) = a sum_i k_i e_i``, as compiled step kernels
    take them.

    What :meth:`femrom.inference.LearnedHysteresis.compiled_sliders` returns: the stretches
    return-map as ``e_i = clip(e_i^0 + (a . q^ - x^0), -phi_i, phi_i)`` (stuck where
    ``|trial| < phi_i``); the state is ``(e^0 (p,), x^0)``, rebuilt into the force's own state
    object by :attr:`state` (whose ``stretch`` and ``coordinate`` are the two parts). The kernels
    are ``newmark_sliders_step`` and ``newmark_sliders_march`` of :func:`compiled_scalar_kernels` (which
    also take a learned potential beside the sliders).

    Attributes
    ----------
    direction : (r,) ndarray
    thresholds, weights : (p,) ndarray
    state : callable
        ``(stretch, coordinate) -> state``.
    """

    direction: np.ndarray
    thresholds: np.ndarray
    weights: np.ndarray
    state: object
