r"""``bolt_preload``: bolts clamping a joint, as pressures on their washer patches.

Bolt ``j`` clamps with a force ``F_j`` (N): a uniform pressure on each of its
two washer patches (outer faces of the joint, on opposite sides),

.. math::

    p_{j,k} = F_j / \Big|\int_{\Gamma_{j,k}} n \, ds\Big|, \qquad
    f_0 = \sum_{j,k} -p_{j,k} \int_{\Gamma_{j,k}} n\, \phi \, ds,

pushing into the body on both patches, so each bolt's two patch forces are
``F_j`` in opposite directions (a self-equilibrated load: the free structure
needs its rigid-body modes held in a static solve, see
:func:`femrom.scene.solve_static`). The divisor is the meshed patch's projected
area (the area of a flat patch), so the resultant is exactly ``F_j`` whatever
the chordal error of the meshed annulus. The bolt shank is not modelled. The
load is the system's constant ``f_0`` (:attr:`SecondOrderSystem.load`).

Example::

    [effects.bolt_preload]
    washers = [["washer_top_1", "washer_bottom_1"], ["washer_top_2", "washer_bottom_2"],
               ["washer_top_3", "washer_bottom_3"]]
    force = 12000.0          # N per bolt, or one value per bolt
"""

from __future__ import annotations

import math

import numpy as np

from femrom import fem
from femrom.scene._conditions import LoadConfig
from femrom.scene._effects import Effect, register_effect
from femrom.scene._errors import SceneError


@register_effect
class BoltPreload(Effect):
    """Washer-patch pressures of bolts (see the module docstring).

    Options: ``washers`` (one ``[patch, patch]`` pair of boundary names per
    bolt), ``force`` (N, > 0: one number for every bolt or one per bolt).
    """

    name = "bolt_preload"
    options = {"washers": None, "force": None}
    provides = "load"
    stage = 3

    @classmethod
    def check(cls, options):
        where = f"[effects.{cls.name}]"
        washers = options["washers"]
        if not (isinstance(washers, (list, tuple)) and washers and all(
                isinstance(bolt, (list, tuple)) and len(bolt) == 2 and all(isinstance(n, str) for n in bolt)
                for bolt in washers)):
            raise SceneError(f"{where} washers must list one [patch, patch] pair of boundary names per bolt, "
                             f"got {washers!r}")
        forces(options)

    def assemble(self, build, options):
        space, condensation = build.space, build.condensation
        where = f"[effects.{self.name}]"
        if not isinstance(space, fem.SolidSpace):
            raise SceneError(f"{where} needs a solid with washer patches, got {type(space).__name__}")
        with build.timed("load"):
            total = np.zeros(space.n_total)
            for bolt, force in zip(options["washers"], forces(options)):
                for patch in bolt:
                    try:
                        unit = space.load_vector(LoadConfig("surface_pressure", patch, magnitude=1.0))
                    except (KeyError, ValueError) as exc:
                        raise SceneError(f"{where} washers: patch {patch!r}: {exc}") from None
                    resultant = np.linalg.norm(unit.reshape(-1, 3).sum(axis=0))   # |int n ds|, m^2
                    if not resultant > 0:
                        raise SceneError(f"{where} washers: patch {patch!r} has no projected area")
                    total += force / resultant * unit
            load = condensation.vector(total)
            build.load = load if build.load is None else build.load + load


def forces(options: dict) -> np.ndarray:
    """(bolts,) clamping forces [N] of the options, or one SceneError naming ``force``."""
    where = "[effects.bolt_preload]"
    n_bolts = len(options["washers"])
    given = options["force"]
    values = given if isinstance(given, (list, tuple)) else [given] * n_bolts
    if len(values) != n_bolts or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0
            for v in values):
        raise SceneError(f"{where} force must be a positive number of newtons, or {n_bolts} of them "
                         f"(one per bolt), got {given!r}")
    return np.asarray(values, dtype=float)
