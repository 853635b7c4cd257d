r"""The nonlinear equation of one implicit step, and Newton on the force's own coordinates.

Every implicit scheme of this package reduces a step of
``M q'' + C q' + K q + f(q, q'; s) = B u`` to

.. math::

    S x + w\, f(q_0 + c_q x,\; v_0 + c_v x;\; s) = b

for one unknown ``x`` (n,): the new acceleration for the Newmark family
(``S = (1 - alpha_m) M + (1 - alpha_f)(gamma h C + beta h^2 K)``, ``w = 1``),
the midpoint velocity for the implicit midpoint rule (``S = M + h C / 2 + h^2
K / 4``, ``w = h / 2``). ``S`` is fixed for a given ``dt``; the state ``s`` of
a stateful force is frozen during the iterations.

Three ways to solve it (:class:`ImplicitSolve`, chosen by ``Newton.method``):

``"full"``
    Newton on all n unknowns with the tangent ``S + w (c_q df/dq + c_v
    df/dv)``, factorised afresh every iteration.
``"condensed"``
    For ``f = L^T g(L q, L v; s)`` with ``s_loc`` local coordinates (``L``
    (s_loc, n), e.g. the dofs of a contact interface or a spring layer).
    Once per ``dt``, with the one factorisation of ``S``: ``G = L S^{-1} L^T``
    (s_loc solves, in blocks) and its inverse ``Sigma = G^{-1}``, the Schur
    complement of the linear step onto the force's coordinates. Each step: one
    solve ``x_lin = S^{-1} b``, then Newton on ``xi = L x`` alone,

    .. math::

        R(\xi) = \Sigma (\xi - L x_{lin}) + w\, g(L q_0 + c_q \xi, L v_0 + c_v \xi; s) = 0,
        \qquad \big(\Sigma + w (c_q\, \partial g/\partial x + c_v\, \partial g / \partial \dot x)\big)\,
        \delta\xi = -R,

    an (s_loc, s_loc) dense system, and finally ``x = x_lin - w S^{-1} L^T
    g(xi)`` (a stored ``Z = S^{-1} L^T`` when it fits the memory budget, else
    one more solve). This is exact, not an approximation: ``L x = xi`` and ``S
    x + w L^T g = b`` hold to the solver's accuracy. The linear part is
    never refactorised. The (s_loc, s_loc) tangent at rest is factorised once
    per ``dt`` (Cholesky when symmetric positive definite, else LU); a step
    iterates with it (chord steps, ``O(s_loc^2)`` each) while every iteration
    reduces the residual at least by ``Newton.refactor_ratio``, and otherwise
    refactorises at the current iterate for the rest of that step. The
    stopping test is the same either way: this changes what an iteration
    costs, not where a step converges; and a step depends on its own inputs
    only, so a resumed run repeats an unbroken one bit for bit.

``"dense"``
    Newton on all n unknowns with dense arrays, for a small system (a reduced
    model): the force's ``dense_force_and_tangent`` (when it has one, e.g. a
    projected joint, :class:`femrom.fem.TransformedForce`) gives force and
    tangent from one evaluation of its law per iteration; no sparse matrix is
    built or factorised in the loop.

``"auto"`` takes the dense path up to ``Newton.dense_max`` dofs; above it, it condenses when the force has a local map with at most
``Newton.condense_max`` coordinates and at most ``Newton.condense_fraction``
of the dofs, and runs the full Newton otherwise (a force on every dof, such
as the sine-Gordon chain's, gains nothing from condensation).
"""

from __future__ import annotations

import contextlib
import time

import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.integrators._newton import ConvergenceError, Newton, TangentMatrix, newton_loop, solve_newton


def dense(system, newton: Newton) -> bool:
    """Whether the model is held in ndarrays (a reduced model: always dense), or ``newton`` asks for
    (``"dense"``) or allows (``"auto"``, ``n <= dense_max``) dense Newton."""
    if not sp.issparse(system.stiffness):
        return True
    return newton.method == "dense" or (newton.method == "auto" and system.n_dofs <= newton.dense_max)


