"""Snapshot store: round trip, metadata, block reads, resume, SIGKILL at random moments,
and one clear error for every kind of bad file."""

import dataclasses
import datetime
import os
import re
import select
import shutil
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
import scipy.sparse as sp

import _kill_helper as helper  # the same systems the script runs (tests/ is on the path)
import femrom
from femrom.integrators import (
    CentralDifference,
    Newmark,
    OutputRecorder,
    Trajectory,
    integrate,
    iterate,
)
from femrom.scene import SecondOrderSystem
from femrom.snapshots import (
    DEFAULT_UNITS,
    FORMAT_NAME,
    PendingChangeWarning,
    SnapshotStore,
    SnapshotStoreError,
    read_rows,
    recover,
    resume,
)
from femrom.snapshots import _format, _journal, _recovery, _writer
from femrom.snapshots._superblock import lookup3, read_superblock

REPO = Path(__file__).resolve().parents[1]
HELPER = Path(__file__).with_name("_kill_helper.py")    # also run as a script (a process to kill)


def forced_chain(n: int = 6) -> SecondOrderSystem:
    """Damped spring chain, u = [sin 1.3 t, cos 0.4 t] on the end dofs, two outputs."""
    K = sp.diags([2.0 * np.ones(n), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
    M = sp.diags(1.0 + 0.1 * np.arange(n), format="csr")
    B = np.zeros((n, 2))
    B[0, 0] = B[-1, 1] = 1.0
    return SecondOrderSystem(mass=M, stiffness=K, damping=(0.02 * K).tocsr(), input_matrix=B,
                             inputs=lambda t: np.array([np.sin(1.3 * t), np.cos(0.4 * t)]),
                             output_matrix=sp.csr_matrix(np.eye(n)[[1, n - 2]]),
                             output_names=("left", "right"))


def _rows_equal(store, other, trajectory, length=None) -> bool:
    """Bitwise equality of every field and the times over ``other``'s first ``length`` rows."""
    length = store.length(trajectory) if length is None else length
    return (all(np.array_equal(store.read(trajectory, f), other.read(trajectory, f, 0, length))
                for f in store.fields)
            and np.array_equal(store.times(trajectory), other.times(trajectory)[:length])
            and np.array_equal(store.steps(trajectory), other.steps(trajectory)[:length]))


# -- round trip ----------------------------------------------------------------
def test_round_trip_of_several_trajectories_and_column_blocks(tmp_path):
    system = forced_chain()
    n, dt = system.n_dofs, 0.05
    store = SnapshotStore.create(tmp_path / "s.h5", system, fields=("q", "v", "a"),
                                 scheme=Newmark(), dt=dt, n_steps=50)
    references = []
    rng = np.random.default_rng(0)
    for every in (1, 3):  # two trajectories: different initial states, sampling and chunks
        q0, v0 = rng.standard_normal(n), rng.standard_normal(n)
        trajectory, outputs = Trajectory(every=every), OutputRecorder(system, every=every)
        writer = store.writer(chunk_steps=7, every=every)  # 51 or 17 rows: partial last chunk
        integrate(system, Newmark(), q0, v0, dt, 50, consumers=[writer, trajectory, outputs])
        references.append((trajectory, outputs))

    assert store.trajectories == ("000", "001")
    assert store.n_dofs == n and store.fields == ("q", "v", "a", "u", "y")
    assert store.n_snapshots("q") == 51 + 17
    for name, (trajectory, outputs) in zip(store.trajectories, references):
        for field in ("q", "v", "a"):  # bitwise: the store copies the integrator's numbers
            assert np.array_equal(store.read(name, field), getattr(trajectory, field))
        assert np.array_equal(store.times(name), trajectory.t)
        assert np.array_equal(store.steps(name), trajectory.steps)
        assert np.array_equal(store.read(name, "y"), outputs.outputs)
        assert np.array_equal(store.read(name, "u"),
                              np.column_stack([system.inputs(t) for t in trajectory.t]))
        assert np.array_equal(store.read(name, "q", 4, 9), trajectory.q[:, 4:9])
        assert store.is_complete(name)
    assert store.attrs(1)["every"] == 3 and store.attrs(0)["dt"] == dt

    blocks = list(store.iter_blocks("q", 5))
    # each block in one trajectory: 51 -> 11 blocks (last of 1), 17 -> 4 blocks (last of 2)
    assert [b.shape[1] for b in blocks] == [5] * 10 + [1] + [5] * 3 + [2]
    assert all(b.shape[0] == n for b in blocks)
    whole = np.hstack([t.q for t, _ in references])
    assert np.array_equal(np.hstack(blocks), whole)
    assert np.array_equal(np.hstack(list(store.iter_blocks("v", 100, trajectories=[1]))),
                          references[1][0].v)

    with h5py.File(store.path, "r") as f:  # the layout: (K, n) rows, chunks of whole columns
        q = f["trajectories/000/q"]
        assert q.chunks == (7, n) and q.maxshape == (None, n) and q.compression is None

    with pytest.raises(SnapshotStoreError, match=r"has 51 committed snapshots; cannot read \[40, 52\)"):
        store.read(0, "q", 40, 52)
    with pytest.raises(SnapshotStoreError, match="no field 'w'; stored: q, v, a, u, y"):
        store.read(0, "w")
    with pytest.raises(SnapshotStoreError, match="no trajectory '007'; stored: 000, 001"):
        store.read(7, "q")
    store.close()


def test_metadata_scene_text_version_dof_map_units(tmp_path):
    model = helper.scene_model()
    store = SnapshotStore.create(tmp_path / "m.h5", model)
    meta = SnapshotStore.open(tmp_path / "m.h5").metadata
    assert meta["format"] == FORMAT_NAME and meta["format_version"] == 1
    assert meta["femrom_version"] == femrom.__version__
    assert meta["scene_toml"] == helper.SCENE_TOML and meta["scene_name"] == "sine_gordon_bar"
    assert meta["units"] == DEFAULT_UNITS
    assert meta["scheme"] == "NewmarkAverageAcceleration"
    assert meta["dt"] == 0.01 and meta["n_steps"] == 1000
    assert meta["fields"] == ["q", "v", "a"]  # the scene's [outputs] fields
    assert meta["output_names"] == ["tip"] and meta["n_inputs"] == 1
    cond = model.system.condensation
    assert meta["dofmap"]["n_total"] == cond.n_total == 25
    assert np.array_equal(meta["dofmap"]["free"], cond.free)
    assert np.array_equal(meta["dofmap"]["fixed"], cond.fixed) and cond.fixed.size == 1
    created = datetime.datetime.fromisoformat(meta["created"])
    assert abs((datetime.datetime.now(datetime.timezone.utc) - created).total_seconds()) < 600
    assert np.array_equal(store.condensation.expand(np.ones(24)), cond.expand(np.ones(24)))


# -- commit and resume in-process ----------------------------------------------
def test_only_completed_chunks_are_declared_and_close_commits_the_rest(tmp_path):
    system = forced_chain()
    store = SnapshotStore.create(tmp_path / "c.h5", system, dt=0.05, n_steps=30,
                                 scheme=CentralDifference())
    writer = store.writer(chunk_steps=4)
    run = iterate(system, CentralDifference(), np.ones(6), np.zeros(6), 0.05, 30)
    for k, result in zip(range(11), run):  # steps 0..10: two chunks of 4 and 3 buffered rows
        writer(result)
    assert store.length(0) == 8 and writer.length == 8
    assert store.checkpoint(0).step == 7  # the last committed row
    with pytest.raises(SnapshotStoreError, match="cannot read"):
        store.read(0, "q", 0, 9)
    writer.close()
    assert store.length(0) == 11 and store.checkpoint(0).step == 10
    assert not store.is_complete(0)
    with pytest.raises(SnapshotStoreError, match="trajectory .000. exists"):
        store.writer(0)  # an existing trajectory is continued by resume, not a new writer
    store.close()


def test_resume_after_an_error_and_before_the_first_chunk_is_bit_identical(tmp_path):
    system = helper.stateful_system()
    q0, v0 = helper.stateful_initial_state()
    reference = SnapshotStore.create(tmp_path / "ref.h5", system, fields=("q", "v", "a"),
                                     scheme=Newmark(), dt=0.02, n_steps=80)
    integrate(system, Newmark(), q0, v0, 0.02, 80, consumers=[reference.writer(chunk_steps=6)])

    # a run stopped by an exception at step 40: close() commits 41 rows, resume does the rest
    def bomb(result):
        if result.step == 40:
            raise KeyboardInterrupt

    store = SnapshotStore.create(tmp_path / "a.h5", system, fields=("q", "v", "a"),
                                 scheme=Newmark(), dt=0.02, n_steps=80)
    with pytest.raises(KeyboardInterrupt):
        integrate(system, Newmark(), q0, v0, 0.02, 80,
                  consumers=[store.writer(chunk_steps=6), bomb])
    assert store.length(0) == 41
    state = store.checkpoint(0).state  # the stateful force's (sliders, commits), restored
    assert state[1] == 40 and state[0].shape == (helper.STATEFUL_DOFS,)
    store.close()
    summary = resume(tmp_path / "a.h5", system, Newmark())
    assert summary.n_steps == 40
    done = SnapshotStore.open(tmp_path / "a.h5")
    assert done.length(0) == 81 and _rows_equal(done, reference, 0)
    done.close()
    assert resume(tmp_path / "a.h5", system, Newmark()).n_steps == 0  # complete: nothing to do

    # a run that died before its first chunk: only the initial checkpoint is committed
    store = SnapshotStore.create(tmp_path / "b.h5", system, fields=("q", "v", "a"),
                                 scheme=Newmark(), dt=0.02, n_steps=80)
    writer = store.writer(chunk_steps=50)
    for _, result in zip(range(20), iterate(system, Newmark(), q0, v0, 0.02, 80)):
        writer(result)
    writer._buffered = 0  # drop the buffered rows, as a kill would
    store.close()
    stopped = SnapshotStore.open(tmp_path / "b.h5")
    assert stopped.length(0) == 0 and stopped.checkpoint(0).step == 0
    stopped.close()
    resume(tmp_path / "b.h5", system, Newmark())
    done = SnapshotStore.open(tmp_path / "b.h5")
    assert _rows_equal(done, reference, 0) and done.length(0) == 81
    done.close()

    with pytest.raises(SnapshotStoreError, match="was run with NewmarkAverageAcceleration, "
                                                 "not CentralDifference"):
        resume(tmp_path / "b.h5", system, CentralDifference())
    reference.close()


class _Stop(BaseException):
    """Stands for a kill at one point of the commit protocol."""


def _run_stopped_at(path, system, event_to_stop):
    """Run 17 steps in chunks of 3, stopping just before write/flush number ``event_to_stop``.

    The file is then closed without the writer's own ``close()``: everything
    written before the stop reaches the disk, nothing after it (the prefix a
    kill leaves that is hardest on the commit order). Returns the events counted.
    """
    events = [0]
    write_rows, flush = _writer._write_rows, _writer.SnapshotWriter._flush

    def count(function):
        def wrapped(*args, **kwargs):
            if events[0] == event_to_stop:
                raise _Stop
            events[0] += 1
            return function(*args, **kwargs)
        return wrapped

    store = SnapshotStore.create(path, system, fields=("q", "v", "a"), scheme=Newmark(),
                                 dt=0.02, n_steps=17)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(_writer, "_write_rows", count(write_rows))
        patch.setattr(_writer.SnapshotWriter, "_flush", count(flush))
        writer = store.writer(chunk_steps=3)
        run = iterate(system, Newmark(), *helper.stateful_initial_state(), 0.02, 17)
        try:
            for result in run:
                writer(result)
        except _Stop:
            pass
    writer._closed = True  # abandon the writer: no commit of the buffered rows
    store._writer_closed()
    return events[0]


def test_a_stop_between_any_two_writes_of_a_commit_keeps_the_store_consistent(tmp_path):
    system = helper.stateful_system()
    n_events = _run_stopped_at(tmp_path / "reference.h5", system, -1)  # never stops
    reference = SnapshotStore.open(tmp_path / "reference.h5")
    assert reference.length(0) == 18
    # the protocol: the initial checkpoint is 8 writes (step, t, has_a, q, v, a, 2 state
    # arrays), flush, committed record, flush; each chunk adds 7 row writes (q, v, a, u, y,
    # t, step) to that
    initial, per_commit = 8 + 3, 7 + 8 + 3
    assert n_events == initial + 6 * per_commit
    first = initial + 3 * per_commit  # every point of the 4th chunk's commit, and just after
    for event in range(first, first + per_commit + 1):
        path = tmp_path / f"stopped_{event}.h5"
        _run_stopped_at(path, system, event)
        store = SnapshotStore.open(path)
        length = store.length(0)
        assert length in (9, 12)  # three chunks committed, or four
        assert _rows_equal(store, reference, 0)
        assert store.checkpoint(0).step == length - 1  # never a checkpoint ahead of the rows
        store.close()
        resume(path, system, Newmark())
        finished = SnapshotStore.open(path)
        assert finished.length(0) == 18 and _rows_equal(finished, reference, 0)
        finished.close()
    reference.close()


# -- SIGKILL at random moments ---------------------------------------------------
def _kill_once(kind, path, delay):
    """Start the helper, wait until its writer exists, sleep ``delay`` s, SIGKILL it."""
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    process = subprocess.Popen([sys.executable, str(HELPER), kind, str(path)],
                               stdout=subprocess.PIPE, env=env)
    try:
        # a child that never says "ready" (stuck before its writer exists) fails here within a
        # minute instead of holding the test run
        ready, _, _ = select.select([process.stdout], [], [], 60.0)
        assert ready and process.stdout.readline().strip() == b"ready", "the helper did not start its writer"
        time.sleep(delay)
    finally:
        os.kill(process.pid, signal.SIGKILL)
        process.wait()
        process.stdout.close()


# Five kills each by default (4 s per kind here: a child starts in ~0.5 s, the scene's
# 1000 steps run in 0.25 s); thirty on the stateful chain with -m slow.
@pytest.mark.parametrize("kind, kills", [
    ("stateful", 5), ("scene", 5),
    pytest.param("stateful", 30, marks=pytest.mark.slow, id="stateful-30-slow"),
])
def test_sigkill_at_random_moments_keeps_chunks_and_resumes_bit_identically(tmp_path, kind, kills):
    tic = time.perf_counter()
    helper.run(kind, tmp_path / "reference.h5")
    run_seconds = time.perf_counter() - tic
    reference = SnapshotStore.open(tmp_path / "reference.h5")
    total = reference.length(0)
    model = helper.model_for(kind)
    scheme = None if kind == "scene" else Newmark()
    rng = np.random.default_rng(2024 if kind == "stateful" else 7)
    chunk = helper.STATEFUL_CHUNK if kind == "stateful" else helper.SCENE_CHUNK
    landed = []
    for attempt in range(3 * kills):
        if len(landed) == kills:
            break
        path = tmp_path / f"killed_{attempt}.h5"
        # the child steps about as fast as the reference run (same code); a kill after its
        # last commit lands nowhere and is retried with a shorter window
        _kill_once(kind, path, rng.uniform(0.0, 0.7 * run_seconds / (1 + attempt // kills)))
        store = SnapshotStore.open(path)  # a killed SWMR writer leaves a readable file
        length = store.length(0)
        assert 0 <= length <= total
        if length == total:
            store.close()
            continue
        assert length % chunk == 0  # only whole chunks are ever declared
        assert _rows_equal(store, reference, 0)  # every committed chunk is the reference's
        checkpoint = store.checkpoint(0)
        assert checkpoint.step == (length - 1 if length else 0)
        store.close()
        if not landed:
            # a killed writer's file cut short is refused, not read as zeros past its end
            cut = tmp_path / "killed_and_cut.h5"
            data = path.read_bytes()
            cut.write_bytes(data[:2 * len(data) // 3])
            with pytest.raises(SnapshotStoreError, match="truncated"):
                SnapshotStore.open(cut).read(0, "q")
            # and every committed chunk of the killed file is inside it (checked on open);
            # seen from a file half as long, the last ones are not
            with h5py.File(path, "r", libver="latest", swmr=True) as f:
                _format.check_on_disk(f, path)
                half = SimpleNamespace(stat=lambda: SimpleNamespace(st_size=len(data) // 2))
                if length:
                    with pytest.raises(SnapshotStoreError, match="is not in the file"):
                        _format.check_on_disk(f, half)
            # a live writer is never overridden
            with pytest.MonkeyPatch.context() as patch:
                patch.setattr(_recovery, "_process_alive", lambda pid: True)
                with pytest.raises(SnapshotStoreError, match="open for writing by process"):
                    resume(path, model, scheme)
        resume(path, model, scheme)
        finished = SnapshotStore.open(path)
        assert finished.length(0) == total and _rows_equal(finished, reference, 0)
        finished.close()
        assert read_superblock(path).flags == 0  # closed cleanly after the resume
        landed.append(length // chunk)
    reference.close()
    print(f"{kind}: kills landed at committed chunks {landed} of {total // chunk}")
    assert len(landed) == kills


# -- kills while the layout changes (before SWMR mode) ------------------------------
def _copy_as_killed(path, destination, *, journal_cut=0, torn=None):
    """Copy the files a SIGKILL at this moment would leave (the store and its journal).

    The copy is another file (device, inode) than the one the journal was written for,
    as a backup restored or an rsync'ed store with its journal: recognised by content.
    ``journal_cut``: bytes cut off the journal (killed while appending a record).
    ``torn``: ``(offset, data)`` written into the copy (an overwrite cut short).
    """
    shutil.copyfile(path, destination)
    journal = _journal.journal_path(path)
    if journal.exists():
        data = journal.read_bytes()
        _journal.journal_path(destination).write_bytes(data[:len(data) - journal_cut])
    if torn is not None:
        with open(destination, "r+b") as fh:
            fh.seek(torn[0])
            fh.write(torn[1])


def _watch_layout_change(patch, path, folder):
    """Copy the files as a kill would leave them at every moment of a journaled change.

    Moments: before each write; for a write over old bytes also after its record is
    journaled, with that record cut short, and with the overwrite half done; before a
    truncation; after the HDF5 file is closed but before the journal is deleted.
    Returns the copies in order and counts: ``writes`` and ``journaled`` (writes over
    old bytes) per change.
    """
    copies, counts = [], SimpleNamespace(writes=[], journaled=0)
    journal_class = _journal.UndoJournalFile
    write, save, truncate, commit = (journal_class.write, journal_class._save,
                                     journal_class.truncate, journal_class.commit)

    def copy(**how):
        copies.append(folder / f"killed_{len(copies)}.h5")
        _copy_as_killed(path, copies[-1], **how)

    def watched_write(self, data):
        copy()
        self.pending = bytes(data)
        return write(self, data)

    def watched_save(self, start, stop):
        save(self, start, stop)
        if stop > start and getattr(self, "pending", None) is not None:
            counts.journaled += 1
            copy()
            copy(journal_cut=5)
            copy(torn=(start, self.pending[:len(self.pending) // 2]))
            self.pending = None

    def watched_truncate(self, size=None):
        copy()
        return truncate(self, size)

    def watched_commit(self):
        copy()
        counts.writes.append(self.writes)
        return commit(self)

    patch.setattr(journal_class, "write", watched_write)
    patch.setattr(journal_class, "_save", watched_save)
    patch.setattr(journal_class, "truncate", watched_truncate)
    patch.setattr(journal_class, "commit", watched_commit)
    return copies, counts


@pytest.mark.parametrize("change", ["add", "resume"])
def test_a_kill_anywhere_in_a_layout_change_leaves_the_store_as_before(tmp_path, change):
    # Adding a trajectory (or trimming one for resume) happens outside SWMR mode, where
    # HDF5 rewrites existing metadata in place and in no set order. Every moment of it
    # is copied as a kill would leave it; each copy must open as the store was before,
    # byte for byte (the undo journal rolled back), and the change must then succeed.
    system = helper.stateful_system()
    folder = tmp_path / "killed"
    folder.mkdir()
    if change == "add":
        reference = helper.layout_store(tmp_path / "reference.h5", trajectories=2)
        path = tmp_path / "store.h5"
        helper.layout_store(path).close()
        before = {"000": 21}
    else:
        _run_stopped_at(tmp_path / "reference.h5", system, -1)
        reference = SnapshotStore.open(tmp_path / "reference.h5")
        path = tmp_path / "stopped.h5"
        # stopped after 4 of the 7 row writes of the 4th chunk: q, v, a, u hold 12 rows,
        # 9 are declared; resume trims them back to 9 under the journal
        _run_stopped_at(path, system, 11 + 3 * 18 + 4)
        with h5py.File(path, "r") as f:
            assert f["trajectories/000/q"].shape[0] == 12
        before = {"000": 9}

    original = path.read_bytes()
    with pytest.MonkeyPatch.context() as patch:
        copies, counts = _watch_layout_change(patch, path, folder)
        if change == "add":
            SnapshotStore.open(path, system=system).writer(chunk_steps=3).close()
        else:
            with patch.context() as stop:  # the change only: resume up to the SWMR reopen
                stop.setattr(_format, "open_swmr_writer", lambda p: (_ for _ in ()).throw(_Stop))
                with pytest.raises(_Stop):
                    resume(path, system, Newmark())
    # one change, which rewrote old bytes (what a kill could tear), watched at every write
    assert len(counts.writes) == 1 and counts.journaled >= 5
    torn_states = warned_reads = 0
    for index, copy in enumerate(copies):
        unrolled = copy.with_name("unrolled_" + copy.name)
        shutil.copyfile(copy, unrolled)  # the same files without their journal
        try:
            with SnapshotStore.open(unrolled) as bare:
                intact = all(bare.length(name) == length and _rows_equal(bare, reference, name)
                             for name, length in before.items())
        except SnapshotStoreError:
            intact = False
        torn_states += not intact
        as_killed = copy.read_bytes()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with SnapshotStore.open(copy) as reader:     # reads the store as before, writes nothing
                assert reader.trajectories == tuple(before)
                for name, length in before.items():
                    assert reader.length(name) == length and _rows_equal(reader, reference, name)
        said = [w for w in caught if issubclass(w.category, PendingChangeWarning)]
        # a journal with records is said once, naming the store; one cut short is no change
        assert len(said) <= 1 and all(str(copy) in str(w.message) for w in said)
        warned_reads += len(said)
        assert copy.read_bytes() == as_killed
        recover(copy)                                # a copy's journal rolls back like the original's
        assert not _journal.journal_path(copy).exists()
        assert copy.read_bytes() == original
        store = SnapshotStore.open(copy, system=system)
        if index not in (0, len(copies) // 2, len(copies) - 1):  # the same bytes: finish a few
            store.close()
            continue
        if change == "add":
            integrate(system, Newmark(), *helper.stateful_initial_state(), helper.STATEFUL_DT,
                      helper.LAYOUT_STEPS, consumers=[store.writer(chunk_steps=3)])
            assert store.length(1) == 21 and _rows_equal(store, reference, 1)
            store.close()
        else:
            store.close()
            resume(copy, system, Newmark())
            with SnapshotStore.open(copy) as finished:
                assert finished.length(0) == 18 and _rows_equal(finished, reference, 0)
    # without its journal, many copies taken mid-change are unreadable or wrong: the
    # journal is what keeps these states safe (so this test fails without it)
    assert torn_states >= 1
    # a reader that reads around a killed writer's change says so (the torn copies at least)
    assert warned_reads >= torn_states
    reference.close()
    print(f"{change}: {counts.writes[0]} writes ({counts.journaled} over old bytes), "
          f"{len(copies)} kill moments, "
          f"{torn_states} unreadable or wrong without the journal")


class _SlashKeys(helper.CreepSpring):
    def checkpoint(self, state):
        return {"sliders/0": np.array(state[0]), "commits": np.array(state[1])}


def test_a_writer_failing_while_it_sets_up_leaves_the_store_unchanged(tmp_path):
    # The checkpoint keys are checked after the datasets are created: the undo journal
    # takes the half-made trajectory away again (before, it stayed and broke the store).
    path = tmp_path / "store.h5"
    helper.layout_store(path).close()
    original = path.read_bytes()
    bad = dataclasses.replace(helper.stateful_system(), nonlinear=_SlashKeys(helper.STATEFUL_DOFS))
    store = SnapshotStore.open(path, system=bad)
    with pytest.raises(ValueError, match="checkpoint key 'sliders/0'.*cannot name a dataset"):
        store.writer()
    store.close()
    assert path.read_bytes() == original and not _journal.journal_path(path).exists()
    with SnapshotStore.open(path) as reopened:
        assert reopened.trajectories == ("000",) and reopened.length(0) == 21
    # a reader holding the file open (HDF5's shared lock) is not written under
    with h5py.File(path, "r"):
        with pytest.raises(SnapshotStoreError, match="is open elsewhere .file locked"):
            SnapshotStore.open(path, system=helper.stateful_system()).writer()
    assert path.read_bytes() == original


def _kill_in_layout_change(path, moment):
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    done = subprocess.run([sys.executable, str(HELPER), "layout", str(path), moment], env=env,
                          capture_output=True, text=True)
    assert done.returncode == -signal.SIGKILL, done.stderr


def test_sigkill_while_a_store_is_made_or_a_trajectory_added(tmp_path):
    # Real SIGKILLs at moments before SWMR mode (the helper kills itself there).
    system = helper.stateful_system()
    reference = helper.layout_store(tmp_path / "reference.h5", trajectories=2)

    # killed while creating the store: no store at all, only the temporary file
    path = tmp_path / "created.h5"
    _kill_in_layout_change(path, "create")
    assert not path.exists()
    assert [p.name for p in tmp_path.glob(".created.h5.*.creating")]
    with pytest.raises(SnapshotStoreError, match="not found"):
        SnapshotStore.open(path)

    # killed in the journaled change that adds trajectory 001: rolled back on opening.
    # Of its 55 writes here, 1-9 go past the old end, 10-17 rewrite old metadata in place.
    for kill_at in (1, 14, 40):
        path = tmp_path / f"added_{kill_at}.h5"
        _kill_in_layout_change(path, f"write:{kill_at}")
        assert _journal.journal_path(path).exists()
        with pytest.MonkeyPatch.context() as patch:  # a live journal's process is respected
            patch.setattr(_recovery, "_process_alive", lambda pid: True)
            with pytest.raises(SnapshotStoreError, match="is adding or resuming a trajectory"):
                SnapshotStore.open(path)
        store = SnapshotStore.open(path, system=system)
        assert store.trajectories == ("000",) and _rows_equal(store, reference, 0)
        assert _journal.journal_path(path).exists()          # a reader leaves it; the writer rolls back
        integrate(system, Newmark(), *helper.stateful_initial_state(), helper.STATEFUL_DT,
                  helper.LAYOUT_STEPS, consumers=[store.writer(chunk_steps=3)])
        assert store.trajectories == ("000", "001") and _rows_equal(store, reference, 1)
        store.close()

    # killed after the change, before the SWMR reopen: the new trajectory is there, empty
    path = tmp_path / "reopen.h5"
    _kill_in_layout_change(path, "reopen")
    with SnapshotStore.open(path) as store:
        assert store.trajectories == ("000", "001") and _rows_equal(store, reference, 0)
        assert store.length(1) == 0 and store.checkpoint(1) is None
    with pytest.raises(SnapshotStoreError, match="has no checkpoint yet; run it again"):
        resume(path, system, Newmark())  # a bare system has no initial state to restart from
    reference.close()


# -- bad files -------------------------------------------------------------------
@pytest.fixture
def good_store(tmp_path):
    system = forced_chain()
    store = SnapshotStore.create(tmp_path / "good.h5", system, scheme=Newmark(), dt=0.05,
                                 n_steps=40)
    integrate(system, Newmark(), np.ones(6), np.zeros(6), 0.05, 40,
              consumers=[store.writer(chunk_steps=8)])
    store.close()
    return tmp_path / "good.h5"


def _damaged(good: Path, name: str, change) -> Path:
    path = good.with_name(name)
    path.write_bytes(good.read_bytes())
    change(path)
    return path


def _edit(path, edit):
    with h5py.File(path, "r+") as f:
        edit(f)


def _replace_q(f):
    del f["trajectories/000/q"]
    f["trajectories/000/q"] = np.zeros((41, 7))


def _set_length(f):
    f["trajectories/000/committed"][0] = 1000


def _truncate(path):
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])


def _scribble(path):
    data = bytearray(path.read_bytes())
    data[48:80] = b"\xab" * 32  # the root object header, guarded by its checksum
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("name, change, message", [
    ("text.h5", lambda p: p.write_text("q, v, a\n1, 2, 3\n"), "not an HDF5 file"),
    ("bare.h5", lambda p: h5py.File(p, "w").close(), "not a femrom snapshot store (HDF5 file without"),
    ("foreign.h5", lambda p: _edit(p, lambda f: f.attrs.__setitem__("format", "netcdf4")),
     "not a femrom snapshot store (format 'netcdf4'"),
    ("shape.h5", lambda p: _edit(p, _replace_q), "/trajectories/000/q has shape (41, 7), "
                                                 "expected (K, 6)"),
    ("length.h5", lambda p: _edit(p, _set_length), "declares 1000 snapshots but its datasets hold 41"),
    ("truncated.h5", _truncate, "truncated HDF5 file"),
    ("scribbled.h5", _scribble, "damaged or unreadable"),
])
def test_bad_files_give_one_clear_error_naming_the_file(good_store, name, change, message):
    path = _damaged(good_store, name, change)
    with pytest.raises(SnapshotStoreError, match=re.escape(message)) as info:
        store = SnapshotStore.open(path)
        store.read(0, "q")  # damage past the metadata shows on reading
    text = str(info.value)
    assert str(path) in text and "\n" not in text
    with pytest.raises(SnapshotStoreError, match="not found"):
        SnapshotStore.open(good_store.with_name("absent.h5"))


def test_superblock_checksum_is_lookup3(good_store):
    # reference values printed by the driver of Bob Jenkins' lookup3.c (2006)
    assert lookup3(b"") == 0xDEADBEEF
    assert lookup3(b"Four score and seven years ago") == 0x17770551
    assert lookup3(b"Four score and seven years ago", 1) == 0xCD628161
    block = read_superblock(good_store)  # raises on a checksum mismatch
    assert block.version == 3 and block.flags == 0


@pytest.mark.parametrize("checksums", [True, False])
def test_a_flipped_byte_in_a_chunk_is_an_error_with_checksums_and_silent_without(tmp_path, checksums):
    """Fletcher-32 per chunk: silent corruption on disk becomes a SnapshotStoreError on reading."""
    system = forced_chain()
    path = tmp_path / "s.h5"
    store = SnapshotStore.create(path, system, fields=("q",), scheme=Newmark(), dt=0.05, n_steps=20,
                                 checksums=checksums)
    writer = store.writer(chunk_steps=7)
    integrate(system, Newmark(), np.ones(system.n_dofs), np.zeros(system.n_dofs), 0.05, 20,
              consumers=[writer])
    good = store.read("000", "q")
    store.close()
    with h5py.File(path, "r") as f:  # where the second chunk of q lies in the file
        dataset = f["trajectories/000/q"]
        assert (dataset.fletcher32, f.attrs["checksums"]) == (checksums, checksums)
        info = dataset.id.get_chunk_info(1)
        offset = info.byte_offset + 8 * system.n_dofs + 3  # inside the chunk's second row
    with open(path, "r+b") as raw:
        raw.seek(offset)
        byte = raw.read(1)
        raw.seek(offset)
        raw.write(bytes([byte[0] ^ 0x10]))

    reopened = SnapshotStore.open(path)
    if checksums:
        with pytest.raises(SnapshotStoreError, match=r"trajectories/000/q.*checksum does not match"):
            reopened.read("000", "q")
        with pytest.raises(SnapshotStoreError, match=r"trajectories/000/q.*checksum does not match"):
            read_rows(path, "000", "q", 0, 21)
        assert np.array_equal(reopened.read("000", "q", 0, 7), good[:, :7])  # other chunks still read
    else:  # no checksum: the changed byte comes back as a wrong number, unnoticed
        changed = reopened.read("000", "q")
        assert np.count_nonzero(changed != good) == 1
    reopened.close()
