"""Benchmarks of the library: run one from the checkout's root as ``python -m benchmarks.<name>``
(so that this checkout's ``femrom`` and the benchmarks import as packages); tests import some
of their functions as ``benchmarks.<name>``."""
