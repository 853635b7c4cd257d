r"""Second-order operator inference: Lagrangian (structure-preserving) and plain.

Given reduced data (:class:`SecondOrderData`), both learners solve

.. math::

    \min_{\hat K, \hat C, \hat B}\;
    \big\| \hat M \ddot{\hat Q} + \hat F_{nl} + \hat C \dot{\hat Q} + \hat K \hat Q
        - \hat B U \big\|_F^2
    + \lambda_K \|\hat K\|_F^2 + \lambda_C \|\hat C\|_F^2 + \lambda_B \|\hat B\|_F^2,

with each term present only when the system has it (damping, inputs,
nonlinear force). :class:`LagrangianOpInf` (Sharma & Kramer, Physica D 462,
2024) asks ``K^ = K^^T >= eps I`` and ``C^ = C^^T >= 0``, so the learned model
has a positive energy ``q'^T M^ q'/2 + q^T K^ q/2`` that damping can only
decrease; :class:`SecondOrderOpInf` is the unconstrained baseline (ordinary
least squares). The reduced mass ``M^`` is the identity for a
mass-orthonormal basis, or given (e.g. ``V^T M V`` for a Euclidean basis).
The output map solves ``min_E ||Y - E Q^||_F^2 + lambda_E ||E||_F^2``.

Regularization weights are *relative*: ``lambda_j = rho_j * trace(D_j D_j^T) /
size_j`` (the mean eigenvalue of the data block's Gram matrix), so a value
means the same for every data set and unit system.
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass

import numpy as np

from femrom.inference._data import SecondOrderData, concatenate
from femrom.inference._fast import FastOptions, solve_fast
from femrom.inference._operators import Damping, Input, ReducedOperators, Stiffness
from femrom.inference._problem import Block, GramProblem
from femrom.inference._sdp import solve_conic

#: Solvers a learner accepts.
SOLVERS = ("fast", "clarabel", "scs")


@dataclass(frozen=True)
class Regularization:
    """Relative Tikhonov weights per operator (see the module docstring).

    Attributes
    ----------
    stiffness, damping, input, output : float
    """

    stiffness: float = 0.0
    damping: float = 0.0
    input: float = 0.0
    output: float = 0.0

    @classmethod
    def uniform(cls, value: float) -> "Regularization":
        return cls(value, value, value, value)

    def __post_init__(self):
        for name, value in asdict(self).items():
            if not value >= 0:
                raise ValueError(f"regularization {name} must be >= 0, got {value}")


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
        ``||M^ Q^'' + F^ + C^ Q^' + K^ Q^ - B^ U||_F / ||M^ Q^'' + F^||_F``: the
        relative residual the fitted operators leave.
    """

    projection: float | None
    derivative: float | None
    velocity: float | None
    optimization: float


