"""The one exception type of :mod:`femrom.snapshots`."""


from femrom._errors import FemromValueError


class SnapshotStoreError(FemromValueError):
    """A snapshot file cannot be used: missing, not HDF5, truncated, foreign,
    wrong-shaped, inconsistent, or a read past its declared length.

    The message is one line and names the file.
    """
