r"""``joint``: interface elements between two named faces of a jointed mesh (a bolted lap joint).

The two faces (``between``) carry duplicated, coincident nodes
(:func:`femrom.mesh.interface_pairs`); each pair becomes a zero-thickness
interface element under one law of :data:`femrom.fem.INTERFACE_LAWS`, and the
scene gets the joint force

.. math::

    f(q; z) = L^\top \big(A_i\, t_i(R_i (u_{b,i} - u_{a,i}) + \Delta_{0,i};\ z_i)\big)_i

on the free dofs (:class:`femrom.fem.JointForce`): ``t_i`` the law's traction
(Pa), ``A_i`` the pair's lumped area, ``R_i`` its frame (``t1`` along x where
the face allows it, ``n`` the outward normal of the first face), ``Delta_0``
the initial normal gap.

Example (``femrom/cases/jointed_beam.toml``)::

    [effects.joint]
    between = ["interface_left", "interface_right"]
    law = "dry_friction"
    parameters = { normal_stiffness = 1e14, tangential_stiffness = 1e12, friction_coefficient = 0.6 }
    initial_gap = 0.0
"""

from __future__ import annotations

import math

import numpy as np

from femrom import fem
from femrom.mesh import MeshError, interface_pairs
from femrom.scene._effects import Effect, register_effect
from femrom.scene._errors import SceneError


@register_effect
class Joint(Effect):
    """Interface elements at the node pairs of two faces (see the module docstring).

    Options: ``between`` (two face names: side a, whose normal is used, and
    side b), ``law`` (a registered interface law: ``dry_friction``,
    ``jenkins``, ``iwan``), ``parameters`` (a table of the law's parameters,
    per unit area), ``initial_gap`` (m; negative: an interference). The pairs
    follow the element: vertices for ``p1``, vertices and edge midpoints for
    ``p2``. A pair component whose dof is clamped by ``[boundary]`` is held
    fixed (dof -1 of :class:`femrom.fem.JointForce`).
    """

    name = "joint"
    options = {"between": None, "law": "dry_friction", "parameters": {}, "initial_gap": 0.0}
    provides = "nonlinear"
    stage = 4

    @classmethod
    def check(cls, options):
        where = f"[effects.{cls.name}]"
        between = options["between"]
        if not (isinstance(between, (list, tuple)) and len(between) == 2
                and all(isinstance(name, str) and name for name in between)):
            raise SceneError(f"{where} between must name two interface faces, e.g. "
                             f"['interface_left', 'interface_right'], got {between!r}")
        if between[0] == between[1]:
            raise SceneError(f"{where} between names the face {between[0]!r} twice; give two different faces")
        law_of(options)
        gap = options["initial_gap"]
        if isinstance(gap, bool) or not isinstance(gap, (int, float)) or not math.isfinite(gap):
            raise SceneError(f"{where} initial_gap must be a finite number (m), got {gap!r}")

    def assemble(self, build, options):
        space, condensation = build.space, build.condensation
        where = f"[effects.{self.name}]"
        if not isinstance(space, fem.SolidSpace):
            raise SceneError(f"{where} needs a solid (a 3D mesh with two interface faces), got {type(space).__name__}")
        with build.timed("nonlinear"):
            side_a, side_b = options["between"]
            order = 2 if space.element == "p2" else 1
            try:
                pairs = interface_pairs(space.mesh, side_a, side_b, order=order)
            except MeshError as exc:
                raise SceneError(f"{where} between = {[side_a, side_b]}: {exc}") from None
            dofs = free_indices(condensation.free, pairs.dofs())          # (s, 2, 3), -1 where clamped
            build.nonlinear_forces.append(fem.JointForce(
                law_of(options), dofs[:, 0], dofs[:, 1], pairs.normals, pairs.areas, condensation.n_free,
                initial_gap=float(options["initial_gap"]), first_tangents=pairs.local_frames()[:, 0],
                name=self.name))


def law_of(options: dict) -> fem.InterfaceLaw:
    """The interface law of the effect's ``law`` and ``parameters``, or one SceneError naming the key."""
    where = "[effects.joint]"
    name = options["law"]
    if name not in fem.INTERFACE_LAWS:
        raise SceneError(f"{where} unknown law {name!r}; valid: {', '.join(fem.INTERFACE_LAWS)}")
    parameters = options["parameters"]
    if not isinstance(parameters, dict):
        raise SceneError(f"{where} parameters must be a table of the {name!r} law's parameters, got {parameters!r}")
    try:
        return fem.interface_law(name, **parameters)
    except TypeError as exc:      # an unknown or missing parameter name
        raise SceneError(f"{where} parameters of law {name!r}: {exc}") from None
    except ValueError as exc:     # a bad value: the law's message names it
        raise SceneError(f"{where} parameters: {exc}") from None


def free_indices(free: np.ndarray, dofs: np.ndarray) -> np.ndarray:
    """Positions of full-numbering ``dofs`` in the sorted ``free`` dofs; -1 for a fixed dof (same shape)."""
    position = np.minimum(np.searchsorted(free, dofs), free.size - 1)
    return np.where(free[position] == dofs, position, -1)
