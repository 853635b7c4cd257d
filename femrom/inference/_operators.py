r"""A reduced second-order model as a list of terms, and its intrusive Galerkin projection.

.. math::

    \hat M \ddot{\hat q} + \hat C \dot{\hat q} + \hat K \hat q
        + \hat f(\hat q, \dot{\hat q}; s) = \hat B u(t) + \hat f_0, \qquad y = \hat E \hat q ,

each term an object of :mod:`._terms` (mass, damping, stiffness, inputs,
known or learned forces, constant loads, the output map). Whether the mass is
the identity depends on the basis: ``V^T M V = I`` holds for a
mass-orthonormal basis only (``../shared/DESIGN.md``, "The reduced mass").
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference._terms import LinearTerm, ReducedTerm, registered_terms
from femrom.scene import SecondOrderSystem


class ReducedForces:
    """Several nonlinear terms acting together: ``f^ = sum_j f^_j(q, v; s_j)``, state ``(s_1, ...)``."""

    def __init__(self, terms):
        self.terms = tuple(terms)

    @property
    def conservative(self) -> bool:
        return all(t.conservative for t in self.terms)

    @property
    def velocity_dependent(self) -> bool:
        return any(t.velocity_dependent for t in self.terms)

    @property
    def stateful(self) -> bool:
        return any(t.stateful for t in self.terms)

    def initial_state(self):
        return tuple(t.initial_state() for t in self.terms)

    def force(self, q, v=None, state=None):
        states = state if state is not None else (None,) * len(self.terms)
        return sum(t.lhs(q, v, state=s) for t, s in zip(self.terms, states))

    def tangent(self, q, v=None, state=None):
        states = state if state is not None else (None,) * len(self.terms)
        parts = [t.tangent(q, v, s) for t, s in zip(self.terms, states)]
        return tuple(_sum([p[k] for p in parts]) for k in range(2))

    def potential(self, q) -> float:
        return float(sum(t.potential(q) for t in self.terms))

    def commit(self, q, v, state):
        states = state if state is not None else self.initial_state()
        return tuple(t.commit(q, v, s) for t, s in zip(self.terms, states))


def _sum(matrices):
    present = [m for m in matrices if m is not None]
    return None if not present else sum(present[1:], present[0])


@dataclass(frozen=True, eq=False)
class ReducedOperators:
    r"""The terms of a reduced second-order model in r coordinates.

    Attributes
    ----------
    terms : tuple of ReducedTerm
        At most one of each name, kept in equation order; no mass term means
        ``M^ = I``.
    metadata : dict
        How the terms were obtained (``method``, learner settings, error split).

    The usual operators are views of the terms: :attr:`stiffness`,
    :attr:`damping`, :attr:`mass` (``None`` for the identity),
    :attr:`input_matrix`, :attr:`output_matrix`, :attr:`nonlinear` (the
    nonlinear terms together) and :attr:`load`.
    """

    terms: tuple = ()
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        terms = tuple(sorted(self.terms, key=lambda t: t.order))
        names = [t.name for t in terms]
        if len(set(names)) != len(names):
            raise FemromValueError(f"a reduced model holds at most one term of each name, got {names}")
        if self.term("stiffness", terms) is None:
            raise FemromValueError("a reduced second-order model needs a stiffness term")
        object.__setattr__(self, "terms", terms)
        r = self.r
        for t in terms:
            if isinstance(t, LinearTerm):
                rows, cols = t.matrix.shape
                if t.role == "output":
                    if cols != r:
                        raise FemromValueError(f"{t.name} has {cols} columns, expected r = {r}")
                elif rows != r or (t.variable in ("q", "v", "a") and cols != r):
                    raise FemromValueError(f"{t.name} has shape {t.matrix.shape}, expected ({r}, "
                                     f"{r if t.variable in ('q', 'v', 'a') else 'm'})")

    @classmethod
    def from_matrices(cls, stiffness, *, mass=None, damping=None, input_matrix=None, output_matrix=None,
                      nonlinear=None, load=None, metadata=None) -> "ReducedOperators":
        """The model of the given operators (``mass=None``: the identity; ``nonlinear``: a force term)."""
        known = registered_terms()
        parts = [("stiffness", stiffness), ("mass", mass), ("damping", damping), ("input", input_matrix),
                 ("output", output_matrix)]
        terms = [known[name](np.asarray(value, dtype=float)) for name, value in parts if value is not None]
        if load is not None:
            terms.append(_load_term(known)(np.asarray(load, dtype=float)))
        if nonlinear is not None:
            terms.append(nonlinear)
        return cls(tuple(terms), dict(metadata or {}))

    # -- the terms ---------------------------------------------------------------------
    def term(self, name: str, terms=None) -> ReducedTerm | None:
        """The term called ``name`` (``None`` if absent)."""
        return next((t for t in (self.terms if terms is None else terms) if t.name == name), None)

    def with_terms(self, *terms: ReducedTerm) -> "ReducedOperators":
        """The model with these terms added, replacing terms of the same names."""
        names = {t.name for t in terms}
        return ReducedOperators(tuple(t for t in self.terms if t.name not in names) + terms, dict(self.metadata))

    def without(self, *names: str) -> "ReducedOperators":
        """The model without the terms called ``names``."""
        return ReducedOperators(tuple(t for t in self.terms if t.name not in names), dict(self.metadata))

    def _linear(self, variable: str):
        matrices = [t.sign * t.matrix for t in self.terms
                    if isinstance(t, LinearTerm) and t.role == "balance" and t.variable == variable]
        return _sum(matrices)

    # -- views ---------------------------------------------------------------------------
    @property
    def r(self) -> int:
        return self.term("stiffness").matrix.shape[0]

    @functools.cached_property
    def system(self):
        """The model as a :class:`~femrom.scene.SecondOrderSystem` with dense (r, r) operators
        (the identity mass when none is held; the nonlinear terms as its force): what every
        time scheme steps."""
        E = self.output_matrix
        names = tuple(self.metadata.get("output_names", ()))
        return SecondOrderSystem(mass=self.mass_matrix, stiffness=self.stiffness, damping=self.damping,
                                 input_matrix=self.input_matrix, output_matrix=E, nonlinear=self.nonlinear,
                                 load=self.load, output_names=names if E is not None and len(names) == E.shape[0] else (),
                                 metadata=dict(self.metadata))

    @property
    def stiffness(self) -> np.ndarray:
        """(r, r) ndarray ``K^`` (all linear terms in ``q``)."""
        return self._linear("q")

    @property
    def damping(self) -> np.ndarray | None:
        """(r, r) ndarray ``C^`` (all linear terms in ``q'``), or ``None``."""
        return self._linear("v")

    @property
    def mass(self) -> np.ndarray | None:
        """(r, r) ndarray ``M^``, or ``None`` for the identity (mass-orthonormal basis)."""
        return self._linear("a")

    @property
    def mass_matrix(self) -> np.ndarray:
        """(r, r) ndarray ``M^`` (the identity when :attr:`mass` is ``None``)."""
        M = self.mass
        return np.eye(self.r) if M is None else M

    @property
    def input_matrix(self) -> np.ndarray | None:
        """(r, m) ndarray ``B^`` of ``+ B^ u`` on the right side, or ``None``."""
        B = self._linear("u")
        return None if B is None else -B

    @property
    def load(self) -> np.ndarray | None:
        """(r,) ndarray ``f^_0`` (constant forcing on the right side), or ``None``."""
        f = self._linear("1")
        return None if f is None else -f[:, 0]

    @property
    def output_matrix(self) -> np.ndarray | None:
        """(p, r) ndarray ``E^``, or ``None``."""
        E = self.term("output")
        return None if E is None else E.matrix

    @property
    def nonlinear(self):
        """The nonlinear terms as one force (``force``, ``tangent``, state), or ``None``."""
        forces = [t for t in self.terms if not isinstance(t, LinearTerm) and t.role == "balance"]
        if not forces:
            return None
        return forces[0] if len(forces) == 1 else ReducedForces(forces)

    @property
    def n_inputs(self) -> int:
        B = self.input_matrix
        return 0 if B is None else B.shape[1]

    @property
    def is_linear(self) -> bool:
        return self.nonlinear is None

    @property
    def stateful(self) -> bool:
        """Whether a term carries a state from step to step (e.g. learned sliders)."""
        return any(t.stateful for t in self.terms)

    def eigenvalues(self) -> dict:
        """Eigenvalues of the symmetric parts of ``K^`` and ``C^`` (ascending)."""
        out = {"stiffness": np.linalg.eigvalsh(0.5 * (self.stiffness + self.stiffness.T))}
        if self.damping is not None:
            out["damping"] = np.linalg.eigvalsh(0.5 * (self.damping + self.damping.T))
        return out

    def frequencies(self) -> np.ndarray:
        """(r,) ndarray: ``sqrt`` of the generalized eigenvalues of ``(K^, M^)`` (rad/s);
        complex-valued entries (non-symmetric or indefinite ``K^``) as ``nan``."""
        import scipy.linalg as sl

        w2 = sl.eigvals(self.stiffness, self.mass_matrix)
        w2 = np.sort_complex(w2)
        out = np.full(w2.shape, np.nan)
        real = (np.abs(w2.imag) <= 1e-10 * np.abs(w2)) & (w2.real >= 0)
        out[real] = np.sqrt(w2.real[real])
        return out

    def energy(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(k,) ``v^T M^ v / 2 + sum of the terms' potentials`` for (r, k) columns."""
        M = self.mass
        Mv = v if M is None else M @ v
        e = 0.5 * np.sum(v * Mv, axis=0)
        for t in self.terms:
            if t.role != "balance" or isinstance(t, LinearTerm) and t.variable in ("a", "v", "u"):
                continue
            if isinstance(t, LinearTerm):
                e = e + t.potential(q)
            elif t.conservative:
                e = e + np.array([t.potential(q[:, k]) for k in range(q.shape[1])])
        return e


def _load_term(known):
    for cls in known.values():
        if getattr(cls, "variable", None) == "1" and cls.learnable:
            return cls
    raise FemromValueError("no registered term holds a constant load (variable '1'): register one")


def galerkin(system, basis: np.ndarray, *, reference: np.ndarray | None = None, reference_state=None,
             mass_orthonormal: bool = False, damping_ratios=None, rtol: float = 1e-8) -> ReducedOperators:
    r"""The intrusive Galerkin model of a :class:`~femrom.scene.SecondOrderSystem` on ``q = q_0 + V q^``.

    Every registered term contributes its projection (``V^T M V``, ``V^T C V``,
    ``V^T K V``, ``V^T B``, ``E V``, ``V^T f(q_0 + V q^)``, ``V^T (f_0 - K q_0)``, ...);
    every effect of the system must be covered by some term, else this raises. The
    model steps as :attr:`ReducedOperators.system`, an instance of the same model type
    as ``system``; at ``q^ = 0`` in the force state at the reference it is in
    equilibrium when ``q_0`` is one of the full model.

    Parameters
    ----------
    system : SecondOrderSystem
    basis : (n, r) ndarray
        ``V``, full column rank; with ``mass_orthonormal`` it must satisfy ``V^T M V = I``.
    reference : (n,) ndarray, optional
        ``q_0`` (a preloaded equilibrium; default zero): the model is of
        :meth:`~femrom.scene.SecondOrderSystem.about`, its outputs measured from ``q_0``.
    reference_state : optional
        The nonlinear force's committed state at ``q_0``: its tangent at ``q^ = 0`` enters
        ``omega_i^2`` for ``damping_ratios``.
    mass_orthonormal : bool
        Check ``||V^T M V - I||_F <= rtol sqrt(r)`` and keep ``M^ = I`` (no mass
        term), else raise.
    damping_ratios : float or (r,) array_like, optional
        Modal damping ``C^ = diag(2 zeta_i omega_i)`` in place of ``V^T C V``, with
        ``omega_i^2`` the diagonal of ``V^T K V`` plus the force's tangent (needs
        ``V^T M V = I``, checked to 1e-8): for a basis of modes of the linearisation.

    Returns
    -------
    ReducedOperators
    """
    V = np.asarray(basis, dtype=float)
    if V.ndim != 2 or V.shape[0] != system.n_dofs or V.shape[1] < 1:
        raise FemromValueError(f"basis has shape {V.shape}, expected ({system.n_dofs}, r)")
    if not np.all(np.isfinite(V)):
        raise FemromValueError("basis has non-finite entries")
    r = V.shape[1]
    about = system if reference is None else system.about(reference)
    terms, covered = [], set()
    for cls in registered_terms().values():
        term = cls.galerkin(about, V)
        if term is None:
            continue
        covered.add(cls.effect)
        if cls.name == "mass" and mass_orthonormal:
            defect = np.linalg.norm(term.matrix - np.eye(r))
            if defect > rtol * np.sqrt(r):
                raise FemromValueError(f"basis is not mass-orthonormal: ||V^T M V - I||_F = {defect:.3e}")
            continue
        terms.append(term)
    missing = sorted(set(about.effects) - covered)
    if missing:
        raise FemromValueError(f"no registered reduced term projects the system's {', '.join(missing)}: "
                               "write one (femrom.inference.register_term)")
    metadata = {"method": "galerkin", "mass_orthonormal": bool(mass_orthonormal),
                "about_reference": reference is not None}
    if system.output_names:
        metadata["output_names"] = list(system.output_names)
    ops = ReducedOperators(tuple(terms), metadata)
    if damping_ratios is not None:
        ops = _modal_damping(ops, damping_ratios, reference_state)
    return ops


def _modal_damping(ops: ReducedOperators, damping_ratios, reference_state) -> ReducedOperators:
    """``C^ = diag(2 zeta_i omega_i)``, ``omega_i^2`` the diagonal of ``K^`` plus the force's tangent at rest."""
    r = ops.r
    if np.max(np.abs(ops.mass_matrix - np.eye(r))) > 1e-8:
        raise FemromValueError("damping_ratios needs a mass-normalised basis (V^T M V = I)")
    zeta = np.broadcast_to(np.asarray(damping_ratios, dtype=float), (r,))
    if not np.all(np.isfinite(zeta)) or np.any(zeta < 0):
        raise FemromValueError(f"damping_ratios must be finite and >= 0, got {damping_ratios!r}")
    stiffness = ops.stiffness.copy()
    force = ops.nonlinear
    if force is not None:
        state = force.initial_state() if reference_state is None else reference_state
        D = force.tangent(np.zeros(r), np.zeros(r), state)[0]
        if D is not None:
            stiffness = stiffness + np.asarray(D)
    omega = np.sqrt(np.maximum(np.diag(stiffness), 0.0))
    damping = registered_terms()["damping"](np.diag(2.0 * zeta * omega))
    return ops.with_terms(damping)
