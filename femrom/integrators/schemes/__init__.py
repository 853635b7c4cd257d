"""The built-in time schemes, one module each (found by :func:`femrom.integrators.registered_schemes`)."""
