"""The ``[rom]`` section of a scene file: which reduced models to learn from which runs, and what to report.

Example (a scene with one input)::

    [rom]
    learners = ["galerkin", "lopinf", "opinf"]
    derivatives = "stored"                 # or { kind = "finite_differences", order = 4 }
    basis = { product = "mass", ranks = [2, 4, 8] }
    extension = 10.0                       # energy window of the tests, in test windows

    [[rom.train]]
    name = "sigmoid"                       # the scene's own signals when 'signals' is absent

    [[rom.test]]
    name = "step"
    signals = [{ kind = "step", amplitude = 2.0e4, start = 0.0305 }]
    t_end = 0.6                            # longer than training: extrapolation in time

This layer checks the section's shape (keys, types, signals, one signal per
input, ranks). Learner names are checked by the study layer, where the
learners are registered (:func:`femrom.study.check_rom_config`), before
anything is built.
"""

from __future__ import annotations

from dataclasses import dataclass

from femrom.scene._errors import SceneError
from femrom.scene._tables import take_table as _table
from femrom.scene._signals import Signal

PRODUCTS = ("mass", "euclidean")
SVD_METHODS = ("randomized", "svd")
DERIVATIVE_KINDS = ("stored", "finite_differences", "integrator")
FD_ORDERS = (2, 4, 6)


def _positive(value, where: str, *, integer: bool = False):
    kind = int if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kind) or not value > 0:
        raise SceneError(f"[{where}] must be a positive {'integer' if integer else 'number'}, got {value!r}")
    return int(value) if integer else float(value)


@dataclass(frozen=True)
class Derivatives:
    """Where the learners' ``q'``, ``q''`` come from: the run's stored integrator
    derivatives, finite differences of the reduced displacements of ``order``, or
    ``integrator``: differences of the displacements alone that the ROM's Newmark
    steps reproduce exactly (:meth:`femrom.inference.SecondOrderData.integrator_consistent`)."""

    kind: str = "stored"
    order: int = 4

    @classmethod
    def from_value(cls, value, where: str) -> "Derivatives":
        if isinstance(value, str):
            value = {"kind": value}
        d = _table(value, where, {"kind": "stored", "order": 4})
        if d["kind"] not in DERIVATIVE_KINDS:
            raise SceneError(f"[{where}] unknown derivative kind {d['kind']!r}; valid: {', '.join(DERIVATIVE_KINDS)}")
        if d["order"] not in FD_ORDERS:
            raise SceneError(f"[{where}] finite-difference order must be one of {FD_ORDERS}, got {d['order']!r}")
        return cls(d["kind"], int(d["order"]))

    @property
    def tag(self) -> str:
        return {"stored": "stored", "integrator": "integrator"}.get(self.kind, f"fd{self.order}")


@dataclass(frozen=True)
class LearnerSpec:
    """One reduced model of the study: a registered learner (``galerkin`` is one), its derivative
    data and regularisation, under a ``label`` (the row name in the report); ``terms``
    names terms to learn beyond those of the scene's effects (``"damping"`` for a
    structure the learner is not told is undamped); ``options``: the learner's other keyword
    options (``{ thresholds = 8 }`` for ``iwan_lopinf``), as ``(name, value)`` pairs."""

    label: str
    learner: str
    derivatives: Derivatives
    regularization: float = 0.0
    terms: tuple[str, ...] = ()
    options: tuple = ()

    @classmethod
    def from_value(cls, value, where: str, derivatives: Derivatives, regularization: float) -> "LearnerSpec":
        if isinstance(value, str):
            value = {"learner": value}
        d = _table(value, where, {"learner": None, "label": None, "derivatives": None,
                                  "regularization": None, "terms": [], "options": {}}, ("learner",))
        if not isinstance(d["options"], dict):
            raise SceneError(f"[{where}] options must be a table of the learner's keyword options, got {d['options']!r}")
        if not isinstance(d["terms"], list) or not all(isinstance(t, str) for t in d["terms"]):
            raise SceneError(f"[{where}] terms must be an array of term names, got {d['terms']!r}")
        if not isinstance(d["learner"], str):
            raise SceneError(f"[{where}] learner must be a name, got {d['learner']!r}")
        own = derivatives if d["derivatives"] is None else Derivatives.from_value(
            d["derivatives"], f"{where}.derivatives")
        reg = regularization if d["regularization"] is None else d["regularization"]
        if isinstance(reg, bool) or not isinstance(reg, (int, float)) or reg < 0:
            raise SceneError(f"[{where}] regularization must be a number >= 0, got {reg!r}")
        label = d["label"] if d["label"] is not None else d["learner"]
        options = tuple((str(k), tuple(v) if isinstance(v, list) else v) for k, v in d["options"].items())
        return cls(str(label), d["learner"], own, float(reg), tuple(d["terms"]), options)


