"""The built-in effects, one module each; :func:`femrom.scene.effects` finds every module here."""
