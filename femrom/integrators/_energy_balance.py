r"""The discrete energy balance of a Newmark average-acceleration run, step by step.

Average acceleration (``beta = 1/4``, ``gamma = 1/2``) gives
``q_{k+1} - q_k = h (v_k + v_{k+1}) / 2``. Averaging the equations of motion
balanced at ``t_k`` and ``t_{k+1}``,
``M a + C v + K q + f_nl = f`` (``f = B u + f_0``), and taking the product
with ``Delta q = q_{k+1} - q_k`` gives, exactly,

.. math::

    \underbrace{\bar f \cdot \Delta q}_{\text{external work}}
    = \Delta\big(\tfrac12 v^\top M v\big) + \Delta\big(\tfrac12 q^\top K q\big)
    + \underbrace{h\, \bar v^\top C \bar v}_{\text{Rayleigh}}
    + \underbrace{\bar g \cdot \Delta x}_{\text{nonlinear work}},

with bars for the means of the step's two ends and ``x = L q`` the nonlinear
force's local coordinates (``g`` its local force). The identity holds to the
Newton tolerance and round-off: it is the scheme's, whatever the force.

For a friction joint the nonlinear work splits further into the change of
the energy stored in the interface springs plus what the sliders dissipate
(``stored_energy`` and ``dissipation`` of :class:`femrom.fem.JointForce`):

.. math::

    \bar g \cdot \Delta x = \Delta E_{joint} + D_{friction} + D_{dashpot} + \epsilon_k .

``D_dashpot`` is the work of a law's rate term (the clamped Iwan law's normal dashpot at re-closed
points, ``damping_power`` of :class:`femrom.fem.JointForce`), taken by the trapezoid of its power,
``h (P_k + P_{k+1}) / 2``: second order in ``h``, not the step's exact work.

``epsilon_k`` vanishes in steps that stick or slip throughout; in a step that
switches between the two, the trapezoidal mean ``bar g`` is not the return
map's work, and ``epsilon_k`` is of the order of ``dt^2`` relative to the
step's work (measured in ``docs/joint.md``); when a penalty contact opens or
closes within a step it can be negative and large: the trapezoidal rule then
creates energy.

A midpoint scheme (:class:`femrom.integrators.DiscreteGradient`) balances the
input at the step's middle: given the scheme, the external work is
``F(t_k + h/2) . Delta q``. Its :attr:`EnergyBalance.residual` is then zero for
conservative steps and positive where the step dissipates more than the law
reports (a joint's step force, :attr:`femrom.fem.NonlinearForce.step_force`);
:attr:`~EnergyBalance.scheme_residual` and :attr:`~EnergyBalance.joint_residual`
split it by the trapezoid's nonlinear work, which is not that scheme's.
"""

from __future__ import annotations

import numpy as np


