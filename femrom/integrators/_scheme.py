r"""The one registry of time schemes, and what every scheme declares.

A scheme integrates a second-order model

.. math::

    M \ddot q + C \dot q + K q + f(q, \dot q; s) = F(t), \qquad F = B u + f_0,

the full-order model (sparse operators) and every reduced model (dense (r, r)
operators) alike. It is one :class:`Scheme` subclass in one module of the
package ``femrom.integrators.schemes`` (found by :func:`registered_schemes`), or
anywhere else decorated with :func:`register_scheme`. It declares

- ``name`` (the registry key, what a scene's ``[time] integrator`` and
  ``predict(scheme=...)`` use) and ``aliases``;
- ``order`` and ``models`` (the kinds of model it steps: ``"second_order"``), and
  :meth:`Scheme.supports`, which says why it cannot step a given model;
- ``input_time`` ``theta``: a step from ``t`` samples the forcing at ``t + theta h``
  (``1``: the step's end; ``1/2``: its midpoint; from samples on the grid, the
  linear interpolation ``(1 - theta) F_k + theta F_{k+1}``);
- :meth:`Scheme.frequency` and :meth:`Scheme.continuous_frequency`: the frequency
  ``Omega`` at which the scheme steps an undamped mode of frequency ``omega``, and
  its inverse, so that a period measured on a computed response is corrected by
  the scheme that made it;
- :meth:`Scheme.init` (one-off work per ``dt``: factorisations, stability checks)
  and :meth:`Scheme.step` (one step, a nonlinear force solved by Newton with its
  state frozen and committed after convergence);
- :meth:`Scheme.step_map`: for a linear model with dense operators, the
  precomputed map ``x_{k+1} = A x_k + G F_{k+theta}`` on ``x = [q; v; a]`` (or
  ``[q; v]``), which the reduced fast path and the discrete state space use.

A scheme that also steps canonical Hamiltonian models (``H = q^T D_q q / 2 + p^T D_p p
/ 2 + H_nl``, :class:`~femrom.integrators.CanonicalSystem`, the Hamiltonian ROMs) gives
:meth:`Scheme.canonical_step_matrix` (the linear step of a separable quadratic ``H``) and,
when it takes a non-separable ``H_nl``, :meth:`Scheme.canonical_nodes` (the quadrature of
the gradient along the step: the midpoint rule, the average vector field); one that steps
first-order models ``y' = f(y)`` gives :meth:`Scheme.first_order_step`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import scipy.linalg as sl
import scipy.optimize as so
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom._registry import Registry

#: The kinds of model a scheme can declare: second-order ``M q'' + C q' + K q + f = F``, canonical
#: Hamiltonian ``y' = J grad H(y)`` (``y = [q; p]``), first-order ``y' = A y + F(y)``.
MODEL_KINDS = ("second_order", "canonical", "first_order")


class _Schemes(Registry):
    """The registry, with each scheme's aliases resolved to its name."""

    def get(self, name: str):
        entries = self.items()
        for key, cls in entries.items():
            if name == key or name in getattr(cls, "aliases", ()):
                return cls
        raise FemromValueError(f"unknown time scheme {name!r}; valid: {', '.join(entries)}")

    def __contains__(self, name: str) -> bool:
        return any(name == key or name in getattr(cls, "aliases", ()) for key, cls in self.items().items())


#: The time schemes by name (sorted).
SCHEMES = _Schemes("time scheme", "femrom.integrators.schemes", order=lambda name, cls: name)


def is_dense(matrix) -> bool:
    """Whether an operator is held as an ndarray (a reduced model's) rather than a sparse matrix."""
    return matrix is not None and not sp.issparse(matrix)


def dense_model(system) -> bool:
    """Whether ``system``'s operators are ndarrays (a small reduced model)."""
    return is_dense(system.stiffness)


@dataclass(frozen=True, eq=False)
class LinearParts:
    """The linear operators of a small model as dense arrays: ``M``, ``C`` (or ``None``), ``K``."""

    mass: np.ndarray
    damping: np.ndarray | None
    stiffness: np.ndarray

    @classmethod
    def of(cls, system) -> "LinearParts":
        """The dense parts of a model (sparse operators are densified: small models only)."""
        def dense(A):
            return None if A is None else (A.toarray() if sp.issparse(A) else np.asarray(A, dtype=float))
        return cls(dense(system.mass), dense(system.damping), dense(system.stiffness))

    @property
    def r(self) -> int:
        return self.stiffness.shape[0]

    @property
    def damping_matrix(self) -> np.ndarray:
        return np.zeros_like(self.stiffness) if self.damping is None else self.damping

    def acceleration(self, force: np.ndarray, q: np.ndarray, v: np.ndarray, nonlinear=None, state=None):
        """``a = M^-1 (F - C v - K q - f(q, v; s))`` for (r,) vectors or (r, k) columns (linear)."""
        rhs = force - self.damping_matrix @ v - self.stiffness @ q
        if nonlinear is not None:
            rhs = rhs - nonlinear.force(q, v, state)
        return np.linalg.solve(self.mass, rhs)


