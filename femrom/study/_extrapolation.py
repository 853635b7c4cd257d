"""A study of extrapolation in time: learn from a structure's release over ``[0, T]``, predict
the same release far beyond ``T``."""

from __future__ import annotations

from dataclasses import replace

from femrom.inference import learner_class
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