def condensable(system, newton: Newton) -> bool:
    """Whether ``newton`` asks for (``"condensed"``) or allows (``"auto"``) condensation of ``system``."""
    force = system.nonlinear
    L = getattr(force, "local_map", None)
    if newton.method in ("full", "dense") or L is None:
        if newton.method == "condensed":
            raise FemromValueError(f"Newton(method='condensed') needs a force with a local map; "
                             f"{type(force).__name__} has none")
        return False
    if newton.method == "condensed":
        return True
    s, n = L.shape
    return s <= newton.condense_max and s <= newton.condense_fraction * n


class ImplicitSolve:
    r"""Solver of ``S x + w f(q0 + c_q x, v0 + c_v x; s) = b`` for one scheme and ``dt``.

    Parameters
    ----------
    system : SecondOrderSystem
        With a nonlinear force.
    effective_matrix : (n, n) sparse
        ``S``.
    c_q, c_v, w : float
    make_solver : callable
        ``(A, spd=...) -> LinearSolver`` (counted by the driver).
    newton : Newton

    Attributes
    ----------
    method : {"full", "condensed"}
    details : dict
        Sizes and set-up times (``condensed_coordinates``, ``condensation_seconds``,
        ``influence_stored``) and, for the condensed method, running totals:
        ``local_newton_seconds`` (the iterations on the force's coordinates),
        ``local_iterations``, ``local_factorizations`` (of the (s, s) tangent),
        ``linear_solve_seconds`` (the solves and products with the linear part).
    """

    def __init__(self, system, effective_matrix, c_q: float, c_v: float, w: float, make_solver,
                 newton: Newton):
        self.system, self.c_q, self.c_v, self.w = system, float(c_q), float(c_v), float(w)
        self.newton, self.make_solver = newton, make_solver
        self.S = effective_matrix
        self.details: dict = {}
        if dense(system, newton):
            self.method = "dense"
            self._S_dense = effective_matrix.toarray() if hasattr(effective_matrix, "toarray") \
                else np.asarray(effective_matrix, dtype=float)
            self._together = getattr(system.nonlinear, "dense_force_and_tangent", None)
        elif condensable(system, newton):
            self.method = "condensed"
            self._setup_condensed()
            self.details.update(local_newton_seconds=0.0, local_iterations=0, local_factorizations=0,
                                linear_solve_seconds=0.0)
            try:
                from threadpoolctl import ThreadpoolController
                self._blas = ThreadpoolController().select(internal_api="openblas")
            except ImportError:  # pragma: no cover - threadpoolctl is a dependency
                self._blas = None
            zero = np.zeros(self.L.shape[0])
            self._initial_tangent = self._factorize(
                self.force.local_tangent(zero, zero, self.force.initial_state()))
        else:
            self.method = "full"
            self.tangent = TangentMatrix(effective_matrix, w * c_q, w * c_v)
        self.details["newton"] = self.method

    # -- full Newton -------------------------------------------------------------
    def _full(self, b, q0, v0, state, guess):
        force, S, w = self.system.nonlinear, self.S, self.w

        def residual(x):
            f = force.force(q0 + self.c_q * x, v0 + self.c_v * x, state)
            Sx = S @ x
            return Sx - b + w * f, float(np.linalg.norm(Sx) + np.linalg.norm(b) + w * np.linalg.norm(f))

        def jacobian(x):
            return self.tangent(*force.tangent(q0 + self.c_q * x, v0 + self.c_v * x, state))

        return solve_newton(residual, jacobian, guess, self.make_solver, self.newton)

    # -- dense Newton -----------------------------------------------------------------
    def _force_and_tangent(self, q, v, state):
        if self._together is not None:
            return self._together(q, v, state)
        force = self.system.nonlinear
        f = force.force(q, v, state)
        return (f, *(None if D is None else (D.toarray() if hasattr(D, "toarray") else np.asarray(D))
                     for D in force.tangent(q, v, state)))

    def _dense(self, b, q0, v0, state, guess):
        """Newton with dense arrays: force and tangent from one evaluation per iteration (a small system)."""
        S, w, c_q, c_v = self._S_dense, self.w, self.c_q, self.c_v

        def evaluate(x):
            f, dfdq, dfdv = self._force_and_tangent(q0 + c_q * x, v0 + c_v * x, state)
            Sx = S @ x
            scale = float(np.linalg.norm(Sx) + np.linalg.norm(b) + w * np.linalg.norm(f))

            def solve(r):
                J = S.copy()
                for c, D in ((w * c_q, dfdq), (w * c_v, dfdv)):
                    if D is not None:
                        J += c * D
                return np.linalg.solve(J, r)

            return Sx - b + w * f, scale, solve

        x0 = np.zeros_like(b, dtype=float) if guess is None else guess
        return newton_loop(evaluate, x0, self.newton)

    # -- condensed Newton ------------------------------------------------------------
    def _setup_condensed(self):
        tic = time.perf_counter()
        force = self.system.nonlinear
        L = force.local_map.tocsr()
        n_local, n = L.shape
        self.linear = self.make_solver(self.S, spd=True)
        LT = L.T.tocsc()
        keep = n_local * n * 8 <= self.newton.condense_memory
        G = np.empty((n_local, n_local))
        Z = np.empty((n, n_local)) if keep else None
        # blocks of columns of Z = S^-1 L^T, at most 256 MiB of right-hand sides at a time
        # (measured at 9.4e4 dofs: 54 s in blocks of 256 against 74-88 s in one solve)
        block = max(1, min(n_local, 256, int(2**28 // (8 * n))))
        for start in range(0, n_local, block):
            stop = min(start + block, n_local)
            columns = self.linear.solve(LT[:, start:stop].toarray(order="F")).reshape(n, stop - start)
            G[:, start:stop] = L @ columns
            if keep:
                Z[:, start:stop] = columns
        G = 0.5 * (G + G.T)
        try:
            factor = sl.cho_factor(G)
        except np.linalg.LinAlgError:
            raise FemromValueError(f"the {n_local} local coordinates of {force.name!r} are linearly dependent "
                             "(L S^-1 L^T is singular): condensation needs a full-rank local map; "
                             "use Newton(method='full')") from None
        self.L, self.Z, self.force = L, Z, force
        self.schur = sl.cho_solve(factor, np.eye(n_local))
        self.schur = 0.5 * (self.schur + self.schur.T)
        self.details.update(condensed_coordinates=n_local, condensation_seconds=time.perf_counter() - tic,
                            influence_stored=keep)

    def _condensed(self, b, q0, v0, state, guess):
        tic = time.perf_counter()
        x_lin = self.linear.solve(b, x0=guess)
        linear_seconds = time.perf_counter() - tic
        tic = time.perf_counter()
        # the dense (s, s) work on one OpenBLAS thread: its spinning threads would otherwise
        # compete with the sparse solver's on the same cores (measured at 2e4 dofs, 2 cores:
        # the next sparse solve 0.086 s instead of 0.016 s)
        with self._one_blas_thread():
            xi, g, iterations = self._local_newton(x_lin, q0, v0, state, guess)
            toc = time.perf_counter()
            if self.Z is not None:
                x = x_lin - self.w * (self.Z @ g)
        if self.Z is None:
            x = x_lin - self.w * self.linear.solve(self.L.T @ g)
        details = self.details
        details["local_newton_seconds"] += toc - tic
        details["local_iterations"] += iterations
        details["linear_solve_seconds"] += linear_seconds + time.perf_counter() - toc
        return x, iterations

    def _one_blas_thread(self):
        if self._blas is None:
            return contextlib.nullcontext()
        return self._blas.limit(limits=1)

    def _local_newton(self, x_lin, q0, v0, state, guess):
        """Newton on the Schur system of the force's coordinates; ``(xi, g(xi), iterations)``."""
        force, w, c_q, c_v = self.force, self.w, self.c_q, self.c_v
        options = self.newton
        L = self.L
        xi_lin = L @ x_lin
        y0, z0 = L @ q0, L @ v0
        Sigma = self.schur
        rhs = Sigma @ xi_lin
        xi = L @ guess if guess is not None else xi_lin.copy()
        eps = np.finfo(float).eps

        def local(xi):
            return y0 + c_q * xi, z0 + c_v * xi

        iterations, previous, tangent = 0, None, self._initial_tangent
        for iteration in range(options.max_iterations + 1):
            x_loc, v_loc = local(xi)
            g = force.local_force(x_loc, v_loc, state)
            Sxi = Sigma @ xi
            R = Sxi - rhs + w * g
            norm = float(np.linalg.norm(R))
            if not np.isfinite(norm):
                raise ConvergenceError(f"condensed Newton residual is not finite at iteration {iteration}")
            scale = float(np.linalg.norm(Sxi) + np.linalg.norm(rhs) + w * np.linalg.norm(g))
            if norm <= options.atol + options.rtol * scale:
                break
            if iteration == options.max_iterations:
                raise ConvergenceError(
                    f"condensed Newton did not converge in {options.max_iterations} iterations: "
                    f"residual {norm:.3g} > tolerance {options.atol + options.rtol * scale:.3g}")
            # a step starts from the tangent factorised once per dt (at rest, initial state)
            # and keeps it while every iteration contracts the residual by refactor_ratio
            # (a chord step costs O(s^2)); else it refactorises at the current iterate, for
            # this step only: a step depends on its own inputs alone (bit-identical resume);
            # past half the iteration budget every iteration is a Newton step
            slow = previous is not None and norm > options.refactor_ratio * previous
            if options.refactor_ratio <= 0.0 or slow or iteration >= options.max_iterations // 2:
                tangent = self._factorize(force.local_tangent(x_loc, v_loc, state))
            delta = tangent(R)
            xi = xi - delta
            iterations, previous = iteration + 1, norm
            if np.linalg.norm(delta) <= 4.0 * eps * np.linalg.norm(xi):
                x_loc, v_loc = local(xi)
                g = force.local_force(x_loc, v_loc, state)
                break
        return xi, g, iterations

    def _factorize(self, tangent):
        """``dxi -> J^-1 dxi`` for ``J = Sigma + w (c_q dg/dx + c_v dg/dxdot)``: Cholesky when ``J`` is
        symmetric positive definite (a diagonal tangent that does not soften too much), else LU."""
        J = self.schur.copy()
        symmetric = True
        for c, D in zip((self.w * self.c_q, self.w * self.c_v), tangent):
            if D is None:
                continue
            if np.ndim(D) == 1 and not hasattr(D, "toarray"):
                J[np.diag_indices_from(J)] += c * D
            else:
                J += c * (D.toarray() if hasattr(D, "toarray") else np.asarray(D))
                symmetric = False
        self.details["local_factorizations"] += 1
        if symmetric:
            try:
                factor = sl.cho_factor(J, check_finite=False)
                return lambda R: sl.cho_solve(factor, R, check_finite=False)
            except np.linalg.LinAlgError:
                pass
        factor = sl.lu_factor(J, check_finite=False)
        return lambda R: sl.lu_solve(factor, R, check_finite=False)

    def __call__(self, b, q0, v0, state, guess):
        """``(x, newton_iterations)`` for the step's ``b``, ``q0``, ``v0``, frozen ``state`` and a guess."""
        if self.method == "condensed":
            return self._condensed(b, q0, v0, state, guess)
        if self.method == "dense":
            return self._dense(b, q0, v0, state, guess)
        return self._full(b, q0, v0, state, guess)
