"""The built-in interface laws, one module each; :data:`femrom.fem.INTERFACE_LAWS` finds every module here."""
