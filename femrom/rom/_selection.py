r"""Choosing the regularization: a grid scored by training fit and long-time energy.

For each weight ``rho`` on the grid the learner is fitted, the ROM is run over
the training window (its relative state error against the training data is
the *fit*) and over a window ``extension`` times longer (the largest reduced
energy there against the largest in the training window is the *growth*). A
weight whose ROM blows up or whose energy grows beyond ``energy_bound`` is
rejected; among the others the smallest training error wins. This is the
simple version of the selection of McQuarrie, Huang & Willcox (J. R. Soc. N.Z.
51, 2021), with an energy criterion in place of a bound on the states.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from femrom._errors import FemromRuntimeError, FemromValueError
from femrom.rom._model import SecondOrderROM


@dataclass(frozen=True)
class RegularizationScore:
    """One grid point: weight, training error, energy growth, verdict."""

    value: float
    training_error: float
    energy_growth: float
    stable: bool


def select_regularization(make_learner: Callable[[float], object], data, times, *, q0, v0=None,
                          inputs=None, grid=(0.0, 1e-12, 1e-10, 1e-8, 1e-6, 1e-4),
                          extension: float = 5.0, energy_bound: float = 2.0,
                          scheme: str = "newmark"):
    """Fit one learner per grid value and keep the best stable one.

    Parameters
    ----------
    make_learner : callable
        ``rho -> learner`` (e.g. ``lambda rho: LagrangianOpInf(regularization=rho)``).
    data : SecondOrderData
        One training trajectory sampled on ``times``.
    times : (K,) ndarray
        Its uniform time grid.
    q0, v0 : (r,) ndarray
        The trajectory's initial reduced state.
    inputs : callable, optional
        ``u(t)`` over the extended window.
    grid : sequence of float
    extension : float
        Length of the stability window in training windows.
    energy_bound : float
        Largest accepted ratio of the extended-window to training-window energy.

    Returns
    -------
    best : float
        The chosen weight.
    learner : object
        The learner fitted with it.
    scores : list of RegularizationScore
    """
    times = np.asarray(times, dtype=float)
    h = times[1] - times[0]
    n_ext = int(round(extension * (times.size - 1)))
    long_times = times[0] + h * np.arange(n_ext + 1)
    sampled = inputs if inputs is None or callable(inputs) else None
    if inputs is not None and sampled is None:
        raise FemromValueError("select_regularization needs inputs as a callable u(t)")
    scores, best = [], (np.inf, None, None)
    reference = np.linalg.norm(data.states)
    for value in grid:
        learner = make_learner(float(value))
        learner.fit(data)
        rom = SecondOrderROM(learner.operators_)
        try:
            with np.errstate(over="ignore", invalid="ignore"):
                short = rom.predict(times, sampled, initial=(q0, v0), scheme=scheme)
                long = rom.predict(long_times, sampled, initial=(q0, v0), scheme=scheme)
            error = float(np.linalg.norm(short.q - data.states) / reference)
            e_short = np.max(np.abs(short.energy))
            growth = float(np.max(np.abs(long.energy)) / max(e_short, np.finfo(float).tiny))
            stable = bool(np.all(np.isfinite(long.q)) and np.isfinite(error)
                          and growth <= energy_bound)
        except (RuntimeError, np.linalg.LinAlgError, ValueError):
            error, growth, stable = np.inf, np.inf, False
        scores.append(RegularizationScore(float(value), error, growth, stable))
        if stable and error < best[0]:
            best = (error, float(value), learner)
    if best[2] is None:
        raise FemromRuntimeError("no regularization on the grid gave a stable ROM: "
                           + ", ".join(f"{s.value:g} (growth {s.energy_growth:.3g})" for s in scores))
    return best[1], best[2], scores