def solve_matrix(S: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``S^-1 rhs`` by an LU factorisation (a step map's blocks)."""
    return sl.lu_solve(sl.lu_factor(S), rhs)


class Scheme:
    r"""A one-step method for ``M q'' + C q' + K q + f(q, q'; s) = F(t)`` (module docstring).

    Class attributes
    ----------------
    name : str
        Registry key.
    aliases : tuple of str
        Other names the registry resolves to this scheme.
    order : int
        Order of accuracy (a subclass may make it a property of its parameters).
    models : tuple of str
        The kinds of model it steps (:data:`MODEL_KINDS`).
    input_time : float
        ``theta`` in ``[0, 1]``: the forcing of a step is sampled at ``t + theta h``.
    carries_acceleration : bool
        Whether the linear step map's state is ``[q; v; a]`` (else ``[q; v]``).
    uses_mass_solver : bool
        Whether steps solve with ``M`` (the driver frees ``M``'s factor otherwise).
    physical_acceleration : bool
        Whether the acceleration it carries satisfies the equation of motion at the step's
        end (generalized-alpha's is algorithmic): a linear state space can then eliminate it.
    """

    name: ClassVar[str] = ""
    aliases: ClassVar[tuple[str, ...]] = ()
    order: ClassVar[int] = 2
    models: ClassVar[tuple[str, ...]] = ("second_order",)
    input_time: ClassVar[float] = 1.0
    carries_acceleration: ClassVar[bool] = True
    uses_mass_solver: ClassVar[bool] = False
    physical_acceleration: ClassVar[bool] = True

    @classmethod
    def from_config(cls, time_config) -> "Scheme":
        """The scheme a scene's ``[time]`` section configures (default options)."""
        return cls()

    @property
    def label(self) -> str:
        """What run summaries call the scheme (its options included)."""
        return type(self).__name__

    # -- what it can step ---------------------------------------------------------------
    def supports(self, system) -> str | None:
        """``None`` when the scheme can step ``system``, else the reason it cannot (one line)."""
        return None

    def check(self, system) -> None:
        """Raise :class:`~femrom.FemromValueError` with :meth:`supports`'s reason (a second-order model)."""
        self.check_kind("second_order")
        reason = self.supports(system)
        if reason is not None:
            raise FemromValueError(f"scheme {self.name!r} cannot step this model: {reason}")

    # -- the discrete frequency -----------------------------------------------------------
    def frequency(self, omega, dt: float):
        r"""``Omega``: the frequency [rad/s] at which the scheme steps an undamped mode
        ``q'' + omega^2 q = 0`` at step ``dt`` (float or ndarray, like ``omega``).

        By default the argument of the principal eigenvalue of the step map on the mode
        (of the complex pair the largest in modulus; a scheme's spurious roots are real);
        schemes with a closed form override it.
        """
        omega = np.asarray(omega, dtype=float)
        out = np.empty(omega.shape)
        for index, w in np.ndenumerate(omega):
            parts = LinearParts(np.eye(1), None, np.array([[w * w]]))
            A, _ = self.step_map(parts, dt, None)
            roots = np.linalg.eigvals(A)
            pair = roots[roots.imag > 1e-14 * np.abs(roots)]
            out[index] = 0.0 if pair.size == 0 else float(np.angle(pair[np.argmax(np.abs(pair))])) / dt
        return out if out.ndim else float(out)

    def continuous_frequency(self, Omega, dt: float):
        r"""``omega`` with ``frequency(omega, dt) = Omega``: the inverse map, which corrects a
        frequency measured on a computed response for the scheme's period error."""
        Omega = np.asarray(Omega, dtype=float)
        out = np.empty(Omega.shape)
        for index, W in np.ndenumerate(Omega):
            if not 0.0 <= W * dt < np.pi:
                raise FemromValueError(f"a discrete frequency {W:g} rad/s is not resolved at dt = {dt:g}")
            upper = max(2.0 * W, 1.0 / dt)
            while self.frequency(upper, dt) < W:
                upper *= 2.0
            out[index] = 0.0 if W == 0.0 else so.brentq(lambda w: self.frequency(w, dt) - W, 0.0, upper,
                                                          xtol=1e-14 * upper, rtol=4 * np.finfo(float).eps)
        return out if out.ndim else float(out)

    # -- stepping -------------------------------------------------------------------------
    def init(self, system, dt: float, make_solver, mass_solver, t0, q0, v0, a0, state0) -> Any:
        """One-off work for this ``dt``; returns the cache :meth:`step` reads."""
        raise NotImplementedError

    def step(self, system, cache, t, q, v, a, state, force, force_end):
        r"""One step of size ``cache.dt`` from ``t``.

        ``force``: ``F`` (n,) at ``t + input_time h`` (``None`` without inputs and load);
        ``force_end``: a callable giving ``F(t + h)`` when the scheme needs it (its
        acceleration at the step's end). Returns ``(q1, v1, a1, state1, newton_iterations)``:
        new arrays, the nonlinear force's state committed at ``(q1, v1)``; ``a1`` may be
        ``None`` for a scheme that does not carry accelerations.
        """
        raise NotImplementedError

    def step_map(self, parts: LinearParts, dt: float, forcing: np.ndarray | None):
        """``(A, G)`` with ``x_{k+1} = A x_k + G F_{k+theta}`` for the (r, m) forcing columns
        ``forcing`` (``G`` is ``None`` without forcing), for a linear model's dense parts."""
        raise NotImplementedError(f"scheme {self.name!r} has no linear step map")

    def check_step(self, parts: LinearParts, dt: float) -> None:
        """Raise if ``dt`` is not allowed for these dense parts (an explicit scheme's bound)."""

    # -- canonical and first-order models --------------------------------------------------
    def check_kind(self, kind: str) -> None:
        """Raise unless the scheme steps models of ``kind`` (:data:`MODEL_KINDS`)."""
        if kind not in self.models:
            valid = ", ".join(name for name, cls in registered_schemes().items() if kind in cls.models)
            raise FemromValueError(f"scheme {self.name!r} does not step {kind.replace('_', '-')} models; "
                                   f"valid: {valid}")

    def canonical_step_matrix(self, position: np.ndarray, momentum: np.ndarray, dt: float) -> np.ndarray:
        """(2r, 2r) ``S``: ``[q; p]_{k+1} = S [q; p]_k`` for ``H = q^T D_q q / 2 + p^T D_p p / 2``."""
        raise FemromValueError(f"scheme {self.name!r} does not step canonical models")

    def canonical_nodes(self, quadrature: int = 2) -> tuple[np.ndarray, np.ndarray]:
        """``(nodes, weights)`` on [0, 1] of the gradient's quadrature along a step (an implicit
        canonical scheme for a non-separable ``H``)."""
        raise FemromValueError(f"scheme {self.name!r} needs a separable Hamiltonian; with a potential "
                               f"coupling q and p use one of implicit_midpoint (midpoint), discrete_gradient (avf)")

    def first_order_step(self, rhs, jacobian, y: np.ndarray, h: float, newton) -> np.ndarray:
        """``y_{k+1}`` of ``y' = rhs(y)`` from ``y`` (``jacobian(y)`` (s, s) for an implicit scheme)."""
        raise FemromValueError(f"scheme {self.name!r} does not step first-order models")


def register_scheme(cls: type[Scheme]) -> type[Scheme]:
    """Class decorator: the scheme is known by ``cls.name`` (and its ``aliases``)."""
    if not cls.name:
        raise FemromValueError(f"scheme class {cls.__name__} has no name")
    theta = cls.input_time
    if isinstance(theta, (int, float)) and not 0.0 <= float(theta) <= 1.0:
        raise FemromValueError(f"scheme {cls.name!r}: input_time must lie in [0, 1], got {cls.input_time!r}")
    unknown = set(cls.models) - set(MODEL_KINDS)
    if unknown:
        raise FemromValueError(f"scheme {cls.name!r} declares unknown model kinds {sorted(unknown)}; "
                               f"valid: {', '.join(MODEL_KINDS)}")
    SCHEMES.add(cls.name, cls)
    return cls


def registered_schemes() -> dict[str, type[Scheme]]:
    """Every registered scheme class by name (the built-in modules imported once)."""
    return SCHEMES.items()


def time_scheme(name, **options) -> Scheme:
    """The scheme registered as ``name`` (or an alias) with ``options``; a :class:`Scheme`
    instance is returned as it is. One clear error for an unknown name."""
    if isinstance(name, Scheme):
        if options:
            raise FemromValueError("options go with a scheme name, not with a scheme instance")
        return name
    return SCHEMES.get(str(name))(**options)


def scheme_for(time_config) -> Scheme:
    """The scheme a scene's ``[time]`` names (one that steps second-order models); one clear error otherwise."""
    name = time_config.integrator
    valid = [key for key, cls in SCHEMES.items().items() if "second_order" in cls.models]
    if name not in SCHEMES or "second_order" not in SCHEMES.get(name).models:
        raise FemromValueError(f"unknown integrator {name!r} in [time]; valid: {', '.join(valid)}")
    return SCHEMES.get(name).from_config(time_config)