class _SecondOrderLearner:
    structure = "free"
    method = ""

    def __init__(self, *, damping: bool = True, regularization: Regularization | float = 0.0,
                 solver: str = "fast", mass: np.ndarray | None = None,
                 mass_orthonormal: bool = True, nonlinear=None, stiffness_margin: float = 1e-10,
                 solver_options: dict | None = None):
        if isinstance(regularization, (int, float)):
            regularization = Regularization.uniform(float(regularization))
        if solver.lower() not in SOLVERS:
            raise ValueError(f"unknown solver {solver!r}; valid: {SOLVERS}")
        self.damping = bool(damping)
        self.regularization = regularization
        self.solver = solver.lower()
        self.mass = None if mass is None else np.asarray(mass, dtype=float)
        self.mass_orthonormal = bool(mass_orthonormal)
        self.nonlinear = nonlinear
        self.stiffness_margin = float(stiffness_margin)
        self.solver_options = dict(solver_options or {})

    @classmethod
    def for_system(cls, system, basis: np.ndarray | None = None, **options):
        """A learner with exactly the terms of ``system``'s effects.

        ``C^`` only when the system has damping; the projected known nonlinear
        force ``V^T f_nl(V q)`` only when it has a nonlinear effect (then
        ``basis`` is needed); ``B^`` follows the data's inputs as always. Only
        which effects exist is read, never the operators' values (the learner
        stays nonintrusive).

        Parameters
        ----------
        system : SecondOrderSystem
            Or a built scene (anything with a ``system`` attribute).
        basis : (n, r) ndarray, optional
        **options
            The other constructor arguments (``regularization``, ``solver``, ...).
        """
        from femrom.inference._operators import ProjectedNonlinearForce

        system = getattr(system, "system", system)
        for name in ("damping", "nonlinear"):
            if name in options:
                raise TypeError(f"for_system sets {name!r} from the system's effects; "
                                f"use {cls.__name__}(...) to choose it by hand")
        nonlinear = None
        if system.nonlinear is not None:
            if basis is None:
                raise ValueError("the system has a nonlinear effect: for_system needs the basis "
                                 "to project its known force")
            nonlinear = ProjectedNonlinearForce(system.nonlinear, basis)
        return cls(damping=system.damping is not None, nonlinear=nonlinear, **options)

    # -- the regression --------------------------------------------------
    def _target(self, data: SecondOrderData) -> np.ndarray:
        Y = data.accelerations if self.mass is None else self.mass @ data.accelerations
        F = data.nonlinear_forces
        if F is None and self.nonlinear is not None:
            F = self.nonlinear.forces(data.states, data.velocities)
        return Y if F is None else Y + F

    def regression(self, data) -> GramProblem:
        """The :class:`GramProblem` this learner solves for ``data`` (one or a list)."""
        data = concatenate(data) if isinstance(data, (list, tuple)) else data
        return self._regression(data, self._target(data), self._datablocks(data))

    def _datablocks(self, data) -> list[np.ndarray]:
        return [term.datablock(data) for term in self._terms(data)]

    def _regression(self, data, Y: np.ndarray, blocks_data: list) -> GramProblem:
        if self.mass is None and not self.mass_orthonormal:
            warnings.warn(
                "fitting with reduced mass M^ = I on a basis that is not mass-orthonormal: the "
                "data then follow M~^-1 K~, which is not symmetric, so the symmetric K^ >= 0 "
                "structure argument breaks; pass mass=V^T M V or use a mass-orthonormal basis",
                UserWarning, stacklevel=3)
        terms = self._terms(data)
        reg = {"stiffness": self.regularization.stiffness, "damping": self.regularization.damping,
               "input": self.regularization.input}
        shift = 0.0
        if self.structure == "psd":
            shift = self.stiffness_margin * np.linalg.norm(Y) / max(np.linalg.norm(data.states),
                                                                    np.finfo(float).tiny)
        blocks = []
        for term, D in zip(terms, blocks_data):
            structure = "free" if (self.structure == "free" or term.structure == "free") \
                else term.structure
            scale = float(np.sum(D * D)) / max(D.shape[0], 1)
            blocks.append(Block(term.name, D.shape[0], structure,
                                shift=shift if term.name == "stiffness" and structure == "psd" else 0.0,
                                regularization=reg[term.name] * scale))
        return GramProblem.from_data(Y, blocks_data, blocks)

    def _terms(self, data) -> list:
        return [Stiffness] + ([Damping] if self.damping else []) + \
            ([Input] if data.inputs is not None else [])

    @staticmethod
    def _residual(Y: np.ndarray, blocks_data: list, X: np.ndarray) -> float:
        """``||Y + X D||_F / ||Y||_F`` from the data columns: the Gram expansion
        ``<X G, X> + 2 <X, H^T> + c`` cancels down to ``eps ||Y||^2``, so it cannot
        resolve a relative residual below ``sqrt(eps) ~ 1.5e-8``."""
        R = Y + X @ np.vstack(blocks_data)
        return float(np.linalg.norm(R) / max(np.linalg.norm(Y), np.finfo(float).tiny))

    def _solve(self, problem: GramProblem):
        if self.solver == "fast":
            options = FastOptions(**self.solver_options) if self.solver_options else FastOptions()
            return solve_fast(problem, options)
        return solve_conic(problem, self.solver.upper(), **self.solver_options)

    # -- fit ---------------------------------------------------------------
    def fit(self, data) -> "_SecondOrderLearner":
        r"""Learn the operators from ``data``.

        Parameters
        ----------
        data : SecondOrderData or list of SecondOrderData
            Several trajectories are fitted together (their Gram matrices add).

        Returns
        -------
        self
        """
        data = concatenate(data) if isinstance(data, (list, tuple)) else data
        # the target (a projected nonlinear force costs one full-order evaluation per
        # snapshot) and the data blocks, built once for the regression and the residual
        Y, blocks_data = self._target(data), self._datablocks(data)
        problem = self._regression(data, Y, blocks_data)
        X, info = self._solve(problem)
        parts = {b.name: X[:, s] for b, s in zip(problem.blocks, problem.slices())}
        self.stiffness_ = parts["stiffness"]
        self.damping_ = parts.get("damping")
        self.input_matrix_ = parts.get("input")
        self.output_matrix_ = self._fit_outputs(data)
        self.regression_ = problem
        self.objective_ = float(info["objective"])
        self.solver_info_ = info
        self.stiffness_shift_ = next(b.shift for b in problem.blocks if b.name == "stiffness")
        residual = self._residual(Y, blocks_data, X)
        diag = data.diagnostics
        self.error_split_ = ErrorSplit(
            projection=diag.get("projection_error"),
            derivative=0.0 if diag.get("derivative_source") == "stored" else diag.get("acceleration_error"),
            velocity=0.0 if diag.get("derivative_source") == "stored" else diag.get("velocity_error"),
            optimization=float(residual))
        self.operators_ = ReducedOperators(
            stiffness=self.stiffness_, mass=self.mass, damping=self.damping_,
            input_matrix=self.input_matrix_, output_matrix=self.output_matrix_,
            nonlinear=self.nonlinear, metadata=self.describe())
        return self

    def _fit_outputs(self, data: SecondOrderData):
        if data.outputs is None:
            return None
        Q = data.states
        G = Q @ Q.T
        lam = self.regularization.output * np.trace(G) / max(Q.shape[0], 1)
        return np.linalg.lstsq(G + lam * np.eye(Q.shape[0]), Q @ data.outputs.T, rcond=None)[0].T

    # -- reports -------------------------------------------------------
    @property
    def eigenvalues_(self) -> dict:
        """Ascending eigenvalues of ``K^`` and ``C^`` (of their symmetric parts for plain OpInf)."""
        return self.operators_.eigenvalues()

    def describe(self) -> dict:
        """What was fitted how (stored with a saved ROM)."""
        out = {"method": self.method, "solver": self.solver, "damping": self.damping,
               "regularization": asdict(self.regularization),
               "mass": "identity" if self.mass is None else "given",
               "mass_orthonormal": self.mass_orthonormal,
               "nonlinear": self.nonlinear is not None}
        info = getattr(self, "solver_info_", None)
        if info is not None:
            out["solver_info"] = {k: v for k, v in info.items() if k != "active"}
            out["objective"] = self.objective_
            out["error_split"] = asdict(self.error_split_)
        return out


