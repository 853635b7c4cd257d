r"""Nonlinear static equilibrium of a system, and the bolt-preload sequence of a jointed one.

:func:`solve_static` solves

.. math::

    r(q) = K q + f(q; z) - F = 0 \quad \text{on the dofs not in } S, \qquad q_S = 0,

by Newton with the tangent ``K + df/dq`` (the state ``z`` of a stick-slip force
frozen, then committed at the solution), ``S`` a set of supports. The
reactions are ``r_S`` at the solution: the forces the supports add to hold the
structure, ``K q + f = F + R``. A free structure under a self-equilibrated load
(a bolt preload) needs ``S`` to hold its rigid-body modes in a statically
determinate way: then the reactions vanish (to the solver's round-off), which
checks that the load is self-equilibrated and that the supports do not clamp.

:func:`preload` is the bolted-joint sequence: the preload solved with
frictionless normal contact (every joint law's ``friction_coefficient`` set to
0: the tangential springs carry nothing, the sliders follow the gap), the
sliders committed at that equilibrium, then friction switched on from it. At
the committed state the friction laws' trial tractions are zero, so the second
solve starts in equilibrium: clamping does not load the interface
tangentially (the usual idealisation of tightening).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from femrom import fem
from femrom._errors import FemromValueError
from femrom.scene._system import SecondOrderSystem
from femrom.solvers import make_solver

#: Normal gap [m] at which :func:`solve_static`'s closed start evaluates a joint's tangent: any
#: negative number closes the pairs; the tangent of a penalty contact does not depend on its size.
CLOSING_GAP = 1e-12


@dataclass(frozen=True, eq=False)
class StaticSolution:
    """Result of :func:`solve_static`.

    Attributes
    ----------
    displacement : (n,) ndarray
        ``q`` on the system's dofs (zero at the supports).
    state : Any
        The nonlinear force's state committed at ``q`` (``None`` for a linear system).
    reactions : (k,) ndarray
        ``R = K q + f(q) - F`` at the supports [N].
    supports : (k,) int ndarray
        The supported dofs.
    iterations : int
        Newton solves (0: the start already satisfied the test).
    residual : float
        ``||r||`` on the unsupported dofs over ``|| |K| |q| || + ||f|| + ||F||``.
    """

    displacement: np.ndarray
    state: Any
    reactions: np.ndarray
    supports: np.ndarray
    iterations: int
    residual: float


def solve_static(system: SecondOrderSystem, load: np.ndarray | None = None, *, supports=(), state=None,
                 initial_displacement: np.ndarray | None = None, closed_start: bool = True,
                 rtol: float = 1e-10, max_iterations: int = 50) -> StaticSolution:
    r"""Newton on ``K q + f(q; z) = F`` with ``q = 0`` at ``supports`` (see the module docstring).

    Parameters
    ----------
    system : SecondOrderSystem
        ``K`` and the nonlinear force ``f`` (or none: one linear solve).
    load : (n,) ndarray, optional
        ``F``; default the system's constant load ``f_0`` (e.g. a bolt preload).
    supports : (k,) int array_like
        Dofs held at zero (e.g. :func:`point_supports`).
    state : optional
        The force's committed state (default: its initial state); frozen during Newton.
    initial_displacement : (n,) ndarray, optional
        Newton's start (default zero).
    closed_start : bool
        Evaluate the first tangent of every :class:`~femrom.fem.JointForce` with its
        open pairs closed (normal gap ``-CLOSING_GAP``): a penalty contact at zero gap
        has no stiffness yet, so the first tangent of two bodies that only touch would
        be singular. The first iterate is then the linear solution with every pair in
        contact; Newton opens the pairs that pull.
    rtol : float
        Converged when ``||r|| <= rtol (|| |K| |q| || + ||f|| + ||F||)`` on the unsupported dofs
        (``|K| |q|``: the entries' magnitudes, the scale of the round-off in ``K q``).
    max_iterations : int

    Returns
    -------
    StaticSolution

    Raises
    ------
    FemromValueError
        No load, a bad support index or tolerance, or no convergence (the message gives
        the residual and the number of pairs that changed contact status last).
    """
    n = system.n_dofs
    F = system.load if load is None else np.asarray(load, dtype=float)
    if F is None:
        raise FemromValueError("load: the system has no constant load f_0 (list bolt_preload) and none was given")
    if F.shape != (n,):
        raise FemromValueError(f"load must have shape ({n},), got {F.shape}")
    supports = np.unique(np.asarray(supports, dtype=np.int64))
    if supports.size and (supports[0] < 0 or supports[-1] >= n):
        raise FemromValueError(f"supports must be dof indices in [0, {n}), got [{supports[0]}, {supports[-1]}]")
    if not (rtol > 0 and max_iterations >= 1):
        raise FemromValueError(f"rtol must be > 0 and max_iterations >= 1, got {rtol!r}, {max_iterations!r}")
    active = np.setdiff1d(np.arange(n), supports)
    force = system.nonlinear
    if force is not None and state is None:
        state = force.initial_state()
    K = sp.csr_matrix(system.stiffness)
    K_abs = abs(K)
    q = np.zeros(n) if initial_displacement is None else np.array(initial_displacement, dtype=float)
    q[supports] = 0.0

    def residual(q):
        elastic = K @ q
        nonlinear = np.zeros(n) if force is None else force.force(q, None, state)
        r = elastic + nonlinear - F
        # |K| |q|: the size of the terms summed in K q, so that rtol sits above their round-off
        scale = np.linalg.norm(K_abs @ np.abs(q)) + np.linalg.norm(nonlinear) + np.linalg.norm(F)
        return r, scale

    iteration = 0
    while True:
        r, scale = residual(q)
        size = float(np.linalg.norm(r[active]))
        relative = size / scale if scale > 0 else 0.0
        if not np.isfinite(size):
            raise FemromValueError(f"solve_static: the residual is not finite at iteration {iteration} (a singular "
                                   "tangent: supports that do not hold the structure, or every contact open)")
        if size <= rtol * scale:
            break
        if iteration == max_iterations:
            raise FemromValueError(f"solve_static did not converge in max_iterations = {max_iterations}: relative "
                                   f"residual {relative:.3g} > rtol {rtol:g}")
        J = K if force is None else K + _tangent(force, q, state, closed=closed_start and iteration == 0)
        J = sp.csr_matrix(J)[active][:, active]
        dq = make_solver(J.tocsc(), spd=False).solve(r[active])
        q[active] -= dq
        iteration += 1
        if force is None:      # linear: one solve is exact up to round-off
            r, scale = residual(q)
            size = float(np.linalg.norm(r[active]))
            relative = size / scale if scale > 0 else 0.0
            break
    committed = None if force is None else force.commit(q, None, state)
    return StaticSolution(displacement=q, state=committed, reactions=r[supports].copy(), supports=supports,
                          iterations=iteration, residual=relative)


def _tangent(force, q, state, *, closed: bool):
    """``df/dq`` at ``q``; with ``closed``, every JointForce's pairs evaluated in contact."""
    parts = force.forces if isinstance(force, fem.ForceSum) else (force,)
    states = state if isinstance(force, fem.ForceSum) else (state,)
    total = None
    for part, part_state in zip(parts, states):
        if closed and isinstance(part, fem.JointForce):
            x = part.localize(q).reshape(-1, 3).copy()
            x[:, 2] = np.minimum(x[:, 2] + part.initial_gap, -CLOSING_GAP) - part.initial_gap
            local = part.local_tangent(x.ravel(), None, part_state)[0]
            D = (part.local_map.T @ local @ part.local_map).tocsr()
        else:
            D = part.tangent(q, None, part_state)[0]
        if D is not None:
            total = D if total is None else total + D
    return total if total is not None else sp.csr_matrix(force.tangent(q, None, state)[0].shape)


def with_friction_coefficient(system: SecondOrderSystem, friction_coefficient: float) -> SecondOrderSystem:
    """The system with every joint law's ``friction_coefficient`` replaced (0: frictionless contact).

    Raises
    ------
    FemromValueError
        The system has no :class:`~femrom.fem.JointForce`, or one whose law has no
        ``friction_coefficient`` (Jenkins and Iwan: a bilateral normal spring, no
        unilateral contact to solve for).
    """
    forces = system.nonlinear_forces
    joints = [f for f in forces if isinstance(f, fem.JointForce)]
    if not joints:
        raise FemromValueError("the system has no joint force (list the 'joint' effect)")
    replaced = []
    for f in forces:
        if isinstance(f, fem.JointForce):
            law = f.law.parameters()
            if "friction_coefficient" not in law:
                raise FemromValueError(f"joint law {law['name']!r} has no friction_coefficient: the preload sequence "
                                       "(frictionless contact, then friction) needs unilateral contact, law "
                                       "'dry_friction'")
            parameters = {**f.parameters(), "law": {**law, "friction_coefficient": float(friction_coefficient)}}
            f = fem.JointForce.from_parameters(parameters)
        replaced.append(f)
    return dataclasses.replace(system, nonlinear=replaced if len(replaced) > 1 else replaced[0])


@dataclass(frozen=True, eq=False)
class Preload:
    """Result of :func:`preload`: the frictionless equilibrium and the one with friction on from it.

    Attributes
    ----------
    frictionless : StaticSolution
        The preload with frictionless normal contact, sliders committed.
    frictional : StaticSolution
        Friction on from there (``iterations == 0`` when the sliders hold the state exactly).
    system : SecondOrderSystem
        The system with friction (the one given).
    """

    frictionless: StaticSolution
    frictional: StaticSolution
    system: SecondOrderSystem

    @property
    def displacement(self) -> np.ndarray:
        return self.frictional.displacement

    @property
    def state(self):
        return self.frictional.state


def preload(system: SecondOrderSystem, *, supports, load: np.ndarray | None = None, rtol: float = 1e-10,
            max_iterations: int = 50) -> Preload:
    """The bolt-preload sequence (module docstring): frictionless contact, then friction on from that state.

    Parameters
    ----------
    system : SecondOrderSystem
        With a :class:`~femrom.fem.JointForce` of law ``dry_friction`` and a constant
        load (the preload, e.g. from the ``bolt_preload`` effect) unless ``load`` is given.
    supports : (k,) int array_like
        Statically determinate supports of the free structure: with frictionless contact
        the halves of a joint may also slide, so they need to hold those mechanisms too
        (the reactions, zero for a self-equilibrated preload, check it).
    load, rtol, max_iterations
        As in :func:`solve_static`.
    """
    frictionless = solve_static(with_friction_coefficient(system, 0.0), load, supports=supports, rtol=rtol,
                                max_iterations=max_iterations)
    frictional = solve_static(system, load, supports=supports, state=frictionless.state,
                              initial_displacement=frictionless.displacement, closed_start=False, rtol=rtol,
                              max_iterations=max_iterations)
    return Preload(frictionless, frictional, system)


def point_supports(space, condensation, supports) -> np.ndarray:
    """Free-dof indices of components held at the mesh nodes nearest to given points.

    Parameters
    ----------
    space : SolidSpace
    condensation : Condensation
    supports : sequence of (point, components)
        ``point`` (3,) coordinates, ``components`` a string of ``x``, ``y``, ``z``,
        e.g. ``[((0, 0, -w), "xyz"), ((0, 0, w), "xy"), ((0, t, -w), "x")]`` (3-2-1).

    Returns
    -------
    (k,) int ndarray
        Positions in the free-dof vector, in the given order.

    Raises
    ------
    FemromValueError
        An unknown component, or a dof that ``condensation`` already fixes.
    """
    dofs = []
    for point, components in supports:
        for component in components:
            if component not in space.components:
                raise FemromValueError(f"supports: unknown component {component!r}; "
                                       f"valid: {', '.join(space.components)}")
            full, locations = space.coordinates(component)
            nearest = full[np.argmin(np.linalg.norm(locations.T - np.asarray(point, dtype=float), axis=1))]
            dofs.append(nearest)
    dofs = np.asarray(dofs, dtype=np.int64)
    position = np.minimum(np.searchsorted(condensation.free, dofs), condensation.n_free - 1)
    if np.any(condensation.free[position] != dofs):
        raise FemromValueError("supports: a supported dof is already fixed by the condensation")
    return position
