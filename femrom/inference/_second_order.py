r"""Second-order operator inference from the terms of a model.

Given reduced data (:class:`SecondOrderData`) and the model's terms, the
learners of :mod:`femrom.inference.learners` solve

.. math::

    \min_{X_j \in \mathcal S_j}\;
    \Big\| \underbrace{\hat M \ddot{\hat Q} + \textstyle\sum_{\text{known}} T_k(\text{data})}_{Y}
        + \sum_{\text{learned}} X_j D_j \Big\|_F^2 + \sum_j \lambda_j \|X_j\|_F^2 ,

one block ``X_j`` and data block ``D_j`` per learned term (``K^`` on ``Q^``,
``C^`` on ``Q^'``, ``B^`` on ``-U``, ...), the known terms (the mass, a
projected known force evaluated along each trajectory) on the target's side.
:class:`~femrom.inference.LagrangianOpInf` (Sharma & Kramer, Physica D 462,
2024) asks every term for its structure (``K^ = K^^T >= eps I``, ``C^ =
C^^T >= 0``), so the learned model has a positive energy that damping can only
decrease; :class:`~femrom.inference.SecondOrderOpInf` is the unconstrained
baseline. The output map solves ``min_E ||Y - E Q^||_F^2 + lambda_E ||E||_F^2``.

Which terms: the stiffness always, the input map when the data carry inputs,
the output map when they carry outputs; any other term only when the caller
names it (``terms=["damping"]``), or from a system's effects
(:meth:`for_system`). Without being told, a learner fits no damping.
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass
from typing import ClassVar

import numpy as np

from femrom._errors import FemromTypeError, FemromValueError
from femrom.inference._data import SecondOrderData, concatenate
from femrom.inference._learner import Learner, Regularization
from femrom.inference._operators import ReducedForces, ReducedOperators
from femrom.inference._problem import Block, GramProblem
from femrom.inference._sdp import CONIC_SOLVERS, ConicSolver
from femrom.inference._smoothing import Smoothing
from femrom.inference._structured_lstsq import FastSolver
from femrom.inference._terms import ReducedTerm, registered_terms, term_class

#: Block structure a Lagrangian learner gives each term structure.
_BLOCKS = {"spd": "psd", "psd": "psd", "symmetric": "symmetric", "free": "free"}


@dataclass(frozen=True)
class ErrorSplit:
    r"""The three error sources of Geng, Singh, Ju, Kramer & Wang (CMAME 427, 2024).

    Attributes
    ----------
    projection : float or None
        ``||Q - V Q^||_W / ||Q||_W`` of the training states (``None`` for
        data that came reduced).
    derivative : float or None
        ``||Q^''_fd - V^T W Q''|| / ||V^T W Q''||``: finite differences
        against the run's stored accelerations (``None`` without them, ``0``
        when the stored ones were used).
    velocity : float or None
        The same for the velocities.
    optimization : float
        ``||Y + sum_j X_j D_j||_F / ||Y||_F``: the relative residual the
        fitted operators leave.
    """

    projection: float | None
    derivative: float | None
    velocity: float | None
    optimization: float


def system_terms(system, basis: np.ndarray | None = None, *, known_forces: bool = True) -> list:
    """The terms of ``system``'s effects beyond the stiffness, mass, input and output: the learnable
    term classes (damping, a constant load, ...) and, with ``known_forces``, the known nonlinear
    forces projected on ``basis`` (which they need). Only which effects exist is read."""
    terms = []
    for effect in system.effects:
        for term in registered_terms().values():
            if term.effect != effect or term.name in ("stiffness", "mass", "input", "output"):
                continue
            if term.learnable:
                terms.append(term)
            elif term.structure == "known" and known_forces:
                if basis is None:
                    raise FemromValueError(f"the system has a {effect!r} effect: for_system needs the "
                                           "basis to project its known force")
                terms.append(term.galerkin(system, basis))
    return terms


class SecondOrderLearner(Learner):
    """Shared machinery of :class:`LagrangianOpInf` and :class:`SecondOrderOpInf`.

    Parameters
    ----------
    terms : sequence
        Terms beyond the stiffness (and the input and output maps, which
        follow the data): names or classes of registered learnable terms
        (``"damping"``, a user's term) are learned; term *instances* are
        known (e.g. a :class:`ProjectedNonlinearForce`) and move to the target.
    regularization : float, mapping or Regularization
        Relative Tikhonov weights (a float applies to every term).
    solver : FastSolver or ConicSolver
        What solves the regression: :class:`FastSolver` (default; its fields are the
        settings), ``ConicSolver("clarabel")`` or ``ConicSolver("scs")`` (the cvxpy
        reference), or any object with ``name`` and ``solve(problem) -> (X, info)``
        (``problem`` a :class:`GramProblem`, ``X`` (r, p)).
    mass : (r, r) ndarray, optional
        Known reduced mass (e.g. ``V^T M V`` of a Euclidean basis); default identity.
    mass_orthonormal : bool
        Whether the basis is mass-orthonormal; ``False`` without ``mass``
        warns that ``M^ = I`` is then an assumption that breaks symmetry.
    stiffness_margin : float
        ``eps = margin * ||Y||_F / ||D_j||_F`` in ``X_j >= eps I`` for ``"spd"`` terms.
    smoothing : Smoothing, True, "auto" or None
        Denoise each training and validation trajectory before the fit (:class:`Smoothing`: one
        smooth curve per coordinate through the states and measured derivatives; ``True``: the
        defaults; ``"auto"``: only trajectories estimated noisy, :meth:`Smoothing.auto`);
        ``None`` (default): the data as given.

    Attributes
    ----------
    operators_ : ReducedOperators
    coefficients_ : dict
        The fitted block of every learned term, by name.
    stiffness_, damping_ : (r, r) ndarray (``damping_`` is ``None`` when not learned)
    input_matrix_ : (r, m) ndarray or None
    output_matrix_ : (p, r) ndarray or None
    eigenvalues_ : dict of ndarray
    objective_ : float
    error_split_ : ErrorSplit
    solver_info_ : dict
    """

    structured: ClassVar[bool] = False

    def __init__(self, terms=(), *, regularization=0.0, solver=FastSolver(),
                 mass: np.ndarray | None = None, mass_orthonormal: bool = True,
                 stiffness_margin: float = 1e-10, smoothing: Smoothing | bool | str | None = None):
        self.smoothing = Smoothing.of(smoothing)
        if isinstance(terms, (str, type, ReducedTerm)):
            terms = (terms,)
        if not callable(getattr(solver, "solve", None)) or not isinstance(getattr(solver, "name", None), str):
            raise FemromTypeError(f"solver must be a solver object (FastSolver(), ConicSolver('clarabel'), ...), "
                                  f"got {solver!r}")
        if isinstance(solver, ConicSolver) and solver.name.upper() not in CONIC_SOLVERS:
            raise FemromValueError(f"conic solver {solver.name!r} cannot solve the regression's semidefinite "
                                   f"program; valid: {', '.join(n.lower() for n in CONIC_SOLVERS)}")
        self.learned_terms: list[type[ReducedTerm]] = []
        self.known_terms: list[ReducedTerm] = []
        for item in terms:
            if isinstance(item, ReducedTerm):
                self.known_terms.append(item)
                continue
            cls = term_class(item) if isinstance(item, str) else item
            if not (isinstance(cls, type) and issubclass(cls, ReducedTerm)):
                raise FemromTypeError(f"terms holds {item!r}: give term names, term classes or known term instances")
            if not cls.learnable:
                raise FemromValueError(f"term {cls.name!r} is not learned from data; pass a known instance of it")
            if cls.name in ("stiffness", "output"):
                continue                            # always there (the output map: with output data)
            self.learned_terms.append(cls)
        names = [c.name for c in self.learned_terms] + [t.name for t in self.known_terms]
        if len(set(names)) != len(names):
            raise FemromValueError(f"each term may be named once, got {names}")
        self.regularization = Regularization.of(regularization)
        self.solver = solver
        self.mass = None if mass is None else np.asarray(mass, dtype=float)
        self.mass_orthonormal = bool(mass_orthonormal)
        self.stiffness_margin = float(stiffness_margin)

    @classmethod
    def for_system(cls, system, basis: np.ndarray | None = None, **options):
        """A learner with exactly the terms of ``system``'s effects.

        Learnable terms (damping, a constant load, ...) are learned when the
        system has their effect; known nonlinear forces are projected
        (``V^T f(V q)``, which needs ``basis``). Only which effects exist is
        read, never the operators' values (the learner stays nonintrusive):
        the projected force is the known nonlinear term, not a matrix.

        Parameters
        ----------
        system : SecondOrderSystem
            Or a built scene (anything with a ``system`` attribute).
        basis : (n, r) ndarray, optional
        **options
            The other constructor arguments (``regularization``, ``solver``, ...).
        """
        system = getattr(system, "system", system)
        if "terms" in options or "damping" in options:
            raise FemromTypeError(f"for_system sets the terms from the system's effects; "
                                  f"use {cls.__name__}(terms=...) to choose them by hand")
        return cls(system_terms(system, basis), **options)

    @classmethod
    def for_training(cls, training, r: int, *, terms=None, extra_terms=(), **options):
        """``(learner, data, validation)`` at size ``r`` of a study's training set
        (:func:`terms_for_training`: the given ``terms``, or the system's plus ``extra_terms``)."""
        return terms_for_training(cls, training, r, terms, extra_terms, options)

    # -- views -------------------------------------------------------------------------
    @property
    def damping(self) -> bool:
        """Whether the model has a damping term ``C^ q'`` (learned)."""
        return any(c.name == "damping" for c in self.learned_terms)

    @property
    def nonlinear(self):
        """The known nonlinear terms as one force, or ``None``."""
        forces = [t for t in self.known_terms if t.role == "balance" and not hasattr(t, "matrix")]
        if not forces:
            return None
        return forces[0] if len(forces) == 1 else ReducedForces(forces)

    # -- the regression --------------------------------------------------------------
    def _learned(self, data) -> list[type[ReducedTerm]]:
        stiffness = term_class("stiffness")
        terms = [stiffness, *self.learned_terms]
        known = {t.name for t in self.known_terms}
        if data.inputs is not None and "input" not in known and not any(c.name == "input" for c in terms):
            terms.append(term_class("input"))
        # stiffness first (the regression's first block), then in equation order
        return sorted(terms, key=lambda c: (c.name != "stiffness", c.order))

    def _target(self, data: SecondOrderData) -> np.ndarray:
        Y = data.accelerations if self.mass is None else self.mass @ data.accelerations
        forces = [t for t in self.known_terms if not hasattr(t, "matrix")]
        linear = [t for t in self.known_terms if hasattr(t, "matrix")]
        if data.nonlinear_forces is not None:
            if not forces:
                raise FemromValueError("the data carry nonlinear_forces but the learner has no known force term "
                                       "to pair them with (name one in terms=, or use for_system)")
            Y = Y + data.nonlinear_forces
        else:
            for term in forces:
                Y = Y + term.target(data)
        for term in linear:
            Y = Y + term.target(data)
        return Y

    def _datablocks(self, data) -> list[np.ndarray]:
        return [term.datablock(data) for term in self._learned(data)]

    def regression(self, data) -> GramProblem:
        """The :class:`GramProblem` this learner solves for ``data`` (one or a list)."""
        data = concatenate(data) if isinstance(data, (list, tuple)) else data
        return self._regression(data, self._target(data), self._datablocks(data))

    def _regression(self, data, Y: np.ndarray, blocks_data: list) -> GramProblem:
        if self.mass is None and not self.mass_orthonormal:
            warnings.warn(
                "fitting with reduced mass M^ = I on a basis that is not mass-orthonormal: the "
                "data then follow M~^-1 K~, which is not symmetric, so the symmetric K^ >= 0 "
                "structure argument breaks; pass mass=V^T M V or use a mass-orthonormal basis",
                UserWarning, stacklevel=3)
        if not any(np.any(D) for D in blocks_data):
            raise FemromValueError(f"{type(self).__name__}: every snapshot of the data is zero: nothing to learn from")
        unknowns, columns = sum(D.shape[0] for D in blocks_data), Y.shape[1]
        if columns < unknowns and not any(self.regularization[t.name] > 0 for t in self._learned(data)):
            warnings.warn(
                f"{type(self).__name__}: {columns} snapshots for {unknowns} unknowns per reduced equation "
                f"(r = {data.r}): the data do not determine the operators; give more snapshots, a smaller r "
                f"or a regularization", UserWarning, stacklevel=3)
        blocks = []
        for term, D in zip(self._learned(data), blocks_data):
            structure = _BLOCKS.get(term.structure) if self.structured else "free"
            if structure is None:
                raise FemromValueError(f"term {term.name!r} of structure {term.structure!r} cannot be learned "
                                       f"by {type(self).__name__}")
            shift = 0.0
            if structure == "psd" and term.structure == "spd":
                shift = self.stiffness_margin * np.linalg.norm(Y) / max(np.linalg.norm(D), np.finfo(float).tiny)
            scale = float(np.sum(D * D)) / max(D.shape[0], 1)
            blocks.append(Block(term.name, D.shape[0], structure, shift=shift,
                                regularization=self.regularization[term.name] * scale))
        return GramProblem.from_data(Y, blocks_data, blocks)

    @staticmethod
    def _residual(Y: np.ndarray, blocks_data: list, X: np.ndarray) -> float:
        """``||Y + X D||_F / ||Y||_F`` from the data columns: the Gram expansion
        ``<X G, X> + 2 <X, H^T> + c`` cancels down to ``eps ||Y||^2``, so it cannot
        resolve a relative residual below ``sqrt(eps) ~ 1.5e-8``."""
        R = Y + X @ np.vstack(blocks_data)
        return float(np.linalg.norm(R) / max(np.linalg.norm(Y), np.finfo(float).tiny))

    def _solve(self, problem: GramProblem):
        return self.solver.solve(problem)

    # -- fit -----------------------------------------------------------------------------
    def fit(self, data, *, validation=None) -> "SecondOrderLearner":
        r"""Learn the operators from ``data``.

        Parameters
        ----------
        data : SecondOrderData or list of SecondOrderData
            Several trajectories are fitted together (their Gram matrices add;
            a stateful known force restarts at each trajectory's first column).
        validation : SecondOrderData or list of them, optional
            Held-out data: the relative residual ``||Y + X D||_F / ||Y||_F`` the fitted
            operators leave on them is ``validation_residual_`` (``None`` without).

        Returns
        -------
        self
        """
        if self.smoothing is not None:
            data = self.smoothing.apply(data)
            validation = None if validation is None else self.smoothing.apply(validation)
        data = concatenate(data) if isinstance(data, (list, tuple)) else data
        learned = self._learned(data)
        # the target (a projected known force costs a force evaluation per snapshot)
        # and the data blocks, built once for the regression and the residual
        Y, blocks_data = self._target(data), self._datablocks(data)
        problem = self._regression(data, Y, blocks_data)
        X, info = self._solve(problem)
        status = str(info.get("status", "optimal"))
        if not status.startswith("optimal"):
            gap = info.get("gap_estimate")
            warnings.warn(
                f"{type(self).__name__}: the {info.get('solver', 'regression')} solver ended {status!r}"
                + ("" if gap is None else f" at a relative gap of {gap:.2g}")
                + ": the operators are feasible but not certified optimal (a smaller r, another solver or "
                  "more iterations)", UserWarning, stacklevel=2)
        self.coefficients_ = {b.name: X[:, s] for b, s in zip(problem.blocks, problem.slices())}
        terms = [cls.from_coefficients(self.coefficients_[cls.name]) for cls in learned]
        output = term_class("output").fit(data, self.regularization["output"])
        if self.mass is not None:
            terms.append(term_class("mass")(self.mass))
        terms += self.known_terms + ([output] if output is not None else [])
        self.stiffness_ = self.coefficients_["stiffness"]
        self.damping_ = self.coefficients_.get("damping")
        self.input_matrix_ = self.coefficients_.get("input")
        self.output_matrix_ = None if output is None else output.matrix
        self.regression_ = problem
        self.objective_ = float(info["objective"])
        self.solver_info_ = info
        self.stiffness_shift_ = next(b.shift for b in problem.blocks if b.name == "stiffness")
        diag = data.diagnostics
        stored = diag.get("derivative_source") == "stored"
        self.error_split_ = ErrorSplit(
            projection=diag.get("projection_error"),
            derivative=0.0 if stored else diag.get("acceleration_error"),
            velocity=0.0 if stored else diag.get("velocity_error"),
            optimization=self._residual(Y, blocks_data, X))
        self.validation_residual_ = None
        if validation is not None:
            held = concatenate(validation) if isinstance(validation, (list, tuple)) else validation
            if [c.name for c in self._learned(held)] != [c.name for c in learned]:
                raise FemromValueError("validation data must carry what the training data carry "
                                       "(inputs, outputs) so that the same terms apply")
            self.validation_residual_ = self._residual(self._target(held), self._datablocks(held), X)
        self.operators_ = ReducedOperators(tuple(terms), self.describe())
        return self

    # -- reports -------------------------------------------------------------------------
    @property
    def eigenvalues_(self) -> dict:
        """Ascending eigenvalues of ``K^`` and ``C^`` (of their symmetric parts for plain OpInf)."""
        return self.operators_.eigenvalues()

    def describe(self) -> dict:
        """What was fitted how (stored with a saved ROM)."""
        out = {"method": self.method, "solver": self.solver.name,
               "terms": ["stiffness"] + [c.name for c in self.learned_terms],
               "known_terms": [t.name for t in self.known_terms],
               "damping": self.damping,
               "regularization": self.regularization.to_dict(),
               "mass": "identity" if self.mass is None else "given",
               "mass_orthonormal": self.mass_orthonormal,
               "nonlinear": self.nonlinear is not None,
               "smoothing": None if self.smoothing is None else asdict(self.smoothing)}
        info = getattr(self, "solver_info_", None)
        if info is not None:
            out["solver_info"] = {k: v for k, v in info.items() if k != "active"}
            out["objective"] = self.objective_
            out["error_split"] = asdict(self.error_split_)
        return out


def terms_for_training(cls, training, r: int, terms, extra_terms, options: dict, system_options=None):
    """``(learner, data, validation)``: ``cls`` with exactly ``terms`` when given, else with the terms
    of the training system's effects (``cls.for_system``: which effects exist, never their values)
    and the learnable ``extra_terms`` it lacks (damping of a structure the learner is not told is
    damped); the reduced runs at size ``r`` and the validation runs. ``system_options`` go to
    ``for_system`` only."""
    V = training.basis_at(r)
    if terms is not None:
        learner = cls(list(terms), **options)
    else:
        learner = cls.for_system(training.system, basis=V, **options, **(system_options or {}))
        known = [t.name for t in (*learner.learned_terms, *learner.known_terms)]
        missing = [t for t in extra_terms if t not in known]
        if missing:
            learner = cls([*learner.learned_terms, *learner.known_terms, *missing], **options)
    return learner, training.reduced(r), training.reduced(r, validation=True)
