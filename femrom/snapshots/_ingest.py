r"""Displacement snapshots of another solver into a femrom snapshot store.

What a user's own finite-element code writes (Abaqus, Code_Aster, FEniCSx, ANSYS,
an in-house code) is usually a time series of nodal displacement fields, often
every k-th step, with no velocities, accelerations or matrices. This module reads
such a series one step at a time and streams it into a :class:`SnapshotStore`:

- the series (:func:`read_series`): a ParaView ``.pvd`` listing ``.vtu`` files, an
  XDMF time series (``.xdmf`` + HDF5, meshio's ``TimeSeriesReader``), or one array
  ``(K, n_points, dim)`` in an HDF5 dataset or an ``.npz`` with a mesh file beside;
  every step is checked (same mesh, finite values, the field present) as it is read;
- the mesh of the series gives femrom its own model of the data
  (:class:`IngestedModel`): vector P1 on the series' tetrahedra, a mass matrix from a
  density (consistent or lumped) for the mass inner product of the POD, Dirichlet dofs
  detected (identically zero over the record) or named (boundaries of the mesh), and
  outputs read at points;
- the inputs ``u(t)`` from a table (CSV with a ``t`` column, or ``.npz`` with ``t``
  and ``u`` (m, K)), interpolated linearly onto the snapshot times.

Nothing of the series is held in memory beyond one step and one chunk of the
store (a series larger than RAM streams), and the store is created under a
temporary name and renamed only when complete, so a failure leaves no store.
Learning from the ingested displacements alone:
:meth:`femrom.inference.SecondOrderData.integrator_consistent`.
"""

from __future__ import annotations

import os
import time
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from pathlib import Path
from typing import Iterator

import numpy as np
import scipy.sparse as sp

from femrom import fem
from femrom._errors import FemromValueError
from femrom.integrators import StepResult
from femrom.mesh import load_mesh
from femrom.scene import SecondOrderSystem
from femrom.snapshots._store import SnapshotStore


class IngestError(FemromValueError):
    """A series, mesh or table that cannot be ingested; the message names the file (and step)."""


# -- reading a series one step at a time ------------------------------------------------
@dataclass
class DisplacementSeries:
    """A time series of nodal displacements: ``times`` (K,), the mesh file, and :meth:`steps`.

    Attributes
    ----------
    times : (K,) ndarray
        Increasing snapshot times (uniform or not).
    mesh_path : Path
        A file meshio reads with the series' points and cells (its first ``.vtu``, the
        XDMF file itself, or the mesh given beside an array).
    field : str
        The point-data name of the displacements.
    """

    times: np.ndarray
    mesh_path: Path
    field: str
    _steps: object = dataclass_field(repr=False, default=None)
    n_points: int = 0
    cells: object = dataclass_field(repr=False, default=None)   # (points, cells) when the mesh file is no mesh file (XDMF)

    def steps(self) -> Iterator[tuple[int, float, np.ndarray]]:
        """Yield ``(k, t_k, U_k)`` with ``U_k`` (n_points, dim), checked finite and of the mesh's size."""
        for k, (t, values, where) in enumerate(self._steps()):
            values = np.asarray(values)
            if values.dtype.kind not in "fiu":
                raise IngestError(f"{where}: field {self.field!r} has dtype {values.dtype}, expected real numbers")
            values = values.astype(float, copy=False)
            if values.ndim == 1:
                values = values[:, None]
            if values.shape[0] != self.n_points:
                raise IngestError(f"{where}: field {self.field!r} has {values.shape[0]} points, the series' mesh "
                                  f"{self.n_points} (mismatched meshes)")
            if not np.all(np.isfinite(values)):
                raise IngestError(f"{where}: field {self.field!r} is not finite (NaN or inf) at step {k}")
            yield k, float(t), values


def _point_field(point_data: dict, name: str | None, where: str) -> tuple[str, np.ndarray]:
    if name is not None:
        if name not in point_data:
            raise IngestError(f"{where}: no point field {name!r}; it has: {', '.join(point_data) or 'none'}")
        return name, point_data[name]
    vectors = [key for key, value in point_data.items() if np.ndim(value) == 2 and np.shape(value)[1] in (2, 3)]
    if len(vectors) != 1:
        raise IngestError(f"{where}: name the displacement field (field=...); vector point fields: "
                          f"{', '.join(vectors) or 'none'}")
    return vectors[0], point_data[vectors[0]]


