r"""Interface (joint friction) laws: traction from the relative displacement of a contact point.

A zero-thickness interface element at a pair of matching nodes sees the
relative displacement of the pair in the pair's local frame,

.. math::

    \Delta = (g_{t1}, g_{t2}, g_n), \qquad g_n > 0 \text{ open}, \quad g_n < 0 \text{ penetration},

and an *interface law* maps it, with an internal state (slider positions),
to the traction ``t`` (force per unit area, work-conjugate to ``Delta``:
the force the interface exerts against the relative displacement, so
``t_n = k_n g_n < 0`` in compression) and its consistent tangent
``dt / dDelta`` (3, 3). A law is vectorised over ``s`` contact points:
``gap`` is (s, 3), the traction (s, 3), the tangent (s, 3, 3).

The state follows the return-map convention of :class:`femrom.fem.JenkinsForce`:
during the Newton iterations of a time step the state is frozen at its
committed value, so the traction is a function of the gap alone (backward
Euler over the step); :meth:`InterfaceLaw.commit` returns the state after a
converged step, and :meth:`InterfaceLaw.dissipation` the energy per unit
area the sliders dissipate in that step.

Laws are one class each, one module each in :mod:`femrom.fem.interface_laws`,
found by name in :data:`INTERFACE_LAWS` (a scene selects one by a string):
:func:`interface_law` builds one from its name and parameters.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from femrom._errors import FemromValueError
from femrom._registry import Registry
from femrom.fem._law_kernels import compiled_kernels
from femrom.fem._law_kinds import PARALLEL_SLIDERS

#: The interface laws by name (the modules of :mod:`femrom.fem.interface_laws` are imported on first read).
INTERFACE_LAWS = Registry("interface law", "femrom.fem.interface_laws", order=lambda name, cls: name,
                          valid="registered")


def register_interface_law(cls):
    """Class decorator: the law can be selected by ``cls.name`` (:func:`interface_law`)."""
    if not getattr(cls, "name", ""):
        raise FemromValueError(f"interface law class {cls.__name__} has no name")
    INTERFACE_LAWS.add(cls.name, cls)
    return cls


def interface_law(name: str, **parameters) -> "InterfaceLaw":
    """The registered law ``name`` with its ``parameters`` (one FemromValueError for an unknown name)."""
    return INTERFACE_LAWS.get(name)(**parameters)


def interface_law_from_parameters(parameters: dict) -> "InterfaceLaw":
    """Inverse of :meth:`InterfaceLaw.parameters` (numbers may come back as 0-d arrays)."""
    values = dict(parameters)
    cls = INTERFACE_LAWS.get(str(values.pop("name")))
    return cls(**{key: float(value) for key, value in values.items()})   # the law coerces its integers


def check_parameters(law, rules) -> None:
    """Validate and coerce the parameters of a frozen dataclass ``law`` in place.

    ``rules``: ``(name, valid, ok)`` triples, ``ok(value) -> bool`` on the float value and
    ``valid`` the range in words. The first bad one raises one FemromValueError naming it.
    """
    kinds = {f.name: f.type for f in dataclasses.fields(law)}
    for name, valid, ok in rules:
        given = getattr(law, name)
        try:
            value = float(given)
        except (TypeError, ValueError):
            value = float("nan")
        if not (np.isfinite(value) and ok(value)):
            raise FemromValueError(f"{type(law).__name__}: {name} must be {valid}, got {given!r}")
        object.__setattr__(law, name, int(value) if kinds.get(name) in (int, "int") else value)


def slider_return(trial, limit):
    r"""Return map of 1-D Coulomb sliders: ``t = clip(t^tr, -tau, tau)``, and where they stick (``|t^tr| < tau``).

    The one return map of a Jenkins element along one direction, whatever its units:
    a spring force ``k (x - z)`` against a slip force (:class:`~femrom.fem.JenkinsForce`),
    a spring stretch ``e + dx`` against a slip stretch (a learned slider). Its 2-D
    (isotropic) form is :func:`radial_return`. ``trial`` and ``limit`` broadcast.
    Returns ``(t, sticking)``: the returned values and a bool array.
    """
    trial = np.asarray(trial, dtype=float)
    return np.clip(trial, -limit, limit), np.abs(trial) < limit


def radial_return(trial: np.ndarray, limit: np.ndarray):
    r"""Return map of isotropic 2-D Coulomb sliders: the trial traction projected onto ``|t| <= limit``.

    .. math::

        t = \begin{cases} t^{tr} & |t^{tr}| \le \tau \text{ and } \tau > 0 \text{ (stick)} \\
        \tau\, t^{tr} / |t^{tr}| & \text{otherwise (slip along the trial traction)} \end{cases}

    A slider of zero limit (an open contact) always slips with zero traction.

    Parameters
    ----------
    trial : (..., 2) ndarray
        Trial tractions ``k (g_t - z)``.
    limit : (...) ndarray
        Slip limits ``tau >= 0`` (broadcast against ``trial[..., 0]``).

    Returns
    -------
    traction : (..., 2) ndarray
    ratio : (...) ndarray
        ``t = ratio * t_trial`` (1 in stick, ``tau / |t_trial|`` in slip).
    direction : (..., 2) ndarray
        ``t_trial / |t_trial|`` (zero where the trial traction is zero).
    slipping : (...) bool ndarray

    The derivative of ``t`` is ``I`` in stick and ``ratio (I - d d^T)`` (in
    ``t_trial``) plus ``d`` (in ``tau``) in slip: :func:`radial_return_tangent`.
    """
    norm = np.hypot(trial[..., 0], trial[..., 1])
    limit = np.broadcast_to(limit, norm.shape)
    slipping = (norm > limit) | (limit <= 0.0)
    safe = np.where(norm > 0.0, norm, 1.0)
    direction = trial / safe[..., None]
    ratio = np.where(slipping, limit / safe, 1.0)
    return ratio[..., None] * trial, ratio, direction, slipping


def radial_return_tangent(ratio: np.ndarray, direction: np.ndarray, slipping: np.ndarray) -> np.ndarray:
    r"""(..., 2, 2) ``dt / dt_trial``: ``I`` in stick, ``ratio (I - d d^T)`` in slip."""
    eye = np.eye(2)
    projector = eye - direction[..., :, None] * direction[..., None, :]
    return np.where(slipping[..., None, None], ratio[..., None, None] * projector, eye)


def radial_return_derivative(dtrial, ratio, direction, slipping, dlimit=None) -> np.ndarray:
    r"""(..., 2, m) forward derivative of :func:`radial_return` along ``m`` directions.

    ``dtrial`` (..., 2, m) is the derivative of the trial traction, ``dlimit`` (..., m) of the
    slip limit (``None``: a fixed limit). Stick: ``dt = dt^tr``; slip:
    ``dt = ratio (I - d d^T) dt^tr + d dtau``.
    """
    along = np.einsum("...i,...im->...m", direction, dtrial)
    slip = ratio[..., None, None] * (dtrial - direction[..., :, None] * along[..., None, :])
    if dlimit is not None:
        slip = slip + direction[..., :, None] * dlimit[..., None, :]
    return np.where(slipping[..., None, None], slip, dtrial)


class InterfaceLaw:
    r"""Traction ``t(Delta; z)`` (s, 3) of ``s`` contact points, its tangent, and a return-mapped state.

    Subclasses are frozen dataclasses of their parameters (validated in
    ``__post_init__``) and implement :meth:`initial_state`, :meth:`evaluate`,
    :meth:`commit`, :meth:`dissipation` and :meth:`stored_energy`. The state
    is one array of tangential slider positions (``checkpoint`` key
    ``"slip"``) whose leading axis is the contact point.

    Units: gaps in m, tractions in Pa, stiffnesses in Pa/m (any consistent set).
    """

    name: ClassVar[str] = ""
    #: Whether the traction also depends on the gap's rate ``gdot`` (s, 3) (a dashpot): such a law gives
    #: :meth:`evaluate_rate` its rate tangent, and its ``step_derivative`` (when it has one) takes
    #: ``rate=`` and ``drate=`` (s, 3, m) keywords; :class:`~femrom.fem.JointForce` then passes the
    #: pairs' relative velocities and is ``velocity_dependent`` itself.
    velocity_dependent: ClassVar[bool] = False

    def initial_state(self, n_points: int) -> np.ndarray:
        """The state of ``n_points`` virgin contact points (every slider at zero)."""
        raise NotImplementedError

    def evaluate(self, gap: np.ndarray, state: np.ndarray, tangent: bool = True):
        """``(traction (s, 3), dt/dgap (s, 3, 3) or None)`` at ``gap`` (s, 3) with ``state`` frozen."""
        raise NotImplementedError

    def evaluate_rate(self, gap: np.ndarray, rate: np.ndarray, state: np.ndarray, tangent: bool = True):
        """``(traction (s, 3), dt/dgap (s, 3, 3) or None, dt/drate (s, 3, 3) or None)`` at ``gap`` and its rate
        ``rate`` (s, 3) with ``state`` frozen. A law without rate dependence: :meth:`evaluate`'s, and ``None``."""
        traction, D = self.evaluate(gap, state, tangent)
        return traction, D, None

    def traction(self, gap: np.ndarray, state: np.ndarray) -> np.ndarray:
        """(s, 3) traction at ``gap`` with ``state`` frozen."""
        return self.evaluate(gap, state, tangent=False)[0]

    def commit(self, gap: np.ndarray, state: np.ndarray) -> np.ndarray:
        """The state after a converged step ending at ``gap`` (a new array; ``state`` is not changed)."""
        raise NotImplementedError

    #: Optional: ``step_derivative(gap, state, dgap, dstate) -> (dtraction, dstate_new)``, the forward
    #: derivative of one return-map step (traction and committed state) along ``m`` directions, with
    #: ``dgap`` (s, 3, m) and ``dstate`` ``state.shape + (m,)``. A law that has it gives
    #: :class:`~femrom.fem.JointForce` an exact harmonic-balance Jacobian
    #: (:class:`femrom.integrators.HarmonicBalance`); ``None``: the frozen-state tangent is used.
    step_derivative = None

    #: Optional: ``step_traction(gap0, gap1, state, tangent=True) -> (traction (s, 3), d/dgap1 (s, 3, 3) or
    #: None)``, the traction of a whole step from ``gap0`` to ``gap1`` (``state`` committed at ``gap0``) whose
    #: work never exceeds what the law stores and dissipates: ``traction . (gap1 - gap0) >= stored_energy(gap1,
    #: commit(gap1, state)) - stored_energy(gap0, state) + dissipation(gap1, state)``, with equality for an
    #: elastic step. A law that has it gives :class:`~femrom.fem.JointForce` a step force
    #: (:attr:`~femrom.fem.NonlinearForce.step_force`), which
    #: :class:`femrom.integrators.DiscreteGradient` balances in place of the midpoint force.
    step_traction = None

    def dissipation(self, gap: np.ndarray, state: np.ndarray) -> np.ndarray:
        """(s,) energy per unit area the sliders dissipate in the step from ``state`` to ``commit(gap, state)``."""
        raise NotImplementedError

    def stored_energy(self, gap: np.ndarray, state: np.ndarray) -> np.ndarray:
        """(s,) elastic energy per unit area in the springs at ``gap`` with the sliders at ``state``."""
        raise NotImplementedError

    def checkpoint(self, state: np.ndarray) -> dict[str, np.ndarray]:
        """Arrays that restore ``state`` exactly."""
        return {"slip": np.array(state, dtype=float)}

    def restore(self, data: dict[str, np.ndarray]) -> np.ndarray:
        """Inverse of :meth:`checkpoint`."""
        return np.array(data["slip"], dtype=float)

    def parameters(self) -> dict:
        """``{"name": ..., parameter: number, ...}``: what :func:`interface_law_from_parameters` rebuilds."""
        return {"name": self.name, **{f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.init}}


