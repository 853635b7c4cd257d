"""``kind`` of an interface law in the compiled joint kernels (:class:`femrom.fem.CompiledJoint`)."""

#: Parallel 2-D Jenkins sliders (``iwan``, ``jenkins``), and the clamped Iwan law.
PARALLEL_SLIDERS, CLAMPED_IWAN = 0, 1