def _check_times(times: np.ndarray, where: str) -> np.ndarray:
    times = np.asarray(times, dtype=float)
    if times.size < 3:
        raise IngestError(f"{where}: {times.size} time step(s); a series needs at least 3")
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        bad = int(np.argmax(~np.isfinite(times) | np.r_[False, np.diff(times) <= 0]))
        raise IngestError(f"{where}: times must increase, step {bad} has t = {times[bad]!r}")
    return times


def _same_mesh(points: np.ndarray, reference: np.ndarray, where: str) -> None:
    if points.shape != reference.shape or not np.allclose(points, reference, rtol=1e-9,
                                                          atol=1e-12 * np.abs(reference).max()):
        raise IngestError(f"{where}: its mesh differs from the series' first (mismatched meshes: "
                          f"{points.shape[0]} points against {reference.shape[0]})")


def read_pvd(path, *, field: str | None = None) -> DisplacementSeries:
    """A ParaView ``.pvd`` collection: one ``<DataSet timestep=... file=...>`` per step, ``.vtu`` each."""
    import meshio

    path = Path(path)
    try:
        root = ElementTree.parse(path).getroot()
    except (ElementTree.ParseError, OSError) as exc:
        raise IngestError(f"{path}: not a readable .pvd file ({exc})") from None
    entries = [(float(d.get("timestep", "nan")), path.parent / d.get("file", "")) for d in root.iter("DataSet")]
    if not entries:
        raise IngestError(f"{path}: lists no <DataSet> files")
    times = _check_times(np.array([t for t, _ in entries]), str(path))
    missing = [str(f) for _, f in entries if not f.is_file()]
    if missing:
        raise IngestError(f"{path}: step {[str(f) for _, f in entries].index(missing[0])} file {missing[0]} is "
                          f"missing ({len(missing)} of {len(entries)} missing)")
    first = meshio.read(entries[0][1])
    name, values = _point_field(first.point_data, field, str(entries[0][1]))
    reference = np.asarray(first.points, dtype=float)

    def steps():
        for k, (t, file) in enumerate(entries):
            try:
                m = first if k == 0 else meshio.read(file)
            except Exception as exc:   # noqa: BLE001 - meshio raises many kinds on a broken file
                raise IngestError(f"{file}: step {k} is not readable ({exc})") from None
            _same_mesh(np.asarray(m.points, dtype=float), reference, f"{file} (step {k})")
            if name not in m.point_data:
                raise IngestError(f"{file}: step {k} has no point field {name!r}")
            yield t, m.point_data[name], f"{file} (step {k})"

    return DisplacementSeries(times, entries[0][1], name, steps, reference.shape[0])


def read_xdmf(path, *, field: str | None = None) -> DisplacementSeries:
    """An XDMF time series (meshio's ``TimeSeriesReader``: the mesh once, then one field set per step)."""
    import meshio

    path = Path(path)
    try:
        with meshio.xdmf.TimeSeriesReader(path) as reader:
            points, cells = reader.read_points_cells()
            times = []
            for k in range(reader.num_steps):
                t, point_data, _ = reader.read_data(k)
                times.append(t)
                if k == 0:
                    name, _ = _point_field(point_data, field, f"{path} (step 0)")
    except IngestError:
        raise
    except Exception as exc:   # noqa: BLE001
        raise IngestError(f"{path}: not a readable XDMF time series ({exc})") from None
    times = _check_times(np.array(times), str(path))

    def steps():
        with meshio.xdmf.TimeSeriesReader(path) as reader:
            reader.read_points_cells()
            for k in range(reader.num_steps):
                t, point_data, _ = reader.read_data(k)
                if name not in point_data:
                    raise IngestError(f"{path}: step {k} has no point field {name!r}")
                yield t, point_data[name], f"{path} (step {k})"

    return DisplacementSeries(times, path, name, steps, np.asarray(points).shape[0], (points, cells))


