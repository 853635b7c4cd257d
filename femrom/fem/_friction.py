r"""Hysteretic (history-dependent) forces: the Jenkins element.

A Jenkins element is a spring of stiffness ``k`` in series with a Coulomb
slider of slip force ``F_s``. With the slider position ``z`` as its state and
the local coordinate ``x``,

.. math::

    g(x; z) = \operatorname{clip}\big(k (x - z), -F_s, F_s\big), \qquad
    z \leftarrow x - g / k \quad \text{(committed after a converged step)},

a return map: during the Newton iterations of a step ``z`` is frozen at its
committed value, so ``g`` is a function of ``x`` with tangent ``k`` while the
element sticks and ``0`` while it slips. Under a slowly varying ``x`` the
force-displacement curve is the elastic-perfectly-plastic (Masing) loop; a
cycle of amplitude ``x_a > F_s / k`` dissipates ``4 F_s (x_a - F_s / k)``.
"""

from __future__ import annotations

import numpy as np

from femrom._errors import FemromValueError
from femrom.fem._interface_law import slider_return
from femrom.fem._nonlinear import NonlinearForce, register_force


@register_force
class JenkinsForce(NonlinearForce):
    r"""Springs ``k_i`` in series with Coulomb sliders ``F_s,i`` on local coordinates ``x = L q``.

    Parameters
    ----------
    stiffness : float or (s,) ndarray
        ``k > 0``.
    slip_force : float or (s,) ndarray
        ``F_s > 0``.
    n_dofs : int
        Size of the system.
    dofs, local_map : optional
        Where the elements act (see :class:`NonlinearForce`): a dof each
        (grounded elements) or, with a map, e.g. relative displacements.
    name : str, optional

    State: the (s,) slider positions ``z`` (zero at t = 0); checkpoint ``{"slider": z}``.
    """

    kind = "jenkins"
    stateful = True

    def __init__(self, stiffness, slip_force, n_dofs: int, *, dofs=None, local_map=None,
                 name: str | None = None):
        super().__init__(n_dofs, dofs=dofs, local_map=local_map, name=name)
        s = self.n_local
        self.stiffness = np.broadcast_to(np.asarray(stiffness, dtype=float), (s,)).copy()
        self.slip_force = np.broadcast_to(np.asarray(slip_force, dtype=float), (s,)).copy()
        if not (np.all(self.stiffness > 0) and np.all(self.slip_force > 0)):
            raise FemromValueError("Jenkins elements need stiffness > 0 and slip_force > 0")

    def initial_state(self) -> np.ndarray:
        return np.zeros(self.n_local)

    def _trial(self, x, state):
        z = self.initial_state() if state is None else state
        return self.stiffness * (x - z)

    def local_force(self, x, xdot=None, state=None):
        return slider_return(self._trial(x, state), self.slip_force)[0]

    def local_tangent(self, x, xdot=None, state=None):
        sticking = slider_return(self._trial(x, state), self.slip_force)[1]
        return np.where(sticking, self.stiffness, 0.0), None

    def local_commit(self, x, xdot, state):
        return x - self.local_force(x, None, state) / self.stiffness

    def local_step_derivative(self, x, state, dx, dstate):
        r"""Forward derivative of one return-map step along ``m`` directions.

        ``dx`` (s, m) and ``dstate`` (s, m) are the derivatives of the coordinates and of the
        frozen slider positions; returns ``(dg, dz)`` (s, m): of the force and of the committed
        slider. Stuck: ``g = k (x - z)``, ``z`` kept, so ``dg = k (dx - dz)``, ``dz`` kept;
        slipping: ``g = +-F_s``, ``z = x -+ F_s / k``, so ``dg = 0``, ``dz = dx``. Carried over a
        sampled period, this is the exact derivative of the sampled hysteresis loop
        (:class:`femrom.integrators.HarmonicBalance`).
        """
        sticking = slider_return(self._trial(x, state), self.slip_force)[1][:, None]
        dg = np.where(sticking, self.stiffness[:, None] * (dx - dstate), 0.0)
        return dg, np.where(sticking, dstate, dx)

    def checkpoint(self, state):
        return {"slider": np.asarray(state, dtype=float)}

    def restore(self, data):
        return np.array(data["slider"], dtype=float)

    def parameters(self):
        return {"kind": self.kind, "stiffness": self.stiffness, "slip_force": self.slip_force,
                "name": self.name, **self._placement()}

    @classmethod
    def from_parameters(cls, parameters):
        return cls(parameters["stiffness"], parameters["slip_force"], name=str(parameters.get("name", "jenkins")),
                   **cls._placement_from(parameters))
