"""Systems whose truth lies in SpML's model class, for its convergence tests and benchmark.

Each :class:`KnownSystem` is a reduced model ``q'' + C q' + K q + grad U(q) = 0`` (unit mass,
linear damping, a polynomial potential of degree <= 4: exactly what
:class:`~femrom.inference.SpML` parametrises), released from rest at scaled displacements.
The data are exact (DOP853 at a relative tolerance of 1e-13; the accelerations from the
equation of motion at the samples), optionally with noise. A test asks for a system by its
factory (:data:`SYSTEMS`), so a held-out system of the same kind is one more factory.

- :func:`chain`: ``n`` unit masses in a line, linear springs (``k = 1``) to the wall and between
  neighbours, a quartic ``kappa / 4 s^4`` on every spring's stretch ``s``, damping ``c I``;
- :func:`duffing`: two coupled Duffing oscillators (quartic self and cross terms and a cubic
  coupling), damping ``c I``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from femrom.inference import LearnedPotential, ReducedOperators, SecondOrderData, SymmetricPolynomial, multi_indices


def polynomial_potential(r: int, tensors: dict) -> LearnedPotential:
    """The potential ``sum_d T_d[q, ..., q]`` of symmetric tensors ``{3: T3, 4: T4}`` as monomials."""
    terms = {}
    for d, T in tensors.items():
        index = multi_indices(r, d)
        coefficients = []
        for m in index:
            # T[q,...,q] = sum over all index tuples; the sorted tuple m stands for its permutations
            perms = len({tuple(p) for p in _permutations(m)})
            coefficients.append(T[tuple(m)] * perms)
        terms[d] = (index, np.array(coefficients))
    return LearnedPotential(r, SymmetricPolynomial(r, terms))


def _permutations(m):
    from itertools import permutations
    return permutations(m.tolist())


@dataclass(frozen=True)
class KnownSystem:
    """A true reduced model, its release shape and the amplitudes it is trained, validated and tested on."""

    name: str
    operators: ReducedOperators
    shape: np.ndarray                   # the initial displacement at amplitude 1 (released from rest)
    train_amplitudes: tuple
    validation_amplitude: float
    test_amplitude: float
    dt: float                           # the data's sampling step
    t_train: float                      # the training window [0, t_train]

    @property
    def r(self) -> int:
        return self.shape.size

    def acceleration(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(r, K) the true acceleration at columns (or (r,) at one state): unit mass, the potential's
        gradient ``3 T3[q, q, .] + 4 T4[q, q, q, .]`` by contractions."""
        ops = self.operators
        poly = ops.term("learned_potential").polynomial
        grad = 3.0 * np.einsum("ijk,j...,k...->i...", poly.T3, q, q) \
            + 4.0 * np.einsum("ijkl,j...,k...,l...->i...", poly.T4, q, q, q)
        return -(ops.stiffness @ q + ops.damping @ v + grad)

    def run(self, amplitude: float, t_end: float, noise: float = 0.0, seed: int = 0) -> SecondOrderData:
        """Exact samples every ``dt`` on [0, t_end] from ``amplitude * shape`` at rest; ``noise``: Gaussian
        noise of that fraction of each field's RMS (per coordinate block: states, velocities, accelerations)."""
        r = self.r
        t = self.dt * np.arange(int(round(t_end / self.dt)) + 1)

        def rhs(_, y):
            return np.concatenate([y[r:], self.acceleration(y[:r], y[r:])])

        y0 = np.concatenate([amplitude * self.shape, np.zeros(r)])
        sol = solve_ivp(rhs, (0.0, t[-1]), y0, method="DOP853", t_eval=t, rtol=1e-13, atol=1e-15)
        q, v = sol.y[:r], sol.y[r:]
        a = self.acceleration(q, v)
        if noise:
            rng = np.random.default_rng(seed)
            q, v, a = (x + noise * np.sqrt(np.mean(x * x)) * rng.standard_normal(x.shape) for x in (q, v, a))
        return SecondOrderData(q, v, a, times=t)

    def training(self, noise: float = 0.0, seed: int = 0):
        """``(train list, validation)`` on the training window."""
        train = [self.run(a, self.t_train, noise, seed + i) for i, a in enumerate(self.train_amplitudes)]
        return train, self.run(self.validation_amplitude, self.t_train, noise, seed + 100)

    def test(self, windows: float = 3.0) -> SecondOrderData:
        """The unseen amplitude's exact run over ``windows`` training windows."""
        return self.run(self.test_amplitude, windows * self.t_train)


