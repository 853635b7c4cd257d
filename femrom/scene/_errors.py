from femrom._errors import FemromValueError


class SceneError(FemromValueError):
    """A scene file or dictionary that cannot be built; the message names the culprit."""
