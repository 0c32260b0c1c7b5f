"""Teaching sessions that survive everything: exceptions, full disks, damaged files, read-only
readers, two writers, far observations (issue 15).

Every case checks the same things afterwards (:func:`goes_on`): the error was a torchcbl error
naming the file and the fix; memory equals disk (records, labels, the live model equals
``load_model``, which equals a fresh fit on ``load_demonstrations``); ``run()`` in the same
process continues; ``resume`` from disk continues; and no demonstration whose action reached
the env was lost (:class:`Witness`).
"""

from __future__ import annotations

import contextlib
import copy
import errno
import hashlib
import io
import json
import math
import os
import resource
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from _toy_envs import oracle, overlap_world, rare_regions_world
from test_session import TESTS, assert_model_is_fit_on_log, same_state

from torchcbl import ConfidentTeacher, GaussianMixtureSet, TeachingConfig
from torchcbl import session as S
from torchcbl.errors import (
    CorruptSessionError,
    EnvError,
    IncompatibleRunDirError,
    SessionLockedError,
    SessionWriteError,
    TeacherError,
    TeachingInterrupted,
)
from torchcbl.session import (
    load_config,
    load_corrections,
    load_demonstrations,
    load_labels,
    load_model,
    load_records,
    repair_journal,
)

# -- helpers ----------------------------------------------------------------------------------


class Witness(gym.Wrapper):
    """Notes every label the teacher gave and every action handed to the env, by step."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.ct: ConfidentTeacher | None = None
        self.taught: dict[int, int] = {}
        self.executed: dict[int, int] = {}
        self.fail: dict[int, BaseException | tuple] = {}  # env step call -> raise / return
        self.calls = 0

    def teacher(self, obs: np.ndarray, info: dict) -> int:
        a = self.env.unwrapped.optimal_action(obs)
        self.taught[self.ct.n_steps] = a
        return a

    def step(self, action: int):
        self.calls += 1
        self.executed[self.ct.n_steps] = int(action)
        out = self.env.step(action)
        bad = self.fail.pop(self.calls, None)
        if isinstance(bad, BaseException):
            raise bad
        return out if bad is None else bad(out)

    def lost(self, run: Path) -> list[int]:
        """Steps whose label was executed in the env but are not demonstrations on disk."""
        records = {r.step: r for r in load_records(run)}
        return [
            s
            for s, a in self.executed.items()
            if s in self.taught
            and self.taught[s] == a
            and (s not in records or records[s].teacher_action != a)
        ]


def session(
    run: Path, world=None, commit_every: int = 32, keep_checkpoints: int | None = 3, **cfg
) -> tuple[ConfidentTeacher, Witness]:
    env = Witness(world or rare_regions_world())
    ct = ConfidentTeacher(
        env,
        env.teacher,
        config=TeachingConfig(**{"max_new": 2, "accuracy_window": 10, **cfg}),
        run_dir=run,
        progress=False,
        commit_every=commit_every,
        keep_checkpoints=keep_checkpoints,
    )
    env.ct = ct
    return ct, env


def resume(run: Path, world=None, **kw) -> tuple[ConfidentTeacher, Witness]:
    env = Witness(world or rare_regions_world())
    ct = ConfidentTeacher.resume(run, env, env.teacher, progress=False, **kw)
    env.ct = ct
    return ct, env


def memory_equals_disk(ct: ConfidentTeacher, run: Path) -> None:
    assert load_records(run) == ct.records
    assert load_corrections(run) == ct.corrections
    x, y = load_labels(run)
    assert len(y) == ct.n_demonstrations
    ns = [r.n_demonstrations for r in ct.records]
    assert ns == sorted(ns) and all(b - a <= 1 for a, b in zip(ns, ns[1:], strict=False))
    assert same_state(load_model(run), ct.model)  # the live model is the one on disk
    assert_model_is_fit_on_log(load_model(run), run)  # which is a fresh fit on the log


def goes_on(
    ct: ConfidentTeacher, env: Witness, run: Path, world=rare_regions_world, **resume_kw
) -> None:
    """After a fault: memory == disk; run() continues; resume (given ``resume_kw``)
    continues; nothing lost."""
    memory_equals_disk(ct, run)
    n = ct.n_steps
    ct.run(max_steps=n + 12)
    assert [r.step for r in ct.records] == list(range(n + 12))
    memory_equals_disk(ct, run)
    assert env.lost(run) == []
    ct.close()
    back, env2 = resume(run, world(), **resume_kw)
    assert back.records == ct.records and same_state(back.model, ct.model)
    back.run(max_steps=back.n_steps + 12)
    memory_equals_disk(back, run)
    assert env2.lost(run) == [] and env.lost(run) == []
    back.close()


def files_of(run: Path) -> dict[str, tuple[int, str]]:
    """{relative path: (mtime_ns, sha256)} of every file under a run directory."""
    return {
        str(p.relative_to(run)): (p.stat().st_mtime_ns, hashlib.sha256(p.read_bytes()).hexdigest())
        for p in sorted(run.rglob("*"))
        if p.is_file()
    }


def crash(ct: ConfidentTeacher) -> None:
    """Leave the directory as a SIGKILL would: journal not committed, lock released."""
    ct._store._release()
    ct._store = None


# -- 1. memory never runs ahead of disk after an exception ------------------------------------


def test_ctrl_c_inside_env_step_on_a_demonstration(tmp_path):
    run = tmp_path / "run"
    ct, env = session(run)  # the non-interactive phase: every step is a demonstration
    ct.run(max_steps=5)
    env.fail[env.calls + 3] = KeyboardInterrupt()
    with pytest.raises(KeyboardInterrupt) as err:
        ct.run(max_steps=20)
    notes = " ".join(getattr(err.value, "__notes__", []))
    assert f"step 7 was logged as interrupted (episode cut) in {run}" in notes
    assert "call run() again" in notes
    last = ct.records[-1]
    assert last.step == 7 and last.is_demonstration and last.truncated
    assert last.info == {"torchcbl_interrupted": True} and last.reward is None
    goes_on(ct, env, run)


def test_ctrl_c_inside_env_step_later_in_confident_execution(tmp_path):
    run = tmp_path / "run"
    ct, env = session(run, noninteractive=False)
    ct.run(max_steps=40)
    env.fail[env.calls + 1] = KeyboardInterrupt()
    with pytest.raises(KeyboardInterrupt):
        ct.run(max_steps=60)
    assert ct.records[-1].info == {"torchcbl_interrupted": True}
    goes_on(ct, env, run)


@pytest.mark.parametrize("error", [KeyboardInterrupt(), ValueError("strategy bug")])
def test_an_error_in_the_strategy_after_a_durable_demonstration_keeps_it(tmp_path, error):
    """A strategy's observe_label raises (or Ctrl-C lands there) after the demonstration was
    written: the label is kept, the step is logged as interrupted without running its action,
    and the next steps neither reuse its number nor fail to save."""
    from torchcbl.strategies import ConfidentExecution

    class Flaky(ConfidentExecution):
        calls = 0

        def observe_label(self, *args, **kwargs):
            Flaky.calls += 1
            if Flaky.calls == 5:
                raise error
            return super().observe_label(*args, **kwargs)

    run = tmp_path / "run"
    env = Witness(rare_regions_world())
    ct = ConfidentTeacher(
        env,
        env.teacher,
        strategy=Flaky(),
        config=TeachingConfig(max_new=2, accuracy_window=10),
        run_dir=run,
        progress=False,
    )
    env.ct = ct
    with pytest.raises(type(error)):
        ct.run(max_steps=12)
    last = ct.records[-1]
    assert last.step == 4 and last.is_demonstration and last.truncated
    assert last.info == {"torchcbl_interrupted": True} and 4 not in env.executed
    assert ct.n_demonstrations == 5 and len(load_labels(run)[1]) == 5
    # a subclass keeping its parent's to_config is stored as custom: passed again to resume
    goes_on(ct, env, run, strategy=Flaky())


@pytest.mark.parametrize(
    "bad, match",
    [
        (lambda out: (*out[:4], ["not", "a dict"]), r"info \['not', 'a dict'\]; expected a dict"),
        (lambda out: (out[0], out[1], np.array([0, 1]), *out[3:]), "terminated=.*expected a bool"),
        (lambda out: (out[0], out[1], out[2], "yes", out[4]), "truncated='yes'.*expected a bool"),
        (lambda out: out[:3], "expected the gymnasium 5-tuple"),
        # numbers no float holds (an OverflowError escaped the step before 2026-11-26: the
        # demonstration stayed on disk only, and every later commit failed)
        (lambda out: (out[0], 10**400, *out[2:]), "non-finite reward"),
        (lambda out: ([10**400, 0.0], *out[1:]), "observation is not numeric"),
    ],
    ids=[
        "info-list",
        "terminated-array",
        "truncated-str",
        "short-tuple",
        "huge-reward",
        "huge-obs",
    ],
)
def test_malformed_env_output_is_an_env_error(tmp_path, bad, match):
    run = tmp_path / "run"
    ct, env = session(run)
    ct.run(max_steps=4)
    env.fail[env.calls + 2] = bad
    with pytest.raises(EnvError, match=match) as err:
        ct.run(max_steps=20)
    assert "call run() again" in str(err.value)
    assert ct.records[-1].truncated and "torchcbl_error" in ct.records[-1].info
    goes_on(ct, env, run)


# -- 2. disk full -----------------------------------------------------------------------------


def _failing_write(monkeypatch, which: str, *, short: bool = False):
    """Make the next journal write of kind ``which`` fail: "demo" (a demonstration before its
    action), "finish" (its outcome), "auto" (an autonomous step), "any"."""
    real = os.write
    state = {"armed": True, "hit": None}

    def write(fd, data):
        payload = json.loads(data.rpartition(b"\t")[0])
        kind = {"f": "finish", "c": "correction"}.get(payload[0])
        if kind is None:
            labelled = payload[1 + S._COLUMNS.index("teacher_action")] is not None
            kind = "demo" if labelled else "auto"
        if state["armed"] and which in (kind, "any"):
            state["armed"], state["hit"] = False, kind
            if short:  # the disk fills up mid-line: part of it reaches the file
                return real(fd, data[: len(data) // 2])
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, data)

    monkeypatch.setattr(S, "_write_fd", write)
    return state


@pytest.mark.parametrize("short", [False, True], ids=["enospc", "short-write"])
@pytest.mark.parametrize("which", ["demo", "finish", "auto"])
def test_journal_write_fails_disk_full(tmp_path, monkeypatch, which, short):
    run = tmp_path / "run"
    ct, env = session(run, noninteractive=which == "auto", commit_every=1000)
    ct.run(max_steps=30)
    size = (run / "steps.journal").stat().st_size
    state = _failing_write(monkeypatch, which, short=short)
    with pytest.raises(SessionWriteError) as err:
        ct.run(max_steps=80)
    assert state["hit"] == which
    msg = str(err.value)
    assert str(run / "steps.journal") in msg and "Free space" in msg and "run() again" in msg
    assert err.value.errno == errno.ENOSPC
    # nothing torn is left behind: every journal line is whole and checks out
    assert (run / "steps.journal").stat().st_size >= size
    assert S._scan_journal(run / "steps.journal").damaged == []
    if which == "finish":  # the demonstration was durable before its action: kept, cut
        assert ct.records[-1].is_demonstration and ct.records[-1].truncated
        assert ct.records[-1].info == {"torchcbl_interrupted": True}
    elif which == "demo":  # asked, not logged, so never executed: not in the session
        assert ct.n_steps in env.taught and ct.n_steps not in env.executed
    else:  # executed but not logged: not in the session, the episode is cut
        assert ct.n_steps in env.executed and ct._needs_reset
    monkeypatch.undo()
    goes_on(ct, env, run)


@pytest.mark.parametrize("short", [False, True], ids=["enospc", "short-write"])
def test_a_run_record_that_cannot_be_written_leaves_runs_jsonl_as_it_was(
    tmp_path, monkeypatch, short
):
    """A run() records where it begins in runs.jsonl before its first step; a write of
    that line that fails (the disk full: nothing written, or part of the line) raises
    SessionWriteError naming the file, takes no step, and leaves runs.jsonl byte for byte
    as it was (a part written is cut off); once writes go through the session goes on."""
    run = tmp_path / "run"
    ct, env = session(run)
    ct.run(max_steps=10)
    runs = run / "runs.jsonl"
    before = runs.read_bytes()
    real = os.write

    def write(fd, data):
        if os.readlink(f"/proc/self/fd/{fd}") == str(runs):
            if short:  # the disk fills up mid-line: part of it reaches the file
                return real(fd, data[: len(data) // 2])
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, data)

    monkeypatch.setattr(os, "write", write)
    with pytest.raises(SessionWriteError) as err:
        ct.run(max_steps=20)
    monkeypatch.undo()
    msg = str(err.value)
    assert f"writing {runs} failed" in msg and "recording the run() from step 10" in msg, msg
    assert "That run() took no step" in msg and err.value.errno == errno.ENOSPC, msg
    assert ct.n_steps == 10 and runs.read_bytes() == before
    goes_on(ct, env, run)
    assert [json.loads(line)["first_step"] for line in runs.read_text().splitlines()] == [
        0,
        10,
        22,
    ]


class FullDisk:
    """A connection proxy whose COMMITs fail like SQLite's on a full disk (SQLite rolls the
    transaction back itself), ``n`` times."""

    def __init__(self, db: sqlite3.Connection, n: int) -> None:
        self.db, self.n = db, n

    def execute(self, sql, *args):
        if sql == "COMMIT" and self.n > 0:
            self.n -= 1
            self.db.execute("ROLLBACK")
            raise sqlite3.OperationalError("database or disk is full")
        return self.db.execute(sql, *args)

    def __getattr__(self, name):
        return getattr(self.db, name)


def test_sqlite_commit_fails_disk_full_then_space_is_freed(tmp_path):
    run = tmp_path / "run"
    ct, env = session(run, commit_every=8)
    ct.run(max_steps=20)
    ct._store._db = FullDisk(ct._store._db, n=10**6)
    with pytest.raises(SessionWriteError) as err:  # the batched commits fail silently, the
        ct.run(max_steps=45)  # flush at the end of run() says so
    msg = str(err.value)
    assert str(run / "steps.sqlite") in msg and "Nothing is lost" in msg and "Free space" in msg
    assert ct.n_steps == 45  # every step was journalled: the session went on
    memory_equals_disk(ct, run)  # readers see the journal
    ct._store._db = ct._store._db.db  # space is freed
    goes_on(ct, env, run)


def test_a_commit_that_conflicts_with_the_log_is_not_called_a_full_disk(tmp_path):
    """A row already in steps.sqlite (here written by another process) makes every commit
    fail; the message must say so instead of asking the user to free space."""
    run = tmp_path / "run"
    ct, env = session(run, commit_every=8)
    ct.run(max_steps=10)  # steps 0-7 committed, 8-9 in the journal
    other = sqlite3.connect(run / "steps.sqlite")
    other.executescript(
        "CREATE TEMP TABLE t AS SELECT * FROM steps WHERE step = 0; UPDATE t SET step = 12;"
        "INSERT INTO steps SELECT * FROM t;"
    )
    other.close()
    with pytest.raises(SessionWriteError) as err:
        ct.run(max_steps=20)
    msg = str(err.value)
    assert "conflicts with one already in steps.sqlite" in msg and "not a full disk" in msg
    assert "Free space" not in msg
    assert ct.n_steps == 20  # every step was journalled: nothing was lost
    journal = (run / "steps.journal").read_text().splitlines()
    assert len(journal) >= 12  # steps 8-19 (and their outcome lines) wait there


def _mount(*args: str) -> bool:
    return subprocess.run(["mount", *args], capture_output=True).returncode == 0


@pytest.fixture
def small_disk(tmp_path):
    """A 1 MiB tmpfs (root only; skipped elsewhere)."""
    where = tmp_path / "disk"
    where.mkdir()
    if os.geteuid() != 0 or not _mount("-t", "tmpfs", "-o", "size=1m", "tmpfs", str(where)):
        pytest.skip("cannot mount a tmpfs here")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)


def _fill(where: Path, leave: int) -> Path:
    st = os.statvfs(where)
    filler = where / "filler"
    with open(filler, "wb") as f:
        f.write(b"\0" * max(st.f_bavail * st.f_frsize - leave, 0))
    return filler


@pytest.mark.parametrize("leave", [0, 4096, 12288, 40960])
def test_really_full_disk(small_disk, leave):
    """A real full disk (tmpfs): whatever write fails first (journal line, SQLite page, WAL,
    checkpoint), the error names the file and the fix, and once space is freed the same
    session and a resumed one go on with nothing lost."""
    run = small_disk / "run"
    ct, env = session(run, world=overlap_world(), max_new=1, commit_every=4)
    ct.run(max_steps=10)
    filler = _fill(small_disk, leave)
    with pytest.raises(SessionWriteError) as err:
        ct.run(max_steps=5000)
    msg = str(err.value)
    assert str(run) in msg and "Free space" in msg
    filler.unlink()
    goes_on(ct, env, run, world=overlap_world)


@contextlib.contextmanager
def file_size_limit(nbytes: int):
    """A full disk without root: a write past ``nbytes`` of a file fails with EFBIG
    (RLIMIT_FSIZE, its SIGXFSZ ignored), in this process, for the block."""
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, handler)


def test_a_session_that_cannot_start_on_a_full_disk_says_which_file(tmp_path):
    """On a full disk a new session's writer.lock gets no room for its note either; the note's
    write was buffered, so closing the lock file wrote it again and raised a bare
    ``OSError: [Errno 28] No space left on device`` that hid the SessionWriteError naming
    config.json and the fix (and, at the command line, was all the user was told)."""
    run = tmp_path / "run"
    env = rare_regions_world()
    with file_size_limit(0), pytest.raises(OSError) as err:
        ConfidentTeacher(env, oracle(env), run_dir=run, progress=False)
    assert type(err.value) is SessionWriteError, repr(err.value)
    assert str(run / "config.json") in str(err.value) and "free space" in str(err.value)
    assert not (run / "config.json").exists()
    ct = ConfidentTeacher(env, oracle(env), run_dir=run, progress=False)  # space freed
    ct.run(max_steps=3)
    ct.close()
    assert len(load_records(run)) == 3


def test_a_checkpoint_that_does_not_fit_on_the_disk_says_the_disk_is_full(tmp_path):
    """A checkpoint written on a full disk failed inside torch.save, whose error is its C++
    assertion: the user read "writing .../model-00000002.pt failed ([enforce fail at
    inline_container.cc:672] . unexpected pos 576 vs 534)", with errno 5 (EIO), and nothing
    saying the disk was full."""
    run = tmp_path / "run"
    ct, env = session(run)
    with file_size_limit(1000), pytest.raises(SessionWriteError) as err:  # a line fits
        ct.run(max_steps=5)
    msg = str(err.value)
    assert str(run / "checkpoints" / "model-00000002.pt") in msg, msg
    assert "(File too large)" in msg and "enforce fail" not in msg, msg
    assert err.value.errno == errno.EFBIG
    assert not list((run / "checkpoints").iterdir())  # no part of it is left
    goes_on(ct, env, run)


def test_a_refit_by_hand_whose_checkpoint_cannot_be_written_says_what_that_loses(tmp_path):
    """A refit by hand moves the refit schedule and only its checkpoint records it. That
    checkpoint failing to be written (a full disk), the error said "a missing checkpoint is
    refitted from the log on resume and by load_model" and to resume: but they rebuild the
    model on the regular schedule until the loop's next refit is saved (here on 5 labels where
    the model in memory stands on 7). It now says so, names the refit due next, and the
    session goes on from memory. Freeing space then left the stages from 7 to 11 on the
    regular schedule for good (at 11 on 10 labels where the loop stood on 7): the teacher now
    keeps the unsaved checkpoint and writes it at its next checkpoint save, so freeing space
    is enough, and the message says so (and that a process ending first loses it)."""
    run = tmp_path / "run"
    ct, env = session(run, max_new=5, noninteractive=False)
    ct.run(max_demonstrations=7)
    with file_size_limit(1000), pytest.raises(SessionWriteError) as err:  # a line fits
        ct.refit()
    msg = " ".join(str(err.value).split())
    assert str(run / "checkpoints" / "model-00000007.pt") in msg, msg
    assert "refit by hand" in msg and "next refit, due at 12 labels" in msg, msg
    assert "refitted from the log on resume" not in msg and "or resume" not in msg, msg
    assert "from 7 labels up to the loop's next refit" in msg, msg
    assert "writes it with its next checkpoint or at close()" in msg, msg
    assert "for good where the process ends before close()" in msg, msg
    assert int(ct.model.n_points_.sum()) == 7  # the refit itself happened
    assert int(load_model(run).n_points_.sum()) == 5  # what the message warns of
    live7 = copy.deepcopy(ct.model.state_dict())
    ct.run(max_demonstrations=12)  # space freed: the loop's refit at 12 is saved
    assert same_state(load_model(run), ct.model)
    ct.close()
    assert _same_payload(run / "checkpoints" / "model-00000007.pt", live7)
    assert _same(load_model(run, n_demonstrations=11), live7)  # the loop's model there


def test_an_unsaved_refit_by_hand_is_written_at_close_or_said_lost(tmp_path, monkeypatch):
    """The checkpoint of a refit by hand that a full disk refused is written when the
    teacher closes, where no refit came since (space freed); where the disk is still full
    then, close() warns that the stages from 7 labels are rebuilt on the regular schedule
    for good, and closes the session all the same."""
    for still_full in (False, True):
        run = tmp_path / f"run-{still_full}"
        ct, env = session(run, max_new=5, noninteractive=False)
        ct.run(max_demonstrations=7)
        with file_size_limit(1000), pytest.raises(SessionWriteError):
            ct.refit()
        live7 = copy.deepcopy(ct.model.state_dict())
        ct.run(max_demonstrations=9)
        hand = run / "checkpoints" / "model-00000007.pt"
        assert not hand.exists()
        if still_full:

            def full(path, data, tmp):
                raise OSError(errno.ENOSPC, "No space left on device")

            monkeypatch.setattr(S, "write_durably", full)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            ct.close()
        monkeypatch.undo()
        said = [str(w.message) for w in caught if str(hand) in str(w.message)]
        if still_full:
            assert len(said) == 1 and "for good" in said[0], said
            assert not hand.exists() and int(load_model(run).n_points_.sum()) == 5
        else:
            assert not said, said
            assert _same_payload(hand, live7) and _same(load_model(run), live7)
        back, _ = resume(run)  # the session closed either way
        back.close()


def _disk_full_for(monkeypatch, *names: str) -> None:
    """Make every write of a file named one of ``names`` fail as a full disk would
    (``write_durably`` raises ENOSPC); other writes go through."""
    real = S.write_durably

    def full(path, data, tmp):
        if path.name in names:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(path, data, tmp)

    monkeypatch.setattr(S, "write_durably", full)


def _two_unsaved_hand_refits(run: Path) -> ConfidentTeacher:
    """A session refitting every 5 labels whose refits by hand at 7 and at 8 a full disk
    refused, taught on to 9 labels (open)."""
    ct, env = session(run, max_new=5, noninteractive=False)
    for n in (7, 8):
        ct.run(max_demonstrations=n)
        with file_size_limit(1000), pytest.raises(SessionWriteError):
            ct.refit()
    ct.run(max_demonstrations=9)
    return ct


def test_close_writes_every_unsaved_refit_by_hand_with_warnings_as_errors(tmp_path, monkeypatch):
    """close() warned inside its loop over the unsaved refits by hand: with warnings as errors
    the first one that could not be written raised, and the later ones were never tried (the
    refit at 8 lost where the disk had room for it). Every one is tried, then the warning."""
    run = tmp_path / "run"
    ct = _two_unsaved_hand_refits(run)
    _disk_full_for(monkeypatch, "model-00000007.pt")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning, match="model-00000007.pt"):
            ct.close()
    monkeypatch.undo()
    checkpoints = run / "checkpoints"
    assert not (checkpoints / "model-00000007.pt").exists()
    assert (checkpoints / "model-00000008.pt").exists()
    back, _ = resume(run)  # the session closed all the same
    back.close()


@pytest.mark.parametrize("where", ["close", "next checkpoint"])
def test_a_ctrl_c_while_an_unsaved_refit_by_hand_is_written_again_says_so(
    tmp_path, monkeypatch, where
):
    """A Ctrl-C while the teacher wrote again a refit by hand's checkpoint that a full disk
    had refused (at close, or before the loop's next checkpoint) went out with no word of it:
    at close that checkpoint was lost for good, silently. A warning now names it and says
    what that leaves, and the Ctrl-C goes on."""
    run = tmp_path / "run"
    ct = _two_unsaved_hand_refits(run)

    def interrupted(path, data, tmp):
        raise KeyboardInterrupt

    monkeypatch.setattr(S, "write_durably", interrupted)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if where == "close":
            with pytest.raises(KeyboardInterrupt):
                ct.close()
        else:  # (the loop's own handler stops it there)
            with contextlib.suppress(KeyboardInterrupt):
                ct.run(max_demonstrations=13)  # the loop's refit: 5 labels after 8
    monkeypatch.undo()
    said = [" ".join(str(w.message).split()) for w in caught]
    for n in (7, 8):
        (one,) = [m for m in said if f"model-{n:08d}.pt" in m]
        assert "interrupted" in one, one
        if where == "close":
            assert "for good" in one, one
        else:
            assert "with its next checkpoint or at close()" in one, one
    if where != "close":
        ct.close()  # space and time enough: both written now
        assert (run / "checkpoints" / "model-00000007.pt").exists()
        assert (run / "checkpoints" / "model-00000008.pt").exists()


def test_a_ctrl_c_at_close_names_a_refused_refit_by_hand_once(tmp_path, monkeypatch):
    """A Ctrl-C while close() wrote the refit by hand at 8 again, after the disk had refused
    the one at 7, warned of 7 twice: refused, then "interrupted" too (the handler walked
    every entry still pending, the failed ones included). 7 is said refused, 8 interrupted."""
    run = tmp_path / "run"
    ct = _two_unsaved_hand_refits(run)

    def full_then_ctrl_c(path, data, tmp):
        if "00000007" in path.name:
            raise OSError(errno.ENOSPC, "No space left on device")
        raise KeyboardInterrupt

    monkeypatch.setattr(S, "write_durably", full_then_ctrl_c)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(KeyboardInterrupt):
            ct.close()
    monkeypatch.undo()
    said = " ".join(" ".join(str(w.message).split()) for w in caught)
    seven = str(run / "checkpoints" / "model-00000007.pt")
    eight = str(run / "checkpoints" / "model-00000008.pt")
    assert said.count(seven) == 1 and f"{seven} failed (No space left on device)" in said, said
    assert said.count(eight) == 1 and f"{eight} was interrupted" in said, said


def test_an_unsaved_refit_by_hand_lost_at_close_names_where_its_stages_end(tmp_path, monkeypatch):
    """close() could not write a refit by hand's checkpoint (7 labels) and said the stages
    from 7 are rebuilt on the regular schedule up to the loop's refit "due at 12 labels";
    a later refit by hand at 9 was saved, so they end there: it says so."""
    run = tmp_path / "run"
    ct, env = session(run, max_new=5, noninteractive=False)
    ct.run(max_demonstrations=7)
    with file_size_limit(1000), pytest.raises(SessionWriteError):
        ct.refit()
    _disk_full_for(monkeypatch, "model-00000007.pt")
    ct.run(max_demonstrations=9)
    assert ct.refit()  # at 9: saved (7 tried again first, refused again)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ct.close()
    monkeypatch.undo()
    (said,) = [" ".join(str(w.message).split()) for w in caught if "00000007" in str(w.message)]
    assert "due at 12" not in said, said
    assert "from 7 labels up to the refit saved at 9 labels" in said, said
    assert int(load_model(run, n_demonstrations=8).n_points_.sum()) == 5  # what it says
    assert int(load_model(run, n_demonstrations=9).n_points_.sum()) == 9


@pytest.mark.parametrize("eight", ["written", "lost"])
def test_a_refit_by_hand_lost_at_close_is_worded_after_every_one_was_tried(
    tmp_path, monkeypatch, eight
):
    """close() worded a lost refit by hand's warning as soon as its write failed, before the
    later ones were tried: with 7 refused and 8 then written, 7's said its stages end at the
    loop's refit "due at 12 labels" (they end at 8, whose model load_model gives); with 8 lost
    too, "due at 12" where the refit at 8 moved the loop's next refit to 13."""
    run = tmp_path / "run"
    ct = _two_unsaved_hand_refits(run)
    refused = ("model-00000007.pt",)
    refused += () if eight == "written" else ("model-00000008.pt",)
    _disk_full_for(monkeypatch, *refused)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ct.close()
    monkeypatch.undo()
    said = " ".join(" ".join(str(w.message).split()) for w in caught)
    assert "due at 12" not in said, said
    if eight == "written":
        assert "from 7 labels up to the refit saved at 8 labels" in said, said
        assert int(load_model(run, n_demonstrations=8).n_points_.sum()) == 8  # what it says
    else:
        assert "from 7 labels up to the loop's next refit, due at 13 labels" in said, said
        assert "from 8 labels up to the loop's next refit, due at 13 labels" in said, said


def test_every_refit_by_hand_lost_at_close_is_named_with_warnings_as_errors(tmp_path, monkeypatch):
    """close() gave one warning per lost refit by hand: with warnings as errors only the
    first was raised, and the refit at 8, lost as well, went with no word. One warning now
    names every lost checkpoint and where each one's stages end."""
    run = tmp_path / "run"
    ct = _two_unsaved_hand_refits(run)

    def full(path, data, tmp):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(S, "write_durably", full)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning) as err:
            ct.close()
    monkeypatch.undo()
    said = " ".join(str(err.value).split())
    for n in (7, 8):
        assert str(run / "checkpoints" / f"model-{n:08d}.pt") in said, said
        assert f"from {n} labels up to the loop's next refit, due at 13 labels" in said, said
    back, _ = resume(run)  # the session closed all the same
    back.close()


