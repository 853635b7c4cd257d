"""The named cases: one module per structure, configuration and case physics over the library.

Each case is a module ``femrom.cases.<name>`` with its scene file ``<name>.toml`` beside it
(package data), a ``main(argv)`` that ``python -m femrom run <name> [options]`` calls, and the
functions its tests and benchmarks import (``run`` and the case's own settings):

- ``beam``: Euler-Bernoulli cantilever (Hermite), FOM and L-OpInf / Galerkin / OpInf ROMs,
  the FOM's accuracy against its cost (docs/cases/beam.md);
- ``fishtail``: soft-robotic fishtail (P2 solid, chamber pressure), snapshots streamed to
  HDF5, L-OpInf against Galerkin and OpInf at mesh levels up to 7.6e5 dofs (docs/cases/fishtail.md);
- ``jointed_beam``: the bolted half Brake-Reuss beam: preload, calibrated modes, QSMA, the Iwan
  joint fitted on the measured backbone, ECSW, the ring-down and the stepped sine
  (docs/cases/jointed_beam.md);
- ``jointed_beam_measured``: data-only ROMs of the beam's measured hammer-impact ring-down
  (docs/cases/jointed_beam_measured.md);
- ``jointed_beam_prestress``: the beam's preload, its modes and the tangential stiffness
  calibrated on the measured first frequency (docs/jointed_beam.md);
- ``jointed_beam_rom``: SpML, L-OpInf, Iwan-L-OpInf and Galerkin ROMs against the beam's
  hyper-reduced Iwan model (docs/cases/jointed_beam_rom.md);
- ``nls``: cubic nonlinear Schroedinger, H-OpInf with a known quartic Hamiltonian (docs/cases/nls.md);
- ``sine_gordon``: the sine-Gordon breather, L-OpInf with a known nonlinear force and
  hyper-reduction (docs/cases/sine_gordon.md);
- ``soft_robot``: SERPENT-like soft robot, L-OpInf against DMDc, ERA, OKID and Galerkin, MPC
  closed loops on the FOM (docs/cases/soft_robot.md).

No case imports another: what two cases share lives in the library (the jointed beam's
facts and model settings: :data:`femrom.study.JOINTED_BEAM`, :class:`femrom.study.JointedBeamModel`).
The command line lists them (:func:`femrom.cli.available_cases`) and imports one by name
(:func:`femrom.cli.load_case`); :func:`scene_file` is a case's scene file.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from femrom.cli import CaseError

__all__ = ["case_parser", "scene_file"]


def case_parser(name: str, doc: str | None, *, quick: str, out: str | None = None) -> argparse.ArgumentParser:
    """The command line of case ``name``: the options every case shares, to which it adds its own.

    Shared: ``-o/--out`` (default ``results/<name>``), ``--quick`` (described by ``quick``: what the
    case makes smaller), ``--yes`` (run even a step the conditioning check flags: the command line
    refuses it otherwise) and ``--debug`` (errors with their traceback; read by the command line).
    ``out`` replaces the help text of ``-o/--out``.
    """
    parser = argparse.ArgumentParser(prog=f"femrom run {name}", description=(doc or name).split("\n")[0])
    shared = parser.add_argument_group("options of every case")
    shared.add_argument("-o", "--out", type=Path, default=Path("results") / name,
                        help=out or f"output folder (default results/{name})")
    shared.add_argument("--quick", action="store_true", help=quick)
    shared.add_argument("--yes", action="store_true",
                        help="run even with a time step the conditioning check flags (refused otherwise)")
    shared.add_argument("--debug", action="store_true", help="errors with their traceback")
    return parser


def scene_file(name: str) -> Path:
    """The scene file ``<name>.toml`` shipped beside the cases (e.g. ``scene_file("beam")``).

    Raises
    ------
    femrom.cli.CaseError
        No such scene file (the message lists the shipped ones).
    """
    path = Path(__file__).with_name(f"{name}.toml")
    if not path.is_file():
        shipped = sorted(p.stem for p in Path(__file__).parent.glob("*.toml"))
        raise CaseError(f"no scene file {name!r} among the cases; shipped: {', '.join(shipped)}")
    return path
