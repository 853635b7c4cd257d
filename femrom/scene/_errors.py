class SceneError(ValueError):
    """A scene file or dictionary that cannot be built; the message names the culprit."""
