r"""Zero-thickness interface elements at matching node pairs: the joint force.

Two faces of a joint (side a, side b) meet at ``s`` pairs of matching nodes,
each with a unit normal ``n_i`` (of side a, pointing towards side b) and a
tributary area ``A_i``. The pair's relative displacement in its local frame
``(t1_i, t2_i, n_i)``,

.. math::

    \Delta_i = R_i (u_{b,i} - u_{a,i}) + \Delta_{0,i}, \qquad
    R_i = [t_{1,i};\ t_{2,i};\ n_i] \ (3, 3),

(``Delta_0`` an initial gap, negative for an interference that stands for a
preload) goes through an interface law (:data:`femrom.fem.INTERFACE_LAWS`)
to a traction ``t_i`` (s, 3), and the joint force on the free dofs is

.. math::

    f(q; z) = L^\top g, \qquad g_i = A_i\, t_i(L_i q + \Delta_{0,i}; z_i), \qquad
    \frac{\partial g}{\partial x} = \operatorname{blockdiag}(A_i\, \partial t_i / \partial \Delta_i),

with ``L`` (3 s, n) the sparse map ``q -> (R_i (u_b - u_a))_i``: a
:class:`femrom.fem.NonlinearForce` whose local coordinates are the pairs'
relative displacements, so Newton condenses onto them and a reduced basis
projects them like any other force.

A law with a rate term (:attr:`femrom.fem.InterfaceLaw.velocity_dependent`, e.g. the reclosed
points' dashpot of :class:`~femrom.fem.ClampedIwanLaw`) also reads the pairs' relative velocities
``dDelta_i/dt = L_i v`` (the rate of the initial gap is zero): ``g_i = A_i t_i(Delta_i, dDelta_i/dt; z_i)``,
and the force has the damping tangent ``dg/dxdot = blockdiag(A_i dt_i / d(dDelta_i/dt))``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.fem._interface_law import InterfaceLaw, interface_law_from_parameters
from femrom.fem._nonlinear import NonlinearForce, register_force


def interface_frames(normals, first_tangents=None) -> np.ndarray:
    r"""(s, 3, 3) rotations ``R_i`` with rows ``(t1_i, t2_i, n_i)``, right-handed.

    ``n_i`` is the given normal normalised. ``t1_i`` is ``first_tangents``
    projected onto the tangent plane and normalised when given, else the unit
    vector of the coordinate axis least aligned with ``n_i``, projected (a
    deterministic choice; the laws are isotropic in the tangent plane, so it
    only names the components). ``t2 = n x t1``.

    Parameters
    ----------
    normals : (s, 3) array
    first_tangents : (s, 3) or (3,) array, optional
    """
    normals = np.asarray(normals, dtype=float)
    if normals.ndim != 2 or normals.shape[1] != 3:
        raise FemromValueError(f"normals must be (s, 3), got shape {normals.shape}")
    length = np.linalg.norm(normals, axis=1)
    if not np.all(length > 0):
        raise FemromValueError(f"normals must be nonzero; {int(np.sum(~(length > 0)))} are zero or not finite")
    n = normals / length[:, None]
    if first_tangents is None:
        t = np.zeros_like(n)
        t[np.arange(n.shape[0]), np.argmin(np.abs(n), axis=1)] = 1.0
    else:
        t = np.broadcast_to(np.asarray(first_tangents, dtype=float), n.shape)
    t = t - np.einsum("si,si->s", t, n)[:, None] * n
    t_length = np.linalg.norm(t, axis=1)
    if not np.all(t_length > 1e-12):
        raise FemromValueError("first_tangents must not be parallel to the normals")
    t1 = t / t_length[:, None]
    t2 = np.cross(n, t1)
    return np.stack([t1, t2, n], axis=1)


def _side(dofs, name: str, n_dofs: int) -> np.ndarray:
    dofs = np.asarray(dofs)
    if dofs.ndim != 2 or dofs.shape[1] != 3 or not np.issubdtype(dofs.dtype, np.integer):
        raise FemromValueError(f"{name} must be an (s, 3) integer array of dof indices, got shape {dofs.shape} "
                               f"and dtype {dofs.dtype}")
    if dofs.size and dofs.max() >= n_dofs:
        raise FemromValueError(f"{name} must lie in [0, {n_dofs}) (or be -1 for a fixed component), got {dofs.max()}")
    return dofs.astype(np.int64)


def relative_displacement_map(dofs_a, dofs_b, frames, n_dofs: int) -> sp.csr_matrix:
    r"""(3 s, n) csr ``L``: ``(L q)[3 i + c] = R_i[c] . (u_b,i - u_a,i)``.

    A negative dof index marks a fixed component (zero displacement: a side
    clamped or grounded).
    """
    s = frames.shape[0]
    rows = np.repeat(np.arange(3 * s).reshape(s, 3, 1), 3, axis=2)          # (s, c, d)
    parts = []
    for dofs, sign in ((dofs_b, 1.0), (dofs_a, -1.0)):
        cols = np.broadcast_to(dofs[:, None, :], (s, 3, 3))
        free = cols >= 0
        parts.append((rows[free], cols[free], sign * frames[free]))
    r, c, v = (np.concatenate(p) for p in zip(*parts))
    return sp.csr_matrix((v, (r, c)), shape=(3 * s, n_dofs))


@register_force
class JointForce(NonlinearForce):
    r"""Interface elements at ``s`` node pairs under one interface law (see the module docstring).

    Parameters
    ----------
    law : InterfaceLaw
        e.g. ``interface_law("iwan", slip_traction=..., ...)``.
    dofs_a, dofs_b : (s, 3) int arrays
        The x, y, z dofs of the pairs' nodes on side a and side b (-1: a fixed component).
    normals : (s, 3) array
        Normals of side a, pointing towards side b (normalised here).
    areas : (s,) array
        Tributary areas ``A_i > 0`` [m^2].
    n_dofs : int
        Size of the system.
    initial_gap : float or (s,) array, optional
        Normal gap ``g_n`` at ``q = 0`` (default 0); negative: an interference (preload).
    first_tangents : (s, 3) or (3,) array, optional
        Direction of the first tangential axis (see :func:`interface_frames`).
    name : str, optional

    Local coordinates: (3 s,) ``(g_t1, g_t2, g_n)`` of each pair without the
    initial gap (``L q``). State: the law's, one row per pair; checkpoint keys
    from :meth:`InterfaceLaw.checkpoint` (``"slip"``).
    """

    kind = "joint"
    stateful = True

    def __init__(self, law: InterfaceLaw, dofs_a, dofs_b, normals, areas, n_dofs: int, *, initial_gap=0.0,
                 first_tangents=None, name: str | None = None):
        if not isinstance(law, InterfaceLaw):
            raise FemromValueError("law must be an InterfaceLaw (see femrom.fem.interface_law), "
                                   f"got {type(law).__name__}")
        n_dofs = int(n_dofs)
        dofs_a, dofs_b = _side(dofs_a, "dofs_a", n_dofs), _side(dofs_b, "dofs_b", n_dofs)
        if dofs_a.shape != dofs_b.shape:
            raise FemromValueError(f"dofs_a and dofs_b must have one shape, got {dofs_a.shape} and {dofs_b.shape}")
        s = dofs_a.shape[0]
        if np.any((dofs_a == dofs_b) & (dofs_a >= 0)):
            raise FemromValueError("dofs_a and dofs_b must differ component by component (a pair joins two nodes)")
        normals = np.asarray(normals, dtype=float)
        if normals.shape != (s, 3):
            raise FemromValueError(f"normals must be ({s}, 3) like the dofs, got shape {normals.shape}")
        areas = np.asarray(areas, dtype=float)
        if areas.shape != (s,) or not np.all(areas > 0):
            raise FemromValueError(f"areas must be ({s},) and > 0, got shape {areas.shape}"
                                   + (f" with minimum {areas.min()!r}" if areas.size else ""))
        gap = np.broadcast_to(np.asarray(initial_gap, dtype=float), (s,)).copy()
        if not np.all(np.isfinite(gap)):
            raise FemromValueError("initial_gap must be finite")
        frames = interface_frames(normals, first_tangents)
        super().__init__(n_dofs, local_map=relative_displacement_map(dofs_a, dofs_b, frames, n_dofs), name=name)
        self.law, self.dofs_a, self.dofs_b, self.areas = law, dofs_a, dofs_b, areas
        self.normals, self.frames, self.initial_gap = frames[:, 2].copy(), frames, gap
        # as given, so that the parameters rebuild the frames bit for bit
        self._given = {"normals": normals.copy()}
        if first_tangents is not None:
            self._given["first_tangents"] = np.array(first_tangents, dtype=float)
        self._offset = np.zeros((s, 3))
        self._offset[:, 2] = gap
        # the block-diagonal pattern of the local tangent, fixed: row 3 i + c holds columns 3 i + (0, 1, 2)
        self._tangent_indices = np.repeat(np.arange(3 * s).reshape(s, 1, 3), 3, axis=1).ravel()
        self._tangent_indptr = np.arange(0, 9 * s + 1, 3)

    @property
    def n_pairs(self) -> int:
        """Number ``s`` of node pairs."""
        return self.areas.size

    # -- local law ------------------------------------------------------------------
    def gaps(self, x: np.ndarray) -> np.ndarray:
        """(s, 3) local relative displacements ``Delta`` of local coordinates ``x`` (3 s,)."""
        return x.reshape(self.n_pairs, 3) + self._offset

    def _state(self, state):
        return self.law.initial_state(self.n_pairs) if state is None else state

    @property
    def velocity_dependent(self) -> bool:  # type: ignore[override]
        """Whether the law reads the gaps' rates (:attr:`femrom.fem.InterfaceLaw.velocity_dependent`)."""
        return bool(getattr(self.law, "velocity_dependent", False))

    #: :meth:`local_step_derivative` takes the rates' derivative too (``xdot=``, ``dxdot=``), so that
    #: :class:`femrom.integrators.HarmonicBalance` keeps the exact Jacobian of a velocity-dependent law.
    step_derivative_rates = True

    def rates(self, xdot) -> np.ndarray:
        """(s, 3) rates ``dDelta/dt`` of the local relative displacements from local velocities ``xdot`` (3 s,)
        (zero for ``None``)."""
        if xdot is None:
            return np.zeros((self.n_pairs, 3))
        return np.asarray(xdot, dtype=float).reshape(self.n_pairs, 3)

    def local_force(self, x, xdot=None, state=None):
        if self.velocity_dependent:
            traction = self.law.evaluate_rate(self.gaps(x), self.rates(xdot), self._state(state), tangent=False)[0]
        else:
            traction, _ = self.law.evaluate(self.gaps(x), self._state(state), tangent=False)
        return (self.areas[:, None] * traction).ravel()

    def _block_matrix(self, D):
        blocks = self.areas[:, None, None] * D
        shape = (3 * self.n_pairs,) * 2
        return sp.csr_matrix((blocks.ravel(), self._tangent_indices, self._tangent_indptr), shape=shape)

    def local_tangent(self, x, xdot=None, state=None):
        """``(dg/dx, dg/dxdot)`` (3 s, 3 s) block-diagonal csr; ``dg/dxdot`` is ``None`` unless the law reads
        the rates."""
        if self.velocity_dependent:
            _, D, C = self.law.evaluate_rate(self.gaps(x), self.rates(xdot), self._state(state), tangent=True)
            return self._block_matrix(D), self._block_matrix(C)
        _, D = self.law.evaluate(self.gaps(x), self._state(state), tangent=True)
        return self._block_matrix(D), None

    def local_force_and_blocks(self, x, state=None):
        """``(g (3 s,), A_i dt_i/dDelta_i (s, 3, 3))``: force and tangent blocks from one law evaluation
        (the rates taken as zero: a velocity-dependent joint's damping tangent is :meth:`local_tangent`'s)."""
        traction, D = self.law.evaluate(self.gaps(x), self._state(state), tangent=True)
        return (self.areas[:, None] * traction).ravel(), self.areas[:, None, None] * D

    def initial_state(self):
        return self.law.initial_state(self.n_pairs)

    @property
    def local_step_derivative(self):
        r"""``(x, state, dx, dstate) -> (dg, dstate_new)``, or ``None`` when the law has no step derivative.

        The forward derivative of one return-map step along ``m`` directions, as
        :meth:`femrom.fem.JenkinsForce.local_step_derivative`: ``dx`` (3 s, m) of the local
        coordinates, ``dstate`` ``state.shape + (m,)`` of the frozen state; ``dg`` (3 s, m) of the
        force ``A_i t_i`` and ``dstate_new`` of the committed state, from the law's
        ``step_derivative``. :class:`femrom.integrators.HarmonicBalance` carries it over the
        sampled period for an exact Jacobian. A velocity-dependent law also gets the local velocities
        ``xdot`` (3 s,) and their derivative ``dxdot`` (3 s, m) (keywords; default zero).
        """
        if not callable(getattr(self.law, "step_derivative", None)):
            return None
        return self._local_step_derivative

    def _local_step_derivative(self, x, state, dx, dstate, xdot=None, dxdot=None):
        s = self.n_pairs
        dx = np.asarray(dx, dtype=float)
        if self.velocity_dependent:
            rates = {"rate": self.rates(xdot),
                     "drate": None if dxdot is None else np.asarray(dxdot, dtype=float).reshape(s, 3, -1)}
        else:
            rates = {}
        dtraction, dz = self.law.step_derivative(self.gaps(x), self._state(state), dx.reshape(s, 3, -1), dstate,
                                                 **rates)
        return (self.areas[:, None, None] * dtraction).reshape(3 * s, -1), dz

    @property
    def local_step_force(self):
        r"""``(x0, x1, state) -> (g (3 s,), dg/dx1 (3 s, 3 s) csr)``, or ``None`` when the law has no step traction.

        The force of a whole step from local coordinates ``x0`` to ``x1``, ``g_i = A_i bar t_i``
        with the law's ``step_traction`` (:meth:`femrom.fem.DryFrictionLaw.step_traction`): its
        work ``g . (x1 - x0)`` is at least the change of :meth:`stored_energy` plus
        :meth:`dissipation` over the step. :meth:`local_step_force_and_blocks` gives the tangent
        as (s, 3, 3) blocks.
        """
        if not callable(getattr(self.law, "step_traction", None)):
            return None
        return self._local_step_force

    def _local_step_force(self, x0, x1, state=None):
        g, blocks = self.local_step_force_and_blocks(x0, x1, state)
        return g, sp.csr_matrix((blocks.ravel(), self._tangent_indices, self._tangent_indptr),
                                shape=(3 * self.n_pairs,) * 2)

    def local_step_force_and_blocks(self, x0, x1, state=None):
        """``(g (3 s,), A_i d bar t_i / d Delta_{i,1} (s, 3, 3))`` of the step from ``x0`` to ``x1`` (one law call)."""
        traction, D = self.law.step_traction(self.gaps(x0), self.gaps(x1), self._state(state), tangent=True)
        return (self.areas[:, None] * traction).ravel(), self.areas[:, None, None] * D

    def local_commit(self, x, xdot, state):
        return self.law.commit(self.gaps(x), self._state(state))

    def checkpoint(self, state):
        return self.law.checkpoint(state)

    def restore(self, data):
        return self.law.restore(data)

    def restricted(self, pairs, weights=None) -> "JointForce":
        r"""The joint on the pairs ``pairs`` only, each pair's area scaled by its weight.

        ``f_S(q; z_S) = sum_{i in S} w_i L_i^T A_i t_i(L_i q; z_i)``: the sampled force of
        energy-conserving sampling and weighting (ECSW). A weighted pair is the same
        interface element with the area ``w_i A_i``, so the sampled force keeps its
        structure: tractions from the law, dissipation and stored energy summed with the
        weighted areas. Its state is the original's rows ``z[pairs]``.

        Parameters
        ----------
        pairs : (k,) int array_like
            Distinct pair indices in ``[0, s)``.
        weights : (k,) array_like, optional
            ``w_i > 0`` (default 1).
        """
        pairs = np.asarray(pairs)
        if pairs.ndim != 1 or pairs.size == 0 or not np.issubdtype(pairs.dtype, np.integer):
            raise FemromValueError(f"pairs must be a non-empty 1-D integer array, got shape {pairs.shape}")
        if pairs.min() < 0 or pairs.max() >= self.n_pairs or np.unique(pairs).size != pairs.size:
            raise FemromValueError(f"pairs must be distinct indices in [0, {self.n_pairs})")
        w = np.ones(pairs.size) if weights is None else np.asarray(weights, dtype=float)
        if w.shape != pairs.shape or not np.all(np.isfinite(w) & (w > 0)):
            raise FemromValueError(f"weights must be ({pairs.size},) finite and > 0")
        tangents = self._given.get("first_tangents")
        if tangents is not None and tangents.ndim == 2:
            tangents = tangents[pairs]
        return JointForce(self.law, self.dofs_a[pairs], self.dofs_b[pairs], self._given["normals"][pairs],
                          w * self.areas[pairs], self.n_dofs, initial_gap=self.initial_gap[pairs],
                          first_tangents=tangents, name=self.name)

    # -- what the interface does ------------------------------------------------------
    def tractions(self, q: np.ndarray, state=None) -> np.ndarray:
        """(s, 3) tractions ``(t_t1, t_t2, t_n)`` [Pa] at ``q`` with ``state`` frozen."""
        return self.law.traction(self.gaps(self.localize(q)), self._state(state))

    def dissipation(self, q: np.ndarray, state=None) -> float:
        """Energy the sliders dissipate in the step from the committed ``state`` to ``commit(q, ., state)``:
        ``sum_i A_i D_i`` [J]."""
        return float(self.areas @ self.law.dissipation(self.gaps(self.localize(q)), self._state(state)))

    def damping_power(self, q: np.ndarray, v: np.ndarray, state=None) -> float:
        """Power the law's rate term dissipates at ``(q, v)`` with ``state`` frozen, ``sum_i A_i P_i`` [W]
        (:meth:`femrom.fem.ClampedIwanLaw.damping_power`; zero for a law without one)."""
        power = getattr(self.law, "damping_power", None)
        if power is None or not self.velocity_dependent:
            return 0.0
        return float(self.areas @ power(self.gaps(self.localize(q)), self.rates(self.localize(v)), self._state(state)))

    def stored_energy(self, q: np.ndarray, state=None) -> float:
        """Elastic energy in the interface springs at ``q`` with the sliders at ``state`` [J]."""
        return float(self.areas @ self.law.stored_energy(self.gaps(self.localize(q)), self._state(state)))

    # -- storage ------------------------------------------------------------------------
    def parameters(self):
        return {"kind": self.kind, "law": self.law.parameters(), "dofs_a": self.dofs_a, "dofs_b": self.dofs_b,
                "areas": self.areas, "n_dofs": self.n_dofs, "initial_gap": self.initial_gap, "name": self.name,
                **self._given}

    @classmethod
    def from_parameters(cls, parameters):
        tangents = parameters.get("first_tangents")
        return cls(interface_law_from_parameters(parameters["law"]), np.asarray(parameters["dofs_a"]),
                   np.asarray(parameters["dofs_b"]), np.asarray(parameters["normals"]),
                   np.asarray(parameters["areas"]), int(parameters["n_dofs"]),
                   initial_gap=np.asarray(parameters["initial_gap"]),
                   first_tangents=None if tangents is None else np.asarray(tangents),
                   name=str(parameters.get("name", cls.kind)))
