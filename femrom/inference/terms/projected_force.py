"""``f^(q, q'; s) = V^T f(V q, V q'; s)``: a known nonlinear force, projected."""

from __future__ import annotations

import numpy as np

from femrom._errors import FemromValueError
from femrom.fem import TransformedForce, dense_projection, force_from_parameters, transform_force
from femrom.inference._terms import ReducedTerm, register_term


@register_term
class ProjectedNonlinearForce(ReducedTerm):
    r"""``f^(q^, v^; s) = V^T f(q_0 + V q^, V v^; s)`` with tangent ``V^T (df/dq) V``.

    The projection of a known full-order force (:class:`femrom.fem.NonlinearForce`), about a
    reference ``q_0`` when the force is a model's about one
    (:meth:`femrom.scene.SecondOrderSystem.about`). It is the force seen through the new
    coordinates (:func:`femrom.fem.transform_force`: the same law on the local map ``L V``),
    evaluated with that map as a dense (s_loc, r) array ``W``: a spring layer or a joint costs
    ``O(s_loc r)`` per call, not ``O(n r)``, and a joint gives force and tangent from one law
    evaluation (:func:`femrom.fem.dense_projection`). A stateful force carries its state on
    its own local coordinates (frozen during a reduced Newton step, committed after it); a
    joint's ``dissipation``, ``stored_energy`` and ``tractions`` are offered on ``q^``.

    As a learning target (:meth:`target`) the force is evaluated along each
    training trajectory in time order from its initial state, committing the
    state after every column: the target of a hysteretic force is the force
    the reduced trajectory would feel.

    Parameters
    ----------
    force : NonlinearForce
    basis : (n, r) ndarray

    Attributes
    ----------
    transformed : NonlinearForce or None
        The force on the reduced coordinates (``None`` for a force without a local map,
        evaluated as ``V^T f(V q^)``).
    """

    name = "projected_force"
    effect = "nonlinear"
    structure = "known"
    order = 30

    def __init__(self, force, basis: np.ndarray):
        self.force_model = force
        self.basis = np.asarray(basis, dtype=float)
        # a projected force projected again (a reduced model reduced further) is the original seen through
        # one map ``L V_1 V_2``: the same law on fewer coordinates, its compiled kernels included
        inner = force.transformed if isinstance(force, ProjectedNonlinearForce) else force
        if getattr(inner, "local_map", None) is None:
            self.transformed, self._local = None, None
        else:
            self.transformed = transform_force(inner, self.basis)
            self._local = np.ascontiguousarray(self.transformed.local_map.toarray())

    @classmethod
    def galerkin(cls, system, basis):
        return None if system.nonlinear is None else cls(system.nonlinear, basis)

    # -- properties of the force ------------------------------------------------------
    @property
    def conservative(self) -> bool:
        return bool(getattr(self.force_model, "conservative", False))

    @property
    def velocity_dependent(self) -> bool:
        return bool(getattr(self.force_model, "velocity_dependent", False))

    @property
    def stateful(self) -> bool:
        return bool(getattr(self.force_model, "stateful", False))

    @property
    def r(self) -> int:
        return self.basis.shape[1]

    def initial_state(self):
        return self.force_model.initial_state()

    # -- evaluations -------------------------------------------------------------------
    def force(self, q, v=None, state=None) -> np.ndarray:
        """(r,) ndarray ``V^T f(q_0 + V q, V v; state)``."""
        W = self._local
        if W is None:
            V = self.basis
            return V.T @ self.force_model.force(V @ q, None if v is None else V @ v, state)
        return W.T @ self.transformed.local_force(W @ q, None if v is None else W @ v, state)

    def lhs(self, q, v=None, a=None, u=None, state=None):
        return self.force(q, v, state)

    def tangent(self, q, v=None, state=None):
        """``(V^T df/dq V, V^T df/dv V)`` as (r, r) ndarrays (``None`` where absent)."""
        W = self._local
        if W is None:
            V = self.basis
            dq, dv = self.force_model.tangent(V @ q, None if v is None else V @ v, state)
            return tuple(None if D is None else V.T @ np.asarray(D @ V) for D in (dq, dv))
        return dense_projection(W, self.transformed, q, v, state, tangent_only=True)

    def dense_force_and_tangent(self, q, v=None, state=None):
        """``(f^, df^/dq^, df^/dv^)`` from one evaluation of the law (what a reduced Newton step asks)."""
        W = self._local
        if W is None:
            return (self.force(q, v, state), *self.tangent(q, v, state))
        return dense_projection(W, self.transformed, q, v, state)

    @property
    def step_force(self):
        """``(q0, q1, state) -> (f^ (r,), df^/dq1 (r, r))`` as dense arrays: the projected force's step force
        (:attr:`femrom.fem.NonlinearForce.step_force`), or ``None`` when it has none."""
        W = self._local
        if W is None:
            inner = getattr(self.force_model, "step_force", None)
            if not callable(inner):
                return None
            V = self.basis

            def step_force(q0, q1, state=None):
                f, D = inner(V @ q0, V @ q1, state)
                return V.T @ f, V.T @ np.asarray(D @ V)

            return step_force
        if not callable(self.transformed.local_step_force):
            return None
        return lambda q0, q1, state=None: self.transformed.dense_step_force(W, q0, q1, state)

    def compiled_joint(self):
        """The projected joint as compiled step kernels take it (:meth:`femrom.fem.TransformedForce.compiled_joint`),
        or ``None`` (no joint, no compiled law, or the compiled laws switched off)."""
        offer = getattr(self.transformed, "compiled_joint", None)
        return offer() if callable(offer) else None

    def potential(self, q) -> float:
        if not self.conservative:
            return 0.0
        W = self._local
        if W is None:
            return self.force_model.potential(self.basis @ q)
        return float(self.transformed.local_potential(W @ q))

    def commit(self, q, v, state):
        W = self._local
        if W is None:
            return self.force_model.commit(self.basis @ q, None if v is None else self.basis @ v, state)
        if not self.stateful:
            return state
        return self.transformed.local_commit(W @ q, None if v is None else W @ v, state)

    def checkpoint(self, state):
        return self.force_model.checkpoint(state)

    def restore(self, data):
        return self.force_model.restore(data)

    def __getattr__(self, attribute):
        # a joint's energy bookkeeping on the reduced coordinates (only reached when lookup fails)
        if attribute in TransformedForce.delegated and "transformed" in self.__dict__ and self.transformed is not None:
            return getattr(self.transformed, attribute)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {attribute!r}")

    def forces(self, Q: np.ndarray, Vel: np.ndarray | None = None, starts=(0,)) -> np.ndarray:
        """(r, K) ndarray: the force at every column of ``Q``, ``Vel`` (r, K).

        A stateful force is evaluated in column order, its state starting
        afresh at each index of ``starts`` (trajectory beginnings) and
        committed after every later column: column ``k`` sees the state
        committed at column ``k - 1``, as a step of the integrators does. The
        columns must be consecutive steps (a state committed at skipped steps
        cannot be recovered from the kept ones).
        """
        K = Q.shape[1]
        W = self._local
        if not self.stateful and W is not None and getattr(getattr(self.transformed, "force_model", None), "columns",
                                                            False):
            # a potential's local force takes columns; the reference's local offset shifts every one
            X, offset = W @ Q, self.transformed.local_offset
            X = X if offset is None else X + offset[:, None]
            return W.T @ self.transformed.force_model.local_force(X, None if Vel is None else W @ Vel, None)
        out = np.empty((self.r, K))
        starts = set(int(s) for s in starts) | {0}
        state = None
        for k in range(K):
            v = None if Vel is None else Vel[:, k]
            if k in starts:
                state = self.initial_state()
            out[:, k] = self.force(Q[:, k], v, state)
            if self.stateful and k not in starts:
                # as the integrators do: the state frozen during the step to column k is the
                # one committed after the step before it (the initial state is not committed)
                state = self.commit(Q[:, k], v, state)
        return out

    def target(self, data) -> np.ndarray:
        if self.stateful and data.diagnostics.get("trimmed_columns", 0):
            raise FemromValueError(f"the stateful force {self.force_model.name!r} is evaluated along each trajectory "
                             f"from its initial state, but these data were trimmed by "
                             f"{data.diagnostics['trimmed_columns']} columns at the start; pass untrimmed data "
                             "or the forces themselves as nonlinear_forces")
        return self.forces(data.states, data.velocities, data.starts)

    # -- storage -----------------------------------------------------------------------
    def save(self, group) -> None:
        """The force's parameters when it has them (rebuilt on load), else its class only.

        The basis is the model's (saved with it): ``load`` needs it.
        """
        parameters = getattr(self.force_model, "parameters", lambda: None)()
        group.attrs["force_class"] = f"{type(self.force_model).__module__}.{type(self.force_model).__qualname__}"
        if parameters is not None:
            _write(group.create_group("force"), parameters)

    @classmethod
    def load(cls, group, *, basis=None, nonlinear=None, **context):
        stored = str(group.attrs["force_class"])
        if basis is None:
            raise FemromValueError("a projected force is evaluated through the basis: the file holds none")
        if nonlinear is not None:
            given = f"{type(nonlinear).__module__}.{type(nonlinear).__qualname__}"
            if given != stored:
                raise FemromValueError(f"nonlinear force {given} does not match the saved {stored}")
            return cls(nonlinear, basis)
        if "force" not in group:
            raise FemromValueError(f"the model's projected force ({stored}) has no stored parameters: "
                             "pass nonlinear=... to load")
        return cls(force_from_parameters(_read(group["force"])), basis)

    def describe(self) -> dict:
        return {"term": self.name, "structure": self.structure, "force": type(self.force_model).__name__,
                "conservative": self.conservative, "stateful": self.stateful}


def _write(group, parameters: dict) -> None:
    for key, value in parameters.items():
        if isinstance(value, dict):
            _write(group.create_group(key), value)
        elif isinstance(value, (list, tuple)) and value and isinstance(value[0], dict):
            sub = group.create_group(key)
            sub.attrs["sequence"] = len(value)
            for i, item in enumerate(value):
                _write(sub.create_group(str(i)), item)
        elif isinstance(value, str):
            group.attrs[key] = value
        else:
            group.create_dataset(key, data=np.asarray(value))


def _read(group) -> dict:
    out = {key: value for key, value in group.attrs.items() if key != "sequence"}
    for key, item in group.items():
        if hasattr(item, "keys"):
            if "sequence" in item.attrs:
                out[key] = [_read(item[str(i)]) for i in range(int(item.attrs["sequence"]))]
            else:
                out[key] = _read(item)
        else:
            value = item[()]
            out[key] = value.item() if np.ndim(value) == 0 else value
    return {k: (str(v) if isinstance(v, bytes) else v) for k, v in out.items()}
