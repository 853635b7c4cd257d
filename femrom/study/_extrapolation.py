"""A study of extrapolation in time: learn from a structure's release over ``[0, T]``, predict
the same release far beyond ``T``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from femrom.inference import learner_class
from femrom.integrators import time_scheme
from femrom.scene import BasisSpec, Derivatives, LearnerSpec, ReportSpec, RomConfig, RunSpec, Scene

#: label -> registered learner: the intrusive reference, L-OpInf and plain OpInf
EXTRAPOLATION_LEARNERS = {"galerkin": "galerkin", "lopinf": "lopinf", "plain_opinf": "opinf"}
#: label -> the name plots and tables give them
EXTRAPOLATION_LEARNER_NAMES = {"galerkin": "intrusive Galerkin", "lopinf": "L-OpInf", "plain_opinf": "plain OpInf"}


def extrapolation_config(dt: float, train_window: float, t_end: float, ranks, *,
                         derivatives: Derivatives = Derivatives("finite_differences", 4), terms=(),
                         learners: dict = EXTRAPOLATION_LEARNERS) -> RomConfig:
    """The ``[rom]`` section of an extrapolation study at step ``dt``.

    Training run ``"train"`` on ``[0, T]``, ``T = round(train_window / dt) dt``; test run
    ``"extrapolation"``, the same release over ``[0, round(t_end / dt) dt]``, scored after
    ``T``; a POD basis (exact SVD) of the training snapshots with ``ranks`` columns; the
    ``learners`` (label -> learner name) on reduced ``derivatives``, the learned ones with the
    extra ``terms`` (e.g. ``("damping",)``: a damping fitted although the structure has none);
    no renders.
    """
    T = int(round(train_window / dt)) * dt
    specs = tuple(LearnerSpec(label, name, derivatives,
                              terms=tuple(terms) if "reduced_data" in learner_class(name).needs else ())
                  for label, name in learners.items())
    return RomConfig(
        train=(RunSpec("train", t_end=T),),
        test=(RunSpec("extrapolation", t_end=int(round(t_end / dt)) * dt, score_after=T),),
        learners=specs, basis=BasisSpec(tuple(ranks), method="svd"), extension=1.0,
        report=ReportSpec(render=False, paraview=False))


def extrapolation_scene(scene: Scene, dt: float, train_window: float, t_end: float, ranks, **options) -> Scene:
    """``scene`` stepped at ``dt`` over ``[0, t_end]`` with the ``[rom]`` section of
    :func:`extrapolation_config` (``options``: its ``derivatives``, ``terms``, ``learners``)."""
    config = extrapolation_config(dt, train_window, t_end, ranks, **options)
    return replace(scene.with_time(dt=dt, t_end=t_end), rom=config)


def dispersion_error(system, q0: np.ndarray, dt: float, times: np.ndarray, r: int, norm: float, *,
                     scheme="newmark") -> float:
    r"""A priori test-window error of a ROM that learned the FOM's *discrete* frequencies.

    Released from ``q0`` at rest, the FOM stepped by ``scheme`` (a linear undamped model) is exactly
    ``q_n = sum_k a_k cos(Omega_k t_n) phi_k`` (``phi_k`` mass-orthonormal modes,
    ``Omega_k`` the scheme's :meth:`~femrom.integrators.Scheme.frequency` of ``omega_k``). Finite
    differences of order p of ``cos(Omega t)`` return ``Omega`` up to ``O((Omega dt)^p)``, so a
    learner that fits the data exactly learns ``Omega_k``, not ``omega_k``; the
    ROM's own step (the same scheme) then runs at ``Omega'_k = frequency(Omega_k)``.
    Over the modes 1..r (those a POD basis of this data spans) that phase error is

    .. math::

        d(r) = \Big(\sum_{t \in \text{test}} \sum_{k \le r}
               a_k^2 (\cos\Omega'_k t - \cos\Omega_k t)^2\Big)^{1/2} / \|Q_{test}\|_M,

    and such a ROM's error is ``sqrt(projection^2 + d(r)^2)``. ``norm`` is
    ``||Q_test||_M``, ``times`` the test window's times.
    """
    import scipy.linalg as sl

    omega2, modes = sl.eigh(system.stiffness.toarray(), system.mass.toarray())
    amplitudes = modes[:, :r].T @ np.asarray(system.mass @ q0)
    scheme = time_scheme(scheme)
    learned = scheme.frequency(np.sqrt(omega2[:r]), dt)
    stepped = scheme.frequency(learned, dt)
    phase = np.cos(np.outer(stepped, times)) - np.cos(np.outer(learned, times))
    return float(np.sqrt(np.sum(amplitudes[:, None] ** 2 * phase**2)) / norm)
