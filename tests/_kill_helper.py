"""Small full-order runs streamed into a snapshot store, for the SIGKILL test.

Run as a script, ``python tests/_kill_helper.py KIND STORE``: creates the
store, prints ``ready`` once the writer exists, then integrates to the end
(unless it is killed). Imported by ``tests/test_snapshots.py``, it builds the
very same systems for the uninterrupted reference run and for ``resume``.

``python tests/_kill_helper.py layout STORE MOMENT`` instead SIGKILLs itself
at one moment of making a store or adding a trajectory to it, before the
file is in SWMR mode (:func:`kill_while_changing_layout`).

Kinds
-----
``scene``
    A P1 bar (sine-Gordon ``LocalPotential``, sine input at the free end, tip
    probe) built by :func:`femrom.scene.build` and run by ``simulate``;
    chunks of 50 steps.
``stateful``
    A spring chain with :class:`CreepSpring`, a nonlinear force whose internal
    state (a creeping slider per dof and a commit counter) changes every step,
    so a resume that lost the state would diverge; chunks of 3 steps, so most
    of the wall time is spent committing and the kills land inside HDF5 writes.
"""

from __future__ import annotations

import os
import signal
import sys
import tomllib

import numpy as np
import scipy.sparse as sp
from skfem import MeshLine

from femrom.fem import NonlinearForce
from femrom.integrators import Newmark, integrate, simulate
from femrom.scene import Scene, SecondOrderSystem, build
from femrom.snapshots import SnapshotStore

SCENE_TOML = """\
name = "sine_gordon_bar"
description = "P1 bar with a sine-Gordon on-site potential, driven at the free end"
[structure]
geometry = "beam_line"
element = "p1"
[material]
youngs_modulus = 1.0
density = 1.0
area = 1.0
[effects]
inertia = { mass = "lumped" }
elasticity = {}
nonlinear_potential = { kind = "sine_gordon", coefficient = 1.0 }
actuation = {}
[boundary]
clamped = ["left"]
[[inputs]]
name = "drive"
load = { at = "right", component = "u" }
signal = { kind = "sine", amplitude = 0.5, frequency = 0.3 }
[initial_conditions]
kind = "expression"
component = "u"
displacement = "0.8 * sin(pi * x / 2)"
[time]
t_end = 10.0
dt = 0.01
integrator = "newmark"
[outputs]
probes = [{ name = "tip", at = "right", component = "u" }]
fields = ["displacement", "velocity", "acceleration"]
"""
SCENE_CHUNK = 50

STATEFUL_DOFS = 12
STATEFUL_DT = 0.02
STATEFUL_STEPS = 450
STATEFUL_CHUNK = 3
#: The store the ``layout`` kills act on: one stateful trajectory of this many steps.
LAYOUT_STEPS = 20


def scene_model():
    """The ``scene`` kind: 24 P1 elements on [0, 1], 1000 steps."""
    scene = Scene.from_dict(tomllib.loads(SCENE_TOML), source_text=SCENE_TOML)
    mesh = MeshLine(np.linspace(0.0, 1.0, 25)).with_boundaries(
        {"left": lambda x: np.isclose(x[0], 0.0), "right": lambda x: np.isclose(x[0], 1.0)})
    return build(scene, mesh=mesh)


class CreepSpring(NonlinearForce):
    """``f_i = k (q_i - s_i)^3`` with sliders that creep after every step, ``s <- s + r (q - s)``.

    State: ``(s, commits)``; :meth:`checkpoint` gives the arrays that restore it.
    """

    def __init__(self, n: int, stiffness: float = 2.0, rate: float = 0.05):
        self.n, self.k, self.rate = n, stiffness, rate

    def initial_state(self):
        return np.zeros(self.n), 0

    def force(self, q, v=None, state=None):
        return self.k * (q - state[0]) ** 3

    def tangent(self, q, v=None, state=None):
        return sp.diags(3.0 * self.k * (q - state[0]) ** 2, format="csr"), None

    def commit(self, q, v, state):
        sliders, commits = state
        return sliders + self.rate * (q - sliders), commits + 1

    def checkpoint(self, state):
        return {"sliders": np.array(state[0]), "commits": np.array(state[1], dtype=np.int64)}

    def restore(self, data):
        return np.array(data["sliders"], dtype=float), int(data["commits"])


