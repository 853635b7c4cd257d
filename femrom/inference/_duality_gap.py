r"""How far a point is from the optimum of the structured regression: duality-gap certificates.

For any feasible ``X`` and multipliers ``Lambda_j >= 0`` (zero on "symmetric"
blocks), with ``N = Lambda - sym(grad f(X))``,

.. math::

    f(X) - f^\star \le \sum_j \langle \Lambda_j, X_j - \varepsilon_j I\rangle
                       + \frac{\|N\|_F^2}{4\, g_{\min}(G)}

(:func:`gap_bound`: the Lagrangian ``f(X + D) - <Lambda, X + D - eps I>`` is bounded
below over all symmetric ``D`` using ``<D G, D> >= g_min ||D||^2``; no linear solve).
The interior-point method evaluates it at every iterate with ``Lambda = Z``; it is
tight there because the dual residual ``N`` of the iterates falls to round-off
(1e-15) while ``<S, Z>`` goes to zero. The first-order path first tries it, then
:func:`gap_estimate`, a dual value from one symmetric least-squares solve
(:mod:`._face_lstsq`), which needs no ``G > 0``. Gaps are reported relative to the
objective (:func:`relative_gap`).
"""

from __future__ import annotations

import weakref
from dataclasses import replace

import numpy as np

from femrom.inference._face_lstsq import embed, make_faces, solve_faces
from femrom.inference._problem import GramProblem
from femrom.inference._svec import sym


def relative_gap(bound: float, f: float, problem: GramProblem) -> float:
    """``bound / |f|``, with ``|f|`` floored at ``eps * c``: the objective comes from the
    expansion ``<X G, X> + 2 <X, H^T> + c``, which cannot resolve values below that
    (data that a model fits to round-off give ``f = 0.0``)."""
    floor = max(np.finfo(float).eps * abs(problem.target), np.finfo(float).tiny)
    return float(bound / max(abs(f), floor))


def smallest_eigenvalue(G: np.ndarray) -> float:
    """A lower bound of ``lambda_min(G)``: the computed one minus the backward error
    of ``eigvalsh`` (``p eps ||G||``, generous); ``0`` if that is not positive."""
    g = np.linalg.eigvalsh(G)
    value = float(g[0] - G.shape[0] * np.finfo(float).eps * max(abs(g[-1]), abs(g[0])))
    return max(value, 0.0)


def gap_bound(problem: GramProblem, X: np.ndarray, multipliers=None, g_min: float | None = None):
    r"""Rigorous bound of ``f(X) - f*`` for a feasible ``X`` (module docstring), absolute.

    ``multipliers``: per block ``Lambda_j`` (zero on "symmetric" blocks); by default
    the minimiser of the bound over ``Lambda_j >= 0``,
    ``Pi_PSD(sym grad f(X)_j - 2 g_min (X_j - eps_j I))`` (complete the square in
    ``<Lambda, S> + ||Lambda - L0||^2 / (4 g_min)``). "free" blocks enter with
    their whole gradient. ``inf`` when ``G`` is singular.
    """
    if g_min is None:
        g_min = smallest_eigenvalue(problem.gram)
    if not g_min > 0:
        return np.inf
    grad = problem.gradient(X)
    eye = np.eye(problem.r)
    slack = residual = 0.0
    for j, (b, s) in enumerate(zip(problem.blocks, problem.slices())):
        if b.structure == "free":       # unconstrained: its whole gradient is residual
            residual += float(np.sum(grad[:, s] ** 2))
            continue
        L0 = sym(grad[:, s])
        if b.structure != "psd":
            residual += float(np.sum(L0 * L0))
            continue
        S = X[:, s] - b.shift * eye
        if multipliers is None:
            g, P = np.linalg.eigh(L0 - 2.0 * g_min * sym(S))
            Lam = (P * np.maximum(g, 0.0)) @ P.T
        else:
            Lam = multipliers[j]
        residual += float(np.sum((Lam - L0) ** 2))
        slack += float(np.sum(Lam * S))
    return max(slack, 0.0) + residual / (4.0 * g_min)


_G_MIN = weakref.WeakKeyDictionary()


def _g_min(problem: GramProblem) -> float:
    """:func:`smallest_eigenvalue` of ``problem.gram``, computed once per problem."""
    if problem not in _G_MIN:
        _G_MIN[problem] = smallest_eigenvalue(problem.gram)
    return _G_MIN[problem]


def gap_estimate(problem: GramProblem, X: np.ndarray, options, info) -> float:
    r"""Relative duality gap of a feasible ``X``, from the multipliers it suggests.

    First the rigorous bound :func:`gap_bound` (no linear solve; accepted when it is
    below ``options.tol``), otherwise the estimate below.
    Take ``Lambda_j = Pi_PSD(sym(grad f(X))_j)`` for the ``"psd"`` blocks
    (zero for the others) as dual point; its dual value is
    ``g = min_{X' symmetric} f(X') - sum_j <Lambda_j, X'_j - eps_j I>``, whose
    minimiser ``X'`` solves a symmetric least-squares problem (conjugate
    gradients, warm-started at ``X``). Then ``f(X) - f* <= f(X) - g``, and with
    ``D = X - X'`` the gap is evaluated without cancellation as

    .. math::

        f(X) - g = \langle \nabla f(X'), D\rangle + \langle D G, D\rangle
                   + \sum_j \langle \Lambda_j, X'_j - \varepsilon_j I\rangle .
    """
    bound = gap_bound(problem, X, g_min=_g_min(problem))
    relative = relative_gap(bound, problem.objective(X), problem)
    if relative <= options.tol:
        return relative
    grad = problem.gradient(X)
    r = problem.r
    multipliers = []
    for b, s in zip(problem.blocks, problem.slices()):
        if b.structure == "psd":
            g, P = np.linalg.eigh(0.5 * (grad[:, s] + grad[:, s].T))
            multipliers.append((P * np.maximum(g, 0.0)) @ P.T)
        else:
            multipliers.append(np.zeros((r, r)))
    shifted = replace(problem, cross=problem.cross - 0.5 * np.hstack(multipliers).T)
    nb = len(problem.blocks)
    full = make_faces(shifted, ([None] * nb, [0.0] * nb))
    As = solve_faces(shifted, full, [X[:, s] for s in problem.slices()], options, info)
    Xd = embed(shifted, full, As, False)
    D = X - Xd
    gap = float(np.sum(problem.gradient(Xd) * D) + np.sum((D @ problem.gram) * D))
    for b, s, Lam in zip(problem.blocks, problem.slices(), multipliers):
        shift = b.shift if b.structure == "psd" else 0.0
        gap += float(np.sum(Lam * (Xd[:, s] - shift * np.eye(r))))
    f = problem.objective(X)
    if gap < -max(1e-10 * abs(f), np.finfo(float).eps * abs(problem.target)):
        # f(X) - g(Lambda) >= f(X) - f* >= 0 for an exact dual value: a negative one means
        # the inner solve for X' was not accurate (a singular G), so nothing is certified
        return np.inf
    return relative_gap(max(gap, 0.0), f, problem)
