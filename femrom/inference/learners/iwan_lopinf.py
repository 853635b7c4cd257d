r"""L-OpInf with a learned Iwan element: a reduced model of a jointed structure that keeps its hysteresis."""

from __future__ import annotations

import time
import warnings
from dataclasses import asdict

import numpy as np

from femrom._errors import FemromRuntimeError, FemromTypeError, FemromValueError
from femrom.inference._data import SecondOrderData, concatenate, sampling_step
from femrom.inference._learner import Learner, register_learner
from femrom.inference._operators import ReducedOperators
from femrom.inference._sdp import ConicSolver
from femrom.inference._smoothing import Smoothing
from femrom.inference._terms import term_class
from femrom.inference.terms.learned_hysteresis import LearnedHysteresis, slider_stretches

#: Linear terms the learner can fit beside the stiffness.
LINEAR_TERMS = ("damping", "input")


@register_learner("iwan_lopinf")
class IwanLOpInf(Learner):
    r"""Lagrangian operator inference with a learned parallel-Jenkins (Iwan) term along one direction.

    .. math::

        \min_{\hat K \succeq \varepsilon I,\; \hat C \succeq 0,\; \hat B,\; k \ge 0}
        \Big\| \ddot{\hat Q} + \hat C \dot{\hat Q} + \hat K \hat Q - \hat B U
            + a\, k^T E(a^T \hat Q) \Big\|_F^2 + \rho \|\text{scaled } k\|^2 ,

    ``E`` (p, K) the stretches of ``p`` Jenkins sliders of thresholds ``phi_i`` driven by the
    data's coordinate ``x = a . q^`` (:func:`slider_stretches`, each trajectory loaded from rest
    to its first column), ``M^ = I`` (a mass-orthonormal basis). For fixed ``a`` and thresholds
    the slider stretches are data, so the problem is convex in ``(K^, C^, B^, k)``; it is solved as
    a second-order cone program (cvxpy, Clarabel) on the QR factor of the column-scaled design:
    the hysteresis of a history-dependent joint is learned by the same regression as the linear
    operators. Structure by construction: ``K^`` SPD, ``C^`` PSD and ``k >= 0`` make the
    learned model passive (:class:`LearnedHysteresis`), for any data.

    A smooth ``F(q')`` of a history-free dissipation cannot do this: it dissipates per cycle
    a power of the velocity amplitude, while a slipping joint dissipates per cycle by friction
    (``4 k_i phi_i (A - phi_i)`` per slider) and softens as sliders let go.

    Parameters
    ----------
    terms : sequence of str
        Linear terms beside ``K^``: ``"damping"``; ``"input"`` (fitted anyway when the data
        carry inputs).
    thresholds : int or (p,) array
        Number of sliders, their thresholds ``phi_i`` log-spaced over ``threshold_span`` times
        the training data's ``max |a . q^|``; or the thresholds themselves.
    threshold_span : (2,) floats
    direction : (r,) array, optional
        ``a``; default ``e_1``, the leading coordinate (of a POD basis: the most energetic).
    monotone : bool
        With generated thresholds, the shape of Segalman's densities (a power law ``phi^chi``,
        ``chi > -1``, up to ``phi_max``, a delta there, nothing above): ``k_1 <= ... <= k_{j-1}``,
        ``k_j`` free, ``k_i = 0`` above ``j``, linear constraints for each top slider ``j``, the
        ``j`` of the smallest residual kept (``p - 1`` solves). Without it the fit on the jointed
        beam put its largest weight on the weakest slider, a Coulomb element whose damping falls
        with the amplitude.
    band : (2,) floats [Hz], optional
        Fit on the rows of the balance band-passed to ``band`` (zero-phase Butterworth of order 4,
        each trajectory from rest): the balance is linear in the unknowns, so the filtered rows obey
        it too, and what the ``r`` coordinates cannot close outside the band (higher modes, the
        blow's broadband content) stops biasing the hysteresis. Needs uniformly sampled data.
    regularization : float
        ``rho``, on the weights in the scaled problem (each unknown's data column scaled to unit
        norm, the target to norm 1).
    stiffness_margin : float
        ``eps = margin ||Q''|| / ||Q^||``.
    solver : ConicSolver
        The cvxpy solver of the second-order cone program, with its options (default
        ``ConicSolver("clarabel")``).
    smoothing : Smoothing, True, "auto" or None
        Denoise each training and validation trajectory before the fit (:class:`Smoothing`;
        ``"auto"``: only trajectories estimated noisy); ``None`` (default): the data as given.

    Attributes
    ----------
    operators_ : ReducedOperators
        Stiffness, damping, input, :class:`LearnedHysteresis`, output (with output data).
    hysteresis_ : LearnedHysteresis
    residual_ : float
        ``||residual||_F / ||Q''||_F`` on the training data.
    linear_residual_ : float
        The same for the best linear model (``k = 0``) under the same constraints.
    validation_residual_ : float or None
    fit_seconds_ : float
    """

    method = "iwan_lopinf"

    def __init__(self, terms=("damping",), *, thresholds=32, threshold_span=(1e-3, 1.0), direction=None,
                 monotone: bool = True, band=None, regularization: float = 1e-9, stiffness_margin: float = 1e-10,
                 solver: ConicSolver = ConicSolver(), smoothing: Smoothing | bool | str | None = None):
        self.smoothing = Smoothing.of(smoothing)
        terms = (terms,) if isinstance(terms, str) else tuple(terms)
        unknown = [t for t in terms if t not in LINEAR_TERMS]
        if unknown:
            raise FemromValueError(f"iwan_lopinf: unknown terms {unknown}; valid: {', '.join(LINEAR_TERMS)}")
        self.terms = terms
        if np.ndim(thresholds) == 0:
            if not (isinstance(thresholds, (int, np.integer)) and thresholds >= 1):
                raise FemromValueError("thresholds must be a positive integer or an array of values > 0, "
                                       f"got {thresholds!r}")
        else:
            values = np.asarray(thresholds, dtype=float)
            if values.ndim != 1 or values.size == 0 or not np.all(np.isfinite(values)) or np.any(values <= 0):
                raise FemromValueError("thresholds must be a positive integer or a 1-d array of finite values > 0")
        self.thresholds = thresholds
        lo, hi = (float(x) for x in threshold_span)
        if not 0 < lo <= hi:
            raise FemromValueError(f"threshold_span must be 0 < low <= high, got {threshold_span!r}")
        self.threshold_span = (lo, hi)
        self.direction = None if direction is None else np.asarray(direction, dtype=float).ravel()
        if not float(regularization) >= 0:
            raise FemromValueError(f"regularization must be >= 0, got {regularization!r}")
        self.regularization = float(regularization)
        self.monotone = bool(monotone)
        self.band = None if band is None else tuple(float(b) for b in band)
        if self.band is not None and not (len(self.band) == 2 and 0 < self.band[0] < self.band[1]):
            raise FemromValueError(f"band must be (low, high) in Hz with 0 < low < high, got {band!r}")
        self.stiffness_margin = float(stiffness_margin)
        if not isinstance(solver, ConicSolver):
            raise FemromTypeError(f"iwan_lopinf: solver must be a ConicSolver, got {solver!r}")
        self.solver = solver

    @classmethod
    def for_training(cls, training, r: int, *, terms=None, **options):
        """``(learner, data, validation)`` at size ``r``: the given linear ``terms``, or those of the
        training system's effects (damping when it is damped, the input map when it has inputs)."""
        if terms is None:
            system = training.system
            terms = [name for name, present in (("damping", getattr(system, "damping", None) is not None),
                                                ("input", getattr(system, "n_inputs", 0) > 0)) if present]
        return cls(terms, **options), training.reduced(r), training.reduced(r, validation=True)

    # -- the regression ----------------------------------------------------------------
    def _direction(self, r: int) -> np.ndarray:
        if self.direction is None:
            return np.eye(r)[0]
        if self.direction.size != r or not np.any(self.direction):
            raise FemromValueError(f"direction must be a non-zero vector of length r = {r}")
        return self.direction

    def _threshold_values(self, x: np.ndarray) -> np.ndarray:
        if np.ndim(self.thresholds) == 1:
            return np.asarray(self.thresholds, dtype=float)
        top = float(np.max(np.abs(x)))
        if not top > 0:
            raise FemromValueError("iwan_lopinf: the data never move along the hysteresis direction")
        return top * np.geomspace(*self.threshold_span, int(self.thresholds))

    def _blocks(self, data: SecondOrderData, a: np.ndarray, phi: np.ndarray) -> dict:
        blocks = {"stiffness": data.states}
        if "damping" in self.terms:
            if data.velocities is None:
                raise FemromValueError("iwan_lopinf: damping needs the data's velocities")
            blocks["damping"] = data.velocities
        if data.inputs is not None:
            blocks["input"] = -data.inputs
        elif "input" in self.terms:
            raise FemromValueError("iwan_lopinf: the input term needs data with inputs")
        blocks["hysteresis"] = slider_stretches(a @ data.states, phi, data.starts)
        return blocks

    def _design(self, blocks: dict, names: list, a: np.ndarray, r: int) -> tuple[np.ndarray, list]:
        """The regression written on the vector of unknowns: ``vec(residual) = vec(Y) + A x``.

        ``x`` holds the upper triangles of ``K^`` and ``C^`` (row by row), ``B^`` (row-major) and
        ``k``; ``A`` is (r K, n_x), one row per equation and column."""
        cols, layout = [], []
        samples = next(iter(blocks.values())).shape[1]
        for n in names:
            D = blocks[n]
            if n in ("stiffness", "damping"):
                for i in range(r):
                    for j in range(i, r):
                        c = np.zeros((r, samples))
                        c[i] += D[j]
                        if j != i:
                            c[j] += D[i]
                        cols.append(c.ravel())
                layout.append((n, r * (r + 1) // 2))
            elif n == "input":
                for i in range(r):
                    for j in range(D.shape[0]):
                        c = np.zeros((r, samples))
                        c[i] = D[j]
                        cols.append(c.ravel())
                layout.append((n, r * D.shape[0]))
            else:
                for j in range(D.shape[0]):
                    cols.append(np.outer(a, D[j]).ravel())
                layout.append((n, D.shape[0]))
        return np.column_stack(cols), layout

    def _prepare(self, Y: np.ndarray, blocks: dict, a: np.ndarray, hysteresis: bool) -> dict:
        """The design, its column scales and its QR factor, once for every solve on the same blocks."""
        r = Y.shape[0]
        names = [n for n in blocks if hysteresis or n != "hysteresis"]
        A, layout = self._design(blocks, names, a, r)
        y_scale = max(float(np.linalg.norm(Y)), np.finfo(float).tiny)
        scale = np.linalg.norm(A, axis=0)
        scale[scale == 0] = 1.0
        # QR of the column-scaled design: the conic problem sees cond(A), not cond(A)^2
        Qf, Rf = np.linalg.qr(A / scale, mode="reduced")
        return {"hysteresis": hysteresis, "layout": layout, "y_scale": y_scale, "scale": scale, "R": Rf,
                "c": Qf.T @ (Y.ravel() / y_scale)}

    def _solve(self, Y: np.ndarray, blocks: dict, a: np.ndarray, prepared: dict, top: int | None = None) -> dict:
        import cvxpy as cp

        r = Y.shape[0]
        hysteresis, layout, y_scale, scale = (prepared[k] for k in ("hysteresis", "layout", "y_scale", "scale"))
        Rf, c = prepared["R"], prepared["c"]
        x = cp.Variable(Rf.shape[1])
        constraints, offset, slices = [], 0, {}
        eps = self.stiffness_margin * y_scale / max(float(np.linalg.norm(blocks["stiffness"])), np.finfo(float).tiny)
        for n, size in layout:
            slices[n] = slice(offset, offset + size)
            offset += size
        physical = cp.multiply(x, y_scale / scale)           # the unknowns in their own units
        for n in ("stiffness", "damping"):
            if n in slices:
                upper = physical[slices[n]]
                entries = [[None] * r for _ in range(r)]
                m = 0
                for i in range(r):
                    for j in range(i, r):
                        entries[i][j] = entries[j][i] = upper[m]
                        m += 1
                X = cp.bmat([[entries[i][j] for j in range(r)] for i in range(r)])
                constraints.append((X - eps * np.eye(r) if n == "stiffness" else X) >> 0)
        if hysteresis:
            k = physical[slices["hysteresis"]]
            constraints.append(k >= 0)
            if top is not None:        # nondecreasing below the top slider, nothing above it
                if top > 1:
                    constraints.append(cp.diff(k[:top]) >= 0)
                if top + 1 < k.size:
                    constraints.append(k[top + 1:] == 0)
        # the norm itself (a second-order cone), not its square: the solver's tolerance then
        # bounds the residual, not the residual squared
        residual = Rf @ x + c
        if hysteresis and self.regularization:
            residual = cp.hstack([residual, np.sqrt(self.regularization) * x[slices["hysteresis"]]])
        objective = cp.norm(residual)
        problem = cp.Problem(cp.Minimize(objective), constraints)
        with warnings.catch_warnings():         # the status is kept; the chosen fit's is reported by fit
            warnings.filterwarnings("ignore", message="Solution may be inaccurate")
            problem.solve(**self.solver.keywords)
        if x.value is None:
            raise FemromRuntimeError(f"iwan_lopinf: the {self.solver.name} solve failed ({problem.status})")
        values = np.asarray(x.value, dtype=float) * y_scale / scale
        out = {}
        for n, _ in layout:
            v = values[slices[n]]
            if n in ("stiffness", "damping"):
                X = np.zeros((r, r))
                X[np.triu_indices(r)] = v
                out[n] = X + np.triu(X, 1).T
            elif n == "input":
                out[n] = v.reshape(r, -1)
            else:
                out[n] = np.clip(v, 0.0, None)        # the solver's round-off below 0
        R = Y + sum((np.outer(a, out[n]) if n == "hysteresis" else out[n]) @ blocks[n] for n in out)
        out["residual"] = float(np.linalg.norm(R) / y_scale)
        out["status"] = problem.status
        return out

    def _filtered(self, data: SecondOrderData, Y: np.ndarray, blocks: dict) -> tuple:
        """Every row of the target and the blocks through the same zero-phase band-pass, trajectory by
        trajectory (the slider stretches are computed before, from the unfiltered coordinate): the
        balance is linear in the unknowns, so it holds for the filtered rows as well, and the
        regression then weighs only the band where the model has to be right."""
        from scipy.signal import butter, sosfiltfilt

        dt = sampling_step(data)
        if dt is None:
            raise FemromValueError("iwan_lopinf: band filtering needs data sampled at one uniform time step")
        bounds = list(data.starts) + [Y.shape[1]]
        sos = butter(4, self.band, btype="bandpass", fs=1.0 / dt, output="sos")

        def filt(X):
            out = np.empty_like(X)
            for begin, end in zip(bounds[:-1], bounds[1:]):
                out[:, begin:end] = sosfiltfilt(sos, X[:, begin:end], axis=1, padtype="constant")
            return out

        return filt(Y), {n: filt(D) for n, D in blocks.items()}

    # -- fit -----------------------------------------------------------------------------
    def fit(self, data, *, validation=None) -> "IwanLOpInf":
        """Learn ``K^, C^, B^`` and the sliders' stiffnesses from ``data`` (one or a list of trajectories).

        ``validation`` (optional data) only reports :attr:`validation_residual_`."""
        tic = time.perf_counter()
        if self.smoothing is not None:
            data = self.smoothing.apply(data)
            validation = None if validation is None else self.smoothing.apply(validation)
        data = concatenate(data) if isinstance(data, (list, tuple)) else data
        if data.accelerations is None:
            raise FemromValueError("iwan_lopinf: the data need accelerations")
        for name, X in (("states", data.states), ("accelerations", data.accelerations)):
            if not np.all(np.isfinite(X)):
                raise FemromValueError(f"iwan_lopinf: the data's {name} are not finite")
        a = self._direction(data.r)
        phi = self._threshold_values(a @ data.states)
        blocks = self._blocks(data, a, phi)
        Y = data.accelerations
        if self.band is not None:
            Y, blocks = self._filtered(data, Y, blocks)
        linear = self._solve(Y, blocks, a, self._prepare(Y, blocks, a, hysteresis=False))
        prepared = self._prepare(Y, blocks, a, hysteresis=True)
        if self.monotone and np.ndim(self.thresholds) == 0:
            trials = [self._solve(Y, blocks, a, prepared, top=top) for top in range(1, phi.size)]
            best = int(np.argmin([trial["residual"] for trial in trials]))
            fit = trials[best]
            self.top_threshold_ = float(phi[1 + best])
        else:
            fit = self._solve(Y, blocks, a, prepared)
            self.top_threshold_ = None
        if fit["status"] != "optimal":
            warnings.warn(f"iwan_lopinf: {self.solver.name} ended {fit['status']!r} (relative residual "
                          f"{fit['residual']:.3g}); another solver= may settle it", UserWarning, stacklevel=2)
        self.hysteresis_ = LearnedHysteresis(a, phi, fit["hysteresis"])
        terms = [term_class("stiffness")(fit["stiffness"])]
        if "damping" in fit:
            terms.append(term_class("damping")(fit["damping"]))
        if "input" in fit:
            terms.append(term_class("input")(fit["input"]))
        terms.append(self.hysteresis_)
        output = term_class("output").fit(data)
        if output is not None:
            terms.append(output)
        self.residual_, self.linear_residual_ = fit["residual"], linear["residual"]
        self.solver_status_ = fit["status"]
        self.validation_residual_ = None
        if validation is not None:
            valid = concatenate(validation) if isinstance(validation, (list, tuple)) else validation
            vb = self._blocks(valid, a, phi)
            R = valid.accelerations + sum((np.outer(a, fit[n]) if n == "hysteresis" else fit[n]) @ vb[n]
                                          for n in vb if n in fit)
            self.validation_residual_ = float(np.linalg.norm(R) / np.linalg.norm(valid.accelerations))
        self.fit_seconds_ = time.perf_counter() - tic
        self.operators_ = ReducedOperators(tuple(terms), self.describe())
        return self

    def describe(self) -> dict:
        out = {"method": self.method, "terms": ["stiffness", *self.terms, "learned_hysteresis"],
               "threshold_span": list(self.threshold_span), "monotone": self.monotone,
               "band": None if self.band is None else list(self.band), "regularization": self.regularization,
               "solver": self.solver.name,
               "smoothing": None if self.smoothing is None else asdict(self.smoothing)}
        if getattr(self, "hysteresis_", None) is not None:
            out.update(hysteresis=self.hysteresis_.describe(), residual=self.residual_,
                       linear_residual=self.linear_residual_, validation_residual=self.validation_residual_)
        return out
