r"""Six additions to femrom written outside it, as a user would: one class each, joined by registries.

``tests/test_extension_everywhere.py`` imports it by name (it is not part of the femrom package),
runs every addition through a scene's ``[rom]``
study, a ring-down comparison and a stepped sine without any femrom file knowing them:

- ``user_two_slider``: an interface law, two parallel Jenkins sliders (a two-element Iwan);
- ``user_ground_springs``: a scene effect that adds stiffness, a Winkler foundation
  ``k int_Gamma u_c v_c dA`` on one displacement component of a boundary;
- ``fox_goodwin``: a time scheme, Newmark with ``beta = 1/12`` (fourth-order phase, stable
  for ``omega dt < sqrt(6)``), with its frequency map in closed form;
- ``user_cubic_stiffness``: a reduced term ``G^ q^3`` (elementwise cubes), learnable;
- ``user_lstsq``: a learner, plain least squares for ``q^'' + C^ q^' + K^ q^ [+ G^ q^3] = B^ u``,
  ``M^ = I``, with the output map ``E^`` from the outputs;
- ``user_peak``: an experiment, the relative error of a model's largest output over a run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from femrom.fem import ParallelSliderLaw, register_interface_law
from femrom.inference import Learner, ReducedOperators, ReducedTerm, register_learner, register_term
from femrom.integrators import Newmark, register_scheme
from femrom.scene import Effect, LoadConfig, register_effect
from femrom.study import Experiment, register_experiment, rest_start


@register_interface_law
@dataclass(frozen=True)
class TwoSliderLaw(ParallelSliderLaw):
    """Two Jenkins sliders in parallel (stiffnesses ``k_1, k_2`` [Pa/m], slip tractions ``tau_1, tau_2``
    [Pa]) and a linear normal spring ``k_n``."""

    name = "user_two_slider"

    k1: float
    k2: float
    tau1: float
    tau2: float
    normal_stiffness: float

    def __post_init__(self):
        object.__setattr__(self, "slider_stiffness", np.array([self.k1, self.k2], dtype=float))
        object.__setattr__(self, "slider_strength", np.array([self.tau1, self.tau2], dtype=float))


@register_effect
class GroundSprings(Effect):
    r"""``K += k diag(w)``: springs to the ground on component ``component`` of boundary ``at``,
    ``w_i = int_Gamma phi_i dA`` (a Winkler foundation of stiffness ``k`` [Pa/m])."""

    name = "user_ground_springs"
    options = {"at": None, "component": "x", "stiffness": 0.0}
    provides = "stiffness"
    stage = 1

    def assemble(self, build, options):
        space = build.space
        direction = tuple(float(c == options["component"]) for c in space.components)
        weights = build.condensation.vector(space.load_vector(LoadConfig("surface_traction", options["at"],
                                                                         direction=direction)))
        build.add_stiffness(sp.diags(float(options["stiffness"]) * weights, format="csr"))


@register_scheme
@dataclass(frozen=True)
class FoxGoodwin(Newmark):
    r"""Newmark with ``beta = 1/12``, ``gamma = 1/2``: an undamped mode of ``omega`` is stepped at ``Omega``
    with ``cos(Omega dt) = (1 - (1/2 - beta) x) / (1 + beta x)``, ``x = (omega dt)^2``."""

    beta: float = 1.0 / 12.0
    name = "fox_goodwin"

    @property
    def label(self) -> str:
        return "FoxGoodwin"

    def frequency(self, omega, dt):
        x = (np.asarray(omega, dtype=float) * dt) ** 2
        return np.arccos((1.0 - (0.5 - self.beta) * x) / (1.0 + self.beta * x)) / dt

    def continuous_frequency(self, Omega, dt):
        c = np.cos(np.asarray(Omega, dtype=float) * dt)
        return np.sqrt((1.0 - c) / (self.beta * c + 0.5 - self.beta)) / dt


@register_term
class CubicStiffness(ReducedTerm):
    """``G^ q^3`` (cubes elementwise), ``G^`` (r, r) learned freely; data block ``Q^3``."""

    name = "user_cubic_stiffness"
    learnable = True
    structure = "free"
    order = 30

    def __init__(self, matrix):
        self.matrix = np.asarray(matrix, dtype=float)

    @classmethod
    def datablock(cls, data):
        return data.states ** 3

    @classmethod
    def from_coefficients(cls, coefficients):
        return cls(coefficients)

    def lhs(self, q, v=None, a=None, u=None, state=None):
        return self.matrix @ q ** 3

    def tangent(self, q, v=None, state=None):
        return self.matrix * (3.0 * q ** 2)[None, :], None


@register_learner("user_lstsq")
class LeastSquaresOpInf(Learner):
    r"""``min || Q^'' + C^ Q^' + K^ Q^ [+ G^ Q^3] - B^ U ||_F`` by ``numpy.linalg.lstsq``, ``M^ = I``;
    ``E^ = Y Q^+`` when the data carry outputs."""

    method = "user_lstsq"

    def __init__(self, cubic: bool = False):
        self.cubic = bool(cubic)

    def fit(self, data, *, validation=None):
        blocks = [data.velocities, data.states] + ([data.states ** 3] if self.cubic else [])
        if data.inputs is not None:
            blocks.append(-data.inputs)
        D = np.vstack(blocks)
        X = -np.linalg.lstsq(D.T, data.accelerations.T, rcond=None)[0].T
        r = data.states.shape[0]
        C, K = X[:, :r], X[:, r:2 * r]
        cubic = CubicStiffness(X[:, 2 * r:3 * r]) if self.cubic else None
        B = X[:, (3 if self.cubic else 2) * r:] if data.inputs is not None else None
        E = None if data.outputs is None else np.linalg.lstsq(data.states.T, data.outputs.T, rcond=None)[0].T
        self.operators_ = ReducedOperators.from_matrices(K, damping=C, input_matrix=B, output_matrix=E,
                                                         nonlinear=cubic, metadata={"method": self.method})
        return self


@register_experiment("user_peak")
class PeakResponse(Experiment):
    """``|max|y| / max|y_ref| - 1|`` of one output over a run: the model from ``initial`` (default its rest,
    :func:`femrom.study.rest_start`) under ``inputs``; ``y = E V q^''`` with ``sensors`` ``E``, else the
    model's own outputs."""

    def __init__(self, times, inputs, reference, *, output=0, initial=None, rest_state=None, sensors=None,
                 scheme=None, label="peak"):
        self.times, self.inputs, self.output, self.label = times, inputs, int(output), label
        self.reference_peak = float(np.max(np.abs(np.asarray(reference)[self.output])))
        self.initial, self.rest_state, self.sensors, self.scheme = initial, rest_state, sensors, scheme

    def run(self, model):
        initial = self.initial if self.initial is not None else rest_start(model, self.rest_state)
        options = {} if self.scheme is None else {"scheme": self.scheme}
        solution = model.predict(self.times, self.inputs, initial=initial, **options)
        y = solution.outputs if self.sensors is None else self.sensors @ (model.basis @ np.asarray(solution.a))
        return {"peak_error": abs(float(np.max(np.abs(y[self.output]))) / self.reference_peak - 1.0)}

    @classmethod
    def for_study(cls, state, *, run):
        fom = state.runs[run]
        return [cls(fom.times, fom.inputs, fom.outputs, initial=(fom.q0, fom.v0), label=f"peak {run}")]
