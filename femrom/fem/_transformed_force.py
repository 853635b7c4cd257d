r"""A nonlinear force re-expressed on new coordinates ``q = T q^``: the local map becomes ``L T``.

A force ``f(q, v; s) = L^T g(L q, L v; s)`` seen through a linear change of
coordinates ``q = T q^`` (``T`` (n, k): a Craig-Bampton transformation, any
reduced basis) is

.. math::

    f^(q^, v^; s) = T^\top f(T q^, T v^; s) = (L T)^\top g\big((L T) q^, (L T) \dot q^; s\big),

the same local law ``g`` on the same local coordinates with the local map
``L T`` (s, k). About a reference state ``q = q_0 + T q^`` (a preloaded
equilibrium) the law reads ``g(L q_0 + (L T) q^, ...)``: the offset ``L q_0`` is
added to the local displacements, so ``q^ = 0`` is the reference. The state, its commit and its checkpoint are the original
force's, unchanged: a joint keeps its sliders. Only the rows of ``T`` at the
dofs ``L`` touches matter, so ``L T`` is built from those rows alone; where
``T`` keeps those dofs as coordinates of their own (the boundary dofs of
Craig-Bampton, ``T[b] = [I 0]``) ``L T`` is ``L``'s columns moved, exactly
sparse.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from femrom._errors import FemromValueError
from femrom.fem._law_kernels import CompiledJoint, compiled_kernels
from femrom.fem._nonlinear import NonlinearForce, force_from_parameters, register_force

#: Up to this many new coordinates the tangent ``(L T)^T D (L T)`` is formed with a dense ``L T``:
#: a reduced basis makes ``L T`` dense, and sparse-times-sparse products into a small dense
#: result cost more in bookkeeping than in arithmetic (3x on the jointed beam's 10-mode model).
DENSE_COORDINATES = 200

#: Methods of the original force taking ``(q, state)`` in its own dofs that the transformed force
#: offers on the new coordinates when the original has them (a joint's energy bookkeeping).
DELEGATED = ("dissipation", "stored_energy", "tractions")


@register_force
class TransformedForce(NonlinearForce):
    r"""``T^T f(T q^, T v^; s)`` of a force ``f`` with a local map (see the module docstring).

    Parameters
    ----------
    force : NonlinearForce
        The original force on ``n`` dofs (a :class:`~femrom.fem.ForceSum` is
        transformed force by force by :func:`transform_force`).
    transformation : (n, k) ndarray or sparse
        ``T``; only its rows at ``force.dofs`` are kept.
    name : str, optional
        Default: the original force's name.
    reference : (n,) ndarray, optional
        ``q_0``: the coordinates are ``q = q_0 + T q^`` (default ``q_0 = 0``).

    Attributes
    ----------
    force_model : NonlinearForce
        The original force.
    touched_dofs : (t,) int ndarray
        The original dofs ``L`` touches (its nonzero columns).
    touched_rows : (t, k) csr
        ``T[touched_dofs]``.

    The methods ``dissipation``, ``stored_energy`` and ``tractions`` of the
    original (a :class:`~femrom.fem.JointForce`) are available with ``q^``
    in place of ``q`` when the original has them.
    """

    kind = "transformed"
    #: The original's methods of ``(q, state)`` offered on the new coordinates.
    delegated = DELEGATED

    def __init__(self, force: NonlinearForce, transformation, *, name: str | None = None, reference=None):
        if not isinstance(force, NonlinearForce):
            raise FemromValueError(f"force must be a NonlinearForce, got {type(force).__name__}")
        T = transformation
        if T.ndim != 2 or T.shape[0] != force.n_dofs:
            raise FemromValueError(f"transformation must be (n, k) with n = {force.n_dofs} (the force's dofs), "
                             f"got shape {T.shape}")
        L = force.local_map.tocsr()
        touched = np.unique(L.indices[L.data != 0])
        rows = sp.csr_matrix(T[touched] if not sp.issparse(T) else sp.csr_matrix(T)[touched], dtype=float)
        local_map = (L[:, touched] @ rows).tocsr()
        local_map.eliminate_zeros()
        super().__init__(T.shape[1], local_map=local_map, name=name or force.name)
        self.force_model = force
        self.original_dofs = force.n_dofs
        touched.setflags(write=False)
        self.touched_dofs, self.touched_rows = touched, rows
        if reference is None:
            self.reference, self.local_offset = None, None
        else:
            q0 = np.asarray(reference, dtype=float).reshape(-1)
            if q0.shape != (force.n_dofs,) or not np.all(np.isfinite(q0)):
                raise FemromValueError(f"reference must be a finite ({force.n_dofs},) vector, got shape {q0.shape}")
            self.reference = np.zeros(force.n_dofs)
            self.reference[touched] = q0[touched]   # only what L reads is kept
            self.local_offset = np.asarray(L @ q0).reshape(-1)

    # -- the law is the original's ------------------------------------------------------
    @property
    def conservative(self) -> bool:  # type: ignore[override]
        return self.force_model.conservative

    @property
    def velocity_dependent(self) -> bool:  # type: ignore[override]
        return self.force_model.velocity_dependent

    @property
    def stateful(self) -> bool:  # type: ignore[override]
        return self.force_model.stateful

    def _shifted(self, x):
        return x if self.local_offset is None else x + self.local_offset

    def local_force(self, x, xdot, state):
        return self.force_model.local_force(self._shifted(x), xdot, state)

    def local_tangent(self, x, xdot, state):
        return self.force_model.local_tangent(self._shifted(x), xdot, state)

    def local_potential(self, x):
        return self.force_model.local_potential(self._shifted(x))

    def initial_state(self):
        return self.force_model.initial_state()

    def local_commit(self, x, xdot, state):
        return self.force_model.local_commit(self._shifted(x), xdot, state)

    def checkpoint(self, state):
        return self.force_model.checkpoint(state)

    @property
    def local_step_derivative(self):
        """The original's forward derivative of one return-map step at the shifted local coordinates
        (:meth:`femrom.fem.JointForce.local_step_derivative`), or ``None`` when it has none."""
        inner = getattr(self.force_model, "local_step_derivative", None)
        if not callable(inner):
            return None
        if self.local_offset is None:
            return inner
        return lambda x, state, dx, dstate, **rates: inner(self._shifted(x), state, dx, dstate, **rates)

    @property
    def step_derivative_rates(self) -> bool:
        """Whether :attr:`local_step_derivative` also takes the local velocities' derivative (the original's)."""
        return bool(getattr(self.force_model, "step_derivative_rates", False))

    @property
    def local_step_force(self):
        """The original's step force (:attr:`femrom.fem.NonlinearForce.local_step_force`) at the shifted local
        coordinates, or ``None`` when it has none."""
        inner = getattr(self.force_model, "local_step_force", None)
        if not callable(inner):
            return None
        if self.local_offset is None:
            return inner
        return lambda x0, x1, state: inner(self._shifted(x0), self._shifted(x1), state)

    def dense_step_force(self, W: np.ndarray, q0_hat, q1_hat, state=None):
        r"""``(W^T g, W^T (dg/dx1) W)`` as dense arrays of the step force at ``x = W q^`` (``W``: (s, k), ``L T``).

        A joint's 3 x 3 blocks are multiplied pair by pair, as :func:`dense_projection` does."""
        x0, x1 = self._shifted(W @ q0_hat), self._shifted(W @ q1_hat)
        blocks = getattr(self.force_model, "local_step_force_and_blocks", None)
        if callable(blocks):
            g, D = blocks(x0, x1, state)
            s = D.shape[0]
            return W.T @ g, W.T @ np.matmul(D, W.reshape(s, 3, -1)).reshape(3 * s, -1)
        g, D = self.force_model.local_step_force(x0, x1, state)
        D = sp.diags(D) if np.ndim(D) == 1 and not sp.issparse(D) else D
        return W.T @ g, W.T @ np.asarray(D @ W)

    def restore(self, data):
        return self.force_model.restore(data)

    def _global_matrix(self, D):
        if D is None or self.n_dofs > DENSE_COORDINATES:
            return super()._global_matrix(D)
        if self.__dict__.get("_dense_map") is None:
            self._dense_map = self.local_map.toarray()
        local = sp.diags(D) if np.ndim(D) == 1 and not sp.issparse(D) else sp.csr_matrix(D)
        L = self._dense_map
        return sp.csr_matrix(L.T @ np.asarray(local @ L))

    def with_force(self, force: NonlinearForce) -> "TransformedForce":
        """Another force on the original dofs seen through the same ``q = q_0 + T q^``.

        ``force`` must read only dofs this force reads (e.g. a joint restricted to some of its
        pairs, :meth:`femrom.fem.JointForce.restricted`): only those rows of ``T`` are kept."""
        if not isinstance(force, NonlinearForce) or force.n_dofs != self.original_dofs:
            raise FemromValueError(f"force must be a NonlinearForce on the original {self.original_dofs} dofs")
        L = force.local_map.tocsr()
        if not np.all(np.isin(np.unique(L.indices[L.data != 0]), self.touched_dofs)):
            raise FemromValueError("force reads dofs outside the rows of T this transformed force kept")
        T = sp.lil_matrix((self.original_dofs, self.n_dofs))
        T[self.touched_dofs] = self.touched_rows
        return TransformedForce(force, T.tocsr(), name=force.name, reference=self.reference)

    def composed(self, transformation, *, reference=None) -> "TransformedForce":
        """This force's original seen through ``q^ = x_0 + T_2 q~`` as well: ``q = q_0 + T_1 x_0 + T_1 T_2 q~``
        (``transformation`` ``T_2`` (k, k2), ``reference`` ``x_0`` (k,), default 0), one :class:`TransformedForce`
        of the original (only the rows of ``T_1`` this force kept are formed)."""
        T2 = transformation
        if T2.ndim != 2 or T2.shape[0] != self.n_dofs:
            raise FemromValueError(f"transformation must be (k, k2) with k = {self.n_dofs} (the force's dofs), "
                                   f"got shape {T2.shape}")
        rows = self.touched_rows @ T2
        rows = rows.toarray() if sp.issparse(rows) else np.asarray(rows, dtype=float)
        T = sp.lil_matrix((self.original_dofs, T2.shape[1]))
        T[self.touched_dofs] = rows
        q0 = np.zeros(self.original_dofs) if self.reference is None else self.reference.copy()
        if reference is not None:
            x0 = np.asarray(reference, dtype=float).reshape(-1)
            if x0.shape != (self.n_dofs,) or not np.all(np.isfinite(x0)):
                raise FemromValueError(f"reference must be a finite ({self.n_dofs},) vector, got shape {x0.shape}")
            q0[self.touched_dofs] += np.asarray(self.touched_rows @ x0).reshape(-1)
        shifted = self.reference is not None or reference is not None
        return TransformedForce(self.force_model, T.tocsr(), name=self.name, reference=q0 if shifted else None)

    def local_force_and_blocks(self, x, state=None):
        """The original's force and 3 x 3 tangent blocks at ``x`` shifted to the reference (a joint's)."""
        return self.force_model.local_force_and_blocks(self._shifted(x), state)

    @property
    def has_blocks(self) -> bool:
        """Whether the law gives force and 3 x 3 tangent blocks from one evaluation (a joint)."""
        return hasattr(self.force_model, "local_force_and_blocks") and not self.force_model.velocity_dependent

    def dense_map(self) -> np.ndarray:
        """(s, k) ndarray ``L T``: the local map as a dense array (cached)."""
        if self.__dict__.get("_dense_map") is None:
            self._dense_map = self.local_map.toarray()
        return self._dense_map

    def dense_force_and_tangent(self, q_hat, v_hat=None, state=None):
        r"""``(f^ (k,), df^/dq^ (k, k) or None, df^/dv^ (k, k) or None)`` as dense arrays, one law evaluation.

        For the small systems a reduced basis gives (``k <= DENSE_COORDINATES``): the dense
        Newton of :mod:`femrom.integrators` asks for force and tangent together, so a joint's
        law runs once per iteration and the tangent ``(L T)^T D (L T)`` is a dense product over
        the pairs' 3 x 3 blocks, with no sparse matrix built (:func:`dense_projection`).
        """
        if self.n_dofs > DENSE_COORDINATES:
            raise FemromValueError(f"dense_force_and_tangent is for at most {DENSE_COORDINATES} coordinates, "
                             f"this force has {self.n_dofs}")
        return dense_projection(self.dense_map(), self, q_hat, v_hat, state)

    def compiled_joint(self):
        """A :class:`~femrom.fem.CompiledJoint` of this force for compiled step kernels, or ``None``.

        ``None`` unless the compiled law kernels are on (:func:`~femrom.fem.compiled_laws`), the
        original is a :class:`~femrom.fem.JointForce` whose law has them (``kernel_arguments``:
        ``iwan``, ``jenkins``, ``clamped_iwan``) and this force has at most
        :data:`DENSE_COORDINATES` coordinates. Asked once per run: the switch
        :func:`~femrom.fem.use_compiled_laws` is read again by whoever steps with it.
        """
        joint = self.force_model
        arguments = getattr(getattr(joint, "law", None), "kernel_arguments", None)
        if compiled_kernels() is None or not callable(arguments) or self.n_dofs > DENSE_COORDINATES \
                or not hasattr(joint, "initial_gap") or not self.has_blocks:
            return None
        given = arguments()
        if given is None:                        # the law has no kernel in this setting (clamped_iwan's closing)
            return None
        kind, stiffness, strength, normal_stiffness = given
        s = joint.areas.size
        gap_offset = np.zeros((s, 3))
        gap_offset[:, 2] = joint.initial_gap
        offset = np.zeros(3 * s) if self.local_offset is None else self.local_offset
        return CompiledJoint(kind=int(kind), dense_map=np.ascontiguousarray(self.dense_map(), dtype=float),
                             local_offset=np.ascontiguousarray(offset, dtype=float), gap_offset=gap_offset,
                             areas=np.ascontiguousarray(joint.areas, dtype=float),
                             stiffness=np.ascontiguousarray(stiffness, dtype=float),
                             strength=np.ascontiguousarray(strength, dtype=float),
                             normal_stiffness=float(normal_stiffness))

    # -- the original's own view ---------------------------------------------------------
    def embed(self, q_hat: np.ndarray) -> np.ndarray:
        """(n,) ndarray equal to ``q_0 + T q^`` on the dofs the original force reads (zero elsewhere):
        what the original's methods of ``q`` need, at ``O(t k)`` instead of ``O(n k)``."""
        q = np.zeros(self.original_dofs) if self.reference is None else self.reference.copy()
        q[self.touched_dofs] += self.touched_rows @ q_hat
        return q

    def __getattr__(self, attribute):
        # only reached when normal lookup fails: offer the original's (q, state) methods on q^
        if attribute in DELEGATED and "force_model" in self.__dict__:
            method = getattr(self.force_model, attribute)  # AttributeError when the original has none

            def on_new_coordinates(q_hat, state=None):
                return method(self.embed(q_hat), state)

            on_new_coordinates.__doc__ = method.__doc__
            return on_new_coordinates
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {attribute!r}")

    # -- storage ------------------------------------------------------------------------------
    def parameters(self):
        inner = self.force_model.parameters()
        if inner is None:
            return None
        R = self.touched_rows
        parameters = {"kind": self.kind, "force": inner, "name": self.name, "touched_dofs": self.touched_dofs,
                      "rows_data": R.data, "rows_indices": R.indices, "rows_indptr": R.indptr,
                      "n_coordinates": self.n_dofs}
        if self.reference is not None:
            parameters["reference"] = self.reference
        if getattr(self, "shift_only", False):
            parameters["shift_only"] = 1
        return parameters

    @classmethod
    def from_parameters(cls, parameters):
        force = force_from_parameters(parameters["force"])
        touched = np.asarray(parameters["touched_dofs"], dtype=np.int64)
        k = int(parameters["n_coordinates"])
        rows = sp.csr_matrix((parameters["rows_data"], parameters["rows_indices"], parameters["rows_indptr"]),
                             shape=(touched.size, k))
        T = sp.lil_matrix((force.n_dofs, k))
        T[touched] = rows
        loaded = cls(force, T.tocsr(), name=str(parameters["name"]), reference=parameters.get("reference"))
        if int(parameters.get("shift_only", 0)):
            loaded.shift_only = True
        return loaded


