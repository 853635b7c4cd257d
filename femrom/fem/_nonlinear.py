r"""Nonlinear internal forces that know where they act, and sums of them.

A nonlinear effect enters the equations of motion as

.. math::

    M \ddot q + C \dot q + K q + f(q, \dot q; s) = B u, \qquad
    f(q, \dot q; s) = L^\top g(L q, L \dot q; s),

where ``L`` (s, n) is the force's *local map* from the n free dofs to its s
local coordinates (a selection of dofs, a relative displacement across an
interface, values at quadrature points) and ``g`` its *local law*. The split
follows tmdsimpy's ``Q``/``T`` pair (with ``T = Q^T``, so that the force is
work-conjugate to its coordinates): the same local law serves Newton on the
force's own coordinates (:mod:`femrom.integrators`), projection onto a reduced
basis (``V^T L^T g(L V q^)``) and hyper-reduction.

``s`` is an optional internal state (the slider positions of a stick-slip
joint): *frozen* during the Newton iterations of a step, *committed* once the
step has converged. A checkpoint is a dict of arrays, so a snapshot store saves
it next to (q, v, a) and a run resumes bit for bit.

A system holds a sum of forces (:class:`ForceSum`), each on its own
coordinates with its own state. A force that can be rebuilt from arrays and
numbers has :meth:`NonlinearForce.parameters` and is registered by name
(:func:`register_force`), so a reduced model that carries it saves it whole.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError

#: Forces that can be rebuilt from :meth:`NonlinearForce.parameters`, by ``kind``.
FORCES: dict[str, type["NonlinearForce"]] = {}


def register_force(cls):
    """Class decorator: ``cls`` can be rebuilt by :func:`force_from_parameters`."""
    FORCES[cls.kind] = cls
    return cls


def force_from_parameters(parameters: dict) -> "NonlinearForce":
    """Inverse of :meth:`NonlinearForce.parameters`."""
    kind = str(parameters["kind"])
    if kind not in FORCES:
        raise FemromValueError(f"unknown nonlinear force kind {kind!r}; known: {', '.join(FORCES)}")
    return FORCES[kind].from_parameters(parameters)


def selection_map(dofs, n_dofs: int) -> sp.csr_matrix:
    """(s, n) csr ``L`` with ``L q = q[dofs]``."""
    dofs = np.asarray(dofs, dtype=np.int64)
    return sp.csr_matrix((np.ones(dofs.size), (np.arange(dofs.size), dofs)), shape=(dofs.size, n_dofs))


def _as_diagonal_or_matrix(D, size: int):
    """A local tangent as given: ``None``, an (s,) diagonal, or an (s, s) matrix."""
    if D is None:
        return None
    if sp.issparse(D):
        return D
    D = np.asarray(D, dtype=float)
    if D.ndim == 1 and D.size != size or D.ndim == 2 and D.shape != (size, size):
        raise FemromValueError(f"local tangent has shape {D.shape}, expected ({size},) or ({size}, {size})")
    return D


class NonlinearForce:
    r"""``f(q, v; s) = L^T g(L q, L v; s)`` on the free dofs.

    Subclasses implement the local law :meth:`local_force` and
    :meth:`local_tangent` (and :meth:`local_potential` when conservative);
    stateful forces also :meth:`initial_state`, :meth:`local_commit`,
    :meth:`checkpoint` and :meth:`restore`.

    Parameters
    ----------
    n_dofs : int
        Size ``n`` of the system the force acts in.
    dofs : (s,) int array, optional
        The local coordinates are these dofs (``L`` a selection). Default: all.
    local_map : (s, n) sparse, optional
        A general ``L`` instead of ``dofs``.
    name : str, optional
        Label of the force in a sum (checkpoint keys, reports).

    Attributes
    ----------
    conservative : bool
        ``g = grad U(x)``: no velocity dependence, no state; the system energy
        includes ``U``.
    velocity_dependent : bool
        ``g`` depends on ``L v`` (its tangent has a ``dg/dxdot`` block).
    stateful : bool
        ``g`` depends on an internal state.
    """

    kind: ClassVar[str] = ""
    #: ``local_force`` also takes (s, k) columns (stateless forces evaluated on many states at once).
    columns: ClassVar[bool] = False
    conservative: ClassVar[bool] = False
    velocity_dependent: ClassVar[bool] = False
    stateful: ClassVar[bool] = False

    def __init__(self, n_dofs: int, *, dofs=None, local_map=None, name: str | None = None):
        n_dofs = int(n_dofs)
        if dofs is not None and local_map is not None:
            raise FemromValueError("give dofs or local_map, not both")
        self.n_dofs = n_dofs
        self.name = name or (self.kind or type(self).__name__)
        if local_map is not None:
            L = sp.csr_matrix(local_map, dtype=float)
            if L.shape[1] != n_dofs:
                raise FemromValueError(f"local_map has {L.shape[1]} columns, the system {n_dofs} dofs")
            self._dofs = None
            self.local_map = L
        else:
            if dofs is None:
                idx = np.arange(n_dofs)
            else:
                idx = np.asarray(dofs, dtype=np.int64).ravel()
                if idx.size and (idx.min() < 0 or idx.max() >= n_dofs):
                    raise FemromValueError(f"dofs must lie in [0, {n_dofs}), got [{idx.min()}, {idx.max()}]")
                if np.unique(idx).size != idx.size:
                    raise FemromValueError("dofs of a nonlinear force must be distinct")
            idx.setflags(write=False)
            self._dofs = idx
            self.local_map = selection_map(idx, n_dofs)
        self._all = self._dofs is not None and self._dofs.size == n_dofs \
            and np.array_equal(self._dofs, np.arange(n_dofs))

    # -- where it acts ---------------------------------------------------------
    @property
    def n_local(self) -> int:
        """Number ``s`` of local coordinates."""
        return self.local_map.shape[0]

    @property
    def dofs(self) -> np.ndarray:
        """Sorted free dofs the force touches (the columns of ``L`` that are used)."""
        if self._dofs is not None:
            return np.sort(self._dofs)
        return np.unique(self.local_map.indices)

    @property
    def selection(self) -> np.ndarray | None:
        """The dof of each local coordinate when ``L`` is a selection, else ``None``."""
        return self._dofs

    def localize(self, q: np.ndarray | None) -> np.ndarray | None:
        """(s,) or (s, k) local coordinates ``L q`` (``None`` stays ``None``)."""
        if q is None:
            return None
        if self._all:
            return q
        if self._dofs is not None:
            return q[self._dofs]
        return np.asarray(self.local_map @ q)

    def globalize(self, g: np.ndarray) -> np.ndarray:
        """(n,) or (n, k) ``L^T g`` of local forces ``g``."""
        if self._all:
            return g
        if self._dofs is not None:
            out = np.zeros((self.n_dofs,) + g.shape[1:])
            out[self._dofs] = g
            return out
        return np.asarray(self.local_map.T @ g)

    # -- the local law (subclasses) ---------------------------------------------
    def local_force(self, x: np.ndarray, xdot: np.ndarray | None, state: Any) -> np.ndarray:
        """(s,) ndarray ``g(x, xdot; state)``; (s, k) columns for stateless forces."""
        raise NotImplementedError

    def local_tangent(self, x: np.ndarray, xdot: np.ndarray | None, state: Any):
        """``(dg/dx, dg/dxdot)``: each ``None``, an (s,) diagonal or an (s, s) matrix."""
        raise NotImplementedError

    def local_potential(self, x: np.ndarray) -> float:
        """``U(x)`` with ``g = grad U`` (conservative forces only)."""
        raise NotImplementedError(f"{type(self).__name__} has no potential")

    #: Optional (a stateful force): ``local_step_force(x0, x1, state) -> (g, dg/dx1)``, the local force of a
    #: whole step from ``x0`` to ``x1`` with ``state`` committed at ``x0``, whose work ``g . (x1 - x0)`` is at
    #: least what the force stores and dissipates over the step (a joint with an energy-consistent law,
    #: :attr:`femrom.fem.JointForce.local_step_force`); the tangent as :meth:`local_tangent`'s. ``None``: the
    #: force has none. :attr:`step_force` is its global view.
    local_step_force = None

    def initial_state(self) -> Any:
        """Internal state at t = 0 (``None`` for a stateless force)."""
        return None

    def local_commit(self, x: np.ndarray, xdot: np.ndarray | None, state: Any) -> Any:
        """State after a converged step ending at local coordinates (x, xdot)."""
        return state

    def checkpoint(self, state: Any) -> dict[str, np.ndarray]:
        """Arrays that restore ``state`` exactly (keys are dataset names: no ``/``)."""
        return {}

    def restore(self, data: dict[str, np.ndarray]) -> Any:
        """Inverse of :meth:`checkpoint`."""
        return self.initial_state()

    # -- the global view ----------------------------------------------------------
    def force(self, q: np.ndarray, v: np.ndarray | None = None, state: Any = None) -> np.ndarray:
        """(n,) ndarray ``f(q, v; state) = L^T g(L q, L v; state)``."""
        return self.globalize(self.local_force(self.localize(q), self.localize(v), state))

    def tangent(self, q: np.ndarray, v: np.ndarray | None = None, state: Any = None):
        """``(df/dq, df/dv)``: (n, n) sparse ``L^T (dg/dx) L`` (a ``dia`` matrix when diagonal), or ``None``."""
        parts = self.local_tangent(self.localize(q), self.localize(v), state)
        return tuple(self._global_matrix(_as_diagonal_or_matrix(D, self.n_local)) for D in parts)

    def _global_matrix(self, D):
        if D is None:
            return None
        n = self.n_dofs
        if np.ndim(D) == 1 and not sp.issparse(D) and self._dofs is not None:
            # a DIA matrix: cheap to build every Newton iteration, added onto a stored diagonal
            d = D if self._all else np.zeros(n)
            if not self._all:
                d[self._dofs] = D
            return sp.dia_matrix((d, 0), shape=(n, n))
        local = sp.diags(D) if np.ndim(D) == 1 and not sp.issparse(D) else sp.csr_matrix(D)
        L = self.local_map
        return (L.T @ local @ L).tocsr()

    @property
    def step_force(self):
        r"""``(q0, q1, state) -> (f (n,), df/dq1 (n, n) sparse)``: ``L^T g`` of :attr:`local_step_force`, or ``None``.

        The force a time step from ``q0`` to ``q1`` balances in place of ``f(q_m)`` when it is to
        keep the discrete energy balance (:class:`femrom.integrators.DiscreteGradient`)."""
        local = self.local_step_force
        if not callable(local):
            return None

        def step_force(q0, q1, state=None):
            g, D = local(self.localize(q0), self.localize(q1), state)
            return self.globalize(g), self._global_matrix(_as_diagonal_or_matrix(D, self.n_local))

        return step_force

    def potential(self, q: np.ndarray) -> float:
        """``U(L q)`` (conservative forces only)."""
        return float(self.local_potential(self.localize(q)))

    def commit(self, q: np.ndarray, v: np.ndarray | None, state: Any) -> Any:
        """State after a converged step ending at (q, v)."""
        if not self.stateful:
            return state
        return self.local_commit(self.localize(q), self.localize(v), state)

    # -- storage ------------------------------------------------------------------
    def parameters(self) -> dict | None:
        """Arrays and numbers that rebuild this force (``kind`` included), or ``None``."""
        return None

    def _placement(self) -> dict:
        """The local map as parameters: ``dofs`` for a selection, else the CSR arrays."""
        if self._dofs is not None:
            return {"n_dofs": self.n_dofs, "dofs": np.asarray(self._dofs)}
        L = self.local_map
        return {"n_dofs": self.n_dofs, "map_data": L.data, "map_indices": L.indices,
                "map_indptr": L.indptr, "n_local": L.shape[0]}

    @staticmethod
    def _placement_from(parameters: dict) -> dict:
        n = int(parameters["n_dofs"])
        if "dofs" in parameters:
            return {"n_dofs": n, "dofs": np.asarray(parameters["dofs"], dtype=np.int64)}
        L = sp.csr_matrix((parameters["map_data"], parameters["map_indices"], parameters["map_indptr"]),
                          shape=(int(parameters["n_local"]), n))
        return {"n_dofs": n, "local_map": L}

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, n_dofs={self.n_dofs}, n_local={self.n_local})"


class ForceSum(NonlinearForce):
    r"""``f = sum_i L_i^T g_i(L_i q, L_i v; s_i)``: several forces, each on its own coordinates.

    The local coordinates are the forces' stacked (``L = [L_1; L_2; ...]``), the
    state is the tuple of their states, checkpoint keys are prefixed by the
    forces' names (``"joint.slider"``), the tangent is block diagonal.

    Parameters
    ----------
    forces : sequence of NonlinearForce
        At least two, acting in one system, with distinct names.
    """

    kind = "sum"

    def __init__(self, forces):
        forces = tuple(forces)
        if len(forces) < 2:
            raise FemromValueError("a ForceSum needs at least two forces")
        n = forces[0].n_dofs
        if any(f.n_dofs != n for f in forces):
            raise FemromValueError(f"forces act in systems of different sizes: {[f.n_dofs for f in forces]}")
        names = [f.name for f in forces]
        if len(set(names)) != len(names):
            raise FemromValueError(f"forces in a sum need distinct names, got {names}")
        self.forces = forces
        super().__init__(n, local_map=sp.vstack([f.local_map for f in forces]).tocsr(), name="sum")
        sizes = np.cumsum([0] + [f.n_local for f in forces])
        self._slices = [slice(a, b) for a, b in zip(sizes[:-1], sizes[1:])]

    @property
    def conservative(self) -> bool:  # type: ignore[override]
        return all(f.conservative for f in self.forces)

    @property
    def velocity_dependent(self) -> bool:  # type: ignore[override]
        return any(f.velocity_dependent for f in self.forces)

    @property
    def stateful(self) -> bool:  # type: ignore[override]
        return any(f.stateful for f in self.forces)

    def _parts(self, x):
        return [None if x is None else x[s] for s in self._slices]

    def local_force(self, x, xdot, state):
        states = state if state is not None else (None,) * len(self.forces)
        return np.concatenate([f.local_force(xi, vi, si) for f, xi, vi, si
                               in zip(self.forces, self._parts(x), self._parts(xdot), states)])

    def local_tangent(self, x, xdot, state):
        states = state if state is not None else (None,) * len(self.forces)
        blocks = [f.local_tangent(xi, vi, si) for f, xi, vi, si
                  in zip(self.forces, self._parts(x), self._parts(xdot), states)]
        return tuple(self._stack([_as_diagonal_or_matrix(b[k], f.n_local)
                                  for b, f in zip(blocks, self.forces)]) for k in range(2))

    def _stack(self, parts):
        if all(p is None for p in parts):
            return None
        sizes = [f.n_local for f in self.forces]
        if all(p is None or (np.ndim(p) == 1 and not sp.issparse(p)) for p in parts):
            return np.concatenate([np.zeros(s) if p is None else p for p, s in zip(parts, sizes)])
        mats = [sp.csr_matrix((s, s)) if p is None else (sp.diags(p) if np.ndim(p) == 1 and not sp.issparse(p)
                                                          else sp.csr_matrix(p)) for p, s in zip(parts, sizes)]
        return sp.block_diag(mats, format="csr")

    def local_potential(self, x):
        return sum(f.local_potential(xi) for f, xi in zip(self.forces, self._parts(x)))

    # global evaluations go force by force (each keeps its own fast path)
    def force(self, q, v=None, state=None):
        states = state if state is not None else (None,) * len(self.forces)
        return sum(f.force(q, v, s) for f, s in zip(self.forces, states))

    def tangent(self, q, v=None, state=None):
        states = state if state is not None else (None,) * len(self.forces)
        parts = [f.tangent(q, v, s) for f, s in zip(self.forces, states)]
        out = []
        for k in range(2):
            mats = [p[k] for p in parts if p[k] is not None]
            out.append(None if not mats else sum(mats[1:], mats[0]).tocsr() if len(mats) > 1 else mats[0])
        return tuple(out)

    def potential(self, q):
        return float(sum(f.potential(q) for f in self.forces))

    def initial_state(self):
        return tuple(f.initial_state() for f in self.forces)

    def commit(self, q, v, state):
        return tuple(f.commit(q, v, s) for f, s in zip(self.forces, state))

    def local_commit(self, x, xdot, state):
        return tuple(f.local_commit(xi, vi, s) if f.stateful else s for f, xi, vi, s
                     in zip(self.forces, self._parts(x), self._parts(xdot), state))

    def checkpoint(self, state):
        return {f"{f.name}.{key}": value for f, s in zip(self.forces, state)
                for key, value in f.checkpoint(s).items()}

    def restore(self, data):
        states = []
        for f in self.forces:
            prefix = f"{f.name}."
            own = {k[len(prefix):]: v for k, v in data.items() if k.startswith(prefix)}
            states.append(f.restore(own))
        return tuple(states)

    def parameters(self):
        parts = [f.parameters() for f in self.forces]
        if any(p is None for p in parts):
            return None
        return {"kind": self.kind, "forces": parts}

    @classmethod
    def from_parameters(cls, parameters):
        return cls([force_from_parameters(p) for p in parameters["forces"]])


register_force(ForceSum)


def sum_of_forces(forces) -> NonlinearForce | None:
    """``None``, the single force, or a :class:`ForceSum` of several."""
    forces = [f for f in forces if f is not None]
    if not forces:
        return None
    if len(forces) == 1:
        return forces[0]
    return ForceSum(forces)