def stateful_system() -> SecondOrderSystem:
    """Chain of 12 unit masses, springs 1, light damping, sine input on the last dof."""
    n = STATEFUL_DOFS
    K = sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
    M = sp.identity(n, format="csr")
    B = np.zeros((n, 1))
    B[-1, 0] = 1.0
    E = sp.csr_matrix(np.eye(n)[[0, n // 2, n - 1]])
    return SecondOrderSystem(mass=M, stiffness=K, damping=(0.01 * M).tocsr(), input_matrix=B,
                             inputs=lambda t: np.array([0.8 * np.sin(0.7 * t)]),
                             output_matrix=E, output_names=("first", "middle", "last"),
                             nonlinear=CreepSpring(n))


def stateful_initial_state():
    x = np.linspace(0.0, 1.0, STATEFUL_DOFS)
    return np.sin(np.pi * x), np.zeros(STATEFUL_DOFS)


def model_for(kind: str):
    """What ``resume`` needs: the model (``scene``) or the system (``stateful``)."""
    return scene_model() if kind == "scene" else stateful_system()


def run(kind: str, path, *, announce: bool = False) -> None:
    """Create the store at ``path`` and integrate ``kind`` to the end, streaming into it."""
    if kind == "scene":
        model = scene_model()
        store = SnapshotStore.create(path, model, overwrite=True)
        writer = store.writer(chunk_steps=SCENE_CHUNK)
        if announce:
            print("ready", flush=True)
        simulate(model, consumers=[writer], progress=False)
    elif kind == "stateful":
        system = stateful_system()
        store = SnapshotStore.create(path, system, fields=("q", "v", "a"), scheme=Newmark(),
                                     dt=STATEFUL_DT, n_steps=STATEFUL_STEPS, overwrite=True)
        writer = store.writer(chunk_steps=STATEFUL_CHUNK)
        if announce:
            print("ready", flush=True)
        integrate(system, Newmark(), *stateful_initial_state(), STATEFUL_DT, STATEFUL_STEPS,
                  consumers=[writer], progress=False)
    else:
        raise SystemExit(f"unknown kind {kind!r}; valid: scene, stateful")
    store.close()


def layout_store(path, *, trajectories: int = 1):
    """A stateful store holding ``trajectories`` complete runs of :data:`LAYOUT_STEPS` steps."""
    system = stateful_system()
    store = SnapshotStore.create(path, system, fields=("q", "v", "a"), scheme=Newmark(),
                                 dt=STATEFUL_DT, n_steps=LAYOUT_STEPS, overwrite=True)
    for _ in range(trajectories):
        integrate(system, Newmark(), *stateful_initial_state(), STATEFUL_DT, LAYOUT_STEPS,
                  consumers=[store.writer(chunk_steps=STATEFUL_CHUNK)], progress=False)
    return store


def _sigkill(*args, **kwargs):
    os.kill(os.getpid(), signal.SIGKILL)


def kill_while_changing_layout(path, moment: str) -> None:
    """SIGKILL this process at ``moment`` while a store is made or a trajectory added to one.

    ``"create"``: while :meth:`SnapshotStore.create` writes a new store, just
    before it is renamed into place. ``"write:N"``: just before the N-th write
    (1-based) of the undo-journaled change that adds a second trajectory to a
    store holding one (:func:`layout_store`). ``"reopen"``: after that change
    is committed, before the file is reopened in SWMR mode.
    """
    from femrom.snapshots import _format, _journal

    if moment == "create":
        os.replace = _sigkill
        layout_store(path)
    elif moment.startswith("write:"):
        store = layout_store(path)
        kill_at, write = int(moment.split(":")[1]), _journal.UndoJournalFile.write

        def write_or_die(self, data):
            if self.writes + 1 == kill_at:
                _sigkill()
            return write(self, data)

        _journal.UndoJournalFile.write = write_or_die
        store.writer(chunk_steps=STATEFUL_CHUNK)
    elif moment == "reopen":
        store = layout_store(path)
        _format.open_swmr_writer = _sigkill
        store.writer(chunk_steps=STATEFUL_CHUNK)
    raise SystemExit(f"no kill at {moment!r}; valid: create, write:N (N <= the writes), reopen")


if __name__ == "__main__":
    if sys.argv[1] == "layout":
        kill_while_changing_layout(sys.argv[2], sys.argv[3])
    run(sys.argv[1], sys.argv[2], announce=True)
