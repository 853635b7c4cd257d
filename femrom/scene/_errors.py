from femrom._errors import FemromValueError


class SceneError(FemromValueError):
    """A scene file or dictionary that cannot be built; the message names the culprit."""


def take_table(data, section: str, allowed: dict, required: tuple = ()) -> dict:
    """Defaults ``allowed`` updated by the table ``data``; one SceneError naming an unknown or
    missing key (or a value that is not a table) of ``[section]``."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise SceneError(f"[{section}] must be a table, got {type(data).__name__}")
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise SceneError(f"unknown key {unknown[0]!r} in [{section}]; valid keys: {', '.join(allowed)}")
    missing = [k for k in required if data.get(k) is None]
    if missing:
        raise SceneError(f"missing key {missing[0]!r} in [{section}]")
    return {**allowed, **data}