def read_array(path, *, mesh, field: str = "u", times: str = "t") -> DisplacementSeries:
    """One array ``field`` of shape (K, n_points, dim) and its ``times`` (K,) in an HDF5 file (read step
    by step) or an ``.npz`` (loaded whole: it must fit in memory), with the mesh in another file."""
    path, mesh = Path(path), Path(mesh)
    if not mesh.is_file():
        raise IngestError(f"{mesh}: mesh file not found (an array series needs its mesh)")
    if path.suffix == ".npz":
        with np.load(path) as data:
            if field not in data or times not in data:
                raise IngestError(f"{path}: needs arrays {field!r} and {times!r}; it has {', '.join(data.files)}")
            values, t = data[field], data[times]
        get = values.__getitem__
        shape = values.shape
    else:
        import h5py

        try:
            with h5py.File(path, "r") as f:
                if field not in f or times not in f:
                    raise IngestError(f"{path}: needs datasets {field!r} and {times!r}; it has {', '.join(f)}")
                shape, t = f[field].shape, f[times][()]
        except OSError as exc:
            raise IngestError(f"{path}: not a readable HDF5 file ({exc})") from None

        get = None
    if len(shape) not in (2, 3) or shape[0] != np.size(t):
        raise IngestError(f"{path}: {field!r} must be (K, n_points[, dim]) with K = {np.size(t)} times, "
                          f"got shape {tuple(shape)}")
    times_ = _check_times(np.asarray(t).ravel(), str(path))

    def steps():
        if get is not None:                      # the .npz, in memory
            for k, tk in enumerate(times_):
                yield tk, get(k), f"{path} (step {k})"
            return
        import h5py

        with h5py.File(path, "r") as f:          # one step at a time from the file
            dataset = f[field]
            for k, tk in enumerate(times_):
                yield tk, dataset[k], f"{path} (step {k})"

    return DisplacementSeries(times_, mesh, field, steps, int(shape[1]))


#: Readers by file suffix.
SERIES_READERS = {".pvd": read_pvd, ".xdmf": read_xdmf, ".h5": read_array, ".hdf5": read_array,
                  ".npz": read_array}


def read_series(path, *, field: str | None = None, mesh=None) -> DisplacementSeries:
    """The reader of ``path``'s suffix (:data:`SERIES_READERS`); ``mesh`` is needed for arrays."""
    path = Path(path)
    if not path.is_file():
        raise IngestError(f"{path}: series file not found")
    reader = SERIES_READERS.get(path.suffix.lower())
    if reader is None:
        raise IngestError(f"{path}: unknown series format {path.suffix!r}; valid: {', '.join(SERIES_READERS)}")
    if reader is read_array:
        if mesh is None:
            raise IngestError(f"{path}: an array series needs its mesh file (mesh=...)")
        return read_array(path, mesh=mesh, **({} if field is None else {"field": field}))
    return reader(path, field=field)


# -- the inputs -------------------------------------------------------------------------
def read_input_table(path) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """``(t (k,), u (m, k), names)`` of a CSV (header row, a ``t`` column) or ``.npz`` (``t``, ``u``)."""
    path = Path(path)
    if not path.is_file():
        raise IngestError(f"{path}: input table not found")
    if path.suffix == ".npz":
        with np.load(path) as data:
            if "t" not in data or "u" not in data:
                raise IngestError(f"{path}: needs arrays 't' and 'u'; it has {', '.join(data.files)}")
            t, u = np.asarray(data["t"], float).ravel(), np.atleast_2d(np.asarray(data["u"], float))
        names = tuple(f"u{i}" for i in range(u.shape[0]))
    else:
        try:
            table = np.genfromtxt(path, delimiter=",", names=True, dtype=float)
        except ValueError as exc:
            raise IngestError(f"{path}: not a CSV table of numbers with a header row ({exc})") from None
        names = table.dtype.names or ()
        if "t" not in names or len(names) < 2:
            raise IngestError(f"{path}: needs a 't' column and at least one input column; header: {names}")
        t = np.atleast_1d(table["t"])
        names = tuple(n for n in names if n != "t")
        u = np.vstack([np.atleast_1d(table[n]) for n in names])
    if u.shape[1] != t.size:
        raise IngestError(f"{path}: {u.shape[1]} input samples for {t.size} times")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(u))):
        raise IngestError(f"{path}: the table holds NaN or inf")
    if t.size < 2 or np.any(np.diff(t) <= 0):
        raise IngestError(f"{path}: the times of the table must increase")
    return t, u, names


@dataclass(frozen=True)
class TabulatedInputs:
    """``u(t)`` by linear interpolation in a table (m inputs); outside it, one clear error."""

    t: np.ndarray
    u: np.ndarray
    names: tuple[str, ...]
    source: str = ""

    def __call__(self, t) -> np.ndarray:
        t = float(t)
        span = self.t[-1] - self.t[0]
        if t < self.t[0] - 1e-9 * span or t > self.t[-1] + 1e-9 * span:
            raise IngestError(f"{self.source}: the input table covers [{self.t[0]:g}, {self.t[-1]:g}], "
                              f"asked for t = {t:g}")
        return np.array([np.interp(t, self.t, row) for row in self.u])