def dense_projection(W: np.ndarray, force, q_hat, v_hat=None, state=None, *, tangent_only: bool = False):
    r"""``(W^T g, W^T (dg/dx) W, W^T (dg/dxdot) W)`` of a force's local law at ``x = W q^``, as dense arrays.

    ``W`` (s, k) maps ``k`` coordinates to the force's ``s`` local ones (``L T``, ``L V``); ``force``
    has ``local_force`` and ``local_tangent`` (each tangent ``None``, an (s,) diagonal or an (s, s)
    matrix), or ``local_force_and_blocks`` and ``has_blocks`` (a joint: force and 3 x 3 tangent
    blocks per pair from one law evaluation, the product ``W^T D W`` formed block by block).
    ``tangent_only``: the two tangents alone (the law's force is not evaluated where it need not be).
    """
    x = W @ q_hat
    if getattr(force, "has_blocks", False):
        g, D = force.local_force_and_blocks(x, state)
        s = D.shape[0]
        WD = np.matmul(D, W.reshape(s, 3, -1)).reshape(3 * s, -1)
        return (W.T @ WD, None) if tangent_only else (W.T @ g, W.T @ WD, None)
    xdot = None if v_hat is None else W @ v_hat
    parts = []
    for D in force.local_tangent(x, xdot, state):
        if D is None:
            parts.append(None)
        elif np.ndim(D) == 1 and not sp.issparse(D):
            parts.append(W.T @ (D[:, None] * W))
        else:
            parts.append(W.T @ np.asarray(D @ W))
    if tangent_only:
        return tuple(parts)
    return (W.T @ force.local_force(x, xdot, state), *parts)


