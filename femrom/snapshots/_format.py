"""The on-disk layout of a snapshot store, and the checks that recognise one.

::

    /                       attrs: format = "femrom.snapshots", format_version,
                                   femrom_version, created, scene_name, scene_toml,
                                   units (JSON), scheme, dt, n_steps, fields (JSON),
                                   n_dofs, n_inputs, n_outputs, output_names (JSON),
                                   system (JSON of SecondOrderSystem.metadata)
    /dofmap/free            (n,) int64       free dofs of the condensation
    /dofmap/fixed           (n_total - n,)   attrs: n_total
    /trajectories/000/      attrs: scheme, dt, n_steps (planned last step), every,
                                   chunk_steps, created
        q, v, a             (K, n) float64   row j = snapshot column j; chunks (c, n)
        u                   (K, m) float64   inputs u(t_j)     (systems with inputs)
        y                   (K, p) float64   outputs y = E q_j (systems with outputs)
        t                   (K,) float64     times
        step                (K,) int64       step indices
        committed           (2,) int64       [declared length L, checkpoint slot]
        checkpoint/         two slots (ping-pong): step (2,), t (2,), q, v, a (2, n),
                            has_a (2,), state/<key> (2, *shape)

A chunk of ``c`` consecutive rows holds ``c`` whole snapshot columns, so a
block of columns of the (n, K) snapshot matrix is ``ceil(k / c)`` contiguous
reads. Only rows ``[0, L)`` are data: ``L`` is written after the rows and the
checkpoint are flushed, and readers never look past it.

Next to the file, while a trajectory is being added or trimmed:
``<store>.journal``, the undo journal of that change (:mod:`._journal`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

from femrom.snapshots._errors import SnapshotStoreError
from femrom.snapshots._superblock import SuperblockError, read_superblock

FORMAT_NAME = "femrom.snapshots"
FORMAT_VERSION = 1
STATE_FIELDS = ("q", "v", "a")
SIGNAL_FIELDS = ("u", "y")
#: What each per-step dataset holds; a field can be named either way
#: (``store.read(0, "displacement")`` reads ``q``).
FIELD_NAMES = {"q": "displacement", "v": "velocity", "a": "acceleration", "u": "inputs",
               "y": "outputs"}
FIELD_KEYS = {name: key for key, name in FIELD_NAMES.items()}
#: SI, as every scene file (``MaterialConfig`` documents SI input).
DEFAULT_UNITS = {"system": "SI", "length": "m", "time": "s", "mass": "kg", "force": "N",
                 "pressure": "Pa", "angle": "rad"}
_ROOT_KEYS = ("format_version", "n_dofs", "fields")


def hdf5_message(exc: BaseException) -> str:
    """The useful first line of an HDF5 error (h5py prefixes long call stacks)."""
    message = exc.args[0] if exc.args and isinstance(exc.args[0], str) else str(exc)
    text = message.strip().splitlines()[0] if message.strip() else type(exc).__name__
    if "file signature not found" in text:
        return "not an HDF5 file"
    if "truncated file" in text:
        return f"truncated HDF5 file ({text.split('(', 1)[-1].rstrip(')')})"
    if "filter returned failure during read" in text:  # Fletcher-32 is the only filter stores use
        return "a chunk's checksum does not match its bytes (the file changed on disk)"
    return text


def open_file(path: Path, mode: str, **kwargs) -> h5py.File:
    """``h5py.File`` whose failures are one-line :class:`SnapshotStoreError` naming ``path``."""
    if mode in ("r", "r+") and not path.exists():
        raise SnapshotStoreError(f"snapshot store not found: {path}")
    try:
        return h5py.File(path, mode, **kwargs)
    except (OSError, ValueError) as exc:
        raise SnapshotStoreError(f"{path}: {hdf5_message(exc)}") from None


def open_swmr_writer(path: Path) -> h5py.File:
    """Open read-write directly in SWMR write mode.

    The superblock goes from "closed" to "open for SWMR write" in one write.
    (``h5py.File(path, "r+")`` followed by ``swmr_mode = True`` passes through
    "open for write" alone, a state that SWMR readers refuse: "file is not
    already open for SWMR writing".)
    """
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_libver_bounds(h5py.h5f.LIBVER_LATEST, h5py.h5f.LIBVER_LATEST)
    try:
        fid = h5py.h5f.open(os.fsencode(path), h5py.h5f.ACC_RDWR | h5py.h5f.ACC_SWMR_WRITE,
                            fapl=fapl)
    except (OSError, ValueError) as exc:
        raise SnapshotStoreError(f"{path}: {hdf5_message(exc)}") from None
    return h5py.File(fid)


def open_for_reading(path: Path) -> tuple[h5py.File, bool]:
    """Open read-only; returns ``(file, swmr)``.

    A file whose superblock says a writer has it open (a live writer, or one
    that was killed) is opened in SWMR read mode, the only mode that can
    read it; its committed chunks are then checked to lie inside the file
    (:func:`check_on_disk`). Any other file is opened normally, so that HDF5's
    own checks run: a SWMR reader skips the truncation check (it reads
    zeros past the end) and retries damaged metadata for minutes.
    """
    if not path.exists():
        raise SnapshotStoreError(f"snapshot store not found: {path}")
    try:
        block = read_superblock(path)
    except (SuperblockError, OSError):
        return open_file(path, "r"), False  # not a version-3 superblock: HDF5 says what is wrong
    if not block.open_for_write:
        return open_file(path, "r"), False
    size, end = path.stat().st_size, block.offset + block.eof_address
    if size < end:  # the SWMR writer records its end of file at every flush
        raise SnapshotStoreError(f"{path}: truncated HDF5 file ({size} of {end} bytes; its "
                                 "writer was killed or is still extending it)")
    return open_file(path, "r", libver="latest", swmr=True), True


def dumps(value) -> str:
    return json.dumps(value, default=_jsonable, sort_keys=True)


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (tuple, set, frozenset)):
        return list(value)
    return str(value)


def text(value) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _dtype_name(dtype) -> str:
    kinds = {"S": "byte strings", "U": "text", "O": "objects (variable-length strings)", "b": "booleans",
             "c": "complex numbers", "V": "compound records", "M": "dates", "m": "time spans"}
    return f"{kinds.get(dtype.kind, 'values')} ({dtype})"


def check_store(f: h5py.File, path: Path) -> None:
    """Raise :class:`SnapshotStoreError` unless ``f`` is a consistent femrom store.

    Checked: the format attributes, the dof map, and for every trajectory the
    dataset shapes and types (floating point; integer steps) and that its declared
    length does not exceed its data.
    """
    fmt = f.attrs.get("format")
    if fmt is None:
        raise SnapshotStoreError(f"{path}: not a femrom snapshot store (HDF5 file without a "
                                 "'format' attribute)")
    if text(fmt) != FORMAT_NAME:
        raise SnapshotStoreError(f"{path}: not a femrom snapshot store (format {text(fmt)!r}, "
                                 f"expected {FORMAT_NAME!r})")
    missing = [k for k in _ROOT_KEYS if k not in f.attrs]
    if missing:
        raise SnapshotStoreError(f"{path}: damaged snapshot store (no {missing[0]!r} attribute)")
    version = int(f.attrs["format_version"])
    if version > FORMAT_VERSION:
        raise SnapshotStoreError(f"{path}: snapshot format version {version} is newer than this "
                                 f"femrom reads ({FORMAT_VERSION})")
    n = int(f.attrs["n_dofs"])
    widths = {"q": n, "v": n, "a": n, "u": int(f.attrs.get("n_inputs", 0)),
              "y": int(f.attrs.get("n_outputs", 0))}
    if "trajectories" not in f or "dofmap" not in f:
        raise SnapshotStoreError(f"{path}: damaged snapshot store (no /trajectories or /dofmap)")
    if f["dofmap/free"].shape != (n,):
        raise SnapshotStoreError(f"{path}: dataset /dofmap/free has shape {f['dofmap/free'].shape}, "
                                 f"expected ({n},)")
    fields = stored_fields(f)
    for name in f["trajectories"]:
        where = f"/trajectories/{name}"
        group = f["trajectories"].get(name)
        if not isinstance(group, h5py.Group):  # a link to an object that is not (fully) there
            raise SnapshotStoreError(f"{path}: damaged snapshot store ({where} is not a readable "
                                     "group)")
        for key in (*fields, "t", "step", "committed"):
            if key not in group:
                raise SnapshotStoreError(f"{path}: trajectory {name!r} has no dataset {key!r}")
        for key in fields:
            shape, chunks = group[key].shape, group[key].chunks
            if len(shape) != 2 or shape[1] != widths[key]:
                raise SnapshotStoreError(f"{path}: dataset {where}/{key} has shape {shape}, "
                                         f"expected (K, {widths[key]})")
            if chunks is None or chunks[1] != shape[1]:
                raise SnapshotStoreError(f"{path}: dataset {where}/{key} has chunks {chunks}, "
                                         f"expected (c, {shape[1]}) (whole snapshot columns)")
        for key in (*fields, "t", "step", "checkpoint/q", "checkpoint/v", "checkpoint/a"):
            kind = group[key].dtype.kind
            if kind not in ("f", "i", "u") or (key != "step" and kind != "f"):
                raise SnapshotStoreError(f"{path}: dataset {where}/{key} holds {_dtype_name(group[key].dtype)}, "
                                         f"expected {'integers' if key == 'step' else 'floating-point numbers'}")
        for key in ("t", "step"):
            if group[key].ndim != 1:
                raise SnapshotStoreError(f"{path}: dataset {where}/{key} has shape "
                                         f"{group[key].shape}, expected (K,)")
        for key in ("q", "v", "a"):
            shape = group[f"checkpoint/{key}"].shape
            if shape != (2, n):
                raise SnapshotStoreError(f"{path}: dataset {where}/checkpoint/{key} has shape "
                                         f"{shape}, expected (2, {n})")
        if group["committed"].shape != (2,):
            raise SnapshotStoreError(f"{path}: dataset {where}/committed has shape "
                                     f"{group['committed'].shape}, expected (2,)")
        length = declared_length(group)
        shortest = min(group[key].shape[0] for key in (*fields, "t", "step"))
        if not 0 <= length <= shortest:
            raise SnapshotStoreError(f"{path}: trajectory {name!r} declares {length} snapshots but "
                                     f"its datasets hold {shortest}")


def check_on_disk(f: h5py.File, path: Path) -> None:
    """Raise unless every committed chunk and checkpoint lies inside the file.

    For files a writer still has open (or was killed with): HDF5 does not
    check their length, and reads past the end return zeros.
    """
    size = path.stat().st_size
    for name, group in f["trajectories"].items():
        length = declared_length(group)
        for key in (*stored_fields(f), "t", "step"):
            ds = group[key]
            for start in range(0, length, ds.chunks[0]):
                info = ds.id.get_chunk_info_by_coord((start,) + (0,) * (ds.ndim - 1))
                if info.byte_offset is None or info.byte_offset + info.size > size:
                    raise SnapshotStoreError(
                        f"{path}: truncated: trajectory {name!r} declares {length} snapshots but "
                        f"the chunk of {key!r} at row {start} is not in the file")
        fixed = [group["committed"], *(ds for ds in group["checkpoint"].values()
                                       if isinstance(ds, h5py.Dataset)),
                 *group["checkpoint/state"].values()]
        for ds in fixed:
            offset = ds.id.get_offset()
            if offset is None or offset + ds.id.get_storage_size() > size:
                raise SnapshotStoreError(f"{path}: truncated: dataset {ds.name} is not in the file")


def stored_fields(f: h5py.File) -> tuple[str, ...]:
    """The per-step datasets of every trajectory: state fields, then ``u``/``y`` if present."""
    fields = tuple(json.loads(text(f.attrs["fields"])))
    signals = tuple(k for k, m in (("u", "n_inputs"), ("y", "n_outputs")) if int(f.attrs.get(m, 0)))
    return fields + signals


def declared_length(group: h5py.Group) -> int:
    return int(group["committed"][0])


def read_metadata(f: h5py.File) -> dict:
    """The root attributes and the dof map, decoded (JSON strings become objects)."""
    meta = {}
    for key, value in f.attrs.items():
        value = text(value) if isinstance(value, (bytes, str)) else value
        if key in ("units", "fields", "output_names", "system"):
            value = json.loads(value)
        elif isinstance(value, np.generic):
            value = value.item()
        meta[key] = value
    meta["dofmap"] = {"n_total": int(f["dofmap"].attrs["n_total"]),
                      "free": f["dofmap/free"][()], "fixed": f["dofmap/fixed"][()]}
    return meta


def trajectory_name(trajectory) -> str:
    """Trajectories are named ``"000"``, ``"001"``, ...; an int ``i`` means ``f"{i:03d}"``."""
    if isinstance(trajectory, (int, np.integer)):
        return f"{int(trajectory):03d}"
    return str(trajectory)
