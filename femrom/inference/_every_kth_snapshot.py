r"""Learning from snapshots every k-th step: the reduced states between them, refined with the model.

A solver that saved every k-th of its steps ``dt`` leaves the reduced states
``x_j`` (``j`` on the fine grid of ``dt``) known at ``j = 0, k, 2k, ...`` only. The
integrator-consistent regression (:meth:`SecondOrderData.integrator_consistent`)
at ``dt`` needs all of them: with ``A x_j = (x_{j-1} + 2 x_j + x_{j+1}) / 4`` its
residual at every fine step is

.. math::

    r_j(x, \theta) = M^ \frac{x_{j+1} - 2 x_j + x_{j-1}}{dt^2}
    + C^ \frac{x_{j+1} - x_{j-1}}{2\,dt} + K^ A x_j - B^ A u_j - f^_0 ,

linear in the operators ``theta = (K^, C^, B^, f^_0)`` for fixed states and linear
in the unknown states for fixed operators. :func:`fill_between_snapshots` solves the
second least-squares problem (the known states held); :func:`alternating_fill`
alternates it with the learner's fit from a cubic-spline start
(:meth:`SecondOrderData.upsampled`): block coordinate descent on
``sum_j ||r_j||^2`` (plus the learner's regularization), whose value never rises,
and the learner's constraints (L-OpInf's ``K^ = K^^T > 0``, ``C^ >= 0``) hold at
every sweep. Linear reduced models only: a nonlinear term would make the state
step a nonlinear least-squares problem with full-order force evaluations.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femrom._errors import FemromRuntimeError, FemromValueError
from femrom.inference._data import SecondOrderData


def newmark_residual_matrix(operators, n_steps: int, dt: float) -> sp.csr_matrix:
    r"""The map ``x -> (r_1, ..., r_{N-1})`` without its input part, as a sparse matrix.

    Parameters
    ----------
    operators : ReducedOperators
        Linear (``M^``, ``C^``, ``K^``).
    n_steps : int
        ``N``: the states are ``x_0 .. x_N``, stacked time-major (``x_j`` at rows
        ``j r .. (j + 1) r``).
    dt : float

    Returns
    -------
    ((N - 1) r, (N + 1) r) csr_matrix
        Row block ``j - 1`` holds ``P_- x_{j-1} + P_0 x_j + P_+ x_{j+1}`` with
        ``P_± = M^/dt^2 ± C^/(2 dt) + K^/4`` and ``P_0 = -2 M^/dt^2 + K^/2``.
    """
    M, K = operators.mass_matrix, operators.stiffness
    C = np.zeros_like(K) if operators.damping is None else operators.damping
    lower, middle, upper = M / dt**2 - C / (2 * dt) + K / 4, -2 * M / dt**2 + K / 2, M / dt**2 + C / (2 * dt) + K / 4
    shift = lambda o: sp.eye(n_steps - 1, n_steps + 1, o, format="csr")  # noqa: E731
    return (sp.kron(shift(0), lower) + sp.kron(shift(1), middle) + sp.kron(shift(2), upper)).tocsr()


def fill_between_snapshots(operators, data: SecondOrderData, known) -> SecondOrderData:
    r"""``data`` with its states at the columns not in ``known`` replaced by the least-squares fit.

    Minimises ``sum_j ||r_j||^2`` (module docstring) over the unknown columns with the
    known ones held; the normal equations are block-banded, solved sparse.

    Parameters
    ----------
    operators : ReducedOperators
        A linear model (``is_linear``) in the data's ``r`` coordinates.
    data : SecondOrderData
        One trajectory on the fine grid (``diagnostics["dt"]``), all columns present
        (the unknown ones any start, e.g. splines).
    known : (K',) int array
        The columns that are data (the snapshots kept).

    Returns
    -------
    SecondOrderData
        The same data with the unknown states replaced; inputs, outputs unchanged.
    """
    if not operators.is_linear:
        names = [t.name for t in operators.terms if t.name not in ("stiffness", "mass", "damping", "input",
                                                                  "output", "load")]
        raise FemromValueError(f"filling between snapshots takes linear reduced models; this one has {names}")
    if data.nonlinear_forces is not None:
        raise FemromValueError("filling between snapshots takes data without known nonlinear forces "
                               "(they would need evaluating at the new states)")
    dt = data.diagnostics.get("dt")
    if dt is None or len(data.starts) > 1:
        raise FemromValueError("filling between snapshots needs one trajectory with a known step dt")
    X = data.states
    r, n_columns = X.shape
    if operators.r != r:
        raise FemromValueError(f"the model has r = {operators.r}, the data r = {r}")
    known = np.unique(np.asarray(known, dtype=int))
    if known.size == 0 or known[0] < 0 or known[-1] >= n_columns:
        raise FemromValueError(f"known columns must lie in 0..{n_columns - 1}")
    unknown = np.setdiff1d(np.arange(n_columns), known)
    if unknown.size == 0:
        return data
    N = n_columns - 1
    A, forcing = newmark_residual_matrix(operators, N, dt), _forcing(operators, data)
    columns = lambda j: (j[:, None] * r + np.arange(r)).ravel()  # noqa: E731
    A_unknown = A[:, columns(unknown)]
    rhs = forcing.T.ravel() - A[:, columns(known)] @ X[:, known].T.ravel()
    normal = (A_unknown.T @ A_unknown).tocsc()
    solution = spla.spsolve(normal, A_unknown.T @ rhs)
    if not np.all(np.isfinite(solution)):
        raise FemromRuntimeError("the states between the snapshots are not determined by this model "
                                 "(singular normal equations)")
    states = X.copy()
    states[:, unknown] = solution.reshape(unknown.size, r).T
    return replace(data, states=states)


@dataclass(frozen=True)
class FillSweep:
    """One sweep of :func:`alternating_fill`.

    Attributes
    ----------
    sweep : int
        0 for the spline start.
    residual : float
        ``||r||_2 / ||B^ A u + f^_0||_2`` after the learner's fit (the regression's
        relative residual).
    change : float
        Relative change of the unknown states in this sweep (``nan`` at 0).
    """

    sweep: int
    residual: float
    change: float


def _forcing(operators, data: SecondOrderData) -> np.ndarray:
    """(r, N - 1) ndarray ``B^ A u_j + f^_0`` at the interior fine steps."""
    forcing = np.zeros((operators.r, data.n_samples - 2))
    if operators.input_matrix is not None:
        U = data.inputs
        forcing += operators.input_matrix @ (0.25 * (U[:, :-2] + 2.0 * U[:, 1:-1] + U[:, 2:]))
    if operators.load is not None:
        forcing += operators.load[:, None]
    return forcing


def _relative_residual(operators, data: SecondOrderData) -> float:
    A = newmark_residual_matrix(operators, data.n_samples - 1, data.diagnostics["dt"])
    forcing = _forcing(operators, data)
    scale = np.linalg.norm(forcing)
    residual = np.linalg.norm(A @ data.states.T.ravel() - forcing.T.ravel())
    return float(residual / scale) if scale > 0 else float(residual)


def alternating_fill(learner, data: SecondOrderData, substeps: int, *, inputs=None, sweeps: int = 40,
                     rtol: float = 1e-3, progress=None):
    r"""Fit ``learner`` to snapshots every ``substeps``-th step of ``dt``, the states between them refined.

    Starts from the cubic-spline fill (:meth:`SecondOrderData.upsampled`) and
    alternates the learner's fit to the integrator-consistent data at ``dt`` with
    :func:`fill_between_snapshots`, until a sweep lowers the relative Newmark
    residual by less than ``rtol`` of its value or ``sweeps`` sweeps are done;
    the learner ends fitted to the last fill. The convergence is linear and slow
    (measured on the fishtail at k = 2: the residual falls 1.5e-6 -> 7e-8 -> 8e-9
    in 0, 10, 40 sweeps, the test error 3.1e-3 -> 9.9e-4 -> 6.3e-4).

    Parameters
    ----------
    learner : SecondOrderLearner
        Refitted in place (``fit(data) -> self``); its model must be linear.
    data : SecondOrderData
        One trajectory sampled every ``substeps``-th step: ``diagnostics["dt"]`` is
        the spacing ``h = substeps dt``.
    substeps : int
        ``k``.
    inputs : (m, (K - 1) k + 1) ndarray, optional
        The inputs at every ``dt`` (interpolated if not given).
    sweeps : int
        At most this many refinements after the spline start.
    rtol : float
    progress : callable, optional
        Called with a line per sweep.

    Returns
    -------
    fine : SecondOrderData
        The last fill on the fine grid (before the integrator-consistent averaging).
    history : list of FillSweep
    """
    k = int(substeps)
    fine = data.upsampled(k, inputs)
    learner.fit(fine.integrator_consistent())
    history = [FillSweep(0, _relative_residual(learner.operators_, fine), float("nan"))]
    known = np.arange(0, fine.n_samples, k)
    unknown = np.setdiff1d(np.arange(fine.n_samples), known)
    for sweep in range(1, int(sweeps) + 1 if unknown.size else 1):
        previous = fine.states[:, unknown]
        fine = fill_between_snapshots(learner.operators_, fine, known)
        learner.fit(fine.integrator_consistent())
        change = float(np.linalg.norm(fine.states[:, unknown] - previous) / max(np.linalg.norm(previous), 1e-300))
        history.append(FillSweep(sweep, _relative_residual(learner.operators_, fine), change))
        if progress is not None:
            progress(f"fill sweep {sweep}: residual {history[-1].residual:.3e}, change {change:.2e}")
        if history[-2].residual - history[-1].residual < rtol * history[-2].residual:
            break
    return fine, history
