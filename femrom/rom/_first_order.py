r"""An unstructured first-order ROM on a cotangent lift: ``y' = A^ y + F^(y)``, the baseline of H-OpInf.

With ``y = [q^; p^]`` (2r,), a learned ``A^`` (2r, 2r) without structure
(:class:`~femrom.inference.CanonicalOpInf`) and a known Hamiltonian term
``H_nl`` evaluated through the basis,

.. math::

    \dot y = \hat A y + \begin{bmatrix} \Phi^\top \partial_p H_{nl} \\ -\Phi^\top \partial_q H_{nl}
             \end{bmatrix}(\Phi \hat q, \Phi \hat p),

stepped by a registered first-order scheme:

- ``"midpoint"`` (implicit midpoint): ``y_1 = y_0 + h f((y_0 + y_1) / 2)``, Newton from the explicit Euler
  predictor with the tolerance of :func:`femrom.integrators.integrate_canonical`, so
  that a baseline and a Hamiltonian ROM compared under it differ only in their
  operators (for ``A^ = [[0, D^_p], [-D^_q, 0]]`` it retraces the Hamiltonian ROM's
  midpoint run);
- ``"rk4"``: the classical explicit Runge-Kutta method.

A step whose Newton iteration fails, or a state beyond ``1e3 max(||y_0||, 1)``,
ends the run: the remaining columns are NaN (a blow-up, reported, not raised).
"""

from __future__ import annotations

import time

import numpy as np

from femrom._errors import FemromValueError
from femrom.inference import ProjectedPotential
from femrom.integrators import ConvergenceError, Newton, time_scheme
from femrom.rom._base import ReducedModel, uniform_step
from femrom.rom._hamiltonian import HamiltonianSolution


#: A state beyond this multiple of ``max(||y_0||, 1)`` has blown up.
BLOWUP_FACTOR = 1e3


class FirstOrderROM(ReducedModel):
    r"""``y' = A^ y + F^(y)`` on a cotangent lift (no structure): predict, stepping time, blow-up.

    Parameters
    ----------
    operator : (2r, 2r) ndarray, optional
        ``A^`` (else :meth:`fit`).
    basis : (n, r) ndarray
        ``Phi``.
    potential : object, optional
        The known ``H_nl`` (``gradient``, ``hessian`` on full states).
    learner : CanonicalOpInf, optional
        What :meth:`fit` uses.
    scheme : str
        A registered scheme of first-order models (``"midpoint"``, ``"rk4"``).
    newton : Newton
        Tolerances of the midpoint rule's Newton iteration.
    """

    def __init__(self, operator: np.ndarray | None = None, basis: np.ndarray | None = None, potential=None, *,
                 learner=None, scheme: str = "midpoint", newton: Newton = Newton(rtol=1e-12)):
        time_scheme(scheme).check_kind("first_order")
        if potential is not None and basis is None:
            raise FemromValueError("a known potential is evaluated through the basis: give basis")
        self.operators_ = None if operator is None else np.asarray(operator, dtype=float)
        self.basis = None if basis is None else np.asarray(basis, dtype=float)
        self.potential = potential
        self.potential_ = None if potential is None else ProjectedPotential(potential, self.basis)
        self.learner, self.scheme, self.newton = learner, scheme, newton

    def fit(self, data, *, validation=None) -> "FirstOrderROM":
        """Fit ``A^`` with the learner (:class:`~femrom.inference.CanonicalOpInf` on CanonicalData)."""
        if self.learner is None:
            raise FemromValueError("this ROM has no learner; pass learner=CanonicalOpInf(...)")
        self.operators_ = self.learner.fit(data, validation=validation).operators_
        return self

    @property
    def r(self) -> int:
        return self._operator().shape[0] // 2

    def _operator(self) -> np.ndarray:
        if self.operators_ is None:
            raise FemromValueError("this ROM is not fitted: call fit(data) or pass operator")
        return self.operators_

    def rhs(self, y: np.ndarray) -> np.ndarray:
        """(2r,) ``A^ y + [Phi^T dH_nl/dp; -Phi^T dH_nl/dq](Phi q^, Phi p^)``."""
        A, r = self._operator(), self.r
        if self.potential_ is None:
            return A @ y
        gq, gp = self.potential_.gradient(y[:r], y[r:])
        return A @ y + np.concatenate([gp, -gq])

    def jacobian(self, y: np.ndarray) -> np.ndarray:
        """(2r, 2r) derivative of :meth:`rhs`."""
        A, r = self._operator(), self.r
        if self.potential_ is None:
            return A
        hqq, hqp, hpp = self.potential_.hessian(y[:r], y[r:])
        return A + np.block([[hqp.T, hpp], [-hqq, -hqp]])

    def predict(self, times, inputs=None, *, initial=None, scheme: str | None = None) -> HamiltonianSolution:
        """Integrate from ``initial = (q0, p0)`` (each reduced (r,) or full (n,)) on a uniform grid (no inputs).

        Returns a :class:`~femrom.rom.HamiltonianSolution` with ``hamiltonian = None``
        (the model has none); ``info`` holds ``stepping_seconds``, ``scheme`` and
        ``blowup_step`` (``None``: finite throughout).
        """
        scheme = self.scheme if scheme is None else scheme
        stepper = time_scheme(scheme)
        stepper.check_kind("first_order")
        times, h = uniform_step(times)
        q0, p0 = self.canonical_initial(initial, inputs)
        y0 = np.concatenate([q0, p0])
        n_steps = times.size - 1
        Y = np.full((y0.size, n_steps + 1), np.nan)
        Y[:, 0] = y0
        limit = BLOWUP_FACTOR * max(np.linalg.norm(y0), 1.0)
        def step(y, h):
            return stepper.first_order_step(self.rhs, self.jacobian, y, h, self.newton)
        tic = time.perf_counter()
        last = n_steps
        y = y0.copy()
        with np.errstate(over="ignore", invalid="ignore"):
            for k in range(n_steps):
                try:
                    y1 = step(y, h)
                except ConvergenceError:
                    last = k
                    break
                if not np.linalg.norm(y1) < limit:
                    last = k
                    break
                y = y1
                Y[:, k + 1] = y
        seconds = time.perf_counter() - tic
        r = self.r
        info = {"scheme": scheme, "dt": h, "n_steps": n_steps, "stepping_seconds": seconds,
                "seconds_per_step": seconds / max(last, 1), "blowup_step": None if last == n_steps else last + 1}
        return HamiltonianSolution(t=times, q=Y[:r], p=Y[r:], hamiltonian=None, basis=self.basis, info=info)
