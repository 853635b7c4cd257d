"""Built-in QP formulations of :class:`~femrom.control.LinearMPC` (one module each, registered on import)."""