def transform_force(force: NonlinearForce | None, transformation, *, reference=None) -> NonlinearForce | None:
    """``None``, or ``force`` on the coordinates ``q = q_0 + T q^`` (``reference`` ``q_0``, default 0): a
    :class:`TransformedForce`, or a :class:`~femrom.fem.ForceSum` of them (each summand transformed on
    its own, with its own state).

    ``transformation=None`` keeps the coordinates and only shifts them to ``q_0``
    (``q = q_0 + x``: the force of a model about a reference state). A force already so
    shifted and then transformed is one :class:`TransformedForce` of the original
    (``q = q_0 + T q^``), not a chain of two; so is a transformed force transformed again
    (``q = q_0 + T_1 (x_0 + T_2 q^)``: one map ``T_1 T_2`` about ``q_0 + T_1 x_0``), which keeps
    what the original offers (a joint's compiled kernels, its blocks) to the twice-reduced model.
    """
    from femrom.fem._nonlinear import ForceSum, sum_of_forces

    if force is None:
        return None
    if isinstance(force, ForceSum):
        return sum_of_forces([transform_force(f, transformation, reference=reference) for f in force.forces])
    if transformation is None:
        transformation = sp.identity(force.n_dofs, format="csr")
        shifted = TransformedForce(force, transformation, reference=reference)
        shifted.shift_only = True
        return shifted
    if isinstance(force, TransformedForce) and getattr(force, "shift_only", False):
        if reference is not None:
            raise FemromValueError("a shifted force is transformed about its own reference: give no second one")
        return TransformedForce(force.force_model, transformation, name=force.name, reference=force.reference)
    if isinstance(force, TransformedForce):
        return force.composed(transformation, reference=reference)
    return TransformedForce(force, transformation, reference=reference)