# -- femrom's model of the data ---------------------------------------------------------
@dataclass(frozen=True, eq=False)
class IngestedModel:
    """What femrom knows of a foreign series: its mesh, P1 space, mass, free dofs, inputs and outputs.

    Attributes
    ----------
    space : SolidSpace
        Vector P1 on the series' tetrahedra (dof ``nodal_dofs[c, i]``: component ``c`` of point ``i``).
    system : SecondOrderSystem
        ``mass`` (free dofs) for the POD product, ``condensation`` (Dirichlet dofs), inputs
        (the table) and ``output_matrix`` (probes); stiffness, damping and ``B`` are unknown
        (``stiffness=None``; ``input_matrix`` zero, a placeholder that only counts the inputs).
    """

    space: object
    system: SecondOrderSystem
    fixed: np.ndarray
    detail: dict = dataclass_field(default_factory=dict)

    def free_values(self, values: np.ndarray) -> np.ndarray:
        """(n_free,) free dofs of point values (n_points, dim)."""
        full = np.zeros(self.space.n_total)
        nodal = np.asarray(self.space.basis.nodal_dofs)
        full[nodal[: values.shape[1]].T.ravel()] = values.ravel()
        return full[self.system.condensation.free]


class _Material:
    def __init__(self, density):
        self.density = float(density)


def _series_mesh(series: DisplacementSeries):
    """The series' mesh as femrom reads meshes (through a ``.vtu`` when it came with the series' data)."""
    if series.cells is None:
        return load_mesh(series.mesh_path)
    import tempfile

    import meshio

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "mesh.vtu"
        meshio.write(path, meshio.Mesh(*series.cells))
        return load_mesh(path)


def ingested_model(series: DisplacementSeries, *, density: float = 1.0, lumped: bool = False, fixed="auto",
                   inputs=None, outputs=(), length_scale: float = 1.0, progress=None) -> IngestedModel:
    """femrom's model of ``series``: one pass over it finds the zero dofs (``fixed="auto"``) and checks it.

    Parameters
    ----------
    density : float
        For the mass matrix (kg/m^3; any positive constant gives the same basis).
    lumped : bool
        HRZ-lumped (diagonal) mass instead of the consistent one.
    fixed : "auto", None or sequence of str
        Dirichlet dofs: those identically zero over the whole record, none, or all
        dofs on the named boundaries of the mesh (physical groups).
    inputs : path, optional
        Input table (:func:`read_input_table`); it must cover the series' times.
    outputs : sequence of (name, point (3,), component)
        Displacement probes (interpolated, ``component`` in ``x``, ``y``, ``z``).
    length_scale : float
        Multiplies the displacements (e.g. 1e-3 for a series written in mm on a mesh in m).
    """
    if not density > 0 or not np.isfinite(density):
        raise IngestError(f"density must be a positive number, got {density!r}")
    if not length_scale > 0 or not np.isfinite(length_scale):
        raise IngestError(f"length_scale must be a positive number, got {length_scale!r}")
    try:
        mesh = _series_mesh(series)
    except Exception as exc:   # noqa: BLE001
        raise IngestError(f"{series.mesh_path}: the series' mesh is not usable ({exc})") from None
    if mesh.p.shape[0] != 3 or mesh.t.shape[0] != 4:
        raise IngestError(f"{series.mesh_path}: femrom ingests displacements on tetrahedra in 3D, got "
                          f"{mesh.p.shape[0]}D cells of {mesh.t.shape[0]} nodes")
    if mesh.p.shape[1] != series.n_points:
        raise IngestError(f"{series.mesh_path}: {mesh.p.shape[1]} mesh points for a field on {series.n_points}")
    space = fem.SolidSpace(mesh, "p1")
    nodal = np.asarray(space.basis.nodal_dofs)
    peak = np.zeros(space.n_total)
    tic = time.perf_counter()
    for k, t, values in series.steps():          # one checking pass
        dofs = nodal[: values.shape[1]].T.ravel()
        peak[dofs] = np.maximum(peak[dofs], np.abs(values).ravel() * length_scale)
        if progress and time.perf_counter() - tic > 2.0:
            progress(f"checking {series.mesh_path.name}: step {k + 1}/{series.times.size}")
            tic = time.perf_counter()
    diameter = float(np.max(np.ptp(mesh.p, axis=1)))
    if peak.max() > 10 * diameter:
        raise IngestError(f"{series.mesh_path}: displacements reach {peak.max():.3g}, more than 10x the "
                          f"structure's size {diameter:.3g}: units? (length_scale)")
    if fixed == "auto":
        fixed_dofs = np.flatnonzero(peak == 0.0)
    elif fixed is None:
        fixed_dofs = np.array([], dtype=int)
    else:
        fixed_dofs = np.unique(np.concatenate([space.boundary_dofs(name, clamped=True) for name in fixed]))
    if fixed_dofs.size == space.n_total:
        raise IngestError(f"{series.mesh_path}: every displacement is zero over the record")
    condensation = fem.Condensation.from_fixed(space.n_total, fixed_dofs)
    M = condensation.matrix(fem.vector_mass(space.basis, density, lumped=lumped))
    table = None
    if inputs is not None:
        t, u, names = read_input_table(inputs)
        span = series.times[-1] - series.times[0]
        if t[0] > series.times[0] + 1e-9 * span or t[-1] < series.times[-1] - 1e-9 * span:
            raise IngestError(f"{inputs}: the input table covers [{t[0]:g}, {t[-1]:g}], the series "
                              f"[{series.times[0]:g}, {series.times[-1]:g}]")
        table = TabulatedInputs(t, u, names, str(inputs))
    rows, names = [], []
    for name, point, component in outputs:
        if component not in ("x", "y", "z"):
            raise IngestError(f"output {name!r}: component must be x, y or z, got {component!r}")
        try:
            row = fem.probe_rows(space.basis, [list(point)], "xyz".index(component))
        except ValueError as exc:
            raise IngestError(f"output {name!r}: {exc}") from None
        rows.append(condensation.columns(row))
        names.append(str(name))
    E = sp.vstack(rows).tocsr() if rows else None
    n = M.shape[0]
    system = SecondOrderSystem(mass=M, stiffness=None, input_matrix=None if table is None else
                               sp.csr_matrix((n, table.u.shape[0])), inputs=table, output_matrix=E,
                               condensation=condensation, output_names=tuple(names),
                               metadata={"ingested_from": str(series.mesh_path), "density": float(density),
                                         "lumped": bool(lumped), "length_scale": float(length_scale),
                                         "operators": "unknown: learned from the snapshots"})
    return IngestedModel(space, system, fixed_dofs, {"fixed": "auto" if fixed == "auto" else fixed,
                                                      "n_fixed": int(fixed_dofs.size)})


