"""Headless Gmsh mesh generation with a content-addressed cache of .msh files."""

from __future__ import annotations

import hashlib
import json
import math
import os
import signal
import tempfile
import threading
from collections.abc import Mapping
from numbers import Real
from pathlib import Path

import gmsh

from femrom._progress import Stage
from femrom.mesh._errors import MeshError
from femrom.mesh._geometry import declared_parameters, find_geometry, source_files

# Part of the cache key: change it whenever the way files are written changes.
_WRITER = "msh4.1-binary-physical-only"

# gmsh keeps one global state per process: one generation at a time.
_GMSH_LOCK = threading.Lock()


def default_cache_dir() -> Path:
    """``$FEMROM_CACHE/meshes``, or ``~/.cache/femrom/meshes`` when the variable is unset."""
    root = os.environ.get("FEMROM_CACHE") or Path.home() / ".cache" / "femrom"
    return Path(root).expanduser() / "meshes"


def generate_mesh(geometry: str | os.PathLike, parameters: Mapping[str, float] | None = None,
                  *, cache_dir: str | os.PathLike | None = None, force: bool = False,
                  verbose: bool = False, progress: bool | None = None) -> Path:
    """Mesh a parametric Gmsh geometry, or reuse the cached mesh of the same inputs.

    The ``.geo`` file is parsed with each given parameter pre-set, so that its
    ``DefineConstant`` default is skipped; the mesh is generated to the
    geometry's dimension and written as MSH 4.1 (binary, elements of physical
    groups only) to ``cache_dir/<stem>-<key>.msh``, where ``key`` is a sha256 of
    the geometry sources (with literal ``Include``/``Merge`` files), the sorted
    parameters, the gmsh version and the writer settings.

    Parameters
    ----------
    geometry : str or path-like
        A ``.geo`` file or a bare geometry name, see :func:`find_geometry`.
    parameters : mapping of str to float, optional
        Values for parameters declared by the geometry; others keep their default.
    cache_dir : path-like, optional
        Directory of the ``.msh`` files; default :func:`default_cache_dir`.
    force : bool
        Regenerate even when the cached file exists.
    verbose : bool
        Let gmsh print its log on the terminal.
    progress : bool or None
        A one-line stage report on stderr while gmsh runs (``meshing <name>
        (<parameters>) ...``, then ``done in m:ss``); nothing on a cache hit.
        ``None``: only on an interactive terminal outside CI.

    Returns
    -------
    pathlib.Path
        The ``.msh`` file.

    Raises
    ------
    MeshError
        Unknown geometry, unknown parameter name (the message lists the valid
        ones), non-numeric value, or gmsh failed (the message has its error).
    """
    geo = find_geometry(geometry)
    values = _checked_parameters(parameters, declared_parameters(geo.read_text()), geo)
    directory = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()
    target = directory / f"{geo.stem}-{_cache_key(geo, values)[:24]}.msh"
    if target.is_file() and not force:
        return target
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        where = "cache_dir" if cache_dir is not None else (
            "FEMROM_CACHE" if os.environ.get("FEMROM_CACHE") else "the default cache folder")
        raise MeshError(f"mesh cache folder {directory} cannot be created ({where}): "
                        f"{exc.strerror or exc}") from None
    label = f"meshing {geo.stem}"
    if values:
        label += " (" + ", ".join(f"{name}={value:g}" for name, value in values.items()) + ")"
    with _GMSH_LOCK, Stage(label, enabled=progress):
        _run_gmsh(geo, values, target, verbose)
    return target


def _checked_parameters(parameters: Mapping[str, float] | None, declared: tuple[str, ...],
                        geo: Path) -> dict[str, float]:
    """Parameters as ``{name: float}`` sorted by name, after checking names and values."""
    parameters = dict(parameters or {})
    valid = ", ".join(declared) or "none"
    values = {}
    for name in sorted(parameters):
        if name not in declared:
            raise MeshError(f"geometry '{geo.name}' has no parameter '{name}'; valid: {valid}")
        value = parameters[name]
        if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
            raise MeshError(f"parameter '{name}' of geometry '{geo.name}' must be a finite "
                            f"number, got {value!r}")
        values[name] = float(value)
    return values


def _cache_key(geo: Path, values: dict[str, float]) -> str:
    """sha256 hex digest of everything that determines the written mesh."""
    digest = hashlib.sha256()
    for path in source_files(geo):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    settings = {"parameters": values, "gmsh": gmsh.__version__, "writer": _WRITER}
    digest.update(json.dumps(settings, sort_keys=True).encode())
    return digest.hexdigest()


def _run_gmsh(geo: Path, values: dict[str, float], target: Path, verbose: bool) -> None:
    """One gmsh session: parse with ``values`` pre-set, mesh, write ``target`` atomically."""
    if gmsh.isInitialized():
        raise MeshError("gmsh is already initialized in this process; call gmsh.finalize() "
                        f"before generating '{geo.name}' (femrom needs a clean gmsh session)")
    in_main_thread = threading.current_thread() is threading.main_thread()
    sigint = signal.getsignal(signal.SIGINT) if in_main_thread else None
    # interruptible: Ctrl-C stops a long meshing at once; only possible in the main thread.
    gmsh.initialize(readConfigFiles=False, interruptible=in_main_thread)
    try:
        gmsh.option.setNumber("General.Terminal", int(verbose))
        for name, value in values.items():
            gmsh.parser.setNumber(name, [value])
        # merge, not open: open() clears the parser variables set above.
        gmsh.merge(str(geo))
        _check_overrides(values, geo)
        dimension = gmsh.model.getDimension()
        if dimension < 1:
            raise MeshError(f"geometry '{geo}' has no curve, surface or volume to mesh")
        gmsh.model.mesh.generate(dimension)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.option.setNumber("Mesh.Binary", 1)
        gmsh.option.setNumber("Mesh.SaveAll", 0)
        _write_atomically(target)
    except MeshError:
        raise
    except Exception as exc:  # gmsh reports every failure as a bare Exception
        raise MeshError(f"gmsh failed on '{geo}' with parameters {values}: {exc}") from exc
    finally:
        gmsh.finalize()
        if sigint is not None:  # gmsh.finalize does not restore the handler it replaced
            signal.signal(signal.SIGINT, sigint)


def _check_overrides(values: dict[str, float], geo: Path) -> None:
    """Fail when the file reassigned a parameter after its ``DefineConstant``."""
    for name, value in values.items():
        parsed = gmsh.parser.getNumber(name)
        if list(parsed) != [value]:
            raise MeshError(f"parameter '{name}' of geometry '{geo.name}' was set to {value} "
                            f"but the file changed it to {list(parsed)}")


def _write_atomically(target: Path) -> None:
    """Write the current gmsh mesh to a temporary file, then rename it to ``target``."""
    handle, temporary = tempfile.mkstemp(prefix=f".{target.stem}-", suffix=".msh",
                                         dir=target.parent)
    os.close(handle)
    try:
        gmsh.write(temporary)
        os.replace(temporary, target)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
