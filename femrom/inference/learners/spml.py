r"""L-OpInf enhanced with structure-preserving machine learning (SpML)."""

from __future__ import annotations

import importlib
import importlib.util
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

from femrom._errors import FemromTypeError, FemromValueError
from femrom._progress import Progress
from femrom.inference._data import SecondOrderData, concatenate, sampling_step
from femrom.inference._learner import Learner, register_learner
from femrom.inference._operators import ReducedOperators
from femrom.inference._output_error import OutputError, output_error_refinement
from femrom.inference._second_order import system_terms, terms_for_training
from femrom.inference._smoothing import Smoothing
from femrom.inference._structured_lstsq import FastSolver
from femrom.inference._terms import ReducedTerm, term_class
from femrom.inference.learners.iwan_lopinf import LINEAR_TERMS as SLIDER_LINEAR_TERMS
from femrom.inference.learners.iwan_lopinf import IwanLOpInf
from femrom.inference.learners.lopinf import LagrangianOpInf
from femrom.inference.terms.learned_dissipation import LearnedDissipation
from femrom.inference.terms.learned_hysteresis import LearnedHysteresis, slider_stretches
from femrom.inference.terms.learned_potential import LearnedPotential

#: Levenberg-Marquardt steps of each output-error candidate (networks as trained, and switched off) before
#: the better one goes on alone.
CANDIDATE_STEPS = 5

#: The names that ask SpML for learned sliders (:class:`LearnedHysteresis`) among its terms.
HYSTERESIS_TERMS = ("hysteresis", LearnedHysteresis.name)

#: The one line a user without torch reads when asking for SpML.
TORCH_MISSING = "SpML needs torch, which is not installed: pip install 'femrom[ml]' (torch==2.13.0, CPU is enough)"


def torch_available() -> bool:
    """Whether torch can be imported (without importing it)."""
    try:
        return importlib.util.find_spec("torch") is not None
    except (ImportError, ValueError):
        return False


def spml_module(r: int, config: "SpMLConfig | None" = None, *, seed: int = 0):
    """SpML's torch model of ``r`` coordinates (mass, potential, dissipation) at its initial weights,
    in unit scales (``export()`` gives the numpy terms): what a fit trains, for benchmarks and tests
    that time or inspect it. Needs torch."""
    import torch

    config = SpMLConfig() if config is None else config
    scales = {"q": np.ones(r), "v": np.ones(r), "potential": 1.0, "dissipation": 1.0}
    return _backend().SpMLModule(r, config, scales, np.eye(r), [], torch.Generator().manual_seed(seed))


def _backend():
    try:
        return importlib.import_module("femrom.inference._spml_torch")
    except ImportError:
        raise ImportError(TORCH_MISSING) from None