def chain(n: int = 3, kappa: float = 4.0, damping: float = 0.02, dt: float = 0.05, t_train: float = 20.0) -> KnownSystem:
    """``n`` unit masses, springs to the wall and between masses, ``kappa / 4 s^4`` on each stretch."""
    D = np.eye(n) - np.eye(n, k=-1)                 # stretches s = D q (the first spring to the wall)
    K = D.T @ D
    T4 = kappa / 4.0 * np.einsum("si,sj,sk,sl->ijkl", D, D, D, D)
    ops = ReducedOperators.from_matrices(K, damping=damping * np.eye(n), nonlinear=polynomial_potential(n, {4: T4}))
    shape = np.linspace(1.0, 2.0, n) / np.sqrt(n)
    return KnownSystem(f"chain{n}", ops, shape, (0.6, 0.9, 1.2, 1.5), 1.05, 1.35, dt, t_train)


def duffing(damping: float = 0.03, dt: float = 0.05, t_train: float = 20.0) -> KnownSystem:
    """Two coupled Duffing oscillators: ``K = [[1, 0.2], [0.2, 2.25]]``, ``U = 0.5 q1^4 + 0.25 q2^4 +
    0.3 q1^2 q2^2 + 0.1 q1^2 q2`` (the cubic coupling small enough to keep ``U + q^T K q / 2`` coercive
    over the data)."""
    K = np.array([[1.0, 0.2], [0.2, 2.25]])
    T4 = np.zeros((2,) * 4)
    T4[0, 0, 0, 0], T4[1, 1, 1, 1] = 0.5, 0.25
    for p in {(0, 0, 1, 1), (0, 1, 0, 1), (0, 1, 1, 0), (1, 0, 0, 1), (1, 0, 1, 0), (1, 1, 0, 0)}:
        T4[p] = 0.3 / 6
    T3 = np.zeros((2,) * 3)
    for p in {(0, 0, 1), (0, 1, 0), (1, 0, 0)}:
        T3[p] = 0.1 / 3
    ops = ReducedOperators.from_matrices(K, damping=damping * np.eye(2),
                                         nonlinear=polynomial_potential(2, {3: T3, 4: T4}))
    return KnownSystem("duffing2", ops, np.array([1.0, -0.6]), (0.5, 0.8, 1.1, 1.4), 0.95, 1.25, dt, t_train)


#: The systems of the convergence tests, by name.
SYSTEMS = {"chain3": chain, "duffing2": duffing}


def predict(operators, test: SecondOrderData, substeps: int = 8, scheme: str = "discrete_gradient"):
    """``(Q, V)`` (r, K): ``operators``' prediction of ``test`` from its initial state at its samples, stepping
    at a ``substeps``-th of their spacing."""
    from femrom.rom import SecondOrderROM

    dt = float(test.times[1] - test.times[0])
    n = test.states.shape[1] - 1
    t = (dt / substeps) * np.arange(n * substeps + 1)
    sol = SecondOrderROM(operators).predict(t, initial=(test.states[:, 0], test.velocities[:, 0]), scheme=scheme)
    return sol.q[:, ::substeps], sol.v[:, ::substeps]


def prediction_errors(operators, system: KnownSystem, test: SecondOrderData, substeps: int = 8) -> dict:
    """Relative errors ``||Q - Q_true||_F / ||Q_true||_F`` of ``operators``' prediction of ``test`` (stepping at
    ``dt / substeps`` with the discrete-gradient scheme) over the training window's length and over all of ``test``."""
    Q = predict(operators, test, substeps)[0]
    split = int(round(system.t_train / system.dt)) + 1

    def error(cols):
        return float(np.linalg.norm(Q[:, cols] - test.states[:, cols]) / np.linalg.norm(test.states[:, cols]))

    return {"window": error(slice(0, split)), "total": error(slice(None)), "finite": bool(np.all(np.isfinite(Q)))}
