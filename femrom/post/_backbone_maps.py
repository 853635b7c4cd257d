r"""Backbone -> backbone maps: a time scheme's period error removed, a linear damping added.

- :func:`period_corrected`: the trapezoidal family (Newmark's average acceleration, the
  implicit midpoint rule, the discrete-gradient schemes built on it) integrates a linear
  oscillator of frequency ``f`` with a period that is too long: at step ``dt`` it oscillates at
  ``f_h = arctan(pi f dt) / (pi dt)``. Its inverse, ``f = tan(pi f_h dt) / (pi dt)``, maps the
  frequency read from a simulated signal back to the model's (exact for a linear mode; for an
  amplitude-dependent one, to the order of the frequency's change over a step).
- :func:`with_linear_damping`: QSMA's damping ratio is the joint's alone (Masing's dissipation);
  a linear modal damping ratio adds to it, ``zeta = zeta_joint + zeta_lin``.
- :func:`epmc_backbone`: a nonlinear mode computed by EPMC as a backbone, to be compared with
  ring-down and QSMA backbones.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from femrom._errors import FemromValueError
from femrom.post._backbone import Backbone


def period_corrected(backbone: Backbone, dt: float) -> Backbone:
    """``backbone`` with the trapezoidal family's period elongation at step ``dt`` removed:
    ``f = tan(pi f_h dt) / (pi dt)`` (module docstring); amplitudes and damping kept."""
    frequency = np.tan(np.pi * backbone.frequency_hz * dt) / (np.pi * dt)
    return dataclasses.replace(backbone, frequency_hz=frequency)


def with_linear_damping(backbone: Backbone, damping_ratio: float) -> Backbone:
    """``backbone`` with ``damping_ratio`` added to its damping ratios (a QSMA backbone, whose damping is
    the joint's alone, of a model with linear modal damping)."""
    return dataclasses.replace(backbone, damping_ratio=backbone.damping_ratio + damping_ratio)


def epmc_backbone(modes, *, quantity: str = "modal", output: int = 0) -> Backbone:
    r"""A nonlinear mode (:class:`femrom.integrators.NonlinearModes`, EPMC) as a :class:`Backbone`.

    ``quantity``: ``"modal"`` (the modal amplitude ``a``), ``"displacement"`` (the fundamental
    amplitude of output ``output``), ``"acceleration"`` (``Omega^2`` times it, as an
    accelerometer's band-passed envelope reads). The frequency is EPMC's ``Omega`` (an undamped
    modal frequency: a ring-down's damped one is lower by ``1 - sqrt(1 - D^2)``, 5e-7 at
    ``D = 0.1 %``), the damping ratio ``D = xi / (2 Omega)``.
    """
    if quantity == "modal":
        amplitude = modes.modal_amplitude
    elif quantity in ("displacement", "acceleration"):
        amplitude = modes.output_amplitude[:, output]
        if quantity == "acceleration":
            amplitude = modes.omega ** 2 * amplitude
    else:
        raise FemromValueError(f"unknown quantity {quantity!r}; valid: modal, displacement, acceleration")
    return Backbone(time=np.zeros(len(modes)), amplitude=amplitude, frequency_hz=modes.frequency_hz,
                    damping_ratio=modes.damping_ratio, method="epmc")