@dataclass(frozen=True)
class ExperimentSpec:
    """One ``[[rom.experiments]]`` entry: a registered experiment's ``kind`` and its keyword ``options``
    (``(name, value)`` pairs; the name is checked against the registry by the study)."""

    kind: str
    options: tuple = ()

    @classmethod
    def from_dict(cls, data, where: str) -> "ExperimentSpec":
        if not isinstance(data, dict) or not isinstance(data.get("kind"), str):
            raise SceneError(f"[{where}] must be a table with a kind (a registered experiment's name), got {data!r}")
        return cls(data["kind"], tuple((str(k), tuple(v) if isinstance(v, list) else v)
                                       for k, v in data.items() if k != "kind"))


@dataclass(frozen=True)
class RunSpec:
    """One full-order run of the study: a name, one signal per input (``None``: the
    scene's), its window ``t_end`` (``None``: the scene's), and ``score_after``: errors
    count only after this time (the end of the training window, for a test of
    extrapolation in time from the same initial state)."""

    name: str
    signals: tuple[Signal, ...] | None = None
    t_end: float | None = None
    score_after: float | None = None

    @classmethod
    def from_dict(cls, data, where: str, n_inputs: int) -> "RunSpec":
        d = _table(data, where, {"name": None, "signals": None, "t_end": None, "score_after": None}, ("name",))
        signals = None
        if d["signals"] is not None:
            entries = d["signals"] if isinstance(d["signals"], list) else [d["signals"]]
            if len(entries) != n_inputs:
                raise SceneError(f"[{where}] signals: the scene has {n_inputs} input(s), got {len(entries)} signal(s)")
            signals = tuple(Signal.from_dict(s, f"{where}.signals[{i}]") for i, s in enumerate(entries))
        t_end = None if d["t_end"] is None else _positive(d["t_end"], f"{where}.t_end")
        score_after = None if d["score_after"] is None else _positive(d["score_after"], f"{where}.score_after")
        if score_after is not None and t_end is not None and score_after >= t_end:
            raise SceneError(f"[{where}] score_after must lie inside the run's window, got {score_after} >= t_end {t_end}")
        return cls(str(d["name"]), signals, t_end, score_after)


@dataclass(frozen=True)
class BasisSpec:
    """A POD basis of the training displacements, orthonormal in ``product`` (the
    mass: the energy inner product of the kinetic term), computed by the out-of-core
    ``method``; one basis of ``max(ranks)`` columns, nested, truncated for each r."""

    ranks: tuple[int, ...] = (2, 4, 6, 8)
    product: str = "mass"
    method: str = "randomized"
    power_iterations: int = 2

    @classmethod
    def from_dict(cls, data, where: str) -> "BasisSpec":
        d = _table(data, where, {"ranks": [2, 4, 6, 8], "product": "mass", "method": "randomized",
                                 "power_iterations": 2})
        ranks = d["ranks"]
        if not isinstance(ranks, list) or not ranks:
            raise SceneError(f"[{where}] ranks must be a non-empty array of positive integers, got {ranks!r}")
        ranks = tuple(_positive(r, f"{where}.ranks", integer=True) for r in ranks)
        if list(ranks) != sorted(set(ranks)):
            raise SceneError(f"[{where}] ranks must increase without repeats, got {list(ranks)}")
        for key, valid in (("product", PRODUCTS), ("method", SVD_METHODS)):
            if d[key] not in valid:
                raise SceneError(f"[{where}] unknown {key} {d[key]!r}; valid: {', '.join(valid)}")
        if isinstance(d["power_iterations"], bool) or not isinstance(d["power_iterations"], int) \
                or d["power_iterations"] < 0:
            raise SceneError(f"[{where}] power_iterations must be an integer >= 0, got {d['power_iterations']!r}")
        return cls(ranks, d["product"], d["method"], int(d["power_iterations"]))


@dataclass(frozen=True)
class TimingSpec:
    """Per-step costs by repetition: ``repeats`` timed blocks of at least ``min_block_seconds`` each."""

    repeats: int = 5
    min_block_seconds: float = 0.1

    @classmethod
    def from_dict(cls, data, where: str) -> "TimingSpec":
        d = _table(data, where, {"repeats": 5, "min_block_seconds": 0.1})
        repeats = _positive(d["repeats"], f"{where}.repeats", integer=True)
        if repeats < 3:
            raise SceneError(f"[{where}] repeats must be >= 3 (a median and a spread), got {repeats}")
        return cls(repeats, _positive(d["min_block_seconds"], f"{where}.min_block_seconds"))


