r"""Segalman's Iwan element under the pressure a preload left: slip spread, contact status frozen.

:mod:`clamped_friction` gives every closed point one Coulomb slider with slip traction
``tau_s = mu p_0``: a point sticks until its traction reaches ``tau_s`` and then slips at
once, so a joint of such points starts to slip where the pressure is lowest and the onset
is sharp. Measured lap joints dissipate from the lowest amplitudes on, with a power law
(Segalman 2005; the Brake-Reuss beam's damping rises from 0.14 % at 1 m/s^2). This law
spreads each closed point's slip over a continuum of Jenkins elements, the 4-parameter
Iwan element (:class:`femrom.fem.IwanLaw`) whose macro-slip traction is the point's own
``F_S = tau_s = mu p_0``:

.. math::

    t_t = c \sum_m \operatorname{proj}_{|t| \le \tau_s f_m}\big(k_m (g_t - z_m)\big), \qquad
    t_n = c\, k_n g_n, \qquad c \in \{0, 1\} \text{ (closed at the preload)}.

The slider stiffnesses ``k_m`` and the unit-traction strengths ``f_m`` are those of
:class:`~femrom.fem.IwanLaw` with ``F_S = 1`` and ``K_T = k_t``: for the power-law
density the stiffnesses do not depend on ``F_S`` and the strengths are proportional to
it (``phi_max ~ F_S``, ``R ~ F_S^{-(chi+1)}``), so every point has the stuck stiffness
``k_t`` (the calibrated ``f_1`` does not move) and the macro-slip traction ``mu p_0``, and
``chi``, ``beta`` shape the onset of slip between the two. ``chi -> -1`` puts the slip in
the weakest sliders (early onset), ``beta`` weighs the delta at ``phi_max`` (the share of
the traction carried to macro-slip). Like :mod:`clamped_friction`, the law is piecewise
linear with dissipative sliders, so the average-acceleration step stays energy-stable.

``closing = kappa > 0`` lets a point open at the preload close again: a unilateral penalty
``kappa k_n`` on its normal gap (the gap it had at the preload plus the motion), and with
``closing_friction = mu_c > 0`` Coulomb friction at the pressure that penalty gives, spread over
the same Iwan element (stiffnesses scaled by ``kappa``, macro-slip traction
``mu_c kappa k_n (-g_n)``): the contact closing of the full ``dry_friction`` law, with
``kappa < 1`` a softer re-closing contact (rough surfaces touching at low pressure).
The reclosed points are evaluated by numpy (the compiled kernels take the others). Points
near the edge of the clamped region close in bending and stiffen the joint at large
amplitudes (docs/cases/jointed_beam.md). The penalty is kinked: the trapezoidal rule can gain energy when a
point opens inside a step, as with ``dry_friction``; harmonic balance has no such issue.

``closing_damping = lambda > 0`` adds a normal dashpot at the reclosed points, Hunt and Crossley's
(1975) penetration-weighted one: with ``g_n`` the normal gap, ``gdot_n`` its rate and
``p = -g_n >= 0`` the penetration,

.. math::

    t_n = \min\big(\kappa k_n g_n - \lambda g_n \dot g_n,\ 0\big) \qquad (g_n < 0,\ \text{reclosed}),

the compressive traction ``kappa k_n p + lambda p pdot`` (Hunt-Crossley's ``k delta + lambda delta
delta_dot`` with a linear spring), ``lambda`` in [Pa s/m^2]. It is the standard impact-damping form: the
damping force grows with the penetration, so the traction is continuous where a point touches
(zero at ``p = 0``, whatever the rate) as well as where it separates, and a touch adds no jump to
harmonic balance's force. It is never adhesive: a point that separates faster than
``kappa k_n / lambda`` (``pdot < -kappa k_n / lambda``) carries no traction until its gap opens.
The friction of a reclosed point keeps the elastic pressure ``kappa k_n (-g_n)`` (its
slip limit ``mu_c kappa k_n (-g_n) f_m``): the sliders' state then depends on the gaps alone, as
without the dashpot, and the dashpot dissipates only normally, ``(t_n - kappa k_n g_n) gdot_n >= 0``
per unit area (``-lambda g_n gdot_n^2`` where it does not pull; :meth:`ClampedIwanLaw.damping_power`).
The law is then velocity dependent (:attr:`ClampedIwanLaw.velocity_dependent`):
:meth:`ClampedIwanLaw.evaluate_rate` gives the traction with the gap tangent's normal entry
``kappa k_n - lambda gdot_n`` and the rate tangent ``dt / dgdot`` (s, 3, 3) (``-lambda g_n = lambda p``
in the normal entry of the damped points), and :meth:`ClampedIwanLaw.step_derivative` takes the
rate's derivative. With ``lambda = 0`` (default) nothing changes.

Parameters
----------
normal_stiffness : float
    ``k_n > 0`` [Pa/m].
tangential_stiffness : float
    ``k_t > 0`` [Pa/m]: the stuck stiffness ``K_T``.
chi : float
    ``-1 < chi`` [-]: the density's exponent (dissipation per cycle ~ amplitude^(3 + chi)).
beta : float
    ``beta >= 0`` [-]: the weight of the delta at ``phi_max``.
n_sliders : int
    Jenkins elements of the power-law part (default 20; one more for the delta when ``beta > 0``).
alpha : float
    ``>= 1``: ratio of successive slip-displacement intervals (default 1.3).
closing : float
    ``kappa >= 0``: ``0`` (default) a point open at the preload stays open; otherwise it closes
    again under a penalty ``kappa k_n`` when its normal gap closes.
closing_friction : float
    ``mu_c >= 0``: the Coulomb coefficient of a reclosed point (default 0: frictionless).
    Its sliders are the closed points' scaled by ``kappa`` (stiffness ``kappa k_m``, macro-slip
    traction ``mu_c kappa k_n (-g_n)``, following the penetration).
closing_damping : float
    ``lambda >= 0`` [Pa s/m^2]: the Hunt-Crossley normal dashpot of a reclosed point, traction
    ``-lambda g_n gdot_n`` (default 0: none); only with ``closing > 0``.

State: (s, N + 1, 2): rows ``0..N-1`` the slider positions ``z_m``, row ``N`` the
point's ``(tau_s [Pa], c)``; set from a ``dry_friction`` preload by
:func:`clamped_iwan_state`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femrom._errors import FemromValueError
from femrom.fem._interface_law import (
    InterfaceLaw,
    check_parameters,
    radial_return,
    radial_return_derivative,
    register_interface_law,
    split_gap,
)
from femrom.fem._law_kernels import compiled_kernels
from femrom.fem._law_kinds import CLAMPED_IWAN
from femrom.fem.interface_laws.iwan import IwanLaw


@register_interface_law
@dataclass(frozen=True)
class ClampedIwanLaw(InterfaceLaw):
    """Iwan elements of macro-slip traction ``mu p_0`` at the preload's closed points (module docstring)."""

    name = "clamped_iwan"
    normal_stiffness: float
    tangential_stiffness: float
    chi: float
    beta: float
    n_sliders: int = 20
    alpha: float = 1.3
    closing: float = 0.0
    closing_friction: float = 0.0
    closing_damping: float = 0.0

    def __post_init__(self):
        check_parameters(self, (("normal_stiffness", "> 0", lambda v: v > 0),
                                ("tangential_stiffness", "> 0", lambda v: v > 0),
                                ("chi", "> -1", lambda v: v > -1),
                                ("beta", ">= 0", lambda v: v >= 0),
                                ("n_sliders", "an integer >= 1", lambda v: v >= 1 and v == int(v)),
                                ("alpha", ">= 1", lambda v: v >= 1),
                                ("closing", ">= 0", lambda v: v >= 0),
                                ("closing_friction", ">= 0", lambda v: v >= 0),
                                ("closing_damping", ">= 0", lambda v: v >= 0)))
        unit = IwanLaw(1.0, self.tangential_stiffness, self.chi, self.beta, n_sliders=self.n_sliders,
                       alpha=self.alpha)
        object.__setattr__(self, "slider_stiffness", unit.slider_stiffness)
        object.__setattr__(self, "unit_strength", unit.slider_strength)
        object.__setattr__(self, "unit_element", unit)

    @property
    def velocity_dependent(self) -> bool:
        """Whether the traction depends on the gap's rate: a reclosing law (``closing > 0``) with a dashpot
        (``closing_damping > 0``)."""
        return bool(self.closing) and bool(self.closing_damping)

    @property
    def n_elements(self) -> int:
        """``N``: Jenkins elements per point (``n_sliders``, + 1 with the delta)."""
        return self.slider_stiffness.size

    def initial_state(self, n_points: int) -> np.ndarray:
        """Every point open (no contact): set a preloaded state with :func:`clamped_iwan_state`."""
        return np.zeros((int(n_points), self.n_elements + 1, 2))

    def _checked(self, gap, state):
        g_t, g_n = split_gap(gap)
        N = self.n_elements
        state = np.asarray(state)
        if state.ndim != 3 or state.shape[1:] != (N + 1, 2) or state.shape[0] != g_n.size:
            raise FemromValueError(f"clamped_iwan state must be ({g_n.size}, {N + 1}, 2), got shape {state.shape}")
        return g_t, g_n, state

    def _compiled(self, gap, state):
        """``(kernels, gap, state)`` as the compiled kernels take them (checked), or ``None``: numpy evaluates."""
        kernels = compiled_kernels()
        if kernels is None:
            return None
        self._checked(gap, state)
        return kernels, np.ascontiguousarray(gap, dtype=float), np.ascontiguousarray(state, dtype=float)

    def _reclosed(self, gap, state) -> np.ndarray:
        """(s,) bool: points open at the preload whose normal gap is closed (``closing > 0``)."""
        state = np.asarray(state)
        if not self.closing:
            return np.zeros(state.shape[0], dtype=bool)
        return (state[:, self.n_elements, 1] <= 0.5) & (np.asarray(gap)[:, 2] < 0.0)

    def _sliders(self, gap, state):
        """The return map of every slider: ``closed`` (s,) at the preload, ``scale`` (s,) of the points'
        stiffnesses (1, ``kappa`` where reclosed, 0 where open), the sliders' stiffness ``k`` (s, N, 1),
        trial and returned tractions (s, N, 2) and the radial return's ``ratio``, ``direction``, ``slipping``."""
        g_t, g_n, state = self._checked(gap, state)
        N = self.n_elements
        closed = state[:, N, 1] > 0.5
        reclosed = self._reclosed(gap, state)
        scale = np.where(reclosed, self.closing, 1.0)
        k = scale[:, None, None] * self.slider_stiffness[None, :, None]
        trial = k * (g_t[:, None, :] - state[:, :N])
        tau = np.where(closed, state[:, N, 0],
                       np.where(reclosed, self.closing * self.closing_friction * self.normal_stiffness * -g_n, 0.0))
        t, ratio, direction, slipping = radial_return(trial, tau[:, None] * self.unit_strength[None, :])
        return g_t, g_n, closed, reclosed, k, trial, t, ratio, direction, slipping

    def kernel_arguments(self):
        """``(kind, stiffness (N,), unit strength (N,), normal_stiffness)``: the law as the compiled joint kernels
        take it (:class:`femrom.fem.CompiledJoint`), or ``None`` with ``closing > 0`` (the kernels do not know
        reclosing points: the numpy step runs)."""
        if self.closing:
            return None
        return CLAMPED_IWAN, self.slider_stiffness, self.unit_strength, float(self.normal_stiffness)

    def _normal_stiffness(self, closed, reclosed) -> np.ndarray:
        """(s,) the points' normal stiffness: ``k_n`` closed at the preload, ``kappa k_n`` reclosed, else 0."""
        return np.where(closed, self.normal_stiffness, np.where(reclosed, self.closing * self.normal_stiffness, 0.0))

    def _evaluate(self, gap, state, tangent):
        """The numpy reference of :meth:`evaluate` (every point, reclosed ones included)."""
        _, g_n, closed, reclosed, k, _, t, ratio, direction, slipping = self._sliders(gap, state)
        k_normal = self._normal_stiffness(closed, reclosed)
        traction = np.empty((g_n.size, 3))
        traction[:, :2] = t.sum(axis=1)
        traction[:, 2] = k_normal * g_n
        if not tangent:
            return traction, None
        D = np.zeros((g_n.size, 3, 3))
        # sum_m k_m dt_m/dt_trial: k_m I when stuck, k_m ratio_m (I - d_m d_m^T) when slipping (an open
        # point's sliders all slip at zero limit: ratio 0, tangent zero); summed without forming the
        # (s, N, 2, 2) blocks
        k = k[:, :, 0]
        slip_weight = np.where(slipping, ratio, 0.0) * k
        diagonal = (np.where(slipping, ratio, 1.0) * k).sum(axis=1)
        d1, d2 = direction[..., 0], direction[..., 1]
        weighted = slip_weight * d1
        D[:, 0, 0] = diagonal - (weighted * d1).sum(axis=1)
        D[:, 0, 1] = D[:, 1, 0] = -(weighted * d2).sum(axis=1)
        D[:, 1, 1] = diagonal - (slip_weight * d2 * d2).sum(axis=1)
        D[:, 2, 2] = k_normal
        if self.closing and self.closing_friction and reclosed.any():
            # a reclosed point's slip limit kappa mu k_n (-g_n) f_m: a slipping slider's traction
            # tau f_m d_m follows the penetration, dt_t / dg_n = -kappa mu k_n sum_m f_m d_m
            along = np.einsum("sm,smi->si", np.where(slipping, self.unit_strength[None, :], 0.0), direction)
            D[:, :2, 2] = np.where(reclosed[:, None],
                                   -self.closing * self.closing_friction * self.normal_stiffness * along, 0.0)
        return traction, D

    def evaluate(self, gap, state, tangent=True):
        compiled = self._compiled(gap, state)
        if compiled is None:
            return self._evaluate(gap, state, tangent)
        kernels, gap, state = compiled
        traction, D = kernels.clamped_iwan(gap, state, self.slider_stiffness, self.unit_strength,
                                           float(self.normal_stiffness), bool(tangent))
        D = D if tangent else None
        if self.closing:
            hit = self._reclosed(gap, state)
            if hit.any():                # the few reclosed points: the reference
                t_hit, D_hit = self._evaluate(gap[hit], state[hit], tangent)
                traction[hit] = t_hit
                if tangent:
                    D[hit] = D_hit
        return traction, D

    def _dashpot(self, gap, rate, state):
        """``(elastic, total, damped, pulling)`` (s,) of the reclosed points' normal dashpot: the penalty's
        traction ``kappa k_n g_n``, ``kappa k_n g_n - lambda g_n gdot_n``, where it acts (reclosed, not
        pulling) and where it would pull (reclosed, total > 0: the traction is zero)."""
        _, g_n = split_gap(gap)
        rate = np.asarray(rate, dtype=float)
        if rate.shape != (g_n.size, 3):
            raise FemromValueError(f"rate must be ({g_n.size}, 3) like the gap, got shape {rate.shape}")
        reclosed = self._reclosed(gap, state)
        elastic = self.closing * self.normal_stiffness * g_n
        total = elastic - self.closing_damping * g_n * rate[:, 2]
        pulling = reclosed & (total > 0.0)
        return elastic, total, reclosed & ~pulling, pulling

    def evaluate_rate(self, gap, rate, state, tangent=True):
        r"""``(traction (s, 3), dt/dgap (s, 3, 3) or None, dt/drate (s, 3, 3) or None)`` at ``gap`` and its rate
        ``rate`` (s, 3) with ``state`` frozen.

        :meth:`evaluate` with the reclosed points' Hunt-Crossley dashpot: ``t_n = min(kappa k_n g_n - lambda
        g_n gdot_n, 0)`` (module docstring); where the sum would pull, ``t_n = 0`` and its derivatives are
        zero. At the damped points the gap tangent's ``(n, n)`` entry is ``kappa k_n - lambda gdot_n`` and
        the rate tangent's is ``-lambda g_n``, zero elsewhere; ``None`` (and :meth:`evaluate`'s result, bit
        for bit) when the law has no dashpot.
        """
        traction, D = self.evaluate(gap, state, tangent)
        if not self.velocity_dependent:
            return traction, D, None
        _, total, damped, pulling = self._dashpot(gap, rate, state)
        traction[:, 2] = np.where(damped, total, np.where(pulling, 0.0, traction[:, 2]))
        if not tangent:
            return traction, None, None
        g_n, gdot_n = np.asarray(gap, dtype=float)[:, 2], np.asarray(rate, dtype=float)[:, 2]
        D[:, 2, 2] += np.where(damped, -self.closing_damping * gdot_n, 0.0)
        D[pulling, 2, 2] = 0.0
        C = np.zeros_like(D)
        C[:, 2, 2] = np.where(damped, -self.closing_damping * g_n, 0.0)
        return traction, D, C

    def damping_power(self, gap, rate, state) -> np.ndarray:
        """(s,) power per unit area the dashpot dissipates, ``(t_n - kappa k_n g_n) gdot_n >= 0`` at the reclosed
        points (``-lambda g_n gdot_n^2`` where it does not pull, ``-kappa k_n g_n gdot_n`` where it would pull;
        zero without a dashpot)."""
        if not self.velocity_dependent:
            return np.zeros(np.shape(gap)[0])
        elastic, total, damped, pulling = self._dashpot(gap, rate, state)
        part = np.where(damped, total - elastic, np.where(pulling, -elastic, 0.0))
        return part * np.asarray(rate, dtype=float)[:, 2]

    def commit(self, gap, state):
        compiled = self._compiled(gap, state)
        if compiled is not None:
            kernels, gap, state = compiled
            new = kernels.clamped_iwan_commit(gap, state, self.slider_stiffness, self.unit_strength)
            if self.closing:
                hit = self._reclosed(gap, state)
                if hit.any():
                    new[hit] = self._commit(gap[hit], state[hit])
            return new
        return self._commit(gap, state)

    def _commit(self, gap, state):
        g_t, _, _, _, k, _, t, *_ = self._sliders(gap, state)
        new = np.array(state, dtype=float)
        new[:, :-1] = g_t[:, None, :] - t / k
        return new

    def step_derivative(self, gap, state, dgap, dstate, rate=None, drate=None):
        r"""Forward derivative of one return-map step along ``m`` directions.

        ``dgap`` (s, 3, m), ``dstate`` (s, N + 1, 2, m); returns ``(dtraction (s, 3, m),
        dstate_new (s, N + 1, 2, m))``. As :meth:`femrom.fem.IwanLaw.step_derivative` per slider,
        with the slip limit ``c tau_s f_m`` read from the state (its derivative ``c f_m dtau_s``
        enters a slipping slider along its direction); the row ``(tau_s, c)`` is kept, an open
        point (``c = 0``) carries no traction and its sliders follow the gap. A reclosed point's
        limit ``kappa mu k_n (-g_n) f_m`` follows the normal gap.

        With a dashpot (:attr:`velocity_dependent`), ``rate`` (s, 3) is the gap's rate (default zero)
        and ``drate`` (s, 3, m) its derivative along the same directions (default zero): a damped point
        adds ``-lambda gdot_n dg_n - lambda g_n dgdot_n`` to ``dt_n``, a pulling one has ``dt_n = 0``; the
        state's derivative does not depend on the rate (the friction keeps the elastic pressure).
        """
        _, g_n, closed, reclosed, k, _, _, ratio, direction, slipping = self._sliders(gap, state)
        N = self.n_elements
        dgap = np.asarray(dgap, dtype=float)
        dstate = np.asarray(dstate, dtype=float)
        dg_t = dgap[:, None, :2, :]
        km = k[..., None]
        dtau = np.where(closed[:, None], dstate[:, N, 0],
                        np.where(reclosed[:, None],
                                 -self.closing * self.closing_friction * self.normal_stiffness * dgap[:, 2], 0.0))
        dlimit = self.unit_strength[None, :, None] * dtau[:, None, :]
        dt = radial_return_derivative(km * (dg_t - dstate[:, :N]), ratio, direction, slipping, dlimit)
        dtraction = np.empty((g_n.size, 3, dgap.shape[2]))
        dtraction[:, :2] = dt.sum(axis=1)
        dtraction[:, 2] = self._normal_stiffness(closed, reclosed)[:, None] * dgap[:, 2]
        if self.velocity_dependent:
            rate = np.zeros((g_n.size, 3)) if rate is None else np.asarray(rate, dtype=float)
            _, _, damped, pulling = self._dashpot(gap, rate, state)
            dtraction[:, 2] += np.where(damped, -self.closing_damping * rate[:, 2], 0.0)[:, None] * dgap[:, 2]
            if drate is not None:
                dtraction[:, 2] += np.where(damped, -self.closing_damping * g_n, 0.0)[:, None] * np.asarray(drate)[:, 2]
            dtraction[pulling, 2] = 0.0
        new = dstate.copy()
        new[:, :N] = np.where(slipping[..., None, None], dg_t - dt / km, dstate[:, :N])
        return dtraction, new

    def dissipation(self, gap, state):
        *_, k, trial, t, _, _, _ = self._sliders(gap, state)
        return np.einsum("smi,smi->s", t, (trial - t) / k)

    def stored_energy(self, gap, state):
        """(s,) the sliders' springs ``sum_m |t_m|^2 / (2 k_m)`` after the return map (with a committed
        state: ``k_m |g_t - z_m|^2 / 2``) and the normal penalty's ``k_n g_n^2 / 2``, at points in contact."""
        _, g_n, closed, reclosed, k, _, t, *_ = self._sliders(gap, state)
        springs = 0.5 * np.einsum("smi,smi->s", t, t / k)
        k_normal = self._normal_stiffness(closed, reclosed)
        return np.where(closed | reclosed, springs + 0.5 * k_normal * g_n**2, 0.0)

    def backbone(self, u, slip_traction) -> np.ndarray:
        """The continuous element's virgin traction at tangential displacement ``u`` for a point of
        macro-slip traction ``slip_traction`` (:meth:`IwanLaw.backbone` scaled: ``F_S t_1(u / F_S)``
        with ``t_1`` the unit element's)."""
        F = float(slip_traction)
        return F * self.unit_element.backbone(np.asarray(u, dtype=float) / F)

    def cycle_dissipation(self, amplitude, slip_traction) -> np.ndarray:
        """The continuous element's dissipation per cycle at displacement amplitude ``u_a`` for a point of
        macro-slip traction ``slip_traction`` (``F_S^2 D_1(u_a / F_S)``: dissipation is traction times
        displacement)."""
        F = float(slip_traction)
        return F * F * self.unit_element.cycle_dissipation(np.asarray(amplitude, dtype=float) / F)