@dataclass(frozen=True)
class SpMLConfig:
    """Settings of the SpML fit (step 2; step 1 is :class:`LagrangianOpInf`'s).

    Attributes
    ----------
    potential_degrees : tuple of int
        Degrees of the potential's monomials, a subset of (3, 4) (degree 2 is ``K^``;
        degrees 0 and 1 would move the equilibrium); all ``C(r + d - 1, d)`` monomials of each.
    potential_widths : tuple of int
        Hidden widths of the potential's MLP (tanh); ``()``: no network.
    learn_dissipation : bool or None
        Whether to learn a nonlinear dissipation function ``F^`` (the linear ``C^`` is step 1's);
        ``None``: when step 1 learns a damping term (an undamped structure gets none, which a
        spurious dissipation would only make lose energy) and there is no ``"hysteresis"`` term (the
        sliders are then the learned dissipation: on the jointed beam a convex dissipation beside
        them fitted what r > 1 coordinates cannot close and spoiled the backbone, docs/spml.md).
    dissipation_directions : int or None
        Directions ``a_k``, ``b_k`` of the convex powers ``|a_k . v|^3 / 3``, ``(b_k . v)^4 / 4``
        (``None``: r; 0: none).
    dissipation_widths : tuple of int
        Hidden widths of the input-convex network (softplus); ``()``: none.
    least_squares : bool
        Solve the part of the model linear in its parameters (the mass, step 1's linear terms,
        the monomials' coefficients) exactly by structured least squares, with the networks and
        convex powers as they are and with them switched off, before L-BFGS and between its
        stages (``least_squares_rounds``); a solve is kept only where it lowers the checked
        (validation) loss, and step 1's start stays a candidate. Without it, L-BFGS alone from
        step 1 (docs/spml.md, "Convergence").
    least_squares_rounds : int
        Least-squares solves at most, each followed by L-BFGS on the remaining iterations; the
        rounds stop early when a solve improves the checked loss by less than ``tolerance``.
    rollout_steps : int
        Samples per window of the rollout refinement (0: none): after the other stages, L-BFGS on
        the error of windows predicted by the discrete-gradient step from every ``rollout_stride``-th
        sample, each sample interval in ``rollout_substeps`` steps, at most ``rollout_iterations``
        iterations, checked on the validation trajectory's windows (docs/spml.md, "Convergence").
        Needs sampled times, and no known force terms.
    rollout_substeps, rollout_stride, rollout_iterations : int
    output_error : bool or "auto"
        After the other stages, refine the parameters linear in the balance (the mass up to its
        gauge when ``learn_mass``, step 1's linear terms when ``refine_linear``, the monomials'
        coefficients) and each trajectory's initial
        state by output error: every measured trajectory simulated by the discrete-gradient march,
        the misfit of its states, velocities and accelerations weighted by their estimated noise,
        Levenberg-Marquardt with exact sensitivities (:mod:`femrom.inference._output_error`; the
        maximum-likelihood estimate where the noise is white). It fits the raw data, not the smoothed
        ones, and is kept only where the validation trajectories' output error (their initial states
        fitted) falls. ``"auto"``: when the smoothing replaced a trajectory (noisy data; on exact
        data the scheme's own error would be all it fits); needs uniformly sampled times, no
        sliders and no known force terms (else skipped, said in :attr:`SpML.stages_`).
    output_error_iterations : int
        Its Levenberg-Marquardt steps at most.
    output_error_substeps : int
        Its discrete-gradient steps per sampling interval.
    polynomial_start : bool
        Start from the least-squares solution whatever step 1's start scores (implies
        ``least_squares``).
    polynomial_ridge : float
        Relative Tikhonov weight of the least-squares solves, per block.
    refine_linear : bool
        Refine step 1's linear terms in step 2 within their structure (``K^ = G G^T + eps I``,
        ``C^ = G G^T``, ``B^`` free), starting from step 1's values; ``False`` keeps them fixed.
        Step 1 fits a linear model to nonlinear data, so its ``K^`` carries the nonlinear force's
        secant part, which a potential of degree >= 3 cannot take back.
    learn_mass : bool
        Learn ``M^ = L L^T`` (``L`` lower triangular, positive diagonal, starting at the step-1
        mass); else keep step 1's.
    max_iterations : int
        L-BFGS iterations at most.
    check_every : int
        Iterations between two checks of the validation loss (and progress updates).
    patience : int
        Checks without improvement before stopping early.
    tolerance : float
        Relative improvement of the checked loss that counts.
    history_size : int
        L-BFGS memory.
    weight_decay : float
        ``mu sum ||W||_F^2`` over the networks' weight matrices, added to the relative loss.
    seed : int
        Seed of the initial weights (a ``torch.Generator``; same seed, same weights).
    threads : int
        torch threads during the fit (restored after; 1 is fastest at these sizes).
    hysteresis_thresholds : int or tuple of float
        With the ``"hysteresis"`` term: the number of sliders, their thresholds log-spaced over
        ``hysteresis_span`` times the training data's ``max |a . q^|``; or the thresholds themselves
        (:class:`IwanLOpInf`'s ``thresholds``).
    hysteresis_span : (2,) floats
    hysteresis_direction : (r,) floats or None
        The sliders' direction ``a`` (fixed; ``None``: ``e_1``, the leading coordinate).
    hysteresis_monotone : bool
        The shape of Segalman's densities for the weights (:class:`IwanLOpInf`'s ``monotone``): the top
        slider is chosen by the start's cone programs and kept through the fit.
    """

    potential_degrees: tuple = (3, 4)
    potential_widths: tuple = (32, 32)
    learn_dissipation: bool | None = None
    dissipation_directions: int | None = None
    dissipation_widths: tuple = (16,)
    least_squares: bool = True
    least_squares_rounds: int = 2
    rollout_steps: int = 0
    rollout_substeps: int = 4
    rollout_stride: int = 1
    rollout_iterations: int = 100
    output_error: bool | str = "auto"
    output_error_iterations: int = 20
    output_error_substeps: int = 8
    polynomial_start: bool = False
    polynomial_ridge: float = 1e-12
    refine_linear: bool = True
    learn_mass: bool = True
    max_iterations: int = 2000
    check_every: int = 20
    patience: int = 10
    tolerance: float = 1e-4
    history_size: int = 50
    weight_decay: float = 0.0
    seed: int = 0
    threads: int = 1
    hysteresis_thresholds: int | tuple = 32
    hysteresis_span: tuple = (1e-3, 1.0)
    hysteresis_direction: tuple | None = None
    hysteresis_monotone: bool = True

    def __post_init__(self):
        object.__setattr__(self, "hysteresis_span", tuple(float(x) for x in self.hysteresis_span))
        if self.hysteresis_direction is not None:
            object.__setattr__(self, "hysteresis_direction", tuple(float(x) for x in self.hysteresis_direction))
        if np.ndim(self.hysteresis_thresholds) == 0:
            if not (isinstance(self.hysteresis_thresholds, (int, np.integer)) and self.hysteresis_thresholds >= 2):
                raise FemromValueError("SpMLConfig.hysteresis_thresholds must be an integer >= 2 or thresholds > 0, "
                                       f"got {self.hysteresis_thresholds!r}")
        else:
            values = tuple(float(x) for x in np.ravel(self.hysteresis_thresholds))
            if not values or not all(np.isfinite(x) and x > 0 for x in values):
                raise FemromValueError("SpMLConfig.hysteresis_thresholds must be an integer >= 2 or thresholds > 0, "
                                       f"got {self.hysteresis_thresholds!r}")
            object.__setattr__(self, "hysteresis_thresholds", values)
        lo, hi = (self.hysteresis_span + (0.0, 0.0))[:2]
        if len(self.hysteresis_span) != 2 or not 0 < lo <= hi:
            raise FemromValueError(f"SpMLConfig.hysteresis_span must be (low, high) with 0 < low <= high, got "
                                   f"{self.hysteresis_span}")
        object.__setattr__(self, "potential_degrees", tuple(int(d) for d in self.potential_degrees))
        object.__setattr__(self, "potential_widths", tuple(int(w) for w in self.potential_widths))
        object.__setattr__(self, "dissipation_widths", tuple(int(w) for w in self.dissipation_widths))
        bad = [d for d in self.potential_degrees if d not in (3, 4)]
        if bad or len(set(self.potential_degrees)) != len(self.potential_degrees):
            raise FemromValueError(f"SpMLConfig.potential_degrees must be distinct values of (3, 4), got "
                                   f"{self.potential_degrees}")
        for name in ("potential_widths", "dissipation_widths"):
            if any(w < 1 for w in getattr(self, name)):
                raise FemromValueError(f"SpMLConfig.{name} must be positive widths, got {getattr(self, name)}")
        if int(self.rollout_steps) < 0:
            raise FemromValueError(f"SpMLConfig.rollout_steps must be >= 0, got {self.rollout_steps}")
        if self.dissipation_directions is not None and int(self.dissipation_directions) < 0:
            raise FemromValueError(f"SpMLConfig.dissipation_directions must be >= 0, got {self.dissipation_directions}")
        if not (isinstance(self.output_error, (bool, np.bool_)) or self.output_error == "auto"):
            raise FemromValueError(f"SpMLConfig.output_error must be True, False or 'auto', got {self.output_error!r}")
        for name in ("max_iterations", "check_every", "patience", "history_size", "threads", "least_squares_rounds",
                     "rollout_substeps", "rollout_stride", "rollout_iterations", "output_error_iterations",
                     "output_error_substeps"):
            if int(getattr(self, name)) < 1:
                raise FemromValueError(f"SpMLConfig.{name} must be >= 1, got {getattr(self, name)}")
        if not (self.tolerance >= 0 and self.weight_decay >= 0 and self.polynomial_ridge >= 0):
            raise FemromValueError(f"SpMLConfig.tolerance, weight_decay and polynomial_ridge must be >= 0, got "
                                   f"{self.tolerance}, {self.weight_decay}, {self.polynomial_ridge}")