def test_a_refused_checkpoint_s_error_holds_no_copy_of_the_model(tmp_path):
    """A checkpoint a full disk refused raised its SessionWriteError with the serialised
    bytes, the payload and the state still alive in the failed frame: a caller keeping the
    error (or its traceback, as a REPL does) kept the model's size over again. The OSError
    it is raised from kept them too, through its own traceback (write_durably's ``data``):
    no frame reachable from the error, its causes and contexts included, holds them."""
    run = tmp_path / "run"
    ct, env = session(run, max_new=5, noninteractive=False)
    ct.run(max_demonstrations=7)
    with file_size_limit(1000), pytest.raises(SessionWriteError) as err:
        ct.refit()
    held = []
    chain, seen = [err.value], set()
    while chain:
        exc = chain.pop()
        if exc is None or id(exc) in seen:
            continue
        seen.add(id(exc))
        chain += [exc.__cause__, exc.__context__]
        tb = exc.__traceback__
        while tb is not None:
            for name, value in tb.tb_frame.f_locals.items():
                if (
                    isinstance(value, io.BytesIO)
                    or (isinstance(value, (bytes, bytearray, memoryview)) and len(value) > 500)
                    or (isinstance(value, dict) and "state_dict" in value)
                ):
                    held.append((type(exc).__name__, tb.tb_frame.f_code.co_name, name))
            tb = tb.tb_next
    assert isinstance(err.value.__cause__, OSError)  # the cause is kept, its errno said
    assert not held, held
    ct.close()


# -- 3. readers never write -------------------------------------------------------------------


def _closed_session(run: Path, **cfg) -> None:
    ct, _ = session(run, **cfg)
    ct.run(max_steps=60)
    ct.close()


def _read_everything(run: Path):
    return (
        load_records(run),
        load_corrections(run),
        load_demonstrations(run),
        load_model(run).state_dict(),
    )


def test_readers_open_the_log_read_only_and_change_nothing(tmp_path, monkeypatch):
    run = tmp_path / "run"
    _closed_session(run)
    for p in run.rglob("*"):  # as read-only as root can make it
        p.chmod(0o444 if p.is_file() else 0o555)
    run.chmod(0o555)
    opened = []
    real = sqlite3.connect

    def connect(database, *args, **kw):
        opened.append(str(database))
        return real(database, *args, **kw)

    monkeypatch.setattr(S.sqlite3, "connect", connect)
    before = files_of(run)
    records, *_ = _read_everything(run)
    assert files_of(run) == before  # same files, bytes and mtimes; no -wal / -shm created
    assert opened and all("immutable=1" in o or "mode=ro" in o for o in opened)
    assert len(records) == 60


def test_a_writer_closing_while_a_reader_reads_leaves_no_wal_behind(tmp_path, monkeypatch):
    """A reader (mode=ro, as the readers open a session whose writer runs) in the middle of a
    read as the writer closed kept SQLite from removing the -wal and -shm, and no read-only
    connection removes them: the cleanly closed session kept both for good, looked like one
    whose writer was killed, and could no longer be read where its -shm cannot be written. The
    writer now waits for the read to end and removes them."""
    import threading

    monkeypatch.setattr(S, "_WAL_CLOSE_WAIT_S", 60.0)  # a loaded machine's reader may be slow
    run = tmp_path / "run"
    ct, _ = session(run, commit_every=10**6)
    ct.run(max_steps=40)
    ct.flush()  # the steps are in the -wal
    assert (run / "steps.sqlite-wal").exists()
    reading, rows = threading.Event(), []

    def reader() -> None:
        db = sqlite3.connect(f"{(run / 'steps.sqlite').resolve().as_uri()}?mode=ro", uri=True)
        try:
            db.execute("BEGIN")
            rows.append(db.execute("SELECT COUNT(*) FROM steps").fetchone()[0])
            reading.set()
            time.sleep(0.3)  # still reading as the writer closes
        finally:
            db.close()

    thread = threading.Thread(target=reader)
    thread.start()
    assert reading.wait(30)
    ct.close()
    thread.join()
    assert rows == [40]
    assert not (run / "steps.sqlite-wal").exists() and not (run / "steps.sqlite-shm").exists()
    assert load_records(run) == ct.records


def test_readers_on_a_read_only_mount(tmp_path):
    src, ro = tmp_path / "src", tmp_path / "ro"
    src.mkdir()
    ro.mkdir()
    _closed_session(src / "clean")
    ct, _ = session(src / "killed", commit_every=10**6)
    ct.run(max_steps=40)  # committed into the -wal, the writer still holds it open
    assert (src / "killed" / "steps.sqlite-wal").stat().st_size > 0
    expected = {"clean": load_records(src / "clean"), "killed": ct.records}
    crash_db = ct._store._db  # keep the WAL open (a killed writer's files stay)
    if os.geteuid() != 0 or not _mount("--bind", str(src), str(ro)):
        pytest.skip("cannot bind-mount here")
    try:
        if not _mount("-o", "remount,bind,ro", str(ro)):
            pytest.skip("cannot remount read-only here")
        with pytest.raises(OSError):
            (ro / "probe").write_text("x")
        for name in ("clean", "killed"):
            assert load_records(ro / name) == expected[name]
            x, y = load_demonstrations(ro / name)
            assert len(y) == sum(r.is_demonstration for r in expected[name])
            assert_model_is_fit_on_log(load_model(ro / name), ro / name)
        with pytest.raises(SessionWriteError, match="write access"):
            ConfidentTeacher.resume(
                ro / "clean", rare_regions_world(), oracle(rare_regions_world())
            )
    finally:
        subprocess.run(["umount", "-l", str(ro)], capture_output=True)
        crash_db.close()


_READ_AS_ANOTHER_USER = """
import json, os, sys
from torchcbl.session import load_records
if os.geteuid() == 0:  # root reads everything: read as nobody, as a colleague would
    # first read the readable session (the last) as root, so every module the readers import
    # lazily is loaded while the checkout may still be read (it may lie where nobody cannot)
    load_records(sys.argv[-1])
    os.setgid(65534)
    os.setuid(65534)
out = {}
for run in sys.argv[1:]:
    try:
        out[run] = ["ok", len(load_records(run))]
    except Exception as exc:
        out[run] = [type(exc).__name__, str(exc)]
print(json.dumps(out))
"""


def test_a_session_this_user_may_not_read_is_said_to_be_that(tmp_path):
    """Another user's session whose files (or directory) this user may not read: each reader
    names the file and says it is a permission, not a damaged config ('restore it from a
    backup'), a -wal that needs write access (there was none) or a missing config."""
    import tempfile

    base = Path(tempfile.mkdtemp(prefix="torchcbl-perm-"))  # pytest's tmp is private to root
    runs = {name: base / name for name in ("config", "log", "wal", "journal", "dir", "fine")}
    try:
        for name in ("config", "log", "dir", "fine"):
            _closed_session(runs[name])
        live = []
        for name in ("wal", "journal"):  # a writer runs: a -wal, and steps in the journal
            ct, _ = session(runs[name], commit_every=10**6)
            ct.run(max_steps=40)
            live.append(ct)
        assert (runs["wal"] / "steps.sqlite-wal").stat().st_size > 0
        subprocess.run(["chmod", "-R", "a+rX", str(base)], check=True)
        denied = {
            "config": runs["config"] / "config.json",
            "log": runs["log"] / "steps.sqlite",
            "wal": runs["wal"] / "steps.sqlite-wal",
            "journal": runs["journal"] / "steps.journal",
            "dir": runs["dir"],
        }
        for p in denied.values():
            p.chmod(0)
        env = {**os.environ, "PYTHONPATH": str(TESTS.parent)}
        proc = subprocess.run(
            [sys.executable, "-c", _READ_AS_ANOTHER_USER, *map(str, runs.values())],
            capture_output=True,
            text=True,
            cwd=base,
            env=env,
            timeout=120,
        )
        assert proc.returncode == 0, proc.stderr
        got = json.loads(proc.stdout)
        assert got[str(runs["fine"])] == ["ok", 60]  # a readable session reads
        for name, path in denied.items():
            kind, msg = got[str(runs[name])]
            named = path / "config.json" if name == "dir" else path
            assert kind == "IncompatibleRunDirError", (name, msg)
            assert msg.startswith(f"{named} cannot be read by this user (permission denied)")
            assert "chmod -R a+rX" in msg and "changed nothing" in msg
            assert "backup" not in msg and "holds commits" not in msg and "missing" not in msg
        for ct in live:
            ct.close()
    finally:
        for p in (base, *base.iterdir()):
            p.chmod(0o755)
        shutil.rmtree(base)


_FS_ERRORS = [errno.EIO, errno.ENOTDIR]  # a failing disk; checkpoints/ replaced by a file


def _without_journal(run: Path) -> None:
    """A closed session of 20 steps without its journal and writers file: read as possibly
    left by a creation killed before its log was whole, which its ``checkpoints/`` tells."""
    ct, _ = session(run)
    ct.run(max_steps=20)
    ct.close()
    for name in ("steps.journal", "writers.jsonl"):
        (run / name).unlink()


def _failing_listing(monkeypatch, folder: Path, code: int) -> None:
    """Listing ``folder`` fails as the file system fails it (``code``)."""
    real_iterdir = Path.iterdir

    def iterdir(self: Path):
        if self == folder:
            raise OSError(code, os.strerror(code), str(self))
        return real_iterdir(self)

    monkeypatch.setattr(Path, "iterdir", iterdir)


@pytest.mark.parametrize("code", _FS_ERRORS, ids=errno.errorcode.get)
def test_a_checkpoints_folder_the_file_system_fails_to_list_is_said_to_be_that(
    tmp_path, monkeypatch, code
):
    """A session without journal and writers file, whose ``checkpoints/`` the readers list to
    tell it from a killed creation, where the file system fails that listing (an I/O error;
    not a directory: replaced by a file meanwhile): every reader and resume let the bare
    OSError through (the command line: exit 1, no word of what to do). Each is now the store's
    IncompatibleRunDirError naming the folder and the error, as a permission is, and nothing
    in the session is renamed, deleted or written."""
    run = tmp_path / "run"
    _without_journal(run)
    before = files_of(run)
    _failing_listing(monkeypatch, run / "checkpoints", code)
    readers = (
        load_records,
        load_corrections,
        load_labels,
        load_demonstrations,
        load_model,
        S.load_policy,
        S.describe,
        repair_journal,
        resume,
    )
    for read in readers:
        with pytest.raises(IncompatibleRunDirError) as info:
            read(run)
        msg = str(info.value)
        assert msg.startswith(f"{run / 'checkpoints'} cannot be read: {os.strerror(code)}"), msg
        assert "changed nothing" in msg, msg
    monkeypatch.undo()
    assert files_of(run) == before
    assert len(load_records(run)) == 20  # the session is whole once the folder reads again


def test_a_checkpoints_folder_that_fails_to_list_in_a_session_with_its_journal(
    tmp_path, monkeypatch
):
    """The same failing ``checkpoints/`` in a closed session (journal and writers file there,
    so the readers of the log do not list it): load_model, load_policy, latest_checkpoint and
    resume, which look for the checkpoint to load, let the bare OSError through (resume after
    it had opened the session for writing); they now say the store's IncompatibleRunDirError,
    as describe did, and resume says it before it opens the session: no file is touched. The
    readers of the log read on."""
    run = tmp_path / "run"
    ct, _ = session(run)
    ct.run(max_steps=20)
    ct.close()
    before = files_of(run)
    _failing_listing(monkeypatch, run / "checkpoints", errno.EIO)
    for read in (load_model, S.load_policy, S.latest_checkpoint, S.describe, resume):
        with pytest.raises(IncompatibleRunDirError) as info:
            read(run)
        msg = str(info.value)
        assert msg.startswith(f"{run / 'checkpoints'} cannot be read: {os.strerror(errno.EIO)}")
        assert "changed nothing" in msg, msg
    assert len(load_records(run)) == 20
    monkeypatch.undo()
    assert files_of(run) == before  # resume refused before it opened the session for writing