def ingest(series: DisplacementSeries, model: IngestedModel, store_path, *, trajectory: str = "000",
           every: int = 1, overwrite: bool = False, length_scale: float = 1.0, progress=None) -> Path:
    """Stream ``series`` (every ``every``-th step) into a new store at ``store_path``; return its path.

    The store holds ``q`` (free dofs), ``t``, the inputs at the snapshot times and the
    outputs; it is written under a temporary name and renamed when complete (a
    failure leaves no store and keeps an existing one).
    """
    store_path = Path(store_path)
    if store_path.exists() and not overwrite:
        raise IngestError(f"{store_path}: exists (overwrite=True to replace it)")
    if int(every) < 1:
        raise IngestError(f"every must be a positive integer, got {every!r}")
    times = series.times[::every]
    steps = np.diff(times)
    uniform = bool(np.allclose(steps, steps[0], rtol=1e-6, atol=0.0))
    temporary = store_path.with_name(f".{store_path.name}.{os.getpid()}.ingesting")
    store = SnapshotStore.create(temporary, model.system, fields=("q",), dt=float(steps[0]) if uniform else None,
                                 n_steps=times.size - 1, overwrite=True)
    try:
        writer = store.writer(trajectory, n_steps=times.size - 1, dt=float(steps[0]) if uniform else None)
        zero = np.zeros(model.system.n_dofs)
        tic = time.perf_counter()
        for k, t, values in series.steps():
            if k % every:
                continue
            q = model.free_values(values * length_scale)
            writer(StepResult(step=k // every, t=t, q=q, v=zero, a=None))
            if progress and time.perf_counter() - tic > 2.0:
                progress(f"ingesting: step {k + 1}/{series.times.size}")
                tic = time.perf_counter()
        writer.close()
        store.close()
        os.replace(temporary, store_path)
    except BaseException:
        store.close()
        temporary.unlink(missing_ok=True)
        raise
    return store_path