class LagrangianOpInf(_SecondOrderLearner):
    r"""Lagrangian operator inference: ``K^ = K^^T >= eps I``, ``C^ = C^^T >= 0``.

    .. math::

        \min_{\hat K \succeq \varepsilon I,\; \hat C \succeq 0,\; \hat B}
        \big\| \hat M \ddot{\hat Q} + \hat F_{nl} + \hat C \dot{\hat Q}
              + \hat K \hat Q - \hat B U \big\|_F^2 + \text{Tikhonov}

    (Sharma & Kramer, Physica D 462, 134128, 2024). A semidefinite program:
    ``solver="fast"`` (default, :func:`~femrom.inference.solve_fast`) or the
    cvxpy reference ``"clarabel"`` / ``"scs"``.

    Parameters
    ----------
    damping : bool
        Whether the model has a damping term ``C^ q'``.
    regularization : Regularization or float
        Relative Tikhonov weights (a float applies to every operator).
    solver : {"fast", "clarabel", "scs"}
    mass : (r, r) ndarray, optional
        Known reduced mass (e.g. ``V^T M V`` of a Euclidean basis); default
        identity.
    mass_orthonormal : bool
        Whether the basis is mass-orthonormal; ``False`` without ``mass``
        warns that ``M^ = I`` is then an assumption that breaks symmetry.
    nonlinear : ProjectedNonlinearForce, optional
        Known nonlinear force; its data come from ``data.nonlinear_forces``
        or, when absent, from evaluating it on the reduced states.
    stiffness_margin : float
        ``eps = margin * ||M^ Q'' + F||_F / ||Q^||_F`` in ``K^ >= eps I``.
    solver_options : dict
        :class:`FastOptions` fields, or keyword arguments of cvxpy's ``solve``.

    Attributes
    ----------
    stiffness_, damping_ : (r, r) ndarray
    input_matrix_ : (r, m) ndarray or None
    output_matrix_ : (p, r) ndarray or None
    operators_ : ReducedOperators
    eigenvalues_ : dict of ndarray
    objective_ : float
    error_split_ : ErrorSplit
    solver_info_ : dict
    """

    structure = "psd"
    method = "lagrangian_opinf"


class SecondOrderOpInf(_SecondOrderLearner):
    r"""Plain second-order operator inference: ordinary (Tikhonov) least squares.

    .. math::

        \min_{\hat K, \hat C, \hat B}
        \big\| \hat M \ddot{\hat Q} + \hat F_{nl} + \hat C \dot{\hat Q}
              + \hat K \hat Q - \hat B U \big\|_F^2 + \text{Tikhonov},

    no symmetry or definiteness: the baseline structure preservation must
    beat. Same parameters and attributes as :class:`LagrangianOpInf`.
    """

    structure = "free"
    method = "plain_opinf"
