"""The built-in reduced schemes, one module each (found by :func:`femrom.rom.registered_schemes`)."""
