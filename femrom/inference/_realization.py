r"""Realisation from Markov parameters (ERA) and Markov parameters from input-output data (OKID).

**ERA** (Juang & Pappa, J. Guid. Control Dyn. 8(5), 1985). With ``a`` block
rows and ``b`` block columns, the block Hankel matrices

.. math::

    H_0 = \begin{bmatrix} Y_1 & Y_2 & \cdots & Y_b \\ Y_2 & Y_3 & & \\ \vdots & & \ddots & \\
          Y_a & & & Y_{a+b-1} \end{bmatrix}, \qquad
    H_1 = \text{the same with } Y_{i+j} \text{ shifted by one},

both (a p, b m), factor as ``H_0 = O R`` (observability times controllability)
and ``H_1 = O A R``. The rank-``n`` truncated SVD ``H_0 ~ P_n S_n Q_n^T`` gives
the balanced realisation

.. math::

    A = S_n^{-1/2} P_n^\top H_1 Q_n S_n^{-1/2}, \quad
    B = S_n^{1/2} Q_n^\top E_m, \quad C = E_p^\top P_n S_n^{1/2}, \quad D = Y_0,

``E_m`` the first ``m`` columns of the identity (the first block column),
``E_p`` the first ``p``. It needs ``Y_0 ... Y_{a+b}`` and costs one SVD of an
(a p, b m) matrix, ``O(a p (b m)^2)`` for ``a p >= b m``; the singular values
``S`` are the Hankel singular values of the finite-horizon impulse response
and show the order. For many outputs the Hankel matrix may first be reduced
*tangentially*: ``Y_k -> W^T Y_k R`` with ``W`` (p, k_o) and ``R`` (m, k_i)
the leading left and right singular vectors of the Markov parameters side by
side, then ``B = B~ R^T``, ``C = W C~``.

**OKID** (Juang, Phan, Horta & Longman, J. Guid. Control Dyn. 16(2), 1993).
An observer with gain ``G`` rewrites the model as

.. math::

    z_{k+1} = \bar A z_k + \bar B v_k, \quad \bar A = A + G C, \quad
    \bar B = [B + G D, \; -G], \quad v_k = \begin{bmatrix} u_k \\ y_k \end{bmatrix},

and for an observer with ``Abar^l ~ 0`` (deadbeat when exact, the Kalman
filter's when the data are noisy) the outputs are a finite regression on the
last ``l`` samples,

.. math::

    y_k = D u_k + \sum_{i=1}^{l} \bar Y_i v_{k-i}, \qquad
    \bar Y_i = C \bar A^{i-1} \bar B = [\bar Y_i^{(1)}, \bar Y_i^{(2)}],

solved by least squares over every ``k >= l`` of every trajectory (from
``k = 0`` with zero samples before the start for data from rest). The system's
Markov parameters follow from the observer's,

.. math::

    Y_0 = D, \qquad Y_k = \bar Y_k^{(1)} + \sum_{i=1}^{\min(k, l)} \bar Y_i^{(2)} Y_{k-i}
    \quad (\bar Y_k^{(1)} = 0 \text{ for } k > l),

as many as ERA asks for. The regression has ``m + l (m + p)`` unknowns per
output row; noise-free data of an order-``n`` model are fitted exactly once
``l`` reaches the observability index of ``(A, C)`` (the smallest ``l`` with
``rank [C; C A; ...; C A^{l-1}] = n``: a deadbeat observer exists; ``l p >= n``
is necessary, and enough for a generic ``C``, not for displacement outputs of a
structure), and every exact solution gives the same ``Y_k``.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
import scipy.linalg

from femrom._errors import FemromTypeError, FemromValueError
from femrom._progress import Stage
from femrom.inference._io_data import InputOutputData, MarkovParameters
from femrom.inference._state_space import StateSpaceOperators

#: Singular values kept in a realisation's metadata beyond its order.
KEPT_SINGULAR_VALUES = 10


def block_hankel(markov: np.ndarray, rows: int, columns: int, shift: int = 0) -> np.ndarray:
    r"""(rows p, columns m) ndarray whose block ``(i, j)`` is ``Y_{1 + i + j + shift}``.

    ``markov`` is (N, p, m) with ``N >= rows + columns + shift``.
    """
    Y = np.asarray(markov, dtype=float)
    N, p, m = Y.shape
    if N < rows + columns + shift:
        raise FemromValueError(f"a ({rows} x {columns}) block Hankel matrix shifted by {shift} needs "
                               f"{rows + columns + shift} Markov parameters, got {N}")
    H = np.empty((rows * p, columns * m))
    for i in range(rows):
        # block row i: Y_{1+i+shift} ... Y_{columns+i+shift}, side by side
        H[i * p:(i + 1) * p] = np.moveaxis(Y[1 + i + shift:1 + i + shift + columns], 0, 1).reshape(p, columns * m)
    return H


def hankel_blocks(count: int, rows: int | None, columns: int | None) -> tuple[int, int]:
    """Block rows and columns of ERA with ``count`` Markov parameters (``None``: split them evenly)."""
    usable = count - 1           # Y_1 ... Y_{count-1}; H_1 reaches Y_{rows+columns}
    if rows is None and columns is None:
        columns = usable // 2
        rows = usable - columns
    elif rows is None:
        rows = usable - int(columns)
    elif columns is None:
        columns = usable - int(rows)
    rows, columns = int(rows), int(columns)
    if rows < 1 or columns < 1:
        raise FemromValueError(f"ERA needs at least 1 block row and column, got rows = {rows}, columns = {columns} "
                               f"from {count} Markov parameters")
    if rows + columns > usable:
        raise FemromValueError(f"ERA with {rows} block rows and {columns} block columns needs "
                               f"{rows + columns + 1} Markov parameters (Y_0 ... Y_{rows + columns}), got {count}")
    return rows, columns


def _directions(Y: np.ndarray, count: int | None, side: str) -> np.ndarray | None:
    """The leading ``count`` left (``side="output"``) or right singular vectors of the Markov parameters."""
    if count is None:
        return None
    N, p, m = Y.shape
    size = p if side == "output" else m
    count = int(count)
    if not 1 <= count <= size:
        raise FemromValueError(f"{side}_directions must be between 1 and {size}, got {count}")
    if side == "output":
        U, _, _ = np.linalg.svd(np.moveaxis(Y[1:], 0, 1).reshape(p, -1), full_matrices=False)
        return U[:, :count]
    _, _, Vt = np.linalg.svd(Y[1:].reshape(-1, m), full_matrices=False)
    return Vt[:count].T


def era_realization(markov: MarkovParameters, order: int, *, rows: int | None = None,
                    columns: int | None = None, output_directions: int | None = None,
                    input_directions: int | None = None, progress: bool | None = None) -> StateSpaceOperators:
    r"""The balanced realisation of order ``n`` from Markov parameters (ERA, module doc).

    Parameters
    ----------
    markov : MarkovParameters
        ``Y_0 ... Y_{N-1}``, (N, p, m).
    order : int
        ``n``, at most the numerical rank of ``H_0``.
    rows, columns : int, optional
        Block rows ``a`` and columns ``b`` (default: ``Y_1 ... Y_{N-1}`` split evenly).
    output_directions, input_directions : int, optional
        Tangential reduction of the outputs (inputs) to this many directions before
        the Hankel matrix is formed (default: none).
    progress : bool, optional
        A progress line around the SVD (:class:`femrom._progress.Stage`).

    Returns
    -------
    StateSpaceOperators
        ``metadata``: ``hankel_shape``, ``rows``, ``columns``, the leading
        ``hankel_singular_values``, ``svd_seconds``.
    """
    order = int(order)
    Y = markov.parameters
    N, p, m = Y.shape
    if order < 1:
        raise FemromValueError(f"order must be at least 1, got {order}")
    rows, columns = hankel_blocks(N, rows, columns)
    W = _directions(Y, output_directions, "output")
    R = _directions(Y, input_directions, "input")
    Yt = Y
    if W is not None:
        Yt = np.einsum("pk,npm->nkm", W, Yt)
    if R is not None:
        Yt = np.einsum("npm,ml->npl", Yt, R)
    _, pt, mt = Yt.shape
    if order > min(rows * pt, columns * mt):
        raise FemromValueError(f"order {order} exceeds the size of the ({rows * pt} x {columns * mt}) Hankel matrix "
                               f"({rows} block rows, {columns} block columns): give more Markov parameters or blocks")
    H0 = block_hankel(Yt, rows, columns)
    H1 = block_hankel(Yt, rows, columns, shift=1)
    flops = 4.0 * H0.shape[0] * H0.shape[1] * min(H0.shape)
    if flops > LARGE_SVD_FLOPS:
        warnings.warn(f"ERA: the Hankel matrix is {H0.shape[0]} x {H0.shape[1]} ({rows} block rows x {pt} outputs, "
                      f"{columns} block columns x {mt} inputs); its SVD takes about {flops:.1e} flops. Fewer rows or "
                      "columns, or output_directions, make it smaller", LargeHankelWarning, stacklevel=2)
    tic = time.perf_counter()
    with Stage(f"ERA: SVD of the {H0.shape[0]} x {H0.shape[1]} Hankel matrix", enabled=progress):
        P, s, Qt = scipy.linalg.svd(H0, full_matrices=False, lapack_driver="gesdd")
    seconds = time.perf_counter() - tic
    floor = s[0] * max(H0.shape) * np.finfo(float).eps
    if not s[order - 1] > floor:
        rank = int(np.sum(s > floor))
        raise FemromValueError(f"order {order} exceeds the numerical rank {rank} of the Hankel matrix "
                               f"(singular value {order} is {s[order - 1]:.3g}, largest {s[0]:.3g}): lower the order")
    root = np.sqrt(s[:order])
    Pn, Qn = P[:, :order], Qt[:order].T
    A = (Pn.T @ H1 @ Qn) / np.outer(root, root)
    B = root[:, None] * Qn[:mt].T
    C = Pn[:pt] * root[None, :]
    if R is not None:
        B = B @ R.T
    if W is not None:
        C = W @ C
    metadata = {"method": "era", "order": order, "rows": rows, "columns": columns,
                "hankel_shape": list(H0.shape), "svd_seconds": seconds,
                "hankel_singular_values": s[:order + KEPT_SINGULAR_VALUES].tolist(),
                "output_directions": output_directions, "input_directions": input_directions,
                "markov_count": N}
    return StateSpaceOperators(A=A, B=B, C=C, D=markov.feedthrough.copy(), dt=markov.dt, metadata=metadata)


#: Flops of the Hankel matrix's SVD (``4 a b min(a, b)``) above which ERA says so before it starts:
#: a few seconds or more (a 10,000 x 3,000 Hankel matrix, 3.6e11 flops, took 20 s on a 2-core machine).
LARGE_SVD_FLOPS = 5e10


class LargeHankelWarning(UserWarning):
    """ERA was asked for a Hankel matrix whose SVD takes long (its size and cost are said)."""


def _observer_regression(data: InputOutputData, observer_order: int, feedthrough: bool, at_rest: bool):
    """``(Phi, Y)``: the regressors (m' + l (m + p), N) and targets (p, N) of the observer's least squares."""
    l, m = observer_order, data.n_inputs
    V = np.vstack([data.inputs, data.outputs])          # v_k = [u_k; y_k]
    phis, targets = [], []
    for window in data.trajectories():
        U, Vj, Yj = data.inputs[:, window], V[:, window], data.outputs[:, window]
        if at_rest:
            pad = lambda X: np.hstack([np.zeros((X.shape[0], l)), X])  # noqa: E731
            U, Vj, Yj = pad(U), pad(Vj), pad(Yj)
        K = U.shape[1]
        if K <= l:
            continue
        blocks = [U[:, l:]] if feedthrough else []
        blocks += [Vj[:, l - i:K - i] for i in range(1, l + 1)]
        phis.append(np.vstack(blocks) if blocks else np.zeros((0, K - l)))
        targets.append(Yj[:, l:])
    unknowns = (m if feedthrough else 0) + l * (m + data.n_outputs)
    equations = sum(t.shape[1] for t in targets)
    if equations < unknowns:
        raise FemromValueError(f"OKID with observer order {l} has {unknowns} unknowns per output but the data give "
                               f"{equations} equations: more samples or a lower observer_order")
    return np.hstack(phis), np.hstack(targets)


def observer_markov_parameters(data: InputOutputData, observer_order: int, *, feedthrough: bool = True,
                               at_rest: bool = False, progress: bool | None = None) -> tuple[np.ndarray, dict]:
    r"""``[D, Ybar_1, ..., Ybar_l]`` (p, m' + l (m + p)) by least squares (module doc), and diagnostics.

    Parameters
    ----------
    data : InputOutputData
        With outputs.
    observer_order : int
        ``l >= 1``.
    feedthrough : bool
        Fit ``D`` (else ``D = 0`` and ``m' = 0``).
    at_rest : bool
        Every trajectory starts from rest (zero state and zero samples before it):
        the first ``l`` samples of each give equations too.

    Returns
    -------
    coefficients : (p, m' + l (m + p)) ndarray
    diagnostics : dict
        ``residual`` (relative), ``rank`` and ``shape`` of the regression, ``seconds``.
    """
    if not isinstance(data, InputOutputData):
        raise FemromTypeError(f"OKID takes InputOutputData, got {type(data).__name__}")
    if data.outputs is None:
        raise FemromValueError("OKID needs outputs: the input-output data have none")
    l = int(observer_order)
    if l < 1:
        raise FemromValueError(f"observer_order must be at least 1, got {observer_order}")
    Phi, Y = _observer_regression(data, l, feedthrough, at_rest)
    tic = time.perf_counter()
    with Stage(f"OKID: least squares {Phi.shape[1]} x {Phi.shape[0]}", enabled=progress):
        coefficients, residual, rank = _least_squares(Phi, Y)
        if not feedthrough and residual > 0:
            _refuse_hidden_feedthrough(data, l, at_rest, residual)
    seconds = time.perf_counter() - tic
    return coefficients, {"residual": residual, "rank": int(rank), "shape": list(Phi.T.shape),
                          "seconds": seconds}


#: ``feedthrough=False`` is refused when fitting ``D`` too lowers the observer regression's
#: relative residual below this fraction of its value: the outputs then respond to the input of
#: the same sample. Noise alone lowers it by about ``m / (equations per output)`` (a few per cent
#: at most for a regression that is not underdetermined), a feedthrough by orders of magnitude.
HIDDEN_FEEDTHROUGH_RATIO = 0.5


def _least_squares(Phi: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, float, int]:
    """``(Theta, relative residual, rank)`` of ``min ||Y - Theta Phi||_F``."""
    theta, _, rank, _ = scipy.linalg.lstsq(Phi.T, Y.T, lapack_driver="gelsd")
    coefficients = theta.T
    den = np.linalg.norm(Y)
    residual = float(np.linalg.norm(Y - coefficients @ Phi) / den) if den > 0 else 0.0
    return coefficients, residual, int(rank)


def _refuse_hidden_feedthrough(data: InputOutputData, observer_order: int, at_rest: bool, residual: float) -> None:
    """One error when the data say ``y_k`` depends on ``u_k`` but ``feedthrough=False`` was asked."""
    _, with_d, _ = _least_squares(*_observer_regression(data, observer_order, True, at_rest))
    if with_d < HIDDEN_FEEDTHROUGH_RATIO * residual:
        raise FemromValueError(
            f"OKID(feedthrough=False): the outputs respond to the input of the same sample (the observer "
            f"regression leaves {residual:.3g} of the outputs unexplained without a feedthrough D, {with_d:.3g} "
            "with one); use feedthrough=True")


def system_markov_from_observer(coefficients: np.ndarray, n_inputs: int, n_outputs: int, observer_order: int,
                                count: int, *, feedthrough: bool = True) -> np.ndarray:
    r"""(count, p, m) ndarray ``Y_0 ... Y_{count-1}`` from the observer's (module doc)."""
    m, p, l = n_inputs, n_outputs, observer_order
    offset = m if feedthrough else 0
    Y = np.empty((count, p, m))
    Y[0] = coefficients[:, :m] if feedthrough else 0.0
    blocks = coefficients[:, offset:].reshape(p, l, m + p)
    first, second = blocks[:, :, :m], blocks[:, :, m:]          # Ybar_i^(1) (p, l, m), Ybar_i^(2) (p, l, p)
    for k in range(1, count):
        Yk = first[:, k - 1].copy() if k <= l else np.zeros((p, m))
        for i in range(1, min(k, l) + 1):
            Yk += second[:, i - 1] @ Y[k - i]
        Y[k] = Yk
    return Y


def okid_observer_gain(coefficients: np.ndarray, n_inputs: int, n_outputs: int, observer_order: int,
                       A: np.ndarray, C: np.ndarray, horizon: int, *, feedthrough: bool = True) -> np.ndarray:
    r"""(n, p) gain ``L`` of the observer ``z^+ = A z^ + B u + L (y - C z^ - D u)`` identified with the model.

    The observer's own Markov parameters ``Y^o_k = C A^{k-1} G`` (``G = -L``) follow
    from ``Ybar_i^(2) = -C Abar^{i-1} G`` by the recursion

    .. math::

        Y^o_k = -\bar Y_k^{(2)} + \sum_{i=1}^{\min(k-1, l)} \bar Y_i^{(2)} Y^o_{k-i}
        \quad (\bar Y_k^{(2)} = 0 \text{ for } k > l),

    (from ``C (zI - A)^{-1} G = -ybar + ybar C (zI - A)^{-1} G``), and
    ``G = O_s^+ [Y^o_1; ...; Y^o_s]`` in the realisation's coordinates, ``O_s``
    the observability matrix of ``(A, C)`` with ``s = horizon`` blocks (Juang et
    al. 1993). With noisy data the least-squares observer tends to the Kalman
    filter's one-step predictor.
    """
    m, p, l = n_inputs, n_outputs, observer_order
    offset = m if feedthrough else 0
    second = coefficients[:, offset:].reshape(p, l, m + p)[:, :, m:]      # Ybar_i^(2), (p, l, p)
    h = []
    for k in range(1, horizon + 1):
        hk = -second[:, k - 1].copy() if k <= l else np.zeros((p, p))
        for i in range(1, min(k - 1, l) + 1):
            hk += second[:, i - 1] @ h[k - i - 1]
        h.append(hk)
    blocks, CAk = [], np.asarray(C, dtype=float)
    for _ in range(horizon):
        blocks.append(CAk)
        CAk = CAk @ A
    G = np.linalg.lstsq(np.vstack(blocks), np.vstack(h), rcond=None)[0]
    return -G


def okid_markov_parameters(data: InputOutputData, observer_order: int, count: int, *, feedthrough: bool = True,
                           at_rest: bool = False, progress: bool | None = None) -> MarkovParameters:
    r"""The system's Markov parameters ``Y_0 ... Y_{count-1}`` estimated from input-output data by OKID.

    The observer's least squares (:func:`observer_markov_parameters`) and the
    recursion of the module doc; ``metadata`` holds the regression's diagnostics.
    """
    count = int(count)
    if count < 2:
        raise FemromValueError(f"count must be at least 2, got {count}")
    coefficients, diagnostics = observer_markov_parameters(data, observer_order, feedthrough=feedthrough,
                                                           at_rest=at_rest, progress=progress)
    return markov_from_observer(data, coefficients, diagnostics, int(observer_order), count,
                                feedthrough=feedthrough, at_rest=at_rest)


def markov_from_observer(data: InputOutputData, coefficients: np.ndarray, diagnostics: dict, observer_order: int,
                         count: int, *, feedthrough: bool, at_rest: bool) -> MarkovParameters:
    """:class:`MarkovParameters` of the system from the observer's coefficients and the regression's diagnostics."""
    with np.errstate(over="ignore", invalid="ignore"):
        Y = system_markov_from_observer(coefficients, data.n_inputs, data.n_outputs, observer_order, count,
                                        feedthrough=feedthrough)
    finite = np.isfinite(Y).all(axis=(1, 2))
    if not finite.all():
        first = int(np.argmin(finite))
        raise FemromValueError(
            f"OKID: the system's Markov parameters, recovered through the identified observer, overflow at "
            f"k = {first} of {count}: the observer is unstable (its regression leaves "
            f"{diagnostics['residual']:.3g} of the outputs unexplained); lower observer_order or ask for fewer "
            "Markov parameters (rows, columns)")
    return MarkovParameters(Y, dt=data.dt, layout="npm",
                            metadata={"source": "okid", "observer_order": observer_order,
                                      "feedthrough": feedthrough, "at_rest": at_rest,
                                      **{f"regression_{k}": v for k, v in diagnostics.items()}})
