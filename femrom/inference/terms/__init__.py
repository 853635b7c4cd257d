"""The built-in reduced terms, one module each (found by :func:`femrom.inference.registered_terms`)."""
