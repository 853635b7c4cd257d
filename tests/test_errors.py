"""Every error femrom raises for a user is a FemromError.

(a) Every exception class femrom defines derives from :class:`femrom.FemromError`
    (warnings are not errors and are left out).
(b) No module raises a bare built-in ``ValueError``, ``TypeError``, ``RuntimeError``,
    ``KeyError``, ``IndexError`` or ``SystemExit``: it raises the matching
    ``FemromValueError`` / ``FemromTypeError`` / ``FemromRuntimeError`` (or a class
    derived from one), which still is the built-in for ``except ValueError``.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
from pathlib import Path

import femrom
from femrom import FemromError

PACKAGE = Path(femrom.__file__).resolve().parent
BUILTINS = {"ValueError", "TypeError", "RuntimeError", "KeyError", "IndexError", "SystemExit"}

# Files not converted yet, relative to the package (a folder ends with "/"). Each entry
# is being rewritten by its owner, who removes it here once it raises Femrom* errors;
# the set is meant to shrink to empty.
NOT_YET_CONVERTED: set[str] = set()


def _excluded(relative: str) -> bool:
    return any(relative == entry or (entry.endswith("/") and relative.startswith(entry))
               for entry in NOT_YET_CONVERTED)


def _relative(path: str | Path) -> str:
    return Path(path).resolve().relative_to(PACKAGE).as_posix()


def _modules():
    """Every module of femrom, imported (``__main__`` would run the command line)."""
    yield femrom
    for info in pkgutil.walk_packages(femrom.__path__, "femrom."):
        if info.name.rsplit(".", 1)[-1] == "__main__":
            continue
        try:
            yield importlib.import_module(info.name)
        except ImportError as exc:  # an optional extra (torch, pyvista, ...) missing
            if exc.name is None or exc.name.split(".")[0] == "femrom":
                raise


def test_every_exception_class_of_femrom_is_a_femrom_error():
    offenders = []
    for module in _modules():
        for name, obj in vars(module).items():
            if not (inspect.isclass(obj) and issubclass(obj, BaseException)):
                continue
            if obj.__module__ != module.__name__ or issubclass(obj, Warning):
                continue
            if _excluded(_relative(inspect.getfile(obj))):
                continue
            if not issubclass(obj, FemromError):
                offenders.append(f"{module.__name__}.{name}")
    assert not offenders, f"exception classes that are not FemromError: {offenders}"


def _exit_with_main(exc) -> bool:
    """``SystemExit(main(...))``: a script's exit status, not an error."""
    return (isinstance(exc, ast.Call) and isinstance(exc.func, ast.Name) and exc.func.id == "SystemExit"
            and len(exc.args) == 1 and isinstance(exc.args[0], ast.Call)
            and isinstance(exc.args[0].func, ast.Name) and exc.args[0].func.id == "main")


def _builtin_raises(path: Path):
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Raise) and node.exc is not None and not _exit_with_main(node.exc):
            target = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            if isinstance(target, ast.Name) and target.id in BUILTINS:
                yield node.lineno, target.id


def test_no_module_raises_a_bare_builtin_error():
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        relative = _relative(path)
        if _excluded(relative):
            continue
        offenders += [f"femrom/{relative}:{line} raises {name}" for line, name in _builtin_raises(path)]
    assert not offenders, "raise the Femrom* error instead:\n" + "\n".join(offenders)


def test_the_not_yet_converted_entries_exist():
    """An entry whose file moved or was deleted would silently exempt nothing: drop it."""
    for entry in NOT_YET_CONVERTED:
        assert (PACKAGE / entry).exists(), f"NOT_YET_CONVERTED lists {entry}, which is not in femrom"