def split_gap(gap) -> tuple[np.ndarray, np.ndarray]:
    """``(g_t (s, 2), g_n (s,))`` of a (s, 3) local relative displacement, checked."""
    gap = np.asarray(gap, dtype=float)
    if gap.ndim != 2 or gap.shape[1] != 3:
        raise FemromValueError(f"gap must be (s, 3) (g_t1, g_t2, g_n) per contact point, got shape {gap.shape}")
    return gap[:, :2], gap[:, 2]


class ParallelSliderLaw(InterfaceLaw):
    r"""Parallel 2-D Jenkins elements in the tangential plane and a linear normal spring.

    Slider ``m`` (stiffness ``k_m``, slip traction ``f_m``, position ``z_m``
    (s, 2)) carries ``t_m = radial_return(k_m (g_t - z_m), f_m)``; the
    tangential traction is ``t_t = sum_m t_m``, the normal one ``t_n = k_n g_n``
    (bilateral). Committing sets ``z_m = g_t - t_m / k_m``; a slipping slider
    dissipates ``t_m . (z_m^{new} - z_m) = f_m |dz_m|``.

    Subclasses provide :attr:`slider_stiffness` (N,), :attr:`slider_strength`
    (N,) and :attr:`normal_stiffness`. State: (s, N, 2) slider positions.
    """

    slider_stiffness: np.ndarray
    slider_strength: np.ndarray
    normal_stiffness: float

    def initial_state(self, n_points: int) -> np.ndarray:
        return np.zeros((int(n_points), self.slider_stiffness.size, 2))

    def _sliders(self, gap, state):
        g_t, g_n = split_gap(gap)
        k = self.slider_stiffness[None, :, None]
        trial = k * (g_t[:, None, :] - state)
        return g_t, g_n, k, trial, radial_return(trial, self.slider_strength[None, :])

    def _compiled(self, gap, state):
        """``(kernels, gap, state)`` as the compiled kernels take them, or ``None``: numpy evaluates."""
        kernels = compiled_kernels()
        if kernels is None:
            return None
        gap = np.ascontiguousarray(gap, dtype=float)
        state = np.ascontiguousarray(state, dtype=float)
        if gap.ndim != 2 or gap.shape[1] != 3 or state.shape != (gap.shape[0], self.slider_stiffness.size, 2):
            return None                                      # numpy broadcasts or raises as it always has
        return kernels, gap, state

    def kernel_arguments(self):
        """``(kind, stiffness (N,), strength (N,), normal_stiffness)``: the law as the compiled joint kernels take it
        (:class:`femrom.fem.CompiledJoint`)."""
        return PARALLEL_SLIDERS, self.slider_stiffness, self.slider_strength, float(self.normal_stiffness)

    def evaluate(self, gap, state, tangent=True):
        compiled = self._compiled(gap, state)
        if compiled is not None:
            kernels, gap, state = compiled
            traction, D = kernels.parallel_sliders(gap, state, self.slider_stiffness, self.slider_strength,
                                                   float(self.normal_stiffness), bool(tangent))
            return traction, (D if tangent else None)
        g_t, g_n, _, _, (t, ratio, direction, slipping) = self._sliders(gap, state)
        traction = np.empty((g_n.size, 3))
        traction[:, :2] = t.sum(axis=1)
        traction[:, 2] = self.normal_stiffness * g_n
        if not tangent:
            return traction, None
        D = np.zeros((g_n.size, 3, 3))
        D[:, :2, :2] = np.einsum("m,smij->sij", self.slider_stiffness,
                                 radial_return_tangent(ratio, direction, slipping))
        D[:, 2, 2] = self.normal_stiffness
        return traction, D

    def commit(self, gap, state):
        compiled = self._compiled(gap, state)
        if compiled is not None:
            kernels, gap, state = compiled
            return kernels.parallel_sliders_commit(gap, state, self.slider_stiffness, self.slider_strength)
        g_t, _, k, _, (t, *_rest) = self._sliders(gap, state)
        return g_t[:, None, :] - t / k

    def step_derivative(self, gap, state, dgap, dstate):
        r"""Forward derivative of one return-map step along ``m`` directions.

        ``dgap`` (s, 3, m) and ``dstate`` (s, N, 2, m) are the derivatives of the gap and of the
        frozen sliders; returns ``(dtraction (s, 3, m), dz (s, N, 2, m))``: of the traction and of
        the committed sliders. Per slider, ``dt^tr = k_m (dg_t - dz_m)``; stuck: ``dt_m = dt^tr``,
        ``z_m`` kept; slipping: ``dt_m = ratio (I - d d^T) dt^tr`` and ``dz_m = dg_t - dt_m / k_m``
        (the committed ``z_m = g_t - t_m / k_m``). ``dt_n = k_n dg_n``.
        """
        _, _, k, _, (_, ratio, direction, slipping) = self._sliders(gap, state)
        dgap = np.asarray(dgap, dtype=float)
        dg_t = dgap[:, None, :2, :]
        km = k[..., None]
        dt = radial_return_derivative(km * (dg_t - dstate), ratio, direction, slipping)
        dtraction = np.empty((dgap.shape[0], 3, dgap.shape[2]))
        dtraction[:, :2] = dt.sum(axis=1)
        dtraction[:, 2] = self.normal_stiffness * dgap[:, 2]
        dz = np.where(slipping[..., None, None], dg_t - dt / km, dstate)
        return dtraction, dz

    def dissipation(self, gap, state):
        _, _, k, trial, (t, *_rest) = self._sliders(gap, state)
        return np.einsum("smi,smi->s", t, (trial - t) / k)

    def stored_energy(self, gap, state):
        g_t, g_n = split_gap(gap)
        slip = g_t[:, None, :] - state
        return 0.5 * np.einsum("m,smi,smi->s", self.slider_stiffness, slip, slip) \
            + 0.5 * self.normal_stiffness * g_n**2