def test_a_new_session_whose_checkpoints_folder_fails_to_list_is_said_to_be_that(
    tmp_path, monkeypatch
):
    """A new session in a folder holding an empty checkpoints/ (what a start that failed may
    leave) lists it to find another session's checkpoints; where the file system failed that
    listing (an I/O error) creating the teacher let the bare OSError through. It is the
    store's IncompatibleRunDirError naming the folder and the error, and no session is made."""
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    _failing_listing(monkeypatch, run / "checkpoints", errno.EIO)
    with pytest.raises(IncompatibleRunDirError) as info:
        session(run)
    msg = str(info.value)
    assert msg.startswith(f"{run / 'checkpoints'} cannot be read: {os.strerror(errno.EIO)}"), msg
    monkeypatch.undo()
    assert not (run / "config.json").exists() and not (run / "steps.sqlite").exists()
    ct, _ = session(run)  # the folder reads again: the session starts there
    ct.close()


# -- 4. damaged files -------------------------------------------------------------------------


def _journalled(run: Path, steps: int = 40, **cfg) -> tuple[ConfidentTeacher, Witness]:
    """A session whose last ``steps`` steps are only in the journal, writer gone (killed)."""
    ct, env = session(run, **cfg)
    ct.run(max_steps=20)
    ct._store.commit_every = 10**6
    for _ in range(steps):
        ct.step()
    crash(ct)
    return ct, env


def _flip(path: Path, offset: int) -> None:
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x20
    path.write_bytes(bytes(data))


def test_damaged_first_journal_line_is_reported_and_every_byte_kept(tmp_path):
    run = tmp_path / "run"
    ct, env = _journalled(run)
    journal = run / "steps.journal"
    _flip(journal, 5)
    damaged = journal.read_bytes()
    n_lines = damaged.count(b"\n")
    for read in (load_records, load_model, load_demonstrations):
        with pytest.raises(CorruptSessionError) as err:
            read(run)
        msg = str(err.value)
        assert f"{journal}: line 1 (byte 0) is damaged" in msg
        assert f"{n_lines - 1} valid lines follow it" in msg and "repair_journal" in msg
    with pytest.raises(CorruptSessionError, match="line 1"):
        resume(run)
    assert journal.read_bytes() == damaged  # resume refused and kept every byte
    report = repair_journal(run)
    assert (run / "steps.journal.damaged").read_bytes() == damaged
    assert "kept 0 valid lines" in report and "steps.journal.damaged" in report
    # The first uncommitted step is lost with its line; the later ones would leave a hole, so
    # they stay in the copy only. The committed prefix goes on.
    back, env2 = resume(run)
    assert back.records == ct.records[:20]
    goes_on(back, env2, run)


def test_damaged_outcome_line_keeps_every_later_line(tmp_path):
    run = tmp_path / "run"
    ct, env = _journalled(run)
    journal = run / "steps.journal"
    lines = journal.read_bytes().split(b"\n")
    at = next(i for i, line in enumerate(lines) if line.startswith(b'["f"'))
    step = json.loads(lines[at].rpartition(b"\t")[0])[-1]
    _flip(journal, sum(len(line) + 1 for line in lines[:at]) + 8)
    with pytest.raises(CorruptSessionError, match=f"line {at + 1} "):
        load_records(run)
    repair_journal(run)
    back, env2 = resume(run)
    # every step is kept; the one whose outcome line was damaged reads as interrupted
    assert [r.step for r in back.records] == [r.step for r in ct.records]
    assert back.records[step].truncated and back.records[step].reward is None
    assert [r.teacher_action for r in back.records] == [r.teacher_action for r in ct.records]
    assert env.lost(run) == []
    goes_on(back, env2, run)


def test_journal_line_changed_into_another_valid_step_fails_its_checksum(tmp_path):
    """A journal line whose content changed but stays valid JSON of the right shape (one
    action digit of a step, here its model_action: a record as valid as the one written) is
    caught by its CRC-32 alone: the readers and resume refuse it as damaged, naming the line
    and the checksum, and change nothing."""
    run = tmp_path / "run"
    _journalled(run, steps=10)
    journal = run / "steps.journal"
    data = journal.read_bytes()
    lines = data.split(b"\n")
    at, entry = next(
        (i, json.loads(line.rpartition(b"\t")[0]))
        for i, line in enumerate(lines)
        if line.startswith(b'["s"') and line.rpartition(b"\t")[0].endswith(b',"teacher"]')
    )
    # ["s", step, episode, "observation hex", model_action, ...]: the 4th comma precedes it
    head = lines[at].split(b",", 4)
    assert int(head[4].split(b",", 1)[0]) == entry[4] in (0, 1, 2)
    changed = b"%d" % ((entry[4] + 1) % 3)  # another action of the 3: a valid record
    head[4] = changed + head[4][1:]
    lines[at] = b",".join(head)
    journal.write_bytes(b"\n".join(lines))
    json.loads(lines[at].rpartition(b"\t")[0])  # still valid JSON
    damaged = journal.read_bytes()
    offset = sum(len(line) + 1 for line in lines[:at])
    said = rf"line {at + 1} \(byte {offset}\) is damaged: its checksum does not match"
    for read in (load_records, load_demonstrations, load_model):
        with pytest.raises(CorruptSessionError, match=said):
            read(run)
    with pytest.raises(CorruptSessionError, match=said):
        resume(run)
    assert journal.read_bytes() == damaged  # every byte kept


def test_journal_line_of_valid_json_but_the_wrong_shape(tmp_path):
    run = tmp_path / "run"
    ct, env = _journalled(run, steps=10)
    journal = run / "steps.journal"
    payload = b'["s",3]'
    with open(journal, "ab") as f:  # a well-formed, checksummed line of the wrong shape
        f.write(b"%s\t%08x\n" % (payload, S._crc32(payload)))
    n = journal.read_bytes().count(b"\n")
    with pytest.raises(CorruptSessionError, match=f"line {n} .*wrong shape"):
        load_records(run)
    repair_journal(run)
    back, env2 = resume(run)
    assert back.records == ct.records  # every real line was kept
    goes_on(back, env2, run)


@pytest.mark.parametrize(
    ("payload", "says"),
    [
        (b'["c",true,1]', r"its step and action \[True, 1\] are not ints >= 0"),
        (b'["f",1.0,0,0,"{}",true]', r"its step True is not an int >= 0"),
    ],
    ids=["correction", "outcome"],
)
def test_journal_line_whose_step_is_true_is_damaged(tmp_path, payload, says):
    """JSON's true is no step (Python reads it as 1): a checksummed correction or outcome line
    giving its step as true is a damaged line, named, not a correction or an outcome of step
    1; repair_journal drops it and every real line is kept."""
    run = tmp_path / "run"
    ct, env = _journalled(run, steps=10)
    journal = run / "steps.journal"
    with open(journal, "ab") as f:
        f.write(b"%s\t%08x\n" % (payload, S._crc32(payload)))
    n = journal.read_bytes().count(b"\n")
    with pytest.raises(CorruptSessionError, match=f"line {n} .*damaged: {says}"):
        load_records(run)
    repair_journal(run)
    assert load_records(run) == ct.records and load_corrections(run) == ct.corrections


def test_stale_checkpoint_is_not_loaded(tmp_path):
    run, other = tmp_path / "run", tmp_path / "other"
    _closed_session(run)
    # a different log of the same size (every checkpoint kept: one of the same count)
    _closed_session(other, keep_checkpoints=None, target_accuracy=None)
    last = max((run / "checkpoints").glob("model-*.pt"))
    assert (other / "checkpoints" / last.name).exists()
    shutil.copy(other / "checkpoints" / last.name, last)  # the log no longer matches it
    stale_bytes = last.read_bytes()
    assert_model_is_fit_on_log(load_model(run), run)
    back, env = resume(run)
    assert_model_is_fit_on_log(back.model, run)
    assert (run / "checkpoints" / (last.name + ".stale")).read_bytes() == stale_bytes
    goes_on(back, env, run)