@dataclass(frozen=True)
class ReportSpec:
    """What the report shows beyond its tables: renders (PNG), a ParaView series, the FOM
    time-step ladder (coarser steps, as factors of the scene's ``dt``)."""

    render: bool = True
    paraview: bool = True
    time_step_factors: tuple[int, ...] = ()
    keep_snapshots: bool = False

    @classmethod
    def from_dict(cls, data, where: str) -> "ReportSpec":
        d = _table(data, where, {"render": True, "paraview": True, "time_step_factors": [],
                                 "keep_snapshots": False})
        for key in ("render", "paraview", "keep_snapshots"):
            if not isinstance(d[key], bool):
                raise SceneError(f"[{where}] {key} must be true or false, got {d[key]!r}")
        factors = d["time_step_factors"]
        if not isinstance(factors, list):
            raise SceneError(f"[{where}] time_step_factors must be an array of integers > 1, got {factors!r}")
        factors = tuple(_positive(f, f"{where}.time_step_factors", integer=True) for f in factors)
        if any(f < 2 for f in factors) or len(set(factors)) != len(factors):
            raise SceneError(f"[{where}] time_step_factors must be distinct integers > 1, got {list(factors)}")
        return cls(d["render"], d["paraview"], tuple(sorted(factors, reverse=True)), d["keep_snapshots"])


@dataclass(frozen=True)
class RomConfig:
    """The ``[rom]`` section: training and test runs, basis, learners, timing and report.

    ``learners`` entries are names (``"lopinf"``) or tables ``{ learner, label,
    derivatives, regularization }`` (e.g. L-OpInf from finite differences next to
    L-OpInf from stored derivatives); ``derivatives`` and ``regularization`` at the
    section's top are the defaults of every entry. ``extension`` is the length of the
    energy window of each test, in multiples of its own window. ``snapshot_every``: the
    store keeps every k-th FOM step (what another solver writing every k-th step
    gives), and the ROMs step with ``k dt``.
    """

    train: tuple[RunSpec, ...]
    test: tuple[RunSpec, ...]
    learners: tuple[LearnerSpec, ...]
    basis: BasisSpec = BasisSpec()
    extension: float = 10.0
    timing: TimingSpec = TimingSpec()
    report: ReportSpec = ReportSpec()
    snapshot_every: int = 1
    experiments: tuple[ExperimentSpec, ...] = ()

    KEYS = ("train", "test", "learners", "basis", "derivatives", "regularization", "extension",
            "timing", "report", "snapshot_every", "experiments")

    @classmethod
    def from_dict(cls, data, n_inputs: int) -> "RomConfig":
        d = _table(data, "rom", {k: None for k in cls.KEYS})
        runs = {}
        for kind in ("train", "test"):
            entries = d[kind]
            if entries is None:
                entries = [{"name": kind}] if kind == "train" else []
            if not isinstance(entries, list) or not entries:
                raise SceneError(f"[rom] needs at least one [[rom.{kind}]] run")
            runs[kind] = tuple(RunSpec.from_dict(e, f"rom.{kind}[{i}]", n_inputs) for i, e in enumerate(entries))
        names = [r.name for r in (*runs["train"], *runs["test"])]
        if n_inputs == 0 and len({(r.t_end, r.score_after) for r in (*runs["train"], *runs["test"])}) < len(names):
            raise SceneError("[rom] without inputs every run starts from the scene's initial state: runs differ "
                             "only by t_end and score_after, and these must differ between runs")
        if len(set(names)) != len(names):
            raise SceneError(f"[rom] run names must be unique across train and test, got {names}")
        derivatives = Derivatives.from_value(d["derivatives"] or "stored", "rom.derivatives")
        reg = 0.0 if d["regularization"] is None else d["regularization"]
        if isinstance(reg, bool) or not isinstance(reg, (int, float)) or reg < 0:
            raise SceneError(f"[rom] regularization must be a number >= 0, got {reg!r}")
        entries = d["learners"] if d["learners"] is not None else ["galerkin", "lopinf"]
        if not isinstance(entries, list) or not entries:
            raise SceneError("[rom] learners must be a non-empty array of names or tables")
        learners = tuple(LearnerSpec.from_value(e, f"rom.learners[{i}]", derivatives, float(reg))
                         for i, e in enumerate(entries))
        labels = [s.label for s in learners]
        if len(set(labels)) != len(labels):
            raise SceneError(f"[rom] learner labels must be unique, got {labels}; give a 'label'")
        extension = 10.0 if d["extension"] is None else _positive(d["extension"], "rom.extension")
        if extension < 1:
            raise SceneError(f"[rom] extension must be >= 1 (the test window itself), got {extension}")
        every = 1 if d["snapshot_every"] is None else _positive(d["snapshot_every"], "rom.snapshot_every",
                                                                 integer=True)
        experiments = d["experiments"] if d["experiments"] is not None else []
        if not isinstance(experiments, list):
            raise SceneError("[rom] experiments must be an array of tables [[rom.experiments]] with a kind")
        return cls(runs["train"], runs["test"], learners,
                   BasisSpec.from_dict(d["basis"], "rom.basis"), extension,
                   TimingSpec.from_dict(d["timing"], "rom.timing"), ReportSpec.from_dict(d["report"], "rom.report"),
                   every, tuple(ExperimentSpec.from_dict(e, f"rom.experiments[{i}]") for i, e in enumerate(experiments)))
