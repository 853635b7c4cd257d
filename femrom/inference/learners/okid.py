r"""Observer/Kalman filter identification (OKID): Markov parameters from input-output data, then ERA."""

from __future__ import annotations

import math
import time

from femrom._errors import FemromTypeError, FemromValueError, positive_integer
from femrom.inference._io_data import InputOutputData
from femrom.inference._learner import Learner, refuse_validation, register_learner
from dataclasses import replace

import numpy as np

from femrom.inference._realization import (
    era_realization,
    hankel_blocks,
    markov_from_observer,
    observer_markov_parameters,
    okid_observer_gain,
)


@register_learner("okid")
class OKID(Learner):
    r"""OKID (Juang, Phan, Horta & Longman, J. Guid. Control Dyn. 16(2), 1993) followed by ERA.

    The observer Markov parameters ``[D, Ybar_1, ..., Ybar_l]`` by least squares
    on every ``k >= l`` of every trajectory,

    .. math::

        y_k = D u_k + \sum_{i=1}^{l} \big(\bar Y_i^{(1)} u_{k-i} + \bar Y_i^{(2)} y_{k-i}\big),

    the system's ``Y_k = Ybar_k^(1) + sum_{i <= min(k, l)} Ybar_i^(2) Y_{k-i}``, and the
    balanced realisation of order ``n`` from them (:class:`ERA`; the module doc of
    :func:`~femrom.inference.okid_markov_parameters`). Needs inputs and outputs
    only (no states); the initial state of each trajectory is unknown unless
    ``at_rest``. The model is not stabilised: ``describe()`` reports the spectral radius.

    Parameters
    ----------
    order : int
        ``n``.
    observer_order : int
        ``l``: at least the observability index of ``(A, C)`` for noise-free data
        (``l p >= n`` is necessary; displacement outputs of a structure need more:
        a velocity is not seen in one sample); larger with noise (the Kalman
        observer's ``Abar^l`` must be negligible). ``m + l (m + p)`` unknowns per output.
    rows, columns : int, optional
        ERA's block rows and columns; ``rows + columns + 1`` Markov parameters are
        recovered. Default both ``max(l, ceil(2 n / min(p, m)), K_min // 10)``, ``K_min``
        the shortest trajectory: the Hankel matrix must span the slow dynamics, not
        only the observer's ``l`` samples (``benchmarks/identification_fit.py``: a
        lightly damped system whose slowest mode has a period of 333 samples gave
        unstable realisations with ``a + b <= 50`` and stable ones from ``a + b = 200``).
        Cost: one SVD of an (a p, b m) matrix (``docs/identification.md``).
    feedthrough : bool
        Fit ``D`` (default); else ``D = 0``.
    at_rest : bool
        Every trajectory starts from rest: its first ``l`` samples give equations too.
    output_directions : int, optional
        ERA's tangential reduction of the outputs.

    Attributes
    ----------
    operators_ : StateSpaceOperators
    markov_ : MarkovParameters
        The recovered system Markov parameters (``metadata``: the regression's
        ``residual``, ``rank``, ``shape``, ``seconds``).

    The identified observer comes with the model: ``operators_.observer_gain``
    ``L`` (:func:`~femrom.inference.okid_observer_gain`) estimates the state from
    measured outputs, ``z^+ = A z^ + B u + L (y - C z^ - D u)``; with noisy data it
    approximates the Kalman filter's one-step predictor. ``describe()`` reports
    the spectral radius of ``A - L C``.
    """

    method = "okid"
    model = "state_space"

    def __init__(self, order: int, observer_order: int, *, rows: int | None = None, columns: int | None = None,
                 feedthrough: bool = True, at_rest: bool = False, output_directions: int | None = None):
        self.order, self.observer_order = positive_integer(order, "order"), positive_integer(observer_order,
                                                                                               "observer_order")
        self.rows, self.columns = (positive_integer(v, n, optional=True) for v, n in ((rows, "rows"), (columns, "columns")))
        self.feedthrough, self.at_rest = bool(feedthrough), bool(at_rest)
        self.output_directions = positive_integer(output_directions, "output_directions", optional=True)
        self.operators_ = None

    def blocks(self, n_outputs: int, n_inputs: int, shortest: int) -> tuple[int, int]:
        """ERA's block rows and columns for ``p`` outputs, ``m`` inputs and trajectories of ``>= shortest`` samples."""
        default = max(self.observer_order, math.ceil(2 * self.order / min(n_outputs, n_inputs)), shortest // 10)
        rows = default if self.rows is None else int(self.rows)
        columns = default if self.columns is None else int(self.columns)
        return hankel_blocks(rows + columns + 1, rows, columns)

    @classmethod
    def for_training(cls, training, r: int, **options):
        """OKID of order ``2 r`` (a second-order model's state count) from the runs' inputs and outputs only."""
        options.setdefault("order", 2 * r)
        return cls(**options), training.input_output(r, "none"), None

    def fit(self, data: InputOutputData, *, validation=None) -> "OKID":
        """Identify ``A, B, C, D`` from the inputs and outputs of ``data`` (no validation data)."""
        refuse_validation(self, validation)
        if not isinstance(data, InputOutputData):
            raise FemromTypeError(f"OKID.fit takes InputOutputData, got {type(data).__name__}")
        if data.outputs is None:
            raise FemromValueError("OKID needs outputs: the input-output data have none")
        shortest = min(window.stop - window.start for window in data.trajectories())
        rows, columns = self.blocks(data.n_outputs, data.n_inputs, shortest)
        tic = time.perf_counter()
        coefficients, diagnostics = observer_markov_parameters(data, self.observer_order,
                                                               feedthrough=self.feedthrough, at_rest=self.at_rest)
        markov = markov_from_observer(data, coefficients, diagnostics, self.observer_order, rows + columns + 1,
                                      feedthrough=self.feedthrough, at_rest=self.at_rest)
        ops = era_realization(markov, self.order, rows=rows, columns=columns,
                              output_directions=self.output_directions)
        gain = okid_observer_gain(coefficients, data.n_inputs, data.n_outputs, self.observer_order, ops.A, ops.C,
                                  rows, feedthrough=self.feedthrough)
        ops = replace(ops, observer_gain=gain)
        ops.metadata.update(method=self.method, observer_order=self.observer_order, feedthrough=self.feedthrough,
                            at_rest=self.at_rest, regression_residual=markov.metadata["regression_residual"],
                            regression_shape=markov.metadata["regression_shape"],
                            fit_seconds=time.perf_counter() - tic, n_trajectories=data.n_trajectories)
        self.markov_, self.operators_ = markov, ops
        return self

    def describe(self) -> dict:
        out = {"method": self.method, "order": self.order, "observer_order": self.observer_order,
               "rows": self.rows, "columns": self.columns, "feedthrough": self.feedthrough,
               "at_rest": self.at_rest, "output_directions": self.output_directions}
        if self.is_fitted:
            meta = self.operators_.metadata
            ops = self.operators_
            observer = ops.A - ops.observer_gain @ ops.C
            out.update(rows=meta["rows"], columns=meta["columns"], hankel_shape=meta["hankel_shape"],
                       spectral_radius=ops.spectral_radius,
                       observer_spectral_radius=float(np.max(np.abs(np.linalg.eigvals(observer)))),
                       regression_residual=meta["regression_residual"], regression_shape=meta["regression_shape"],
                       hankel_singular_values=meta["hankel_singular_values"][:self.order + 1],
                       fit_seconds=meta["fit_seconds"])
        return out