@pytest.mark.parametrize("damage", ["empty", "cut", "garbage"])
def test_damaged_checkpoint_is_refitted_from_the_log(tmp_path, damage):
    run = tmp_path / "run"
    _closed_session(run)
    last = max((run / "checkpoints").glob("model-*.pt"))
    data = last.read_bytes()
    last.write_bytes({"empty": b"", "cut": data[: len(data) // 2], "garbage": b"x" * 100}[damage])
    assert_model_is_fit_on_log(load_model(run), run)
    back, env = resume(run)
    assert_model_is_fit_on_log(back.model, run)
    assert (run / "checkpoints" / (last.name + ".damaged")).exists()
    goes_on(back, env, run)


def _hand_refit_session(
    run: Path,
    refit: str,
    keep: int | None = 3,
    upto: int = 9,
    live: dict[int, dict[str, torch.Tensor]] | None = None,
    backup: Path | None = None,
):
    """A session refitting every 5 labels, refitted by hand at 7 (off that schedule) and
    taught on to ``upto`` labels (9: its model stands on the hand refit), keeping ``keep``
    checkpoints; with ``backup``, closed at 5 labels, copied there and resumed. Returns the
    live model and ``live`` (made where not given): {labels: the live model's state after
    each refit, 0: unfitted}."""
    live = {} if live is None else live

    def on_refit(m: torch.nn.Module, n: int) -> None:
        live[n] = copy.deepcopy(m.state_dict())

    env = rare_regions_world()
    ct = ConfidentTeacher(
        env,
        oracle(env),
        config=TeachingConfig(noninteractive=False, max_new=5, refit=refit),
        run_dir=run,
        progress=False,
        keep_checkpoints=keep,
        on_refit=on_refit,
    )
    live[0] = copy.deepcopy(ct.model.state_dict())  # unfitted
    if backup is not None:
        ct.run(max_demonstrations=5)
        ct.close()
        shutil.copytree(run, backup)
        env = rare_regions_world()
        ct = ConfidentTeacher.resume(run, env, oracle(env), progress=False, on_refit=on_refit)
    ct.run(max_demonstrations=7)
    assert ct.refit()  # by hand, at 7: the loop's next refit is at 12, not 10
    ct.run(max_demonstrations=upto)
    ct.close()
    assert sorted(live) == [0, 5, 7, *range(12, upto + 1, 5)]
    return ct.model, live


def _same(model: torch.nn.Module, state: dict[str, torch.Tensor]) -> bool:
    own = model.state_dict()
    return own.keys() == state.keys() and all(torch.equal(own[k], state[k]) for k in own)


@pytest.mark.parametrize("damage", ["cut", "empty"])
@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_a_damaged_checkpoint_of_a_refit_by_hand_still_says_where_the_schedule_went(
    tmp_path, refit, damage
):
    """A refit by hand moves the refit schedule, and its checkpoint alone records it. That
    checkpoint damaged (cut short, emptied), load_model, load_models and resume rebuilt the
    model on the regular schedule from the checkpoint below it (on 5 labels, the live one
    stood on 7), silently. The damaged file's name still records the refit: the model is
    rebuilt on it, bit for bit, before and after resume set the file aside as .damaged, and
    the resumed loop refits next where the live one would have (at 12)."""
    run = tmp_path / "run"
    model, live = _hand_refit_session(run, refit)
    hand = run / "checkpoints" / "model-00000007.pt"
    data = hand.read_bytes()
    hand.write_bytes(data[: len(data) // 2] if damage == "cut" else b"")
    assert _same(load_model(run), live[7])
    for n, staged in S.load_models(run, range(10)):
        assert _same(staged, live[max(r for r in live if r <= n)]), n
    (note,) = S.describe(run).notes
    assert "model-00000007.pt" in note and "records a refit on 7 labels" in note, note
    back, env = resume(run)
    assert _same(back.model, live[7]) and same_state(back.model, model)
    assert (run / "checkpoints" / "model-00000007.pt.damaged").exists()
    assert _same(load_model(run), live[7])  # the model rebuilt on 7, written in its place
    back.run(max_demonstrations=11)
    assert _same(back.model, live[7])  # no refit at 10
    back.run(max_demonstrations=12)
    assert int(back.model.n_points_.sum()) == 12
    back.close()


@pytest.mark.parametrize("full_disk", [False, True])
@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_a_resume_past_a_damaged_refit_by_hand_writes_its_model_in_its_place(
    tmp_path, monkeypatch, refit, full_disk
):
    """A refit by hand at 7 (max_new=5), taught on to 13: the loop's refit at 12 never saved
    (killed between logging and saving) and the checkpoint of 7 damaged. Resume rebuilt the
    model on 12 and set the damaged file aside, whose .damaged name was then the only record
    of the refit at 7. It now writes the model rebuilt on 7 labels in its place, so a real
    checkpoint records the refit and a .damaged name need record nothing; where that write
    fails (a full disk), the damaged file stays under its name, which still records it,
    with a warning. Either way every stage reads as the loop had it."""
    run = tmp_path / "run"
    _, live = _hand_refit_session(run, refit, upto=13)
    (run / "checkpoints" / "model-00000012.pt").unlink()  # never saved
    hand = run / "checkpoints" / "model-00000007.pt"
    data = hand.read_bytes()[:100]
    hand.write_bytes(data)
    real = torch.save

    def full(obj, f, *args, **kw):
        if isinstance(obj, dict) and "n_demonstrations" in obj:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(obj, f, *args, **kw)

    if full_disk:
        monkeypatch.setattr(S.torch, "save", full)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            back, env = resume(run)
        monkeypatch.setattr(S.torch, "save", real)
        (said,) = [str(w.message) for w in caught if "model-00000007.pt failed" in str(w.message)]
        # not "a missing checkpoint is refitted": the damaged file stayed, recording the refit
        assert "missing" not in said, said
        assert (
            "The damaged model-00000007.pt stays under its name, which still records the refit "
            "on 7 labels: resume and load_model rebuild that model from the log" in said
        ), said
        assert said.endswith("then resume again to have the model written in its place."), said
        assert hand.read_bytes() == data and not hand.with_name(hand.name + ".damaged").exists()
    else:
        back, env = resume(run)
        assert hand.with_name(hand.name + ".damaged").read_bytes() == data
        assert _same_payload(hand, live[7])
    assert _same(back.model, live[12])
    for n, staged in S.load_models(run, range(14)):
        stood = live[max(r for r in live if r <= n)]
        assert _same(staged, stood), n
        assert _same(load_model(run, n_demonstrations=n), stood), n
    back.run(max_demonstrations=17)
    assert int(back.model.n_points_.sum()) == 17  # the loop's next refit, on 7's schedule
    back.close()


@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_a_resume_interrupted_while_it_rebuilds_a_damaged_refit_by_hand_keeps_its_record(
    tmp_path, monkeypatch, refit
):
    """A refit by hand at 7 (max_new=5) whose checkpoint is damaged: its name alone records
    the refit. Resume renamed the file .damaged first and wrote the model rebuilt on 7 labels
    under the name only after its refits, so a Ctrl-C (or a kill, an out-of-memory) in
    between left nothing recording the refit: load_model, and every later resume, rebuilt
    on 5 labels where the live loop stood on 7; and a reader meanwhile read 5 too. The name
    now stays in place until the rebuilt model replaces it (the damaged bytes copied to
    .damaged first): here the refit is interrupted, and a reader during it, load_model after
    it and the next resume all stand on 7, which then writes the model in its place."""
    run = tmp_path / "run"
    _, live = _hand_refit_session(run, refit)
    hand = run / "checkpoints" / "model-00000007.pt"
    data = hand.read_bytes()[:100]
    hand.write_bytes(data)
    read = []

    def interrupted(self, *args, **kw):
        monkeypatch.undo()  # the reader below fits as it would
        read.append(load_model(run))  # another process reading while the resume refits
        raise KeyboardInterrupt

    monkeypatch.setattr(GaussianMixtureSet, "fit", interrupted)
    monkeypatch.setattr(GaussianMixtureSet, "refit", interrupted)
    with pytest.raises(KeyboardInterrupt):
        resume(run)
    assert len(read) == 1 and _same(read[0], live[7])
    assert hand.read_bytes() == data  # still in place, still recording the refit
    assert _same(load_model(run), live[7])
    back, _ = resume(run)
    assert _same(back.model, live[7])
    back.close()
    assert _same_payload(hand, live[7])  # the rebuilt model in its place
    assert hand.with_name(hand.name + ".damaged").read_bytes() == data  # every byte kept


@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_resumes_interrupted_at_the_write_back_keep_one_copy_of_the_damaged_bytes(
    tmp_path, monkeypatch, refit
):
    """A resume interrupted after it kept a damaged refit by hand's bytes as .damaged and
    before it wrote the rebuilt model over the name left the copy; each retry made another,
    .damaged-1, -2, ..., of the same bytes. A copy holding the same bytes is used again: two
    interrupted resumes and a third that completes leave one .damaged, as describe says.
    A .damaged of other bytes (another file's, put there by hand) is kept, and describe and
    resume name the next free one."""
    run = tmp_path / "run"
    _, live = _hand_refit_session(run, refit)
    hand = run / "checkpoints" / "model-00000007.pt"
    data = hand.read_bytes()[:100]
    hand.write_bytes(data)
    other = hand.with_name(hand.name + ".damaged")
    other.write_bytes(b"another file's bytes")

    def interrupted(obj, f, *args, **kw):
        raise KeyboardInterrupt

    (note,) = S.describe(run).notes
    assert "keeping this file as model-00000007.pt.damaged-1)" in note, note
    for _ in range(2):
        monkeypatch.setattr(S.torch, "save", interrupted)
        with pytest.raises(KeyboardInterrupt):
            resume(run)
        monkeypatch.undo()
        assert hand.read_bytes() == data
    back, _ = resume(run)
    back.close()
    assert _same_payload(hand, live[7])
    names = sorted(p.name for p in hand.parent.iterdir() if "00000007" in p.name)
    assert names == [hand.name, other.name, other.name + "-1"], names
    assert other.read_bytes() == b"another file's bytes"
    assert hand.with_name(other.name + "-1").read_bytes() == data


def test_a_full_refit_resume_rebuilds_only_the_damaged_checkpoints_off_the_schedule(
    tmp_path, monkeypatch
):
    """A resume of full refits fitted and wrote back every damaged checkpoint above the
    newest readable one, though one on the regular schedule from the refit recorded below it
    records nothing new: with checkpoints 5, 10, 15, 20 and a hand refit's 22 all damaged it
    made five fits where the model (on 22 labels) needed one. Only those off that schedule
    (22) are now rebuilt in place; the others are set aside as .damaged, as before, and every
    stage reads as the loop had it."""
    run = tmp_path / "run"
    env = rare_regions_world()
    live: dict[int, dict[str, torch.Tensor]] = {}
    ct = ConfidentTeacher(
        env,
        oracle(env),
        config=TeachingConfig(noninteractive=False, max_new=5),
        run_dir=run,
        progress=False,
        keep_checkpoints=None,
        on_refit=lambda m, n: live.__setitem__(n, copy.deepcopy(m.state_dict())),
    )
    live[0] = copy.deepcopy(ct.model.state_dict())  # unfitted
    ct.run(max_demonstrations=22)
    assert ct.refit()  # by hand, at 22
    ct.run(max_demonstrations=24)
    ct.close()
    assert sorted(live) == [0, 5, 10, 15, 20, 22]
    ck = run / "checkpoints"
    damaged = {n: ck / f"model-{n:08d}.pt" for n in (5, 10, 15, 20, 22)}
    for path in damaged.values():
        path.write_bytes(path.read_bytes()[:100])
    notes = S.describe(run).notes
    assert [n for n in notes if "model-00000022.pt" in n and "in its place" in n], notes
    assert [n for n in notes if "model-00000020.pt" in n and "renames it" in n], notes
    fits = []
    real_fit = GaussianMixtureSet.fit

    def counted(self, *args, **kw):
        fits.append(len(args[1]))
        return real_fit(self, *args, **kw)

    monkeypatch.setattr(GaussianMixtureSet, "fit", counted)
    back, _ = resume(run)
    monkeypatch.undo()
    back.close()
    assert fits == [22] and _same(back.model, live[22])
    assert _same_payload(damaged[22], live[22])
    assert damaged[22].with_name(damaged[22].name + ".damaged").exists()
    for n in (5, 10, 15, 20):
        assert (
            not damaged[n].exists() and damaged[n].with_name(f"{damaged[n].name}.damaged").exists()
        )
    for n, staged in S.load_models(run, range(25)):
        assert _same(staged, live[max(r for r in live if r <= n)]), n


def test_resumes_interrupted_at_the_write_back_of_a_linked_checkpoint_keep_one_link(
    tmp_path, monkeypatch
):
    """A damaged refit by hand whose checkpoint is a symbolic link is kept as a link to the
    same file, ``.damaged``; a retried resume did not know its own link again (only regular
    files were compared) and made another each time: ``.damaged-1``, ``-2``. Links are
    compared by what they point to."""
    run = tmp_path / "run"
    _, live = _hand_refit_session(run, "full")
    hand = run / "checkpoints" / "model-00000007.pt"
    outside = tmp_path / "elsewhere.pt"
    outside.write_bytes(hand.read_bytes()[:100])
    hand.unlink()
    hand.symlink_to(outside)

    def interrupted(obj, f, *args, **kw):
        raise KeyboardInterrupt

    for _ in range(2):
        monkeypatch.setattr(S.torch, "save", interrupted)
        with pytest.raises(KeyboardInterrupt):
            resume(run)
        monkeypatch.undo()
    back, _ = resume(run)
    back.close()
    assert _same_payload(hand, live[7]) and not hand.is_symlink()
    names = sorted(p.name for p in hand.parent.iterdir() if "00000007" in p.name)
    assert names == [hand.name, hand.name + ".damaged"], names
    assert os.readlink(hand.with_name(hand.name + ".damaged")) == str(outside)


def test_a_checkpoint_linked_to_its_own_damaged_copy_keeps_it_when_the_write_back_fails(
    tmp_path, monkeypatch
):
    """``model-7.pt`` a link a person made to ``model-7.pt.damaged`` (damaged bytes): the
    resume took that file for its own copy (the same file, through the link), and when
    writing the rebuilt model failed it removed the "copy", the only one of those bytes,
    leaving the name a dangling link. Only a link is a link's copy now, and the file stays."""
    run = tmp_path / "run"
    _hand_refit_session(run, "full")
    hand = run / "checkpoints" / "model-00000007.pt"
    theirs = hand.with_name(hand.name + ".damaged")
    data = hand.read_bytes()[:100]
    theirs.write_bytes(data)
    hand.unlink()
    hand.symlink_to(theirs.name)
    _disk_full_for(monkeypatch, hand.name)
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        back, _ = resume(run)
        back.close()
    monkeypatch.undo()
    assert theirs.read_bytes() == data
    assert hand.is_symlink() and hand.read_bytes() == data


@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_a_damaged_refit_by_hand_whose_bytes_cannot_be_kept_stays_in_place(
    tmp_path, monkeypatch, refit
):
    """A resume writes the model rebuilt over a damaged checkpoint only once its bytes are
    kept as .damaged. Where neither a hard link (here refused, as on file systems without
    them) nor a copy (the file cannot be read) can be made, the file stays as it is, still
    recording its refit, with a warning naming it and saying what to do; every stage reads
    as the loop had it, and a later resume that can keep the bytes writes the model."""
    run = tmp_path / "run"
    _, live = _hand_refit_session(run, refit)
    hand = run / "checkpoints" / "model-00000007.pt"
    data = hand.read_bytes()[:100]
    hand.write_bytes(data)
    real_read = Path.read_bytes

    def no_link(*args, **kw):
        raise OSError(errno.EPERM, "Operation not permitted")

    def unreadable(path):
        if path == hand:
            raise OSError(errno.EIO, "Input/output error")
        return real_read(path)

    monkeypatch.setattr(S.os, "link", no_link)
    monkeypatch.setattr(Path, "read_bytes", unreadable)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        back, _ = resume(run)
    monkeypatch.undo()
    (said,) = [str(w.message) for w in caught if str(hand) in str(w.message)]
    assert "could not be kept as model-00000007.pt.damaged (Input/output error)" in said, said
    assert "the refit there" in said and "resume again" in said, said
    assert _same(back.model, live[7])
    back.close()
    assert hand.read_bytes() == data
    assert sorted(p.name for p in hand.parent.iterdir() if "00000007" in p.name) == [hand.name]
    assert _same(load_model(run), live[7])
    back, _ = resume(run)
    back.close()
    assert _same_payload(hand, live[7])
    assert hand.with_name(hand.name + ".damaged").read_bytes() == data


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="reads /proc/self/fd")
def test_a_rebuilt_refit_by_hand_whose_folder_cannot_be_flushed_says_so(tmp_path, monkeypatch):
    """Where the rebuilt model of a damaged refit by hand was renamed over its name but the
    folder could not be flushed to the disk (an I/O error), the warning says that, not that
    the damaged file stays: the name holds the model now, a power cut may bring the damaged
    file back (which records the refit too), and its bytes are kept as .damaged."""
    run = tmp_path / "run"
    _, live = _hand_refit_session(run, "full")
    hand = run / "checkpoints" / "model-00000007.pt"
    data = hand.read_bytes()[:100]
    hand.write_bytes(data)
    real_fsync, armed = os.fsync, []

    def fsync(fd):
        if armed and os.path.isdir(os.readlink(f"/proc/self/fd/{fd}")):
            armed.clear()
            raise OSError(errno.EIO, "Input/output error")
        real_fsync(fd)
        if os.readlink(f"/proc/self/fd/{fd}").endswith(".model-00000007.pt.tmp"):
            armed.append(None)  # the rebuilt model's file: the folder's flush after it fails

    monkeypatch.setattr(os, "fsync", fsync)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        back, _ = resume(run)
    monkeypatch.undo()
    back.close()
    (said,) = [str(w.message) for w in caught if "model-00000007.pt failed" in str(w.message)]
    assert "(Input/output error)" in said and "stays" not in said, said
    assert "may not be on the disk" in said and "kept as model-00000007.pt.damaged" in said
    assert _same_payload(hand, live[7])
    assert hand.with_name(hand.name + ".damaged").read_bytes() == data


def _same_payload(path: Path, state: dict[str, torch.Tensor]) -> bool:
    """Whether the checkpoint at ``path`` holds ``state``."""
    saved = torch.load(path, weights_only=True)["state_dict"]
    return saved.keys() == state.keys() and all(torch.equal(saved[k], state[k]) for k in saved)


@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_pruning_keeps_what_a_set_aside_checkpoint_leaves_off_the_schedule(tmp_path, refit):
    """A damaged checkpoint records a refit by its name, which may have moved the schedule (a
    refit by hand): pruning removed a later checkpoint as lying on the schedule of the one
    kept below it, counted from there and not from the damaged one once a resume set it
    aside. Here (max_new=5, keeping 1) a hand refit at 7, damaged and set aside by a resume
    (which now writes the model rebuilt on 7 labels in its place), then another by hand at 10
    (on the schedule from 0, off the one from 7): the loop's refit at 15 removed checkpoint
    10, and the stages from 10 to 14 were rebuilt on 7's schedule, on 12 labels where the
    live model stood on 10."""
    run = tmp_path / "run"
    _, live = _hand_refit_session(run, refit, keep=1, upto=8)

    def on_refit(m: torch.nn.Module, n: int) -> None:
        live[n] = copy.deepcopy(m.state_dict())

    hand = run / "checkpoints" / "model-00000007.pt"
    hand.write_bytes(hand.read_bytes()[:100])
    env = rare_regions_world()
    back = ConfidentTeacher.resume(run, env, oracle(env), progress=False, on_refit=on_refit)
    assert (run / "checkpoints" / "model-00000007.pt.damaged").exists()
    back.run(max_demonstrations=10)
    assert back.refit()  # by hand, at 10
    back.run(max_demonstrations=16)  # the loop refits at 15
    back.close()
    assert sorted(live) == [0, 5, 7, 10, 15]
    for n, model in S.load_models(run, range(17)):
        assert _same(model, live[max(r for r in live if r <= n)]), n
        assert _same(load_model(run, n_demonstrations=n), live[max(r for r in live if r <= n)]), n


@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_an_older_resume_that_set_a_refit_by_hand_aside_kept_the_regular_schedule(tmp_path, refit):
    """A torchcbl before bce98c3 resuming a session whose checkpoint of a refit by hand was
    damaged set it aside as .damaged and taught on on the regular schedule: here a hand refit
    at 7 (max_new=5, keeping 1), damaged and set aside by a resume at 9 labels, which stood on
    5 and refitted at 10, 15 and 20. Read as a record of a refit at 7, the .damaged name had
    load_model and load_models rebuild the stages from 7 to 19 on 7, 12 and 17 labels, a
    schedule no loop had. The directory is built here as that resume left it (the set-aside
    file out of sight while it runs, so it teaches on the regular schedule, then put back):
    a .damaged name records nothing now, every stage reads as the loop had it (as that
    torchcbl read it), and the file stays."""
    run = tmp_path / "run"
    _, live = _hand_refit_session(run, refit, keep=1)
    hand = run / "checkpoints" / "model-00000007.pt"
    assert sorted(p.name for p in hand.parent.iterdir()) == [hand.name]
    data = hand.read_bytes()[:100]
    hand.write_bytes(data)
    aside = tmp_path / (hand.name + ".damaged")  # renamed by the older resume
    hand.rename(aside)
    env = rare_regions_world()
    again: dict[int, dict[str, torch.Tensor]] = {}
    back = ConfidentTeacher.resume(
        run,
        env,
        oracle(env),
        progress=False,
        on_refit=lambda m, n: again.__setitem__(n, copy.deepcopy(m.state_dict())),
    )
    assert _same(back.model, live[5])  # the older resume: on the regular schedule
    back.run(max_demonstrations=21)
    back.close()
    assert sorted(again) == [10, 15, 20]
    aside.rename(run / "checkpoints" / aside.name)
    want = {0: live[0], 5: live[5], **again}  # the schedule the session's loops had
    for n, staged in S.load_models(run, range(22)):
        stood = want[max(r for r in want if r <= n)]
        assert _same(staged, stood), n
        assert _same(load_model(run, n_demonstrations=n), stood), n
    back, _ = resume(run)
    assert _same(back.model, again[20])
    back.close()
    assert (run / "checkpoints" / aside.name).read_bytes() == data


@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_a_resume_writes_a_missing_checkpoint_only_of_full_refits(tmp_path, refit):
    """restore_model's docstring said a resume writes the checkpoint of the labels the model
    stands on where it is missing (the process killed between logging and saving); only a
    resume of full refits does. One of incremental refits replays them to that count, bit
    for bit, and leaves it missing (it writes only the models of refits recorded by damaged
    files). The docstring now says so; either way the model is the live one."""
    run = tmp_path / "run"
    env = rare_regions_world()
    config = TeachingConfig(noninteractive=False, max_new=5, refit=refit)
    ct = ConfidentTeacher(env, oracle(env), config=config, run_dir=run, progress=False)
    ct.run(max_demonstrations=11)
    ct.close()
    ten = run / "checkpoints" / "model-00000010.pt"
    ten.unlink()  # never saved
    back, _ = resume(run)
    assert same_state(back.model, ct.model)
    back.close()
    assert ten.exists() == (refit == "full")


@pytest.mark.parametrize("where", ["beyond", "stale"])
def test_a_checkpoint_resume_cannot_set_aside_is_said_and_left_as_it_is(
    tmp_path, monkeypatch, where
):
    """Resume renames a checkpoint named for more labels than the log holds ``.stale`` (read
    as a refit once the session is taught that far again: here a damaged one at 7 in a
    session of 5 labels), and a stale one ``.stale``; where the rename failed, the file
    stayed, silently, and the stale one of the count the model stands on was written over
    (its bytes lost). Each now stays as it is, with a warning naming it and what to do."""
    run = tmp_path / "run"
    env = rare_regions_world()
    config = TeachingConfig(noninteractive=False, max_new=5)
    ct = ConfidentTeacher(env, oracle(env), config=config, run_dir=run, progress=False)
    ct.run(max_demonstrations=5)
    live = copy.deepcopy(ct.model.state_dict())
    ct.close()
    five = run / "checkpoints" / "model-00000005.pt"
    if where == "beyond":
        odd = run / "checkpoints" / "model-00000007.pt"
        odd.write_bytes(five.read_bytes()[:100])
    else:
        odd = five
        payload = torch.load(five, weights_only=True)
        torch.save({**payload, "labels_sha256": "0" * 64}, five)  # fitted on other labels
    data = odd.read_bytes()
    real = os.replace

    def replace(src, dst, *args, **kw):
        if Path(src) == odd and str(dst).endswith(".stale"):
            raise OSError(errno.EACCES, "Permission denied")
        return real(src, dst, *args, **kw)

    monkeypatch.setattr(os, "replace", replace)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        back, _ = resume(run)
    monkeypatch.undo()
    back.close()
    said = [str(w.message) for w in caught if str(odd) in str(w.message)]
    assert len(said) == 1, [str(w.message) for w in caught]
    assert f"could not be renamed {odd.name}.stale (Permission denied)" in said[0], said
    assert f"move it out of {odd.parent}" in said[0], said
    assert odd.read_bytes() == data and not odd.with_name(odd.name + ".stale").exists()
    assert _same(back.model, live)


@pytest.mark.parametrize("damage", ["cut", "whole"])
@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_a_checkpoint_of_labels_the_log_lost_is_set_aside_as_stale(tmp_path, refit, damage):
    """A writer logs a label before it saves a checkpoint of it, so a checkpoint named for
    more labels than the log holds belongs to labels the log lost (here the log restored from
    a backup of 5 labels, after a refit by hand at 7 whose checkpoint stayed). Resume passed
    it over and left it, and once the session was taught past 7 again (the loop refitting at
    10, no refit by hand) readers took it for a refit at 7: damaged, by its name; whole, by
    its labels' SHA-256, the same labels taught again. load_model gave a model on 7 labels
    where the live one stood on 5. Resume now sets it aside as .stale, its bytes kept, and
    every stage reads as the loop had it."""
    run, backup = tmp_path / "run", tmp_path / "backup"
    live: dict[int, dict[str, torch.Tensor]] = {}

    def on_refit(m: torch.nn.Module, n: int) -> None:
        live[n] = copy.deepcopy(m.state_dict())

    _hand_refit_session(run, refit, live=live, backup=backup)
    live.pop(7)  # the refit the log lost with the backup
    hand = run / "checkpoints" / "model-00000007.pt"
    if damage == "cut":
        hand.write_bytes(hand.read_bytes()[:100])
    data = hand.read_bytes()
    for path in run.iterdir():  # the log and the rest from the backup, checkpoints/ kept
        if path.name != "checkpoints":
            shutil.rmtree(path) if path.is_dir() else path.unlink()
    for path in backup.iterdir():
        if path.name != "checkpoints":
            shutil.copy2(path, run / path.name)
    assert int(load_model(run).n_points_.sum()) == 5  # not read: more than the log's labels
    env = rare_regions_world()
    back = ConfidentTeacher.resume(run, env, oracle(env), progress=False, on_refit=on_refit)
    assert back.n_demonstrations == 5 and _same(back.model, live[5])
    assert not hand.exists()
    assert hand.with_name(hand.name + ".stale").read_bytes() == data
    back.run(max_demonstrations=9)
    assert _same(back.model, live[5])  # no refit since 5: the next is due at 10
    for n, staged in S.load_models(run, range(10)):
        stood = live[max(r for r in (0, 5) if r <= n)]
        assert _same(staged, stood), n
        assert _same(load_model(run, n_demonstrations=n), stood), n
    back.run(max_demonstrations=12)
    back.close()
    assert sorted(live) == [0, 5, 10]
    assert _same(load_model(run), live[10])


def test_damaged_sqlite_file(tmp_path):
    run = tmp_path / "run"
    _closed_session(run)
    log = run / "steps.sqlite"
    good = log.read_bytes()
    log.write_bytes(b"garbage!" * 64 + good[512:])
    for read in (load_records, load_model):
        with pytest.raises(CorruptSessionError) as err:
            read(run)
        assert f"{log} is not a readable SQLite database" in str(err.value)
        assert ".recover" in str(err.value) and "changed nothing" in str(err.value)
    with pytest.raises(CorruptSessionError, match="not a readable SQLite database"):
        resume(run)
    assert log.read_bytes()[:8] == b"garbage!"  # untouched
    log.write_bytes(good)  # restored from a backup
    back, env = resume(run)
    goes_on(back, env, run)


def test_a_session_copied_without_its_wal_file_is_said_to_lack_it(tmp_path):
    """A session not closed cleanly (killed, or copied while its writer ran) has its commits
    in steps.sqlite-wal, the tables themselves included until the first checkpoint. Read
    without that file (deleted as a temporary file, or left behind by a copy), the log was
    called "not a readable SQLite database (no such table: steps)", with the advice to salvage
    it with sqlite3's .recover, which finds nothing: the steps were never in that file. The
    error now names the missing -wal file and says to put it back."""
    run, copy = tmp_path / "run", tmp_path / "copy"
    ct, env = session(run, commit_every=4)
    ct.run(max_steps=20)
    assert (run / "steps.sqlite-wal").exists()
    copy.mkdir()
    for name in ("config.json", "steps.sqlite", "steps.journal", "writers.jsonl"):
        shutil.copy2(run / name, copy / name)  # the -wal and -shm left behind
    for read in (load_records, load_model, resume):
        with pytest.raises(CorruptSessionError) as err:
            read(copy)
        msg = str(err.value)
        assert str(copy / "steps.sqlite-wal") in msg and "is missing" in msg, msg
        assert "back beside steps.sqlite" in msg and ".recover" not in msg, msg
    shutil.copy2(run / "steps.sqlite-wal", copy / "steps.sqlite-wal")  # put back
    assert load_records(copy) == ct.records
    ct.close()


@pytest.mark.parametrize("where", ["a resume", "a checkpoint", "a resume, then the journal"])
def test_a_wal_lost_after_its_tables_reached_the_log_is_said_to_be_missing(tmp_path, where):
    """Once steps.sqlite holds the tables (a writer closed cleanly, or SQLite checkpointed the
    WAL into it, which it does by itself every ~4 MB), a session read without its -wal file
    (deleted by hand, or left out of a copy) read as the shorter session the log held at that
    point: load_records, load_demonstrations and load_model gave fewer steps and labels with no
    word, and resume went on after them, numbering its new steps over the lost ones. The
    writer now keeps in writer.lock how many steps and corrections it committed, and a log
    holding fewer is an error naming the missing -wal, changing nothing; with the -wal put
    back every step reads again, and removing writer.lock accepts the loss."""
    run, copy = tmp_path / "run", tmp_path / "copy"
    ct, env = session(run, commit_every=4)
    ct.run(max_steps=20)
    if where.startswith("a resume"):
        ct.close()
        ct, env = resume(run, commit_every=4)
    else:  # as SQLite's automatic checkpoint does, with the writer running
        other = sqlite3.connect(run / "steps.sqlite")
        assert other.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchone()[0] == 0
        other.close()
    ct.run(max_steps=40)  # committed into the -wal (run() commits at its end)
    assert (run / "steps.sqlite-wal").stat().st_size > 0
    assert (run / "steps.journal").stat().st_size == 0
    if where.endswith("journal"):  # and 5 more steps only in the journal (killed then)
        ct._store.commit_every = 10**6
        for _ in range(5):
            ct.step()
    want = load_records(run)
    assert len(want) == 45 if where.endswith("journal") else 40
    shutil.copytree(
        run, copy, ignore=shutil.ignore_patterns("steps.sqlite-wal", "steps.sqlite-shm")
    )
    before = files_of(copy)
    for read in (load_records, load_demonstrations, load_model, resume, repair_journal):
        with pytest.raises(CorruptSessionError) as err:
            read(copy)
        msg = str(err.value)
        assert str(copy / "steps.sqlite-wal") in msg and "is missing" in msg, msg
        assert "committed 40 steps" in msg and "holds 20 of those" in msg, msg
        assert "remove " + str(copy / "writer.lock") in msg and "changed nothing" in msg, msg
    assert files_of(copy) == before  # nothing changed
    shutil.copy2(run / "steps.sqlite-wal", copy / "steps.sqlite-wal")  # put back
    assert load_records(copy) == want
    lost = tmp_path / "lost"
    shutil.copytree(
        run, lost, ignore=shutil.ignore_patterns("steps.sqlite-wal", "steps.sqlite-shm")
    )
    (lost / "writer.lock").unlink()  # the loss accepted: the 20 steps left read and resume
    if where.endswith("journal"):  # the journal's steps follow a gap: as a line lost from it
        with pytest.warns(UserWarning, match=r"lacks 20 steps \(20, 21,"):
            load_records(lost)
        repair_journal(lost)
    assert load_records(lost) == want[:20]
    back, _ = resume(lost)
    assert back.records == want[:20]
    back.close()
    ct.close()


class _Contrary:
    """A teacher that labels as ``label(obs, info) -> int`` does and corrects every fourth
    autonomous step it is shown (with another of 3 actions)."""

    def __init__(self, label) -> None:
        self.label, self.calls = label, 0

    def __call__(self, obs, info):
        return self.label(obs, info)

    def correct(self, obs, info, action):
        self.calls += 1
        return (action + 1) % 3 if self.calls % 4 == 0 else None


def test_a_log_lacking_committed_corrections_alone_is_said_to_lack_them(tmp_path):
    """writer.lock counts corrections as well as steps: a log holding every committed step
    but fewer corrections than its writers committed (a correction's row gone, here deleted by
    hand as a lost -wal loses rows) is refused by the readers and resume, naming both counts
    and the missing -wal, and nothing changes; with writer.lock removed (the loss accepted)
    the session reads with the corrections left."""
    from torchcbl.strategies.cba import ConfidenceBasedAutonomy

    run = tmp_path / "run"
    env = rare_regions_world()
    cfg = TeachingConfig(max_new=2, accuracy_window=10, noninteractive=False)
    with ConfidentTeacher(
        env,
        _Contrary(oracle(env)),
        strategy=ConfidenceBasedAutonomy(),
        config=cfg,
        run_dir=run,
        progress=False,
        commit_every=4,
    ) as ct:
        ct.run(max_steps=80)
    corrections = load_corrections(run)
    n, k = len(ct.records), len(corrections)
    assert k >= 2 and not (run / "steps.sqlite-wal").exists()
    db = sqlite3.connect(run / "steps.sqlite")
    db.execute("DELETE FROM corrections WHERE step = ?", (corrections[-1].step,))
    db.commit()
    db.close()
    before = files_of(run)
    said = (
        rf"committed {n} steps and {k} corrections .*but the log holds {n} of those steps and "
        rf"{k - 1} corrections.* is missing"
    )
    for read in (load_records, load_corrections, load_labels, load_model):
        with pytest.raises(CorruptSessionError, match=said):
            read(run)
    with pytest.raises(CorruptSessionError, match=said):
        ConfidentTeacher.resume(run, rare_regions_world(), _Contrary(oracle(env)), progress=False)
    assert files_of(run) == before  # nothing changed
    (run / "writer.lock").unlink()
    assert load_corrections(run) == corrections[:-1]


def test_a_session_copied_while_its_writer_ran_reads_and_resumes_with_a_warning(tmp_path):
    """A copy that takes writer.lock after the log (rsync does, by name order; GNU cp -a goes
    in directory order, either way) taken while the writer runs can hold a writer.lock that
    counts commits made after the log was copied. Every
    reader, resume and repair_journal refused such a copy with a CorruptSessionError ("the
    rest are not in the session's files"), though its -wal and journal are there and it reads
    as a consistent earlier state of the session, as it did before writer.lock held counts.
    With the -wal and the journal present, a log holding fewer steps than writer.lock says is
    read and resumed with a warning naming both counts and the two causes (a copy taken while
    the writer ran, a power cut); resume then notes its own counts, so later reads say
    nothing. (A missing -wal or journal stays an error: the tests above.)"""
    run, copy = tmp_path / "run", tmp_path / "copy"
    ct, env = session(run, commit_every=4)
    ct.run(max_steps=20)
    want = load_records(run)
    shutil.copytree(run, copy, ignore=shutil.ignore_patterns("writer.lock"))
    ct.run(max_steps=30)  # the writer commits 10 more steps meanwhile
    shutil.copy2(run / "writer.lock", copy / "writer.lock")  # copied last
    ct.close()
    assert (copy / "steps.sqlite-wal").exists() and (copy / "steps.journal").exists()
    said = (
        r"writer\.lock says its writer committed 30 steps and 0 corrections, but the log "
        r"holds 20 of those steps and 0 corrections.*copied while its writer ran.*power cut"
    )
    before = files_of(copy)
    for read in (load_records, load_labels, load_model):
        with pytest.warns(UserWarning, match=said):
            read(copy)
    with pytest.warns(UserWarning, match=said):
        assert load_records(copy) == want
    after = files_of(copy)  # the readers changed nothing (but SQLite's index of the -wal)
    assert after.pop("steps.sqlite-shm") and before.pop("steps.sqlite-shm") and after == before
    with pytest.warns(UserWarning, match=said):
        repair_journal(copy)
    with pytest.warns(UserWarning, match=said):
        back, _ = resume(copy)
    assert back.records == want
    back.run(max_steps=26)
    back.close()
    with warnings.catch_warnings():  # resume noted the counts it has: no warning since
        warnings.simplefilter("error")
        assert load_records(copy)[:20] == want and len(load_records(copy)) == 26
        back, _ = resume(copy)
        back.close()


def test_a_readers_warning_about_the_session_points_at_the_readers_caller(tmp_path):
    """The warnings of a copy taken while the writer ran, and of steps missing from the log,
    named torchcbl's own session.py as their place for load_model and load_demonstrations
    (and load_policy), which read the log through load_labels: a user filtering warnings by
    module, or reading where one came from, was sent into torchcbl. Every reader's warnings
    now point at the line that called it, here this file."""
    run, copy = tmp_path / "run", tmp_path / "copy"
    ct, env = session(run, commit_every=4)
    ct.run(max_steps=20)
    shutil.copytree(run, copy, ignore=shutil.ignore_patterns("writer.lock"))
    ct.run(max_steps=30)  # the writer commits 10 more steps meanwhile
    shutil.copy2(run / "writer.lock", copy / "writer.lock")  # copied last
    ct.close()
    gap = tmp_path / "gap"
    shutil.copytree(run, gap)
    db = sqlite3.connect(gap / "steps.sqlite")
    db.execute("DELETE FROM steps WHERE step IN (5, 6)")
    db.commit()
    db.close()
    readers = (
        load_records,
        load_labels,
        load_corrections,
        load_demonstrations,
        load_model,
        S.load_policy,
    )
    for where, said in ((copy, "copied while its writer ran"), (gap, r"lacks 2 steps \(5, 6\)")):
        for read in readers:
            with pytest.warns(UserWarning, match=said) as got:
                read(where)
            places = {(Path(w.filename).name, read.__name__) for w in got}
            assert places == {(Path(__file__).name, read.__name__)}, places


def test_a_torn_read_of_writer_locks_counts_is_not_taken_for_a_count(tmp_path):
    """The writer rewrites writer.lock's count line in place and readers read it without a
    lock, so a read that overlaps the rewrite can see the new line's first bytes and the old
    one's last: from 19 to 20 steps, "          29" (as "999" to "1000" reads as "1999"),
    more steps than the log holds: a false warning (an error without the -wal). A line whose
    CRC-32 does not match is now read as no count. Every tear of the file between its note at
    19 steps and at 20 (a prefix of one, the rest of the other) reads the 20 steps with no
    warning; so does a tear that leaves the line cut short."""
    run = tmp_path / "run"
    ct, env = session(run, commit_every=4)
    ct.run(max_steps=19)  # run() commits at its end, and notes the count
    at_19 = (run / "writer.lock").read_bytes()
    ct.run(max_steps=20)
    at_20 = (run / "writer.lock").read_bytes()
    assert len(at_19) == len(at_20) and at_19 != at_20
    want = load_records(run)
    torn = {a[:k] + b[k:] for a, b in ((at_19, at_20), (at_20, at_19)) for k in range(len(a))}
    torn |= {at_20[:k] for k in range(len(at_20))}
    assert b"committed to steps.sqlite:           29 steps" in b"".join(torn)
    try:
        for lock in sorted(torn):
            (run / "writer.lock").write_bytes(lock)
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                assert load_records(run) == want, lock
    finally:
        (run / "writer.lock").write_bytes(at_20)
        ct.close()
    assert load_records(run) == want


def test_a_writer_that_cannot_note_itself_in_writer_lock_keeps_the_count_there(
    tmp_path, monkeypatch
):
    """A new writer notes itself in writer.lock, keeping the last writer's count line. It
    truncated the file to nothing and then wrote the holder and count lines, so a write that
    failed (a full disk: the error is swallowed, the lock holds without the note) or a SIGKILL
    between the two left writer.lock without the count: a -wal lost after that was read as a
    shorter session with no word, until the writer's next note. Here every write to
    writer.lock fails while a resume takes it: the count line of the last writer is still
    there, and once writes go through again the writer notes its own."""
    run = tmp_path / "run"
    ct, env = session(run, commit_every=4)
    ct.run(max_steps=20)
    ct.close()
    count = b"committed to steps.sqlite:           20 steps"
    assert count in (run / "writer.lock").read_bytes()

    def lock_fd(fd: int) -> bool:
        return os.readlink(f"/proc/self/fd/{fd}").endswith("writer.lock")

    def failing(real):
        def write(fd, *args):
            if lock_fd(fd):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            return real(fd, *args)

        return write

    real_write, real_pwrite = os.write, os.pwrite
    monkeypatch.setattr(os, "write", failing(real_write))
    monkeypatch.setattr(os, "pwrite", failing(real_pwrite))
    ct, env = resume(run, commit_every=4)
    assert count in (run / "writer.lock").read_bytes()
    monkeypatch.setattr(os, "write", real_write)
    monkeypatch.setattr(os, "pwrite", real_pwrite)
    ct.run(max_steps=24)  # a commit: the writer's own note
    lock = (run / "writer.lock").read_bytes()
    assert b"committed to steps.sqlite:           24 steps" in lock, lock
    assert len(lock.splitlines()) == 2, lock
    ct.close()
    assert len(load_records(run)) == 24


def test_a_journal_deleted_while_it_held_steps_is_said_to_be_missing(tmp_path):
    """A writer killed with steps only in steps.journal (not yet committed to steps.sqlite),
    whose journal was then deleted by hand or left out of a copy, read as the shorter session
    in steps.sqlite: 20 of 25 steps, with no word, and resume went on after them. writer.lock
    now also says whether the journal holds lines not yet committed (set before the first line
    after a commit, cleared by the commit), so a missing journal that held some is an error
    naming it and changing nothing; one that held none (a cleanly closed session's) is not."""
    run, copy = tmp_path / "run", tmp_path / "copy"
    ct, env = _journalled(run, steps=5, commit_every=4)  # killed: 5 steps only in the journal
    want = load_records(run)
    assert len(want) == 25
    shutil.copytree(run, copy, ignore=shutil.ignore_patterns("steps.journal"))
    before = files_of(copy)
    for read in (load_records, load_labels, load_model, resume, repair_journal):
        with pytest.raises(CorruptSessionError) as err:
            read(copy)
        msg = str(err.value)
        assert str(copy / "steps.journal") + " is missing" in msg, msg
        assert "changed nothing" in msg and "writer.lock" in msg, msg
    assert files_of(copy) == before
    shutil.copy2(run / "steps.journal", copy / "steps.journal")  # put back
    assert load_records(copy) == want
    back, _ = resume(copy)
    assert back.records == want
    back.close()
    (copy / "steps.journal").unlink()  # closed cleanly: the journal held nothing
    assert load_records(copy) == want


def test_a_log_deleted_beside_its_writers_file_is_said_to_be_missing(tmp_path):
    """writers.jsonl says a writer opened the session's log: with the log, the journal, the
    checkpoints and writer.lock gone, the log is named as missing (the readers and resume
    refuse, changing nothing), not taken for a session whose creation was killed before its
    log (read as one of no step), which a folder without writers.jsonl too is."""
    run = tmp_path / "run"
    ct, _ = session(run)
    ct.run(max_steps=5)
    ct.close()
    for path in (*run.glob("steps.*"), *run.glob("checkpoints/*"), run / "writer.lock"):
        path.unlink()
    names = sorted(p.name for p in run.glob("*.*"))
    assert names == ["config.json", "runs.jsonl", "writers.jsonl"], names
    before = files_of(run)
    for read in (load_records, load_model, resume):
        with pytest.raises(CorruptSessionError, match="steps.sqlite is missing"):
            read(run)
    assert files_of(run) == before
    (run / "writers.jsonl").unlink()  # no writer ran: a creation killed before its log
    assert load_records(run) == []


@pytest.mark.parametrize("key", ["teaching", "model", "env", "seed"])
def test_config_missing_a_key(tmp_path, key):
    run = tmp_path / "run"
    _closed_session(run)
    path = run / "config.json"
    good = path.read_text()
    config = json.loads(good)
    del config[key]
    path.write_text(json.dumps(config))
    for call in (load_records, load_model, resume):
        with pytest.raises(CorruptSessionError) as err:
            call(run)
        assert f"{path}: the key {key!r}" in str(err.value) and "restore it" in str(err.value)
    path.write_text(good)
    back, env = resume(run)
    goes_on(back, env, run)


@pytest.mark.parametrize(
    "field, value, says",
    [
        ("max_new", 0, "max_new 0, not an int >= 1"),
        ("max_new", "5", "max_new '5', not an int >= 1"),
        ("accuracy_window", -3, "no valid TeachingConfig (TeachingConfig.accuracy_window"),
    ],
)
def test_config_with_a_teaching_value_no_session_takes(tmp_path, field, value, says):
    """A config.json edited by hand to a value no TeachingConfig takes: resume raised the
    config's bare ValueError ("TeachingConfig.max_new: expected None or an int >= 1, got 0"),
    and load_model int()'s ("invalid literal for int() with base 10") or fit_count's, none
    naming the file. Each is now a CorruptSessionError naming config.json and the way back."""
    run = tmp_path / "run"
    _closed_session(run)
    path = run / "config.json"
    good = path.read_text()
    config = json.loads(good)
    config["teaching"][field] = value
    path.write_text(json.dumps(config))
    before = files_of(run)
    calls = (load_model, load_demonstrations, resume) if field == "max_new" else (resume,)
    for call in calls:
        with pytest.raises(CorruptSessionError) as err:
            call(run)
        assert str(err.value).startswith(f"{path}: ") and says in str(err.value)
        assert "edited or damaged" in str(err.value)
    assert files_of(run) == before
    path.write_text(good)
    back, env = resume(run)
    goes_on(back, env, run)


def test_deleted_step_log_is_not_restarted_silently(tmp_path):
    run = tmp_path / "run"
    _closed_session(run)
    log = run / "steps.sqlite"
    kept = tmp_path / "kept.sqlite"
    log.rename(kept)
    n = len(list((run / "checkpoints").glob("model-*.pt")))
    for call in (load_records, load_model, resume):
        with pytest.raises(CorruptSessionError) as err:
            call(run)
        msg = str(err.value)
        assert f"{log} is missing" in msg and f"{n} checkpoints" in msg and "Put it back" in msg
    with pytest.raises(IncompatibleRunDirError, match="already holds"):
        session(run)
    assert not log.exists()
    kept.rename(log)
    back, env = resume(run)
    goes_on(back, env, run)


def test_a_closed_teacher_does_not_go_on_unlogged(tmp_path):
    run = tmp_path / "run"
    ct, env = session(run)
    ct.run(max_steps=5)
    ct.close()
    with pytest.raises(IncompatibleRunDirError, match="was closed.*ConfidentTeacher.resume"):
        ct.run(max_steps=10)
    assert ct.n_steps == 5 and load_records(run) == ct.records


# -- 5. one writer ----------------------------------------------------------------------------


def test_a_second_writer_is_refused_while_the_first_runs(tmp_path):
    run = tmp_path / "run"
    ct, env = session(run)
    ct.run(max_steps=15)
    with pytest.raises(SessionLockedError) as err:
        resume(run)
    msg = str(err.value)
    assert str(run / "writer.lock") in msg and f"process {os.getpid()}" in msg
    assert "close the other ConfidentTeacher" in msg
    ct.run(max_steps=30)  # the first writer is unharmed
    memory_equals_disk(ct, run)
    goes_on(ct, env, run)  # closes it; then a resume takes the lock


def test_a_killed_writer_leaves_no_stuck_lock(tmp_path):
    run, side = tmp_path / "run", tmp_path / "side.log"
    proc = subprocess.Popen(
        [sys.executable, str(TESTS / "_toy_envs.py"), str(run), str(side)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "ready", proc.stderr.read()
        with pytest.raises(SessionLockedError, match=f"process {proc.pid}"):
            resume(run, overlap_world(episode_length=25), rule=S_rule())
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    back, env = resume(run, overlap_world(episode_length=25), rule=S_rule())
    assert_model_is_fit_on_log(back.model, run)
    back.run(max_steps=back.n_steps + 10)
    memory_equals_disk(back, run)
    back.close()


def S_rule():  # noqa: N802 - the rule the kill child uses
    from torchcbl import PosteriorRule

    return PosteriorRule(0.9)


# -- 6. far observations ----------------------------------------------------------------------


def _two_blobs() -> GaussianMixtureSet:
    rng = np.random.default_rng(0)
    x = np.r_[rng.normal(0, 1, (60, 2)), rng.normal([6, 0], [1, 3], (60, 2))]
    y = np.r_[np.zeros(60, int), np.ones(60, int)]
    return GaussianMixtureSet(2, 2, max_components=2, seed=0).fit(x, y)


def _nearest_component_action(model: GaussianMixtureSet, x: np.ndarray) -> tuple[int, float]:
    """Oracle: the action of the component with the smallest Mahalanobis distance and that
    distance, each distance ||U^T (x - mu)|| computed on x / s (s = max |x|) then times s."""
    s = max(np.abs(x).max(), 1.0)
    best = (np.inf, -1)
    for a in range(model.n_actions):
        for k in range(model.max_components):
            if not bool(model.component_mask_[a, k]):
                continue
            u = model.precisions_cholesky_[a, k].double().numpy()
            mu = model.means_[a, k].double().numpy()
            with np.errstate(over="ignore"):
                d = s * np.linalg.norm((x / s - mu / s) @ u)
            best = min(best, (d, a))
    return best[1], best[0]


@pytest.mark.parametrize(
    "x",
    [[1e155, 0.0], [0.0, -1e155], [1e308, -1e308], [-3e200, 1.0], [1e160, 1e160]],
)
def test_far_observations_classify_with_finite_values(x, recwarn):
    model = _two_blobs()
    obs = np.array([x, [0.0, 0.0], [6.0, 0.0]])
    want_a, want_d = _nearest_component_action(model, obs[0])
    for rows in (obs[:1], obs):  # the loop's one-row path and the batch path
        c = model.classify(rows)
        assert torch.isfinite(c.posterior).all() and torch.isfinite(c.distance).all()
        assert int(c.action[0]) == want_a and float(c.confidence[0]) == 0.0
        assert c.posterior[0].tolist() == [float(a == want_a) for a in range(2)]
        assert float(c.distance[0]) == pytest.approx(min(want_d, np.finfo(float).max), rel=1e-9)
        assert c.action[1:].tolist() == [0, 1][: len(rows) - 1]
    import torchcbl.gmm as G

    model._cache = None
    old, G._NUMPY_MAX_ROWS = G._NUMPY_MAX_ROWS, 0  # the torch path
    try:
        c2 = model.classify(obs)
    finally:
        G._NUMPY_MAX_ROWS = old
        model._cache = None
    for a, b in zip(c, c2, strict=True):
        assert torch.allclose(a.double(), b.double(), rtol=1e-12, atol=0)
    # its log-density is 0 (log -inf) on the one-row, the batch and the torch paths, never NaN
    for rows in (obs[:1], obs, np.tile(obs, (100, 1))):  # 300 rows: the torch path
        lp = model.log_prob(rows)
        assert not torch.isnan(lp).any() and bool((lp[0] == -math.inf).all())
        assert torch.isfinite(lp[1:3]).all()
    assert model.aic(obs, np.array([0, 0, 1])).tolist()[0] == math.inf
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]


def test_far_path_equals_the_plain_one_where_both_are_representable():
    model = _two_blobs()
    rng = np.random.default_rng(1)
    x = rng.normal(3, 4, (200, 2)) * rng.choice([1, 10, 1e3], (200, 1))
    plain, far = model.classify(x), model._classify_far(x)
    assert torch.equal(plain.action, far.action)
    for a, b in zip(plain[1:], far[1:], strict=True):
        assert torch.allclose(a, b, rtol=1e-9, atol=1e-300)


def test_a_far_observation_in_the_loop(tmp_path):
    run = tmp_path / "run"

    class Far(gym.Wrapper):
        def step(self, action):
            obs, r, term, trunc, info = self.env.step(action)
            if self.unwrapped._t == 5:
                obs = np.array([1e155, 0.0], dtype=np.float64)
            return obs, r, term, trunc, info

    world = rare_regions_world()
    model = GaussianMixtureSet(3, 2, seed=0).fit(*world.sample(300, np.random.default_rng(0)))
    env = Far(world)
    ct = ConfidentTeacher(
        env,
        lambda o, i: 0,
        model=model,
        config=TeachingConfig(noninteractive=False, max_new=10**6, max_steps=30),
        run_dir=run,
        progress=False,
    )
    ct.run()
    far = [r for r in ct.records if r.observation[0] == 1e155]
    assert far and all(r.confidence == 0.0 and r.is_demonstration for r in far)
    assert all(np.isfinite(r.posterior).all() for r in far)
    assert load_records(run) == ct.records


# -- 7. determinism, recorded -----------------------------------------------------------------


def test_each_writer_records_torch_threads(tmp_path):
    run = tmp_path / "run"
    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        ct, _ = session(run)
        ct.run(max_steps=10)
        ct.close()
        torch.set_num_threads(2)
        back, _ = resume(run)
        back.run(max_steps=15)
        back.close()
    finally:
        torch.set_num_threads(threads)
    lines = [json.loads(x) for x in (run / "writers.jsonl").read_text().splitlines()]
    assert [(w["first_step"], w["torch_num_threads"]) for w in lines] == [(0, 1), (10, 2)]
    assert [w["model_device"] for w in lines] == ["cpu", "cpu"]
    assert lines[0]["torch_version"] == torch.__version__
    assert load_config(run)["format"] == S.FORMAT


# -- a Ctrl-C that lands between a write and its bookkeeping -----------------------------------


def _line_kind(data: bytes) -> str:
    entry = json.loads(data.rpartition(b"\t")[0])
    if entry[0] == "s":
        return "autonomous" if entry[8] is None else "demonstration"  # teacher_action
    return {"f": "outcome", "c": "correction"}[entry[0]]


class _CtrlCAfterCommit:
    """The session's SQLite connection, with a real SIGINT sent as its next COMMIT returns."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self.db, self.armed = db, True

    def execute(self, sql: str, *args):
        out = self.db.execute(sql, *args)
        if sql == "COMMIT" and self.armed:
            self.armed = False
            os.kill(os.getpid(), signal.SIGINT)
        return out

    def __getattr__(self, name: str):
        return getattr(self.db, name)


@pytest.mark.parametrize("where", ["demonstration", "outcome", "autonomous", "commit"])
def test_a_real_ctrl_c_right_after_a_journal_write_or_a_commit(tmp_path, monkeypatch, where):
    """A SIGINT that arrives just as a journal line was written (or as SQLite committed a
    batch) waits until memory holds what disk holds: the KeyboardInterrupt still stops the
    run, and afterwards no step is on disk that memory lacks, no number is used twice, and the
    session goes on in this process and after a resume (before 2026-11-26 the step was on disk
    only, the next one took its number, and every later commit failed)."""
    run = tmp_path / "run"
    ct, env = session(run, commit_every=4, noninteractive=False)
    ct.run(max_steps=20)  # a model: from here on requests and autonomous steps mix
    sent: list[str] = []
    if where == "commit":
        ct._store._db = _CtrlCAfterCommit(ct._store._db)
        sent.append(where)
    else:

        def write(fd: int, data: bytes) -> int:
            n = os.write(fd, data)
            if not sent and _line_kind(data) == where:
                sent.append(where)
                os.kill(os.getpid(), signal.SIGINT)
            return n

        monkeypatch.setattr(S, "_write_fd", write)
    with pytest.raises(KeyboardInterrupt):
        ct.run(max_steps=400)
    assert sent == [where]
    monkeypatch.setattr(S, "_write_fd", os.write)
    if where == "commit":
        ct._store._db = ct._store._db.db
    steps = [r.step for r in load_records(run)]
    assert steps == list(range(len(steps))) == [r.step for r in ct.records]
    goes_on(ct, env, run)


def test_a_real_ctrl_c_right_after_a_corrections_line(tmp_path, monkeypatch):
    """The correction is on disk: memory, the strategy and the refit schedule learn it before
    the held KeyboardInterrupt stops the run (the live model then equals load_model's)."""
    from torchcbl.strategies.cba import ConfidenceBasedAutonomy

    run = tmp_path / "run"
    env = Witness(rare_regions_world())
    cfg = TeachingConfig(max_new=2, accuracy_window=10, noninteractive=False)
    ct = ConfidentTeacher(
        env,
        _Contrary(env.teacher),
        strategy=ConfidenceBasedAutonomy(),
        config=cfg,
        run_dir=run,
        progress=False,
        commit_every=4,
    )
    env.ct = ct
    sent: list[int] = []

    def write(fd: int, data: bytes) -> int:
        n = os.write(fd, data)
        if not sent and _line_kind(data) == "correction":
            sent.append(json.loads(data.rpartition(b"\t")[0])[1])
            os.kill(os.getpid(), signal.SIGINT)
        return n

    monkeypatch.setattr(S, "_write_fd", write)
    with pytest.raises(KeyboardInterrupt):
        ct.run(max_steps=600)
    monkeypatch.setattr(S, "_write_fd", os.write)
    assert sent and [c.step for c in ct.corrections][-1] == sent[0]
    memory_equals_disk(ct, run)
    n = ct.n_steps
    ct.run(max_steps=n + 30)
    memory_equals_disk(ct, run)
    ct.close()


def test_a_ctrl_c_goes_to_the_handler_the_loop_found(tmp_path, monkeypatch):
    """The loop's hold only delays a SIGINT: a handler of the user's still gets every one,
    outside a write at once and inside one when memory and disk agree again, and a handler
    that does not raise lets teaching go on."""
    seen: list[int] = []
    old = signal.signal(signal.SIGINT, lambda signum, frame: seen.append(signum))
    try:
        run = tmp_path / "run"
        ct, env = session(run, noninteractive=False)
        ct.run(max_steps=5)
        os.kill(os.getpid(), signal.SIGINT)  # between steps: no hold
        assert seen == [signal.SIGINT]
        sent: list[bool] = []

        def write(fd: int, data: bytes) -> int:
            n = os.write(fd, data)
            if not sent:
                sent.append(True)
                os.kill(os.getpid(), signal.SIGINT)  # inside the hold around this line
            return n

        monkeypatch.setattr(S, "_write_fd", write)
        ct.run(max_steps=40)  # nothing raises: the handler only notes the signal
        assert sent and seen == [signal.SIGINT, signal.SIGINT] and ct.n_steps == 40
        monkeypatch.setattr(S, "_write_fd", os.write)
        goes_on(ct, env, run)
    finally:
        signal.signal(signal.SIGINT, old)


def test_a_ctrl_c_after_a_handler_of_ones_own_was_put_back_stops_the_loop(tmp_path):
    """A handler of one's own installed for a while and then put back as it was (old =
    signal.signal(SIGINT, mine) ... signal.signal(SIGINT, old)) left the loop's SIGINT hook
    handing every later Ctrl-C to that handler, long gone: a Ctrl-C no longer raised
    KeyboardInterrupt, in the loop or outside it (seen as the real-Ctrl-C tests failing after
    such a test). The hook put back hands it to what it wrapped, the default handler."""
    run = tmp_path / "run"
    ct, env = session(run, noninteractive=False)
    ct.run(max_steps=5)  # the loop's hold puts its hook in front of the default handler
    seen: list[int] = []
    old = signal.signal(signal.SIGINT, lambda signum, frame: seen.append(signum))
    try:
        ct.run(max_steps=10)  # a hold while one's own handler is in place
        os.kill(os.getpid(), signal.SIGINT)
        assert seen == [signal.SIGINT]
    finally:
        signal.signal(signal.SIGINT, old)
    with pytest.raises(KeyboardInterrupt):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(1)
    assert seen == [signal.SIGINT]
    goes_on(ct, env, run)


# -- what a new session or a resume must not take over ----------------------------------------


def test_a_new_session_does_not_take_over_a_journal_another_session_left(tmp_path):
    run = tmp_path / "run"
    ct, _ = session(run, commit_every=10**6, max_new=50)
    for _ in range(5):
        ct.step()
    crash(ct)  # the steps are in the journal only
    for name in ("config.json", "steps.sqlite", "steps.sqlite-wal", "steps.sqlite-shm"):
        (run / name).unlink(missing_ok=True)  # "starting over" by hand, the journal left
    with pytest.raises(
        IncompatibleRunDirError, match=r"holds what another session left \(steps.journal, "
    ):
        session(run)
    assert (run / "steps.journal").stat().st_size > 0  # refused without touching it


def test_a_new_session_does_not_take_over_a_writers_file_another_session_left(tmp_path):
    """A session created where another one left its writers.jsonl appended its writer to
    the other's: its first line said that writer started at the other's step 0, and the
    other's resumes read as this session's writers (thread counts, devices, from which step),
    the record that says which thread count reproduces which step. It is refused, as a
    journal or checkpoints left there are, and the file is left as it was; so is its
    runs.jsonl (where its run() calls began, which would move where this session's streak
    is counted from)."""
    run = tmp_path / "run"
    ct, _ = session(run)
    ct.run(max_steps=10)
    ct.close()
    back, _ = resume(run)
    back.run(max_steps=20)
    back.close()
    for name in ("config.json", "steps.sqlite"):  # "starting over" by hand
        (run / name).unlink()
    shutil.rmtree(run / "checkpoints")
    before = files_of(run)
    for left in ("runs.jsonl, writers.jsonl", "runs.jsonl"):
        with pytest.raises(
            IncompatibleRunDirError, match=rf"holds what another session left \({left}\)"
        ):
            session(run)
        assert files_of(run) == before
        assert not (run / "config.json").exists()
        (run / "writers.jsonl").unlink(missing_ok=True)  # moved away: runs.jsonl is still there
        before = files_of(run)
    (run / "runs.jsonl").unlink()  # moved away: a new session starts there
    ct, _ = session(run)
    ct.close()
    assert [json.loads(line)["first_step"] for line in (run / "writers.jsonl").open()] == [0]


def test_a_new_session_is_refused_in_a_folder_holding_files_of_ones_own(tmp_path):
    """ConfidentTeacher(..., run_dir=folder), the folder holding one's own script, wrote
    config.json, steps.sqlite, checkpoints/ and the rest beside it, while torchcbl teach
    --run-dir refused the same folder. Both refuse it now, by one rule (the store's): a new
    session needs a missing or empty folder, or one holding only what torchcbl leaves where a
    session could not start; the error says what is there and to pick another folder, and
    nothing is written there (no writer.lock either)."""
    run = tmp_path / "proj"
    run.mkdir()
    (run / "myteach.py").write_text("print('mine')\n")
    (run / "notes").mkdir()
    with pytest.raises(IncompatibleRunDirError) as info:
        session(run)
    msg = str(info.value)
    assert "myteach.py" in msg and "notes" in msg and "choose another run_dir" in msg, msg
    assert sorted(p.name for p in run.iterdir()) == ["myteach.py", "notes"]


def test_a_new_session_starts_beside_what_torchcbl_leaves_where_one_could_not_start(tmp_path):
    """What torchcbl itself leaves in a folder that holds no session (a failed start's
    writer.lock, a closed session's empty journal once its log went, an empty checkpoints/,
    the temporary files of a start killed mid-write) does not keep a new session out."""
    run = tmp_path / "run"
    run.mkdir()
    for name in ("writer.lock", "steps.journal", "writers.jsonl"):
        (run / name).write_bytes(b"")
    (run / "checkpoints").mkdir()
    (run / "checkpoints" / ".model-00000000.pt.tmp").write_bytes(b"torn")
    (run / "config.json.tmp").write_text("{")
    (run / ".prior.npz.tmp").write_bytes(b"torn")
    ct, _ = session(run)
    ct.run(max_steps=3)
    ct.close()
    assert len(load_records(run)) == 3


@pytest.mark.parametrize(
    "text", ['{"lr": 0.1}\n', "not json", '["torchcbl.session/2"]'], ids=["dict", "text", "list"]
)
def test_a_config_json_of_ones_own_is_not_called_a_session(tmp_path, text):
    """A folder holding one's own config.json (not a session's) was said to hold a teaching
    session, "Continue it with ConfidentTeacher.resume", whose resume then failed ("expected a
    session format ... got None"), and the refusal left a writer.lock there. The error now says
    that config.json is no torchcbl session's and to choose another folder, and nothing is
    written."""
    run = tmp_path / "proj"
    run.mkdir()
    (run / "config.json").write_text(text)
    with pytest.raises(IncompatibleRunDirError) as info:
        session(run)
    msg = str(info.value)
    assert "config.json" in msg and "not a torchcbl session" in msg, msg
    assert "resume" not in msg and "choose another run_dir" in msg, msg
    assert sorted(p.name for p in run.iterdir()) == ["config.json"]
    assert (run / "config.json").read_text() == text


def test_a_log_without_its_config_is_not_said_to_be_a_session_to_resume(tmp_path):
    """A folder holding a session's steps.sqlite whose config.json was deleted or moved was
    refused as one that "already holds a teaching session. Continue it with
    ConfidentTeacher.resume", and resume then said config.json is missing and to start a
    session there first: a dead end. It now says the config is missing, to put it back to
    continue that session or to choose another folder, and writes nothing."""
    run = tmp_path / "run"
    ct, _ = session(run)
    ct.run(max_steps=5)
    ct.close()
    (run / "config.json").rename(tmp_path / "config.json")
    before = files_of(run)
    with pytest.raises(IncompatibleRunDirError) as info:
        session(run)
    msg = str(info.value)
    assert "steps.sqlite" in msg and "config.json" in msg and "Put it back" in msg, msg
    assert "choose a new run_dir" in msg and "Continue it" not in msg, msg
    assert files_of(run) == before


def test_a_session_is_still_refused_as_a_session_and_nothing_is_written(tmp_path):
    """A session's own folder is refused as one, to be resumed, and the refusal writes nothing
    (its writer.lock is left as it was)."""
    run = tmp_path / "run"
    ct, _ = session(run)
    ct.run(max_steps=5)
    ct.close()
    before = files_of(run)
    with pytest.raises(IncompatibleRunDirError, match=r"already holds a teaching session.*resume"):
        session(run)
    assert files_of(run) == before


def test_resume_rebuilds_the_sessions_model_not_the_callers_fitted_one(tmp_path):
    """At 4 labels (no refit yet, max_new 50) the session has no model; a fitted model passed
    to resume must not decide in its place."""
    run = tmp_path / "run"
    ct, env = session(run, max_new=50)
    ct.run(max_steps=4)
    ct.close()
    assert not load_model(run).is_fitted
    m = GaussianMixtureSet(3, 2, seed=0)  # the session's model arguments, fitted elsewhere
    x, y = rare_regions_world().sample(300, np.random.default_rng(1))
    m.fit(x, 2 - y)
    back, _ = resume(run, model=m)
    assert not back.model.is_fitted
    assert back.step().model_action == -1
    back.close()


@pytest.mark.filterwarnings("error::UserWarning")  # a refused resume warns of nothing
def test_resume_compares_a_custom_strategy_by_its_class_name_and_relabel_flag(tmp_path):
    from torchcbl.strategies import correcting
    from torchcbl.strategies.bc import BehaviourCloning
    from torchcbl.strategies.cba import ConfidenceBasedAutonomy

    class Mine(BehaviourCloning):  # a user's strategy without to_config
        to_config = None
        relabel = True

    run = tmp_path / "run"
    env = rare_regions_world()
    cfg = TeachingConfig(max_new=5, noninteractive=False)
    with ConfidentTeacher(
        env,
        correcting(oracle(env)),
        strategy=ConfidenceBasedAutonomy(),
        config=cfg,
        run_dir=run,
        progress=False,
    ) as ct:
        ct.run(max_steps=10)
    with pytest.raises(IncompatibleRunDirError, match="strategy: stored"):
        ConfidentTeacher.resume(run, env, oracle(env), strategy=Mine(), progress=False)
    mine_run = tmp_path / "mine"
    with ConfidentTeacher(
        env, oracle(env), strategy=Mine(), config=cfg, run_dir=mine_run, progress=False
    ) as ct:
        ct.run(max_steps=10)
    ConfidentTeacher.resume(mine_run, env, oracle(env), strategy=Mine(), progress=False).close()
    # the same class imported from a package instead of run as a script: its name decides
    moved = type("Mine", (BehaviourCloning,), {"to_config": None, "relabel": True})
    moved.__module__ = "pkg.teach"
    ConfidentTeacher.resume(mine_run, env, oracle(env), strategy=moved(), progress=False).close()
    with pytest.raises(IncompatibleRunDirError, match="strategy: stored"):
        ConfidentTeacher.resume(mine_run, env, oracle(env), strategy=BehaviourCloning())


def test_resume_compares_what_gymnasium_make_was_given(tmp_path):
    run = tmp_path / "run"

    def teacher(obs, info):
        return 2 if obs[1] >= 0 else 0

    cfg = TeachingConfig(max_new=5)
    with ConfidentTeacher(
        gym.make("MountainCar-v0", goal_velocity=0.0),
        teacher,
        config=cfg,
        run_dir=run,
        progress=False,
    ) as ct:
        ct.run(max_steps=10)
    with pytest.raises(
        IncompatibleRunDirError, match=r"env kwargs .*'goal_velocity': \(0.0, 0.5\)"
    ):
        ConfidentTeacher.resume(run, gym.make("MountainCar-v0", goal_velocity=0.5), teacher)
    # the same kwargs, and another render mode, resume
    same = gym.make("MountainCar-v0", goal_velocity=0.0, render_mode="rgb_array")
    ConfidentTeacher.resume(run, same, teacher, progress=False).close()
    # gymnasium.make's step cap is part of the env: another one is refused, the same resumes
    with pytest.raises(
        IncompatibleRunDirError, match=r"'max_episode_steps': \(200, 5\).*max_episode_steps=200"
    ):
        ConfidentTeacher.resume(
            run, gym.make("MountainCar-v0", goal_velocity=0.0, max_episode_steps=5), teacher
        )
    capped = gym.make("MountainCar-v0", goal_velocity=0.0, max_episode_steps=200)
    ConfidentTeacher.resume(run, capped, teacher, progress=False).close()
    # a session written before the cap was kept resumes with any cap, as before
    config = json.loads((run / "config.json").read_text())
    del config["env"]["max_episode_steps"]
    (run / "config.json").write_text(json.dumps(config))
    short = gym.make("MountainCar-v0", goal_velocity=0.0, max_episode_steps=5)
    ConfidentTeacher.resume(run, short, teacher, progress=False).close()


class _FileWorld(gym.Wrapper):
    """rare_regions_world, told to depend on a file: describe_inputs() gives its digest."""

    def __init__(self, path: Path) -> None:
        super().__init__(rare_regions_world())
        self.path = path

    def describe_inputs(self) -> dict[str, str]:
        return {"centres_sha256": hashlib.sha256(self.path.read_bytes()).hexdigest()}

    @property
    def unwrapped(self):  # an env of one's own: the hook sits on the unwrapped env
        return self


def _file_world_session(tmp_path: Path) -> tuple[Path, Path, _FileWorld]:
    """(the file, the run, the env) of a 10-step session of a _FileWorld on a file of two
    centres, closed."""
    data = tmp_path / "centres.txt"
    data.write_text("0 0\n4 4\n")
    run = tmp_path / "run"
    env = _FileWorld(data)
    with ConfidentTeacher(env, oracle(env.env), run_dir=run, progress=False) as ct:
        ct.run(max_steps=10)
    return data, run, env


def test_resume_refuses_an_env_whose_described_inputs_changed(tmp_path):
    """An env that reads more than its make() arguments (a file) describes it: the session
    keeps the description and a resume on the file edited since is refused, naming what
    differs; the file put back resumes, and a session that kept none resumes as before."""
    data, run, env = _file_world_session(tmp_path)
    kept = load_config(run)["env"]["inputs"]
    assert kept == {"centres_sha256": hashlib.sha256(data.read_bytes()).hexdigest()}
    data.write_text("0 0\n5 5\n")
    with pytest.raises(IncompatibleRunDirError, match=r"env inputs \(stored, given\): "):
        ConfidentTeacher.resume(run, env, oracle(env.env), progress=False)
    assert len(load_records(run)) == 10
    data.write_text("0 0\n4 4\n")
    ConfidentTeacher.resume(run, env, oracle(env.env), progress=False).close()
    data.rename(tmp_path / "moved.txt")  # describe_inputs() raises: an EnvError, as the loop's
    with pytest.raises(EnvError, match=r"_FileWorld.describe_inputs\(\) raised FileNotFound"):
        ConfidentTeacher.resume(run, env, oracle(env.env), progress=False)
    (tmp_path / "moved.txt").rename(data)
    config = load_config(run)
    del config["env"]["inputs"]  # as a session written before 2026-11-27
    (run / "config.json").write_text(json.dumps(config))
    data.write_text("0 0\n5 5\n")
    ConfidentTeacher.resume(run, env, oracle(env.env), progress=False).close()


def test_resume_compares_the_described_inputs_both_sides_describe(tmp_path, monkeypatch):
    """A key the env describes that the session did not keep (a later version of the env
    describing a new input, e.g. a new field of a driving scenario) refused every session kept
    before it; the keys both describe are compared, as a kept object's fields are: a new key
    alone resumes, a differing common one is refused (True against 1 too)."""
    data, run, env = _file_world_session(tmp_path)
    digest = hashlib.sha256(data.read_bytes()).hexdigest()
    later = {"centres_sha256": digest, "weather": "dry"}
    monkeypatch.setattr(_FileWorld, "describe_inputs", lambda self: later)
    ConfidentTeacher.resume(run, env, oracle(env.env), progress=False).close()
    config = load_config(run)
    config["env"]["inputs"]["lanes"] = 1
    (run / "config.json").write_text(json.dumps(config))
    monkeypatch.setattr(_FileWorld, "describe_inputs", lambda self: {**later, "lanes": True})
    with pytest.raises(
        IncompatibleRunDirError, match=r"env inputs \(stored, given\): \{'lanes': \(1, True\)\}"
    ):
        ConfidentTeacher.resume(run, env, oracle(env.env), progress=False)


@pytest.mark.parametrize("value", [object(), math.nan, np.int64(3)], ids=["object", "nan", "int64"])
def test_a_describe_inputs_that_is_no_dict_of_plain_values_is_named(tmp_path, value):
    """Also NaN, which JSON keeps but which never equals itself (every resume was refused)."""
    env = _FileWorld(tmp_path / "x")
    env.describe_inputs = lambda: {"when": value}
    with pytest.raises(TypeError, match=r"_FileWorld.describe_inputs\(\) must return a dict"):
        ConfidentTeacher(env, oracle(env.env), run_dir=tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()


def test_a_resume_refused_for_a_model_that_is_no_gmm_set_reads_as_one_sentence(tmp_path):
    run = tmp_path / "run"
    _closed_session(run)
    with pytest.raises(IncompatibleRunDirError) as err:
        resume(run, model=torch.nn.Linear(2, 2))
    msg = str(err.value)
    assert "Pass a torchcbl.GaussianMixtureSet as model. Resume with matching" in msg
    assert ".." not in msg


def test_the_cap_kept_is_the_one_in_force_under_an_outer_time_limit(tmp_path):
    def teacher(obs, info):
        return 2 if obs[1] >= 0 else 0

    for outer, in_force in ((1000, 200), (50, 50)):
        run = tmp_path / f"run{outer}"
        env = gym.wrappers.TimeLimit(gym.make("MountainCar-v0"), outer)
        with ConfidentTeacher(
            env, teacher, config=TeachingConfig(max_new=5), run_dir=run, progress=False
        ) as ct:
            ct.run(max_steps=10)
        assert load_config(run)["env"]["max_episode_steps"] == in_force
        # the plain env with the cap in force resumes (it stored the outer 1000 before)
        plain = gym.make("MountainCar-v0", max_episode_steps=in_force)
        ConfidentTeacher.resume(run, plain, teacher, progress=False).close()
    # a session that stored the outer 1000 (before the cap in force was kept) resumes with the
    # env it was made with
    config = json.loads((tmp_path / "run1000" / "config.json").read_text())
    config["env"]["max_episode_steps"] = 1000
    (tmp_path / "run1000" / "config.json").write_text(json.dumps(config))
    same = gym.wrappers.TimeLimit(gym.make("MountainCar-v0"), 1000)
    ConfidentTeacher.resume(tmp_path / "run1000", same, teacher, progress=False).close()


def test_the_cap_kept_is_the_envs_own_so_a_resume_never_changes_it(tmp_path):
    """A corridor env made by gymnasium.make has no TimeLimit: its cap is its own, resolved
    from the map when not given (81, or two circuits of a longer route), and the session kept
    only the spec's None. A session on a map whose circuit takes more than 40 actions, taught
    when the default was 81, resumed with today's 2 circuits without a word. The cap in force
    is now kept, so an env whose own cap differs (as another version's default would give) is
    refused, naming the cap and how to make the env with it."""
    import corridor
    from corridor.expert import CorridorExpert

    loop = tmp_path / "loop.json"
    loop.write_text(
        json.dumps(
            {
                "name": "loop",
                "corridor_width": 0.6,
                "nodes": {"A": [0, 0], "B": [6.0, 0], "C": [6.0, 4.0], "D": [0, 4.0]},
                "corridors": [["A", "B"], ["B", "C"], ["C", "D"], ["D", "A"]],
                "route": ["A", "B", "C", "D", "A"],
            }
        )
    )

    def make(cap=None):
        env = gym.make(corridor.ENV_ID, corridor_map=str(loop))
        if cap is not None:  # the env as a version with another default makes it
            env.unwrapped.max_episode_steps = cap
        return env

    env = make()
    teacher = CorridorExpert(env.unwrapped.corridor_map)
    run = tmp_path / "run"
    with ConfidentTeacher(env, teacher, run_dir=run, progress=False) as ct:
        ct.run(max_steps=5)
    assert env.unwrapped.max_episode_steps == 192
    assert load_config(run)["env"]["max_episode_steps"] == 192
    with pytest.raises(
        IncompatibleRunDirError, match=r"'max_episode_steps': \(192, 81\).*max_episode_steps=192"
    ):
        ConfidentTeacher.resume(run, make(cap=81), teacher, progress=False)
    ConfidentTeacher.resume(run, make(), teacher, progress=False).close()
    # a session that kept the spec's None (before the cap in force was kept) still resumes
    config = json.loads((run / "config.json").read_text())
    config["env"]["max_episode_steps"] = None
    (run / "config.json").write_text(json.dumps(config))
    ConfidentTeacher.resume(run, make(), teacher, progress=False).close()


# -- 7. a gap in the step numbers ----------------------------------------------------------


def test_a_step_deleted_from_the_log_is_named_and_resume_refuses(tmp_path):
    run = tmp_path / "run"
    _closed_session(run)
    log = run / "steps.sqlite"
    kept = log.read_bytes()
    db = sqlite3.connect(log)
    db.execute("DELETE FROM steps WHERE step IN (5, 6)")
    db.commit()
    db.close()
    with pytest.warns(UserWarning, match=r"lacks 2 steps \(5, 6\) before its last one"):
        records = load_records(run)
    assert [r.step for r in records] == [s for s in range(60) if s not in (5, 6)]
    before = files_of(run)
    # Before: resume went on, numbered its first step len(records) = 58, which the log held,
    # and every later commit failed.
    with pytest.raises(CorruptSessionError, match=r"lacks 2 steps \(5, 6\).*Nothing was changed"):
        resume(run)
    assert files_of(run) == before
    log.write_bytes(kept)  # restored from a backup
    (run / "steps.sqlite-wal").unlink(missing_ok=True)
    (run / "steps.sqlite-shm").unlink(missing_ok=True)
    back, env = resume(run)
    goes_on(back, env, run)


def test_a_line_removed_from_the_journal_is_refused_then_repaired(tmp_path):
    run = tmp_path / "run"
    ct, env = _journalled(run, steps=10)
    journal = run / "steps.journal"
    lines = journal.read_bytes().split(b"\n")
    at = next(i for i, line in enumerate(lines) if line.startswith(b'["s",25,'))
    journal.write_bytes(b"\n".join(lines[:at] + lines[at + 1 :]))  # step 25's line is gone
    with pytest.warns(UserWarning, match=r"lacks 1 step \(25\).*or lines from steps.journal"):
        load_records(run)
    with pytest.raises(CorruptSessionError, match="repair_journal"):
        resume(run)
    report = repair_journal(run)
    assert "a step is missing" in report and "steps.journal.damaged" in report
    # step 25's outcome line, which followed its step line, goes with it (an outcome of no
    # step of the log), and so does every later line: the journal keeps the lines before
    assert b"".join(lines[at + 1 : at + 2]).startswith(b'["f",') and b",25]\t" in lines[at + 1]
    assert journal.read_bytes() == b"".join(line + b"\n" for line in lines[:at])
    back, env2 = resume(run)
    assert back.records == ct.records[:25]  # the steps before the gap; the rest in the copy
    goes_on(back, env2, run)


# -- a session that starts from a fitted model ------------------------------------------------


def _fitted_start() -> tuple[gym.Env, GaussianMixtureSet]:
    env = rare_regions_world()
    x, y = env.sample(120, np.random.default_rng(0))
    return env, GaussianMixtureSet(3, 2, seed=0).fit(x, y)


def _started_from(run: Path, model: GaussianMixtureSet) -> None:
    """Either ``run`` holds no session, or one that resumes with the model it started from."""
    if not (run / "config.json").exists():
        with pytest.raises(IncompatibleRunDirError):
            load_config(run)
        return
    env = rare_regions_world()
    back = ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    try:
        assert back.model.is_fitted, "resumed without the model the session started from"
        assert same_state(back.model, model)
        assert same_state(load_model(run), model)
    finally:
        back.close()


def test_a_session_from_a_fitted_model_that_cannot_save_it_leaves_no_session(tmp_path, monkeypatch):
    """Disk full as the starting model's checkpoint 0 is written: the constructor fails and
    leaves no session behind (there was one, which resumed with an unfitted model: no label
    can refit the model a session starts from); once space is freed the session starts."""
    env, fitted = _fitted_start()
    run = tmp_path / "run"
    real = torch.save

    def full(obj, f, *args, **kw):
        if isinstance(obj, dict) and obj.get("n_demonstrations") == 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(obj, f, *args, **kw)

    monkeypatch.setattr(S.torch, "save", full)
    config = TeachingConfig(max_new=5, noninteractive=False)
    with pytest.raises(SessionWriteError, match="model-00000000.pt") as err:
        ConfidentTeacher(env, oracle(env), model=fitted, config=config, run_dir=run)
    assert "left without a session" in " ".join(getattr(err.value, "__notes__", []))
    _started_from(run, fitted)
    monkeypatch.setattr(S.torch, "save", real)
    ct = ConfidentTeacher(
        env, oracle(env), model=fitted, config=config, run_dir=run, progress=False
    )
    ct.run(max_steps=3)  # fewer labels than max_new: still the model it started from
    ct.close()
    _started_from(run, fitted)


_KILLED_AT_CHECKPOINT_0 = """
import os, signal, sys
import numpy as np, torch
sys.path[:0] = [{tests!r}, {root!r}]
from _toy_envs import oracle, rare_regions_world
from torchcbl import ConfidentTeacher, GaussianMixtureSet, TeachingConfig
from torchcbl import session as S
env = rare_regions_world()
x, y = env.sample(120, np.random.default_rng(0))
fitted = GaussianMixtureSet(3, 2, seed=0).fit(x, y)
torch.save(fitted.state_dict(), {started!r})
real = torch.save
def save(obj, f, *args, **kw):
    if isinstance(obj, dict) and obj.get("n_demonstrations") == 0:
        real(obj, f, *args, **kw)
        os.kill(os.getpid(), signal.SIGKILL)  # killed as checkpoint 0 is written
    return real(obj, f, *args, **kw)
S.torch.save = save
ConfidentTeacher(env, oracle(env), model=fitted, config=TeachingConfig(max_new=5),
                 run_dir={run!r}, progress=False)
"""


def test_a_session_from_a_fitted_model_killed_as_it_starts_resumes_with_that_model(tmp_path):
    """SIGKILL while the starting model's checkpoint 0 is written: the directory holds no
    session, never one that resumes with an unfitted model in place of the one it started
    from (a config.json was written before checkpoint 0)."""
    run, started = tmp_path / "run", tmp_path / "started.pt"
    code = _KILLED_AT_CHECKPOINT_0.format(
        tests=str(TESTS), root=str(TESTS.parent), started=str(started), run=str(run)
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    fitted = GaussianMixtureSet(3, 2, seed=0)
    fitted.load_state_dict(torch.load(started, weights_only=True))
    _started_from(run, fitted)


_KILLED_AFTER_CONFIG = """
import os, signal, sys
import numpy as np
sys.path[:0] = [{tests!r}, {root!r}]
from _toy_envs import oracle, rare_regions_world
from torchcbl import ConfidentTeacher, GaussianMixtureSet, TeachingConfig
from torchcbl import session as S
env = rare_regions_world()
model = GaussianMixtureSet(3, 2, seed=0)
if {fitted!r}:
    model.fit(*env.sample(120, np.random.default_rng(0)))
real, connect = S.write_json_atomic, S.sqlite3.connect
def write(path, data):
    real(path, data)
    if {where!r} == "config":
        os.kill(os.getpid(), signal.SIGKILL)  # config.json is written, the step log is not yet
class Killing:  # the log's connection: SIGKILL after WAL mode is asked for, or the tables
    def __init__(self, db): self.db = db
    def __getattr__(self, name): return getattr(self.db, name)
    def execute(self, sql, *args):
        out = self.db.execute(sql, *args)
        if {where!r} == "wal" and sql.startswith("PRAGMA journal_mode"):
            os.kill(os.getpid(), signal.SIGKILL)  # an empty file and SQLite's hot -journal
        return out
    def executescript(self, sql):
        out = self.db.executescript(sql)
        if {where!r} == "schema":
            os.kill(os.getpid(), signal.SIGKILL)  # the tables, and not our journal yet
        return out
def open_log(database, *args, **kw):
    db = connect(database, *args, **kw)
    if str(database).endswith("steps.sqlite") and {where!r} == "connect":
        os.kill(os.getpid(), signal.SIGKILL)  # an empty file: no header, no table
    return Killing(db) if str(database).endswith("steps.sqlite") else db
S.write_json_atomic, S.sqlite3.connect = write, open_log
ConfidentTeacher(env, oracle(env), model=model, config=TeachingConfig(max_new=5),
                 run_dir={run!r}, progress=False)
"""


@pytest.mark.parametrize(
    ("where", "fitted"),
    [("config", False), ("config", True), ("connect", False), ("wal", False), ("schema", False)],
    ids=["no-log", "no-log-fitted-model", "log-empty", "log-empty-hot-journal", "log-tables"],
)
def test_a_session_killed_between_its_config_and_its_log_resumes_as_a_new_one(
    tmp_path, where, fitted
):
    """SIGKILL after a new session's config.json was written and before its log was opened
    in full (no log, an empty file, one with SQLite's hot -journal, one with its tables but
    not our journal): the directory was no session for a
    new teacher ("already holds a teaching session") and a broken one for resume and the
    readers ("steps.sqlite is missing ... put it back", "no such table: steps"), a dead end.
    Nothing of it ran, so it reads as a session of no step, and resumes into the run the
    uninterrupted session makes."""
    run = tmp_path / "run"
    code = _KILLED_AFTER_CONFIG.format(
        tests=str(TESTS), root=str(TESTS.parent), fitted=fitted, run=str(run), where=where
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    log = run / "steps.sqlite"
    assert (where == "config") == (not log.exists()) and (run / "config.json").exists()
    assert load_records(run) == []
    env = rare_regions_world()
    ct = ConfidentTeacher.resume(run, env, oracle(env), progress=False)
    ct.run(max_steps=30)
    ct.close()
    model = GaussianMixtureSet(3, 2, seed=0)
    if fitted:
        model.fit(*env.sample(120, np.random.default_rng(0)))
    whole = tmp_path / "whole"
    cfg = TeachingConfig(max_new=5)
    env = rare_regions_world()
    with ConfidentTeacher(
        env, oracle(env), model=model, config=cfg, run_dir=whole, progress=False
    ) as ct:
        ct.run(max_steps=30)
    assert load_records(run) == load_records(whole)
    # a session that ran, without its journal, writers file and checkpoints: read as it is,
    # and the look at its log for tables creates no -wal or -shm (a reader writes nothing)
    bare = tmp_path / "bare"
    shutil.copytree(whole, bare)
    for path in (bare / "steps.journal", bare / "writers.jsonl", *bare.glob("checkpoints/*")):
        path.unlink()
    assert load_records(bare) == load_records(whole)
    assert not list(bare.glob("steps.sqlite-*"))
    # a log deleted from a session that ran is still named, not taken for an unborn one,
    # with its writers file and checkpoints gone too (its journal says it opened)
    for path in (whole / "steps.sqlite", whole / "writers.jsonl", *whole.glob("checkpoints/*")):
        path.unlink()
    with pytest.raises(CorruptSessionError, match="steps.sqlite is missing"):
        load_records(whole)


@pytest.mark.parametrize("damage", ["deleted", "garbage"])
@pytest.mark.parametrize("refit", ["full", "incremental"])
def test_a_lost_starting_model_is_named_not_replaced_by_a_fresh_one(tmp_path, damage, refit):
    """Checkpoint 0 of a session started from a fitted model deleted (the docs say a missing
    checkpoint is refitted from the log) or damaged: where the session's model still stands on
    it (no refit since, or incremental refits that start from it) resume and load_model refuse
    with CorruptSessionError naming the file and leave it as it is; they rebuilt an unfitted
    model, or a fit from scratch, in its place. A full refit since does not need it."""
    env, fitted = _fitted_start()
    run = tmp_path / "run"
    config = TeachingConfig(max_new=4, refit=refit, noninteractive=False)
    ct = ConfidentTeacher(
        env, oracle(env), model=fitted, config=config, run_dir=run, progress=False
    )
    ct.run(max_steps=40)
    assert 4 <= ct.n_demonstrations < 40  # refits came, and autonomous steps on the model
    live = ct.model.state_dict()
    ct.close()
    zero = run / "checkpoints" / "model-00000000.pt"
    for later in zero.parent.glob("model-*.pt"):  # as if killed before any later was saved
        if later != zero:
            later.unlink()
    if damage == "deleted":
        zero.unlink()
    else:
        zero.write_bytes(b"not a checkpoint")
    before = files_of(run)
    if refit == "full":  # a fit from scratch on the labels is the live model
        assert same_state(load_model(run), ct.model)
        back, _ = resume(run)
        assert all(torch.equal(back.model.state_dict()[k], v) for k, v in live.items())
        back.close()
        return
    with pytest.raises(CorruptSessionError, match=r"started from a fitted model.*model-00000000"):
        load_model(run)
    with pytest.raises(CorruptSessionError, match=r"incremental refits start from it"):
        resume(run)
    assert (zero.exists(), damage) in ((False, "deleted"), (True, "garbage"))
    assert files_of(run).keys() == before.keys()  # nothing set aside


def test_a_session_still_on_its_starting_model_refuses_to_resume_without_it(tmp_path):
    env, fitted = _fitted_start()
    run = tmp_path / "run"
    config = TeachingConfig(max_new=50, noninteractive=False)
    ct = ConfidentTeacher(
        env, oracle(env), model=fitted, config=config, run_dir=run, progress=False
    )
    ct.run(max_steps=10)
    assert ct.model.is_fitted and any(r.autonomous for r in ct.records)
    ct.close()
    (run / "checkpoints" / "model-00000000.pt").unlink()
    with pytest.raises(CorruptSessionError, match="no refit came since"):
        resume(run)
    with pytest.raises(CorruptSessionError, match="no refit came since"):
        S.load_policy(run)


def test_a_later_checkpoint_this_model_cannot_load_replays_from_the_starting_model(tmp_path):
    """A session started from a fitted model, refit="incremental": its newest checkpoint has
    the right labels but a state this model cannot load (written by another model class).
    The refits were replayed from a fit from scratch, a model unlike the live one; they are
    now replayed from checkpoint 0, the starting model, as the live loop made them."""
    env, fitted = _fitted_start()
    run = tmp_path / "run"
    config = TeachingConfig(max_new=4, refit="incremental", noninteractive=False)
    ct = ConfidentTeacher(
        env, oracle(env), model=fitted, config=config, run_dir=run, progress=False
    )
    ct.run(max_steps=40)
    assert ct.n_demonstrations >= 8  # two refits at least: a checkpoint after checkpoint 0
    ct.close()
    newest = max((run / "checkpoints").glob("model-*.pt"))
    assert newest.name != "model-00000000.pt"
    payload = torch.load(newest, weights_only=True)
    payload["state_dict"] = {"not_this_model": torch.zeros(1)}
    torch.save(payload, newest)
    assert same_state(load_model(run), ct.model)
    back, _ = resume(run)
    assert same_state(back.model, ct.model)
    back.close()


def test_a_replay_from_the_starting_model_goes_through_a_refit_by_hand_below(tmp_path):
    """refit="incremental" from a fitted model, refitted by hand at 6 (max_new=4): its newest
    checkpoint (10) holds a state this model cannot load, so the refits are replayed from
    checkpoint 0. That replay went 4, 8, 10 (the regular schedule, then the count it ends
    on), not 4, 6, 10 as the live loop refitted: the checkpoints below the one it could not
    load record the refit by hand, and the replay now goes through them. (Two components at
    most, each action fitted on about 40 points: the refits are warm, so the path shows.)"""
    env = rare_regions_world()
    x, y = env.sample(120, np.random.default_rng(0))
    fitted = GaussianMixtureSet(3, 2, max_components=2, seed=0).fit(x, y)
    run = tmp_path / "run"
    config = TeachingConfig(max_new=4, refit="incremental", noninteractive=False)
    ct = ConfidentTeacher(
        env, oracle(env), model=fitted, config=config, run_dir=run, progress=False
    )
    ct.run(max_demonstrations=6)
    assert ct.refit()  # by hand, at 6
    ct.run(max_demonstrations=11)  # the loop refits at 10
    ct.close()
    assert sorted(p.name for p in (run / "checkpoints").iterdir())[1:] == [
        f"model-{n:08d}.pt" for n in (4, 6, 10)
    ]
    newest = run / "checkpoints" / "model-00000010.pt"
    payload = torch.load(newest, weights_only=True)
    payload["state_dict"] = {"not_this_model": torch.zeros(1)}
    torch.save(payload, newest)
    assert same_state(load_model(run), ct.model)
    back, _ = resume(run)
    assert same_state(back.model, ct.model)
    back.close()


# -- power cuts: every file put in place is on the disk ---------------------------------------


def test_every_file_put_in_place_is_flushed_before_its_rename_and_its_directory_after(
    tmp_path, monkeypatch
):
    """config.json, prior.npz, the checkpoints, a repaired journal, the benchmark's cells and
    results.json, and the evaluation's files were written to a temporary name and renamed over
    the target, but (in the session) never fsynced: after a power cut the rename can be on the
    disk and the content not, so config.json or a checkpoint read back empty; and no directory
    was fsynced after its rename (the benchmark and evaluation fsynced the file only), so the
    rename itself could be lost. A power cut cannot be staged here; the test records each
    os.replace torchcbl makes and checks that the renamed file's own inode was fsynced before
    it and its directory after it, which is what makes the file survive one."""
    from torchcbl.cli import main
    from torchcbl.evaluation import write_atomically

    events: list[tuple[str, tuple[int, int], Path | None]] = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        st = os.fstat(fd)
        events.append(("fsync", (st.st_dev, st.st_ino), None))
        return real_fsync(fd)

    def replace(src, dst, *args, **kwargs):
        st = os.stat(src)
        events.append(("replace", (st.st_dev, st.st_ino), Path(dst)))
        return real_replace(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)

    run = tmp_path / "run"
    env = Witness(rare_regions_world())
    prior = env.unwrapped.sample(30, np.random.default_rng(0))
    ct = ConfidentTeacher(
        env,
        env.teacher,
        config=TeachingConfig(max_new=2, accuracy_window=10),
        run_dir=run,
        progress=False,
        prior_demonstrations=prior,
    )
    env.ct = ct
    ct.run(max_steps=20)
    ct._store.commit_every = 10**6  # the next steps only in the journal, then a line lost
    for _ in range(6):
        ct.step()
    crash(ct)
    journal = run / "steps.journal"
    lines = journal.read_bytes().split(b"\n")
    journal.write_bytes(b"\n".join(lines[:1] + lines[2:]))
    repair_journal(run)
    write_atomically(tmp_path / "summary.md", "done\n")
    argv = ["benchmark", "--envs", "", "--gym-env", "_bench_env:BenchCluster-v0"]
    argv += ["--teacher", "_bench_env:teacher", "--strategies", "bc"]
    argv += ["--seeds", "1", "--budgets", "5", "--max-steps", "10", "--eval-episodes", "1"]
    argv += ["--workers", "1", "--out", str(tmp_path / "bench")]
    assert main(argv) == 0

    renamed = {}
    for i, (kind, inode, dst) in enumerate(events):
        if kind != "replace":
            continue
        st = os.stat(dst.parent)
        directory = (st.st_dev, st.st_ino)
        renamed[dst.relative_to(tmp_path).as_posix()] = (
            ("fsync", inode, None) in events[:i],
            ("fsync", directory, None) in events[i + 1 :],
        )
    for name in (
        "run/prior.npz",
        "run/config.json",
        "run/checkpoints/model-00000000.pt",
        "run/checkpoints/model-00000002.pt",
        "run/steps.journal",
        "summary.md",
        "bench/results.json",
    ):
        assert renamed.pop(name) == (True, True), name
    cells = [n for n in renamed if n.startswith("bench/cells/")]
    assert cells and all(renamed.pop(n) == (True, True) for n in cells), cells
    assert all(v == (True, True) for v in renamed.values()), renamed


@pytest.mark.parametrize("refused_for", ["a session", "what a session left"])
def test_a_new_session_refused_on_an_existing_one_leaves_its_count_in_writer_lock(
    tmp_path, refused_for
):
    """Starting a new session in a directory that holds one (or what one left: its log and
    config moved aside for a moment) is refused; but the refusal came after the new writer
    had noted itself in writer.lock as a new session's, without the last writer's count
    line. Steps then lost from that session's log (here its last 4 rows, as a lost -wal
    loses them) read as a shorter session with no word. The count survives the refusal, and
    the loss is an error."""
    run, aside = tmp_path / "run", tmp_path / "aside"
    ct, env = session(run, commit_every=4)
    ct.run(max_steps=20)
    ct.close()
    moved = ("config.json", "steps.sqlite") if refused_for.startswith("what") else ()
    aside.mkdir()
    for name in moved:
        shutil.move(run / name, aside / name)
    with pytest.raises(IncompatibleRunDirError, match="already holds|another session left"):
        session(run)
    for name in moved:
        shutil.move(aside / name, run / name)
    db = sqlite3.connect(run / "steps.sqlite")
    db.execute("DELETE FROM steps WHERE step >= 16")
    db.commit()
    db.close()
    with pytest.raises(CorruptSessionError, match="committed 20 steps"):
        load_records(run)


# -- a session that fails at its first step ---------------------------------------------------


class _DeclaresThree(gym.Wrapper):
    """A 2-D world whose observation space is declared 3-D (a user's mistake): reset fails."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(3,), dtype=np.float32)


def test_a_new_session_whose_first_step_fails_leaves_no_session_to_block_a_rerun(tmp_path):
    """An env whose first reset failed (declared (3,), returned (2,)) left a session of no
    step in its run_dir: re-running the cell with the env fixed was refused ("already holds a
    teaching session") and resume refused the fixed env (its space differs). Nothing was
    recorded, so nothing is lost: the session made by that teacher is removed again, the
    error says so, and the same run_dir starts the fixed session."""
    run = tmp_path / "run"
    world = rare_regions_world()
    ct = ConfidentTeacher(_DeclaresThree(world), oracle(world), run_dir=run, progress=False)
    with pytest.raises(EnvError, match=r"shape \(3,\), got \(2,\)") as info:
        ct.run(max_steps=5)
    assert "nothing was recorded" in "\n".join(info.value.__notes__)
    ct.close()
    assert not (run / "config.json").exists() and not (run / "steps.sqlite").exists()
    with pytest.raises(IncompatibleRunDirError, match="closed after its first step failed"):
        ct.run(max_steps=5)  # closed: it does not write the session again
    assert not (run / "config.json").exists()
    with ConfidentTeacher(world, oracle(world), run_dir=run, progress=False) as ct:
        ct.run(max_steps=5)
    assert len(load_records(run)) == 5


def test_a_teacher_error_at_step_0_lets_the_cell_run_again_with_other_model_settings(tmp_path):
    """A teacher error at step 0 ("Nothing was recorded") left a session whose stored model
    settings then refused both a new session and a resume with the settings changed."""
    run = tmp_path / "run"
    world = rare_regions_world()
    with pytest.raises(TeacherError, match="at step 0"):
        with ConfidentTeacher(world, lambda o, i: 7, run_dir=run, progress=False) as ct:
            ct.run(max_steps=5)
    model = GaussianMixtureSet(3, 2, var_floor=0.01)
    with ConfidentTeacher(world, oracle(world), model=model, run_dir=run, progress=False) as ct:
        ct.run(max_steps=5)
    assert S.load_config(run)["model"]["args"]["var_floor"] == 0.01


def test_a_retry_on_the_same_teacher_after_a_failed_first_step_records_the_session(tmp_path):
    """The teacher whose first reset failed goes on when run() is called again (a passing
    fault): its session is made again, with its prior demonstrations, and resumes."""
    run = tmp_path / "run"
    world = rare_regions_world()
    x, y = world.sample(30, np.random.default_rng(0))
    calls = []

    class FlakyReset(gym.Wrapper):
        def reset(self, **kw):
            calls.append(1)
            if len(calls) == 1:
                raise OSError("simulator not up yet")
            return self.env.reset(**kw)

    ct = ConfidentTeacher(
        FlakyReset(world), oracle(world), prior_demonstrations=(x, y), run_dir=run, progress=False
    )
    with pytest.raises(EnvError, match="simulator not up yet"):
        ct.run(max_steps=5)
    assert not (run / "config.json").exists()
    ct.run(max_steps=5)
    ct.close()
    assert len(load_records(run)) == 5 and S.load_config(run)["prior"]["n_demonstrations"] == 30
    ct2 = ConfidentTeacher.resume(run, world, oracle(world), progress=False)
    assert ct2.n_steps == 5 and ct2.n_prior == 30
    ct2.close()


def test_a_session_of_no_step_is_kept_where_it_was_resumed_or_stopped_by_the_user(tmp_path):
    """Only a session this teacher made and that recorded nothing is removed, and only on an
    error: one stopped by Ctrl-C or 'q' at its first request is kept (it resumes), and a resumed
    session of no step whose first step fails stays too (the user resumed it)."""
    run = tmp_path / "run"
    world = rare_regions_world()

    for stop in (KeyboardInterrupt, TeachingInterrupted):

        def teacher(obs, info, stop=stop):
            raise stop("not now")

        where = tmp_path / stop.__name__
        ct = ConfidentTeacher(world, teacher, run_dir=where, progress=False)
        with pytest.raises(stop):
            ct.run(max_steps=5)
        ct.close()
        assert load_records(where) == []
    run = tmp_path / "KeyboardInterrupt"
    ct = ConfidentTeacher.resume(run, world, lambda o, i: 7, progress=False)
    with pytest.raises(TeacherError):
        ct.run(max_steps=5)
    ct.close()
    assert load_records(run) == []
    with ConfidentTeacher.resume(run, world, oracle(world), progress=False) as ct:
        ct.run(max_steps=5)
    assert len(load_records(run)) == 5
    with pytest.raises(IncompatibleRunDirError, match="was closed, so .*resume"):
        ct.run(max_steps=10)


def test_a_first_step_interrupted_just_after_its_journal_line_keeps_the_session(
    tmp_path, monkeypatch
):
    """An exception from a signal handler (an alarm, an async timeout) landing just after the
    first journal line was written, before the store noted it, made the failed first step read
    as one that recorded nothing: the session, demonstration and all, was removed, with a note
    saying nothing was recorded (review, 2026-11-27). A store counts a line as written from the
    moment it begins to write it."""
    run = tmp_path / "run"
    world = rare_regions_world()
    real = S._write_fd

    class Alarm(Exception):
        pass

    def write_then_alarm(fd, data):
        real(fd, data)
        raise Alarm("the alarm went off")

    monkeypatch.setattr(S, "_write_fd", write_then_alarm)
    ct = ConfidentTeacher(world, oracle(world), run_dir=run, progress=False)
    with pytest.raises(Alarm) as info:
        ct.run(max_steps=3)
    assert "nothing was recorded" not in "\n".join(getattr(info.value, "__notes__", []))
    monkeypatch.setattr(S, "_write_fd", real)
    ct.close()
    assert (run / "config.json").exists() and (run / "steps.journal").stat().st_size > 0
    back = ConfidentTeacher.resume(run, world, oracle(world), progress=False)
    assert back.n_steps == 1  # the demonstration whose line reached the journal
    back.close()


class _Killed(BaseException):
    """The process killed (SIGKILL) at that point: nothing after it runs."""


class _ResetFails(gym.Wrapper):
    def reset(self, **kw):
        raise OSError("simulator not up")


def _resumed_or_new(run: Path, world: object) -> str:
    """What a folder left by a killed or failed start of a session with a prior of 30 labels
    takes: ``"resumed"`` (that session, of no step, resumes and runs 3 steps) or ``"new"``
    (a new session starts there, keeping nothing of the killed one, and runs 3 steps)."""
    if (run / "config.json").exists():
        with ConfidentTeacher.resume(run, world, oracle(world), progress=False) as ct:
            assert ct.n_steps == 0 and ct.n_prior == 30
            ct.run(max_steps=3)
        outcome = "resumed"
    else:
        with ConfidentTeacher(world, oracle(world), run_dir=run, progress=False) as ct:
            ct.run(max_steps=3)
        assert "prior" not in S.load_config(run)  # not the killed start's
        assert not (run / "prior.npz").exists()
        assert not (run / "checkpoints" / "model-00000000.pt").exists()
        outcome = "new"
    assert len(load_records(run)) == 3
    return outcome


def test_a_kill_while_a_failed_first_step_is_undone_leaves_a_session_or_room_for_one(
    tmp_path, monkeypatch
):
    """The removal of a session whose first step failed deleted config.json first: killed
    right after, it left steps.sqlite with no config, and the next start was refused as a
    session whose config was deleted. Killed after any of its removals (k = 0, 1, ...), the
    folder now either resumes as the session of no step or starts a new session."""
    world = rare_regions_world()
    x, y = world.sample(30, np.random.default_rng(0))  # prior.npz and checkpoint 0 too
    done = {"n": 0, "at": None}
    real = {f: getattr(Path, f) for f in ("unlink", "rmdir", "replace", "rename")}

    def killing(f):
        def op(self, *args, **kw):
            if done["at"] is not None:
                if done["n"] == done["at"]:
                    raise _Killed
                done["n"] += 1
            return real[f](self, *args, **kw)

        return op

    real_discard = S.SessionStore.discard_new

    def discard_new(self, k):
        done["n"], done["at"] = 0, k
        try:
            real_discard(self)
        finally:
            done["at"] = None

    for f in real:
        monkeypatch.setattr(Path, f, killing(f))
    outcomes = []
    for k in range(20):
        run = tmp_path / f"k{k}"
        monkeypatch.setattr(S.SessionStore, "discard_new", lambda self, k=k: discard_new(self, k))
        ct = ConfidentTeacher(
            _ResetFails(world),
            oracle(world),
            prior_demonstrations=(x, y),
            run_dir=run,
            progress=False,
        )
        try:
            ct.run(max_steps=3)
        except _Killed:
            killed = True
        except EnvError:
            killed = False
        outcomes.append(_resumed_or_new(run, world))
        if not killed:
            break
    assert not killed and outcomes[0] == "resumed" and outcomes[-1] == "new", outcomes


@pytest.mark.parametrize("when", ["starting", "undoing-a-failed-config"])
def test_a_start_killed_at_any_point_leaves_a_session_or_room_for_one(tmp_path, monkeypatch, when):
    """A new session from prior demonstrations killed (SIGKILL) after prior.npz was in place
    and before config.json.tmp was made left a prior.npz with no config.json.tmp beside it,
    and the next start there was refused as what another session left. Killed before any of
    its file operations (k = 0, 1, ...), the folder now either resumes as the session of no
    step or starts a new one, which keeps nothing of the killed start's; so too where its
    config.json could not be written (a full disk: config.json.tmp removed) and the start is
    killed while it removes what it wrote, once it has marked the folder again (k >= 1; a
    kill between the failed write and that mark, k = 0, is the one point left)."""
    import torchcbl._durable as D

    world = rare_regions_world()
    x, y = world.sample(30, np.random.default_rng(0))  # prior.npz and checkpoint 0 too
    state = {"n": 0, "at": None, "dead": False, "armed": when == "starting"}
    locks: list = []

    def killing(f):
        def op(*args, **kw):
            if state["dead"]:  # a killed process runs nothing more
                raise _Killed
            if state["at"] is not None and state["armed"]:
                if state["n"] == state["at"]:
                    state["dead"] = True
                    raise _Killed
                state["n"] += 1
            return f(*args, **kw)

        return op

    for name in ("mkdir", "unlink", "replace", "rename", "rmdir", "touch"):
        monkeypatch.setattr(Path, name, killing(getattr(Path, name)))
    monkeypatch.setattr(os, "replace", killing(os.replace))
    monkeypatch.setattr(os, "open", killing(os.open))
    monkeypatch.setattr(D, "open", killing(open), raising=False)  # write_durably's files
    monkeypatch.setattr(S, "open", killing(open), raising=False)  # writers.jsonl
    real_lock = S._acquire_lock
    monkeypatch.setattr(S, "_acquire_lock", lambda run: locks.append(real_lock(run)) or locks[-1])
    if when != "starting":
        real_write, real_remove = S.write_json_atomic, S._remove_new_session_files

        def write(path, data):
            if path.name != "config.json" or state["at"] is None:
                return real_write(path, data)
            path.with_name("config.json.tmp").unlink(missing_ok=True)  # as write_durably does
            raise OSError(errno.ENOSPC, "No space left on device")

        def remove(path):
            state["armed"] = True
            real_remove(path)

        monkeypatch.setattr(S, "write_json_atomic", write)
        monkeypatch.setattr(S, "_remove_new_session_files", remove)
    outcomes = []
    for k in range(0 if when == "starting" else 1, 40):
        run = tmp_path / f"k{k}"
        state.update(n=0, at=k, dead=False, armed=when == "starting")
        try:
            ConfidentTeacher(
                world, oracle(world), prior_demonstrations=(x, y), run_dir=run, progress=False
            ).close()
            killed = False
        except (_Killed, SessionWriteError) as exc:
            killed = isinstance(exc, _Killed)
        finally:
            state.update(at=None, dead=False)
            for lock in locks:  # the kernel closes a killed process's files
                lock.close()
            locks.clear()
        outcomes.append(_resumed_or_new(run, world))
        if not killed:
            break
    assert not killed and len(outcomes) > 2, outcomes
    assert set(outcomes) == ({"new", "resumed"} if when == "starting" else {"new"}), outcomes


def test_prior_demonstrations_left_without_a_config_tmp_still_keep_a_new_session_out(tmp_path):
    """Only beside config.json.tmp (a start or a removal killed) are a prior.npz and
    checkpoint 0 what no session left; alone they are another session's and refuse a start."""
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "prior.npz").write_bytes(b"another session's")
    (run / "checkpoints" / "model-00000000.pt").write_bytes(b"another session's")
    world = rare_regions_world()
    with pytest.raises(IncompatibleRunDirError, match=r"another session left \(checkpoints/mod"):
        ConfidentTeacher(world, oracle(world), run_dir=run, progress=False)
    assert (run / "prior.npz").read_bytes() == b"another session's"
    (run / "checkpoints" / "model-00000000.pt").unlink()
    (run / "checkpoints").rmdir()  # prior.npz alone: refused too
    with pytest.raises(IncompatibleRunDirError, match=r"another session left \(prior.npz\)"):
        ConfidentTeacher(world, oracle(world), run_dir=run, progress=False)
    assert (run / "prior.npz").read_bytes() == b"another session's"
    assert [p.name for p in run.iterdir()] == ["prior.npz"]


def test_a_new_session_on_a_kept_session_of_no_step_says_it_holds_none(tmp_path):
    """A session stopped at its first request (Ctrl-C, 'q') is kept, with no step: a new
    session there was told only to resume it. It is now told too that the session holds no
    step, so that the folder may be removed to start afresh; one holding a step, or prior
    demonstrations, is not."""
    world = rare_regions_world()

    def stop(obs, info):
        raise TeachingInterrupted("q")

    empty = tmp_path / "empty"
    with ConfidentTeacher(world, stop, run_dir=empty, progress=False) as ct:
        with pytest.raises(TeachingInterrupted):
            ct.run(max_steps=3)
    x, y = world.sample(30, np.random.default_rng(0))
    prior = tmp_path / "prior"
    with ConfidentTeacher(
        world, stop, prior_demonstrations=(x, y), run_dir=prior, progress=False
    ) as ct:
        with pytest.raises(TeachingInterrupted):
            ct.run(max_steps=3)
    stepped = tmp_path / "stepped"
    with ConfidentTeacher(world, oracle(world), run_dir=stepped, progress=False) as ct:
        ct.run(max_steps=1)
    with pytest.raises(IncompatibleRunDirError) as info:
        ConfidentTeacher(world, oracle(world), run_dir=empty, progress=False)
    msg = str(info.value)
    assert "ConfidentTeacher.resume" in msg and "holds no step" in msg, msg
    assert "shutil.rmtree(run_dir)" in msg, msg
    for run in (prior, stepped):
        with pytest.raises(IncompatibleRunDirError, match="already holds") as info:
            ConfidentTeacher(world, oracle(world), run_dir=run, progress=False)
        assert "no step" not in str(info.value)
    shutil.rmtree(empty)
    with ConfidentTeacher(world, oracle(world), run_dir=empty, progress=False) as ct:
        ct.run(max_steps=2)
    assert len(load_records(empty)) == 2
