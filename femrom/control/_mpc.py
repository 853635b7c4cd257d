r"""Linear model-predictive control on a discrete state-space model.

:class:`LinearMPC` builds the tracking QP of :mod:`._problem` once, as a
registered formulation (``"condensed"`` or ``"sparse"``: parametrised cvxpy
problems; ``"condensed_osqp"``, the default with OSQP: the condensed QP in OSQP
directly), and re-solves
it every step with the new state estimate, reference window and previous input
(OSQP warm-starts from the last solution). ``control`` returns the first input of the optimal plan and logs
the wall time of the call and the solver's status.
"""

from __future__ import annotations

import dataclasses
import time
import warnings

import numpy as np

from femrom._errors import FemromRuntimeError, FemromValueError
from femrom.control._formulation import QP_FORMULATIONS
from femrom.control._certificate import PlanCertificate
from femrom.control._problem import CondensedQP, MPCConfig, MPCProblem, vector
from femrom.control._qp_solver import QPSolver
from femrom.rom import DiscreteStateSpace


class MPCError(FemromRuntimeError):
    """A QP solve failed and the controller's policy is ``on_failure="raise"``."""


class MPCWarning(UserWarning):
    """A QP solve failed and the controller fell back (``"shift"`` or ``"hold"``)."""


class LinearMPC:
    r"""Output-tracking MPC with input bounds on a :class:`~femrom.rom.DiscreteStateSpace`.

    Solves, every step, the QP of :mod:`femrom.control._problem`

    .. math::

        \min \sum_{j=0}^{N-1} \|y_j - r_j\|_Q^2 + \|u_j\|_R^2 + \|u_j - u_{j-1}\|_S^2
        + \|z_N - z_T\|_P^2, \quad z_{j+1} = A z_j + B u_j + w_z,\;
        y_j = C z_j + D u_j + w_y,\; |u_j| \le b,

    and applies ``u_0``.

    Parameters
    ----------
    model : DiscreteStateSpace
        The controller's model (a ROM's ``to_state_space(dt)``, an identified model).
    config : MPCConfig, optional
        Settings; keyword arguments override its fields (``horizon``,
        ``output_weight``, ``input_weight``, ``input_rate_weight``,
        ``input_bound``, ``terminal_weight``, ``formulation``, ``solver`` (a
        :class:`~femrom.control.QPSolver`), ``on_failure``). For one release a
        solver name (``solver="OSQP"``) and the keywords ``tolerance``,
        ``max_iterations`` and ``solver_options`` are still taken, into a
        ``QPSolver``, with a DeprecationWarning.

    Attributes
    ----------
    config : MPCConfig
    qp : MPCProblem
        The weights and bounds as matrices.
    formulation : QPFormulation
        Holds the QP (a cvxpy formulation's parametrised problem is ``formulation.problem``).
    plan_ : (m, N) ndarray or None
        The last successful plan.
    solve_seconds : list of float
        Wall time of every :meth:`control` call: parameters, solve and unpacking.
    solver_seconds : list of float
        The solver's own time of every solve (``nan`` where it reports none).
    statuses : list of str
        The cvxpy status of every solve (``"error"`` when the solver raised).
    iterations : list of int
        Solver iterations of every solve (-1 where it reports none).
    n_fallbacks : int
        Solves that failed and were replaced by the ``on_failure`` policy.
    n_repaired : int
        Plans that failed the accuracy certificate and were repaired (``config.accuracy``).
    error_bounds : list of float
        The certified bound of ``||U - U*||`` of every plan checked (``config.accuracy``).
    """

    def __init__(self, model: DiscreteStateSpace, config: MPCConfig | None = None, **settings):
        settings = _solver_from_names(settings, config)
        config = MPCConfig(**settings) if config is None else dataclasses.replace(config, **settings)
        self.model, self.config = model, config
        self.qp = MPCProblem.from_model(model, config)
        self.formulation = QP_FORMULATIONS.get(config.formulation_name)(self.qp, config)
        self._condensed = self._certificate = None
        if config.accuracy is not None:
            self._condensed = getattr(self.formulation, "qp", None) or CondensedQP.from_problem(self.qp)
            self._certificate = PlanCertificate.from_hessian(self._condensed.hessian, self.qp.bound, self.qp.horizon)
            reach = self._certificate.round_off_bound()
            if not reach < config.accuracy:
                warnings.warn(f"the QP's Hessian has condition {self._certificate.condition:.2g}: a plan cannot be "
                              f"certified to accuracy {config.accuracy:g} in double precision (round-off alone "
                              f"allows {reach:.2g}); rescale the weights, or give a larger accuracy or None",
                              MPCWarning, stacklevel=2)
        self.plan_: np.ndarray | None = None
        self._plan_age = 0
        self.solve_seconds: list[float] = []
        self.solver_seconds: list[float] = []
        self.statuses: list[str] = []
        self.iterations: list[int] = []
        self.n_fallbacks = 0
        self.n_repaired = 0
        self.error_bounds: list[float] = []
        self._warned = False

    # -- sizes -----------------------------------------------------------------------------
    @property
    def horizon(self) -> int:
        return self.qp.horizon

    @property
    def n_states(self) -> int:
        return self.qp.n_states

    @property
    def n_inputs(self) -> int:
        return self.qp.n_inputs

    @property
    def n_outputs(self) -> int:
        return self.qp.n_outputs

    @property
    def input_bound(self) -> np.ndarray:
        """(m,) ndarray ``b`` (``inf`` where unbounded)."""
        return self.qp.bound

    # -- one step --------------------------------------------------------------------------
    def control(self, state, reference, u_previous=None, *, state_offset=None, output_offset=None,
                terminal_state=None) -> np.ndarray:
        """(m,) ndarray: the first input of the optimal plan.

        Parameters
        ----------
        state : (n,) array_like
            ``z_0``: the state (estimate) at the time the returned input is applied.
        reference : (p, N) or (p,) array_like
            ``r_0 .. r_{N-1}``: the outputs wanted from that time on (a (p,) vector: constant).
        u_previous : (m,) array_like, optional
            ``u_{-1}``, the input applied one step earlier (zeros by default); used by the
            input-rate weight.
        state_offset, output_offset : (n,) and (p,) array_like, optional
            ``w_z`` and ``w_y`` (zeros by default): e.g. :meth:`LinearObserver.offsets`.
        terminal_state : (n,) array_like, optional
            ``z_T`` of the terminal cost (zeros by default).
        """
        tic = time.perf_counter()
        n, m, p, N = self.n_states, self.n_inputs, self.n_outputs, self.horizon
        z = vector(state, n, "state")
        R = np.asarray(reference, dtype=float)
        if R.ndim == 1 and R.shape == (p,):
            R = np.repeat(R[:, None], N, axis=1)
        if R.shape != (p, N):
            raise FemromValueError(f"reference has shape {R.shape}, expected ({p}, {N}) (outputs, horizon) or ({p},)")
        if not np.all(np.isfinite(R)):
            raise FemromValueError("reference has non-finite entries")
        u_prev = vector(u_previous, m, "u_previous")
        w_z = vector(state_offset, n, "state_offset")
        w_y = vector(output_offset, p, "output_offset")
        z_T = vector(terminal_state, n, "terminal_state")
        self.formulation.set_parameters(z, R, u_prev, w_z, w_y, z_T)
        solution = self.formulation.solve()
        status, plan = solution.status, solution.plan
        if plan is not None and not np.all(np.isfinite(plan)):
            plan, status = None, f"{status} (non-finite)"
        elif plan is not None and "inaccurate" in status and self.config.on_failure == "raise":
            plan = None           # a solver that stopped short of its tolerance failed, for "raise"
        elif plan is not None and self._certificate is not None:
            plan, status = self._certified(plan, status, (z, R, u_prev, w_z, w_y, z_T))
        self.statuses.append(status)
        self.solver_seconds.append(solution.solver_seconds)
        self.iterations.append(solution.iterations)
        if plan is not None:
            self.plan_, self._plan_age = plan, 0
            u = plan[:, 0].copy()
        else:
            u = self._fallback(status, u_prev)
        self.solve_seconds.append(time.perf_counter() - tic)
        return u

    def _certified(self, plan: np.ndarray, status: str, parameters: tuple) -> tuple[np.ndarray | None, str]:
        """``(plan, status)``: the plan as solved if certified, else repaired (``" (repaired)"``) or
        ``None`` (``" (uncertified)"``); the bound is logged in :attr:`error_bounds`."""
        # the condensed formulations computed g for this solve already (``gradient_``)
        gradient = getattr(self.formulation, "gradient_", None)
        if gradient is None:
            gradient = self._condensed.gradient(*parameters)
        certificate = self._certificate
        # into the bounds first (a solver's plan may leave them by its tolerance): the projection
        # onto the box is never farther from the optimum, which lies inside it
        U = np.clip(plan.T.ravel(), certificate.lower, certificate.upper)
        tolerance = self.config.accuracy * max(float(np.linalg.norm(U)),
                                               float(np.linalg.norm(gradient)) / certificate.largest)
        bound = certificate.error_bound(U, gradient)
        if bound <= tolerance:
            self.error_bounds.append(bound)
            return U.reshape(self.horizon, self.n_inputs).T.copy(), status
        repaired = certificate.repair(U, gradient)
        if repaired is not None:
            tolerance = self.config.accuracy * max(float(np.linalg.norm(repaired)),
                                                   float(np.linalg.norm(gradient)) / certificate.largest)
            bound = certificate.error_bound(repaired, gradient)
        self.error_bounds.append(bound)
        if repaired is None or not bound <= tolerance:
            return None, f"{status} (uncertified)"
        self.n_repaired += 1
        return repaired.reshape(self.horizon, self.n_inputs).T.copy(), f"{status} (repaired)"

    def _fallback(self, status: str, u_previous: np.ndarray) -> np.ndarray:
        policy = self.config.on_failure
        if policy == "raise":
            raise MPCError(f"QP solve failed with status {status!r} ({self.config.solver.name}, "
                           f"{self.config.formulation_name}) at solve {len(self.statuses)}")
        self.n_fallbacks += 1
        if not self._warned:
            warnings.warn(f"QP solve failed with status {status!r}; applying the "
                          f"{'shifted last plan' if policy == 'shift' else 'previous input'} "
                          "(further fallbacks are counted in n_fallbacks)", MPCWarning, stacklevel=3)
            self._warned = True
        if policy == "shift" and self.plan_ is not None:
            self._plan_age += 1
            return self.plan_[:, min(self._plan_age, self.horizon - 1)].copy()
        return u_previous.copy()

    def reset_log(self) -> None:
        """Forget the timings, statuses and the last plan (the compiled QP stays)."""
        self.plan_, self._plan_age = None, 0
        self.solve_seconds.clear(), self.solver_seconds.clear(), self.statuses.clear()
        self.iterations.clear(), self.error_bounds.clear()
        self.n_fallbacks, self.n_repaired, self._warned = 0, 0, False

    def describe(self) -> dict:
        """The configuration and sizes as plain JSON values."""
        return {**self.config.describe(), "n_states": self.n_states, "n_inputs": self.n_inputs,
                "n_outputs": self.n_outputs}


#: The settings a LinearMPC took before the QPSolver object (one release more).
_SOLVER_KEYWORDS = {"tolerance": "tolerance", "max_iterations": "max_iterations", "solver_options": "options"}


def _solver_from_names(settings: dict, config: MPCConfig | None) -> dict:
    """``settings`` with a solver name and the old solver keywords folded into a QPSolver
    (a DeprecationWarning says what to write instead); unchanged without them."""
    old = {key: settings.pop(key) for key in list(settings) if key in _SOLVER_KEYWORDS}
    solver = settings.get("solver")
    if not old and not isinstance(solver, str):
        return settings
    warnings.warn("LinearMPC(solver='OSQP', tolerance=..., max_iterations=..., solver_options=...) is "
                  "deprecated: pass solver=QPSolver('osqp', tolerance=..., max_iterations=..., options=...)",
                  DeprecationWarning, stacklevel=3)
    if solver is None:
        solver = config.solver if config is not None else QPSolver()
    elif isinstance(solver, str):
        solver = QPSolver(solver)
    changes = {_SOLVER_KEYWORDS[key]: value for key, value in old.items()}
    return {**settings, "solver": dataclasses.replace(solver, **changes)}
