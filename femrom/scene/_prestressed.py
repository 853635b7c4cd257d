r"""A preloaded structure with a frictional joint: its modes, a law parameter calibrated on a
measured frequency, and an Iwan joint about the preload.

:func:`prestressed_model` builds a scene and runs the preload sequence (:func:`preload`:
frictionless contact, then friction on from that state) on statically determinate point
supports. The modes about the preload are those of the tangent ``K + df/dq`` at the preloaded
state (:func:`linearized_modes`: closed pairs stuck, open pairs free). A joint-law parameter
``p`` that does not change the preloaded state (the tangential stiffness ``k_t`` of a
frictionless preload) is calibrated by :func:`calibrate_law_parameter`: Brent's method on
``log10 p`` for ``f_m(p) = f_target``, one eigensolve per trial (:func:`mode_frequency`).

:func:`clamped_iwan_joint` replaces the dry-friction joint by the ``clamped_iwan`` law
(:class:`~femrom.fem.ClampedIwanLaw`: the preload's contact status and slip traction
``mu p_0`` frozen, the slip spread over an Iwan element) and re-solves the static equilibrium
under it.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from femrom._errors import FemromRuntimeError
from femrom.fem import ClampedIwanLaw, JointForce, clamped_iwan_state, clamped_state
from femrom.scene._build import build
from femrom.scene._modal import BeamModeShape, beam_mode_shape, linearized_modes
from femrom.scene._static import point_supports, preload, solve_static


@dataclass(frozen=True, eq=False)
class PrestressedModel:
    """A built scene, the free-dof indices of its point supports and its preload.

    Attributes
    ----------
    fom : FullOrderModel
        :func:`build`'s result; ``fom.system.nonlinear`` is the joint.
    supports : (k,) int ndarray
        Free-dof indices held in the preload (:func:`point_supports`).
    preload : Preload
        :func:`preload`'s result: ``preload.displacement`` (n,), ``preload.state``.
    seconds : float
        Build and preload time.
    """

    fom: object
    supports: np.ndarray
    preload: object
    seconds: float

    @property
    def joint(self) -> JointForce:
        return self.fom.system.nonlinear


def prestressed_model(scene, supports) -> PrestressedModel:
    """Build ``scene`` and preload it on the point ``supports`` (``[(point (3,), "xyz"), ...]``,
    as :func:`point_supports` takes them): statically determinate, so that the reactions of a
    self-equilibrated preload vanish."""
    tic = time.perf_counter()
    fom = build(scene)
    dofs = point_supports(fom.space, fom.system.condensation, supports)
    state = preload(fom.system, supports=dofs)
    return PrestressedModel(fom, dofs, state, time.perf_counter() - tic)


def with_law_parameters(system, **parameters):
    """``system`` with its joint's interface-law parameters replaced, e.g.
    ``with_law_parameters(system, tangential_stiffness=1e12)`` (the others and the joint's
    geometry kept)."""
    joint = system.nonlinear
    law = {**joint.law.parameters(), **{name: float(value) for name, value in parameters.items()}}
    return dataclasses.replace(system, nonlinear=JointForce.from_parameters({**joint.parameters(), "law": law}))


def beam_mode_shapes(space, condensation, vectors) -> list[BeamModeShape]:
    """:func:`beam_mode_shape` of each column of ``vectors`` (n_free, k): the free-dof shapes expanded
    to the nodes of a 3-component vector space (node ``i``'s components at rows ``3 i .. 3 i + 2``)."""
    points = space.basis.doflocs[:, ::3].T
    vectors = np.asarray(vectors)
    vectors = vectors.reshape(vectors.shape[0], -1)
    return [beam_mode_shape(points, condensation.expand(vectors[:, j]).reshape(-1, 3)) for j in range(vectors.shape[1])]


def mode_frequency(model: PrestressedModel, mode: int, *, shape: tuple[str, int] | None = None,
                   **law_parameters) -> float:
    """Frequency [Hz] of mode ``mode`` (0-based, rigid-body modes counted) about the preload, with the
    joint law's parameters replaced (:func:`with_law_parameters`).

    ``shape``: ``(kind, sign_changes)`` the mode must have (:class:`BeamModeShape`), e.g.
    ``("vertical", 2)`` for the first vertical bending mode of a free beam.

    Raises
    ------
    RuntimeError
        The mode's shape is not ``shape``.
    """
    system = with_law_parameters(model.fom.system, **law_parameters) if law_parameters else model.fom.system
    modes = linearized_modes(system, model.preload.displacement, model.preload.state, n_modes=mode + 1)
    if shape is not None:
        (found,) = beam_mode_shapes(model.fom.space, system.condensation, modes.shapes[:, mode:mode + 1])
        if (found.kind, found.sign_changes) != tuple(shape):
            raise FemromRuntimeError(f"mode {mode} is not of shape {tuple(shape)}: {found}")
    return float(modes.frequencies[mode])


def calibrate_law_parameter(model: PrestressedModel, name: str, target_hz: float, bracket, *, mode: int,
                            shape: tuple[str, int] | None = None, xtol: float = 1e-5) -> tuple[float, int]:
    """``(p, evaluations)``: the joint-law parameter ``name`` for which :func:`mode_frequency` is ``target_hz``.

    Brent's method on ``log10 p`` in ``bracket`` (``f_m`` must cross the target there: it rises with a
    stiffness); ``xtol`` in ``log10 p`` (1e-5: 2.3e-5 relative in ``p``). The parameter must not change
    the preloaded state (the preload is not re-solved), as ``tangential_stiffness`` does not after a
    frictionless preload."""
    count = [0]

    def mismatch(log_p):
        count[0] += 1
        return mode_frequency(model, mode, shape=shape, **{name: 10.0**log_p}) - target_hz

    log_p = brentq(mismatch, *np.log10(bracket), xtol=xtol)
    return 10.0**log_p, count[0]


def clamped_iwan_joint(system, displacement, state, supports, *, friction_coefficient: float, chi: float,
                       beta: float, closing: float = 0.0, closing_friction: float = 0.0,
                       closing_damping: float = 0.0):
    """``(system, q0, z0)``: ``system``'s ``dry_friction`` joint replaced by the ``clamped_iwan`` law about a
    preload (``displacement``, ``state``), at its static equilibrium.

    The Iwan points start from the preload (:func:`~femrom.fem.clamped_state`: contact status, slip
    traction ``mu p_0`` with ``mu = friction_coefficient``; :func:`~femrom.fem.clamped_iwan_state`: every
    slider at the point's preload slider); the static equilibrium is re-solved under the new law on the
    free-dof ``supports`` (its weakest sliders carry less of the preload's tangential traction), so that
    ``q0`` is an equilibrium of the returned system and ``z0`` its committed state there. ``chi`` and
    ``beta``: the Iwan density's exponent and the weight of its delta (:class:`~femrom.fem.ClampedIwanLaw`);
    the normal and tangential stiffnesses are the dry-friction law's. ``closing``: ``kappa``, points open at the
    preload close again under the normal penalty ``kappa k_n`` (the law's ``closing``; 0: they stay open), with Coulomb
    coefficient ``closing_friction`` and the Hunt-Crossley normal dashpot ``closing_damping`` ``lambda`` [Pa s/m^2]
    (the law's, ``t_n = min(kappa k_n g_n - lambda g_n gdot_n, 0)``; 0: none).
    """
    joint = system.nonlinear
    law = joint.law.parameters()
    gaps = joint.gaps(joint.localize(displacement))
    clamped = clamped_state(gaps, state, normal_stiffness=law["normal_stiffness"],
                            friction_coefficient=friction_coefficient)
    iwan = ClampedIwanLaw(law["normal_stiffness"], law["tangential_stiffness"], chi, beta, closing=closing,
                          closing_friction=closing_friction, closing_damping=closing_damping)
    force = JointForce.from_parameters({**joint.parameters(), "law": iwan.parameters()})
    model = dataclasses.replace(system, nonlinear=force)
    static = solve_static(model, system.load, supports=supports, state=clamped_iwan_state(iwan, gaps, clamped),
                          initial_displacement=displacement, closed_start=False)
    q = static.displacement
    return model, q, force.commit(q, None, static.state)
