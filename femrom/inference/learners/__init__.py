"""The built-in learners, one module each (found by :func:`femrom.inference.registered_learners`)."""
