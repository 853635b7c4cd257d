r"""Modes of a system linearised about a static state, and how a beam mode is named by its shape.

About an equilibrium ``(q_0, z)`` (e.g. a bolt preload, :func:`femrom.scene.preload`),
small vibrations obey ``M dq'' + K_t dq = 0`` with the tangent

.. math::

    K_t = K + \partial f / \partial q\,(q_0; z),

the state ``z`` frozen (a stuck joint: the tangential springs of the closed pairs
act, open pairs contribute nothing). :func:`linearized_modes` solves
``K_t phi = omega^2 M phi`` by shift-invert Lanczos below zero, so a free
structure's rigid-body modes (omega^2 ~ 0) come first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import eigsh

from femrom._errors import FemromValueError
from femrom.scene._system import SecondOrderSystem

#: ``||K_t - K_t^T||_1 / ||K_t||_1`` above which the tangent is refused (a slipping dry-friction
#: pair's tangent is not symmetric: linearise about a stuck state).
SYMMETRY_TOLERANCE = 1e-10


@dataclass(frozen=True, eq=False)
class Modes:
    """Result of :func:`linearized_modes`.

    Attributes
    ----------
    eigenvalues : (k,) ndarray
        ``omega^2`` [rad^2/s^2], ascending.
    shapes : (n, k) ndarray
        Mass-normalised mode shapes (``phi^T M phi = 1``).
    """

    eigenvalues: np.ndarray
    shapes: np.ndarray

    @property
    def frequencies(self) -> np.ndarray:
        """(k,) ``sign(omega^2) sqrt(|omega^2|) / (2 pi)`` [Hz] (a rigid-body mode's round-off keeps its sign)."""
        return np.sign(self.eigenvalues) * np.sqrt(np.abs(self.eigenvalues)) / (2 * np.pi)


def tangent_stiffness(system: SecondOrderSystem, displacement: np.ndarray, state=None) -> sp.csr_matrix:
    """(n, n) ``K + df/dq (q_0; z)`` (``K`` alone for a linear system)."""
    K = sp.csr_matrix(system.stiffness)
    if system.nonlinear is None:
        return K
    force = system.nonlinear
    D = force.tangent(displacement, None, force.initial_state() if state is None else state)[0]
    return K if D is None else (K + D).tocsr()


def linearized_modes(system: SecondOrderSystem, displacement: np.ndarray | None = None, state=None, *,
                     n_modes: int = 12, shift: float = -(2 * np.pi * 10.0) ** 2) -> Modes:
    r"""The ``n_modes`` lowest modes of ``K_t phi = omega^2 M phi`` about ``(q_0, z)`` (module docstring).

    Parameters
    ----------
    system : SecondOrderSystem
    displacement : (n,) ndarray, optional
        ``q_0`` (default zero).
    state : optional
        The nonlinear force's committed state at ``q_0``.
    n_modes : int
        Number of modes (a free solid: 6 rigid-body modes first).
    shift : float
        ``sigma`` [rad^2/s^2] of the shift-invert; below zero, ``K_t - sigma M`` is positive
        definite for a free structure (default ``-(2 pi 10 Hz)^2``).

    Raises
    ------
    FemromValueError
        A bad ``n_modes``, or a tangent that is not symmetric (a slipping contact).
    """
    n = system.n_dofs
    if not (1 <= int(n_modes) < n):
        raise FemromValueError(f"n_modes must lie in [1, {n}), got {n_modes!r}")
    q = np.zeros(n) if displacement is None else np.asarray(displacement, dtype=float)
    Kt = tangent_stiffness(system, q, state)
    asymmetry = sp.linalg.norm(Kt - Kt.T, 1) / sp.linalg.norm(Kt, 1)
    if asymmetry > SYMMETRY_TOLERANCE:
        raise FemromValueError(f"the tangent stiffness is not symmetric (relative {asymmetry:.2g}): "
                               "a slipping contact; linearise about a stuck state "
                               "(friction on from the committed preload)")
    # a fixed start vector (ARPACK's default is random) and a sign convention (largest entry positive):
    # the same system gives the same modes, run after run
    values, vectors = eigsh(Kt.tocsc(), k=int(n_modes), M=sp.csc_matrix(system.mass), sigma=float(shift),
                            which="LM", v0=np.ones(n))
    order = np.argsort(values)
    vectors = vectors[:, order]
    signs = np.sign(vectors[np.argmax(np.abs(vectors), axis=0), np.arange(vectors.shape[1])])
    return Modes(values[order], vectors * np.where(signs == 0, 1.0, signs))


@dataclass(frozen=True)
class BeamModeShape:
    """How :func:`beam_mode_shape` reads a mode of a beam along x.

    Attributes
    ----------
    kind : str
        ``"axial"`` (mean u_x), ``"vertical"`` (mean u_y: bending in y), ``"in-plane"`` (mean u_z:
        bending in z) or ``"torsion"`` (rotation of the section about x).
    share : float
        That motion's share of the norm of the four section profiles (1: pure).
    sign_changes : int
        Sign changes of its profile along x (2 for a first bending mode, 3 for a second;
        1 for a first torsion or axial mode).
    """

    kind: str
    share: float
    sign_changes: int


def beam_mode_shape(points: np.ndarray, displacements: np.ndarray, *, n_slices: int = 36) -> BeamModeShape:
    r"""Name a mode of a straight beam along x by its section motion.

    The nodes are binned into ``n_slices`` slices along x; per slice the mean
    displacements ``(u_x, u_y, u_z)`` and the rotation about the slice's centroid axis

    .. math::

        \theta = \frac{\sum (y' u_z - z' u_y)}{\sum (y'^2 + z'^2)}, \quad
        \text{scaled by } r = \sqrt{\overline{y'^2 + z'^2}},

    give four profiles along x; the largest (in the 2-norm over the slices) names the mode.

    Parameters
    ----------
    points : (k, 3) ndarray
        Node positions.
    displacements : (k, 3) ndarray
        The mode's displacement at those nodes.
    n_slices : int
    """
    points = np.asarray(points, dtype=float)
    u = np.asarray(displacements, dtype=float)
    x = points[:, 0]
    cells = np.minimum(((x - x.min()) / np.ptp(x) * n_slices).astype(int), n_slices - 1)
    count = np.bincount(cells, minlength=n_slices).astype(float)
    count[count == 0] = np.inf
    mean = lambda values: np.bincount(cells, values, n_slices) / count          # noqa: E731
    y = points[:, 1] - mean(points[:, 1])[cells]
    z = points[:, 2] - mean(points[:, 2])[cells]
    inertia = mean(y**2 + z**2)
    theta = mean(y * u[:, 2] - z * u[:, 1]) / np.where(inertia > 0, inertia, np.inf)
    profiles = {"axial": mean(u[:, 0]), "vertical": mean(u[:, 1]), "in-plane": mean(u[:, 2]),
                "torsion": theta * np.sqrt(inertia)}
    norms = {kind: float(np.linalg.norm(p)) for kind, p in profiles.items()}
    kind = max(norms, key=norms.get)
    total = np.sqrt(sum(v**2 for v in norms.values()))
    profile = profiles[kind]
    signs = np.sign(profile[np.abs(profile) > 1e-3 * np.abs(profile).max()])
    return BeamModeShape(kind, norms[kind] / total, int(np.count_nonzero(np.diff(signs))))
