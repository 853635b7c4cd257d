r"""Backbone -> backbone maps: a time scheme's period error removed, a linear damping added.

- :func:`period_corrected`: the trapezoidal family (Newmark's average acceleration, the
  implicit midpoint rule, the discrete-gradient schemes built on it) integrates a linear
  oscillator of frequency ``f`` with a period that is too long: at step ``dt`` it oscillates at
  ``f_h = arctan(pi f dt) / (pi dt)``. Its inverse, ``f = tan(pi f_h dt) / (pi dt)``, maps the
  frequency read from a simulated signal back to the model's (exact for a linear mode; for an
  amplitude-dependent one, to the order of the frequency's change over a step).
- :func:`with_linear_damping`: QSMA's damping ratio is the joint's alone (Masing's dissipation);
  a linear modal damping ratio adds to it, ``zeta = zeta_joint + zeta_lin``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

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