class EnergyBalance:
    r"""A consumer recording the terms of the discrete energy balance (module docstring) every step.

    Parameters
    ----------
    system : SecondOrderSystem
        The system being integrated by Newmark average acceleration (the
        identity is that scheme's; another scheme's run gives a nonzero
        :attr:`scheme_residual` of its own order).
    scheme : Scheme, optional
        The scheme of the run: one that samples the input at the step's middle
        (``input_time = 0.5``, the midpoint family) has its external work taken
        there. Default: the trapezoid's ``(f_k + f_{k+1}) / 2``.

    Attributes (after the run; (k + 1,) ndarrays over the steps, cumulative from step 0)
    ------------------------------------------------------------------------------------
    t, kinetic, strain, external_work, rayleigh, nonlinear_work, joint_energy, friction, joint_damping

    ``joint_energy`` is the energy stored in the nonlinear forces that report it
    (``stored_energy(q, state)``, else ``potential(q)`` for conservative forces);
    ``friction`` the cumulated ``dissipation(q_{k+1}, state_k)`` of those that
    report it; ``joint_damping`` the cumulated trapezoid of ``damping_power(q, v, state)`` of those
    that report one (zero for rate-independent laws). The external work includes a constant load ``f_0``.
    """

    def __init__(self, system, scheme=None):
        self.system = system
        self._midpoint_input = scheme is not None and float(scheme.input_time) == 0.5
        forces = system.nonlinear_forces
        self._stored = [f for f in forces if hasattr(f, "stored_energy") or f.conservative]
        self._dissipative = [f for f in forces if hasattr(f, "dissipation")]
        self._damped = [f for f in forces if hasattr(f, "damping_power") and getattr(f, "velocity_dependent", False)]
        self._previous = None
        self._rows: list[tuple] = []

    def _nonlinear(self, q, v, state):
        """``(x, g)``: the force's local coordinates and law (its work ``g . dx``), or for a reduced
        model's force without local coordinates ``(q, f(q, v; s))`` (the same work, ``f . dq``)."""
        force = self.system.nonlinear
        if not hasattr(force, "localize"):
            return q, force.force(q, v, state)
        x = force.localize(q)
        return x, force.local_force(x, force.localize(v), state)

    def _joint_energy(self, q, state):
        total = 0.0
        for force in self._stored:
            own = self._own_state(force, state)
            total += force.stored_energy(q, own) if hasattr(force, "stored_energy") else force.potential(q)
        return total

    def _own_state(self, force, state):
        forces = self.system.nonlinear_forces
        return state if len(forces) == 1 else state[forces.index(force)]

    def __call__(self, result) -> None:
        system = self.system
        q, v, t, state = result.q, result.v, result.t, result.state
        f = system.external_force(t)
        x, g = (None, None) if system.nonlinear is None else self._nonlinear(q, v, state)
        kinetic = system.kinetic_energy(v)
        strain = 0.5 * float(q @ (system.stiffness @ q))
        joint = self._joint_energy(q, state)
        power = sum(force.damping_power(q, v, self._own_state(force, state)) for force in self._damped)
        if self._previous is None:
            work = rayleigh = nonlinear = friction = damping = 0.0
        else:
            p = self._previous
            dq = q - p["q"]
            if f is None:
                work = 0.0
            elif self._midpoint_input:
                work = float(system.external_force(0.5 * (t + p["t"])) @ dq)
            else:
                work = 0.5 * float((f + p["f"]) @ dq)
            if system.damping is not None:
                v_mean = 0.5 * (v + p["v"])
                rayleigh = (t - p["t"]) * float(v_mean @ (system.damping @ v_mean))
            else:
                rayleigh = 0.0
            nonlinear = 0.0 if g is None else 0.5 * float((g + p["g"]) @ (x - p["x"]))
            friction = sum(force.dissipation(q, self._own_state(force, p["state"]))
                           for force in self._dissipative)
            damping = 0.5 * (t - p["t"]) * (power + p["power"])
        self._rows.append((t, kinetic, strain, work, rayleigh, nonlinear, joint, friction, damping))
        self._previous = {"q": q, "v": v, "t": t, "f": f, "x": x, "g": g, "state": state, "power": power}

    def __len__(self) -> int:
        return len(self._rows)

    def _column(self, index: int, cumulative: bool = False) -> np.ndarray:
        column = np.array([row[index] for row in self._rows], dtype=float)
        return np.cumsum(column) if cumulative else column

    @property
    def t(self) -> np.ndarray:
        return self._column(0)

    @property
    def kinetic(self) -> np.ndarray:
        """``v^T M v / 2``."""
        return self._column(1)

    @property
    def strain(self) -> np.ndarray:
        """``q^T K q / 2`` (the linear part's strain energy)."""
        return self._column(2)

    @property
    def external_work(self) -> np.ndarray:
        """Cumulated ``sum (f_k + f_{k+1})/2 . (q_{k+1} - q_k)`` (``f(t_k + h/2)`` for a midpoint scheme)."""
        return self._column(3, cumulative=True)

    @property
    def rayleigh(self) -> np.ndarray:
        """Cumulated damping dissipation ``sum h vbar^T C vbar``."""
        return self._column(4, cumulative=True)

    @property
    def nonlinear_work(self) -> np.ndarray:
        """Cumulated work done on the nonlinear forces, ``sum (g_k + g_{k+1})/2 . (x_{k+1} - x_k)``."""
        return self._column(5, cumulative=True)

    @property
    def joint_energy(self) -> np.ndarray:
        """Energy stored in the nonlinear forces (interface springs, potentials)."""
        return self._column(6)

    @property
    def friction(self) -> np.ndarray:
        """Cumulated friction dissipation of the forces that report one."""
        return self._column(7, cumulative=True)

    @property
    def joint_damping(self) -> np.ndarray:
        """Cumulated work of the nonlinear forces' rate terms, ``sum h (P_k + P_{k+1}) / 2`` (a normal
        dashpot's; zero without one)."""
        return self._column(8, cumulative=True)

    @property
    def scheme_residual(self) -> np.ndarray:
        r"""(k,) per step: ``W_ext - Delta T - Delta V - D_C - W_nl`` (zero to round-off for average
        acceleration)."""
        return np.diff(self.external_work - self.kinetic - self.strain - self.rayleigh - self.nonlinear_work)

    @property
    def joint_residual(self) -> np.ndarray:
        r"""(k,) per step: ``W_nl - Delta E_joint - D_friction - D_dashpot`` (the return map against the
        trapezoid)."""
        return np.diff(self.nonlinear_work - self.joint_energy - self.friction - self.joint_damping)

    @property
    def residual(self) -> np.ndarray:
        """(k,) per step: work in minus (kinetic + strain + Rayleigh + joint energy + friction + dashpot)
        changes, the sum of :attr:`scheme_residual` and :attr:`joint_residual`."""
        return np.diff(self.external_work - self.kinetic - self.strain - self.rayleigh - self.joint_energy
                       - self.friction - self.joint_damping)

    def as_dict(self) -> dict[str, np.ndarray]:
        """The recorded terms as arrays (for a report or an HDF5 group)."""
        names = ("t", "kinetic", "strain", "external_work", "rayleigh", "nonlinear_work", "joint_energy",
                 "friction", "joint_damping")
        return {name: getattr(self, name) for name in names}
