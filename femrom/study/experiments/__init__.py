"""The built-in experiments, one per module (``femrom.study.register_experiment`` for more)."""