@register_learner("spml")
class SpML(Learner):
    r"""L-OpInf, then the nonlinear Lagrangian and dissipation learned on top.

    Sharma, Najera-Flores, Todd & Kramer, CMAME 423, 116865, 2024 (docs/spml.md).

    Step 1, :class:`LagrangianOpInf`: the best linear Lagrangian model
    ``M_0 q'' + C^ q' + K^ q = B^ u`` (``K^ = K^^T > 0``, ``C^ = C^^T >= 0``,
    ``M_0 = I`` for a mass-orthonormal basis). Step 2 starts there and learns, refining
    ``K^, C^, B^`` within their structure (``refine_linear``; step 1's ``K^`` carries the
    nonlinear force's secant part, which only a quadratic term can take back)

    .. math::

        \min_{L,\,\hat K,\,\hat C,\,\hat B,\,\alpha,\,\theta_U,\,a,\,b,\,\theta_F}\;
        \frac{\big\| \hat M^{-1} \big(\hat M \ddot{\hat Q} + \hat C \dot{\hat Q} + \nabla\hat{\mathcal F}(\dot{\hat Q})
              + \hat K \hat Q + \nabla\hat U(\hat Q) - \hat B U\big) \big\|_F^2}
             {\| \ddot{\hat Q} \|_F^2}

    (the residual solved with ``M^``: an acceleration, so that scaling every term by one
    factor changes nothing, and that scale is fixed by ``tr M^ = tr M_0``) by full-batch
    L-BFGS (torch, float64, one thread), with every structure built in, not penalised:

    - mass ``M^ = L L^T``, ``L`` lower triangular with an exponential
      diagonal: symmetric positive definite for any weights (the seed's
      ``I + M^_NN``), so ``T = v^T M^ v / 2 > 0``;
    - potential ``U^`` (:class:`LearnedPotential`): monomials of degree 3 and
      4 plus an MLP, shifted to ``U^(0) = 0``, ``grad U^(0) = 0``: a scalar,
      whose force is its exact gradient (explicit backward passes in training,
      checked against autograd in the tests; the exported analytic gradient and
      Hessian in the ROM, 65-135x cheaper a call than autograd,
      ``benchmarks/spml_step.py``);
    - dissipation ``F^`` (:class:`LearnedDissipation`): convex powers and an
      input-convex network, convex with minimum 0 at ``v = 0``, hence
      ``v . grad F^(v) >= F^(v) >= 0``: it never feeds power in.

    With the :class:`~femrom.rom.SecondOrderROM` scheme ``"discrete_gradient"``
    the energy ``T + q^T K^ q / 2 + U^`` never increases without input.
    The validation trajectory, when given, decides when to stop (the best
    weights by its loss are kept). Fitting needs torch (the ``ml`` extra);
    the fitted model is numpy only (steps, saves and loads without torch).

    Parameters
    ----------
    terms, regularization, solver, mass, mass_orthonormal, stiffness_margin
        Step 1's (:class:`~femrom.inference.SecondOrderLearner`): e.g. ``terms=["damping"]``; with
        ``"hysteresis"`` (or ``"learned_hysteresis"``, or the class :class:`LearnedHysteresis`) among
        them, learned Jenkins sliders along one reduced direction join the model (docs/spml.md,
        "SpML with learned sliders"): their weights start at :class:`IwanLOpInf`'s fit, are solved in
        every least-squares stage (non-negative, in the monotone shape) and refined by L-BFGS with
        every other weight. The model then steps with Newmark (a return mapping; the sliders' state).
    config : SpMLConfig
    smoothing : Smoothing, True, "auto" or None
        Denoise each training and validation trajectory before both steps (:class:`Smoothing`; for
        noisy states: their noise is noise in the regressors, docs/spml.md, "Convergence").
        ``"auto"`` (default): :meth:`Smoothing.auto`, only the trajectories whose estimated noise
        is at least 1e-3 of their RMS (exact and integrator data estimate 1e-12 to 1e-4 and are kept
        as given); ``True``: every trajectory; ``None``: the data as given.
    progress : bool or None
        The progress line with the loss (``None``: on a terminal, in a log every 30 s).

    Attributes
    ----------
    operators_ : ReducedOperators
        Step 1's terms with ``M^`` in place of its mass, :class:`LearnedPotential`,
        :class:`LearnedDissipation` and the output map.
    linear_ : LagrangianOpInf
        The fitted step 1.
    config_ : SpMLConfig
        The settings used (``learn_dissipation`` decided).
    mass_ : (r, r) ndarray
    potential_ : LearnedPotential or None
    dissipation_ : LearnedDissipation or None
    hysteresis_ : LearnedHysteresis or None
        The learned sliders (with the ``"hysteresis"`` term).
    history_ : list of dict
        ``iteration``, ``loss`` (training), ``validation_loss`` at every check of L-BFGS, ``kept``
        where the weights were the best so far.
    stages_ : list of dict
        ``stage`` ("step 1", "least squares", "L-BFGS", "rollout"), ``seconds``, ``loss``, ``validation_loss``
        after it (``pruned``: whether a least-squares solve switched the networks off); the
        "output error" stage's ``cost`` and ``cost_before`` (half the noise-weighted squared misfit),
        ``expected`` (the noise's share: half the number of residuals), ``validation_cost(_before)``,
        ``steps``, ``networks_off`` (the candidate with the networks switched off won), ``projected``
        (matrices put back on their cones) and ``kept``, or ``skipped`` with the reason.
    best_iteration_, iterations_ : int
    loss_ : float
        The relative training loss of the kept weights; ``linear_loss_`` step 1's.
    training_seconds_ : float
    smoothed_ : list of bool or None
        Per training trajectory, whether the smoothing replaced it (``None`` without smoothing).
    """

    method = "spml"

    def __init__(self, terms=(), *, config: SpMLConfig = SpMLConfig(), regularization=0.0, solver=FastSolver(),
                 mass: np.ndarray | None = None, mass_orthonormal: bool = True, stiffness_margin: float = 1e-10,
                 smoothing: Smoothing | bool | str | None = "auto", progress: bool | None = None):
        if not torch_available():
            raise ImportError(TORCH_MISSING)
        if not isinstance(config, SpMLConfig):
            raise FemromTypeError(f"config must be an SpMLConfig, got {type(config).__name__}")
        self.config, self.progress = config, progress
        self.smoothing = Smoothing.of(smoothing)
        terms = (terms,) if isinstance(terms, (str, type, ReducedTerm)) else tuple(terms)
        sliders = [t for t in terms if t is LearnedHysteresis or (isinstance(t, str) and t in HYSTERESIS_TERMS)]
        if len(sliders) > 1:
            raise FemromValueError(f"each term may be named once, got the hysteresis as {sliders}")
        self.hysteresis = bool(sliders)
        terms = [t for t in terms if not (t is LearnedHysteresis or (isinstance(t, str) and t in HYSTERESIS_TERMS))]
        self.linear = LagrangianOpInf(terms, regularization=regularization, solver=solver, mass=mass,
                                      mass_orthonormal=mass_orthonormal, stiffness_margin=stiffness_margin)
        self.linear_options = {"regularization": regularization, "solver": solver, "mass": mass,
                               "mass_orthonormal": mass_orthonormal, "stiffness_margin": stiffness_margin}

    @property
    def learned_terms(self):
        return [*self.linear.learned_terms, *([LearnedHysteresis] if self.hysteresis else [])]

    @property
    def known_terms(self):
        return self.linear.known_terms

    @classmethod
    def for_system(cls, system, basis: np.ndarray | None = None, *, known_forces: bool = False, **options):
        """An SpML with the learnable terms of ``system``'s effects (damping, ...).

        A known nonlinear force is what SpML learns, so it is left out unless
        ``known_forces`` (then it is projected with ``basis`` and kept, and SpML learns the rest).
        """
        system = getattr(system, "system", system)
        return cls(system_terms(system, basis, known_forces=known_forces), **options)

    @classmethod
    def for_training(cls, training, r: int, *, terms=None, extra_terms=(), known_forces: bool = False, **options):
        """``(learner, data, validation)`` at size ``r`` of a study's training set: the given ``terms``, or
        the system's learnable ones (:meth:`for_system`) and ``extra_terms``; SpML stops on the validation runs."""
        return terms_for_training(cls, training, r, terms, extra_terms, options, {"known_forces": known_forces})

    # -- the regression's pieces on any data ------------------------------------------------
    def _arrays(self, data: SecondOrderData, sliders: LearnedHysteresis | None = None):
        """``(Q^T, Q'^T, Q''^T, Y^T, [D_j^T], ||Q''||_F^2, E^T)``: step 1's target (``M_0 Q''`` and
        the known terms), the data blocks of its learned linear terms, as (K, .) arrays, and the
        stretches (K, p) of ``sliders`` along the data's history (``None`` without)."""
        linear = self.linear
        Y = linear._target(data)
        blocks = [cls.datablock(data).T for cls in linear._learned(data)]
        norm = float(np.sum(data.accelerations ** 2))
        stretches = None if sliders is None else \
            slider_stretches(sliders.direction @ data.states, sliders.thresholds, data.starts).T
        return (data.states.T, data.velocities.T, data.accelerations.T, Y.T, blocks,
                max(norm, np.finfo(float).tiny), stretches)

    def _linear_specs(self, data: SecondOrderData, arrays) -> list:
        """Step 1's learned linear terms: name, structure, matrix, ``eps`` shift and a scale floor."""
        force = np.sqrt(arrays[5] / data.states.size)
        specs = []
        for cls, D in zip(self.linear._learned(data), arrays[4]):
            typical = force / max(float(np.sqrt(np.mean(D * D))), np.finfo(float).tiny)
            structure = {"spd": "spd", "psd": "psd", "symmetric": "symmetric"}.get(cls.structure, "free")
            specs.append({"name": cls.name, "structure": structure, "matrix": self.linear.coefficients_[cls.name],
                          "shift": self.linear.stiffness_shift_ if structure == "spd" else 0.0,
                          "floor": np.sqrt(1e-2 * typical) if structure == "psd" else 1e-2 * typical})
        return specs

    def _own(self, data: SecondOrderData) -> SecondOrderData:
        """The data without projected known forces unless a known force term pairs with them: the
        nonlinear force is what SpML learns, so it must not see its projection (a study's data carry
        it for the learners that know the force)."""
        if data.nonlinear_forces is not None and self.linear.nonlinear is None:
            return replace(data, nonlinear_forces=None)
        return data

    def _mass0(self, r: int) -> np.ndarray:
        return np.eye(r) if self.linear.mass is None else self.linear.mass

    # -- fit ---------------------------------------------------------------------------------
    def fit(self, data, *, validation=None) -> "SpML":
        r"""Step 1 (L-OpInf) on ``data``, then step 2 (module docstring).

        Parameters
        ----------
        data : SecondOrderData or list of SecondOrderData
            Reduced training trajectories (with inputs when the model has inputs). Projected
            known forces in them are ignored unless a known force term was given.
        validation : SecondOrderData or list, optional
            Trajectories not trained on: their loss picks the kept weights and stops
            the fit (without them, the training loss does).

        Returns
        -------
        self
        """
        backend = _backend()
        import torch

        tic = time.perf_counter()
        self.smoothed_ = None
        measured = (data, validation)
        if self.smoothing is not None:
            data = self.smoothing.apply(data)
            validation = None if validation is None else self.smoothing.apply(validation)
            self.smoothed_ = [not t.get("kept", False) for d in (data if isinstance(data, (list, tuple)) else [data])
                              for t in _trajectory_reports(d)]
        pieces = list(data) if isinstance(data, (list, tuple)) else [data]
        if self.config.output_error is True and self._output_error_obstacle(pieces) is not None:
            raise FemromValueError(f"SpMLConfig.output_error=True is not possible with "
                                   f"{self._output_error_obstacle(pieces)}")
        held = None if validation is None else list(validation) if isinstance(validation, (list, tuple)) \
            else [validation]
        data = self._own(concatenate(data) if isinstance(data, (list, tuple)) else data)
        if validation is not None:
            validation = self._own(concatenate(validation) if isinstance(validation, (list, tuple)) else validation)
            if validation.r != data.r:
                raise FemromValueError(f"validation data have r = {validation.r}, the training data r = {data.r}")
        self.linear_ = self.linear.fit(data)
        linear_ops = self.linear.operators_
        r, cfg = data.r, self.config
        train_arrays = self._arrays(data)
        validation_arrays = None if validation is None else self._arrays(validation)
        scales = _scales(data, train_arrays[5])
        if cfg.learn_dissipation is None:     # with sliders, they are the learned dissipation (docs/spml.md)
            cfg = replace(cfg, learn_dissipation=self.linear.damping and not self.hysteresis)
        self.config_ = cfg
        specs = self._linear_specs(data, train_arrays)
        sliders, start_stage = None, None
        if self.hysteresis:
            tic_sliders = time.perf_counter()
            sliders, matrices = self._slider_start(data, cfg)
            for spec in specs:               # step 1's linear terms: the sliders' fit's
                spec["matrix"] = matrices.get(spec["name"], spec["matrix"])
            train_arrays = self._arrays(data, sliders.hysteresis_)
            validation_arrays = None if validation is None else self._arrays(validation, sliders.hysteresis_)
            start_stage = {"stage": "sliders (IwanLOpInf)", "seconds": time.perf_counter() - tic_sliders,
                           "residual": sliders.residual_, "linear_residual": sliders.linear_residual_}
        generator = torch.Generator().manual_seed(int(cfg.seed))
        module = backend.SpMLModule(r, cfg, scales, self._mass0(r), specs, generator, hysteresis=None
                                    if sliders is None else self._slider_spec(sliders, cfg.hysteresis_monotone))
        rollouts = None
        if cfg.rollout_steps and not self.linear.known_terms:
            rollouts = (_trajectories(pieces), None if held is None else _trajectories(held))
        with Progress(cfg.max_iterations, "SpML fit", enabled=self.progress) as progress:
            result = backend.train(module, train_arrays, validation_arrays, cfg, progress, rollouts)
        self._module = module                     # the torch side, for diagnostics (not saved)
        mass, linear, polynomial, u_network, powers, f_network = module.export()
        self.linear_matrices_ = linear
        self.history_ = result["history"]
        self.stages_ = ([start_stage] if start_stage else []) + result["stages"]
        self.best_iteration_, self.iterations_ = result["best_iteration"], result["iterations"]
        self.mass_ = mass
        self.potential_ = None if polynomial is None and u_network is None else \
            LearnedPotential(r, polynomial, u_network)
        self.dissipation_ = None if powers is None and f_network is None else \
            LearnedDissipation(r, powers, f_network)
        self.hysteresis_ = None
        if module.hysteresis is not None:
            with torch.no_grad():
                weights = module.hysteresis_weights().numpy().copy()
            self.hysteresis_ = LearnedHysteresis(sliders.hysteresis_.direction, sliders.hysteresis_.thresholds,
                                                 np.clip(weights, 0.0, None))
        self.linear_loss_ = self._loss(data, {n: self.linear.coefficients_[n] for n in linear}, step1=True)
        self.training_seconds_ = time.perf_counter() - tic
        self.loss_ = self._loss(data, linear)
        self.operators_ = self._operators(linear_ops, data)
        stage = self._output_error(measured, pieces, held, data, cfg)
        if stage is not None:
            self.stages_.append(stage)
            if stage.get("kept"):
                self.loss_ = self._loss(data, self.linear_matrices_)
        self.training_seconds_ = time.perf_counter() - tic
        self.operators_ = self._operators(linear_ops, data)
        return self

    def _output_error_obstacle(self, pieces) -> str | None:
        """Why the output-error stage cannot run on ``pieces`` with this model (``None``: it can)."""
        if self.hysteresis:
            return "sliders (their state is not followed by the sensitivities)"
        if self.linear.known_terms:
            return "known force terms"
        if any(sampling_step(d) is None for d in pieces):
            return "data without a uniform sampling step"
        return None

    def _output_error(self, measured, pieces, held, data, cfg: SpMLConfig) -> dict | None:
        """The output-error stage (:attr:`SpMLConfig.output_error`) on the measured trajectories from the
        (smoothed) ``pieces``' initial states; updates the learned parts when kept. Returns its record."""
        wanted = bool(self.smoothed_ and any(self.smoothed_)) if cfg.output_error == "auto" else cfg.output_error
        if not wanted:
            return None
        reason = self._output_error_obstacle(pieces)
        if reason is not None:          # output_error=True was refused at the start of the fit
            return {"stage": "output error", "skipped": reason}
        free = [cls.name for cls in self.linear._learned(data)] if cfg.refine_linear else []
        if cfg.learn_mass:
            free.append("mass")
        if self.potential_ is not None and self.potential_.polynomial is not None:
            free.append("learned_potential")
        train_raw, validation_raw = measured
        settings = OutputError(iterations=int(cfg.output_error_iterations), substeps=int(cfg.output_error_substeps))
        tic = time.perf_counter()
        # two candidates, as in the least-squares stage: the networks as trained (fixed), and switched off
        # (a fixed network the monomials cannot take back biases a polynomial truth's fit)
        candidates = [(self.operators_, False)]
        networks = (self.potential_ is not None and self.potential_.network is not None) or self.dissipation_ is not None
        if networks and "learned_potential" in free:
            pruned = self.operators_.with_terms(LearnedPotential(self.potential_.r, self.potential_.polynomial))
            candidates.append((pruned.without(LearnedDissipation.name), True))
        # a few steps each, then the better one to the end: the candidates have the same free parameters, so
        # the lower output error over all trajectories wins (the validation's alone is too few samples to tell
        # two fits a few units of cost apart)
        first = replace(settings, iterations=min(CANDIDATE_STEPS, settings.iterations)) if len(candidates) > 1 \
            else settings
        results = []
        total = first.iterations * len(candidates) + settings.iterations - first.iterations
        with Progress(total, "SpML output error", enabled=self.progress) as bar:
            def shown(step, cost):
                bar.label = f"SpML output error: cost {cost:.6g}"
                bar.update(1)

            for operators, switched_off in candidates:
                result = output_error_refinement(operators, train_raw, free, start_from=pieces,
                                                 validation=validation_raw, validation_start_from=held,
                                                 settings=first, progress=shown)
                results.append((result["cost"] + result.get("validation_cost", 0.0), switched_off, result))
            _, switched_off, result = min(results, key=lambda item: item[0])
            if first.iterations < settings.iterations and result["steps"] == first.iterations:
                steps = result["steps"]
                result = output_error_refinement(result["operators"], train_raw, free,
                                                 initial_states=result["initial_states"], validation=validation_raw,
                                                 validation_start_from=held, progress=shown,
                                                 settings=replace(settings, iterations=settings.iterations - steps))
                result["steps"] += steps
        refined = result["operators"]
        projected = []
        for name in free:
            term = refined.term(name)
            if name == "learned_potential" or term.structure not in ("spd", "psd"):
                continue
            floor = self.linear.stiffness_shift_ if name == "stiffness" else 0.0
            w, V = np.linalg.eigh(0.5 * (term.matrix + term.matrix.T))
            low = floor if term.structure == "psd" or name == "stiffness" else 1e-12 * max(float(w.max()), 0.0)
            if w.min() < low:
                projected.append(name)
                refined = refined.with_terms(type(term)((V * np.maximum(w, low)) @ V.T))
        before = results[0][2].get("validation_cost_before", results[0][2]["cost_before"])
        better = result.get("validation_cost", result["cost"]) < before
        record = {"stage": "output error", "seconds": time.perf_counter() - tic, "cost": result["cost"],
                  "cost_before": results[0][2]["cost_before"], "expected": result["expected"], "steps": result["steps"],
                  "parameters": result["parameters"], "networks_off": switched_off, "projected": projected,
                  "kept": bool(better)}
        if "validation_cost" in result:
            record.update(validation_cost=result["validation_cost"], validation_cost_before=before)
        if better:
            if "mass" in free:
                self.mass_ = refined.term("mass").matrix
            for name in free:
                if name in self.linear_matrices_:
                    self.linear_matrices_[name] = refined.term(name).matrix
            if "learned_potential" in free:
                self.potential_ = refined.term("learned_potential")
            if switched_off:
                self.dissipation_ = None
        return record

    def _slider_start(self, data: SecondOrderData, cfg: SpMLConfig):
        """The sliders' start: :class:`IwanLOpInf` on the data (thresholds, top slider, weights, and its
        ``K^, C^, B^`` as step 1's linear terms), the accelerations taken as ``M_0 Q''``; and those matrices."""
        if self.linear.known_terms:
            raise FemromValueError("SpML: the hysteresis term does not combine with known force terms")
        if cfg.rollout_steps:
            raise FemromValueError("SpML: the hysteresis term does not combine with SpMLConfig.rollout_steps "
                                   "(the rollout does not step sliders)")
        names = [cls.name for cls in self.linear._learned(data) if cls.name != "stiffness"]
        unknown = [n for n in names if n not in SLIDER_LINEAR_TERMS]
        if unknown:
            raise FemromValueError(f"SpML: the hysteresis term combines with the linear terms "
                                   f"{', '.join(SLIDER_LINEAR_TERMS)}, not {unknown}")
        mass0 = self._mass0(data.r)
        shifted = data if self.linear.mass is None else replace(data, accelerations=mass0 @ data.accelerations)
        iwan = IwanLOpInf(names, thresholds=cfg.hysteresis_thresholds if np.ndim(cfg.hysteresis_thresholds) == 0
                          else np.asarray(cfg.hysteresis_thresholds), threshold_span=cfg.hysteresis_span,
                          direction=None if cfg.hysteresis_direction is None else np.asarray(cfg.hysteresis_direction),
                          monotone=cfg.hysteresis_monotone,
                          stiffness_margin=self.linear_options["stiffness_margin"]).fit(shifted)
        matrices = {t.name: t.matrix for t in iwan.operators_.terms if t.name in ("stiffness", *SLIDER_LINEAR_TERMS)}
        return iwan, matrices

    @staticmethod
    def _slider_spec(iwan: IwanLOpInf, monotone: bool) -> dict:
        """The start of the sliders in the torch module: direction, thresholds, weights and their shape
        (the top slider; with explicit thresholds, the largest weight's)."""
        h = iwan.hysteresis_
        top = None
        if monotone:
            top = int(np.argmin(np.abs(h.thresholds - iwan.top_threshold_))) if iwan.top_threshold_ is not None \
                else int(np.argmax(h.weights))
        weights = h.weights.copy()
        if top is not None:            # in the shape: nondecreasing below the top, nothing above
            weights[:top] = np.minimum.accumulate(weights[:top][::-1])[::-1]
            weights[top + 1:] = 0.0
        return {"direction": h.direction, "thresholds": h.thresholds, "weights": weights, "top": top,
                "monotone": monotone}

    def _operators(self, linear_ops: ReducedOperators, data) -> ReducedOperators:
        refined = {cls.name: cls.from_coefficients(self.linear_matrices_[cls.name])
                   for cls in self.linear._learned(data)}
        terms = [refined.get(t.name, t) for t in linear_ops.terms if t.name != "mass"]
        if self.config.learn_mass or self.linear.mass is not None:
            terms.append(term_class("mass")(self.mass_))
        terms += [t for t in (self.potential_, self.dissipation_, self.hysteresis_) if t is not None]
        return ReducedOperators(tuple(terms), self.describe())

    def nonlinear_forces(self, Q: np.ndarray, Vel: np.ndarray | None = None, starts=(0,)) -> np.ndarray:
        """(r, K) ``grad U^(Q) + grad F^(Vel)`` and the sliders' force along the history ``Q`` (each
        trajectory of ``starts`` loaded from rest to its first column): the learned nonlinear forces."""
        out = np.zeros(np.shape(Q))
        if self.potential_ is not None:
            out += self.potential_.forces(Q)
        if self.dissipation_ is not None and Vel is not None:
            out += self.dissipation_.forces(Q, Vel)
        if getattr(self, "hysteresis_", None) is not None:
            out += self.hysteresis_.forces(Q, starts=starts)
        return out

    def _loss(self, data: SecondOrderData, linear: dict, step1: bool = False) -> float:
        """The relative residual ``||M^^-1 R||_F^2 / ||Q''||_F^2`` of the exported (numpy) model
        (``step1``: of step 1's model alone)."""
        q, v, a, Y, blocks, norm, _ = self._arrays(data)
        R = Y.T + sum(linear[cls.name] @ D.T for cls, D in zip(self.linear._learned(data), blocks))
        mass = self._mass0(data.r)
        if not step1:
            R = R + (self.mass_ - mass) @ data.accelerations \
                + self.nonlinear_forces(data.states, data.velocities, data.starts)
            mass = self.mass_
        R = np.linalg.solve(mass, R)
        return float(np.sum(R * R) / norm)

    def describe(self) -> dict:
        out = {"method": self.method, "config": asdict(getattr(self, "config_", self.config)),
               "smoothing": None if self.smoothing is None else asdict(self.smoothing),
               "linear": self.linear.describe() if self.linear.is_fitted else {"method": self.linear.method}}
        if getattr(self, "history_", None) is not None:
            out.update(loss=self.loss_, linear_loss=self.linear_loss_, iterations=self.iterations_,
                       best_iteration=self.best_iteration_, training_seconds=self.training_seconds_)
        if getattr(self, "hysteresis_", None) is not None:
            out["hysteresis"] = self.hysteresis_.describe()
        return out


