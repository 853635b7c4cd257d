r"""A whole Newmark-family step of a small model with a joint or learned sliders in one compiled call.

The dense Newton of a reduced model with a joint (:class:`~femrom.integrators.ImplicitSolve`,
``method = "dense"``) spends most of a step in Python around its few hundred floating-point
operations: the law's and the force's wrappers, the ``(L V)^T D (L V)`` products, norms and
``r x r`` solves on tiny arrays, the scheme's bookkeeping. When the model's force offers a
:class:`~femrom.fem.CompiledJoint` (:meth:`femrom.fem.TransformedForce.compiled_joint`: a joint
whose law has compiled kernels), :class:`FusedJointStep` runs the predictor, the Newton
iterations (gaps, law, projection, solve, convergence tests) and the commit of the slider
states as one numba call (``newmark_joint_step`` of :func:`femrom.fem.compiled_kernels`, kept
in the file of the law kernels it calls so that numba's on-disk cache cannot go stale), with
the tolerances, tests and iteration counts of the reference path. Sums run in loops where
numpy calls BLAS, so the two paths agree to round-off, not bit for bit.

:meth:`FusedJointStep.march_batch` steps ``B`` runs of one such model (different forcing, starts or
states) together, one compiled call for all their steps (:func:`femrom.integrators.march_batch`).

Learned Jenkins sliders along a reduced direction (:class:`~femrom.inference.LearnedHysteresis`,
which offers a :class:`~femrom.fem.CompiledSliders`) step the same way
(:class:`FusedSlidersStep`), and a whole trajectory of them in one call (:meth:`FusedSlidersStep.march`,
taken by :func:`femrom.integrators.march`).

A model whose nonlinear force is a learned potential of ``q^`` and/or a learned dissipation
function of ``q^'`` (SpML's :class:`~femrom.inference.LearnedPotential` and
:class:`~femrom.inference.LearnedDissipation`, which offer a :class:`~femrom.fem.CompiledScalar`)
steps the discrete-gradient scheme the same way (:class:`FusedDiscreteGradientStep`, the kernel
``discrete_gradient_step`` of :func:`femrom.fem.compiled_scalar_kernels`), and a whole trajectory in one
call (:meth:`FusedDiscreteGradientStep.march`, ``discrete_gradient_march``), by default by a chord
iteration with one Jacobian a step.

The numpy path stays the reference: the scheme takes it whenever the force offers no compiled
joint, and at every step where the compiled laws are switched off
(``FEMROM_COMPILED_LAWS=0``, :func:`femrom.fem.use_compiled_laws`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromRuntimeError, FemromValueError
from femrom.fem import compiled_kernels, compiled_laws, compiled_scalar_kernels
from femrom.integrators._newton import ConvergenceError


def _dense(A) -> np.ndarray:
    return np.ascontiguousarray(A.toarray() if sp.issparse(A) else A, dtype=float)


def _frozen(x) -> np.ndarray:
    """``x`` as a read-only float C array (the driver's own vectors are; one compiled signature for all)."""
    if x.flags.writeable or x.dtype != np.float64 or not x.flags.c_contiguous:
        x = np.array(x, dtype=float)
        x.setflags(write=False)
    return x


class NonFiniteState(FemromRuntimeError):
    """A marched step's new state is not finite (the march turns it into its own error)."""

    def __init__(self, step: int):
        super().__init__(f"the state became non-finite at step {step}")
        self.step = step


class _FusedStep:
    """What the fused steps share: the model's dense matrices and the scheme's coefficients, as the reference
    forms them (``NewmarkFamily.init``, ``ImplicitSolve``)."""

    def __init__(self, scheme, system, dt: float, effective_matrix, initial_state):
        kernels = compiled_kernels()
        self._kernels = kernels
        self._status = {kernels.NOT_CONVERGED: "not converged", kernels.NOT_FINITE: "not finite",
                        kernels.SINGULAR: "singular"}
        h = float(dt)
        beta, gamma = float(scheme.beta), float(scheme.gamma)
        am, af = float(scheme.alpha_m), float(scheme.alpha_f)
        newton = scheme.newton
        r = system.n_dofs
        self._initial_state, self._newton = initial_state, newton
        damping = system.damping
        self._matrices = (_dense(system.mass), _dense(damping) if damping is not None else np.zeros((r, r)),
                          damping is not None, _dense(system.stiffness), _dense(effective_matrix))
        c_q = float((1.0 - af) * beta * h * h)
        self._scalars = (h, beta, gamma, am, af, c_q, 1.0, float(newton.rtol), float(newton.atol),
                         int(newton.max_iterations))
        self._no_force = np.zeros(r)

    @staticmethod
    def enabled() -> bool:
        """Whether the compiled laws are on now (the fused step follows the same switch)."""
        return compiled_laws()

    def _raise(self, status, iteration, norm, tolerance):
        options = self._newton
        what = self._status[status]
        if what == "not finite":
            raise ConvergenceError(f"Newton residual is not finite at iteration {iteration}")
        if what == "singular":
            raise ConvergenceError(f"Newton's matrix is singular at iteration {iteration}")
        raise ConvergenceError(
            f"Newton did not converge in {options.max_iterations} iterations: residual "
            f"{norm:.3g} > tolerance {tolerance:.3g} (atol={options.atol:g}, rtol={options.rtol:g})")


class FusedJointStep(_FusedStep):
    """One Newmark-family step (``scheme``'s coefficients, ``dt``) of ``system`` in one compiled call.

    Parameters
    ----------
    scheme : NewmarkFamily
    system : SecondOrderSystem
        Small (dense matrices), whose force gave ``joint``.
    dt : float
    effective_matrix : (n, n) array
        ``S`` of the scheme.
    joint : CompiledJoint
    initial_state : callable
        The force's ``initial_state`` (for a ``None`` state).
    """

    def __init__(self, scheme, system, dt: float, effective_matrix, joint, initial_state):
        super().__init__(scheme, system, dt, effective_matrix, initial_state)
        self._kernel = self._kernels.newmark_joint_step
        self.joint = joint
        self._law = (joint.kind, joint.dense_map, joint.local_offset, joint.gap_offset, joint.areas,
                     joint.stiffness, joint.strength, joint.normal_stiffness)

    def __call__(self, q, v, a, state, force):
        """``(q1, v1, a1, state1, newton_iterations)`` of the step from ``(q, v, a)``, ``state`` and ``force``."""
        if state is None:
            state = self._initial_state()
        if not (state.flags.writeable and state.flags.c_contiguous and state.dtype == np.float64):
            state = np.array(state, dtype=float)
        if force is None:
            force, has_force = self._no_force, False
        else:
            has_force = True
            if not (force.flags.writeable and force.flags.c_contiguous and force.dtype == np.float64):
                force = np.array(force, dtype=float)
        M, C, has_C, K, S = self._matrices
        q1, v1, a1, state1, iterations, status, norm, tolerance = self._kernel(
            _frozen(q), _frozen(v), _frozen(a), force, has_force, M, C, has_C, K, S, *self._scalars, *self._law,
            state)
        if status:
            self._raise(status, iterations, norm, tolerance)
        return q1, v1, a1, state1, iterations

    def march_batch(self, q0, v0, a0, states, forces, n_steps: int):
        """``B`` runs of ``n = n_steps`` steps together, every step of every run this step's.

        ``q0, v0, a0`` (B, r), ``states`` (B, ...) (each run's committed state), ``forces`` (B, r, n) (the
        forcing of step ``k`` of run ``b`` at ``forces[b, :, k]``) or ``None``. Returns ``(Q, V, A (B, r, n +
        1), states (B, ...), iterations (B, n))``. A failing run raises :class:`ConvergenceError` (Newton) or
        :class:`NonFiniteState` with ``run`` and ``step`` (1-based) after all runs have stepped (the first
        failing run's)."""
        q0, v0, a0 = (np.array(x, dtype=float, ndmin=2) for x in (q0, v0, a0))
        B, r = q0.shape
        n = int(n_steps)
        states = np.array(states, dtype=float)
        if states.shape[0] != B:
            raise FemromValueError(f"states must have one row a run ({B}), got shape {states.shape}")
        has_force = forces is not None
        if has_force:
            forces = np.asarray(forces, dtype=float)
            if forces.shape != (B, r, n):
                raise FemromValueError(f"forces must be ({B}, {r}, {n}), got shape {forces.shape}")
            forces = np.ascontiguousarray(forces.transpose(2, 0, 1))
        else:
            forces = np.zeros((n, B, r))
        Q, V, A = (np.full((n + 1, B, r), np.nan) for _ in range(3))
        Q[0], V[0], A[0] = q0, v0, a0
        iterations = np.zeros((n, B), dtype=np.int64)
        status = np.zeros(B, dtype=np.int64)
        failed = np.full(B, -1, dtype=np.int64)
        norms, tolerances = np.full(B, np.nan), np.full(B, np.nan)
        M, C, has_C, K, S = self._matrices
        self._kernels.newmark_joint_batch_march(Q, V, A, forces, has_force, M, C, has_C, K, S, *self._scalars,
                                                *self._law, states, iterations, status, failed, norms, tolerances)
        bad = np.flatnonzero(status)
        if bad.size:
            b = int(bad[0])
            if status[b] == self._kernels.STATE_NOT_FINITE:
                err = NonFiniteState(int(failed[b]) + 1)
            else:
                try:
                    self._raise(status[b], iterations[failed[b], b], norms[b], tolerances[b])
                except ConvergenceError as raised:
                    err = raised
                err.step = int(failed[b]) + 1
            err.run = b
            raise err
        return (Q.transpose(1, 2, 0).copy(), V.transpose(1, 2, 0).copy(), A.transpose(1, 2, 0).copy(), states,
                iterations.T.copy())


class FusedSlidersStep(_FusedStep):
    """:class:`FusedJointStep` for learned Jenkins sliders along a reduced direction (a
    :class:`~femrom.fem.CompiledSliders`), alone or beside a learned potential of ``q^`` (a
    :class:`~femrom.fem.CompiledScalar`: SpML with sliders), by ``newmark_sliders_step`` of
    :func:`femrom.fem.compiled_scalar_kernels`; :meth:`march` takes a whole trajectory in one call.

    ``slot``: with a potential, the model's force is a sum whose state is a tuple; ``slot`` is the sliders'
    place in it (the potential's entry is stateless and passes through)."""

    def __init__(self, scheme, system, dt: float, effective_matrix, sliders, initial_state, *, potential=None,
                 slot: int | None = None):
        super().__init__(scheme, system, dt, effective_matrix, initial_state)
        self.sliders, self.potential, self._slot = sliders, potential, slot
        self._law = (sliders.direction, sliders.thresholds, sliders.weights)
        scalar = compiled_scalar_kernels()
        self._step, self._march = scalar.newmark_sliders_step, scalar.newmark_sliders_march
        # the potential's parts and workspace (scratch, reused by every step), or None for the sliders alone
        self._extra = (None, None) if potential is None else \
            (potential.parts, scalar.scalar_workspace(potential.parts, system.n_dofs))

    @staticmethod
    def enabled() -> bool:
        """Whether the compiled laws are on now (the fused step follows the same switch)."""
        return compiled_kernels() is not None and compiled_scalar_kernels() is not None

    def _state(self, sliders, state):
        """The model's state with the sliders' part ``sliders``."""
        if self._slot is None:
            return sliders
        state = self._initial_state() if state is None else state
        return tuple(sliders if i == self._slot else s for i, s in enumerate(state))

    def _parts(self, state):
        state = self._initial_state() if state is None else state
        if self._slot is not None:
            state = state[self._slot]
        stretch = state.stretch
        if not (stretch.flags.c_contiguous and stretch.dtype == np.float64):
            stretch = np.array(stretch, dtype=float)
        return stretch, float(state.coordinate)

    def __call__(self, q, v, a, state, force):
        """``(q1, v1, a1, state1, newton_iterations)`` of the step from ``(q, v, a)``, ``state`` and ``force``."""
        stretch, coordinate = self._parts(state)
        has_force = force is not None
        M, C, has_C, K, S = self._matrices
        q1, v1, a1, stretch1, coordinate1, iterations, status, norm, tolerance = \
            self._step(q, v, a, force if has_force else self._no_force, has_force,
                       M, C, has_C, K, S, *self._scalars, *self._law, stretch, coordinate, *self._extra)
        if status:
            self._raise(status, iterations, norm, tolerance)
        return q1, v1, a1, self._state(self.sliders.state(stretch1, coordinate1), state), iterations

    def march(self, q0, v0, a0, state, forces, n_steps: int, forces_end=None):
        """``(Q, V, A (r, n + 1), final state, newton_iterations)`` of ``n = n_steps`` steps, the forcing of
        step ``k`` in ``forces[:, k]`` ((r, n) or ``None``; ``forces_end``, the forcing on the grid, is not
        used: the Newmark family carries its accelerations). A failing step raises :class:`ConvergenceError`
        (Newton) or :class:`NonFiniteState` (a non-finite ``q``) with its number in ``step``."""
        stretch, coordinate = self._parts(state)
        r, n = q0.size, int(n_steps)
        has_force = forces is not None
        forces = np.ascontiguousarray(forces, dtype=float) if has_force else np.zeros((r, n))
        if forces.shape != (r, n):
            raise FemromValueError(f"forces must be ({r}, {n}), got shape {forces.shape}")
        Q, V, A = (np.empty((r, n + 1)) for _ in range(3))
        Q[:, 0], V[:, 0], A[:, 0] = q0, v0, a0
        M, C, has_C, K, S = self._matrices
        stretch1, coordinate1, done, iterations, status, norm, tolerance = self._march(
            np.array(q0, dtype=float), np.array(v0, dtype=float), np.array(a0, dtype=float), forces, has_force,
            M, C, has_C, K, S, *self._scalars, *self._law, stretch, coordinate, *self._extra, Q, V, A)
        if status == self._kernels.STATE_NOT_FINITE:
            raise NonFiniteState(done + 1)
        if status:
            try:
                self._raise(status, iterations, norm, tolerance)
            except ConvergenceError as err:
                err.step = done + 1
                raise
        return Q, V, A, self._state(self.sliders.state(stretch1, coordinate1), state), iterations


def fused_step(scheme, system, dt: float, effective_matrix, implicit):
    """A :class:`FusedJointStep` or :class:`FusedSlidersStep` when ``implicit`` (the step's
    :class:`ImplicitSolve`) runs dense Newton and ``system``'s force offers a compiled joint or compiled
    sliders, or is the sum of compiled sliders and a compiled stateless potential of ``q^`` (compiled laws
    on), else ``None``."""
    if implicit.method != "dense":
        return None
    force = system.nonlinear
    offer = getattr(force, "compiled_joint", None)
    joint = offer() if callable(offer) else None
    if joint is not None:
        return FusedJointStep(scheme, system, dt, effective_matrix, joint, force.initial_state)
    offer = getattr(force, "compiled_sliders", None)
    sliders = offer() if callable(offer) else None
    if sliders is not None:
        return FusedSlidersStep(scheme, system, dt, effective_matrix, sliders, force.initial_state)
    return _sliders_beside_a_potential(scheme, system, dt, effective_matrix, force)


def _sliders_beside_a_potential(scheme, system, dt, effective_matrix, force):
    """:class:`FusedSlidersStep` with a potential for a force that sums exactly two terms: compiled sliders and
    a compiled, conservative, stateless scalar function of ``q^``; else ``None``."""
    terms = getattr(force, "terms", None)
    if not isinstance(terms, tuple) or len(terms) != 2 or compiled_scalar_kernels() is None:
        return None
    sliders = potential = slot = None
    for i, term in enumerate(terms):
        offer = getattr(term, "compiled_sliders", None)
        compiled = offer() if callable(offer) else None
        if compiled is not None:
            sliders, slot = compiled, i
            continue
        offer = getattr(term, "compiled_scalar", None)
        compiled = offer() if callable(offer) else None
        if compiled is not None and compiled.argument == "q" and term.conservative and not term.stateful:
            potential = compiled
    if sliders is None or potential is None:
        return None
    return FusedSlidersStep(scheme, system, dt, effective_matrix, sliders, force.initial_state, potential=potential,
                            slot=slot)


#: The chord march holds its Jacobian into the next step when the step converged in at most this many updates
#: (2: what a Jacobian formed at the step's first iterate takes from the extrapolated predictor); a step that
#: took more forms a new one at the next step's first iterate. ``0`` (the default): a new Jacobian every step.
#: Holding it saves Jacobians but costs updates (the held one contracts less well): on the default SpML shapes
#: at r = 8 (``benchmarks/spml_rom_step.py``) 2.29 updates and 0.29 Jacobians a step against 2.00 and 1.00,
#: the same time; at r = 12 2.44 and 0.45, 9 % slower.
HOLD_UPDATES = 0

#: The degree of the polynomial that extrapolates the learned terms' force into the chord march's predictor.
EXTRAPOLATION_ORDER = 3


class FusedDiscreteGradientStep:
    """One :class:`~femrom.integrators.DiscreteGradient` step of a small model whose nonlinear force is a learned
    potential (a :class:`~femrom.fem.CompiledScalar` of ``q``) and/or a learned dissipation function (one of
    ``v``), in one compiled call: the reference's predictor, Newton iterations, update and stagnation tests,
    iteration count and end-of-step acceleration, equal to round-off.

    Parameters
    ----------
    scheme : DiscreteGradient
    system : SecondOrderSystem
    dt : float
    matrix : (r, r) ndarray
        ``(2/h) M + C + (h/2) K``.
    potential, dissipation : CompiledScalar or None
    """

    def __init__(self, scheme, system, dt: float, matrix, potential, dissipation):
        self._kernels = compiled_scalar_kernels()
        r = system.n_dofs
        damping = system.damping
        self._matrices = (_dense(system.mass), _dense(damping) if damping is not None else np.zeros((r, r)),
                          damping is not None, _dense(system.stiffness), _dense(matrix))
        newton = scheme.newton
        self._newton = newton
        self._scalars = (float(dt), float(newton.rtol), int(newton.max_iterations), bool(scheme.accelerations))
        self._empty = np.zeros(r)
        self.potential, self.dissipation = potential, dissipation
        self._terms = (potential.parts if potential is not None else dissipation.parts, potential is not None,
                       dissipation.parts if dissipation is not None else potential.parts, dissipation is not None)

    @staticmethod
    def enabled() -> bool:
        """Whether the compiled laws are on now (the fused step follows the same switch)."""
        return compiled_scalar_kernels() is not None

    def __call__(self, t, q, v, a, state, force, force_end=None):
        """``(q1, v1, a1, state, newton_iterations)`` of the step from ``(q, v, a)`` at ``t`` (the state of
        stateless terms passes through)."""
        h, rtol, max_iterations, accelerations = self._scalars
        F_end = force_end() if (accelerations and force_end is not None) else None
        M, C, has_C, K, J = self._matrices
        empty = self._empty
        q1, v1, a1, iterations, status = self._kernels.discrete_gradient_step(
            _frozen(q), _frozen(v), empty if a is None else _frozen(a), a is not None,
            empty if force is None else _frozen(force), force is not None,
            empty if F_end is None else _frozen(F_end), F_end is not None,
            M, C, has_C, K, J, h, rtol, max_iterations, accelerations, *self._terms)
        if status:
            where = f" at t = {t + h:.6g}"
            if status == self._kernels.NOT_FINITE:
                raise ConvergenceError(f"Newton residual is not finite at iteration {iterations}{where}")
            if status == self._kernels.SINGULAR:
                raise ConvergenceError(f"Newton's matrix is singular at iteration {iterations}{where}")
            raise ConvergenceError(f"Newton did not converge in {self._newton.max_iterations} iterations{where}")
        return q1, v1, (a1 if accelerations else None), state, iterations

    def march(self, q0, v0, a0, state, forces, n_steps: int, forces_end=None):
        r"""``(Q, V, A (r, n + 1), state, newton_iterations, jacobians)`` of ``n = n_steps`` steps in one compiled
        call (``discrete_gradient_march``), the forcing of step ``k`` at ``t_k + h/2`` in ``forces[:, k]`` and
        at ``t_{k+1}`` in ``forces_end[:, k]`` ((r, n) each, or ``None``); ``newton_iterations`` and
        ``jacobians`` (n,) int, per step: updates and Jacobians formed (each the potential's Hessian at the
        two Gauss nodes and the dissipation's at ``v_m``).

        ``scheme.newton.refactor_ratio = 0``: Newton at every iterate, the steps of :meth:`__call__` (and of
        the numpy reference) to round-off, with their iteration counts. Otherwise (the default ``0.1``) the
        chord iteration: one Jacobian a step (formed at its first iterate; or held across steps,
        :data:`HOLD_UPDATES`), values and gradients at the other iterates, while each update is at most
        ``refactor_ratio`` times the one before (Newton for the rest of a step that contracts more slowly),
        from a predictor that solves the step's linear part exactly with the learned force extrapolated
        from the previous steps; the same fixed point to the same update test, a failing step redone by
        Newton from the reference's predictor. A failing step raises :class:`ConvergenceError` or
        :class:`NonFiniteState` with its number in ``step``."""
        h, rtol, max_iterations, accelerations = self._scalars
        r, n = q0.size, int(n_steps)
        has_force = forces is not None
        if has_force:
            forces = np.asarray(forces, dtype=float)
            if forces.shape != (r, n):
                raise FemromValueError(f"forces must be ({r}, {n}), got shape {forces.shape}")
            forces = np.ascontiguousarray(forces.T)
            ends = np.zeros((n, r)) if forces_end is None else np.ascontiguousarray(
                np.asarray(forces_end, dtype=float).reshape(r, n).T)
        else:
            forces = ends = np.zeros((n, r))
        Q, V, A = (np.empty((n + 1, r)) for _ in range(3))
        Q[0], V[0] = q0, v0
        A[0] = a0 if a0 is not None else np.nan
        iterations = np.zeros(n, dtype=np.int64)
        jacobians = np.zeros(n, dtype=np.int64)
        M, C, has_C, K, J = self._matrices
        done, status = self._kernels.discrete_gradient_march(
            forces, has_force, ends, M, C, has_C, K, J, h, rtol, max_iterations, accelerations,
            float(self._newton.refactor_ratio), HOLD_UPDATES, EXTRAPOLATION_ORDER, *self._terms, Q, V, A, iterations,
            jacobians)
        if status:
            if status == self._kernels.STATE_NOT_FINITE:
                raise NonFiniteState(done + 1)
            if status == self._kernels.NOT_FINITE:
                err = ConvergenceError(f"Newton residual is not finite at iteration {iterations[done]}")
            elif status == self._kernels.SINGULAR:
                err = ConvergenceError(f"Newton's matrix is singular at iteration {iterations[done]}")
            else:
                err = ConvergenceError(f"Newton did not converge in {self._newton.max_iterations} iterations")
            err.step = done + 1
            raise err
        return Q.T.copy(), V.T.copy(), A.T.copy(), state, iterations, jacobians


def fused_discrete_gradient(scheme, system, dt: float, matrix):
    """A :class:`FusedDiscreteGradientStep` when ``system`` is small (a dense step matrix) and every summand of
    its nonlinear force offers a compiled scalar function (``compiled_scalar()``: at most one of ``q``,
    conservative, and one of ``v``), none stateful, with the compiled laws on; else ``None``."""
    force = system.nonlinear
    if force is None or compiled_scalar_kernels() is None or not isinstance(matrix, np.ndarray):
        return None
    parts = (force,)
    for attribute in ("forces", "terms"):               # a sum's summands (as the scheme's ``forces_of``)
        summands = getattr(force, attribute, None)
        if isinstance(summands, (tuple, list)):
            parts = tuple(summands)
            break
    found = {}
    for part in parts:
        offer = getattr(part, "compiled_scalar", None)
        compiled = offer() if callable(offer) else None
        if compiled is None or getattr(part, "stateful", False) or compiled.argument in found:
            return None
        if compiled.argument == "q" and not part.conservative:
            return None
        found[compiled.argument] = compiled
    return FusedDiscreteGradientStep(scheme, system, dt, matrix, found.get("q"), found.get("v"))
