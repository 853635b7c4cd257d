r"""Quasi-static modal analysis (QSMA): a mode's backbone from static solves alone.

Lacayo & Allen (2019, "Updating structural models containing nonlinear Iwan joints using
quasi-static modal analysis", MSSP 118) load a structure statically in the shape of one
mode's inertia force, ``F = alpha M phi`` (``phi`` mass-normalised, ``phi^T M phi = 1``),
for increasing ``alpha``, and read the mode's amplitude-dependent stiffness and damping
from the monotonic load-displacement curve, measured in the modal coordinate
``a = phi^T M (q - q_0)`` from the preloaded state ``q_0``:

- the secant frequency ``omega(a)^2 = alpha(a) / a``;
- Masing's rules (unloading and reloading branches are the loading curve scaled by two
  and shifted to the turning points) give the energy one full cycle of amplitude ``a``
  dissipates,

      D(a) = 8 [ int_0^a alpha(s) ds - a alpha(a) / 2 ],

  which is ``4 F_s (a - F_s / k_t)`` for a Jenkins element beyond slip;
- the damping ratio of a linear oscillator that dissipates ``D`` per cycle at the same
  amplitude and frequency, ``D = 2 pi zeta omega^2 a^2`` (unit modal mass):

      zeta(a) = D(a) / (2 pi omega(a)^2 a^2).

It needs no time integration, so it costs a few dozen Newton solves where a ring-down
costs thousands of steps; it assumes the mode keeps its shape (one mode, weak coupling)
and that the joint's hysteresis is Masing (true of Jenkins and Iwan elements).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from femrom._errors import FemromValueError
from femrom.post._backbone import Backbone


def masing_damping(modal_amplitude, modal_force) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Secant frequency, dissipation per cycle and damping ratio along a monotonic loading curve.

    Parameters
    ----------
    modal_amplitude : (s,) array
        ``a_1 < a_2 < ... < a_s``, positive (the curve starts at the origin, which is not
        listed).
    modal_force : (s,) array
        ``alpha(a_i)``.

    Returns
    -------
    omega : (s,) ndarray
        ``sqrt(alpha / a)`` [rad/s].
    dissipation : (s,) ndarray
        ``D(a_i)``, the integral by the trapezoidal rule from the origin (exact for a
        piecewise-linear curve whose kinks are samples; O(h^2) otherwise).
    damping_ratio : (s,) ndarray
        ``D / (2 pi omega^2 a^2)``.
    """
    a = np.asarray(modal_amplitude, dtype=float).reshape(-1)
    f = np.asarray(modal_force, dtype=float).reshape(-1)
    if a.shape != f.shape or a.size == 0:
        raise FemromValueError(f"modal_amplitude and modal_force need one shape, got {a.shape} and {f.shape}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(f))):
        raise FemromValueError("modal_amplitude and modal_force must be finite")
    if a[0] <= 0 or np.any(np.diff(a) <= 0):
        raise FemromValueError("modal_amplitude must be positive and increasing (a monotonic loading curve)")
    if np.any(f <= 0):
        raise FemromValueError("modal_force must be positive along the loading curve")
    a0, f0 = np.concatenate([[0.0], a]), np.concatenate([[0.0], f])
    work = np.cumsum(0.5 * (f0[1:] + f0[:-1]) * np.diff(a0))
    dissipation = 8.0 * (work - 0.5 * a * f)
    omega_squared = f / a
    zeta = dissipation / (2.0 * np.pi * omega_squared * a * a)
    return np.sqrt(omega_squared), dissipation, zeta


@dataclass(frozen=True)
class QuasiStaticBackbone:
    """A QSMA result: the loading curve and what Masing's rules make of it.

    Attributes
    ----------
    modal_force, modal_amplitude : (s,) ndarray
        ``alpha`` and ``a = phi^T M (q - q_0)``.
    frequency_hz, dissipation, damping_ratio : (s,) ndarray
        ``omega / 2 pi``, ``D(a)``, ``zeta(a)`` (:func:`masing_damping`).
    output_amplitude : (s, p) ndarray or None
        ``|E (q - q_0)|`` at each load: the outputs' displacement amplitudes.
    """

    modal_force: np.ndarray
    modal_amplitude: np.ndarray
    frequency_hz: np.ndarray
    dissipation: np.ndarray
    damping_ratio: np.ndarray
    output_amplitude: np.ndarray | None = None

    def backbone(self, output: int = 0, *, quantity: str = "acceleration") -> Backbone:
        """The curve as a :class:`Backbone` against one output's amplitude.

        ``quantity="acceleration"``: ``omega^2 |E_i (q - q_0)|`` (a harmonic motion's
        acceleration amplitude, as an accelerometer reads it); ``"displacement"``:
        ``|E_i (q - q_0)|``; ``"modal"``: ``a`` itself.
        """
        if quantity == "modal":
            amplitude = self.modal_amplitude
        else:
            if self.output_amplitude is None:
                raise FemromValueError("this QSMA was run without outputs; pass output_matrix")
            displacement = self.output_amplitude[:, output]
            if quantity == "displacement":
                amplitude = displacement
            elif quantity == "acceleration":
                amplitude = (2 * np.pi * self.frequency_hz) ** 2 * displacement
            else:
                raise FemromValueError(f"unknown quantity {quantity!r}; valid: acceleration, displacement, modal")
        return Backbone(time=np.zeros_like(amplitude), amplitude=amplitude, frequency_hz=self.frequency_hz,
                        damping_ratio=self.damping_ratio, method="qsma")


def quasi_static_modal_analysis(solve: Callable[[np.ndarray], np.ndarray], mass, mode: np.ndarray,
                                modal_forces, *, reference: np.ndarray | None = None,
                                output_matrix=None, rigid_modes: np.ndarray | None = None, progress: Callable[[str], None] | None = None
                                ) -> QuasiStaticBackbone:
    r"""Load ``F = alpha M phi`` for increasing ``alpha`` and read the backbone (module docstring).

    Parameters
    ----------
    solve : callable
        ``solve(F) -> q`` (n,): the static state under the preload plus ``F``, continued
        from the previous call (a frictional joint's sliders follow the loading path: the
        calls come in increasing ``alpha``, as a monotonic loading from ``q_0``).
    mass : (n, n) sparse or ndarray
    mode : (n,) ndarray
        ``phi``; normalised here to ``phi^T M phi = 1``.
    modal_forces : (s,) array
        Increasing positive ``alpha`` [N per unit modal mass, i.e. m/s^2 * kg^{1/2}].
    reference : (n,) ndarray, optional
        ``q_0``, the preloaded state (default zero).
    output_matrix : (p, n) sparse or ndarray, optional
        ``E``: the outputs' amplitudes are reported along.
    rigid_modes : (n, k) ndarray, optional
        Mass-orthonormal rigid-body modes ``R`` of a free structure held by statically
        determinate supports in ``solve``: the supports add a rigid motion to the static
        deflection (the load ``M phi`` is self-equilibrated, the deflection is fixed at the
        supports), which the outputs must not see; they read ``(I - R R^T M)(q - q_0)``.
        The modal amplitude is unaffected (``phi^T M R = 0``).
    progress : callable, optional
        Called with one line per load.
    """
    phi = np.asarray(mode, dtype=float).reshape(-1)
    m_phi = mass @ phi
    norm = float(phi @ m_phi)
    if not norm > 0:
        raise FemromValueError("mode must have positive modal mass phi^T M phi")
    phi, m_phi = phi / np.sqrt(norm), m_phi / np.sqrt(norm)
    alphas = np.asarray(modal_forces, dtype=float).reshape(-1)
    if alphas.size == 0 or not np.all(np.isfinite(alphas)) or alphas[0] <= 0 or np.any(np.diff(alphas) <= 0):
        raise FemromValueError("modal_forces must be positive, finite and increasing")
    q0 = np.zeros_like(phi) if reference is None else np.asarray(reference, dtype=float).reshape(-1)
    amplitudes, outputs = [], []
    for i, alpha in enumerate(alphas):
        q = np.asarray(solve(alpha * m_phi), dtype=float).reshape(-1) - q0
        if rigid_modes is not None:
            q = q - rigid_modes @ (rigid_modes.T @ (mass @ q))
        amplitudes.append(float(phi @ (mass @ q)))
        if output_matrix is not None:
            outputs.append(np.abs(np.asarray(output_matrix @ q).reshape(-1)))
        if progress is not None:
            progress(f"QSMA load {i + 1}/{alphas.size}: alpha = {alpha:.4g}, a = {amplitudes[-1]:.4g}")
    a = np.asarray(amplitudes)
    omega, dissipation, zeta = masing_damping(a, alphas)
    return QuasiStaticBackbone(alphas, a, omega / (2 * np.pi), dissipation, zeta,
                               None if output_matrix is None else np.vstack(outputs))