def _trajectories(datasets) -> list:
    """``{"q", "v", "u", "dt"}`` of every trajectory of ``datasets`` (split at their ``starts``), for the
    rollout refinement: the sampling step from the times."""
    out = []
    for d in datasets:
        step = sampling_step(d)
        if step is None:
            raise FemromValueError("SpMLConfig.rollout_steps needs data with uniformly sampled times")
        bounds = list(d.starts) + [d.n_samples]
        for a, b in zip(bounds[:-1], bounds[1:]):
            out.append({"q": d.states[:, a:b], "v": d.velocities[:, a:b], "dt": float(step),
                        "u": None if d.inputs is None else d.inputs[:, a:b]})
    return out


def _scales(data: SecondOrderData, target_norm2: float) -> dict:
    """Scales of the training coordinates (module :mod:`._spml_torch`): one RMS for all of
    ``q^`` and one for all of ``q^'`` (isotropic: POD coordinates span orders of magnitude,
    and a per-coordinate scale would blow the random initial forces of a small coordinate up
    by ``1 / s_i``), and the energy scales ``f s`` from the RMS force ``f``."""
    r = data.r
    sq = max(float(np.sqrt(np.mean(data.states ** 2))), np.finfo(float).tiny)
    sv = max(float(np.sqrt(np.mean(data.velocities ** 2))), np.finfo(float).tiny)
    force = np.sqrt(target_norm2 / data.states.size)
    return {"q": np.full(r, sq), "v": np.full(r, sv), "potential": force * sq, "dissipation": force * sv}


def _trajectory_reports(data) -> list:
    """The per-trajectory entries of a smoothed trajectory's ``diagnostics["smoothing"]``: a dict for a
    trajectory kept as measured, a list of per-coordinate fits for a smoothed one."""
    return [t if isinstance(t, dict) else {} for t in data.diagnostics["smoothing"]["trajectories"]]