def clamped_iwan_state(law: ClampedIwanLaw, gap: np.ndarray, clamped: np.ndarray) -> np.ndarray:
    """(s, N + 1, 2) state of :class:`ClampedIwanLaw` from a :func:`clamped_state` (s, 4).

    Every slider starts where the point's single preload slider is (``z_m = z``), returned
    onto its own slip limit ``tau_s f_m``: the traction is then the Iwan element's at the
    preload's tangential displacement, which differs slightly from the dry-friction one
    where weak sliders are already loaded past their strength. Re-solve the static
    equilibrium with the new law (``solve_static``) before using the state as a reference.

    Parameters
    ----------
    law : ClampedIwanLaw
    gap : (s, 3) ndarray
        The local relative displacements at the preload (``JointForce.gaps``).
    clamped : (s, 4) ndarray
        ``(z (2), tau_s, c)`` per point from :func:`femrom.fem.clamped_state`.
    """
    gap = np.asarray(gap, dtype=float)
    clamped = np.asarray(clamped, dtype=float)
    if gap.ndim != 2 or gap.shape[1] != 3 or clamped.shape != (gap.shape[0], 4):
        raise FemromValueError(f"gap must be (s, 3) and clamped (s, 4), got {gap.shape} and {clamped.shape}")
    N = law.n_elements
    state = np.zeros((gap.shape[0], N + 1, 2))
    state[:, :N] = clamped[:, None, :2]
    state[:, N] = clamped[:, 2:4]
    return law.commit(gap, state)
