"""Finding Gmsh geometry sources and the parameters they declare."""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

from femrom.mesh._errors import MeshError

GEOMETRY_SUFFIX = ".geo"

# Repository folder of the shipped geometries: <repo>/meshes next to <repo>/femrom.
_REPOSITORY_MESHES = Path(__file__).resolve().parents[2] / "meshes"

# A string literal (kept) or a comment (dropped), in the .geo language (C-like).
_STRING_OR_COMMENT = re.compile(r'("(?:\\.|[^"\\])*")|//[^\n]*|/\*.*?\*/', re.DOTALL)
_STRING = re.compile(r'"(?:\\.|[^"\\])*"')
_DEFINE_CONSTANT = re.compile(r"\bDefineConstant\s*\[")
_DEFINE_NUMBER = re.compile(r"\b([A-Za-z_]\w*)\s*=\s*DefineNumber\s*\[")
_ASSIGNED_NAME = re.compile(r"\s*([A-Za-z_]\w*)\s*=")
_OPENING = {"[": "]", "{": "}", "(": ")"}


def search_directories() -> list[Path]:
    """Directories searched for bare geometry names, in order.

    The entries of the environment variable ``FEMROM_MESH_PATH``
    (``os.pathsep``-separated), then the repository's ``meshes/`` folder.
    """
    entries = [Path(entry).expanduser() for entry in os.environ.get("FEMROM_MESH_PATH", "").split(os.pathsep)
               if entry]
    for entry in entries:
        if not entry.is_dir():
            warnings.warn(f"FEMROM_MESH_PATH entry {entry} is not a folder; it is skipped", stacklevel=2)
    return entries + [_REPOSITORY_MESHES]


def available_geometries() -> dict[str, Path]:
    """Bare name -> ``.geo`` file of every geometry found in :func:`search_directories`.

    A name found in several directories resolves to the first one.
    """
    found: dict[str, Path] = {}
    for directory in search_directories():
        if directory.is_dir():
            for path in sorted(directory.glob("*" + GEOMETRY_SUFFIX)):
                found.setdefault(path.stem, path.resolve())
    return found


def find_geometry(name_or_path: str | os.PathLike) -> Path:
    """Resolve a geometry given as a path to a ``.geo`` file or as a bare name.

    A bare name (``"beam_solid"`` or ``"beam_solid.geo"``, no directory part)
    that is not an existing file in the working directory is looked up in
    :func:`search_directories`.

    Raises
    ------
    MeshError
        The file is not a ``.geo`` file, does not exist, or the name is unknown
        (the message lists the available geometries).
    """
    path = Path(name_or_path).expanduser()
    if path.suffix and path.suffix != GEOMETRY_SUFFIX:
        raise MeshError(f"geometry must be a Gmsh {GEOMETRY_SUFFIX} file, got '{path}'")
    if path.is_file():
        return path.resolve()
    available = available_geometries()
    if len(path.parts) == 1 and path.stem in available:
        return available[path.stem]
    if len(path.parts) > 1:
        raise MeshError(f"geometry file not found: '{path}'")
    listing = ", ".join(available) or "none"
    places = ", ".join(str(d) for d in search_directories())
    raise MeshError(f"unknown geometry '{name_or_path}'; available: {listing} "
                    f"(searched {places})")


def geometry_parameters(geometry: str | os.PathLike) -> tuple[str, ...]:
    """Names of the parameters a geometry declares, in order of declaration.

    A parameter is a variable declared with ``DefineConstant[...]`` (or the
    older ``name = DefineNumber[...]``): Gmsh keeps a value set before the file
    is parsed instead of the default written in the file.
    """
    return declared_parameters(find_geometry(geometry).read_text())


def declared_parameters(text: str) -> tuple[str, ...]:
    """Variables declared by ``DefineConstant`` / ``DefineNumber`` in .geo source text."""
    code = _STRING_OR_COMMENT.sub(lambda m: m.group(1) or " ", text)
    names: list[str] = []
    for match in _DEFINE_CONSTANT.finditer(code):
        body = _bracketed(code, match.end() - 1)
        for item in _top_level_items(body):
            assigned = _ASSIGNED_NAME.match(item)
            if assigned:
                names.append(assigned.group(1))
    names += [m.group(1) for m in _DEFINE_NUMBER.finditer(code)]
    return tuple(dict.fromkeys(names))


def source_files(geometry: Path) -> list[Path]:
    """The geometry file and the files it pulls in with ``Include`` or ``Merge``.

    Only literal file names are followed (relative to the including file),
    recursively through included ``.geo`` files; used to key the mesh cache.
    """
    files = [geometry]
    index = 0
    while index < len(files):
        current = files[index]
        index += 1
        if current.suffix != GEOMETRY_SUFFIX:
            continue
        code = _STRING_OR_COMMENT.sub(lambda m: m.group(1) or " ", current.read_text())
        for match in re.finditer(r'\b(?:Include|Merge)\s*("(?:\\.|[^"\\])*")', code):
            target = (current.parent / match.group(1)[1:-1]).resolve()
            if target.is_file() and target not in files:
                files.append(target)
    return files


def _bracketed(code: str, start: int) -> str:
    """Text between the bracket at ``code[start]`` and its matching closer."""
    stack = [_OPENING[code[start]]]
    position = start + 1
    while stack and position < len(code):
        char = code[position]
        if char == '"':
            position = _string_end(code, position)
            continue
        if char in _OPENING:
            stack.append(_OPENING[char])
        elif char == stack[-1]:
            stack.pop()
        position += 1
    return code[start + 1:position - 1]


def _top_level_items(body: str) -> list[str]:
    """Split on the commas that are not nested in brackets or strings."""
    items, depth, current = [], 0, []
    position = 0
    while position < len(body):
        char = body[position]
        if char == '"':
            end = _string_end(body, position)
            current.append(body[position:end])
            position = end
            continue
        if char in _OPENING:
            depth += 1
        elif char in "]})":
            depth -= 1
        elif char == "," and depth == 0:
            items.append("".join(current))
            current = []
            position += 1
            continue
        current.append(char)
        position += 1
    items.append("".join(current))
    return items


def _string_end(code: str, start: int) -> int:
    """Index just past the string literal opening at ``code[start]`` (unterminated: end)."""
    match = _STRING.match(code, start)
    return match.end() if match else len(code)
