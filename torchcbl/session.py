"""Teaching sessions on disk: the run directory, its SQLite step log and model checkpoints.

Run directory layout (one directory per teaching session)::

    <run_dir>/
        config.json              what the session was started with: the TeachingConfig, the
                                 model's class and constructor arguments, the strategy
                                 (``to_config``) and its confidence rule, the env's id,
                                 class, spaces, make() arguments, step cap and
                                 ``describe_inputs()``, the session seed, the log format
                                 version and whether it started from a fitted model
                                 (``starts_fitted``); for a session with prior
                                 demonstrations, ``"prior"``: their count and the
                                 SHA-256 of prior.npz (and format 3, which a torchcbl
                                 without prior demonstrations refuses to read), and,
                                 where they were read from a session
                                 (:class:`Demonstrations`), ``"source"``: its path,
                                 absolute and relative, and its step count then
        prior.npz                the prior demonstrations the session started from
                                 (``observations`` [N, D] float64, ``actions`` [N] int64),
                                 written with the session, before config.json; the first
                                 labels of every fit (absent without them)
        steps.sqlite             the step log: table ``steps``, one row per StepRecord;
                                 table ``corrections``, one row per CorrectionRecord (a
                                 label for an earlier step's observation, journalled and
                                 committed exactly like a demonstration)
        steps.sqlite-wal         SQLite's write-ahead log (present while a writer is open,
        steps.sqlite-shm         after a crash, or when a reader held the log for over 2 s as
                                 the writer closed; never delete it by hand: it may hold
                                 commits)
        steps.journal            the steps not yet committed to steps.sqlite, one JSON line
                                 each with its CRC-32 (empty after a clean close; never delete
                                 it by hand)
        writer.lock              held (fcntl.flock) by the one writer; says which process,
                                 how many steps and corrections its writers committed to
                                 steps.sqlite, and whether steps.journal holds lines not yet
                                 committed (rewritten in place; kept from one writer to the
                                 next)
        writers.jsonl            one line per writer (start or resume): the first step it
                                 wrote, torch's thread counts, the model's device, torch /
                                 numpy versions, its pid and start time (UTC), the
                                 checkpoints it keeps (``keep_checkpoints``), and what its
                                 env runs on (``env_versions``, the env's
                                 ``describe_versions()``, e.g. ``{"sumo": "1.28.0"}``; None
                                 for an env without it)
        runs.jsonl               one line per ``ConfidentTeacher.run()`` call that went as
                                 far as its first step, written before that step: the step
                                 it began at (``first_step``), the stop settings in force
                                 for it (``stops``: the config's with run()'s overrides,
                                 which config.json does not keep) and its start time (UTC).
                                 A resume and :func:`describe` count the streak the log
                                 ends on from the last one inside the log (absent in
                                 sessions written before 2026-11-28: from their last
                                 writer's first step)
        checkpoints/
            model-00000012.pt    ``{"n_demonstrations": 12, "labels_sha256": ...,
                                 "state_dict": ...}`` of the model fitted on the first 12
                                 labels (and the SHA-256 of those labels), its tensors on the
                                 CPU whatever the model's device; one per refit, the newest
                                 ``keep_checkpoints`` kept (3 for a new session; a resume
                                 keeps its last writer's choice; None: all), and checkpoint
                                 0 and a refit by hand's (``ConfidentTeacher.refit``, which
                                 moves the refit schedule) always (an older stage is
                                 refitted from the log, the model the loop had then). The
                                 schedule is read from the names: a refit at the count of
                                 every checkpoint readable and fitted on the log's labels,
                                 or a regular file damaged in place (cut short, emptied);
                                 none at a stale one, one named for more labels than the
                                 log holds, a folder, a dangling link or a file set aside
                                 (``.damaged``, ``.stale``); then one every ``max_new``
                                 labels. A session started from
                                 a fitted model has its model-00000000.pt, written before
                                 config.json: no label can refit it; a session with prior
                                 demonstrations has its model fitted on them alone as
                                 model-00000000.pt, and its checkpoints' SHA-256 covers
                                 the prior's labels first
            model-00000007.pt.damaged
                                 the bytes of a checkpoint that could not be loaded, kept
                                 by a resume (``-1``, ``-2``, ... where the name is taken
                                 already); never read
            model-00000015.pt.stale
                                 a checkpoint a resume set aside as not fitted on the
                                 log's labels, or named for more labels than the log holds
                                 (numbered alike); never read

Durability. Every step is appended to ``steps.journal`` with one ``write()`` before the loop
goes on: a demonstration (teacher label, observation, model output, counters) before its action
is sent to the environment, its outcome (reward, end of episode, info) right after. A written
line sits in the operating system's cache, which outlives the process, so a process killed at
any instant, SIGKILL included, loses no step it has taken. (A power cut or kernel crash may lose
the last steps; that is the price of not calling ``fsync`` on every step.) The same rows go to
the SQLite log (WAL mode, ``synchronous=NORMAL``) in batches: a commit every ``commit_every``
journal lines, at the end of ``run`` and on close; each commit empties the journal. Opening the
directory for writing (``resume``) first replays whatever the journal holds into SQLite (replay
is idempotent, so a crash between a commit and the emptying is harmless), and the readers
(:func:`load_records`, :func:`load_demonstrations`) overlay it, so they see every step even
while a writer runs. The log is therefore always a prefix of the session, ending at worst with
one demonstration whose outcome was never seen (the process died between the two writes, or
before the action ran); on resume that row is kept (the demonstration counts) and marked
``truncated`` with ``info["torchcbl_interrupted"]``. A line torn by the kill (no newline) was
never acknowledged and is ignored: its action never ran. A new session killed after its
``config.json`` was written and before its log was (nothing of it ran) reads as a session of no
step and resumes as one, into the run the uninterrupted session makes; one killed before its
``config.json`` was in place is no session, and what it wrote (its ``prior.npz`` and checkpoint
0, beside the empty ``config.json.tmp`` it makes first) is cleared by the next start there.

Why a journal: a SQLite commit rewrites at least one whole page into the WAL (tens of
microseconds, plus periodic checkpoints), while a journal line is one small ``write()``; this
keeps the loop's own cost per step within the 200 us budget with every step durable.

Checkpoints, like ``config.json`` and ``prior.npz``, are written to a temporary name, fsynced,
renamed, and their directory fsynced, so a checkpoint file is complete or absent, after a power
cut too. A checkpoint can lag behind the log (killed between the commit and the refit); then
:func:`load_model` refits deterministically on the logged demonstrations instead.

What else can go wrong, and what happens (every case is tested in tests/test_session_faults.py):

- An exception in the middle of a step (Ctrl-C inside ``env.step``, an env returning a
  malformed answer, a failing write). The loop's memory never runs ahead of disk: a step is in
  the session once its journal line is written. A Ctrl-C in ``env.step`` logs the step as
  interrupted (episode cut) and re-raises the KeyboardInterrupt with a note; a Ctrl-C that
  arrives while a line is written, a record joins memory or SQLite commits a batch waits until
  memory and disk hold the same steps, then stops the run; a malformed
  ``info`` / ``terminated`` / ``truncated`` / 5-tuple is an :class:`EnvError`.
- A full disk. A journal write that fails (or is cut short) is undone, the file cut back to its
  previous size, and raises :class:`SessionWriteError`: that step is not in the session (a
  demonstration whose outcome line failed is kept, as interrupted, since its label was durable
  before its action ran). A SQLite commit that fails is rolled back; its rows stay in the
  journal and in memory, and the next commit retries them, so a session goes on once space is
  freed. A checkpoint that cannot be written is refitted from the log when needed, save a
  refit by hand's (``ConfidentTeacher.refit``): only its checkpoint records where it moved
  the refit schedule, so the writer keeps its model and writes it with its next checkpoint
  and at close, and freeing space is enough; where the process ends without close() (killed,
  or exiting without calling it: nothing writes it on the way out), that write fails at
  close too, or a Ctrl-C interrupts close() before it is written (a warning, for the last
  two, naming every such checkpoint), the stages from its count to the loop's next refit
  are rebuilt on the regular schedule for good. A new session's starting model
  (checkpoint 0) that cannot be written leaves no session.
- Readers without write access. :func:`load_records`, :func:`load_model`, :func:`describe`
  (what a session holds, ``torchcbl show``) etc. open the log with
  SQLite's ``immutable=1`` (a cleanly closed session: no ``-wal`` file), and then never write,
  lock or create a file, so a read-only mount works; or, while a writer runs or after one was
  killed (a ``-wal`` file is there), with ``mode=ro``, under which SQLite itself takes its
  shared locks and may create or rewrite the ``-shm`` index beside the log (never the log, the
  journal or a checkpoint). A file of the session this user may not read (another user's
  session) is an :class:`IncompatibleRunDirError` naming it; so is a ``checkpoints/`` the
  file system fails to list (an I/O error), naming the error, with nothing renamed.
- Damaged files. A journal line that fails its checksum, or is valid JSON of the wrong shape,
  is reported with its line number and byte offset by readers and by resume, which then refuse
  and change nothing; :func:`repair_journal` copies the journal aside byte for byte and keeps
  every line that does not depend on a damaged one. A checkpoint that cannot be read, or whose
  ``labels_sha256`` does not match the log (stale), is never loaded: the model is refitted from
  the log and a resume renames the file ``.damaged`` / ``.stale`` (a damaged one that records
  a refit, below, stays in place); except the checkpoint 0 of a session
  started from a fitted model, which no label can refit: where the session still stands on it
  (no refit since, or incremental refits) it is a :class:`CorruptSessionError` naming the file,
  left as it is. A damaged checkpoint's name (a regular file's, in place) still records a
  refit at its count, which may have been one asked by hand off the schedule: the model is
  refitted on that count's labels (``refit="incremental"``: the refits are replayed through
  it), as the live loop had it, and a resume writes the model rebuilt at its count in its
  place, so a real checkpoint records the refit again (with full refits only where the
  refit lies off the regular schedule from the one recorded below it; one on it records
  nothing the schedule does not, and is renamed ``.damaged`` at no fit's cost). The
  damaged file stays under its name until then (its bytes kept first as ``<name>.damaged``,
  a hard link or a copy; where neither can be made, or the write fails, it stays as it is,
  with a warning): a reader racing the
  resume, and a resume interrupted (a Ctrl-C, a kill), leave the refit recorded. A name set aside
  (``.damaged``, ``.stale``) records nothing: an older torchcbl's resume set damaged
  checkpoints aside and taught on on the regular schedule, and its sessions read as it read
  them. A checkpoint deleted outright takes its record with it: past a refit by hand whose
  file is gone, and up to the next refit kept on disk, the model is rebuilt on the regular
  schedule, not the live one's. A checkpoint named for more labels than the log holds (the
  log lost its tail: a backup restored, a power cut; a writer logs a label before it saves
  its checkpoint) is never read, and a resume renames it ``.stale``: once the session was
  taught that far again, it would read as a refit the new loop never made. A file a resume
  cannot rename stays as it is (never written over), with a warning naming it.
  A ``prior.npz`` that is missing, or whose SHA-256 is not the one config.json
  recorded, is a :class:`CorruptSessionError` naming it for every reader of the training set
  or the model and for resume (never a model fitted without the prior). An unreadable
  ``steps.sqlite``, a ``config.json`` missing a key, or a missing ``steps.sqlite`` beside a
  config are :class:`CorruptSessionError` naming the file and how to recover; nothing is
  started over.
  Steps are numbered 0, 1, 2, ... without a gap; a log that lacks some (rows deleted by hand, a
  journal line removed) is read with a warning naming them, and resume refuses it (it would
  log new steps under numbers the log holds).
- A lost ``-wal``. A session not closed cleanly keeps its latest commits in
  ``steps.sqlite-wal``, all of them until SQLite first checkpoints it into the log. Without
  that file (deleted by hand, left out of a copy), a log without its tables is a
  :class:`CorruptSessionError` naming the missing file; a log with them, which would read as
  a shorter session (the steps since the last checkpoint or clean close gone), is told by
  ``writer.lock``'s committed counts: a log holding fewer steps or corrections than they say,
  its ``-wal`` missing, is a :class:`CorruptSessionError` for every reader, resume and
  :func:`repair_journal`, naming the missing ``-wal``, changing nothing; removing
  ``writer.lock`` accepts the loss. With the ``-wal`` there, a log holding fewer is what a copy
  taken while the writer ran holds (a copy that took ``writer.lock`` after the log, as rsync
  does by name order, after the writer committed more) or what a power cut left: it is read, and
  resumed, as it is, with a warning naming both counts; resume then notes its own counts.
  Likewise a missing ``steps.journal`` that ``writer.lock`` says held lines not yet committed
  (the writer was killed with steps only there) is a :class:`CorruptSessionError` naming it; one
  that held none (a cleanly closed session's) is not. A copy without ``writer.lock`` (or a
  session whose last writer was a torchcbl without these notes) is not checked.
- Two writers. The writer holds ``writer.lock`` with ``fcntl.flock`` (released by the kernel
  when the process dies, SIGKILL included); a second writer gets :class:`SessionLockedError`.

Determinism. A refit is a deterministic function of the labels, the model's seed, and torch's
intra-op thread count (and the BLAS / CPU, see docs/reproduction.md), and of the model's device:
the same labels with the same seed and the same thread count give bit-identical models, and so
bit-identical step logs for the same env and teacher. With another thread count, torch's
reductions are summed in another order: fits can differ in the last bits (measured: 1.8e-15 in
the candidates' means of a 3000-point 6-D fit, 2026-11-25, 8a2a7dd; bit-identical on 300
points, 2026-11-23; docs/architecture.md, "The EM"), which can flip a confidence decision near
its threshold, after which the two step logs diverge. The count that matters is the one the EM ran
on: with more than one intra-op thread, a fit of at least
:data:`torchcbl.gmm.SINGLE_THREAD_WORK` uses them only while the machine has a core to spare
(the thread policy, docs/architecture.md), so such a fit's last bits also depend on the
machine's load at that moment; with ``torch.set_num_threads(1)`` (the experiments' and the
benchmark's workers call it) every fit runs on one thread. So resume and :func:`load_model`
reproduce the live model exactly when they run with the thread count of the writer that refitted
it (recorded in ``writers.jsonl``), one thread being the sure case; the checkpoints, when
present and matching, are loaded rather than refitted, which needs no particular thread count. A
model on a GPU sums in another order than on the CPU (relative differences up to 5e-13 in the
log-likelihoods measured by bench/bench_gmm_device.py), so a session taught on a GPU is
reproduced exactly by a model on the same kind of GPU (``resume(model=...)``; the EM's sums on
CUDA run in a fixed order, checked on an H200 by tests/test_teaching_cuda.py);
``writers.jsonl`` records each writer's model device.
"""

from __future__ import annotations

import bisect
import contextlib
import copy
import dataclasses
import datetime
import errno
import fcntl
import hashlib
import io
import json
import keyword
import os
import re
import signal
import socket
import sqlite3
import stat
import struct
import sys
import threading
import time
import warnings
import zlib
from collections.abc import Callable, Collection, Iterable, Iterator, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, overload

import numpy as np
import torch

from torchcbl._checkpoints import is_keep_count
from torchcbl._durable import fsync_directory, write_durably
from torchcbl._text import counted
from torchcbl.errors import (
    CorruptSessionError,
    IncompatibleRunDirError,
    SessionLockedError,
    SessionWriteError,
)
from torchcbl.records import CorrectionRecord, StepRecord, training_set

if TYPE_CHECKING:  # pragma: no cover
    from torchcbl.gmm import GaussianMixtureSet
    from torchcbl.policy import GreedyPolicy

__all__ = [
    "COMPARE_ON_RESUME",
    "FORMAT",
    "RESUME_AS",
    "CorruptSessionError",
    "Demonstrations",
    "IncompatibleRunDirError",
    "SessionLockedError",
    "SessionSummary",
    "SessionWriteError",
    "describe",
    "env_make_argument",
    "env_make_arguments",
    "kept_as_repr",
    "kept_checkpoints",
    "latest_checkpoint",
    "load_config",
    "load_corrections",
    "load_demonstrations",
    "load_labels",
    "load_model",
    "load_models",
    "load_policy",
    "load_prior_demonstrations",
    "load_records",
    "prior_source",
    "PriorSource",
    "repair_journal",
    "restore_model",
]

# a model given to load_model, returned as itself
_Model = TypeVar("_Model", bound=torch.nn.Module)

FORMAT = "torchcbl.session/2"
#: The format of a session that starts from prior demonstrations (``prior.npz``, its SHA-256
#: in config.json's ``"prior"``): format 2 plus that file. Its own number, so that a torchcbl
#: that does not know prior demonstrations refuses the session instead of fitting its model
#: without them; a session without a prior keeps format 2.
PRIOR_FORMAT = "torchcbl.session/3"
#: Formats this version reads. Format 1 (before strategies) has no ``actor`` column and no
#: ``corrections`` table: its actor is derived (teacher when labelled, else agent), it has no
#: corrections, and resuming it upgrades the directory to format 2 in place.
READABLE_FORMATS = ("torchcbl.session/1", FORMAT, PRIOR_FORMAT)
CONFIG_NAME = "config.json"
PRIOR_NAME = "prior.npz"
LOG_NAME = "steps.sqlite"
JOURNAL_NAME = "steps.journal"
LOCK_NAME = "writer.lock"
WRITERS_NAME = "writers.jsonl"
RUNS_NAME = "runs.jsonl"
CHECKPOINT_DIR = "checkpoints"
_CKPT_RE = re.compile(r"^model-(\d{8})\.pt$")

_COLUMNS = (
    "step",
    "episode",
    "observation",
    "model_action",
    "confidence",
    "distance",
    "posterior",
    "teacher_action",
    "executed_action",
    "phase",
    "autonomous",
    "reward",
    "terminated",
    "truncated",
    "info",
    "n_demonstrations",
    "autonomy_rate",
    "windowed_accuracy",
    "pending",
    "actor",
)
_FORMAT1_COLUMNS = _COLUMNS[:-1]
_SCHEMA = """
CREATE TABLE IF NOT EXISTS steps (
    step INTEGER PRIMARY KEY,
    episode INTEGER NOT NULL,
    observation BLOB NOT NULL,      -- float64 little-endian, [D]
    model_action INTEGER NOT NULL,  -- -1: no model
    confidence REAL,
    distance REAL,                  -- +inf before any model
    posterior BLOB,                 -- float64 little-endian, [A]
    teacher_action INTEGER,         -- NULL: teacher not asked
    executed_action INTEGER NOT NULL,
    phase TEXT NOT NULL,
    autonomous INTEGER NOT NULL,
    reward REAL,                    -- NULL: outcome never observed
    terminated INTEGER NOT NULL,
    truncated INTEGER NOT NULL,
    info TEXT NOT NULL,             -- JSON
    n_demonstrations INTEGER NOT NULL,
    autonomy_rate REAL,
    windowed_accuracy REAL,
    pending INTEGER NOT NULL,       -- 1: demonstration committed, outcome not yet written
    actor TEXT                      -- who chose executed_action: 'teacher' or 'agent'
);
CREATE TABLE IF NOT EXISTS corrections (
    step INTEGER PRIMARY KEY,       -- the (autonomous) step whose decision-time state it relabels
    action INTEGER NOT NULL         -- the teacher's corrected action for that step's observation
);
"""
_INSERT = f"INSERT INTO steps ({', '.join(_COLUMNS)}) VALUES ({', '.join('?' * len(_COLUMNS))})"
_REPLACE = _INSERT.replace("INSERT", "INSERT OR REPLACE", 1)
FINISH_FIELDS = ("reward", "terminated", "truncated", "info")
_CORRECT = "INSERT OR REPLACE INTO corrections (step, action) VALUES (?, ?)"
_FINISH = (
    "UPDATE steps SET reward = ?, terminated = ?, truncated = ?, info = ?, pending = 0 "
    "WHERE step = ?"
)
_SQL = {"s": _INSERT, "f": _FINISH, "c": _CORRECT}


def _blob(values: tuple[float, ...]) -> bytes:
    return struct.pack(f"<{len(values)}d", *values)


_ENCODER = json.JSONEncoder(sort_keys=True, separators=(",", ":"))


def _info_json(info: dict[str, Any]) -> str:
    return _ENCODER.encode(info) if info else "{}"


def _unblob(blob: bytes | None) -> tuple[float, ...] | None:
    if blob is None:
        return None
    return tuple(np.frombuffer(blob, dtype="<f8").tolist())


_BLOB_COLUMNS = (_COLUMNS.index("observation"), _COLUMNS.index("posterior"))
_JSON_LINE = json.JSONEncoder(separators=(",", ":"))  # Infinity allowed: distance may be inf
_crc32 = zlib.crc32


def _journal_line(kind: str, values: tuple[Any, ...]) -> bytes:
    """One journal line: ``["s", *row]`` (a step row, blobs as hex), ``["f", *finish]`` or
    ``["c", step, action]`` (a correction), then a tab and the CRC-32 of the JSON in 8 hex
    digits, then a newline."""
    if kind == "s":
        values = tuple(
            v.hex() if i in _BLOB_COLUMNS and v is not None else v for i, v in enumerate(values)
        )
    payload = _JSON_LINE.encode([kind, *values]).encode()
    return b"%s\t%08x\n" % (payload, _crc32(payload))


def _is_step(v: Any) -> bool:
    return type(v) is int and v >= 0


def _parse_journal_line(line: bytes) -> tuple[str, tuple[Any, ...]]:
    """One complete journal line -> (kind, values); ValueError saying what is wrong."""
    payload, tab, crc = line.rpartition(b"\t")
    if tab:
        if len(crc) != 8 or int(crc, 16) != _crc32(payload):
            raise ValueError("its checksum does not match its content")
    else:  # written before lines carried a checksum (format 2 of torchcbl 0.1)
        payload = line
    try:
        entry = json.loads(payload)
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"it is not valid JSON ({exc})") from None
    if not isinstance(entry, list) or not entry:
        raise ValueError("it is valid JSON but not a journal entry (a non-empty list)")
    kind, *values = entry
    if kind == "s" and len(values) in (len(_COLUMNS), len(_FORMAT1_COLUMNS)):
        if not _is_step(values[0]):
            raise ValueError(f"its step {values[0]!r} is not an int >= 0")
        for i in _BLOB_COLUMNS:
            if values[i] is not None:
                if not isinstance(values[i], str):
                    raise ValueError(f"its {_COLUMNS[i]} is not a hex string")
                values[i] = bytes.fromhex(values[i])
        if len(values) == len(_FORMAT1_COLUMNS):  # written by a format-1 writer
            values.append(_derived_actor(values[_COLUMNS.index("teacher_action")]))
    elif kind == "f" and len(values) == len(FINISH_FIELDS) + 1:
        if not _is_step(values[-1]):
            raise ValueError(f"its step {values[-1]!r} is not an int >= 0")
    elif kind == "c" and len(values) == 2:
        if not (_is_step(values[0]) and _is_step(values[1])):
            raise ValueError(f"its step and action {values!r} are not ints >= 0")
    else:
        raise ValueError(
            f"it is valid JSON of the wrong shape (kind {kind!r} with {len(values)} values)"
        )
    return kind, tuple(values)


@dataclass(frozen=True)
class _JournalScan:
    """A journal read line by line: the valid entries (with their line numbers) and the
    damaged lines ``(line number from 1, byte offset, what is wrong)``."""

    entries: list[tuple[int, str, tuple[Any, ...]]]
    damaged: list[tuple[int, int, str]]


def _scan_journal(path: Path) -> _JournalScan:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return _JournalScan([], [])
    except PermissionError:
        raise _no_read_access(path) from None
    except OSError as exc:
        raise IncompatibleRunDirError(f"{path} cannot be read: {exc}") from exc
    entries, damaged = [], []
    offset = 0
    for number, line in enumerate(data.split(b"\n")[:-1], 1):  # after the last \n: torn
        try:
            kind, values = _parse_journal_line(line)
        except ValueError as exc:
            damaged.append((number, offset, str(exc)))
        else:
            entries.append((number, kind, values))
        offset += len(line) + 1
    return _JournalScan(entries, damaged)


def _journal_entries(path: Path) -> list[tuple[str, tuple[Any, ...]]]:
    """The complete lines of a journal, in order; a torn last line (no newline: the writer
    was killed mid-write, its step never went on) is left out.

    Raises:
        CorruptSessionError: a complete line is damaged; nothing is changed on disk.
    """
    scan = _scan_journal(path)
    for _ in range(2):
        if not scan.damaged:
            break
        # A reader racing a writer's commit (which empties the journal, then appends) can read
        # a spliced line once; real damage stays. Look again before reporting it.
        time.sleep(0.02)
        scan = _scan_journal(path)
    if scan.damaged:
        number, offset, what = scan.damaged[0]
        after = sum(n > number for n, _, _ in scan.entries)
        raise CorruptSessionError(
            f"{path}: line {number} (byte {offset}) is damaged: {what}"
            + (f"; {len(scan.damaged)} damaged lines in all" if len(scan.damaged) > 1 else "")
            + f". {after} valid lines follow it. Nothing was changed on disk. To recover, call "
            f"torchcbl.session.repair_journal({str(path.parent)!r}): it copies every byte of "
            "the journal aside, keeps the lines before the damage and every later line that "
            "does not depend on a damaged one, and reports what it could not keep."
        )
    return [(kind, values) for _, kind, values in scan.entries]


def _no_read_access(path: Path) -> IncompatibleRunDirError:
    """The error for a file of a session this user may not read (another user's session)."""
    return IncompatibleRunDirError(
        f"{path} cannot be read by this user (permission denied). Reading a session needs "
        "read access to its files and read and search (x) access to its directory and the "
        "ones above it; torchcbl changed nothing. Ask the session's owner for access (e.g. "
        "chmod -R a+rX on the run directory), or read a copy they make."
    )


def _unreadable(path: Path, exc: OSError) -> IncompatibleRunDirError:
    """The error for a file or folder of a session the file system fails to read (an I/O
    error; not a directory where one was made; a loop of links): what failed, and that
    torchcbl changed nothing. A permission is said as :func:`_no_read_access` says it."""
    if isinstance(exc, PermissionError):
        return _no_read_access(path)
    name = errno.errorcode.get(exc.errno or 0)
    return IncompatibleRunDirError(
        f"{path} cannot be read: {exc.strerror or exc}"
        + (f" ({name})" if name else "")
        + ". The file system failed to read it; torchcbl changed nothing. Check the disk and "
        f"the mount it is on (the kernel log: dmesg), and that {path.name} is what the "
        "session made there, then run this again; if it stays unreadable, restore the run "
        "directory from a backup."
    )


def _derived_actor(teacher_action: Any) -> str:
    return "agent" if teacher_action is None else "teacher"


def _upgrade_format1(db: sqlite3.Connection) -> bool:
    """Add format 2's ``actor`` column to a format-1 log (in place); True if it was format 1."""
    columns = {row[1] for row in db.execute("PRAGMA table_info(steps)")}
    if not columns or "actor" in columns:
        return False
    db.execute("ALTER TABLE steps ADD COLUMN actor TEXT")
    db.execute(
        "UPDATE steps SET actor = CASE WHEN teacher_action IS NULL THEN 'agent' ELSE 'teacher' END"
    )
    return True


def write_json_atomic(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` to ``path`` through ``<name>.tmp`` renamed over it, durably (fsynced
    before the rename, the directory after: :func:`torchcbl._durable.write_durably`); a write
    that fails (full disk) leaves neither ``path`` changed nor the ``.tmp`` behind."""
    text = json.dumps(data, indent=2, sort_keys=True) + "\n"
    write_durably(path, text.encode(), path.with_name(path.name + ".tmp"))


def _write_atomic(path: Path, data: bytes, what: str, after: str) -> None:
    """Write ``data`` to ``path`` through ``.<name>.tmp`` renamed over it, durably: the file is
    whole or absent, power cut included; a failure is a :class:`SessionWriteError` ending with
    ``after``."""
    try:
        write_durably(path, data, path.with_name(f".{path.name}.tmp"))
    except OSError as exc:
        raise _write_error(exc, path, what, after) from exc


#: Keys a session config must have, with what each must be (checked by :func:`load_config`).
_REQUIRED = {
    "teaching": (dict, "the TeachingConfig fields"),
    "model": (dict, 'the model entry {"class": ..., "args": {...}}'),
    "env": (dict, 'the env entry {"n_features": ..., "n_actions": ..., ...}'),
    "seed": (int, "the session seed (an int)"),
}


def _config_problem(config: dict[str, Any]) -> str | None:
    for key, (kind, what) in _REQUIRED.items():
        if not isinstance(config.get(key), kind) or isinstance(config.get(key), bool):
            got = "missing" if key not in config else f"{config[key]!r}"
            return f"the key {key!r} should hold {what}, got {got}"
    if not isinstance(config["model"].get("args"), dict):
        return "the key 'model' has no 'args' dict"
    for key in ("n_features", "n_actions"):
        if type(config["env"].get(key)) is not int:
            return f"the key 'env' has no int {key!r}"
    if "max_new" not in config["teaching"]:
        return "the key 'teaching' has no 'max_new'"
    max_new = config["teaching"]["max_new"]
    if type(max_new) is not int or max_new < 1:  # every reader refits by it
        return f"the key 'teaching' has max_new {max_new!r}, not an int >= 1 (the refit period)"
    strategy = config.get("strategy")
    # a dict (its "type" is read with str(): a user's to_config() may have left it out, or
    # given a session made before strategy_to_config refused that something else)
    if "strategy" in config and not isinstance(strategy, dict):
        return (
            f"the key 'strategy' should hold the strategy's to_config() dict, got {strategy!r:.200}"
        )
    prior = config.get("prior")
    if config.get("format") == PRIOR_FORMAT or prior is not None:
        if config.get("format") != PRIOR_FORMAT:
            return f"it has a 'prior' entry, which only format {PRIOR_FORMAT!r} sessions have"
        if not (
            isinstance(prior, dict)
            and isinstance(prior.get("sha256"), str)
            and type(prior.get("n_demonstrations")) is int
            and prior["n_demonstrations"] >= 1
        ):
            return (
                "the key 'prior' should hold the session's prior demonstrations "
                '{"file": "prior.npz", "sha256": ..., "n_demonstrations": N >= 1}, got '
                + ("missing" if prior is None else repr(prior))
            )
    return None


def _sessions_below(
    path: Path,
    limit: int | None = 5,
    depth: int = 3,
    not_searched: list[tuple[Path, str]] | None = None,
) -> list[Path]:
    """Teaching session directories one to ``depth`` levels below ``path`` (at most
    ``limit``; None: all), shallower first, as a reproduction's run directory holds them
    (``sessions/seed<k>``, ``seed_<k>/sessions/arm_a``) and a benchmark's (``sessions/<key>``).

    The folders it cannot list or search (another user's, mode 0o700; ``path`` itself
    included), whose sessions are not among those returned, are appended to ``not_searched``
    as ``(folder, why)`` when it is given; a session's own folders (its ``checkpoints/``) are
    not (the session's readers say what they cannot read of it)."""
    found: list[Path] = []
    level: list[tuple[Path, bool]] = [(path, False)]  # (folder, whether inside a session)
    for _ in range(depth):
        children: list[tuple[Path, bool]] = []
        for parent, inside in level:
            try:
                with os.scandir(parent) as entries:
                    names = [e.name for e in entries if _is_dir(e)]
            except OSError as exc:
                if not_searched is not None and not inside:
                    not_searched.append((parent, exc.strerror or str(exc)))
                continue
            children.extend((parent / name, inside) for name in names)
        level = []
        for folder, inside in sorted(children):
            try:
                is_session = (folder / CONFIG_NAME).exists() and (folder / LOG_NAME).exists()
            except OSError as exc:  # a folder this user may list but not search
                if not_searched is not None and not inside:
                    not_searched.append((folder, exc.strerror or str(exc)))
                continue
            if is_session:
                found.append(folder)
                if limit is not None and len(found) >= limit:
                    return found
            level.append((folder, inside or is_session))
    return found


def _is_dir(entry: os.DirEntry[str]) -> bool:
    """Whether a directory entry is a folder (a link to one included); False where that
    cannot be told (a name in a folder this user may list but not search)."""
    try:
        return entry.is_dir()
    except OSError:
        return False


def load_config(run_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """The ``config.json`` of a run directory.

    Raises:
        IncompatibleRunDirError: no config (the message says whether the path does not
            exist, is a file, or is a directory without one), or another log format.
        CorruptSessionError: unreadable config, or one missing a required key (or whose
            ``teaching.max_new`` is no int >= 1).
    """
    path = Path(run_dir) / CONFIG_NAME
    try:
        os.stat(path)
    except PermissionError:  # the directory, or one above it, may not be searched
        raise _no_read_access(path) from None
    except OSError:
        pass  # said below: missing, or the path is a file
    if not path.is_file():
        given = Path(run_dir)
        if given.is_file():  # e.g. the session's steps.sqlite or config.json itself
            inside = (given.parent / CONFIG_NAME).is_file()
            raise IncompatibleRunDirError(
                f"{run_dir!s} is a file; expected a teaching session directory (one holding "
                f"{CONFIG_NAME})"
                + (f": give the directory it is in, {str(given.parent)!r}." if inside else ".")
            )
        if not given.exists():
            raise IncompatibleRunDirError(
                f"{run_dir!s} does not exist; expected a teaching session directory (one "
                f"holding {CONFIG_NAME}). Check the path (relative paths are taken from the "
                f"working directory, {os.getcwd()}"
                + ("; '~' is not expanded: use os.path.expanduser" if "~" in str(run_dir) else "")
                + "), or start a session there with ConfidentTeacher(..., run_dir=...)."
            )
        below = _sessions_below(given)
        if below:  # a reproduction's run directory (runs/reproduce/corridor), a folder of them
            raise IncompatibleRunDirError(
                f"{run_dir!s} is not a teaching session directory but holds sessions: "
                f"{', '.join(str(s) for s in below)}; pass one of them."
            )
        raise IncompatibleRunDirError(
            f"{run_dir!s} is not a teaching session directory: {CONFIG_NAME} is missing. "
            "Start a session with ConfidentTeacher(..., run_dir=...) first."
        )
    try:
        config = json.loads(path.read_text(encoding="utf-8"))
    except PermissionError:
        raise _no_read_access(path) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CorruptSessionError(
            f"{path} is not readable JSON ({exc}). It is written once when the session "
            "starts; restore it from a backup or a copy of the run directory."
        ) from exc
    if not isinstance(config, dict) or config.get("format") not in READABLE_FORMATS:
        got = config.get("format") if isinstance(config, dict) else type(config).__name__
        raise IncompatibleRunDirError(
            f"{path}: expected a session format among {READABLE_FORMATS}, got {got!r}. This "
            "directory was written by another version of torchcbl or by something else; read "
            "it with that version, or start a new session in a new run_dir."
        )
    problem = _config_problem(config)
    if problem is not None:
        raise CorruptSessionError(
            f"{path}: {problem}. The file was edited or damaged; restore it from a backup or "
            "a copy of the run directory, or put the value the session was started with back "
            "under that key. Nothing else was read or changed."
        )
    return config


def _write_error(exc: BaseException, path: Path, what: str, after: str) -> SessionWriteError:
    """A SessionWriteError for a failed write of ``path``; ``after`` says where that leaves
    the session and what to do."""
    reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
    code = getattr(exc, "errno", None) or errno.EIO
    return SessionWriteError(code, f"writing {path} failed ({reason}) while {what}. {after}")


_write_fd = os.write  # the journal's write (a seam for the disk-full tests)


def kept_as_repr(value: Any) -> bool:
    """Whether ``value``, a ``gymnasium.make`` argument as a session's config keeps it
    (``config["env"]["kwargs"][name]``), is the ``{"repr": text}`` kept of an object JSON
    cannot hold, rather than the plain value the env was made with.

    Such an argument is made again, where it can be, by :func:`env_make_argument`.

    Args:
        value: one of the config's ``env.kwargs`` values.

    Returns:
        True for a dict whose only key is ``"repr"``, False for anything else.
    """
    return isinstance(value, dict) and set(value) == {"repr"}


#: what :func:`_object_form` gives for a value it cannot keep
_UNKEPT = object()
#: the keys of a kept object (config.json's ``env.kwargs_objects``)
_OBJECT_KEYS = {"class", "fields"}


#: the most values a kept argument counts, itself included (each object, field value,
#: container and number counts one: a dataclass holding one tuple of n numbers counts n + 2);
#: a larger one (a table of a million numbers) is kept as text alone, not as megabytes of
#: config.json
_KEPT_VALUES = 10_000


def _object_form(value: Any, budget: list[int] | None = None) -> Any:
    """A ``gymnasium.make`` argument in a form JSON holds and :func:`env_make_argument`
    rebuilds: a frozen dataclass as ``{"class": "module:QualName", "fields": {...}}`` (its init
    fields, each in this form: a nested frozen dataclass alike, a tuple as a list, a path as
    its str, a numpy number as the number); plain JSON values as they are. ``_UNKEPT`` for
    anything else (a dataclass that is not frozen may change after make, a non-finite float,
    an object of another kind, also one of a subclass of a JSON type, which would come back
    as that type: an enum, a namedtuple), for a dict of non-str keys or one that reads as a
    kept object (a dataclass holding one is not kept), and past ``_KEPT_VALUES`` values in
    all (``budget``, the values left)."""
    budget = [_KEPT_VALUES] if budget is None else budget
    budget[0] -= 1
    if budget[0] < 0:
        return _UNKEPT
    kind = type(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        params = getattr(kind, "__dataclass_params__", None)
        if not getattr(params, "frozen", False):
            return _UNKEPT
        fields: dict[str, Any] = {}
        for f in dataclasses.fields(value):
            if not f.init:  # a cache, or what __post_init__ derives
                continue
            kept = _object_form(getattr(value, f.name), budget)
            if kept is _UNKEPT:
                return _UNKEPT
            fields[f.name] = kept
        return {"class": f"{kind.__module__}:{kind.__qualname__}", "fields": fields}
    if value is None or kind in (bool, str):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if kind is int or isinstance(value, np.integer):
        return int(value)
    if kind is float or isinstance(value, np.floating):
        return float(value) if np.isfinite(value) else _UNKEPT
    if isinstance(value, os.PathLike) and isinstance(os.fspath(value), str):
        return os.fspath(value)
    if kind in (list, tuple):
        items = []
        for v in value:
            items.append(_object_form(v, budget))
            if items[-1] is _UNKEPT:
                return _UNKEPT
        return items
    if kind is dict and set(value) != _OBJECT_KEYS:
        if not all(type(k) is str for k in value):  # JSON would make them str
            return _UNKEPT
        kept_items = {}
        for k, v in value.items():
            kept_items[k] = _object_form(v, budget)
            if kept_items[k] is _UNKEPT:
                return _UNKEPT
        return kept_items
    return _UNKEPT


def _classes_in(value: Any, found: dict[str, type]) -> dict[str, type]:
    """``found`` with the class of each dataclass in ``value`` (nested ones too) by the name
    :func:`_object_form` keeps it under."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        found[f"{type(value).__module__}:{type(value).__qualname__}"] = type(value)
        for f in dataclasses.fields(value):
            _classes_in(getattr(value, f.name), found)
    elif isinstance(value, (list, tuple)):
        for v in value:
            _classes_in(v, found)
    elif isinstance(value, dict):
        for v in value.values():
            _classes_in(v, found)
    return found


def _env_objects(kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """config.json's ``env.kwargs_objects``: of ``gymnasium.make``'s arguments, each frozen
    dataclass in the form :func:`env_make_argument` rebuilds (see :func:`_object_form`), where
    rebuilding it with its own classes gives an equal object (not so for a field holding a
    list, which comes back a tuple, or for a class that compares by identity)."""
    out = {}
    for name, value in kwargs.items():
        if not dataclasses.is_dataclass(value) or isinstance(value, type):
            continue
        try:
            kept = _object_form(value)
            if kept is _UNKEPT:
                continue
            same = _rebuild(json.loads(json.dumps(kept)), _classes_in(value, {})) == value
        except Exception:  # a class that refuses its own fields, a dict holding itself
            same = False  # (RecursionError): kept as text alone
        if same is True:
            out[str(name)] = kept
    return out


def _rebuild(form: Any, builders: Mapping[str, Callable[..., Any]]) -> Any:
    """The value :func:`_object_form` kept as ``form``: a kept object made again by the
    builder of its class (KeyError naming the class where ``builders`` has none), a JSON
    array as a tuple (as a frozen dataclass holds a sequence)."""
    # the keys alone, not _is_kept_object: _object_form keeps no plain dict of these keys, so
    # one edited out of shape (a class that is no str) is refused here, not built as a dict
    if isinstance(form, dict) and set(form) == _OBJECT_KEYS:
        build = builders.get(form["class"])
        if build is None:
            raise KeyError(form["class"])
        return build(**{k: _rebuild(v, builders) for k, v in dict(form["fields"]).items()})
    if isinstance(form, list):
        return tuple(_rebuild(v, builders) for v in form)
    if isinstance(form, dict):
        return {k: _rebuild(v, builders) for k, v in form.items()}
    return form


#: a dataclass field whose ``metadata`` holds this key set to False is not compared on resume:
#: what changes nothing the env does (a ``CorridorMap``'s name, a ``TrafficScenario``'s)
COMPARE_ON_RESUME = "torchcbl.compare_on_resume"

#: a dataclass field whose ``metadata`` holds this key, with a function of the field's value,
#: takes more than one spelling of one value (a ``DrivingConfig``'s scenario: a shipped
#: scenario's name or the ``TrafficScenario`` itself): on resume, a field kept as an object
#: on one side and as a plain value on the other (a name) is compared as the object the
#: function makes of the plain value (``get_scenario("train")``); a plain value it refuses is
#: compared as it is. The function is given the plain value as JSON reads it back (a list
#: for a tuple) and returns an object given objects as they are
RESUME_AS = "torchcbl.resume_as"


def _is_kept_object(form: Any) -> bool:
    """Whether ``form`` is a kept object, ``{"class": str, "fields": dict}`` (one edited into
    another shape is compared as the plain value it is)."""
    return (
        isinstance(form, dict)
        and set(form) == _OBJECT_KEYS
        and isinstance(form["class"], str)
        and isinstance(form["fields"], dict)
    )


def _resume_as(value: Any) -> dict[str, dict[str, Callable[[Any], Any]]]:
    """Of each dataclass class in ``value`` (nested ones too), by its qualified name, the
    fields its ``metadata`` gives a function that makes the object a plain value spells
    (:data:`RESUME_AS`), with that function."""
    out: dict[str, dict[str, Callable[[Any], Any]]] = {}
    for name, cls in _classes_in(value, {}).items():
        spelt = {
            f.name: f.metadata[RESUME_AS]
            for f in dataclasses.fields(cls)
            if callable(f.metadata.get(RESUME_AS))
        }
        if spelt:
            out[name.rsplit(":", 1)[-1]] = spelt
    return out


def _spelt_as_object(form: Any, make: Callable[[Any], Any], skip: dict[str, set[str]]) -> Any:
    """The kept form of the object ``make`` (a field's :data:`RESUME_AS` function) makes of
    the plain value ``form`` (a scenario's name), the fields its classes mark not compared
    added to ``skip``; ``form`` as it is where it is a kept object already, or where ``make``
    refuses it (a name this version does not ship) or makes what cannot be kept."""
    if _is_kept_object(form):
        return form
    try:
        made = make(form)
        kept = _object_form(made)
    except Exception:  # a name it does not know: compared as it is, and said so
        return form
    if kept is _UNKEPT or not _is_kept_object(kept):
        return form
    for qualname, names in _not_compared(made).items():
        skip.setdefault(qualname, set()).update(names)
    return json.loads(json.dumps(kept))


def _not_compared(value: Any) -> dict[str, set[str]]:
    """Of each dataclass class in ``value`` (nested ones too), by its qualified name (the
    part of the kept ``"module:QualName"`` after the colon), the fields its ``metadata`` marks
    as not compared on resume (:data:`COMPARE_ON_RESUME`)."""
    out: dict[str, set[str]] = {}
    for name, cls in _classes_in(value, {}).items():
        skip = {
            f.name for f in dataclasses.fields(cls) if f.metadata.get(COMPARE_ON_RESUME) is False
        }
        if skip:
            out[name.rsplit(":", 1)[-1]] = skip
    return out


#: how a field absent on one side of a comparison reads in the message
_ABSENT = "(absent)"


def _form_differences(
    stored: Any,
    given: Any,
    skip: dict[str, set[str]],
    path: str,
    spelt: Mapping[str, Mapping[str, Callable[[Any], Any]]] | None = None,
) -> list[tuple[str, Any, Any]]:
    """Where the kept form ``stored`` of a ``gymnasium.make`` argument differs from ``given``'s
    (both as :func:`_object_form` writes them, read back from JSON): ``(path, stored, given)``
    for each differing value, ``path`` the argument's name and its fields (``scenario.seed``,
    ``course.start.cell``, ``nodes.P1[0]``). A kept object's class is compared by its
    qualified name (one moved to another module is the same); of its fields only those both
    sides kept, less those its class marks as not compared (``skip``); a field its class
    gives a :data:`RESUME_AS` function (``spelt``), kept as an object on one side and as a
    plain value on the other, is compared as the object that value spells. 2 and 2.0 are
    equal; True and 1 are not."""
    spelt = spelt or {}
    if _is_kept_object(stored) and _is_kept_object(given):
        qualname = stored["class"].rsplit(":", 1)[-1]
        if qualname != given["class"].rsplit(":", 1)[-1]:
            return [(path, f"a {stored['class']}", f"a {given['class']}")]
        out: list[tuple[str, Any, Any]] = []
        fields, given_fields = stored["fields"], given["fields"]
        for name, value in fields.items():
            if name not in given_fields or name in skip.get(qualname, set()):
                continue
            other = given_fields[name]
            make = spelt.get(qualname, {}).get(name)
            if make is not None and _is_kept_object(value) != _is_kept_object(other):
                value = _spelt_as_object(value, make, skip)
                other = _spelt_as_object(other, make, skip)
            out += _form_differences(value, other, skip, f"{path}.{name}", spelt)
        return out
    if _is_kept_object(stored) or _is_kept_object(given):
        return [(path, stored, given)]
    if isinstance(stored, dict) and isinstance(given, dict):
        out = []
        for key in list(stored) + [k for k in given if k not in stored]:
            if key not in stored or key not in given:
                out.append((f"{path}.{key}", stored.get(key, _ABSENT), given.get(key, _ABSENT)))
            else:
                out += _form_differences(stored[key], given[key], skip, f"{path}.{key}", spelt)
        return out
    if isinstance(stored, list) and isinstance(given, list) and len(stored) == len(given):
        out = []
        for k, (a, b) in enumerate(zip(stored, given, strict=True)):
            out += _form_differences(a, b, skip, f"{path}[{k}]", spelt)
        return out
    if isinstance(stored, bool) != isinstance(given, bool) or stored != given:
        return [(path, stored, given)]
    return []


def _shortened(value: Any, width: int = 60) -> Any:
    """``value`` for a one-line message: a number, bool, None or short str as it is, anything
    else as its JSON text cut to ``width`` characters."""
    if value is None or isinstance(value, (bool, int, float)):
        return value
    text = value if isinstance(value, str) else json.dumps(value, sort_keys=True)
    return text if len(text) <= width else text[: width - 3] + "..."


def _object_problems(
    stored_kw: Mapping[str, Any], stored_objects: Any, given: Mapping[str, Any]
) -> list[str]:
    """What tells the ``gymnasium.make`` arguments ``given`` (as given: the spec's kwargs)
    that are frozen dataclasses from the session's, where both the session (config.json's
    ``env.kwargs_objects``, ``stored_objects``) and the given env keep the argument whole
    (:func:`_env_objects`): one line per argument naming it, each differing field with both
    values, and both objects as text (shortened). An argument only one side keeps whole (a
    session written before 2026-11-27, an object that cannot be kept) is not compared here,
    as it was not before."""
    if not isinstance(stored_objects, dict) or not stored_objects:
        return []
    given_forms = json.loads(json.dumps(_env_objects(given)))
    problems = []
    for name in sorted(set(stored_objects) & set(given_forms)):
        differ = _form_differences(
            stored_objects[name],
            given_forms[name],
            _not_compared(given[name]),
            name,
            _resume_as(given[name]),
        )
        if not differ:
            continue
        fields = {p: (_shortened(a), _shortened(b)) for p, a, b in differ[:6]}
        more = f" and {len(differ) - 6} more" if len(differ) > 6 else ""
        kept = stored_kw.get(name)
        kept_text = kept["repr"] if kept_as_repr(kept) else json.dumps(stored_objects[name])
        problems.append(
            f"env argument {name} (stored, given): {fields}{more}; the session's "
            f"{_shortened(str(kept_text), 100)}, the given {_shortened(repr(given[name]), 100)}"
        )
    return problems


def env_make_argument(
    config: Mapping[str, Any],
    name: str,
    builders: Mapping[str, Callable[..., Any]],
    *,
    default: Any = None,
) -> Any:
    """The argument ``name`` that ``gymnasium.make`` was given for a session's env, as the
    session keeps it: a plain value (a str, number, list or dict) as it is, an object rebuilt.

    A session keeps each argument that is a frozen dataclass (a domain's settings, a
    ``TrafficScenario`` or ``CorridorMap`` say) as ``{"class": "module:QualName", "fields":
    {...}}`` in its config's ``env.kwargs_objects`` (its init fields; a nested frozen dataclass
    alike), beside the shortened text ``env.kwargs`` keeps of it. It is rebuilt by
    ``builders[class](**fields)``, nested objects first: only the classes named there are
    made (nothing is imported by name), so a caller passes the classes it takes, e.g.
    ``{"sumo_scenarios.scenarios:TrafficScenario": TrafficScenario}``.

    Args:
        config: the session's config (:func:`load_config`).
        name: the argument's keyword.
        builders: ``"module:QualName"`` -> the class (or a function of the fields) to make.
        default: what to return when the env was made without ``name`` (or directly, without
            ``gymnasium.make``, which keeps no argument).

    Raises:
        ValueError: the argument was kept only as text (an object that is no frozen dataclass,
            or one holding a value JSON cannot hold, or any object of a session written before
            2026-11-27), or as an object of a class ``builders`` does not name, or the class
            refused its kept fields; the message names the argument and what was kept, in
            one line.
    """
    env = config.get("env") or {}
    kwargs = env.get("kwargs") or {}
    if name not in kwargs:
        return default
    value = kwargs[name]
    if not kept_as_repr(value):
        return value
    text = _kept_text(value)
    form = (env.get("kwargs_objects") or {}).get(name)
    if not _is_kept_object(form):
        raise ValueError(
            f"its env was made with {name} given as an object ({text}), which its config keeps "
            "only as text (a frozen dataclass is kept whole since 2026-11-27; another object "
            "never)"
        )
    try:
        return _rebuild(form, builders)
    except KeyError as exc:
        raise ValueError(
            f"its env was made with {name} given as a {exc.args[0]}, which this rebuilds only "
            f"as one of {sorted(builders)} ({text})"
        ) from None
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"its env was made with {name} given as an object its config keeps as "
            f"{json.dumps(form)[:300]}, which no longer makes a {form['class']} ({exc})"
        ) from None


def env_make_arguments(
    config: Mapping[str, Any],
    builders: Mapping[str, Callable[..., Any]],
    *,
    skip: Collection[str] = ("render_mode",),
) -> tuple[dict[str, Any], dict[str, str]]:
    """Every argument ``gymnasium.make`` was given for a session's env but those in ``skip``,
    as :func:`env_make_argument` makes each again, and why each of those it cannot make cannot
    be made: what a domain's evaluate, replay and ``torchcbl teach --resume`` make the
    session's env again with.

    Args:
        config: the session's config (:func:`load_config`).
        builders: ``"module:QualName"`` -> the class to make (see :func:`env_make_argument`).
        skip: arguments left out of both (neither made nor reported): by default
            ``render_mode``, which only draws (resume compares it neither) and which each
            caller chooses itself; ``()`` for every one.

    Returns:
        ``(made, unknown)``: ``made`` maps each argument made again to its value (a plain
        value as it is, an object rebuilt); ``unknown`` each other argument to
        :func:`env_make_argument`'s one-line reason. Both are empty for an env made directly.
    """
    made: dict[str, Any] = {}
    unknown: dict[str, str] = {}
    for name in (config.get("env") or {}).get("kwargs") or {}:
        if name in skip:
            continue
        try:
            made[name] = env_make_argument(config, name, builders)
        except ValueError as exc:
            unknown[name] = str(exc)
    return made, unknown


#: the most characters of one object argument a refusal writes out as its constructor call
#: (a TrafficScenario takes about 200, a CorridorMap about 1,000); a longer one (a table of
#: thousands of numbers) is named by the env_make_argument call that makes it again
_CALL_CHARS = 2_000
#: where the text :func:`_call_source` writes may be wrapped (after each ", " of a call,
#: tuple or dict): a space on one line, a line break in ``torchcbl show``
_BREAK = "\0"


#: the ``imports`` key under which :func:`_importable_name` notes classes made in a function
_LOCAL_CLASSES = "<locals>"


def _importable_name(module: str, qualname: str, imports: dict[str, set[str]]) -> str:
    """The name a call writes for the class ``module:qualname``, its import added to
    ``imports``; a class defined inside a function (``f.<locals>.Cfg``), which no import
    reaches, by its own name, noted under :data:`_LOCAL_CLASSES` for the reader to have it in
    scope."""
    if "<locals>" in qualname:
        imports.setdefault(_LOCAL_CLASSES, set()).add(f"{module}:{qualname}")
        return qualname.rpartition(".")[2]
    if module:
        imports.setdefault(module, set()).add(qualname.split(".")[0])
    return qualname


def _call_source(form: Any, imports: dict[str, set[str]]) -> str:
    """Python source making again what :func:`_object_form` kept as ``form``, as
    :func:`env_make_argument` makes it: a kept object as its class's constructor call with its
    kept fields as keywords (``TrafficScenario(name='rushhour', seed=11, ...)``; nested objects
    alike, a field that is no Python name in a ``**{...}``), a JSON array as a tuple, a JSON
    object as a dict, anything else as its repr. The name each class is imported by is added
    to ``imports`` (module -> names); ``_BREAK`` follows each separating ", "."""
    sep = "," + _BREAK
    if _is_kept_object(form):
        module, _, qualname = form["class"].rpartition(":")
        qualname = _importable_name(module, qualname, imports)
        args = [
            f"{k}={_call_source(v, imports)}"
            for k, v in form["fields"].items()
            if k.isidentifier() and not keyword.iskeyword(k)
        ]
        odd = {
            k: v
            for k, v in form["fields"].items()
            if not (k.isidentifier() and not keyword.iskeyword(k))
        }
        if odd:
            args.append("**" + _call_source(odd, imports))
        return f"{qualname}({sep.join(args)})"
    if isinstance(form, list):  # rebuilt as a tuple
        items = [_call_source(v, imports) for v in form]
        return "(" + sep.join(items) + ("," if len(items) == 1 else "") + ")"
    if isinstance(form, dict):
        return "{" + sep.join(f"{k!r}: {_call_source(v, imports)}" for k, v in form.items()) + "}"
    return repr(form)


#: ``torchcbl show``'s width for an env's arguments, and the most characters of one argument
#: it writes out (a longer one: the env_make_argument call that makes it; --json gives it whole)
_SHOW_WIDTH = 100
_SHOW_CALL_CHARS = 6_000


def _wrapped(source: str, first: str, rest: str, width: int) -> list[str]:
    """``source`` (:func:`_call_source`'s text) in lines of at most ``width`` characters where
    it can be (a str longer than a line is not cut), broken only where ``_BREAK`` marks, the
    first line after ``first``, the others after ``rest``."""
    chunks = source.split(_BREAK)
    lines = [first + chunks[0]]
    for chunk in chunks[1:]:
        if len(lines[-1]) + 1 + len(chunk) <= width:
            lines[-1] += " " + chunk
        else:
            lines.append(rest + chunk)
    return lines


def _kept_text(value: Mapping[str, Any]) -> str:
    """The text of an argument kept only as ``{"repr": text}``, ending with "..." where it may
    have been cut (a session keeps at most 200 characters of it)."""
    text = str(value["repr"])
    return text if len(text) < 200 or text.endswith("...") else text + "..."


def _kept_arguments(senv: Mapping[str, Any]) -> dict[str, Any]:
    """Each ``gymnasium.make`` argument a session keeps (``senv``, config.json's ``"env"``),
    as whole as it keeps it: an object kept whole as its kept form (``{"class": ..., "fields":
    ...}``, from ``env.kwargs_objects``), one kept only as text as ``{"repr": text}``, the text
    ending with "..." where it may have been cut (:func:`_kept_text`), a plain value as it is."""
    kwargs = senv.get("kwargs")
    objects = senv.get("kwargs_objects")
    objects = objects if isinstance(objects, dict) else {}
    kept: dict[str, Any] = {}
    for name, value in (kwargs if isinstance(kwargs, dict) else {}).items():
        if kept_as_repr(value) and _is_kept_object(objects.get(name)):
            kept[name] = objects[name]
        elif kept_as_repr(value):
            kept[name] = {"repr": _kept_text(value)}
        else:
            kept[name] = value
    return kept


def _make_arguments_source(kept: Mapping[str, Any], *, limit: int) -> tuple[list[str], list[str]]:
    """How to pass again the ``gymnasium.make`` arguments a session keeps (``kept``, as
    :func:`_kept_arguments` gives them) as Python source: ``(arguments, notes)``. Each argument
    is ``name=source``: a plain value as its repr, an object kept whole as its constructor call
    (:func:`_call_source`), or, where that is longer than ``limit`` characters, as the
    :func:`env_make_argument` call that makes it from the session's config
    (``load_config(run_dir)``); an object kept only as text as ``<text>``, which no call makes
    again. Arguments that are no Python name come last, in one ``**{...}``. ``notes``: what a
    reader needs besides (why an argument is not written out) and, last, the imports of the
    classes the source names, ``from module import A, B``."""
    imports: dict[str, set[str]] = {}
    notes: list[str] = []
    named: list[str] = []
    odd: list[str] = []
    for name, form in kept.items():
        if _is_kept_object(form):
            mine: dict[str, set[str]] = {}
            source = _call_source(form, mine)
            written = len(source.replace(_BREAK, " "))
            if written > limit:
                classes = sorted(_kept_classes(form, set()))
                mine = {"torchcbl.session": {"env_make_argument", "load_config"}}
                builders = ", ".join(
                    f"{c!r}: {_importable_name(*c.rpartition(':')[::2], mine)}" for c in classes
                )
                source = f"env_make_argument(load_config(run_dir), {name!r}, {{{builders}}})"
                notes.append(
                    f"{name} is too long to print ({written} characters written out): "
                    "env_make_argument makes it from the session's config"
                )
            for module, names in mine.items():
                imports.setdefault(module, set()).update(names)
        elif kept_as_repr(form):
            source = f"<{form['repr']}>"
            notes.append(
                f"{name} was given as an object the session keeps only as this text: make it "
                "as it was"
            )
        else:
            source = repr(form)
        if name.isidentifier() and not keyword.iskeyword(name):
            named.append(f"{name}={source}")
        else:
            odd.append(f"{name!r}: {source}")
    if odd:
        named.append("**{" + ("," + _BREAK).join(odd) + "}")
    local = sorted(imports.pop(_LOCAL_CLASSES, set()))
    notes += [
        f"{c.rpartition('.')[2]} is {c.replace(':', '.')}, a class defined inside a function: "
        "the call needs that class in scope under this name"
        for c in local
    ]
    notes += [f"from {m} import {', '.join(sorted(imports[m]))}" for m in sorted(imports)]
    return named, notes


def _kept_classes(form: Any, found: set[str]) -> set[str]:
    """``found`` with the class (``"module:QualName"``) of each kept object in ``form``."""
    if _is_kept_object(form):
        found.add(form["class"])
        _kept_classes(form["fields"], found)
    elif isinstance(form, dict):
        for v in form.values():
            _kept_classes(v, found)
    elif isinstance(form, list):
        for v in form:
            _kept_classes(v, found)
    return found


# The SIGINT hook the holds install (main thread) and leave in place: outside a hold it hands
# every signal to the handler it was put in front of, so a Ctrl-C acts as before; inside one it
# only notes the signal. Each hook holds its own handler (`_hook`), so a handler of the user's
# put in for a while and then replaced by the hook it replaced (old = signal.signal(SIGINT,
# mine) ... signal.signal(SIGINT, old)) is forgotten with it. Installing a hook costs ~10 us; a
# hold then costs ~1 us.
_hold_depth = 0
_held: list[tuple[int, Any]] = []


def _hook(chained: Any) -> Any:
    """A SIGINT handler in front of ``chained``: noted during a hold, else handed on."""

    def _sigint(signum: int, frame: Any) -> None:
        if _hold_depth > 0:
            if not _held:
                _held.append((signum, frame))
            return
        chained(signum, frame)

    _sigint.torchcbl_chained = chained  # type: ignore[attr-defined]
    return _sigint


def _deliver(signum: int, frame: Any) -> None:
    """Hand a held SIGINT to the handler in force now (the one behind our hook)."""
    handler = signal.getsignal(signal.SIGINT)
    handler = getattr(handler, "torchcbl_chained", handler)
    if callable(handler):
        handler(signum, frame)  # the default handler raises KeyboardInterrupt
    elif handler == signal.SIG_DFL:
        signal.raise_signal(signum)  # what it would have done: end the process


class _InterruptHold:
    """Hold a Ctrl-C (SIGINT) back while memory and disk are brought into step.

    A ``KeyboardInterrupt`` raised between a journal write and the bookkeeping after it (or
    between a record entering :attr:`ConfidentTeacher.records` and its journal line) would
    leave the two out of step: a step on disk that memory lacks, whose number the next step
    reuses. While a hold is active, SIGINT is only noted; :meth:`release` returns what the
    handler would have raised (the caller decides when to raise it), or None. Holds nest:
    the outermost release delivers. Python delivers signals to the main thread only, and a
    handler that is not a Python function (SIG_DFL kills the process, which the journal
    survives; SIG_IGN) is left alone: there, and with ``active=False``, the hold does nothing.

    A hold that finds a handler other than a hook of ours installs a hook in front of it
    (:func:`_hook`) and leaves it there: outside a hold it passes every signal straight on.
    """

    def __init__(self, active: bool = True) -> None:
        global _hold_depth
        self._on = False
        if not active or threading.current_thread() is not threading.main_thread():
            return
        current = signal.getsignal(signal.SIGINT)
        if not hasattr(current, "torchcbl_chained"):
            if not callable(current):
                return
            signal.signal(signal.SIGINT, _hook(current))
        _hold_depth += 1
        self._on = True

    def release(self) -> BaseException | None:
        """End the hold; for a Ctrl-C held back, what the handler raises (returned, not
        raised), else None."""
        global _hold_depth
        if not self._on:
            return None
        self._on = False
        _hold_depth -= 1
        if _hold_depth or not _held:
            return None
        signum, frame = _held.pop()
        try:
            _deliver(signum, frame)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller to raise
            return exc
        return None


def _raise_held(hold: _InterruptHold) -> None:
    """Release ``hold`` and raise what it caught, if anything."""
    late = hold.release()
    if late is not None:
        raise late


_START_AGAIN = "free space (or fix the permissions) and start the session again"


def _remove_new_session_files(path: Path) -> None:
    """Undo a session creation that failed before its first step: the files it made.

    In an order where a kill at any point leaves either the whole session (a session of no
    step, which resumes) or only what a new session may start beside
    (:func:`_check_new_session_dir`). First, where ``config.json`` is not there (the start
    failed writing it), ``config.json.tmp`` is made again (:func:`_mark_unstarted`); then the
    runs file, the writers file and the journal are removed, then the step log (the session
    then reads as one whose creation was killed before its log: it resumes as a session of no
    step, see :func:`_unborn`); then ``config.json`` is renamed to ``config.json.tmp``, after
    which the folder holds no session (its prior demonstrations and starting model, left
    beside that ``.tmp``, are what a start killed before its config.json was in place leaves,
    and a new start removes them); last those and the ``.tmp``. Deleting ``config.json``
    first left a step log with no config, which refused the next start as a
    session whose config was deleted."""
    if not (path / CONFIG_NAME).exists():
        # a start that failed before its config.json was in place (so no log), whose failed
        # write of it removed config.json.tmp: marked again first, so that a kill below leaves
        # what it removes beside the mark, not a prior.npz alone (a kill before this mark,
        # right after the failed write, is the one point left)
        try:
            _mark_unstarted(path)
        except OSError:
            pass
    for name in (
        RUNS_NAME,
        WRITERS_NAME,
        JOURNAL_NAME,
        LOG_NAME + "-wal",  # before the log: a -wal beside no log would apply to a new one
        LOG_NAME + "-shm",
        LOG_NAME,
    ):
        try:
            (path / name).unlink(missing_ok=True)
        except OSError:
            pass
    try:
        (path / CONFIG_NAME).replace(path / (CONFIG_NAME + ".tmp"))  # no session from here on
    except FileNotFoundError:
        pass
    except OSError:  # the folder still holds the session, which resumes as one of no step
        return
    for name in (
        PRIOR_NAME,  # create found none: refused as another session's leftover
        f"{CHECKPOINT_DIR}/model-{0:08d}.pt",  # the starting model (create found no checkpoint)
        CONFIG_NAME + ".tmp",
    ):
        try:
            (path / name).unlink(missing_ok=True)
        except OSError:
            pass
    try:
        (path / CHECKPOINT_DIR).rmdir()  # only if empty
    except OSError:
        pass


def _mark_unstarted(path: Path) -> None:
    """Make ``config.json.tmp`` (empty) in a folder where a new session starts, and fsync the
    folder, before the start writes its prior demonstrations or starting model: those files,
    left by a kill before its ``config.json`` is in place, are then beside it, where
    :func:`_check_new_session_dir` takes them for no session's and a new start clears them
    (:func:`_clear_unstarted`). (Without it a start killed between its ``prior.npz`` and its
    config left a ``prior.npz`` alone, refused as what another session left.) ``config.json``
    is then written through that same name, which its rename takes away.

    Raises:
        OSError: it cannot be made.
    """
    os.close(os.open(path / (CONFIG_NAME + ".tmp"), os.O_WRONLY | os.O_CREAT, 0o644))
    fsync_directory(path)


def _clear_unstarted(path: Path) -> None:
    """Before a new session writes its files where :func:`_check_new_session_dir` let it
    start (under its lock): remove the prior demonstrations and starting model that a start
    killed before its config.json was in place, or a removal killed
    (:func:`_remove_new_session_files`), left beside ``config.json.tmp``; they are no
    session's, and the new one writes its own."""
    for name in (PRIOR_NAME, f"{CHECKPOINT_DIR}/model-{0:08d}.pt"):
        try:
            (path / name).unlink(missing_ok=True)
        except OSError as exc:
            raise _write_error(exc, path / name, "starting the session", _START_AGAIN) from exc


#: What torchcbl leaves in a folder where no session started, beside which a new one may
#: start: the writer lock of a start that failed, the temporary files of a start killed while
#: it wrote its config.json or prior.npz (and checkpoints/.model-<n>.pt.tmp, see below).
_LEFT_WITHOUT_SESSION = (LOCK_NAME, CONFIG_NAME + ".tmp", f".{PRIOR_NAME}.tmp")
_CKPT_TMP_RE = re.compile(r"^\.model-\d{8}\.pt\.tmp$")
_RESUME_ADVICE = "Continue it with ConfidentTeacher.resume(run_dir, env, teacher)"


def _listing(folder: Path) -> list[Path]:
    """The entries of ``folder``, sorted; the store's error if it cannot be listed."""
    try:
        return sorted(folder.iterdir())
    except OSError as exc:
        raise _unreadable(folder, exc) from exc


def _names_a_session_format(config: Path) -> bool:
    """Whether the file ``config`` is a session's config.json: a JSON object whose
    ``format`` is a torchcbl session format (one this version reads or not).

    Raises:
        IncompatibleRunDirError: it cannot be read (:func:`_unreadable`).
    """
    try:
        if not config.is_file():
            return False
        text = config.read_bytes()
    except OSError as exc:
        raise _unreadable(config, exc) from exc
    try:
        data = json.loads(text)
    except (UnicodeDecodeError, json.JSONDecodeError):
        return False
    fmt = data.get("format") if isinstance(data, dict) else None
    return isinstance(fmt, str) and fmt.startswith("torchcbl.session/")


def _a_file_in_the_way(path: Path) -> Path | None:
    """``path`` itself or its nearest parent that is a file (a run directory cannot be made
    there), or None; reads only."""
    return next((p for p in (path, *path.parents) if p.is_file()), None)


def _not_a_directory(path: Path, culprit: Path) -> IncompatibleRunDirError:
    return IncompatibleRunDirError(
        f"run_dir {str(path)!r} cannot be a directory: {culprit} is a file. Give a new "
        "directory path for a new session (or a session's directory to resume it)."
    )


def _check_new_session_path(path: Path) -> None:
    """What :meth:`SessionStore.create` refuses before it writes, checked before a session's
    costly preparation (the fit on its prior demonstrations); reads only, and create checks
    again. Raises :class:`IncompatibleRunDirError` as :func:`_check_new_session_dir` does, or
    where ``path`` is a file or lies under one."""
    culprit = _a_file_in_the_way(path)
    if culprit is not None:
        raise _not_a_directory(path, culprit)
    _check_new_session_dir(path)


def _holds_no_step(path: Path) -> bool:
    """Whether the session in ``path`` holds nothing: no step in its log or journal, no
    prior demonstrations, and no writer running there now (one stopped at its first request,
    Ctrl-C or 'q'). Reads only (the log as the readers open it: no -wal or -shm is made);
    False where any of it cannot be told."""
    try:
        config = json.loads((path / CONFIG_NAME).read_bytes())
        if not isinstance(config, dict) or config.get("prior") or _lock_held(path) is not False:
            return False
        journal = path / JOURNAL_NAME
        if journal.exists() and journal.stat().st_size:
            return False
        log = path / LOG_NAME
        if not log.exists() or log.stat().st_size == 0:
            return True
        mode = "mode=ro" if log.with_name(LOG_NAME + "-wal").exists() else "immutable=1"
        db = sqlite3.connect(f"{log.resolve().as_uri()}?{mode}", uri=True)
        try:
            tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master")}
            return "steps" not in tables or not db.execute("SELECT 1 FROM steps").fetchone()
        finally:
            db.close()
    except (OSError, ValueError, sqlite3.Error):
        return False


def _check_new_session_dir(
    path: Path,
    *,
    name: str = "run_dir",
    resume: str = _RESUME_ADVICE,
    remove: str = "shutil.rmtree(run_dir)",
) -> None:
    """Refuse a folder a new session may not start in; reads only. A new session's folder
    holds that session alone: it may be missing, empty, or hold only what torchcbl leaves
    where no session started (a failed start's ``writer.lock``, a session's empty journal and
    writers file once its log and config went, an empty ``checkpoints/``, the temporary files
    of a start killed while it wrote; beside a ``config.json.tmp``, with no log, the prior
    demonstrations and starting model of a start killed before its config.json was in place,
    which makes that ``.tmp`` first (:func:`_mark_unstarted`), or of a removal killed, see
    :func:`_remove_new_session_files`: the new session removes them).
    ``name`` names the path for the caller (``--run-dir`` at the command line); ``resume``
    says how to continue a session found there, and ``remove`` how to remove the folder of a
    session found there that holds nothing (no step, no prior demonstrations), to start anew.

    Raises:
        IncompatibleRunDirError: ``path`` holds a session, what another session left (its
            journal's steps, its writers, prior demonstrations, checkpoints), or files of
            one's own; or it cannot be listed (:func:`_unreadable`).
    """
    try:
        if not path.is_dir():
            return  # to be made (a path that is a file is said as create makes it)
    except OSError as exc:
        raise _unreadable(path, exc) from exc
    entries = _listing(path)
    names = {e.name for e in entries}
    if LOG_NAME in names and CONFIG_NAME not in names:  # resume would say no config either
        raise IncompatibleRunDirError(
            f"{path} holds a session's {LOG_NAME} but no {CONFIG_NAME}: that session's config "
            "was deleted or moved. Put it back to continue that session (resume), or choose a "
            f"new {name}; torchcbl starts no new session beside another's log. Nothing was "
            "written there."
        )
    if CONFIG_NAME in names:
        if LOG_NAME in names or _names_a_session_format(path / CONFIG_NAME):
            empty = (
                f" It holds no step (nor prior demonstrations): to start afresh there instead, "
                f"remove it first ({remove})."
                if _holds_no_step(path)
                else ""
            )
            raise IncompatibleRunDirError(
                f"{path} already holds a teaching session. {resume} or choose a new {name}." + empty
            )
        # one's own config.json (resume could only refuse it): no session to continue
        raise IncompatibleRunDirError(
            f"{path} holds a {CONFIG_NAME} that is not a torchcbl session's (it names no "
            f"torchcbl.session format), and no session; a new session writes its own "
            f"{CONFIG_NAME} and needs a folder of its own, new or empty: choose another "
            f"{name}. Nothing was written there."
        )
    # a journal's steps, a writers.jsonl's writers and a runs.jsonl's run() calls (whose step
    # numbers and thread counts would read as this session's) and checkpoints belong to
    # another session
    leftovers: list[str] = []
    others: list[str] = []
    # a start killed before its config.json was in place (it makes config.json.tmp before its
    # prior demonstrations and starting model), or the removal of a session that failed at its
    # first step, killed after it renamed config.json aside, leaves config.json.tmp beside
    # those, and no log: no session's
    unstarted = CONFIG_NAME + ".tmp" in names
    starting_model = f"{CHECKPOINT_DIR}/model-{0:08d}.pt"
    for entry in entries:
        try:
            if entry.name in (JOURNAL_NAME, WRITERS_NAME, RUNS_NAME):
                if entry.stat().st_size:
                    leftovers.append(entry.name)
            elif entry.name == PRIOR_NAME and unstarted:
                pass
            elif entry.name == PRIOR_NAME or entry.name.startswith(LOG_NAME):
                leftovers.append(entry.name)
            elif entry.name == CHECKPOINT_DIR and entry.is_dir():
                leftovers += [
                    f"{CHECKPOINT_DIR}/{e.name}"
                    for e in _listing(entry)
                    if not _CKPT_TMP_RE.match(e.name)
                    and not (unstarted and f"{CHECKPOINT_DIR}/{e.name}" == starting_model)
                ]
            elif entry.name not in _LEFT_WITHOUT_SESSION:
                others.append(entry.name + ("/" if entry.is_dir() else ""))
        except OSError as exc:
            raise _unreadable(entry, exc) from exc
    if leftovers:  # a new session would take another session's steps, writers, models
        raise IncompatibleRunDirError(
            f"{path} holds what another session left ({', '.join(leftovers[:3])}"
            f"{', ...' if len(leftovers) > 3 else ''}) but no session; choose a new "
            f"{name} (or move those files away)."
        )
    if others:  # a session's folder holds the session alone: not beside files of one's own
        raise IncompatibleRunDirError(
            f"{path} holds other files ({', '.join(others[:3])}"
            f"{f', and {len(others) - 3} more' if len(others) > 3 else ''}) and no session; a "
            f"new session needs a folder of its own, new or empty: choose another {name}. "
            "Nothing was written there."
        )


_FREE_SPACE = "Free space (or fix the file's permissions), then call run() again or resume."

#: How long a closing writer waits for readers to let go of the log (seconds), see _close_wal.
_WAL_CLOSE_WAIT_S = 2.0


def _close_wal(log: Path) -> None:
    """After the writer's connection closed: fold the ``-wal`` into the log and remove it
    with the ``-shm``, as SQLite does when the last connection closes.

    SQLite does so only when it can lock the log alone; a reader (``mode=ro``) reading at that
    moment keeps both files, and a read-only connection never removes them, so a cleanly
    closed session looked like one whose writer runs or was killed (readers then need the
    ``-shm`` and so write access). The writer, still holding its lock, opens the log again
    until it is alone, for at most :data:`_WAL_CLOSE_WAIT_S` (a reader holds it for one read);
    past that the files stay, which is harmless (readers use ``mode=ro``) and the next writer
    removes them."""
    wal = log.with_name(LOG_NAME + "-wal")
    deadline = time.monotonic() + _WAL_CLOSE_WAIT_S
    while wal.exists() and log.exists():  # (never a new, empty log in its place)
        try:
            db = sqlite3.connect(log, isolation_level=None)
            try:
                db.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchone()
            finally:
                db.close()  # the last connection: folds and removes -wal and -shm
        except sqlite3.Error:
            return  # e.g. a full disk: the next writer does it
        if not wal.exists() or time.monotonic() > deadline:
            return
        time.sleep(0.005)


def _acquire_lock(run_dir: Path) -> Any:
    """Take the run directory's writer lock (``writer.lock``, fcntl.flock: released by the
    kernel when the holder closes it or dies, SIGKILL included) and note the holder in it,
    keeping what the last writer committed (a new session drops it once it knows the
    directory holds no session: :func:`_note_holder`). Returns the open lock
    file."""
    path = run_dir / LOCK_NAME
    try:
        # held open for the writer's life; not O_APPEND, so that the committed line is
        # rewritten in place (pwrite appends on an O_APPEND file on Linux)
        f = os.fdopen(
            os.open(path, os.O_RDWR | os.O_CREAT, 0o644), "r+", encoding="utf-8", errors="replace"
        )
    except OSError as exc:
        raise _write_error(
            exc,
            path,
            "opening the session for writing",
            "Writing a session needs write access to its directory; reading it does not "
            "(load_records, load_model).",
        ) from exc
    try:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        f.seek(0)
        holder = (f.read().splitlines() or ["unknown"])[0]
        f.close()
        if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            raise _write_error(exc, path, "locking the session", _FREE_SPACE) from exc
        err = SessionLockedError(
            f"{run_dir} is already open for writing ({path} is locked by {holder}). One writer "
            "per session: close the other ConfidentTeacher (close() or a with-block) or stop "
            "that process, then resume; a writer that died releases the lock by itself. "
            "Reading meanwhile needs no lock (load_records, load_model)."
        )
        err.holder = holder
        raise err from None
    _note_holder(f, keep_count=True)
    return f


def _note_holder(f: Any, *, keep_count: bool) -> None:
    """Note this process as ``writer.lock``'s holder (``f``: the open, locked file), keeping
    the last writer's count line if ``keep_count``; a note that cannot be written is left out
    (the lock holds without it)."""
    try:
        # what the last writer committed stays (its log is checked against it before a
        # writer opens it, see _check_committed); the writer then notes its own counts
        committed = _committed_line(os.pread(f.fileno(), 4096, 0)) if keep_count else None
        note = f"process {os.getpid()} on {socket.gethostname()}\n".encode() + (
            committed.group(0) if committed else b""  # a torn or damaged one not kept
        )
        # straight to the file, not through f's buffer: a note that does not fit (full disk)
        # would stay buffered, and closing the lock would write it again and raise, hiding
        # the error that closing it goes with. Written over the old note, then cut to its
        # length: never a moment (a SIGKILL, a write that fails) without the count line
        if os.pwrite(f.fileno(), note, 0) == len(note):
            os.ftruncate(f.fileno(), len(note))
    except OSError:
        pass  # the lock holds without the note


#: writer.lock's second line: what the writer has committed to steps.sqlite so far, and
#: whether steps.journal holds lines not yet committed ("lines", set before the first line
#: after a commit; "empty", set by the commit), then a tab and the CRC-32 of what precedes it
#: in 8 hex digits, as journal lines end; fixed width, rewritten in place. So a log found
#: holding less (its -wal lost) or a journal missing that held lines is said to be that
#: instead of read as a shorter session. Readers read it without a lock: a read overlapping
#: the rewrite can mix the two lines (999 -> 1000 read as 1999), which the CRC tells.
_COMMITTED_LINE = "committed to steps.sqlite: %12d steps, %12d corrections; steps.journal: %s"
_COMMITTED_RE = re.compile(
    rb"(committed to steps\.sqlite: +(\d+) steps, +(\d+) corrections; "
    rb"steps\.journal: (empty|lines))\t([0-9a-f]{8})\n"
)


def _committed_line(data: bytes) -> re.Match[bytes] | None:
    """writer.lock's committed line in ``data`` (the file's bytes), None if there is none or
    its CRC-32 does not match (a read torn by the writer's rewrite, or a damaged file)."""
    m = _COMMITTED_RE.search(data)
    return m if m is not None and int(m.group(5), 16) == _crc32(m.group(1)) else None


def _read_committed(run_dir: Path) -> tuple[int, int, bool] | None:
    """(steps, corrections, whether the journal holds lines not yet committed) the session's
    writers committed, as writer.lock says; None when it says nothing (no lock file, one this
    user may not read, one written by a torchcbl that did not note it, or a line read while
    the writer rewrote it)."""
    try:
        m = _committed_line((run_dir / LOCK_NAME).read_bytes())
    except OSError:
        return None
    return None if m is None else (int(m.group(2)), int(m.group(3)), m.group(4) == b"lines")


def _check_committed(
    run_dir: Path,
    committed: tuple[int, int, bool] | None,
    steps: list[int],
    n_corrections: int,
    stacklevel: int,
) -> None:
    """Raise if the log (steps.sqlite, its -wal and the journal: its step numbers ``steps``,
    in order, and ``n_corrections``) lacks the last steps, or corrections, its writers
    committed (``committed``, read before the log), as it does without its -wal, or if the
    journal is missing while it held steps not yet committed. With the -wal and the journal
    there, a log holding fewer is what a copy taken while the writer ran holds (a copy that took
    writer.lock after the log: rsync does, by name order) or what a power cut left: warned
    (``stacklevel`` for :func:`warnings.warn`), and read as it is. (Steps missing before others
    the log holds are a gap, said by the readers and resume.)"""
    if committed is None:
        return
    journal, lock = run_dir / JOURNAL_NAME, run_dir / LOCK_NAME
    if committed[2] and not journal.exists():
        raise CorruptSessionError(
            f"{journal} is missing, but {lock} says it held steps its writer had not yet "
            f"committed to {LOG_NAME} (the writer was killed, or the directory copied while "
            f"it ran): they are only in that file. Put it back (from the directory it was "
            "copied from, or a backup), then read or resume the session again; never delete "
            f"it by hand. torchcbl changed nothing. If it is lost for good, remove {lock} (with "
            "no writer running) to read and resume the session with what is left."
        )
    n_steps = bisect.bisect_left(steps, committed[0])  # those below the committed count
    if n_steps and steps[n_steps - 1] != n_steps - 1:
        return  # a gap among them: rows deleted by hand, said as such (_gap_text)
    if n_steps >= committed[0] and n_corrections >= committed[1]:
        return
    log = run_dir / LOG_NAME
    wal = log.with_name(LOG_NAME + "-wal")
    if wal.exists():  # the files are all there: an earlier state of the session, read as is
        warnings.warn(
            f"{run_dir}: {lock.name} says its writer committed {committed[0]} steps and "
            f"{committed[1]} corrections, but the log holds {n_steps} of those steps and "
            f"{n_corrections} corrections. Either the directory was copied while its writer "
            f"ran (a copy that took {lock.name} after the log, as rsync does by name order, "
            "after the writer committed more; the copy holds the session as it was "
            "earlier), or a power cut lost commits not yet on the disk (or an older "
            f"{log.name} was put back). What the files hold is read; "
            f"a resume goes on from there and notes its own counts in {lock.name}. For the "
            "steps missing here, read the directory this one was copied from, once its writer "
            "has stopped.",
            stacklevel=stacklevel + 1,
        )
        return
    raise CorruptSessionError(
        f"{run_dir}: its writer committed {committed[0]} steps and {committed[1]} corrections "
        f"({lock} says so), but the log holds {n_steps} of those steps and {n_corrections} "
        f"corrections: the rest are not in the session's files. {wal} is missing: a session "
        "that was not closed cleanly (killed, or copied while it ran) keeps its latest commits "
        f"in that file. Put it back beside {log.name} (from the directory it was copied from, "
        "or a backup), then read or resume the session again; never delete it by hand. (Or "
        f"the last rows were deleted from {log.name} by something other than torchcbl.) "
        f"torchcbl changed nothing. If they are lost for good, remove {lock} (with no writer "
        "running) to read and resume the session with what is left."
    )


_CHECKPOINT_LATER = (
    "The session and its model in memory are intact and the step log is complete; a missing "
    "checkpoint is refitted from the log on resume and by load_model. " + _FREE_SPACE
)


def _lost_hand_refit(n: int, max_new: int) -> str:
    """What a failed write of the checkpoint of a refit by hand on ``n`` labels leaves: the
    ``after`` of its :class:`SessionWriteError` (see :func:`_write_error`)."""
    return (
        "The session and its model in memory are intact and the step log is complete, but "
        "this was a refit by hand, which moved the refit schedule, and only its checkpoint "
        f"records it: until it is written, resume and load_model rebuild the stages from {n} "
        f"labels up to the loop's next refit, due at {n + max_new} labels, on the regular "
        f"schedule instead, not on these {n} labels (the session's newest model too, until "
        "that refit is saved). The teacher keeps this model and writes it with its next "
        "checkpoint or at close(): free space (or fix the file's permissions), then call "
        "run() again. Those stages stay on the regular schedule for good where the process "
        "ends before close() (killed, or exiting without calling it: nothing writes it on "
        "the way out), where the write fails at close() too, or where a Ctrl-C interrupts "
        "close() before it is written."
    )


def _lost_at_close(
    n: int, max_new: int | None, saved: int | None = None, last: int | None = None
) -> str:
    """The warning's tail where :meth:`SessionStore.close` could not write the checkpoint
    of a refit by hand on ``n`` labels that an earlier write failed to save; ``saved``: the
    smallest count above ``n`` whose checkpoint is there (where the affected stages end, if
    before the loop's next refit); ``last``: the last refit by hand from ``n`` on also lost,
    each within ``max_new`` labels of the one before (the loop's next refit is due
    ``max_new`` labels after it; ``n`` where none)."""
    if last is None:
        last = n
    if saved is not None and (max_new is None or saved < last + max_new):
        end = f"the refit saved at {saved} labels"
    else:
        end = "the loop's next refit" + (
            "" if max_new is None else f", due at {last + max_new} labels"
        )
    return (
        "This was a refit by hand whose checkpoint an earlier write could not save either, "
        "and the teacher closed without it: resume and load_model rebuild the stages from "
        f"{n} labels up to {end}, on the regular schedule, not on these "
        f"{n} labels, for good. The step log is complete."
    )


def _warn_unwritten(said: list[str]) -> None:
    """One warning (stacklevel: the caller of ``ConfidentTeacher.close`` or ``run``) for the
    checkpoints of refits by hand left unwritten, ``said`` one text each: every one named,
    even with warnings as errors (which raise the first warning given). None for none."""
    if not said:
        return
    if len(said) > 1:
        said = [
            f"{len(said)} checkpoints of refits by hand were not written:",
            *(f"({i}) {one}" for i, one in enumerate(said, 1)),
        ]
    warnings.warn(" ".join(said), UserWarning, stacklevel=5)


def _cpu_state(model: torch.nn.Module, *, clone: bool = False) -> dict[str, Any]:
    """``model``'s state dict (a new OrderedDict, its _metadata kept) with its tensors on the
    CPU whatever the model's device: a session taught on a GPU resumes, and its policy
    loads, on a machine without one. ``clone``: copies, which later refits leave alone."""
    state = model.state_dict()
    for name, value in state.items():
        if isinstance(value, torch.Tensor):
            value = value.detach().cpu()
            state[name] = value.clone() if clone else value
    return state


def _drop_tracebacks(exc: BaseException, outer: BaseException | None) -> None:
    """Drop the traceback of ``exc`` and of every exception in its ``__cause__`` and
    ``__context__`` chains: their frames (and what those hold) are then freed with them.
    ``outer``: the exception a caller was handling already (its context), left as it is."""
    chain: list[BaseException | None] = [exc]
    seen: set[int] = set()
    while chain:
        one = chain.pop()
        if one is None or one is outer or id(one) in seen:
            continue
        seen.add(id(one))
        one.with_traceback(None)
        chain += [one.__cause__, one.__context__]


def _write_checkpoint(
    run_dir: Path,
    model: torch.nn.Module | None,
    n_demonstrations: int,
    digest: str | None,
    after: str = _CHECKPOINT_LATER,
    state: dict[str, Any] | None = None,
) -> Path:
    """Write ``checkpoints/model-<n>.pt`` under a temporary name, then rename it into place;
    a failure is a :class:`SessionWriteError` ending with ``after``. ``state``: the state to
    write (:func:`_cpu_state`) instead of ``model``'s."""
    directory = run_dir / CHECKPOINT_DIR
    path = directory / f"model-{n_demonstrations:08d}.pt"
    tmp = directory / f".model-{n_demonstrations:08d}.pt.tmp"
    outer = sys.exc_info()[1]  # one a caller is handling: not this write's to change
    if state is None:
        assert model is not None
        state = _cpu_state(model)
    payload: dict[str, Any] = {"n_demonstrations": n_demonstrations, "state_dict": state}
    if digest is not None:
        payload["labels_sha256"] = digest
    try:
        # the bytes written by Python, not by torch.save: a full disk is then an OSError
        # saying so (ENOSPC), where torch.save's own writer fails with a C++ assertion
        # ("[enforce fail at inline_container.cc:...] unexpected pos ...")
        buffer = io.BytesIO()
        torch.save(payload, buffer)
        write_durably(path, buffer.getvalue(), tmp)
    except (OSError, RuntimeError) as exc:
        # not kept alive by the error's traceback (held by a caller, a REPL): the model's
        # size over again (its copy on the CPU where it is on a GPU) for each of these; nor
        # by its cause's (write_durably's ``data``, torch.save's payload), dropped
        del buffer, payload, state
        _drop_tracebacks(exc, outer)
        raise _write_error(
            exc, path, f"saving the model fitted on {n_demonstrations} labels", after
        ) from exc
    return path


class SessionStore:
    """Writer and reader of one run directory's step log and checkpoints (private helper).

    Not thread-safe. One writer per run directory, enforced by a lock (``writer.lock``).

    Invariant: a step is in the session once its journal line is written. A journal write that
    fails is undone (the file is cut back to its previous size) and raises
    :class:`SessionWriteError`: the step is not in the session. The rows waiting for a SQLite
    commit are kept in memory until a commit succeeds, so a commit that fails (disk full) is
    simply retried by the next one; the journal keeps them durable meanwhile.
    """

    def __init__(self, run_dir: Path, *, commit_every: int = 32, lock: Any = None) -> None:
        self.run_dir = Path(run_dir)
        self.commit_every = commit_every
        #: the newest checkpoints kept besides checkpoint 0 as each is written (None: all);
        #: recorded in writers.jsonl by :meth:`note_writer`
        self.keep_checkpoints: int | None = None
        self._on_disk: list[int] | None = None  # checkpoints > 0 there (read once, then kept)
        self._max_new: int | None = None  # the session's refit schedule (read by _open)
        self._prune_warned = False
        #: the refits by hand whose checkpoint a write failed to save: (labels, digest, CPU
        #: state), written again with the next checkpoint and at close
        self._unsaved: list[tuple[int, str | None, dict[str, Any]]] = []
        self._lock = _acquire_lock(self.run_dir) if lock is None else lock
        self._db: sqlite3.Connection | None = None
        self._journal = -1
        self._journal_size = 0
        self._pending: list[tuple[str, tuple[Any, ...]]] = []
        self._n_committed = 0  # steps in steps.sqlite, up to the last one
        self._corrected: set[int] = set()  # the steps that have a correction there
        self._note_at = -1  # where writer.lock's committed line starts (-1: not written)
        self._journal_noted = False  # writer.lock says the journal holds uncommitted lines
        #: whether this store has written, or begun to write, a journal line (a step, an
        #: outcome, a correction): a session that may hold one is never removed
        self.logged = False
        try:
            self._open()
        except BaseException:
            self._release()
            raise

    def _open(self) -> None:
        log = self.run_dir / LOG_NAME
        try:
            (self.run_dir / CHECKPOINT_DIR).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise _write_error(exc, self.run_dir, "opening the session", _FREE_SPACE) from exc
        journal = self.run_dir / JOURNAL_NAME
        entries = _journal_entries(journal)  # a damaged journal stops here, untouched
        try:
            # isolation_level=None: we issue BEGIN / COMMIT ourselves, so batching is explicit.
            self._db = sqlite3.connect(log, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            upgraded = _upgrade_format1(self._db)
            self._db.executescript(_SCHEMA)
        except sqlite3.DatabaseError as exc:
            raise _db_error(exc, log, writing=True) from exc
        config = load_config(self.run_dir)
        max_new = config.get("teaching", {}).get("max_new") if isinstance(config, dict) else None
        # the refit schedule, which pruning keeps rebuildable (None: not known, nothing pruned)
        self._max_new = max_new if isinstance(max_new, int) and max_new >= 1 else None
        if upgraded or config.get("format") == "torchcbl.session/1":
            # also where an earlier open upgraded the log but could not write config.json
            # (a format-3 session, one with prior demonstrations, keeps its format)
            config["format"] = FORMAT
            try:
                write_json_atomic(self.run_dir / CONFIG_NAME, config)
            except OSError as exc:
                raise _write_error(
                    exc,
                    self.run_dir / CONFIG_NAME,
                    "upgrading the session to format 2",
                    _FREE_SPACE,
                ) from exc
        for kind, values in entries:  # steps a killed writer left only in the journal
            self._pending.append((_REPLACE if kind == "s" else _SQL[kind], values))
        self.commit()
        try:
            top = self._db.execute("SELECT MAX(step) FROM steps").fetchone()[0]
            self._corrected = {row[0] for row in self._db.execute("SELECT step FROM corrections")}
        except sqlite3.DatabaseError as exc:
            raise _db_error(exc, log, writing=True) from exc
        self._n_committed = 0 if top is None else top + 1
        self._note_committed()
        try:
            self._journal = os.open(journal, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
            os.ftruncate(self._journal, 0)
        except OSError as exc:
            raise _write_error(exc, journal, "opening the journal", _FREE_SPACE) from exc

    def _release(self) -> None:
        if self._db is not None:
            self._db.close()
            self._db = None
            _close_wal(self.run_dir / LOG_NAME)
        if self._journal >= 0:
            os.close(self._journal)
            self._journal = -1
        if self._lock is not None:
            self._lock.close()  # releases the flock
            self._lock = None

    # -- creation ---------------------------------------------------------------------------

    @classmethod
    def create(
        cls,
        run_dir: str | os.PathLike[str],
        config: dict[str, Any],
        initial_model: torch.nn.Module | None = None,
        *,
        initial_digest: str | None = None,
        prior: bytes | None = None,
    ) -> SessionStore:
        """Make a new session directory; ``initial_model``: the fitted model the session starts
        from, saved as checkpoint 0 (with ``initial_digest``, default: that of no label) before
        ``config.json`` is written, so that a directory with a config always holds it (a kill
        in between leaves no session, not one without its model); ``prior``: the bytes of the
        session's prior demonstrations (:func:`prior_bytes`), written to ``prior.npz`` before
        ``config.json`` too (under a temporary name, then renamed). With either, an empty
        ``config.json.tmp`` is made before them (:func:`_mark_unstarted`): a start killed
        before its ``config.json`` is in place leaves them beside it, which a new start clears,
        and a kill at any point leaves a session of no step (which resumes) or a folder a new
        session starts in."""
        path = Path(run_dir)
        try:
            path.mkdir(parents=True, exist_ok=True)
        except (FileExistsError, NotADirectoryError) as exc:  # it, or a parent, is a file
            raise _not_a_directory(path, _a_file_in_the_way(path) or path) from exc
        except OSError as exc:
            raise _write_error(
                exc,
                path,
                "creating the run directory",
                "Free space (or fix the directory's permissions), then create the teacher again.",
            ) from exc
        _check_new_session_dir(path)  # before the lock: a refusal writes nothing
        # the last writer's count kept until the directory is known to hold no session: a
        # refused start must not drop the count of the session it was refused for
        lock = _acquire_lock(path)
        started = False
        try:
            _check_new_session_dir(path)  # again, locked: another start may have come between
            _note_holder(lock, keep_count=False)  # a count left by no session: not this one's
            started = True
            if prior is not None or initial_model is not None:
                try:  # before prior.npz and checkpoint 0: a kill leaves them beside it
                    _mark_unstarted(path)
                except OSError as exc:
                    marker = path / (CONFIG_NAME + ".tmp")
                    raise _write_error(exc, marker, "starting the session", _START_AGAIN) from exc
            _clear_unstarted(path)
            if prior is not None:
                _write_atomic(path / PRIOR_NAME, prior, "starting the session", _START_AGAIN)
            if initial_model is not None:  # a resume can only load it: no label refits it
                ckpts = path / CHECKPOINT_DIR
                try:
                    ckpts.mkdir(exist_ok=True)
                except OSError as exc:
                    raise _write_error(exc, ckpts, "starting the session", _START_AGAIN) from exc
                digest = LabelDigest().hexdigest() if initial_digest is None else initial_digest
                _write_checkpoint(path, initial_model, 0, digest, after=_START_AGAIN)
            try:
                write_json_atomic(path / CONFIG_NAME, config)
            except OSError as exc:
                raise _write_error(
                    exc, path / CONFIG_NAME, "starting the session", _START_AGAIN
                ) from exc
            store = cls(path, lock=lock)
        except BaseException as exc:
            if started:  # nothing was recorded: leave the directory as no session, not half one
                _remove_new_session_files(path)
                if isinstance(exc, SessionWriteError):
                    exc.add_note(f"torchcbl: {path} was left without a session; {_START_AGAIN}")
            lock.close()
            raise
        return store

    def discard_new(self) -> None:
        """Undo :meth:`create` for a session that failed before its first step (nothing is
        recorded): close it and remove its files while still holding the lock, so that the
        directory holds no session and creating it again starts afresh."""
        lock, self._lock = self._lock, None
        try:
            self._release()
            _remove_new_session_files(self.run_dir)
        finally:
            if lock is not None:
                lock.close()

    @classmethod
    def open_for_resume(
        cls,
        run_dir: str | os.PathLike[str],
        *,
        commit_every: int = 32,
        check: Callable[[list[StepRecord], list[CorrectionRecord]], None] | None = None,
    ) -> tuple[SessionStore, list[StepRecord], list[CorrectionRecord]]:
        """Open an existing session for writing: replay its journal, mark a demonstration
        whose outcome was never written as interrupted, upgrade a format-1 log, and return the
        store with every record and correction.

        Every refusal comes before anything is written (the lock, the journal, the log): the
        log is read first, read-only, and each of its steps parsed; ``check`` is then called
        with those records and corrections (a demonstration whose outcome never came still
        pending; it must not change them), and what it raises refuses the resume with no file
        touched.

        The records returned are the log as it is once locked (a writer may have logged more,
        or finished a demonstration, between the two): it is read again then, and a row read
        from SQLite both times and equal keeps the record parsed from it the first time (rows
        the journal set or changed are parsed again, as are new and changed ones), so an
        unchanged log is parsed once."""
        run = Path(run_dir)
        load_config(run_dir)
        _check_log_present(run)
        committed = _read_committed(run)  # before the log: a writer commits first
        from_journal: set[int] = set()
        db = _open_readonly(run)
        try:
            rows, corrected = _rows(db, run / JOURNAL_NAME, run / LOG_NAME, from_journal)
        finally:
            db.close()
        steps = [row[0] for row in rows]
        _check_committed(run, committed, steps, len(corrected), stacklevel=3)
        missing = _missing_steps(steps)
        if missing:  # the loop numbers a new step len(records): it would take a logged number
            raise CorruptSessionError(
                f"cannot resume the session in {run_dir}: {_gap_text(missing)}. Resuming "
                "would log new steps under numbers the log already holds. Nothing was changed. "
                "Restore the run directory from a backup; where the lost steps were only in "
                f"{JOURNAL_NAME} (a line removed), torchcbl.session.repair_journal(run_dir) "
                "keeps the steps before the gap and copies the journal aside."
            )
        records = _records_of(rows, run)  # a step that cannot be read: refused here
        if check is not None:
            check(records, _corrections_of(records, corrected))
        # the records parsed from rows read from SQLite, by step: read again under the lock, a
        # row found equal keeps its record (a pending one comes back finished or marked
        # interrupted: unequal). A row of the journal's is parsed again: replayed into SQLite,
        # it may come back otherwise than it was read (a reward of -0.0 as 0.0)
        known = {
            row[0]: (row, record)
            for row, record in zip(rows, records, strict=True)
            if row[0] not in from_journal
        }
        del rows
        store = cls(run, commit_every=commit_every)
        try:
            store.finalize_pending()
            records, corrections = store.records_and_corrections(known)
        except BaseException:
            store._release()
            raise
        return store, records, corrections

    def note_writer(
        self,
        first_step: int,
        model_device: str = "cpu",
        *,
        env_versions: dict[str, str] | None = None,
    ) -> None:
        """Append who writes from ``first_step`` on to ``writers.jsonl``: torch's thread count,
        the model's device and versions (results are bit-identical only for the same thread
        count and device), :attr:`keep_checkpoints` (what a resume keeps by default) and
        ``env_versions``, what the env runs on as its ``describe_versions()`` says (None: the
        env has no such hook)."""
        line = json.dumps(
            {
                "first_step": first_step,
                "env_versions": env_versions,
                "keep_checkpoints": self.keep_checkpoints,
                "model_device": model_device,
                "torch_num_threads": torch.get_num_threads(),
                "torch_num_interop_threads": torch.get_num_interop_threads(),
                "torch_version": torch.__version__,
                "numpy_version": np.__version__,
                "pid": os.getpid(),
                "started_utc": datetime.datetime.now(datetime.UTC).isoformat(),
            },
            sort_keys=True,
        )
        path = self.run_dir / WRITERS_NAME
        try:
            with open(path, "a", encoding="utf-8") as f:
                f.write(line + "\n")
        except OSError as exc:
            raise _write_error(exc, path, "recording the writer", _FREE_SPACE) from exc

    def note_run(self, first_step: int, stops: Mapping[str, Any]) -> None:
        """Append the ``run()`` call whose first step is ``first_step`` to ``runs.jsonl``,
        with ``stops``, the stop settings in force for it; called before that step is taken,
        so a kill in between leaves a record past the log's end (passed over by the readers).

        A line left torn by a kill (no newline at the file's end: never acknowledged, its
        run() took no step) is cut off first, so that this one starts a line of its own. A
        write that fails is cut back likewise (nothing of it stays) and raises.

        Raises:
            SessionWriteError: the line could not be written (e.g. disk full); nothing of
                the run() is recorded and it takes no step.
        """
        line = (
            json.dumps(
                {
                    "first_step": first_step,
                    "stops": dict(stops),
                    "started_utc": datetime.datetime.now(datetime.UTC).isoformat(),
                },
                sort_keys=True,
            )
            + "\n"
        ).encode()
        path = self.run_dir / RUNS_NAME
        what = f"recording the run() from step {first_step}"
        after = f"That run() took no step. {_FREE_SPACE}"
        try:
            fd = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o666)
        except OSError as exc:
            raise _write_error(exc, path, what, after) from exc
        size: int | None = None
        try:
            size = os.fstat(fd).st_size
            if size:
                tail = os.pread(fd, min(size, 4096), max(size - 4096, 0))
                if not tail.endswith(b"\n"):  # torn by a kill: its run() took no step
                    cut = tail.rfind(b"\n")
                    if cut >= 0 or size <= 4096:
                        size = max(size - 4096, 0) + cut + 1
                        os.ftruncate(fd, size)
                    else:  # a line longer than any run() writes: kept, as a bad line
                        line = b"\n" + line
            written = os.write(fd, line)
            if written != len(line):
                raise OSError(errno.ENOSPC, f"short write ({written} of {len(line)} bytes)")
        except OSError as exc:
            try:  # cut a partly written line off
                if size is not None:
                    os.ftruncate(fd, size)
            except OSError:
                pass
            raise _write_error(exc, path, what, after) from exc
        finally:
            os.close(fd)

    # -- writing ----------------------------------------------------------------------------

    def commit(self) -> None:
        """Commit the waiting rows to SQLite, then empty the journal (they are in both).

        Raises:
            SessionWriteError: the commit failed (e.g. disk full). Nothing is lost: the rows
                stay in the journal and in memory, and the next commit retries them. A row
                that conflicts with one already in the log (another process wrote to it) is
                said to be that, not a full disk: no retry mends it.
        """
        pending = self._pending
        if not pending:
            return
        db = self._db
        assert db is not None
        # a Ctrl-C waits for the end: between COMMIT and emptying the list, the next commit
        # would insert the same steps again and fail on every later try
        hold = _InterruptHold()
        try:
            try:
                db.execute("BEGIN")
                for sql, values in pending:
                    db.execute(sql, values)
                db.execute("COMMIT")
            except BaseException as exc:
                if db.in_transaction:
                    try:
                        db.execute("ROLLBACK")
                    except sqlite3.Error:
                        pass
                if not isinstance(exc, sqlite3.Error):
                    raise
                if isinstance(exc, sqlite3.IntegrityError):  # a retry cannot mend this one
                    after = (
                        f"A row conflicts with one already in {LOG_NAME}: another process "
                        "wrote to this session's log, or torchcbl has a defect; it is not a "
                        f"full disk. Nothing is lost yet: the rows stay in {JOURNAL_NAME} and "
                        "in memory. Stop here, keep the directory as it is (do not delete the "
                        "journal) and report it."
                    )
                else:
                    after = (
                        f"Nothing is lost: they stay in {JOURNAL_NAME} and the next commit "
                        f"retries them. {_FREE_SPACE}"
                    )
                what = f"committing {len(pending)} journalled rows"
                raise _write_error(exc, self.run_dir / LOG_NAME, what, after) from exc
            n, c = self._n_committed, len(self._corrected)
            for sql, values in pending:
                if sql is _CORRECT:
                    self._corrected.add(values[0])
                elif sql is not _FINISH:
                    self._n_committed = max(self._n_committed, values[0] + 1)
            pending.clear()
            if (n, c) != (self._n_committed, len(self._corrected)) or self._journal_noted:
                self._journal_noted = False  # its lines are all in steps.sqlite now
                self._note_committed()
            try:
                os.ftruncate(self._journal, 0)
                self._journal_size = 0
            except OSError:
                pass  # lines also in SQLite are harmless: replaying them changes nothing
        finally:
            _raise_held(hold)

    def _note_committed(self) -> None:
        """Note in writer.lock what steps.sqlite holds (after a commit): one ``pwrite`` in
        place. Best-effort: a note that cannot be written leaves the check on a lower count
        (or none), never a false alarm."""
        if self._lock is None:
            return
        line = (
            _COMMITTED_LINE
            % (self._n_committed, len(self._corrected), "lines" if self._journal_noted else "empty")
        ).encode()
        line = b"%s\t%08x\n" % (line, _crc32(line))
        fd = self._lock.fileno()
        try:
            if self._note_at < 0:  # the first note of this writer: after the holder line
                head = os.pread(fd, 4096, 0).split(b"\n", 1)[0]
                at = len(head) + 1 if head else 0
                # over the last writer's note, then cut to its end (once written whole): the
                # count line is never gone, as it was between a truncation and the write
                if os.pwrite(fd, line, at) == len(line):
                    os.ftruncate(fd, at + len(line))
                    self._note_at = at
            else:
                os.pwrite(fd, line, self._note_at)
        except OSError:
            pass

    def _write(self, kind: str, values: tuple[Any, ...]) -> None:
        """Append one journal line (the step is durable from here on) and queue its row.

        A full batch is committed first, so that anything raised here, a
        :class:`SessionWriteError` of the write or whatever the commit raised but its own
        :class:`SessionWriteError` (which is retried at the next commit), means the line is
        not part of the session. The teaching loop holds a Ctrl-C back around this call
        (:class:`_InterruptHold`), so none lands between the write and its bookkeeping.
        """
        if len(self._pending) >= self.commit_every:
            try:
                self.commit()
            except SessionWriteError:
                pass  # the rows are durable in the journal; the next commit retries them
        line = _journal_line(kind, values)
        if not self._journal_noted:  # before the line: a kill after it finds the note
            self._journal_noted = True
            self._note_committed()
        # before the write: whatever interrupts it (an error of the write, or an exception from
        # a signal handler just after it), the line may be on disk, and the session is kept
        self.logged = True
        try:
            written = _write_fd(self._journal, line)
            if written != len(line):
                raise OSError(errno.ENOSPC, f"short write ({written} of {len(line)} bytes)")
        except OSError as exc:
            try:  # cut a partly written line off, so the next line starts clean
                os.ftruncate(self._journal, self._journal_size)
            except OSError:
                pass
            raise _write_error(
                exc,
                self.run_dir / JOURNAL_NAME,
                f"logging step {values[0] if kind != 'f' else values[-1]}",
                f"That write is not part of the session. {_FREE_SPACE}",
            ) from exc
        self._journal_size += written
        self._pending.append((_SQL[kind], values))

    @staticmethod
    def row(record: StepRecord, *, pending: bool) -> tuple[Any, ...]:
        r = record
        return (
            r.step,
            r.episode,
            _blob(r.observation),
            r.model_action,
            r.confidence,
            r.distance,
            None if r.posterior is None else _blob(r.posterior),
            r.teacher_action,
            r.executed_action,
            r.phase,
            int(r.autonomous),
            r.reward,
            int(r.terminated),
            int(r.truncated),
            _info_json(r.info),
            r.n_demonstrations,
            r.autonomy_rate,
            r.windowed_accuracy,
            int(pending),
            r.actor,
        )

    def commit_demonstration(self, provisional: StepRecord) -> None:
        """Make a demonstration (outcome fields still unknown) durable before its action runs."""
        self._write("s", self.row(provisional, pending=True))

    def finish(self, record: StepRecord) -> None:
        """Complete a logged demonstration with the env's answer."""
        values = (
            record.reward,
            int(record.terminated),
            int(record.truncated),
            _info_json(record.info),
            record.step,
        )
        self._write("f", values)

    def append(self, record: StepRecord) -> None:
        """Log an autonomous step."""
        self._write("s", self.row(record, pending=False))

    def correct(self, correction: CorrectionRecord) -> None:
        """Make a correction (a label for an earlier step's observation) durable."""
        self._write("c", (correction.step, correction.action))

    def finalize_pending(self) -> int:
        """Mark demonstrations whose outcome was never written; returns how many there were."""
        self.commit()
        db = self._db
        assert db is not None
        try:
            db.execute("BEGIN")
            cur = db.execute(
                "UPDATE steps SET truncated = 1, terminated = 0, reward = NULL, "
                "info = ?, pending = 0 WHERE pending = 1",
                (json.dumps({"torchcbl_interrupted": True}),),
            )
            db.execute("COMMIT")
        except sqlite3.Error as exc:
            if db.in_transaction:
                db.execute("ROLLBACK")
            raise _write_error(
                exc, self.run_dir / LOG_NAME, "marking interrupted steps", _FREE_SPACE
            ) from exc
        return cur.rowcount

    def save_checkpoint(
        self,
        model: torch.nn.Module,
        n_demonstrations: int,
        digest: str | None = None,
        *,
        by_hand: bool = False,
        after: str | None = None,
    ) -> Path:
        """Write the model fitted on the first ``n_demonstrations`` labels, with ``digest``
        (:func:`labels_digest` of those labels) to tell it from a stale one later; then, with
        :attr:`keep_checkpoints`, remove the checkpoints older than the newest that many (not
        checkpoint 0, and none named for more labels than this one). ``by_hand``: the model of
        a refit asked by hand (``ConfidentTeacher.refit``), which this checkpoint alone
        records: a failed write says what its loss costs (:func:`_lost_hand_refit`).
        ``after``: what a failed write's message says it leaves (default: the checkpoint is
        refitted from the log where it is missing)."""
        if after is None:
            after = _CHECKPOINT_LATER
        if by_hand and self._max_new is not None:
            after = _lost_hand_refit(n_demonstrations, self._max_new)
        self._write_unsaved()
        try:
            path = _write_checkpoint(self.run_dir, model, n_demonstrations, digest, after)
        except SessionWriteError:
            if by_hand:  # only its checkpoint records it: kept, to be written again
                self._unsaved.append((n_demonstrations, digest, _cpu_state(model, clone=True)))
            raise
        if self.keep_checkpoints is not None:
            self._prune_checkpoints(n_demonstrations, self.keep_checkpoints)
        return path

    def _write_unsaved(self, *, closing: bool = False) -> None:
        """Write the checkpoints of refits by hand that an earlier write failed to save
        (:meth:`save_checkpoint`), oldest first, each pruning as its own write would have;
        one that fails again is kept for the next try, or at ``closing`` said lost (a
        warning, worded and given once every one was tried: where each one's stages end
        depends on which later ones were written, and with warnings as errors it raises only
        then)."""
        failed: list[tuple[int, str]] = []  # (n, what the failed write said)
        refused: list[int] = []  # the id of each entry whose write failed (not interrupted)
        try:
            for entry in list(self._unsaved):
                n, digest, state = entry
                try:
                    _write_checkpoint(self.run_dir, None, n, digest, "", state=state)
                except SessionWriteError as exc:
                    refused.append(id(entry))
                    failed.append((n, str(exc)))
                    continue
                self._unsaved.remove(entry)
                if self.keep_checkpoints is not None:
                    self._prune_checkpoints(n, self.keep_checkpoints)
        except BaseException:  # a Ctrl-C: what it left unwritten said, then it goes on out
            lost: list[str] = []
            untried = [e for e in self._unsaved if id(e) not in refused]  # (or the one cut)
            if closing:
                interrupted = [
                    (n, f"writing {self._path_of(n)} was interrupted. ") for n, _, _ in untried
                ]
                ends = self._lost_ends([n for n, _ in failed + interrupted])
                lost = [
                    f"{said}{_lost_at_close(n, self._max_new, *ends[n])}"
                    for n, said in failed + interrupted
                ]
            else:  # a refused one is kept as it was, to be tried again: no word
                for n, _, _ in untried:
                    then = _lost_hand_refit(n, self._max_new) if self._max_new else ""
                    lost.append(f"writing {self._path_of(n)} was interrupted. {then}")
            with contextlib.suppress(Exception):  # (warnings as errors: the Ctrl-C first)
                _warn_unwritten(lost)
            raise
        if not closing:
            return  # each refused one kept for the next try
        ends = self._lost_ends([n for n, _ in failed])
        _warn_unwritten(
            [f"{said}{_lost_at_close(n, self._max_new, *ends[n])}" for n, said in failed]
        )

    def _path_of(self, n: int) -> Path:
        """The checkpoint of the model fitted on ``n`` labels."""
        return self.run_dir / CHECKPOINT_DIR / f"model-{n:08d}.pt"

    def _lost_ends(self, lost: list[int]) -> dict[int, tuple[int | None, int | None]]:
        """For each refit by hand on ``n`` labels in ``lost`` (those whose checkpoints close()
        leaves unwritten, all of them tried): ``(saved, last)``, the arguments of
        :func:`_lost_at_close` saying where its stages end. Those stages are rebuilt on the
        regular schedule from the checkpoint below them up to the first checkpoint above
        ``n`` there now (a later refit saved), or where none comes before it, up to the
        loop's next refit; each later lost refit by hand before that moved it, to
        ``max_new`` labels after ``last``, the last of them."""
        try:
            above = sorted(m for m, _ in _checkpoint_entries(self.run_dir / CHECKPOINT_DIR))
        except IncompatibleRunDirError:
            above = []
        max_new = self._max_new
        ends: dict[int, tuple[int | None, int | None]] = {}
        for n in lost:
            last = n
            saved = min((m for m in above if m > n), default=None)
            for m in sorted(set(lost)):
                if m <= last or (saved is not None and m > saved):
                    continue
                if max_new is None or m < last + max_new:
                    last = m  # the loop's refit moved again, unsaved
                else:
                    break
            ends[n] = (saved, last)
        return ends

    def _prune_checkpoints(self, newest: int, keep: int) -> None:
        """Remove the files ``model-<m>.pt`` with 0 < m <= ``newest`` but the ``keep`` largest
        m, save those off the refit schedule (the folder is listed once per store, then
        followed in memory); one that cannot be removed stays (harmless: readers take the
        newest), with one warning per store. Only regular files go, the ones a writer wrote:
        a link a person put there stays (removing it would free nothing), and so does what
        it links to.

        A stage whose checkpoint is gone is rebuilt from the newest checkpoint below it (or
        from the start) on the loop's schedule, a refit every ``max_new`` labels
        (:func:`restore_model`). A refit by hand (``ConfidentTeacher.refit``) moves that
        schedule, and its checkpoint alone says where it fell (by its name, even damaged in
        place): so a checkpoint ``c`` goes only where ``c - b`` is a multiple of ``max_new``,
        ``b`` the checkpoint kept below it (0 for none). Every refit between two kept
        checkpoints then lies on the lower one's schedule (all checkpoints there, it holds;
        each removal keeps it)."""
        max_new = self._max_new
        if max_new is None:
            return
        directory = self.run_dir / CHECKPOINT_DIR
        if self._on_disk is None:
            try:
                self._on_disk = sorted(m for m, _ in _checkpoint_entries(directory) if m > 0)
            except IncompatibleRunDirError:
                return  # the checkpoint was just written there; a listing failure is passing
        on_disk = sorted(set(self._on_disk) | {newest})
        below = 0
        older = []
        for m in [m for m in on_disk if m <= newest][:-keep]:
            if (m - below) % max_new == 0:
                older.append(m)  # on the schedule from the one kept below: rebuilt alike
            else:
                below = m  # where a hand refit may have moved the schedule: kept
        self._on_disk = [m for m in on_disk if m not in older]
        for m in older:
            path = directory / f"model-{m:08d}.pt"
            try:
                if path.is_file() and not path.is_symlink():
                    path.unlink()
            except FileNotFoundError:
                pass
            except OSError as exc:
                if not self._prune_warned:
                    self._prune_warned = True
                    warnings.warn(
                        f"could not remove the old checkpoint {path} ({exc}); it is harmless "
                        "(resume and load_model read the newest checkpoints), remove it by "
                        "hand to free its space. Older ones that cannot be removed are not "
                        "reported again.",
                        UserWarning,
                        stacklevel=4,
                    )

    def close(self) -> None:
        """Commit and close; the lock is released even if the commit fails (the journal
        keeps what the commit could not write, and resume replays it). A refit by hand's
        checkpoint that a write failed to save is written first (a warning where it fails
        again: :meth:`_write_unsaved`)."""
        try:
            try:
                self._write_unsaved(closing=True)
            finally:
                self._unsaved = []
                if self._db is not None:
                    self.commit()
        finally:
            self._release()

    # -- reading ----------------------------------------------------------------------------

    def records_and_corrections(
        self, known: dict[int, tuple[tuple[Any, ...], StepRecord]] | None = None
    ) -> tuple[list[StepRecord], list[CorrectionRecord]]:
        """Every record and correction of the log, read through the writer's connection;
        ``known``: ``{step: (row, record)}`` parsed before, each record kept where its step's
        row is read equal to ``row`` (:func:`_records_of`)."""
        assert self._db is not None
        rows, corrections = _rows(self._db, None, self.run_dir / LOG_NAME)
        records = _records_of(rows, self.run_dir, known)
        return records, _corrections_of(records, corrections)


def _db_error(exc: sqlite3.DatabaseError, path: Path, *, writing: bool = False) -> Exception:
    if isinstance(exc, sqlite3.OperationalError) and "readonly" in str(exc):
        return _write_error(  # type: ignore[return-value]
            exc,
            path,
            "opening the step log for writing",
            "Writing a session needs write access to its directory; reading does not "
            "(load_records, load_model).",
        )
    # a writer out of space or hitting an I/O error: the disk's trouble, not the file's
    # (SQLITE_FULL, SQLITE_IOERR and its extended codes)
    code = getattr(exc, "sqlite_errorcode", None)
    if writing and ((code is not None and (code & 0xFF) in (13, 10)) or "disk is full" in str(exc)):
        return _write_error(exc, path, "opening the step log", _FREE_SPACE)
    wal = path.with_name(LOG_NAME + "-wal")
    ran = any(path.with_name(name).exists() for name in (JOURNAL_NAME, WRITERS_NAME))
    if "no such table: steps" in str(exc) and ran and not wal.exists():
        # a writer ran, and its tables are not in the log: they were only in its WAL (no
        # checkpoint since the session started: it was never closed cleanly), now missing
        return CorruptSessionError(
            f"{path} holds no steps table although a writer logged into it, and {wal} is "
            "missing: a session that was not closed cleanly (killed, or copied while it ran) "
            "keeps its commits in that file, here all of them. torchcbl changed "
            f"nothing. Put {wal.name} back beside {path.name} (from the directory it was "
            "copied from, or a backup), then read or resume the session again; do not delete "
            "it by hand."
        )
    return CorruptSessionError(
        f"{path} is not a readable SQLite database ({exc}). torchcbl changed nothing. Restore "
        f"it from a backup, or salvage it with `sqlite3 {path} .recover | sqlite3 "
        "recovered.sqlite` and put the result in its place (keep the damaged file)."
    )


def _unborn(run_dir: Path) -> bool:
    """Whether a session directory was left by a creation killed after its ``config.json``
    was written and before its log was opened in full: no journal (the last file an opening
    creates) and no writers file, no checkpoint but the starting model's 0, and a step log
    that is absent or holds no step table (SQLite creates the file, then its header, then the
    tables). Nothing of it ran, so nothing is lost: it reads as a session of no step and
    resumes as one (the log is made whole then).

    Raises :class:`IncompatibleRunDirError` where a file it looks at, or ``checkpoints/``,
    cannot be read: the read-access error for a permission (e.g. another user's
    ``checkpoints/`` this user may not list), else :func:`_unreadable`'s (an I/O error, ...).
    It renames, deletes and writes nothing."""
    try:
        return _unborn_unchecked(run_dir)
    except OSError as exc:
        raise _unreadable(Path(exc.filename or run_dir), exc) from exc


def _unborn_unchecked(run_dir: Path) -> bool:
    if (run_dir / JOURNAL_NAME).exists() or (run_dir / WRITERS_NAME).exists():
        return False
    kept = [n for n, _ in _checkpoint_entries(run_dir / CHECKPOINT_DIR)]
    if kept not in ([], [0]):
        return False
    log = run_dir / LOG_NAME
    if not log.exists() or log.stat().st_size == 0:
        return True
    # read only, as the readers open a log: immutable=1 creates no -wal or -shm file; with a
    # -wal there (its tables may be only in it), mode=ro
    mode = "mode=ro" if log.with_name(LOG_NAME + "-wal").exists() else "immutable=1"
    try:
        db = sqlite3.connect(f"{log.resolve().as_uri()}?{mode}", uri=True)
        try:
            found = db.execute(
                "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = 'steps'"
            ).fetchone()[0]
        finally:
            db.close()
    except sqlite3.Error:
        return False  # a damaged log is said as such by whoever opens it next
    return found == 0


def _checkpoint_entries(directory: Path) -> list[tuple[int, Path]]:
    """The entries of a session's ``checkpoints/`` named as checkpoints
    (``model-<8 digits>.pt``), whatever they are, with the count of labels their names give
    (none where it is no folder).

    Raises:
        IncompatibleRunDirError: the folder cannot be listed (:func:`_unreadable`).
    """
    try:
        if not directory.is_dir():
            return []
        matched = [(_CKPT_RE.match(e.name), e) for e in directory.iterdir()]
    except OSError as exc:
        raise _unreadable(directory, exc) from exc
    return [(int(m.group(1)), e) for m, e in matched if m is not None]


def _written_file(path: Path) -> bool:
    """Whether ``path``, listed under a checkpoint's name, may be a file a writer wrote: a
    regular file (followed through a link), or one whose kind cannot be told (an I/O error);
    not a directory, a FIFO or a dangling link, which no writer makes."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except FileNotFoundError:  # a dangling link, or removed since the listing
        return False
    except OSError:
        return True


def _records_refit(path: Path, why: str) -> bool:
    """Whether a checkpoint that could not be loaded (``why``, as
    :func:`_checkpoint_payload` says) still records a refit at its count by its name: a
    damaged one (not a stale one) that a writer may have written (:func:`_written_file`)."""
    return why == "damaged" and _written_file(path)


def _refit_schedule(start: int, k: int, recorded: Iterable[int], max_new: int) -> list[int]:
    """The loop's refits after the one at ``start`` labels up to the one at ``k``: every
    ``max_new`` labels from the last refit, which a refit recorded at a count in between
    (``recorded``: counts with a checkpoint's name, :func:`_recorded_refits`; a refit by hand
    may be one) moves. Ends at ``k``, itself a refit of that schedule (or a recorded one)."""
    if k <= start:
        return []
    counts: list[int] = []
    at = start
    for point in sorted({p for p in recorded if start < p <= k} | {k}):
        counts.extend(range(at + max_new, point, max_new))
        counts.append(point)
        at = point
    return counts


def _check_log_present(run_dir: Path) -> None:
    log = run_dir / LOG_NAME
    if log.is_file() or _unborn(run_dir):
        return
    n = len(_checkpoint_entries(run_dir / CHECKPOINT_DIR))
    raise CorruptSessionError(
        f"{log} is missing, but {run_dir / CONFIG_NAME}"
        + (f" and {n} checkpoints" if n else "")
        + " are there: the step log was deleted or moved. Put it back (with "
        f"{LOG_NAME}-wal if it had one); torchcbl will not start the session over beside "
        "what is left of it. To start afresh, use a new run_dir."
    )


def _record_from_row(row: tuple[Any, ...]) -> StepRecord:
    d = dict(zip(_COLUMNS, row, strict=True))
    pending = bool(d.pop("pending"))
    d["observation"] = _unblob(d["observation"])
    d["posterior"] = _unblob(d["posterior"])
    d["autonomous"] = bool(d["autonomous"])
    d["terminated"] = bool(d["terminated"])
    d["truncated"] = bool(d["truncated"])
    d["info"] = json.loads(d["info"])
    if pending:  # read while its writer is between commit and finish, or after a crash
        d["truncated"], d["terminated"], d["reward"] = True, False, None
        d["info"] = {"torchcbl_interrupted": True}
    if d["confidence"] is not None:
        d["confidence"] = float(d["confidence"])
    return StepRecord(**d)


def _table_columns(db: sqlite3.Connection, table: str) -> set[str]:
    return {row[1] for row in db.execute(f"PRAGMA table_info({table})")}


def _rows(
    db: sqlite3.Connection, journal: Path | None, log: Path, from_journal: set[int] | None = None
) -> tuple[list[tuple[Any, ...]], dict[int, int]]:
    try:
        return _rows_unchecked(db, journal, from_journal)
    except sqlite3.DatabaseError as exc:
        raise _db_error(exc, log) from exc


def _rows_unchecked(
    db: sqlite3.Connection, journal: Path | None, from_journal: set[int] | None = None
) -> tuple[list[tuple[Any, ...]], dict[int, int]]:
    """Every step row of the log in step order, with a journal's lines applied on top, and the
    corrections ``{step: action}``; the steps whose rows a journal line set or changed are
    added to ``from_journal`` where given.

    The journal is read first: a writer that commits and empties it in between has then put
    those rows in SQLite, where the SELECT finds them. A finished SQLite row is never replaced
    by an older journal line. A format-1 log (no ``actor`` column) gets its actor derived.
    """
    entries = [] if journal is None else _journal_entries(journal)
    columns = _table_columns(db, "steps")
    if "actor" in columns:
        cur = db.execute(f"SELECT {', '.join(_COLUMNS)} FROM steps ORDER BY step")
        rows = {row[0]: row for row in cur}
    else:
        cur = db.execute(f"SELECT {', '.join(_FORMAT1_COLUMNS)} FROM steps ORDER BY step")
        label = _COLUMNS.index("teacher_action")
        rows = {row[0]: (*row, _derived_actor(row[label])) for row in cur}
    corrections: dict[int, int] = {}
    if _table_columns(db, "corrections"):
        corrections = dict(db.execute("SELECT step, action FROM corrections"))
    at = {name: i for i, name in enumerate(_COLUMNS)}
    pending = at["pending"]
    for kind, values in entries:
        if kind == "c":
            corrections[int(values[0])] = int(values[1])
            continue
        step = values[0] if kind == "s" else values[-1]
        if kind == "s":
            if step in rows and not rows[step][pending]:
                continue  # a finished row stays
            rows[step] = values
        elif step in rows and rows[step][pending]:
            row = list(rows[step])
            for name, v in zip(FINISH_FIELDS, values[:4], strict=True):
                row[at[name]] = v
            row[pending] = 0
            rows[step] = tuple(row)
        else:
            continue  # it finishes no pending row
        if from_journal is not None:
            from_journal.add(step)
    return [rows[k] for k in sorted(rows)], corrections


def _records_of(
    rows: list[tuple[Any, ...]],
    run_dir: Path,
    known: dict[int, tuple[tuple[Any, ...], StepRecord]] | None = None,
) -> list[StepRecord]:
    """The records of ``rows``; ``known``: ``{step: (row, record)}`` parsed before, a record
    taken as it is where its row equals the one read now (SQLite's rows of one log: equal
    values are of one type in a column of the schema), parsed otherwise."""
    out = []
    for row in rows:
        if known is not None:
            seen = known.get(row[0])
            if seen is not None and seen[0] == row:
                out.append(seen[1])
                continue
        try:
            out.append(_record_from_row(row))
        except (ValueError, TypeError, KeyError) as exc:
            raise CorruptSessionError(
                f"{run_dir}: the logged step {row[0]!r} is not a valid step ({exc}). The log "
                f"({LOG_NAME} or {JOURNAL_NAME}) was changed by something other than torchcbl; "
                "restore the run directory from a backup. Nothing was changed on disk."
            ) from exc
    return out


def _corrections_of(
    records: list[StepRecord], corrections: dict[int, int]
) -> list[CorrectionRecord]:
    by_step = {r.step: r for r in records}
    out = []
    for step in sorted(corrections):
        r = by_step.get(step)
        if r is None:  # a correction can only follow its step; a torn log lost both
            continue
        out.append(
            CorrectionRecord(
                step=step,
                episode=r.episode,
                observation=r.observation,
                executed_action=r.executed_action,
                action=int(corrections[step]),
            )
        )
    return out


def label_sequence(
    records: list[StepRecord], corrections: list[CorrectionRecord]
) -> tuple[list[np.ndarray], list[int]]:
    """Every label of a session in the order it arrived: observations and actions.

    A step's own teacher label comes first, then a correction of that step (which arrives after
    the step was executed and before the next decision).
    """
    by_step = {c.step: c for c in corrections}
    xs: list[np.ndarray] = []
    ys: list[int] = []
    for r in records:
        if r.teacher_action is not None:
            xs.append(r.observation_array)
            ys.append(r.teacher_action)
        c = by_step.get(r.step)
        if c is not None:
            xs.append(c.observation_array)
            ys.append(c.action)
    return xs, ys


def _connect_reader(path: Path, mode: str) -> sqlite3.Connection:
    db = sqlite3.connect(f"{path.resolve().as_uri()}?{mode}", uri=True)
    try:
        db.execute("SELECT COUNT(*) FROM sqlite_master").fetchone()
    except BaseException:
        db.close()
        raise
    return db


def _open_readonly(run_dir: str | os.PathLike[str]) -> sqlite3.Connection:
    """A connection that can never write the step log.

    A cleanly closed session (no ``-wal`` file: no WAL writer has it open) is opened with
    SQLite's ``immutable=1``: no lock, no ``-shm`` / ``-wal`` file created, so it works on a
    read-only mount or a directory of another user and leaves every byte and mtime as it was.
    A session with a ``-wal`` file (a writer runs, or was killed) is opened ``mode=ro``, which
    reads the commits in the WAL through the writer's ``-shm`` index.
    """
    path = Path(run_dir) / LOG_NAME
    _check_log_present(Path(run_dir))
    wal = path.with_name(LOG_NAME + "-wal")
    if not path.is_file() or _unborn(Path(run_dir)):  # its creation was killed: no step yet
        db = sqlite3.connect(":memory:")
        db.executescript(_SCHEMA)
        return db
    try:
        if not wal.exists():
            return _connect_reader(path, "immutable=1")
        return _connect_reader(path, "mode=ro")
    except sqlite3.OperationalError as exc:
        shm = path.with_name(LOG_NAME + "-shm")
        for p in (path, wal, shm):  # a file this user may not read (another user's session)
            if p.exists() and not os.access(p, os.R_OK):
                raise _no_read_access(p) from exc
        if ("unable to open" in str(exc) or "readonly" in str(exc)) and wal.exists():
            raise IncompatibleRunDirError(
                f"{path} cannot be opened read-only ({exc}) and {wal} holds commits that need "
                "write access to the directory to be read. Copy the run directory somewhere "
                "writable (cp -a) and read the copy, or open it once with write access."
            ) from exc
        raise _db_error(exc, path) from exc
    except sqlite3.DatabaseError as exc:
        raise _db_error(exc, path) from exc


def _missing_steps(steps: list[int]) -> list[int]:
    """The step numbers below the last one that ``steps`` (distinct, increasing) lack."""
    if not steps or steps[-1] + 1 == len(steps):
        return []
    have = set(steps)
    return [s for s in range(steps[-1]) if s not in have]


def _sqlite_steps(run: Path) -> set[int]:
    """The step numbers in a session's SQLite log (not its journal), read-only."""
    db = _open_readonly(run)
    try:
        return {row[0] for row in db.execute("SELECT step FROM steps")}
    except sqlite3.DatabaseError as exc:
        raise _db_error(exc, run / LOG_NAME) from exc
    finally:
        db.close()


def _logged(run: Path, journal: list[tuple[str, tuple[Any, ...]]]) -> tuple[list[int], int]:
    """Every step number of a session, the given journal entries' included (read before the
    log), in order (no record is parsed), and how many steps have a correction."""
    db = _open_readonly(run)
    try:
        steps = {row[0] for row in db.execute("SELECT step FROM steps")}
        corrected = set()
        if _table_columns(db, "corrections"):
            corrected = {row[0] for row in db.execute("SELECT step FROM corrections")}
    except sqlite3.DatabaseError as exc:
        raise _db_error(exc, run / LOG_NAME) from exc
    finally:
        db.close()
    steps |= {int(v[0]) for kind, v in journal if kind == "s"}
    corrected |= {int(v[0]) for kind, v in journal if kind == "c"}
    return sorted(steps), len(corrected)


def _gap_text(missing: list[int]) -> str:
    shown = ", ".join(str(s) for s in missing[:5]) + (", ..." if len(missing) > 5 else "")
    return (
        f"its step log lacks {len(missing)} step{'' if len(missing) == 1 else 's'} ({shown}) "
        f"before its last one: rows were deleted from {LOG_NAME}, or lines from "
        f"{JOURNAL_NAME}, by something other than torchcbl (a session's steps are numbered 0, "
        "1, 2, ... without a gap)"
    )


def _read_log(
    run_dir: str | os.PathLike[str], *, depth: int = 0, below: int | None = None
) -> tuple[list[StepRecord], dict[int, int]]:
    """Every record and the corrections ``{step: action}`` of a run directory, read-only;
    warns when steps are missing. The warnings point at the caller of the public reader that
    called this, ``depth`` frames of torchcbl's own between them. ``below``: the records and
    corrections of the steps before that step only (the log is checked whole, but only those
    rows are made records)."""
    run = Path(run_dir)
    wal = run / (LOG_NAME + "-wal")
    log = run / LOG_NAME
    committed = _read_committed(run)  # before the log: a writer commits, then notes it
    for attempt in range(3):
        had_wal = wal.exists()
        before = _file_state(log)
        db = _open_readonly(run)
        try:
            rows, corrections = _rows(db, run / JOURNAL_NAME, log)
        except CorruptSessionError:
            # an immutable read of a file a writer changed meanwhile can look damaged
            if attempt < 2 and not had_wal and _file_state(log) != before:
                continue
            raise
        finally:
            db.close()
        if had_wal or (not wal.exists() and _file_state(log) == before):
            break
        # A writer opened the session while we read without its WAL (and may have closed it
        # again, checkpointing into the log): read again.
    steps = [row[0] for row in rows]
    _check_committed(run, committed, steps, len(corrections), stacklevel=3 + depth)
    if below is not None:  # (rows in step order)
        rows = rows[: bisect.bisect_left(steps, below)]
        corrections = {s: a for s, a in corrections.items() if s < below}
    records = _records_of(rows, run)
    missing = _missing_steps([r.step for r in records])
    if missing:  # never transient: the journal is read before the SELECT (_rows_unchecked)
        warnings.warn(
            f"{run}: {_gap_text(missing)}. What is read is what is left: the labels and "
            "models built from it lack the missing steps' demonstrations. Restore the run "
            f"directory from a backup to have them back; where they were only in {JOURNAL_NAME}"
            ", torchcbl.session.repair_journal(run_dir) keeps the steps before the gap so that "
            "the session can be resumed.",
            stacklevel=3 + depth,
        )
    return records, corrections


def _file_state(path: Path) -> tuple[int, int] | None:
    """(size, mtime in ns) of a file, None if it is gone."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns


def load_records(run_dir: str | os.PathLike[str]) -> list[StepRecord]:
    """All step records of a run directory, in step order (safe while a writer runs).

    Never writes: the directory may be read-only or belong to another user.

    Raises:
        CorruptSessionError: a file of the session is damaged (the message says which and how
            to recover); or its ``-wal`` is missing and the log lacks steps or corrections
            ``writer.lock`` says were committed, or its journal is missing and ``writer.lock``
            says it held steps not yet committed (the module docstring, "A lost -wal").

    Warns:
        UserWarning: the log lacks steps (rows or journal lines removed by something other than
            torchcbl), naming them; the records read are those that remain. Or the log holds
            fewer steps or corrections than ``writer.lock`` says were committed, its ``-wal``
            and journal there (a copy taken while the writer ran, or a power cut): what the
            files hold is read.
    """
    load_config(run_dir)
    return _read_log(run_dir)[0]


def load_corrections(run_dir: str | os.PathLike[str]) -> list[CorrectionRecord]:
    """Every correction of a run directory (labels for earlier steps), in step order."""
    load_config(run_dir)
    records, corrections = _read_log(run_dir)
    return _corrections_of(records, corrections)


def _relabels(config: dict[str, Any]) -> bool:
    return bool(config.get("strategy", {}).get("relabel", False))


def load_labels(run_dir: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """Every label of the session in arrival order (demonstrations and corrections):
    observations [L, D] float64 and actions [L] int64, before any relabelling (D is the
    session's feature count also when there are no labels: [0, D])."""
    return _labels(run_dir)


def _labels(run_dir: str | os.PathLike[str], *, depth: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """:func:`load_labels` for torchcbl's readers, its warnings pointing at the caller of the
    public reader that called it, ``depth`` frames of torchcbl's own between them."""
    config = load_config(run_dir)
    return _label_arrays(config, *_read_log(run_dir, depth=depth + 1))


def _label_arrays(
    config: Mapping[str, Any], records: list[StepRecord], corrections: dict[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """The labels of ``records`` and their ``corrections`` in arrival order
    (:func:`label_sequence`) as arrays: observations [M, D] float64 and labels [M] int64,
    [0, D] and [0] (D from ``config``) for none."""
    xs, ys = label_sequence(records, _corrections_of(records, corrections))
    if not ys:
        n_features = int(config["env"]["n_features"])
        return np.zeros((0, n_features), dtype=np.float64), np.zeros(0, dtype=np.int64)
    return np.stack(xs), np.asarray(ys, dtype=np.int64)


#: Demonstrations' ``actions`` not given: made as a tuple is, from one iterable
_ONE_ITERABLE: Any = object()


class Demonstrations(tuple[np.ndarray, np.ndarray]):
    """A session's training set as :func:`load_demonstrations` returns it: the pair
    ``(observations, actions)``, unpacked or indexed as any tuple, which also says where it
    was read. ``source``: the session directory, absolute; ``n_steps``: the steps its log held
    then (the training set is that of its first ``n_steps`` steps). Both None for one made
    as a tuple is, from one iterable of the two arrays (``Demonstrations(pair)``, as
    ``dataclasses.asdict`` or ``type(d)(...)`` make one again), which names no session.

    A session started from it as it is returned (``ConfidentTeacher(...,
    prior_demonstrations=load_demonstrations(run_dir))``, as ``torchcbl teach
    --prior-demonstrations DIR`` starts one) records both in its config.json, so that where
    its prior demonstrations were taught can be told later (:func:`prior_source`: a driving
    evaluation counts the road they were taught on as taught). The two arrays taken apart, or
    changed (in place too: ``digest``, the :func:`labels_digest` of the pair as it was read,
    no longer matches them), record nothing of it."""

    source: Path | None
    n_steps: int | None
    digest: str | None

    def __new__(
        cls,
        observations: Any,
        actions: Any = _ONE_ITERABLE,
        *,
        source: str | os.PathLike[str] | None = None,
        n_steps: int | None = None,
    ) -> Demonstrations:
        """``(observations, actions)`` read from the session ``source`` at ``n_steps`` steps;
        ``Demonstrations(pair)``: the two items of the iterable ``pair``, as ``tuple(pair)``
        takes them. Without ``source`` and ``n_steps`` (they go together) it names no session,
        and a session started from it records none.

        Raises:
            TypeError: one iterable that is not of two items, or ``source`` without
                ``n_steps`` (or the other way round).
        """
        if actions is _ONE_ITERABLE:
            pair = tuple(observations)
            if len(pair) != 2:
                raise TypeError(
                    "Demonstrations is a pair (observations, actions): expected one iterable "
                    f"of 2 items, got {len(pair)}; or give them as Demonstrations(observations, "
                    "actions)"
                )
        else:
            pair = (observations, actions)
        if (source is None) != (n_steps is None):
            raise TypeError(
                "Demonstrations takes source= (the session read) and n_steps= (its steps "
                f"then) together, or neither; got source={source!r}, n_steps={n_steps!r}"
            )
        self = super().__new__(cls, pair)
        self.source = None if source is None else Path(os.path.abspath(source))
        self.n_steps = None if n_steps is None else int(n_steps)
        self.digest = None if source is None else _pair_digest(*pair)
        return self

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled and copied with its source and digest (a tuple's own would drop them)."""
        source = None if self.source is None else str(self.source)
        return (_demonstrations, (self[0], self[1], source, self.n_steps, self.digest))


def _pair_digest(observations: Any, actions: Any) -> str | None:
    """:func:`labels_digest` of a pair of arrays (observations [N, D], actions [N]); None where
    they are no such pair (what a teacher refuses anyway)."""
    try:
        return labels_digest(list(np.asarray(observations)), np.asarray(actions).tolist())
    except (ValueError, TypeError):
        return None


def _demonstrations(
    x: np.ndarray,
    y: np.ndarray,
    source: str | None,
    n_steps: int | None,
    digest: str | None = None,
) -> Demonstrations:
    """A :class:`Demonstrations` again (pickle's and copy's), with the digest it had (of the
    arrays as read, not as they may have been changed since: kept, not hashed again)."""
    if source is None or digest is None:
        return Demonstrations(x, y, source=source, n_steps=n_steps)
    made = tuple.__new__(Demonstrations, (x, y))
    made.source, made.n_steps, made.digest = Path(os.path.abspath(source)), n_steps, digest
    return made


def load_demonstrations(run_dir: str | os.PathLike[str]) -> Demonstrations:
    """The session's training set, what its model's every fit stands on: observations [M, D]
    float64 and labels [M] int64 ([0, D] and [0] when the session has none), as a
    :class:`Demonstrations` pair, which also names the session and the steps it was read at.

    The prior demonstrations the session started from, if any (:func:`load_prior_demonstrations`),
    then its own labels in arrival order (:func:`load_labels`); with a strategy that relabels
    (``"relabel": true`` in the stored strategy, e.g. Confidence-Based Autonomy), a label for
    an observation already stored, a prior one included, replaces that point's label instead
    of adding a point. So ``prior_demonstrations=load_demonstrations(earlier_run_dir)`` starts
    a session from everything an earlier one was fitted on (and records which session that
    was, :func:`prior_source`).

    Raises:
        CorruptSessionError: the session's ``prior.npz`` is missing or changed.
    """
    x, y, n_steps, _ = _training_set(run_dir)
    return Demonstrations(x, y, source=run_dir, n_steps=n_steps)


def _training_set(
    run_dir: str | os.PathLike[str], *, at_steps: int | None = None, depth: int = 0
) -> tuple[np.ndarray, np.ndarray, int, list[StepRecord]]:
    """:func:`load_demonstrations`'s training set, the steps the log held (the last step's
    number + 1; 0 for none) and the records read; with ``at_steps``, those of the log's steps
    before step ``at_steps`` only (and their corrections: no later row is made a record).
    Warnings point at the caller of the public reader, ``depth`` frames of torchcbl's own
    between them."""
    config = load_config(run_dir)
    prior = _read_prior(run_dir, config)  # (this config: not read again for the prior)
    records, corrections = _read_log(run_dir, depth=depth + 1, below=at_steps)
    n_steps = records[-1].step + 1 if records else 0
    x, y = _label_arrays(config, records, corrections)
    if prior is not None:
        x, y = np.concatenate([prior[0], x]), np.concatenate([prior[1], y])
    if len(y) and _relabels(config):
        x, y = training_set(list(x), y.tolist(), relabel=True)
    return x, y, n_steps, records


@dataclass(frozen=True)
class PriorSource:
    """Where a session's prior demonstrations were read from, as far as it can be told
    (:func:`prior_source`).

    Attributes:
        session: the session directory they were read from (:class:`Demonstrations`), found
            where the session's config.json records it, or else where it was beside this
            session (both moved together), and checked: its training set over its first
            ``n_steps`` steps is, row for row, the prior this session keeps. None where that
            cannot be told.
        n_steps: the steps of that session's log they were read at; None with ``session``.
        unknown: why ``session`` is None, a clause that follows "its N prior demonstrations"
            (given as arrays, or read by a torchcbl that did not record their session, so
            that nothing of their origin is recorded; or read from a session that is not
            there any more, or no longer holds them, or is this session itself, moved to
            where that one was); None otherwise.
    """

    session: Path | None
    n_steps: int | None
    unknown: str | None


def prior_source(run_dir: str | os.PathLike[str]) -> PriorSource | None:
    """Where the prior demonstrations of the session ``run_dir`` were read from; None for a
    session without prior demonstrations.

    A session records the session its prior was read from when it was given them as
    :func:`load_demonstrations` returns them (``torchcbl teach --prior-demonstrations
    SESSION_DIR``): that session's path, absolute and relative to this session's directory,
    and its step count then. It is sought at the recorded path, then at the relative one, and
    taken only where its first steps still give exactly the prior this session keeps (read
    only; its own warnings, a damaged log's, are not passed on) and it is not this session
    itself (moved to where that one was, its first steps can give its own prior). A prior
    given as arrays (a ``.npz`` file's, or arrays of one's own), or that of a session written
    before the source was recorded, has no known source: ``PriorSource(None, None, why)``.

    Raises:
        CorruptSessionError: this session's ``prior.npz`` is missing or changed.
    """
    return _prior_source(run_dir)[0]


def _prior_source(
    run_dir: str | os.PathLike[str],
) -> tuple[PriorSource | None, list[StepRecord]]:
    """:func:`prior_source`, and the records of the source session's first ``n_steps`` steps
    as read to check it (``[]`` where none is found): what a reader of those steps (a
    driving evaluation's scan of the segments they drove) takes instead of reading its log
    again."""
    config = load_config(run_dir)
    prior = _read_prior(run_dir, config)
    if prior is None:
        return None, []
    entry = config["prior"]
    source = entry.get("source")
    if not (
        isinstance(source, dict)
        and isinstance(source.get("session"), str)
        and type(source.get("n_steps")) is int
        and source["n_steps"] >= 0
    ):
        # (a session written before the source was recorded reads as one given arrays)
        unknown = (
            "were given as arrays, or read by a torchcbl that did not record their session, "
            "so where they were taught is not recorded"
        )
        return PriorSource(None, None, unknown), []
    recorded, at_steps = Path(source["session"]), source["n_steps"]
    places = [recorded]
    relative = source.get("relative")
    if isinstance(relative, str):
        beside = Path(os.path.normpath(os.path.join(os.path.abspath(run_dir), relative)))
        if beside != recorded:
            places.append(beside)
    found: list[str] = []
    for place in places:
        if not place.exists():
            found.append(f"{place} is not there")
            continue
        if _same_directory(place, run_dir):  # moved where that session was: not its source
            found.append(f"{place} is this session itself")
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                x, y, _, records = _training_set(place, at_steps=at_steps)
        except (OSError, ValueError) as exc:  # (IncompatibleRunDirError, CorruptSessionError)
            found.append(f"{place} cannot be read ({str(exc).split('. ')[0]})")
            continue
        if np.array_equal(x, prior[0]) and np.array_equal(y, prior[1]):
            return PriorSource(place, at_steps, None), records
        found.append(f"{place} no longer holds them in its first {at_steps} steps")
    unknown = (
        f"were read from the session {recorded} (its first {at_steps} steps), which is not "
        f"there as it was: {'; '.join(found)}"
    )
    return PriorSource(None, None, unknown), []


def _same_directory(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """Whether ``a`` and ``b`` are one directory (by any path or link); False where either
    cannot be looked at."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def latest_checkpoint(
    run_dir: str | os.PathLike[str], *, at_most: int | None = None
) -> tuple[int, Path] | None:
    """(n_demonstrations, path) of the newest checkpoint (with at most ``at_most`` demos);
    None when the session has none.

    Raises:
        IncompatibleRunDirError: ``run_dir`` is not a session directory (no ``config.json``),
            or its ``checkpoints/`` cannot be listed (a permission, an I/O error).
        ValueError: ``at_most`` is not None or an int >= 0.
    """
    if at_most is not None and (
        isinstance(at_most, (bool, np.bool_))
        or not isinstance(at_most, (int, np.integer))
        or at_most < 0
    ):
        raise ValueError(
            f"latest_checkpoint: at_most must be None (the newest checkpoint) or an int >= 0 "
            f"(a count of labels), got {at_most!r}"
        )
    if not (Path(run_dir) / CONFIG_NAME).is_file():
        load_config(run_dir)  # raises, saying what the path is
    best: tuple[int, Path] | None = None
    for n, entry in _checkpoint_entries(Path(run_dir) / CHECKPOINT_DIR):
        if (at_most is None or n <= at_most) and (best is None or n > best[0]):
            best = (n, entry)
    return best


# the model's constructor arguments a session keeps (config.json's model.args)
_MODEL_ARG_NAMES = (
    "n_actions",
    "n_features",
    "max_components",
    "criterion",
    "var_floor",
    "tol",
    "max_iter",
    "seed",
    "refit_growth",
    "n_init",
)


def _model_args(model: torch.nn.Module) -> dict[str, Any]:
    """The constructor arguments of ``model`` a session keeps: its ``init_args`` dict if it
    has one, else the attributes of GaussianMixtureSet's arguments, ``n_init`` left out where
    it is the default 1 (a plain session's config is then the one written before n_init
    existed, which an older torchcbl's GaussianMixtureSet, taking no n_init, still builds;
    readers complete it with :func:`_with_default_args` or the constructor's default)."""
    args = getattr(model, "init_args", None)
    if isinstance(args, dict):
        return dict(args)
    missing = [n for n in _MODEL_ARG_NAMES if not hasattr(model, n)]
    if missing:
        raise ValueError(
            f"cannot record the constructor arguments of {type(model).__name__}: attributes "
            f"{missing} are missing. Pass a torchcbl.GaussianMixtureSet as model."
        )
    kept = {n: getattr(model, n) for n in _MODEL_ARG_NAMES}
    if kept["n_init"] == 1:
        del kept["n_init"]
    return kept


def _unrecorded_args(model_type: type, recorded: dict[str, Any]) -> list[str]:
    """The parameters of ``model_type.__init__`` beyond GaussianMixtureSet's that ``recorded``
    (a session's model arguments) lacks: a subclass's arguments of its own that a session
    keeps only in an ``init_args`` dict of the model's."""
    import inspect

    from torchcbl.gmm import GaussianMixtureSet

    try:
        params = inspect.signature(model_type.__init__).parameters
    except (TypeError, ValueError):  # no signature to read: nothing to say
        return []
    library = inspect.signature(GaussianMixtureSet.__init__).parameters
    plain = (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)
    return [
        name
        for name, p in params.items()
        if name != "self" and p.kind not in plain and name not in library and name not in recorded
    ]


def _warn_unrecorded_args(model: torch.nn.Module) -> None:
    """Warn, as a session starts, where its model's class takes constructor arguments of its
    own that the session will not record (no ``init_args``): a reader or a resume cannot tell
    a model made with other values of them."""
    if isinstance(getattr(model, "init_args", None), dict):
        return
    own = _unrecorded_args(type(model), {})
    if own:
        import warnings

        name = type(model).__name__
        warnings.warn(
            f"{name}'s own arguments ({', '.join(own)}) are not recorded in the session's "
            "config.json, only GaussianMixtureSet's are: a resume or load_model given a "
            f"{name} made with other values of them accepts it. To record them, give the "
            "model an init_args dict of all its constructor arguments (see "
            "docs/architecture.md, 'Contract: ConfidentTeacher').",
            UserWarning,
            stacklevel=3,
        )


def _with_default_args(args: dict[str, Any]) -> dict[str, Any]:
    """A stored session's model arguments, completed with the constructor's defaults for the
    arguments added since it was written (e.g. ``refit_growth``), so an older session resumes
    with a model built with those defaults."""
    import inspect

    from torchcbl.gmm import GaussianMixtureSet

    params = inspect.signature(GaussianMixtureSet.__init__).parameters
    full = {
        name: p.default
        for name, p in params.items()
        if name != "self" and p.default is not inspect.Parameter.empty
    }
    return {**{k: v for k, v in full.items() if k not in args and k in _DEFAULTED}, **args}


# model arguments that sessions written before they existed lacked
_DEFAULTED = ("refit_growth", "n_init")


def build_model(config: dict[str, Any]) -> GaussianMixtureSet:
    """A fresh, unfitted model built from a session config's ``model`` entry.

    Raises:
        IncompatibleRunDirError: the session's model is of another class than torchcbl's
            GaussianMixtureSet (a user's subclass): the message says to pass it as ``model=``.
    """
    from torchcbl.gmm import GaussianMixtureSet

    spec = config.get("model", {})
    if spec.get("class") != "GaussianMixtureSet":
        raise IncompatibleRunDirError(
            f"the session's model is a {spec.get('class')}, a class other than torchcbl's "
            "GaussianMixtureSet (the one a run directory can rebuild), so it is not rebuilt "
            f"from the run directory: {_pass_model(config)} (a fresh one: the session's "
            "state is loaded into it)"
        )
    return GaussianMixtureSet(**spec["args"])


def _given_model(run_dir: str | os.PathLike[str], config: dict[str, Any], model: Any) -> None:
    """Refuse a ``model=`` given to a reader that is not a fresh model of the session's
    class and arguments."""
    try:
        args = _model_args(model)
    except ValueError as exc:
        args = {"error": str(exc)}
    problems = _model_problems(config, type(model).__name__, args, type(model))
    if problems:
        raise IncompatibleRunDirError(
            f"cannot load the model of the session in {run_dir} into the given one: "
            + "; ".join(problems).rstrip(".")
            + "."
        )
    if getattr(model, "is_fitted", False):
        cls = type(model).__name__
        raise ValueError(
            f"model: expected a fresh, unfitted {cls} (the session's model is loaded into it),"
            f" got a fitted one; pass a new one, {cls}(**{config['model']['args']})"
        )


def fit_count(n_demonstrations: int, max_new: int) -> int:
    """Demonstrations the loop's model stands on after ``n_demonstrations``, when every refit
    was the loop's own (one each time ``max_new`` new demonstrations have accumulated)."""
    if isinstance(max_new, bool) or not isinstance(max_new, (int, np.integer)) or max_new < 1:
        raise ValueError(f"max_new must be an int >= 1 (the refit period), got {max_new!r}")
    return (n_demonstrations // max_new) * max_new


class LabelDigest:
    """SHA-256 of a label sequence (each label: its observation as float64 bytes, then its
    action as int64), updated in O(1) per label. A checkpoint stores the digest of the labels
    it was fitted on, so a checkpoint that no longer matches the log is recognised."""

    def __init__(self) -> None:
        self._h = hashlib.sha256()

    def update(self, x: np.ndarray, y: int) -> None:
        self._h.update(np.ascontiguousarray(x, dtype="<f8").tobytes())
        self._h.update(struct.pack("<q", int(y)))

    def hexdigest(self) -> str:
        return self._h.hexdigest()


def labels_digest(xs: list[np.ndarray], ys: list[int]) -> str:
    """:class:`LabelDigest` of a whole label sequence."""
    d = LabelDigest()
    for x, y in zip(xs, ys, strict=True):
        d.update(x, y)
    return d.hexdigest()


def prior_bytes(observations: np.ndarray, actions: np.ndarray) -> bytes:
    """The ``prior.npz`` of a session's prior demonstrations: ``observations`` [N, D] as
    little-endian float64 and ``actions`` [N] as little-endian int64 (no pickled object)."""
    buffer = io.BytesIO()
    np.savez(
        buffer,
        observations=np.ascontiguousarray(observations, dtype="<f8"),
        actions=np.ascontiguousarray(actions, dtype="<i8"),
    )
    return buffer.getvalue()


def _read_prior(
    run_dir: str | os.PathLike[str], config: dict[str, Any]
) -> tuple[np.ndarray, np.ndarray] | None:
    """The prior demonstrations of a session (observations [N, D] float64, actions [N] int64),
    read from its ``prior.npz`` and checked against the SHA-256 its config.json keeps; None for
    a session without them.

    Raises:
        CorruptSessionError: the file is missing, changed or unreadable (never a session
            taught on without it).
    """
    entry = config.get("prior")
    if entry is None:
        return None
    path = Path(run_dir) / PRIOR_NAME
    n = entry["n_demonstrations"]
    restore = (
        f"The session started from {n} prior demonstrations kept in that file, and every "
        "fit of its model includes them, so it is not read or taught on without them. Restore "
        "the file from a backup or a copy of the run directory. Nothing was changed."
    )
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise CorruptSessionError(f"{path} is missing. {restore}") from None
    except PermissionError:
        raise _no_read_access(path) from None
    except OSError as exc:
        raise CorruptSessionError(f"{path} cannot be read ({exc}). {restore}") from exc
    digest = hashlib.sha256(data).hexdigest()
    if digest != entry["sha256"]:
        raise CorruptSessionError(
            f"{path} was changed or damaged: its SHA-256 is {digest}, the session recorded "
            f"{entry['sha256']} in {CONFIG_NAME} when it started. {restore}"
        )
    n_features, n_actions = config["env"]["n_features"], config["env"]["n_actions"]
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            x, y = npz["observations"], npz["actions"]
    except Exception as exc:  # not a zip, a key missing, a pickled array: any of numpy's errors
        raise CorruptSessionError(
            f"{path} is not a readable prior-demonstrations file ({type(exc).__name__}: {exc})."
            f" {restore}"
        ) from exc
    if not (
        x.dtype == np.float64
        and y.dtype == np.int64
        and x.shape == (n, n_features)
        and y.shape == (n,)
        and np.isfinite(x).all()
        and ((y >= 0) & (y < n_actions)).all()
    ):
        raise CorruptSessionError(
            f"{path} holds observations {x.dtype} {x.shape} and actions {y.dtype} {y.shape}; "
            f"expected finite float64 ({n}, {n_features}) and int64 ({n},) in [0, {n_actions})"
            f", as {CONFIG_NAME} says. {restore}"
        )
    return x, y


def load_prior_demonstrations(run_dir: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """The prior demonstrations a session started from (``ConfidentTeacher(...,
    prior_demonstrations=...)``): observations [N, D] float64 and actions [N] int64, as kept
    in its ``prior.npz``; [0, D] and [0] for a session without them. They are not in
    :func:`load_labels` (the session's own labels); :func:`load_demonstrations` (the training
    set) and every fit of the session's model take them first.

    Raises:
        CorruptSessionError: the file is missing or does not match the SHA-256 in config.json.
    """
    config = load_config(run_dir)
    prior = _read_prior(run_dir, config)
    if prior is None:
        n_features = int(config["env"]["n_features"])
        return np.zeros((0, n_features), dtype=np.float64), np.zeros(0, dtype=np.int64)
    return prior


def _checkpoint_payload(
    path: Path, n: int, xs: list[np.ndarray], ys: list[int]
) -> tuple[dict[str, Any] | None, str]:
    """The checkpoint's content if it is readable and was fitted on ``xs[:n], ys[:n]``;
    else (None, "damaged" | "stale")."""
    try:
        if not path.is_file():  # a folder, a dangling link; a FIFO would block the load
            return None, "damaged"
        # map_location: a checkpoint written with CUDA tensors (before 2026-11-26) loads on a
        # machine without CUDA instead of being set aside as damaged
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:  # empty, cut short, not a torch file: any of torch's many errors
        return None, "damaged"
    if not isinstance(payload, dict) or not isinstance(payload.get("state_dict"), dict):
        return None, "damaged"
    digest = payload.get("labels_sha256")  # absent in checkpoints written before it existed
    if digest is not None and digest != labels_digest(xs[:n], ys[:n]):
        return None, "stale"
    return payload, ""


@dataclass(frozen=True)
class _CheckpointScan:
    """A session's ``checkpoints/`` as resume and :func:`load_model` read it
    (:func:`restore_model`): ``n`` and ``payload``, the newest checkpoint of at most the log's
    labels that is readable and was fitted on them (None: none is); ``passed_over``, the
    newer ones of at most those labels that are not, ``(count, path, "damaged" | "stale")``
    newest first; ``beyond``, those named for more labels than the log holds, never read
    (resume sets them aside as ``.stale``: they belong to labels the log lost);
    ``refits``, the counts above ``n`` (above 0 for none) and of at most the log's labels at
    which the names of files that cannot be loaded record a refit, ascending
    (:func:`_recorded_refits`)."""

    n: int | None
    payload: dict[str, Any] | None
    passed_over: list[tuple[int, Path, str]]
    beyond: list[tuple[int, Path]]
    refits: tuple[int, ...] = ()

    def stood_on(self, n_labels: int, max_new: int) -> int:
        """The labels the session's model stood on after ``n_labels``: its last refit, the
        newest recorded (this checkpoint's, or a later one's :attr:`refits`) then one every
        ``max_new`` labels (:func:`_stood_on`)."""
        return _stood_on(self.n or 0, self.refits, n_labels, max_new)


def _stood_on(last: int, refits: Iterable[int], n_labels: int, max_new: int) -> int:
    """The labels a session's model stood on after ``n_labels``: its last refit, the newest
    of ``last`` (a checkpoint's count; 0 for none) and the ``refits`` recorded by names above
    it and of at most ``n_labels`` (:func:`_recorded_refits`), then one every ``max_new``
    labels. The one rule of resume, :func:`load_model`, :func:`load_models` and
    :func:`describe`."""
    moved = max((last, *(r for r in refits if last < r <= n_labels)))
    return moved + fit_count(n_labels - moved, max_new)


def _scan_checkpoints(
    directory: Path,
    n_labels: int,
    base: int,
    all_xs: list[np.ndarray],
    all_ys: list[int],
    entries: list[tuple[int, Path]] | None = None,
) -> _CheckpointScan:
    """Find the checkpoint a session's model stands on (see :class:`_CheckpointScan`); reads
    only. ``n_labels``: the session's labels; ``base``: prior demonstrations, which come
    first in ``all_xs, all_ys`` and in every checkpoint's digest; ``entries``: the listing of
    ``directory`` to scan (:func:`_checkpoint_entries`; default: listed now). Listed before
    the labels were read from the log, every checkpoint in it names labels the log held then
    (a writer logs a label before it saves a checkpoint of it), so one in ``beyond`` names
    labels the log lacks; listed after, it may be one a writer saved since the read.

    Raises:
        IncompatibleRunDirError: ``directory`` cannot be listed.
    """
    if entries is None:
        entries = _checkpoint_entries(directory)
    beyond = sorted((n, path) for n, path in entries if n > n_labels)
    passed_over: list[tuple[int, Path, str]] = []
    found: tuple[int, dict[str, Any]] | None = None
    for n, path in sorted(((n, p) for n, p in entries if n <= n_labels), reverse=True):
        payload, why = _checkpoint_payload(path, base + n, all_xs, all_ys)
        if payload is not None:
            found = (n, payload)
            break
        if not os.path.lexists(path):  # removed since the listing: a writer kept newer ones
            continue
        passed_over.append((n, path, why))
    last = 0 if found is None else found[0]
    refits = _recorded_refits(passed_over, last, n_labels)
    n, payload = found or (None, None)
    return _CheckpointScan(n, payload, passed_over, beyond, refits)


def _recorded_refits(
    passed_over: list[tuple[int, Path, str]], above: int, n_labels: int
) -> tuple[int, ...]:
    """The counts of labels in (``above``, ``n_labels``] at which a file that cannot be loaded
    records a refit by its name, ascending: a checkpoint passed over as damaged
    (``passed_over``, as :func:`_scan_checkpoints` finds them) that is a regular file (cut
    short, emptied, unreadable: torchcbl wrote it at a refit; a directory or a dangling link
    it never wrote), still in place. A refit by hand (``ConfidentTeacher.refit``) moves the
    refit schedule and only its checkpoint records it, so its name counts even where its
    content is lost. A stale one (fitted on other labels than the log's) records none of this
    session's refits; nor does a file set aside (``.damaged``, ``.stale``): a resume keeps a
    damaged one in place until the model of its count replaces it, its bytes kept as
    ``.damaged`` (:func:`restore_model`), and an older torchcbl's resume that set one aside
    taught on on the regular schedule.
    """
    named = {n for n, path, why in passed_over if _records_refit(path, why)}
    return tuple(sorted(n for n in named if above < n <= n_labels))


def _rebuilt_in_place(
    refits: tuple[int, ...], last: int, max_new: int, incremental: bool
) -> tuple[int, ...]:
    """The counts among ``refits`` (recorded by the names of damaged files above ``last``,
    the newest readable checkpoint's count, 0 for none: :func:`_recorded_refits`) whose
    files a resume keeps in place and writes the rebuilt model over (:func:`restore_model`).
    With full refits, only those off the regular schedule from the refit recorded below
    them (``(j - prev) % max_new != 0``: where a refit by hand moved it): one on it records
    nothing the schedule does not say, so it is set aside, as a resume did before such names
    counted, and costs no fit. With ``incremental`` every one: the replay passes through
    each refit anyway, and its model costs a write only."""
    if incremental:
        return refits
    moved, prev = [], last
    for j in refits:
        if (j - prev) % max_new:
            moved.append(j)
        prev = j
    return tuple(moved)


def _set_aside(path: Path, why: str) -> Path:
    """Rename a checkpoint that cannot be used, keeping its bytes (``<name>.<why>[-i]``);
    returns its new path.

    Raises:
        OSError: it could not be renamed, and stays.
    """
    for i in range(1000):
        target = path.with_name(f"{path.name}.{why}" + (f"-{i}" if i else ""))
        if not os.path.lexists(target):
            os.replace(path, target)
            return target
    raise OSError(errno.EEXIST, f"{path.name}.{why} and its 999 numbered names are taken")


def _copy_name(path: Path) -> tuple[Path | None, bool]:
    """Where :func:`_keep_a_copy` keeps the bytes of ``path``: the first ``<name>.damaged[-i]``
    that already holds them (the same file or the same bytes; where ``path`` is a symbolic
    link, only the same link: kept by a resume interrupted before it wrote the rebuilt model over
    ``path``), ``True``; else the first free one, ``False``; ``(None, False)`` where all 1000
    are taken. Reads only."""
    free = None
    link = _link_of(path)
    try:  # the folder listed once: 1000 names each looked up cost 1000 system calls
        there = {e.name for e in os.scandir(path.parent)}
    except OSError:
        there = None  # each name looked up, as below
    for i in range(1000):
        target = path.with_name(f"{path.name}.damaged" + (f"-{i}" if i else ""))
        if there is not None and target.name not in there:
            free = target if free is None else free
            continue
        if not os.path.lexists(target):
            free = target if free is None else free
        elif target.is_symlink():
            if link is not None and _link_of(target) == link:
                return target, True
        elif link is None and _holds_same(target, path):
            # (not for a link: the file it points to, maybe this very target, is no copy
            # of the link, and a failed write would remove it as one)
            return target, True
    return free, False


def _link_of(path: Path) -> str | None:
    """What the symbolic link ``path`` points to; None where it is none (or unreadable)."""
    try:
        return os.readlink(path)
    except OSError:
        return None


def _keep_a_copy(path: Path) -> Path:
    """Keep the bytes of ``path``, a checkpoint that cannot be loaded, under
    ``<name>.damaged[-i]`` while ``path`` stays in place until a rebuilt model replaces it:
    a hard link where the file system allows (to the link itself where ``path`` is a
    symbolic link), else a durable copy; one that already holds them is used again
    (:func:`_copy_name`), so retried resumes leave one copy. Returns the copy's path.

    Raises:
        OSError: neither could be made (nothing is left behind).
    """
    target, held = _copy_name(path)
    if target is None:
        raise OSError(errno.EEXIST, f"{path.name}.damaged and its 999 numbered names are taken")
    if held:
        fsync_directory(path.parent)  # a link made by the interrupted resume: on the disk
        return target
    try:
        try:
            os.link(path, target, follow_symlinks=False)
        except (OSError, NotImplementedError):  # no hard links here (FAT, some shares)
            if path.is_symlink():
                os.symlink(os.readlink(path), target)
            else:
                write_durably(target, path.read_bytes(), target.with_name(f".{target.name}.tmp"))
                return target
        fsync_directory(path.parent)  # the copy on the disk before the name is written over
    except OSError:
        with contextlib.suppress(OSError):
            if os.path.lexists(target) and os.path.lexists(path):
                target.unlink()
        raise
    return target


def _holds_same(path: Path, other: Path) -> bool:
    """Whether ``path`` still holds what ``other`` does: the same file, or the same bytes."""
    try:
        if os.path.samefile(path, other):
            return True
        return path.read_bytes() == other.read_bytes()
    except OSError:
        return False


def restore_model(
    run_dir: str | os.PathLike[str],
    model: torch.nn.Module,
    xs: list[np.ndarray],
    ys: list[int],
    *,
    max_new: int,
    relabel: bool,
    store: SessionStore | None = None,
    incremental: bool = False,
    starts_fitted: bool = False,
    prior: tuple[np.ndarray, np.ndarray] | None = None,
) -> int:
    """Bring ``model`` to where the session's live model stood after the labels ``xs, ys``:
    THE one "load the checkpoint or refit" path (resume and :func:`load_model` both use it).

    The last refit the directory knows of is its newest checkpoint with at most ``len(ys)``
    labels that is readable and was fitted on the log's labels, or a later one recorded by
    the name of a checkpoint that cannot be loaded (damaged in place: cut short, emptied,
    unreadable; not a stale one, nor a file set aside): a refit may also be asked for by
    hand, :meth:`ConfidentTeacher.refit`, at any count, and only its checkpoint says so.
    From there the loop refits every ``max_new`` labels, so the model stood on the first ``k``
    labels. That checkpoint is loaded when ``k`` is its count; otherwise (the process died
    between logging and saving, or the checkpoint is damaged or stale) the model is refitted
    deterministically on the training set of those labels, and with ``store`` (of full refits;
    see ``incremental`` below) the checkpoint is written (a stale one is first renamed
    ``<name>.stale``, a damaged one kept as ``<name>.damaged``, never deleted; see below). With
    ``store``, a file named for more labels than ``ys`` holds (a checkpoint of labels the log
    lost: a writer logs a label before it saves its checkpoint) is renamed ``<name>.stale``
    too, so that no reader takes it for a refit once the session is taught that far again (a
    file that cannot be renamed stays as it is, never written over, with a warning naming it);
    a damaged checkpoint whose name records a refit (with full refits, one off the regular
    schedule from the refit recorded below it, :func:`_rebuilt_in_place`; the others are
    renamed ``.damaged``), or the checkpoint of ``k`` that this model cannot load, stays in
    place, recording it, until the model rebuilt at its count (a fit on those labels;
    ``incremental``: the replayed state there) replaces it: its bytes are first
    kept as ``<name>.damaged`` (a hard link, else a copy), then the rebuilt model is renamed
    over the name. Where the bytes cannot be kept, or that write fails, the file stays as it is
    (with a warning), so an interruption at any point (a Ctrl-C, a kill) leaves the refit
    recorded.
    With ``incremental`` (``TeachingConfig.refit="incremental"``) the loop's incremental
    refits (``GaussianMixtureSet.refit``, a pure function of the state and the data) are
    replayed from that checkpoint's state instead, through every refit the names record, so
    the model is the live one bit for bit; with ``store`` only the models of refits recorded
    by damaged files (and of ``k`` where this model cannot load its checkpoint) are written
    then, in their place: a missing checkpoint stays missing, the replay rebuilding it.
    ``starts_fitted``: the session started from a fitted model (config.json's
    ``"starts_fitted"``), which only checkpoint 0 holds and no label can refit: where the model
    still stands on it (``k`` is 0, or the refits are incremental) and it cannot be loaded,
    :class:`CorruptSessionError`, the file left as it is. ``prior``: the session's prior
    demonstrations (:func:`load_prior_demonstrations`), the first labels of every fit (and of
    every checkpoint's digest): the loop fitted the model on them alone before its first step,
    so with them the model is fitted also at ``k`` = 0. Returns ``k``.
    """

    px, py = ([], []) if prior is None else (list(prior[0]), prior[1].tolist())
    base = len(py)  # the prior's labels come first in every fit and digest
    all_xs, all_ys = px + list(xs), py + list(ys)
    directory = Path(run_dir) / CHECKPOINT_DIR
    # (the store's error where checkpoints/ cannot be listed; describe reads it alike); a
    # starting model that cannot be had is refused here, before anything is set aside
    scan, k = _restore_plan(
        run_dir, model, len(ys), base, all_xs, all_ys, max_new, incremental, starts_fitted
    )
    # the counts whose files could not be set aside: left as they are, never written over
    pinned: set[int] = set()

    def set_aside(n: int, path: Path, why: str) -> None:
        """Rename the file of ``n`` labels at ``path`` ``<name>.<why>``; where that fails,
        warn (the file stays, and ``pinned`` keeps save from writing over it)."""
        try:
            _set_aside(path, why)
        except FileNotFoundError:  # gone since the listing: nothing to set aside
            return
        except OSError as exc:
            pinned.add(n)
            failed = f"could not be renamed {path.name}.{why} ({exc.strerror or exc})"
            if n > len(ys):
                said = (
                    f"{path} names {n} labels, more than the {len(ys)} the session's log "
                    f"holds (a checkpoint of labels the log lost), and {failed}: move it out "
                    f"of {path.parent} yourself, or once the session is taught to {n} labels "
                    "again readers take it for a refit there."
                )
            else:
                what = "cannot be loaded"
                if why == "stale":
                    what = "is stale (not fitted on the log's labels)"
                said = (
                    f"{path} {what} and {failed}: it stays as it is (resume and load_model "
                    f"pass it over, and nothing is written over it); move it out of "
                    f"{path.parent} yourself."
                )
            warnings.warn(said, stacklevel=3)

    if store is not None:
        # a writer logs a label before it saves its checkpoint: one named for more labels
        # than the log holds is of labels the log lost, and no refit of what is taught next
        for n, path in scan.beyond:
            set_aside(n, path, "stale")
    # the counts whose files cannot be loaded but stay in place until the model rebuilt at
    # their count replaces them (their bytes kept as .damaged first, by save): the damaged
    # ones whose names record a refit, which they go on recording meanwhile (for a reader
    # racing this resume, and if it is interrupted: a Ctrl-C, a kill, an exception)
    # (with full refits only those off the schedule: _rebuilt_in_place)
    last, payload = (0, None) if scan.n is None else (scan.n, scan.payload)
    rebuilt = _rebuilt_in_place(scan.refits, last, max_new, incremental)
    in_place: set[int] = set()
    for n, path, why in scan.passed_over:
        if store is not None and not (n == 0 and starts_fitted):  # that one: kept as it is
            if n in rebuilt:
                in_place.add(n)
            else:
                set_aside(n, path, why)

    def save(j: int) -> None:
        """With ``store``, write the checkpoint of the model refitted on ``j`` labels; over a
        file kept in place (``in_place``), only once its bytes are kept as ``.damaged``, so
        that it records the refit until the rebuilt model does."""
        assert store is not None
        if j in pinned:  # a file that could not be set aside: left as it is (said)
            return
        own = directory / f"model-{j:08d}.pt"
        kept = None
        if j in in_place:
            try:
                kept = _keep_a_copy(own)
            except OSError as exc:
                warnings.warn(
                    f"{own} cannot be loaded and its bytes could not be kept as "
                    f"{own.name}.damaged ({exc.strerror or exc}), so the model rebuilt on {j} "
                    "labels was not written over it: it stays as it is, its name still "
                    "recording the refit there, which resume and load_model rebuild from the "
                    "log. Free space (or fix the folder's permissions), then resume again to "
                    "have the model written in its place.",
                    stacklevel=3,
                )
                return
        digest = labels_digest(all_xs[: base + j], all_ys[: base + j])
        try:
            # over a damaged file kept in place, the message says what stays (below)
            store.save_checkpoint(model, j, digest, after="" if kept is not None else None)
        except SessionWriteError as exc:
            if kept is None:  # the checkpoint missing (or set aside): refitted from the log
                warnings.warn(str(exc), stacklevel=3)
            elif _holds_same(own, kept):  # the write left the name as it was
                with contextlib.suppress(OSError):
                    kept.unlink()  # the same bytes, still under the name
                warnings.warn(
                    f"{exc}The damaged {own.name} stays under its name, which still records "
                    f"the refit on {j} labels: resume and load_model rebuild that model from "
                    "the log, as this resume did (the session and its model in memory are "
                    "intact). Free space (or fix the folder's permissions), then resume again "
                    "to have the model written in its place.",
                    stacklevel=3,
                )
            else:  # renamed over the name, the folder not flushed: a power cut may undo it
                warnings.warn(
                    f"{exc}The model was put in its place but may not be on the disk: after "
                    f"a power cut the name may hold the damaged file again (which records the "
                    f"refit on {j} labels too; its bytes are kept as {kept.name}). Nothing is "
                    "lost either way.",
                    stacklevel=3,
                )

    def lost_start(why: str) -> CorruptSessionError:  # (_restore_plan raised where it comes)
        return _lost_start(run_dir, k, why)

    if k == last and payload is not None:
        try:
            model.load_state_dict(payload["state_dict"])
            return k
        except Exception:  # e.g. saved by another model class: refit below
            if starts_fitted and k == 0:
                raise lost_start("unreadable as this model's state") from None
            if store is not None and k > 0:  # its rebuilt model in its place, its bytes kept
                in_place.add(k)
            elif store is not None:
                set_aside(k, directory / f"model-{k:08d}.pt", "damaged")
        payload = None
    if (k > 0 or base) and incremental:
        start, loaded = 0, False
        if payload is not None:
            try:
                model.load_state_dict(payload["state_dict"])
                start, loaded = last, True
            except Exception:  # e.g. saved by another model class: replay from the start
                if starts_fitted and last == 0:
                    raise lost_start("unreadable as this model's state") from None
                start = 0
        if starts_fitted and not loaded:
            # a later checkpoint this model could not load: the incremental refits are
            # replayed from the starting model (checkpoint 0), not from a fit from scratch
            zero, why = _checkpoint_payload(directory / f"model-{0:08d}.pt", base, all_xs, all_ys)
            if zero is None:
                raise lost_start(why)
            try:
                model.load_state_dict(zero["state_dict"])
            except Exception:
                raise lost_start("unreadable as this model's state") from None
            start, loaded = 0, True
        if base and not loaded:  # the loop fitted on the prior alone before its first step
            model.fit(*training_set(px, py, relabel=relabel))
            start, loaded = 0, True
        recorded = scan.refits
        if start < last:  # replayed from below the checkpoint: its refits, and those below
            recorded += _refits_below(directory, last, base, all_xs, all_ys)
        for i, j in enumerate(_refit_schedule(start, k, recorded, max_new)):
            x, y = training_set(all_xs[: base + j], all_ys[: base + j], relabel=relabel)
            # with no checkpoint loaded, the first refit is a fit from scratch (whatever a
            # failed load left in the buffers); from a loaded one, even the pre-fit state of
            # a session that started from a fitted model (checkpoint 0), the loop refitted
            (model.refit if i > 0 or loaded else model.fit)(x, y)
            if j in in_place:  # a refit recorded by a damaged file: its model in its place
                save(j)
    elif k > 0 or base:
        # a refit recorded by a damaged file below k: its model in its place first
        for j in [*(j for j in sorted(in_place) if j < k), k]:
            x, y = training_set(all_xs[: base + j], all_ys[: base + j], relabel=relabel)
            model.fit(x, y)
            if store is not None:
                save(j)
    return k


def _refits_below(
    directory: Path, last: int, base: int, all_xs: list[np.ndarray], all_ys: list[int]
) -> tuple[int, ...]:
    """The refits in (0, ``last``] that the files of ``directory`` record by their names, for
    a replay from the start through the checkpoint of ``last`` labels (which it could not
    load): ``last`` itself and each checkpoint below it but a stale one (each read to tell;
    a damaged one in place too, see :func:`_recorded_refits`)."""
    named = {last}
    for n, path in _checkpoint_entries(directory):
        if 0 < n < last and n not in named:
            payload, why = _checkpoint_payload(path, base + n, all_xs, all_ys)
            if payload is not None or _records_refit(path, why):
                named.add(n)
    return tuple(sorted(named))


def _lost_start(run_dir: str | os.PathLike[str], k: int, why: str) -> CorruptSessionError:
    """The error of a session started from a fitted model whose checkpoint 0 cannot be had
    (``why``) where the model still stands on it (``k``: the labels it was last fitted on)."""
    on_it = (
        "no refit came since, so the session's model is that one"
        if k == 0
        else "its incremental refits start from it"
    )
    return CorruptSessionError(
        f"cannot rebuild the model of the session in {run_dir}: the session started from a "
        f"fitted model, which only {CHECKPOINT_DIR}/model-{0:08d}.pt holds, and that file is "
        f"{why} ({on_it}); no label can refit it. The file was left as it is: restore it "
        "from a backup, or start a new session"
    )


def _restore_plan(
    run_dir: str | os.PathLike[str],
    model: torch.nn.Module,
    n_labels: int,
    base: int,
    all_xs: list[np.ndarray],
    all_ys: list[int],
    max_new: int,
    incremental: bool,
    starts_fitted: bool,
) -> tuple[_CheckpointScan, int]:
    """Where :func:`restore_model` starts: the scan of ``checkpoints/`` and ``k``, the labels
    the model was last fitted on. Reads only. Raises the :class:`CorruptSessionError` of a
    session started from a fitted model (``starts_fitted``) that still stands on it and whose
    checkpoint 0 is missing, damaged or not this model's state (tried on a copy or a shadow
    of ``model``, :func:`_trial_copy`), as restore_model would after setting aside what it
    passes over; so a resume refuses it before it opens the session
    (:func:`_check_restorable`).

    Raises:
        IncompatibleRunDirError: ``checkpoints/`` cannot be listed.
    """
    directory = Path(run_dir) / CHECKPOINT_DIR
    scan = _scan_checkpoints(directory, n_labels, base, all_xs, all_ys)
    last, payload = (0, None) if scan.n is None else (scan.n, scan.payload)
    k = scan.stood_on(n_labels, max_new)
    if not starts_fitted:
        return scan, k
    why0 = next((why for n, _, why in scan.passed_over if n == 0), "missing")
    trial = _trial_copy(model)

    def loads(state: dict[str, Any]) -> bool:
        if trial is None:  # left to restore_model's own load, which refuses it alike
            return True
        try:
            trial.load_state_dict(state)
            return True
        except Exception:  # e.g. saved by another model class
            return False

    # restore_model's paths to the starting model, in its order
    if payload is None and (k == 0 or incremental):
        raise _lost_start(run_dir, k, why0)
    if k == last and payload is not None:
        if loads(payload["state_dict"]):
            return scan, k
        if k == 0:
            raise _lost_start(run_dir, k, "unreadable as this model's state")
        payload = None  # refitted (and with a store written in its place, or set aside at 0)
    if (k > 0 or base) and incremental:
        if payload is not None and loads(payload["state_dict"]):
            return scan, k
        if payload is not None and last == 0:
            raise _lost_start(run_dir, k, "unreadable as this model's state")
        zero, why = _checkpoint_payload(directory / f"model-{0:08d}.pt", base, all_xs, all_ys)
        if zero is None:
            raise _lost_start(run_dir, k, why)
        if not loads(zero["state_dict"]):
            raise _lost_start(run_dir, k, "unreadable as this model's state")
    return scan, k


def _trial_copy(model: torch.nn.Module) -> torch.nn.Module | None:
    """A model to try a checkpoint on, never ``model`` itself: a deep copy of a model on the
    CPU that can be copied; else (a model with tensors off the CPU, whose copy would double
    its accelerator memory, or one holding what cannot be copied: a lock, a logger) its
    shadow (:func:`_shadow`), its tensors copied to the CPU, where its load is the library's
    own (:func:`_shadow_loads_alike`); ``None`` otherwise, and then whether the checkpoint
    loads is found by :func:`restore_model`'s own load, which raises the same error, only
    after the session was opened."""
    tensors = [*model.parameters(), *model.buffers()]
    if all(t.device.type == "cpu" for t in tensors):
        try:
            return copy.deepcopy(model)
        except Exception:  # e.g. TypeError: cannot pickle '_thread.lock' object
            pass
    if not _shadow_loads_alike(model):
        return None
    try:
        return _shadow(model)
    except Exception:  # a class whose __new__ needs its arguments, a tensor that cannot be
        return None  # copied to the CPU (one on the meta device)


def _shadow_loads_alike(model: torch.nn.Module) -> bool:
    """Whether a load into :func:`_shadow` of ``model`` fails exactly where one into
    ``model`` would, and touches nothing of ``model``: a GaussianMixtureSet (of a subclass
    or not) with no submodule, no slot, no load hook and the library's own load path. A
    model's own load may read what a shadow lacks (a slot: a healthy session would be
    refused as corrupt), and a load hook or an override may act on ``model`` itself."""
    from torchcbl.gmm import GaussianMixtureSet

    cls = type(model)
    return (
        isinstance(model, GaussianMixtureSet)
        and cls.load_state_dict is torch.nn.Module.load_state_dict
        and cls._load_from_state_dict is GaussianMixtureSet._load_from_state_dict
        and not any("__slots__" in vars(c) for c in cls.__mro__)
        and not model._load_state_dict_pre_hooks
        and not model._load_state_dict_post_hooks
        and not model._modules
    )


def _shadow(module: torch.nn.Module) -> torch.nn.Module:
    """An instance of ``module``'s class, made without its constructor, holding its
    attributes, with its parameters and buffers copied to the CPU: what ``load_state_dict``
    changes (the tensors, the attributes it sets) is the shadow's, never ``module``'s; what a
    copy cannot take (a lock, a logger) is the same object in both, not copied. No
    accelerator memory is taken. Only a module without submodules is shadowed (see
    :func:`_shadow_loads_alike`): the shadow has none."""
    cls = type(module)
    shadow = cls.__new__(cls)
    own = dict(module.__dict__)
    own["_parameters"] = type(module._parameters)(
        (
            name,
            None
            if p is None
            else torch.nn.Parameter(p.detach().to("cpu", copy=True), p.requires_grad),
        )
        for name, p in module._parameters.items()
    )
    own["_buffers"] = type(module._buffers)(
        (name, None if b is None else b.detach().to("cpu", copy=True))
        for name, b in module._buffers.items()
    )
    own["_modules"] = type(module._modules)()  # its own, not the model's (empty) one
    shadow.__dict__.update(own)
    return shadow


def _check_restorable(
    run_dir: str | os.PathLike[str],
    model: torch.nn.Module,
    xs: list[np.ndarray],
    ys: list[int],
    *,
    max_new: int,
    incremental: bool,
    starts_fitted: bool,
    prior: tuple[np.ndarray, np.ndarray] | None = None,
) -> None:
    """Refuse, as :func:`restore_model` would, a session whose model cannot be rebuilt from
    the labels ``xs, ys`` (its starting model lost, see :func:`_restore_plan`), without
    writing or setting aside anything: a resume calls it before it opens the session.

    Raises:
        CorruptSessionError: the session started from a fitted model that its checkpoint 0
            alone holds, still stands on it, and that file is missing or damaged.
        IncompatibleRunDirError: ``checkpoints/`` cannot be listed.
    """
    px, py = ([], []) if prior is None else (list(prior[0]), prior[1].tolist())
    _restore_plan(
        run_dir,
        model,
        len(ys),
        len(py),
        px + list(xs),
        py + list(ys),
        max_new,
        incremental,
        starts_fitted,
    )


@overload
def load_model(
    run_dir: str | os.PathLike[str], *, n_demonstrations: int | None = None, model: None = None
) -> GaussianMixtureSet: ...
@overload
def load_model(
    run_dir: str | os.PathLike[str], *, n_demonstrations: int | None = None, model: _Model
) -> _Model: ...
def load_model(
    run_dir: str | os.PathLike[str],
    *,
    n_demonstrations: int | None = None,
    model: torch.nn.Module | None = None,
) -> torch.nn.Module:
    """The session's model as the loop had it, from its checkpoint or refitted from the log.

    For the model at many stages (a learning curve after the fact), :func:`load_models`
    gives them in one pass: with ``refit="incremental"`` each call here replays the refits
    since the newest kept checkpoint below its stage, that pass replays them once for all.

    Args:
        run_dir: a session directory.
        n_demonstrations: rebuild the model as it stood when this many labels (demonstrations
            and corrections) were logged (default: all of them).
        model: the model to load the session's into (default: a GaussianMixtureSet built
            from the session's config.json). Needed for a session whose model is of a class
            of the user's own (a subclass of GaussianMixtureSet), which the run directory
            cannot rebuild: a fresh, unfitted instance of that class (its name as the session
            kept it) made with the session's arguments (config.json's ``model.args``: the
            subclass's ``init_args`` dict where it set one, else GaussianMixtureSet's
            arguments only, its own then not recorded or compared); the
            checkpoint's state is loaded into it, or it is refitted. Also a way to load onto
            a device (``GaussianMixtureSet(...).to("cuda")``).

    Returns:
        A GaussianMixtureSet (``model`` itself, when given) fitted on the labels the live
        model stood on after ``n`` labels, a session's prior demonstrations first (unfitted
        when there were none and the session started from neither a fitted model nor prior
        demonstrations), see :func:`restore_model`. If the matching checkpoint is missing,
        damaged or stale, the model is refitted deterministically on the logged labels
        (nothing is written); a damaged one's name still says a refit came at its count (a
        refit by hand moves the schedule), so the model is rebuilt on the labels it stood on.

    Raises:
        IncompatibleRunDirError: the session's model is of a class of the user's own and no
            ``model`` was given, or the given one is of another class or was made with other
            arguments (the message says what to pass).
        ValueError: ``model`` is already fitted; or ``n_demonstrations`` is out of range.
    """
    return _model(run_dir, n_demonstrations, model)


def _model(
    run_dir: str | os.PathLike[str],
    n_demonstrations: int | None,
    given: torch.nn.Module | None = None,
) -> Any:
    """:func:`load_model` for a public reader, its warnings pointing at that reader's caller."""
    config = load_config(run_dir)
    if given is not None:
        _given_model(run_dir, config, given)
    x, y = _labels(run_dir, depth=1)
    if n_demonstrations is None:
        n = len(y)
    elif (
        isinstance(n_demonstrations, bool)
        or not isinstance(n_demonstrations, int | np.integer)
        or not 0 <= n_demonstrations <= len(y)
    ):
        raise ValueError(
            f"n_demonstrations: expected an int from 0 to {len(y)} (the labels logged in "
            f"{run_dir}), got {n_demonstrations!r}; leave it out for all of them."
        )
    else:
        n = int(n_demonstrations)
    model = build_model(config) if given is None else given
    restore_model(
        run_dir,
        model,
        list(x[:n]),
        y[:n].tolist(),
        max_new=int(config["teaching"]["max_new"]),
        relabel=_relabels(config),
        incremental=config["teaching"].get("refit", "full") == "incremental",
        starts_fitted=config.get("starts_fitted") is True,
        prior=_read_prior(run_dir, config),
    )
    return model


@overload
def load_models(
    run_dir: str | os.PathLike[str], n_demonstrations: Iterable[int], *, model: None = None
) -> Iterator[tuple[int, GaussianMixtureSet]]: ...
@overload
def load_models(
    run_dir: str | os.PathLike[str], n_demonstrations: Iterable[int], *, model: _Model
) -> Iterator[tuple[int, _Model]]: ...
def load_models(
    run_dir: str | os.PathLike[str],
    n_demonstrations: Iterable[int],
    *,
    model: torch.nn.Module | None = None,
) -> Iterator[tuple[int, torch.nn.Module]]:
    """The session's model at several stages in one pass: for a learning curve after the fact.

    Each model is exactly what ``load_model(run_dir, n_demonstrations=n, model=...)`` gives
    (the live model's state after its last refit at or before ``n`` labels, bit for bit), but
    the stages are read together: a stage whose checkpoint is kept is loaded from it, and with
    ``TeachingConfig(refit="incremental")`` the refits between kept checkpoints are replayed
    once across the stages, not from the checkpoint below each stage again (for ``S`` stages of
    an ``N``-label session that kept only its newest checkpoints, ``load_model`` at each
    replays about ``S * N / 2`` refits, this at most ``N``). With ``refit="full"`` a stage
    whose checkpoint is gone is one fit, as with ``load_model`` (stages on the same refit share
    it). Reads only: no checkpoint is written or set aside, and the logged labels are read once,
    at the call.

    Args:
        run_dir: a session directory.
        n_demonstrations: the stages: counts of labels logged (demonstrations and
            corrections), from 0 to all of them, in increasing order, e.g.
            ``range(first, n + 1, 50)`` from the first fitted stage (the example). The models
            come in the order asked, each with its count,
            so stages out of order or repeated are refused, at the call (before any model is
            read), not sorted: pass ``sorted(set(stages))``.
        model: as :func:`load_model`'s, a fresh, unfitted model of the session's class and
            arguments (needed where that class is the user's own, or to read onto a device):
            a template, left as it is; each stage's model is a ``copy.deepcopy`` of it holding
            the session's state, so it must be one that can be copied.

    Returns:
        An iterator of ``(n, model)``, one per stage in the order given, each model an object
        of its own that a caller may keep (each holds the model's whole state: 0.14 MB for
        the default model on 4 features and 3 actions, 2 MB with ``max_components=40``; on
        ``model``'s device). A stage is computed when the iterator reaches it. A stage before
        the session's first refit (at ``max_new`` labels, ``TeachingConfig.max_new``; earlier
        where a refit was asked by hand; none for a session with prior demonstrations or a
        fitted starting model) is an unfitted model, ``model.is_fitted`` False, of which a
        :class:`~torchcbl.GreedyPolicy` has no action to give (a RuntimeError, called or in
        :func:`~torchcbl.evaluate_policy`).

    Raises:
        ValueError: ``n_demonstrations`` is not increasing ints in range, or ``model`` is
            fitted or cannot be copied (at the call).
        IncompatibleRunDirError: as :func:`load_model` raises for ``model`` (at the call).
        CorruptSessionError: as :func:`load_model`: the session's ``prior.npz`` is missing or
            changed (at the call); a stage stands on the starting model of a session started
            from a fitted one, and its checkpoint 0 is lost (when the iterator reaches it).

    Example (a learning curve of a session after the fact, from its first fitted stage;
    ``next`` reads the stages lazily up to it, those before it unfitted models that cost
    nothing to make, and raises StopIteration where the session's first fit has not come)::

        from torchcbl import GreedyPolicy, describe, evaluate_policy, load_models

        n_labels = describe(run_dir).n_labels
        first = next(n for n, m in load_models(run_dir, range(n_labels + 1)) if m.is_fitted)
        for n, model in load_models(run_dir, range(first, n_labels + 1, 50)):
            records = evaluate_policy(GreedyPolicy(model), env, n_episodes=20, seed=0)
    """
    config = load_config(run_dir)
    if model is not None:
        _given_model(run_dir, config, model)
    x, y = _labels(run_dir)
    stages = _stage_counts(run_dir, n_demonstrations, len(y), _stages_example(config, len(y)))
    prior = _read_prior(run_dir, config)
    if model is None:
        template: torch.nn.Module = build_model(config)
    else:
        try:  # (a copy: the given model stays the caller's, as it is)
            template = copy.deepcopy(model)
        except Exception as exc:  # e.g. TypeError: cannot pickle '_thread.lock' object
            cls = type(model).__name__
            raise ValueError(
                f"model: expected a model copy.deepcopy can copy (load_models gives each stage "
                f"a copy of it), got a {cls} that cannot be copied ({type(exc).__name__}: "
                f"{exc}); read the stages one at a time with load_model(run_dir, "
                f"n_demonstrations=n, model={cls}(...)), a fresh model for each"
            ) from exc
    return _stage_models(run_dir, config, template, x, y, prior, stages)


def _stages_example(config: dict[str, Any], n_labels: int) -> str:
    """The stages :func:`load_models`' refusals give as an example: from a fitted one, 0 for a
    session with prior demonstrations or a fitted starting model, else its first scheduled
    refit, ``max_new`` (a refit by hand may have come earlier), where the log reaches it."""
    if config.get("starts_fitted") is True or isinstance(config.get("prior"), dict):
        return f"e.g. range(0, {n_labels + 1}, 10)"
    max_new = int(config["teaching"]["max_new"])
    first = max_new if max_new <= n_labels else 0
    return (
        f"e.g. range({first}, {n_labels + 1}, 10) (the session's first refit is due at "
        f"max_new={max_new} labels: a stage before it is an unfitted model, which has no action)"
    )


def _stage_counts(
    run_dir: str | os.PathLike[str],
    n_demonstrations: Any,
    n_labels: int,
    example: str | None = None,
) -> list[int]:
    """:func:`load_models`'s stages as a list of ints, refused unless increasing and from 0 to
    ``n_labels``; ``example``: the stages the refusal suggests (default from 0)."""
    expected = (
        f"n_demonstrations: expected increasing ints from 0 to {n_labels} (counts of the "
        f"labels logged in {run_dir}, each at most once)"
    )
    example = example or f"e.g. range(0, {n_labels + 1}, 10)"
    if isinstance(n_demonstrations, str | bytes):
        raise ValueError(f"{expected}, got {n_demonstrations!r}; pass a list or a range, {example}")
    try:
        values = list(n_demonstrations)
    except TypeError:
        raise ValueError(
            f"{expected}, got {n_demonstrations!r}, which is no list of them; pass a list or a "
            f"range ([{n_demonstrations!r}] for one stage), {example}"
        ) from None
    counts: list[int] = []
    for value in values:
        if (
            isinstance(value, bool)
            or not isinstance(value, int | np.integer)
            or not 0 <= value <= n_labels
        ):
            raise ValueError(f"{expected}, got {value!r}; {example}")
        if counts and value <= counts[-1]:
            raise ValueError(
                f"{expected}, got {int(value)} after {counts[-1]}; pass them sorted, each once "
                "(sorted(set(stages))): the models come in the order asked"
            )
        counts.append(int(value))
    return counts


def _stage_models(
    run_dir: str | os.PathLike[str],
    config: dict[str, Any],
    template: torch.nn.Module,
    x: np.ndarray,
    y: np.ndarray,
    prior: tuple[np.ndarray, np.ndarray] | None,
    stages: list[int],
) -> Iterator[tuple[int, torch.nn.Module]]:
    """:func:`load_models`' pass: at each stage the model :func:`restore_model` gives (reads
    only), from the checkpoint it would load and the refits it would replay, the replay kept
    from one stage to the next. Where that path does more than the plain cases (a checkpoint
    this model cannot load, a session's starting model not on disk), restore_model itself
    gives the stage."""
    if not stages:
        return
    max_new = int(config["teaching"]["max_new"])
    relabel = _relabels(config)
    incremental = config["teaching"].get("refit", "full") == "incremental"
    starts_fitted = config.get("starts_fitted") is True
    px, py = ([], []) if prior is None else (list(prior[0]), prior[1].tolist())
    base = len(py)  # the prior's labels come first in every fit and digest
    xs, ys = list(x), y.tolist()
    all_xs, all_ys = px + xs, py + ys
    directory = Path(run_dir) / CHECKPOINT_DIR
    entries = sorted((n, path) for n, path in _checkpoint_entries(directory) if n <= stages[-1])
    # the refits recorded by the names of files that cannot be loaded (_recorded_refits):
    # the checkpoints found damaged in place as the stages are read
    recorded: set[int] = set()

    def fresh() -> torch.nn.Module:
        return copy.deepcopy(template)

    def data(n: int) -> tuple[np.ndarray, np.ndarray]:  # the training set of n labels
        return training_set(all_xs[: base + n], all_ys[: base + n], relabel=relabel)

    def loaded(state: dict[str, Any]) -> torch.nn.Module | None:
        m = fresh()
        try:
            m.load_state_dict(state["state_dict"])
        except Exception:  # e.g. saved by another model class: restore_model's case
            return None
        return m

    # the checkpoint restore_model would start from: the newest one read so far that is
    # readable and fitted on the log's labels; the checkpoints up to `scanned` were read
    last: int | None = None
    payload: dict[str, Any] | None = None
    scanned = -1
    made: tuple[Any, torch.nn.Module] | None = None  # the previous stage's model, its key
    # incremental refits: (model, the checkpoint it started from (None: none), its labels,
    # whether it is fitted), carried from stage to stage
    replay: tuple[torch.nn.Module, int | None, int, bool] | None = None
    for n in stages:
        for c, path in reversed([e for e in entries if scanned < e[0] <= n]):
            found, why = _checkpoint_payload(path, base + c, all_xs, all_ys)
            if found is not None:
                last, payload = c, found
                break
            if c > 0 and _records_refit(path, why):
                recorded.add(c)
        scanned = n
        start = 0 if last is None else last
        k = _stood_on(start, recorded, n, max_new)  # the labels the model stood on
        key: Any = None
        model: torch.nn.Module | None = None
        if payload is None and starts_fitted:
            pass  # checkpoint 0 is not on disk: restore_model refuses or refits the stage
        elif k == start and payload is not None:
            key = ("checkpoint", start)
            model = made[1] if made is not None and made[0] == key else loaded(payload)
            if model is not None and incremental and (replay is None or replay[1] != start):
                replay = (copy.deepcopy(model), start, start, True)
        elif (k > 0 or base) and incremental:
            anchor = None if payload is None else start
            if replay is None or replay[1] != anchor or replay[2] > k:
                if payload is not None:
                    work = loaded(payload)
                    replay = None if work is None else (work, anchor, start, True)
                elif base:  # the loop fitted on the prior alone before its first step
                    replay = (fresh().fit(*data(0)), None, 0, True)
                else:
                    replay = (fresh(), None, 0, False)
            if replay is not None:
                work, _, at, ready = replay
                for j in _refit_schedule(at, k, recorded, max_new):
                    (work.refit if ready else work.fit)(*data(j))
                    ready = True
                replay = (work, anchor, k, ready)
                key, model = ("replay", anchor, k), work
        elif k > 0 or base:
            key = ("fit", k)
            model = made[1] if made is not None and made[0] == key else fresh().fit(*data(k))
        else:
            key = ("unfitted",)
            model = made[1] if made is not None and made[0] == key else fresh()
        if model is None:  # restore_model's own path, at this stage alone, writing nothing
            key, model, replay = None, fresh(), None
            restore_model(
                run_dir,
                model,
                xs[:n],
                ys[:n],
                max_new=max_new,
                relabel=relabel,
                incremental=incremental,
                starts_fitted=starts_fitted,
                prior=prior,
            )
        made = (key, model)
        yield n, copy.deepcopy(model)  # the caller's own: the replay goes on with `model`


def load_policy(
    run_dir: str | os.PathLike[str], *, model: torch.nn.Module | None = None
) -> GreedyPolicy:
    """The latest learned policy of a session directory, as a callable obs -> action.

    Args:
        run_dir: a session directory.
        model: as :func:`load_model`'s: a fresh model of the session's class and arguments
            to load the session's into, needed where that class is the user's own.

    Raises:
        IncompatibleRunDirError: the session holds no model yet (fewer labels were logged than
            its first fit needs, ``max_new``, and it did not start from a fitted model): there
            is nothing to act with. Or as :func:`load_model` raises for ``model``.
        ValueError: ``model`` is already fitted.
    """
    from torchcbl.policy import GreedyPolicy

    model = _model(run_dir, None, model)
    if not model.is_fitted:
        n = len(_labels(run_dir)[1])
        first = int(load_config(run_dir)["teaching"]["max_new"])
        raise IncompatibleRunDirError(
            f"{run_dir} holds {n} demonstration{'' if n == 1 else 's'} and its first fit comes "
            f"at {first} (max_new), so there is no model to act with yet; teach on (resume "
            "the session), or use load_model for the unfitted model"
        )
    return GreedyPolicy(model)


#: Steps per block of :attr:`SessionSummary.requests_per_block`.
SUMMARY_BLOCK_STEPS = 100


@dataclass(frozen=True)
class SessionSummary:
    """What a teaching session directory holds, as :func:`describe` read it.

    Counts are numbers of steps, episodes or labels of this session (resumes included); a
    label is a demonstration (a step on which the teacher was asked, ``teacher_action`` set)
    or a correction (a label for an earlier, autonomous step). Episode and block tuples are
    indexed by episode number (from 0) and by block of :attr:`block_steps` steps.

    Attributes:
        run_dir: the session directory, as given.
        format: the log format, ``"torchcbl.session/1"`` .. ``"/3"``.
        env_id: the gymnasium id the env was made with (None: made directly).
        env_kwargs: what ``gymnasium.make`` was given ({} when none), each argument as whole
            as the session keeps it: a plain value as it is; an object kept whole (a frozen
            dataclass, since 2026-11-27) as its kept fields, ``{"class": "module:QualName",
            "fields": {...}}`` (config.json's ``env.kwargs_objects``, which
            :func:`env_make_argument` makes again); one kept only as text as ``{"repr":
            text}``, the text ending with "..." where it may have been cut (a session keeps 200
            characters of it).
        env_class: the unwrapped env's class, ``module.qualname``, as config.json's
            ``env.class`` keeps it (resume compares it by its name, whether the env was made
            by ``gymnasium.make`` or directly); None: not recorded (a session written before
            2026-11-27, which resume does not compare on it).
        env_max_episode_steps: the step cap in force on the session's env (its smallest
            ``TimeLimit``'s or the env's own), as config.json's ``env.max_episode_steps``
            keeps it, which resume compares (a cap ``gymnasium.make`` was given is here, not
            in ``env_kwargs``); None: no cap, or not recorded (see the next field).
        env_max_episode_steps_recorded: whether config.json keeps the cap (sessions of an env
            with a gymnasium id keep it since 2026-11-26, of every env since 2026-11-27; a
            session that does not is not compared on it).
        n_features, n_actions: the observation's size D and the number of actions A.
        seed: the session seed.
        strategy: the strategy's config as stored (``"type"``, its arguments, ``"relabel"``,
            ``"rule"``; a strategy of one's own: ``"custom": true`` and, where it keeps its
            parent's ``to_config``, the parent's dict under ``"inherited"``).
        model_class, model_args: the model's class name and constructor arguments.
        starts_fitted: the session started from a fitted model.
        n_prior: prior demonstrations the session started from (0: none); not labels of it.
        n_steps, n_episodes: steps logged and episodes they belong to (every episode
            with a logged step, the last one included while it is under way).
        n_episodes_ended: episodes that ended (terminated or truncated), what
            ``ConfidentTeacher.n_episodes`` and ``max_episodes`` count: ``n_episodes``
            less the last one while it is under way.
        n_labels: demonstrations + corrections.
        n_demonstrations, n_corrections: the two kinds of label.
        n_requests: steps on which the teacher was asked (each gave a demonstration).
        n_requests_confident: of those, the ones the strategy chose to ask on (phase
            ``"confident"``); the rest were asked by design (``"noninteractive"``).
        n_autonomous: steps on which the teacher was not asked and the model's action ran.
        n_interrupted: steps cut short (``info["torchcbl_interrupted"]``: a Ctrl-C in the
            env's step, or a writer killed between a demonstration and its outcome).
        steps_per_episode, requests_per_episode: steps and requests of episode 0, 1, ...
        block_steps: the block size of ``requests_per_block``, in steps.
        requests_per_block: requests in steps 0 .. block_steps - 1, then the next block, ...
        last_checkpoint: labels the newest usable checkpoint's model was fitted on (besides
            the ``n_prior`` prior demonstrations, which every fit includes), the one
            resume and :func:`load_model` start from: of no more labels than the log holds,
            readable, and fitted on the log's labels (its SHA-256 matches them); None: none
            is. The name alone does not make one: a file named ``model-<n>.pt`` that is
            damaged, empty, a directory or stale, or of more labels than the log holds, is
            passed over and noted in ``notes`` (a damaged or empty file's name still records
            a refit at its count, which resume and :func:`load_model` rebuild from the log,
            resume writing the rebuilt model in its place: one asked by hand moved the refit
            schedule). Nor is one holding a state the session's model cannot load (another
            class's, or a GaussianMixtureSet's of other sizes or settings; tried where the
            session's model is torchcbl's GaussianMixtureSet, which the directory rebuilds,
            not a class of the user's own): None, and noted, as resume and
            :func:`load_model` then rebuild the model from the log.
        checkpoints_on_disk: the label counts of the files in ``checkpoints/`` named as
            checkpoints (``model-<n>.pt``), ascending, whatever they are (``notes`` says which
            resume passes over): the stages whose model is loaded, not refitted. The others
            (those a writer's ``keep_checkpoints`` removed) are rebuilt from the log by
            ``load_model(run_dir, n_demonstrations=k)``, bit for bit: one fit with
            ``refit="full"``, with ``"incremental"`` a replay of the refits since the kept
            checkpoint before ``k``.
        keep_checkpoints: how many of the newest checkpoints (besides checkpoint 0) the last
            writer kept (:func:`kept_checkpoints`, what a resume keeps by default); None:
            every one.
        refit: the session's ``TeachingConfig.refit``, ``"full"`` or ``"incremental"``.
        stops: the session's stop settings as config.json keeps them (its ``TeachingConfig``'s:
            ``autonomous_steps_to_stop``, ``autonomous_episodes_to_stop``,
            ``max_demonstrations``, ``max_steps``, ``max_episodes``,
            ``time_limit_is_success``; one an older session does not keep: its default, None,
            or False). Stops given to ``run()``, or to a resume's config, are not kept there.
        streak_met: the streak stop of ``stops`` the session had met, as
            ``ConfidentTeacher.stop_reason`` names it (``"autonomous_steps"``,
            ``"autonomous_episodes"``): its log ends on that many autonomous steps, or
            successful episodes with no request, in a row, counted over the steps of its last
            ``run()`` call (where ``runs.jsonl`` says it began) as a resume counts them (the
            same count: a resume then says it in ``stop_reason`` and takes no step, and
            ``torchcbl teach --resume`` refuses the session as done). Judged by the stop
            ``config.json`` keeps, whatever stop that run() was given: a last run() that
            stopped on a streak of 20 has met a kept stop of 3. None: none met (stopped short
            of it, by a budget, a Ctrl-C or a kill, or no streak stop kept); a session without
            ``runs.jsonl`` (older ones) is counted over its last writer's steps, one without
            ``writers.jsonl`` either over its whole log, as resume counts them.
        writers: one dict per writer (start or resume) from ``writers.jsonl``: first_step,
            torch_num_threads, torch_num_interop_threads, torch_version, numpy_version,
            model_device, keep_checkpoints, env_versions (what the env ran on, as its
            ``describe_versions()`` said, e.g. ``{"sumo": "1.28.0"}``; None: the env has no
            such hook), pid, started_utc (what that writer's torchcbl recorded: a writer of
            an older torchcbl lacks the later keys).
        last_writer: ``writer.lock``'s note of its last holder ("process PID on HOST"),
            None without one; it stays after that writer stops.
        writer_running: whether a process holds ``writer.lock`` now, as this machine's
            ``/proc/locks`` shows (None where it cannot be told: no ``/proc/locks``, or a
            lock on writer.lock's inode number on another device, as an overlay or btrfs
            reports, held by a process writer.lock does not name); a writer on another
            machine of a shared file system is not seen.
        state: ``"running"`` (a writer holds the lock; or writers wrote to the session while
            it was read, at each of the three reads describe makes then, ``writer_running``
            telling whether one holds it at the end), ``"closed"`` (the last writer closed
            the session: nothing left uncommitted), ``"killed"`` (no writer holds the lock and
            the last one left ``steps.journal`` lines or ``steps.sqlite-wal`` behind: killed,
            or a reader held the log as it closed; the readers see every logged step and a
            resume takes it on), or ``"running or killed"`` (such files are there and
            ``writer_running`` is None).
        notes: what the readers warned of (steps missing from the log, fewer steps than
            ``writer.lock`` says were committed), lines of ``writers.jsonl`` and
            ``runs.jsonl`` that could not be read, and the files named as checkpoints that
            resume and :func:`load_model` pass over or cannot load (what each is and what
            resume does with it; one of more labels than the log holds is not noted while a
            writer runs, which may have saved it since the log was read).
    """

    run_dir: str
    format: str
    env_id: str | None
    env_kwargs: dict[str, Any]
    env_class: str | None
    env_max_episode_steps: int | None
    env_max_episode_steps_recorded: bool
    n_features: int
    n_actions: int
    seed: int
    strategy: dict[str, Any]
    model_class: str
    model_args: dict[str, Any]
    starts_fitted: bool
    n_prior: int
    n_steps: int
    n_episodes: int
    n_episodes_ended: int
    n_labels: int
    n_demonstrations: int
    n_corrections: int
    n_requests: int
    n_requests_confident: int
    n_autonomous: int
    n_interrupted: int
    steps_per_episode: tuple[int, ...]
    requests_per_episode: tuple[int, ...]
    block_steps: int
    requests_per_block: tuple[int, ...]
    last_checkpoint: int | None
    checkpoints_on_disk: tuple[int, ...]
    keep_checkpoints: int | None
    refit: str
    stops: dict[str, Any]
    streak_met: str | None
    writers: tuple[dict[str, Any], ...]
    last_writer: str | None
    writer_running: bool | None
    state: str
    notes: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        """Every field, as JSON-able values (tuples as lists)."""
        return json.loads(json.dumps(asdict(self)))

    def text(self, *, ends: int = 5) -> str:
        """The summary in a screenful of lines; per-episode (or, with fewer than 4 episodes,
        per-block) requests for the first and last ``ends`` episodes or blocks."""
        lines = [f"{self.run_dir}: teaching session ({self.format}), {self._state_text()}"]
        env = f"{self.env_id or 'made directly (no gymnasium id)'}, "
        env += f"{counted(self.n_features, 'feature')}, {counted(self.n_actions, 'action')}"
        start = ", started from a fitted model" if self.starts_fitted else ""
        lines.append(f"env:        {env}")
        lines.append(f"class:      {self.env_class or _NOT_RECORDED}")
        lines.append(f"step cap:   {self._cap_text()}")
        if self.env_kwargs:  # as the Python that passes them again, each object written out
            args, notes = _make_arguments_source(self.env_kwargs, limit=_SHOW_CALL_CHARS)
            for i, arg in enumerate(args):
                comma = "," if i < len(args) - 1 else ""
                label = "kwargs:     " if i == 0 else " " * 12
                lines += _wrapped(arg + comma, label, " " * 14, _SHOW_WIDTH)
            lines += [f"            ({note})" for note in notes]
        lines += [
            f"strategy:   {_config_text(self.strategy)}",
            f"model:      {self.model_class}({_args_text(self.model_args)}){start}",
            f"seed:       {self.seed}",
            f"steps:      {self.n_steps} in {self.n_episodes} episode"
            f"{'' if self.n_episodes == 1 else 's'} ({self.n_episodes_ended} ended); "
            f"{self.n_autonomous} autonomous",
            f"labels:     {self.n_labels} ({self.n_demonstrations} demonstrations, "
            f"{self.n_corrections} corrections)"
            + (f"; {self.n_prior} prior demonstrations before them" if self.n_prior else ""),
            f"requests:   {self.n_requests} steps the teacher was asked "
            f"({self.n_requests - self.n_requests_confident} by design, non-interactive; "
            f"{self.n_requests_confident} by the strategy)",
            f"stops:      {self._stops_text()}",
        ]
        if self.streak_met is not None:
            lines.append(f"done:       {self._done_text()}")
        if self.n_episodes >= 4 or not self.requests_per_block:
            lines.append(
                "per episode (requests/steps): "
                + _ends_text(
                    [
                        f"{i}: {r}/{s}"
                        for i, (r, s) in enumerate(
                            zip(self.requests_per_episode, self.steps_per_episode, strict=True)
                        )
                    ],
                    ends,
                )
            )
        else:
            lines.append(
                f"per block of {self.block_steps} steps (requests): "
                + _ends_text(
                    [
                        # (the last block ends at the last step logged)
                        f"{i * self.block_steps}-"
                        f"{min((i + 1) * self.block_steps, self.n_steps) - 1}: {r}"
                        for i, r in enumerate(self.requests_per_block)
                    ],
                    ends,
                )
            )
        if self.n_interrupted:
            lines.append(
                f"interrupted: {self.n_interrupted} step{'' if self.n_interrupted == 1 else 's'}"
                " cut short (a Ctrl-C in the env's step, or a writer killed before the outcome)"
            )
        lines.append(
            "checkpoint: "
            + (
                "none"
                if self.last_checkpoint is None
                else f"the newest fitted on {self.last_checkpoint} labels{self._prior_text()}"
            )
        )
        lines.append("            " + self._kept_text())
        if not self.writers:
            lines.append("writers:    none recorded")
        for i, w in enumerate(self.writers):
            lines.append(
                ("writers:    " if i == 0 else "            ")
                + f"from step {w.get('first_step', '?')}: torch {w.get('torch_version', '?')}, "
                f"numpy {w.get('numpy_version', '?')}, {_env_versions_text(w)}torch threads "
                f"{w.get('torch_num_threads', '?')}, {w.get('model_device', '?')}, "
                f"pid {w.get('pid', '?')}, "
                f"{w.get('started_utc', '?')}"
            )
        lines += [f"note:       {note}" for note in self.notes]
        return "\n".join(lines)

    def line(self) -> str:
        """The summary in one line (a folder's listing); a session that met its streak stop
        (:attr:`streak_met`) ends with "; done: FIELD=N met"."""
        kind = str(self.strategy.get("type", "?"))
        episodes = f"{self.n_episodes} episode{'' if self.n_episodes == 1 else 's'}"
        done = ""
        if self.streak_met is not None:
            field = _STREAK_DONE[self.streak_met][0]
            done = f"; done: {field}={self.stops[field]} met"
        return (
            f"{self.run_dir}: {self.state}, {self._env_name()}, {kind}, "
            f"seed {self.seed}, {self.n_steps} steps, {episodes}, {self.n_labels} labels "
            f"({self.n_requests} requests, {self.n_corrections} corrections){done}"
        )

    def _env_name(self) -> str:
        """The env in a folder's listing: its gymnasium id, else its class (by its name)."""
        if self.env_id:
            return self.env_id
        if self.env_class:
            return f"{self.env_class.rsplit('.', 1)[-1]} made directly"
        return "env made directly"

    def _stops_text(self) -> str:
        """The stop settings config.json keeps, those set."""
        kept = [
            f"{k}={json.dumps(v)}"
            for k, v in self.stops.items()
            if v is not None and v is not False  # (a budget of 0 is one)
        ]
        return ", ".join(kept) or "none kept (a stop given to run() is not kept)"

    def _done_text(self) -> str:
        """The streak stop the session had met, what that says, and what a resume does."""
        assert self.streak_met is not None
        field, says = _STREAK_DONE[self.streak_met]
        stop = self.stops[field]
        return (
            f"{field}={stop} met ({says.format(stop)}): teaching is done; a resume takes no "
            "step (teach --resume refuses it), evaluate it or teach on from its "
            "demonstrations in a new session"
        )

    def _prior_text(self) -> str:
        """What every fit of the session includes besides its labels: " + N prior
        demonstrations", empty for a session without them."""
        return f" + {self.n_prior} prior demonstrations" if self.n_prior else ""

    def _cap_text(self) -> str:
        """The step cap as config.json keeps it, in words."""
        if not self.env_max_episode_steps_recorded:
            return _NOT_RECORDED
        if self.env_max_episode_steps is None:
            return "none (no TimeLimit, and no cap of its own)"
        return f"{self.env_max_episode_steps} (max_episode_steps)"

    def _kept_text(self) -> str:
        """The checkpoints on disk, the last writer's retention and, where a writer's
        retention may have removed earlier stages' checkpoints, how one is rebuilt."""
        on_disk = self.checkpoints_on_disk
        each = ", each" if len(on_disk) > 1 and self.n_prior else ""
        text = "on disk: " + (
            f"{len(on_disk)} ({_ends_text([str(n) for n in on_disk], 2)} labels"
            f"{each}{self._prior_text()})"
            if on_disk
            else "none"
        )
        keep = self.keep_checkpoints
        text += f", keep_checkpoints={keep} (" + (
            "every one)" if keep is None else f"the newest {keep}, besides 0 and hand refits)"
        )
        kept = [w.get("keep_checkpoints") for w in self.writers]
        kept = [k for k in kept if is_keep_count(k)]
        if kept and sum(1 for n in on_disk if n > 0) >= min(kept):  # some may be gone
            text += "; earlier stages: load_model(run_dir, n_demonstrations=k) rebuilds one " + (
                "from the log (replaying the refits before it)"
                if self.refit == "incremental"
                else "from the log (one fit)"
            )
        return text

    def _state_text(self) -> str:
        who = f" ({self.last_writer})" if self.last_writer else ""
        return {
            "running": f"a writer holds it now{who}"
            if self.writer_running
            else f"a writer wrote to it while it was read{who}",
            "closed": f"closed by its last writer{who}",
            "killed": f"its last writer{who} stopped without closing it (killed; a resume "
            "takes it on)",
        }.get(self.state, f"{self.state}{who}: /proc/locks cannot tell whether a writer runs")


#: what ``torchcbl show`` says of what a session's config.json does not keep (an older one's)
_NOT_RECORDED = "not recorded (an older session: resume does not compare it)"


def _env_versions_text(writer: dict[str, Any]) -> str:
    """A writer's ``env_versions`` as ``"sumo 1.28.0, "`` (what its env ran on, each name
    and version); empty where it recorded none."""
    versions = writer.get("env_versions")
    if not isinstance(versions, dict):
        return ""
    return "".join(f"{k} {v}, " for k, v in versions.items())


def _args_text(args: dict[str, Any]) -> str:
    return ", ".join(
        f"{k}={_config_text(v) if isinstance(v, dict) else json.dumps(v)}" for k, v in args.items()
    )


def _config_text(config: dict[str, Any]) -> str:
    """A stored ``to_config`` dict as ``Type(key=value, ...)``, nested dicts alike; a class
    of one's own (``"custom": true``) as ``Type[custom, as Parent](...)``, the fields of the
    parent's config it keeps (``"inherited"``) among its own, ``custom`` said once."""
    if not config.get("custom"):
        rest = {k: v for k, v in config.items() if k != "type"}
        return f"{config.get('type', '?')}({_args_text(rest)})"
    inherited = config.get("inherited")
    fields: dict[str, Any] = {}
    tag = "custom"
    if isinstance(inherited, dict):
        tag += f", as {inherited.get('type', '?')}"
        fields.update({k: v for k, v in inherited.items() if k not in ("type", "custom")})
    fields.update({k: v for k, v in config.items() if k not in ("type", "custom", "inherited")})
    return f"{config.get('type', '?')}[{tag}]({_args_text(dict(sorted(fields.items())))})"


def _ends_text(items: list[str], ends: int) -> str:
    if len(items) <= 2 * ends + 1:
        return ", ".join(items) or "none"
    return ", ".join(items[:ends]) + ", ..., " + ", ".join(items[-ends:])


def _read_writers(run_dir: Path) -> tuple[list[dict[str, Any]], list[str]]:
    """The writers of ``writers.jsonl`` and notes of what could not be read of it: the file,
    or lines that are not JSON objects (a line torn by a kill mid-append is left out without
    a note)."""
    return _read_lines(run_dir / WRITERS_NAME, "a writer's record")


def _read_runs(run_dir: Path) -> tuple[list[dict[str, Any]], list[str]]:
    """The run() calls of ``runs.jsonl`` (:meth:`SessionStore.note_run`), and notes of what
    could not be read of it, as :func:`_read_writers`."""
    return _read_lines(run_dir / RUNS_NAME, "a run()'s record")


def _read_lines(path: Path, what: str) -> tuple[list[dict[str, Any]], list[str]]:
    """The JSON objects of the lines of ``path`` (none where it is missing), and notes of
    what could not be read of it: the file, or lines that are not JSON objects (``what``
    each line should be); a line torn by a kill mid-append is left out without a note."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return [], []
    except OSError as exc:  # e.g. another user's file this user may not read
        return [], [f"{path} cannot be read ({exc.strerror or exc})"]
    entries, bad = [], []
    for number, line in enumerate(data.split(b"\n")[:-1], 1):  # after the last \n: torn
        try:
            entry = json.loads(line)
        except (ValueError, UnicodeDecodeError):
            entry = None
        if isinstance(entry, dict):
            entries.append(entry)
        else:
            bad.append(number)
    return entries, [f"{path}: lines {bad} are not {what}"] if bad else []


def _last_writer_reading(run_dir: str | os.PathLike[str], n_steps: int) -> tuple[Any, int]:
    """What a resume reads of the session's ``writers.jsonl`` and ``runs.jsonl`` as they are
    now, each read once: the ``env_versions`` its last writer recorded (None: that writer
    recorded none, or the file has no writer or cannot be read), and :func:`_run_start` of
    its ``n_steps`` logged steps."""
    run = Path(run_dir)
    writers = _read_writers(run)[0]
    versions = writers[-1].get("env_versions") if writers else None
    return versions, _run_start(writers, n_steps, _read_runs(run)[0])


def _run_start(
    writers: Iterable[Mapping[str, Any]],
    n_steps: int,
    runs: Iterable[Mapping[str, Any]] = (),
) -> int:
    """The first step of the run() call that wrote the last of the session's ``n_steps``
    logged steps: where the last record of ``runs.jsonl`` (``runs``) that is inside the log
    says it began (a record past the log's end, of a run() that took no step, passed over),
    or where the writer that wrote that step began (``writers.jsonl``'s records,
    ``writers``; a writer that wrote no step passed over), whichever is later: a run() ends
    with its writer. 0 where none says (no such file: a torchcbl before writers, or runs,
    were recorded; a session without ``runs.jsonl`` is counted from its last writer's first
    step, which cannot tell that writer's run() calls apart). The steps from here on hold the
    last run's streaks."""

    def inside(starts: Iterable[Any]) -> list[int]:
        return [s for s in starts if type(s) is int and 0 <= s < n_steps]

    writer = max(inside(w.get("first_step") for w in writers), default=0)
    # the last one appended, not the highest: a log cut back (repair_journal) and taught on
    # has older records of steps numbered again
    run = (inside(r.get("first_step") for r in runs) or [0])[-1]
    return max(writer, run)


#: The stop criteria of a TeachingConfig (torchcbl.teaching takes them from here): two
#: streaks, counted within one run(), and three budgets of the whole session.
STOP_FIELDS = (
    "autonomous_steps_to_stop",
    "autonomous_episodes_to_stop",
    "max_demonstrations",
    "max_steps",
    "max_episodes",
)
# The stop criteria plus the settings that only say when to stop: a resumed session and a
# run() call may change these; every other field is part of what the session learned with.
# (TeachingConfig's defaults: None for the stops, False for time_limit_is_success.)
_STOP_SETTINGS = (*STOP_FIELDS, "time_limit_is_success")


def _judged(record: StepRecord, info: Mapping[str, Any], time_limit_is_success: bool) -> bool:
    """Whether the episode ``record`` ends (with the env's ``info``) succeeded:
    ``info["is_success"]`` where the env says (not None), else a time-limit end with
    ``time_limit_is_success`` (TeachingConfig's)."""
    if info.get("is_success") is not None:  # None: the env does not say, as absent
        return bool(info["is_success"])
    return time_limit_is_success and record.truncated and not record.terminated


def _last_run_streaks(
    records: Iterable[StepRecord],
    corrected: Collection[int],
    start: int,
    *,
    time_limit_is_success: bool,
) -> tuple[int, int]:
    """The streaks (autonomous steps, successful autonomous episodes) a session's log ends
    on, counted as run() counts them over its steps from ``start`` on, the first step of its
    last run() (:func:`_run_start`; one that raised ends its streaks too), ``corrected`` the
    steps a correction labels, success judged with ``time_limit_is_success``. The one count
    resume (its ``stop_reason``) and :func:`describe` (``streak_met``) make."""
    steps = episodes = 0
    episode, labelled = None, False
    for r in records:
        if r.step < start:
            continue
        if r.episode != episode:
            episode, labelled = r.episode, False
        label = r.teacher_action is not None or r.step in corrected
        labelled |= label
        steps = 0 if label else steps + 1
        if "torchcbl_interrupted" in r.info or "torchcbl_error" in r.info:
            steps = episodes = 0  # the run() it was in raised: the next counts afresh
        elif r.terminated or r.truncated:
            clean = (
                not labelled
                and r.phase == "confident"
                and _judged(r, r.info, time_limit_is_success)
            )
            episodes = episodes + 1 if clean else 0
    return steps, episodes


def _streak_met(
    streaks: tuple[int, int],
    autonomous_steps_to_stop: int | None,
    autonomous_episodes_to_stop: int | None,
) -> str | None:
    """The streak stop met by ``streaks`` (:func:`_last_run_streaks`), as
    ``ConfidentTeacher.stop_reason`` names it ("autonomous_steps", "autonomous_episodes");
    None: none (a stop of None is none)."""
    steps, episodes = streaks
    if autonomous_steps_to_stop is not None and steps >= autonomous_steps_to_stop:
        return "autonomous_steps"
    if autonomous_episodes_to_stop is not None and episodes >= autonomous_episodes_to_stop:
        return "autonomous_episodes"
    return None


#: The streak stops by ``stop_reason``: the stop field, and what meeting it says of the agent
#: (of the stop's value), for ``torchcbl show`` and a ``teach --resume`` refused.
_STREAK_DONE = {
    "autonomous_steps": (
        "autonomous_steps_to_stop",
        "the agent drove its last {} steps on its own",
    ),
    "autonomous_episodes": (
        "autonomous_episodes_to_stop",
        "the agent drove its last {} episodes on its own, each a success",
    ),
}


def kept_checkpoints(run_dir: str | os.PathLike[str]) -> int | None:
    """How many of the newest checkpoints the session's last writer kept
    (``ConfidentTeacher(keep_checkpoints=)``, as ``writers.jsonl`` records it), which a
    resume keeps by default; None (every one) for a session whose writers did not record it
    (a torchcbl before 2026-11-27 kept every checkpoint) or whose ``writers.jsonl`` cannot be
    read."""
    return _kept_by(_read_writers(Path(run_dir))[0])


def _kept_by(writers: list[dict[str, Any]]) -> int | None:
    """:func:`kept_checkpoints` of the records of ``writers.jsonl``."""
    keep = writers[-1].get("keep_checkpoints") if writers else None
    if not is_keep_count(keep):
        return None
    return keep


def _lock_held(run_dir: Path) -> bool | None:
    """Whether a process holds an flock on ``writer.lock`` now, read from ``/proc/locks``
    (Linux) without opening, locking or touching the file (a reader's lock, even for an
    instant, could turn a writer starting then away); None where it cannot be told (no
    ``/proc/locks``, or a lock on its inode number on another device whose holder is not the
    one ``writer.lock`` names)."""
    path = run_dir / LOCK_NAME
    try:
        st = path.stat()
    except FileNotFoundError:
        return False
    except OSError:
        return None
    try:
        table = Path("/proc/locks").read_text(encoding="utf-8")
    except OSError:
        return None
    holder = None  # writer.lock's note of its holder, when on this machine
    try:
        m = re.match(rb"process (\d+) on (\S+)\n", path.read_bytes())
        if m and m.group(2).decode(errors="replace") == socket.gethostname():
            holder = m.group(1).decode()
    except OSError:
        pass
    unsure = False
    for entry in table.splitlines():
        fields = entry.split()
        if "->" in fields or len(fields) < 6 or fields[1] != "FLOCK":
            continue  # a waiter's line, or a lock of another kind
        try:
            major, minor, inode = fields[5].split(":")
            device, inode_number = (int(major, 16), int(minor, 16)), int(inode)
        except ValueError:
            continue
        if inode_number != st.st_ino:
            continue
        # the device as stat gives it, or (an overlay file system reports another device
        # than the lock's) the holder writer.lock names
        if device == (os.major(st.st_dev), os.minor(st.st_dev)) or fields[4] == holder:
            return True
        # writer.lock's inode number on another device, held by a process writer.lock does
        # not name as seen here (its note is from another host, or /proc/locks shows the
        # holder of another PID namespace as pid 0 or by another number): writer.lock on an
        # overlay or btrfs, or another file; which, cannot be told
        unsure = True
    return None if unsure else False


#: How many times :func:`describe` reads a session that a writer writes to as it reads it (one
#: holds ``writer.lock`` as the read starts, or the files a writer changes change) before it
#: reports what it read as a moment of a running session.
_DESCRIBE_READS = 3


def _writer_traces(run: Path) -> tuple[tuple[int, int] | None, ...]:
    """(size, mtime) of what a writer changes as it runs, read by ``stat`` alone: the log, its
    ``-wal``, the journal, ``writer.lock`` (rewritten by each writer as it starts and as it
    commits), ``writers.jsonl`` (a line appended by each writer as it starts),
    ``runs.jsonl`` (a line appended as each run() begins) and ``checkpoints/`` (a checkpoint
    saved or pruned)."""
    names = (
        LOG_NAME,
        LOG_NAME + "-wal",
        JOURNAL_NAME,
        LOCK_NAME,
        WRITERS_NAME,
        RUNS_NAME,
        CHECKPOINT_DIR,
    )
    return tuple(_file_state(run / name) for name in names)


@dataclass(frozen=True)
class _SummaryRead:
    """What :func:`describe` reads of a session in one go (see :func:`_read_for_summary`)."""

    records: list[StepRecord]
    correction_records: list[CorrectionRecord]
    log_notes: list[str]
    writers: list[dict[str, Any]]
    writer_notes: list[str]
    runs: list[dict[str, Any]]
    run_notes: list[str]
    checkpoint: int | None
    checkpoint_notes: list[str]
    beyond_notes: list[str]
    on_disk: tuple[int, ...]  # the checkpoints' label counts, as listed before the log's read
    left: bool
    lock_note: str | None


def _read_for_summary(run: Path, config: dict[str, Any]) -> _SummaryRead:
    """Read what :func:`describe` reports of the session in ``run``, read-only: its log (the
    readers' warnings as notes), its writers, its checkpoint (``checkpoints/`` listed before
    the log is read, so that a checkpoint of more labels than the log holds is one of labels
    the log lacks, not one a writer saved since), whether its last writer left lines or a
    ``-wal`` behind, and ``writer.lock``'s note of its holder."""
    entries = _checkpoint_entries(run / CHECKPOINT_DIR)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        records, corrections = _read_log(run)
    log_notes = [" ".join(str(w.message).split()) for w in caught]
    writers, writer_notes = _read_writers(run)
    runs, run_notes = _read_runs(run)
    correction_records = _corrections_of(records, corrections)
    checkpoint, checkpoint_notes, beyond_notes = _checkpoint_report(
        run, config, records, correction_records, entries
    )
    left = (run / LOG_NAME).with_name(LOG_NAME + "-wal").exists() or _unborn(run)
    try:
        left = left or (run / JOURNAL_NAME).stat().st_size > 0
    except FileNotFoundError:
        pass
    try:
        m = re.match(rb"process \d+ on [^\n]*", (run / LOCK_NAME).read_bytes())
    except OSError:
        m = None
    return _SummaryRead(
        records=records,
        correction_records=correction_records,
        log_notes=log_notes,
        writers=writers,
        writer_notes=writer_notes,
        runs=runs,
        run_notes=run_notes,
        checkpoint=checkpoint,
        checkpoint_notes=checkpoint_notes,
        beyond_notes=beyond_notes,
        on_disk=tuple(sorted(n for n, _ in entries)),
        left=left,
        lock_note=m.group(0).decode(errors="replace") if m else None,
    )


def describe(run_dir: str | os.PathLike[str]) -> SessionSummary:
    """What a teaching session directory holds: its env, strategy and model, its counts of
    steps, episodes, labels and requests, its checkpoints, its writers and whether one runs.

    Read with the session's own readers (:func:`load_config` and the log's, as
    :func:`load_records` reads it), so it is safe while a writer runs and writes nothing: the
    directory may be read-only or another user's (where a writer runs or was killed, SQLite
    may create its ``-shm`` index, as for every reader: the module docstring). Whether a
    writer holds the session is read from ``/proc/locks``, never by taking its lock. Its
    checkpoint is found as resume finds it: the files are read and checked against the log's
    labels (and the prior demonstrations', read from ``prior.npz``), not taken by name, and
    its state is tried on a fresh model of the session's (a GaussianMixtureSet session's: a
    class of the user's own cannot be built here), as resume loads it.
    ``print(describe(run_dir).text())`` shows it in a screenful; ``torchcbl show SESSION_DIR``
    does so at the command line.

    What it reports is one moment of the session: a writer that held the lock as the read
    began, or that left a trace as it went on (a line of ``writers.jsonl``, a change to the
    log, the journal, ``writer.lock`` or ``checkpoints/``), may have logged, saved checkpoints
    or closed meanwhile, so the session is read again, up to three times in all, unless a
    writer holds it at the end (``"running"``, read once); written to at every read, it is
    ``"running"`` too. A checkpoint of more labels than the log holds is noted only where no
    writer ran during the read, as one of labels the log lost (``checkpoints/`` is listed
    before the log is read: a writer logs a label before it saves a checkpoint of it).

    Returns:
        A :class:`SessionSummary`. What the readers would warn of (steps missing from the
        log, fewer than ``writer.lock`` says were committed) is in its ``notes``, not warned.

    Raises:
        IncompatibleRunDirError: ``run_dir`` is not a session directory (the message names the
            sessions below it, if any), or a file of it (or its ``checkpoints/``) may not be
            read or the file system fails to read it (an I/O error).
        CorruptSessionError: a file of the session is damaged or missing (as
            :func:`load_records`).
    """
    run = Path(run_dir)
    config = load_config(run)
    for _ in range(_DESCRIBE_READS):
        held = _lock_held(run)
        traces = _writer_traces(run)
        read = _read_for_summary(run, config)
        # after the read: a writer seen now, or at the start, or whose traces changed, may
        # have logged, saved checkpoints or closed while the session was read
        running = _lock_held(run)
        settled = held is not True and _writer_traces(run) == traces
        if settled or running is True:  # (a writer that runs on: read once, as running)
            break
    # a writer wrote to the session as it was read, every time: what was read is a moment of
    # a session being written, so a checkpoint of more labels than that log held may be one
    # the writer saved after it, and the session is not said to be closed or killed
    writing = running is True or not settled
    records = read.records
    n_episodes = max((r.episode for r in records), default=-1) + 1
    steps = [0] * n_episodes
    asked = [0] * n_episodes
    last_step = max((r.step for r in records), default=-1)
    blocks = [0] * (last_step // SUMMARY_BLOCK_STEPS + 1 if records else 0)
    for r in records:
        steps[r.episode] += 1
        if r.teacher_action is not None:
            asked[r.episode] += 1
            blocks[r.step // SUMMARY_BLOCK_STEPS] += 1
    correction_records = read.correction_records
    n_corrections = len(correction_records)
    n_demonstrations = sum(asked)
    if writing:
        state = "running"
    elif not read.left:
        state = "closed"
    else:
        state = "killed" if running is False else "running or killed"
    checkpoint_notes = read.checkpoint_notes + ([] if writing else read.beyond_notes)
    writers, writer_notes, lock_note = read.writers, read.writer_notes, read.lock_note
    notes = read.log_notes
    prior = config.get("prior")
    teaching = config["teaching"]
    stops = {
        k: teaching.get(k, False if k == "time_limit_is_success" else None) for k in _STOP_SETTINGS
    }
    return SessionSummary(
        run_dir=str(run_dir),
        format=str(config["format"]),
        env_id=config["env"].get("id"),
        env_kwargs=_kept_arguments(config["env"]),
        env_class=_stored_class(config["env"]),
        env_max_episode_steps=_stored_cap(config["env"]),
        env_max_episode_steps_recorded="max_episode_steps" in config["env"],
        n_features=int(config["env"]["n_features"]),
        n_actions=int(config["env"]["n_actions"]),
        seed=int(config["seed"]),
        strategy=stored_strategy(config),
        model_class=str(config["model"].get("class")),
        model_args=dict(config["model"]["args"]),
        starts_fitted=config.get("starts_fitted") is True,
        n_prior=int(prior["n_demonstrations"]) if isinstance(prior, dict) else 0,
        n_steps=len(records),
        n_episodes=n_episodes,
        n_episodes_ended=sum(1 for r in records if r.terminated or r.truncated),
        n_labels=n_demonstrations + n_corrections,
        n_demonstrations=n_demonstrations,
        n_corrections=n_corrections,
        n_requests=n_demonstrations,
        n_requests_confident=sum(
            1 for r in records if r.teacher_action is not None and r.phase == "confident"
        ),
        n_autonomous=sum(1 for r in records if r.autonomous),
        n_interrupted=sum(1 for r in records if r.info.get("torchcbl_interrupted")),
        steps_per_episode=tuple(steps),
        requests_per_episode=tuple(asked),
        block_steps=SUMMARY_BLOCK_STEPS,
        requests_per_block=tuple(blocks),
        last_checkpoint=read.checkpoint,
        checkpoints_on_disk=read.on_disk,
        keep_checkpoints=_kept_by(writers),
        refit=str(config["teaching"].get("refit", "full")),
        stops=stops,
        streak_met=_streak_met(
            _last_run_streaks(
                records,
                {c.step for c in correction_records},
                _run_start(writers, len(records), read.runs),
                time_limit_is_success=stops["time_limit_is_success"] is True,
            ),
            _stop_value(stops["autonomous_steps_to_stop"]),
            _stop_value(stops["autonomous_episodes_to_stop"]),
        ),
        writers=tuple(writers),
        last_writer=lock_note,
        writer_running=running,
        state=state,
        notes=tuple(notes + writer_notes + read.run_notes + checkpoint_notes),
    )


def _stop_value(kept: Any) -> int | None:
    """A streak stop config.json keeps, as run() takes it: an int >= 1, else None (none; a
    value no TeachingConfig takes, which resume refuses, is none here)."""
    return kept if type(kept) is int and kept >= 1 else None


def _stored_class(senv: Mapping[str, Any]) -> str | None:
    """The env's class config.json keeps (``senv``: its ``"env"``), None where it keeps none."""
    kept = senv.get("class")
    return kept if isinstance(kept, str) and kept else None


def _stored_cap(senv: Mapping[str, Any]) -> int | None:
    """The step cap config.json keeps (``senv``: its ``"env"``), None where it keeps none."""
    kept = senv.get("max_episode_steps")
    return int(kept) if isinstance(kept, int) and not isinstance(kept, bool) else None


def _checkpoint_report(
    run: Path,
    config: dict[str, Any],
    records: list[StepRecord],
    corrections: list[CorrectionRecord],
    entries: list[tuple[int, Path]],
) -> tuple[int | None, list[str], list[str]]:
    """The checkpoint resume and :func:`load_model` start from (its count of labels; None:
    none), found as they find it (:func:`_scan_checkpoints`, in ``entries``: ``checkpoints/``
    listed before ``records`` were read) and loaded as they load it (:func:`_foreign_state`),
    and a note on each file named as a checkpoint that they pass over or cannot load: what it
    is and what resume does with it; the notes on those of more labels than the log holds
    apart (a writer running as the log was read may have saved them since). Reads only."""
    xs, ys = label_sequence(records, corrections)
    try:
        prior = _read_prior(run, config)
    except IncompatibleRunDirError as exc:  # missing, changed, unreadable: resume refuses
        return None, [f"no checkpoint is usable: {' '.join(str(exc).split())}"], []
    px, py = ([], []) if prior is None else (list(prior[0]), prior[1].tolist())
    scan = _scan_checkpoints(run / CHECKPOINT_DIR, len(ys), len(py), px + xs, py + ys, entries)
    notes = []
    max_new = int(config["teaching"]["max_new"])
    incremental = config["teaching"].get("refit", "full") == "incremental"
    rebuilt = _rebuilt_in_place(scan.refits, scan.n or 0, max_new, incremental)
    foreign = None if scan.payload is None else _foreign_state(config, scan.payload)
    if foreign is not None and scan.n is not None:
        k = scan.stood_on(len(ys), max_new)
        copy_name = _copy_name(run / CHECKPOINT_DIR / f"model-{scan.n:08d}.pt")[0]
        notes.append(_foreign_note(config, scan.n, k, foreign, copy_name))
        scan = dataclasses.replace(scan, n=None, payload=None)  # resume starts from none
    for n, path, why in scan.passed_over:
        name = f"{CHECKPOINT_DIR}/{path.name}"
        if why == "stale":
            what = f"is stale (not fitted on the log's first {n} labels"
            what += ", after the prior demonstrations)" if py else ")"
        else:
            what = _damage_text(path)
        if n == 0 and config.get("starts_fitted") is True:
            notes.append(
                f"{name} {what}: it holds the fitted model the session started from, which "
                "no label can refit; resume and load_model cannot load it, refuse the session "
                "where its model still stands on it, and leave the file as it is"
            )
        elif n in scan.refits and n not in rebuilt:
            notes.append(
                f"{name} {what}: resume and load_model pass it over; its name records a refit "
                f"on {n} labels, where the refit schedule puts one anyway, which they rebuild "
                f"from an earlier checkpoint or the log (resume renames it {path.name}.{why})"
            )
        elif n in scan.refits:
            kept = (_copy_name(path)[0] or path.with_name(f"{path.name}.damaged")).name
            notes.append(
                f"{name} {what}: resume and load_model pass it over; its name still records "
                f"a refit on {n} labels (where a refit by hand may have moved the refit "
                "schedule), which they rebuild from an earlier checkpoint or the log (resume "
                f"writes the rebuilt model in its place, keeping this file as {kept})"
            )
        else:
            notes.append(
                f"{name} {what}: resume and load_model pass it over (resume renames it "
                f"{path.name}.{why}) and rebuild the model from an earlier checkpoint or "
                "the log"
            )
    beyond = [
        f"{CHECKPOINT_DIR}/{path.name} names {n} labels, more than the {len(ys)} the log "
        "holds (a checkpoint of labels the log lost, or a file put there by hand): load_model "
        f"passes it over and resume renames it {path.name}.stale, so that no reader takes it "
        "for a refit once the session is taught that far again"
        for n, path in scan.beyond
    ]
    return scan.n, notes, beyond


def _foreign_state(config: dict[str, Any], payload: dict[str, Any]) -> str | None:
    """Why the session's model cannot load the checkpoint ``payload``'s state, tried as
    resume and :func:`load_model` load it: into a fresh model built from ``config``
    (:func:`build_model`), on the CPU; None where it loads, or where no such model can be
    built here (a class of the user's own: only resume, given one, finds out)."""
    try:
        model = build_model(config)
    except Exception:
        return None
    state = payload["state_dict"]
    try:
        model.load_state_dict(state)
    except Exception as exc:
        name = type(model).__name__
        own, saved = set(model.state_dict()), {str(k) for k in state}

        def few(keys: set[str]) -> str:
            names = sorted(keys)
            more = f" and {len(names) - 3} more" if len(names) > 3 else ""
            return ", ".join(names[:3]) + more

        if saved - own:
            keys = "its key {} is" if len(saved - own) == 1 else "its keys {} are"
            return f"{keys.format(few(saved - own))} not a {name}'s"
        if "Missing key" in str(exc):
            return f"it lacks a {name}'s {few(own - saved)}"
        text = " ".join(str(exc).split()).removeprefix("load_state_dict: ")
        return text.split("; ", 1)[0][:200]
    return None


def _foreign_note(
    config: dict[str, Any], n: int, k: int, why: str, copy_name: Path | None = None
) -> str:
    """:func:`describe`'s note on ``checkpoints/model-<n>.pt``, the checkpoint resume would
    start from, whose state the session's model cannot load (``why``), saying what resume
    and :func:`load_model` do with it (as :func:`restore_model` does); ``k``: the labels the
    session's model stood on (:meth:`_CheckpointScan.stood_on`); ``copy_name``: where a
    resume would keep its bytes (:func:`_copy_name`; default ``<name>.damaged``)."""
    name = f"model-{n:08d}.pt"
    kept_as = f"{name}.damaged" if copy_name is None else copy_name.name
    model = str(config["model"].get("class"))
    what = (
        f"{CHECKPOINT_DIR}/{name} holds the state of another model than the session's "
        f"{model} ({why})"
    )
    if n == 0 and config.get("starts_fitted") is True:
        return (
            f"{what}: it holds the fitted model the session started from, which no label can "
            "refit; resume and load_model cannot load it, refuse the session where its model "
            "still stands on it, and leave the file as it is"
        )
    teaching = config["teaching"]
    if k == n:
        kept = (
            f"writes the rebuilt model in its place, keeping this file as {kept_as}"
            if n > 0
            else f"renames it {name}.damaged"
        )
        return (
            f"{what}: resume and load_model cannot load it and refit the model on the log's "
            f"labels (resume {kept})"
        )
    if teaching.get("refit", "full") == "incremental":
        return (
            f"{what}: resume and load_model cannot load it and replay the session's refits "
            "from the log's labels, leaving the file as it is"
        )
    return (
        f"{what}: resume and load_model do not load it (they refit the model on the log's "
        f"first {k} labels) and leave the file as it is"
    )


def _damage_text(path: Path) -> str:
    """What is wrong with a file named as a checkpoint that cannot be loaded."""
    try:
        st = path.stat()
    except OSError as exc:  # a dangling link, an I/O error
        return f"cannot be read ({exc.strerror or exc})"
    if stat.S_ISDIR(st.st_mode):
        return "is a directory, not a checkpoint file"
    if not stat.S_ISREG(st.st_mode):
        return "is not a regular file"
    if st.st_size == 0:
        return "is an empty file"
    if not os.access(path, os.R_OK):
        return "cannot be read by this user"
    return "is damaged (cut short, or not a checkpoint torchcbl wrote)"


def resume_problems(
    stored: dict[str, Any],
    *,
    n_features: int,
    n_actions: int,
    env_id: str | None,
    learning: tuple[dict[str, Any], dict[str, Any]] | None,
    model_args: dict[str, Any] | None,
    strategy: dict[str, Any] | None,
    env_kwargs: dict[str, Any] | None = None,
    env_max_episode_steps: int | None = None,
    env_inputs: dict[str, Any] | None = None,
    model_class: str | None = None,
    model_type: type | None = None,
    env_class: str | None = None,
    env_observation_space: Any = None,
    env_make_kwargs: Mapping[str, Any],
) -> list[str]:
    """What keeps a session from resuming with the given env, configuration, model and
    strategy (empty list: nothing). ``learning`` is (stored, given) learning fields;
    ``model_args`` / ``strategy`` None means "rebuilt from the directory"; ``model_class``:
    the given model's class name, compared with the one the session kept (``model_type``,
    its class, lets the advice name the class's arguments the session did not record); of a
    strategy
    config with ``"custom": true`` (no ``to_config``, or a parent's) only the class name, the
    relabel flag, the parent's dict (``"inherited"``) and the rule are compared (a session
    stored before a subclass keeping its parent's ``to_config`` was custom holds the parent's
    dict: that subclass given resumes it). The rule has been compared too since 2026-11-27
    (a custom one, without ``to_config``, by the last part of its class name, so one moved to
    another module resumes): a custom rule renamed since the session was stored, which
    resumed before, is refused; ``env_kwargs``: what ``gymnasium.make`` was given
    for the env (plain values are compared, ``render_mode`` aside), with its
    ``max_episode_steps`` (the cap in force: the smallest TimeLimit's or the env's own;
    sessions written before 2026-11-26 do not keep it, and those written before 2026-11-27
    kept None for an env with a cap of its own only);
    ``env_inputs``: the env's ``describe_inputs()`` (None: it has none), compared with the
    session's where the session kept one (sessions written before 2026-11-27 did not), on the
    keys both hold (a key one side lacks, e.g. one a later version of the env describes, is
    not compared);
    ``env_class``: the unwrapped env's class (``module.qualname``), compared by its name with
    the session's where the session kept one, and ``env_observation_space`` (the space),
    compared with the one the session kept; ``env_make_kwargs``: what ``gymnasium.make`` was
    given, as given (the spec's kwargs, objects whole; empty for an env made directly): of each
    argument that both it and the session (config.json's ``env.kwargs_objects``, kept since
    2026-11-27) keep whole (a frozen dataclass), the kept forms are compared field by field (a
    field its class marks ``metadata={COMPARE_ON_RESUME: False}`` aside; one it gives a
    :data:`RESUME_AS` function, kept as a plain value on one side, as the object that value
    spells); see
    :func:`_env_problems`, which compares them whether or not the env was made by
    ``gymnasium.make``."""
    problems: list[str] = []
    senv = stored["env"]
    if (senv["n_features"], senv["n_actions"]) != (n_features, n_actions):
        problems.append(
            f"env: the session has {counted(senv['n_features'], 'feature')} and "
            f"{counted(senv['n_actions'], 'action')}, the given env {n_features} and {n_actions}"
        )
    env_lines: list[str] = []  # (each ends saying how to make the session's env)
    if senv.get("id") and env_id and senv["id"] != env_id:
        problems.append(f"env id: the session used {senv['id']!r}, got {env_id!r}")
    elif env_kwargs is not None:  # (another id says enough)
        env_lines = _env_problems(
            senv,
            env_id,
            env_kwargs,
            env_max_episode_steps,
            env_class,
            env_observation_space,
            env_make_kwargs,
        )
        problems += env_lines
    kept_inputs = senv.get("inputs")
    given = env_inputs or {}
    # the keys both describe, as a kept object's fields: a key a later version of the env
    # describes (a new field of its scenario, say) does not refuse the sessions kept before it
    differ = {
        k: (kept_inputs[k], given[k])
        for k in sorted(set(kept_inputs) & set(given) if isinstance(kept_inputs, dict) else ())
        if kept_inputs[k] != given[k]
        or isinstance(kept_inputs[k], bool) != isinstance(given[k], bool)
    }
    if differ:
        line = (
            f"env inputs (stored, given): {differ}; the env reads other inputs than the "
            "session was taught on (its describe_inputs() differs, e.g. a file edited since): "
            "give it the inputs as they were"
        )
        if not env_lines:  # (other traffic given as a name against an object, say)
            line += "; " + _how_to_make(senv)
        problems.append(line)
    if learning is not None and learning[0] != learning[1]:
        diff = {
            k: (v, learning[1].get(k)) for k, v in learning[0].items() if learning[1].get(k) != v
        }
        problems.append(f"config (stored, given): {diff}; only the stop fields may change")
    if model_args is not None:
        problems += _model_problems(stored, model_class, model_args, model_type)
    if strategy is not None:
        want = stored_strategy(stored)
        # (a subclass's own to_config naming "NoveltyGated" may lack the key: read alike)
        strategy = _with_added_keys(strategy)
        if strategy.get("custom") or want.get("custom"):
            # a session stored before a subclass keeping its parent's to_config was stored as
            # custom holds the parent's dict: the subclass passed resumes it, as it did then.
            # That dict is custom where the rule is a user's without to_config, and is then
            # compared as custom dicts are (by class name: a script's module reads __main__);
            # the library's own dicts are compared whole
            before = _as_stored_before(strategy)
            as_before = before == want or (
                bool(want.get("custom")) and _comparable(before) == _comparable(want)
            )
            if not as_before and _comparable(strategy) != _comparable(want):
                problems.append(f"strategy: stored {want}, given {strategy}")
        elif strategy != want:
            problems.append(f"strategy: stored {want}, given {strategy}")
    return problems


class _Said:
    """A value a refusal writes as words, not as a Python value (its ``repr`` is ``text``)."""

    def __init__(self, text: str) -> None:
        self.text = text

    def __repr__(self) -> str:
        return self.text


#: a ``gymnasium.make`` argument one side did not give
_NOT_GIVEN = _Said("not given (the env's default)")
#: a step cap (``max_episode_steps``) of None: no cap, not an argument left out
_NO_CAP = _Said("no cap")


def _cap_text(cap: int | None) -> int | _Said:
    """A step cap as a refusal writes it: the number, or "no cap" for None."""
    return _NO_CAP if cap is None else cap


def _env_problems(
    senv: dict[str, Any],
    env_id: str | None,
    env_kwargs: dict[str, Any],
    cap: int | None,
    env_class: str | None,
    space: Any,
    make_kwargs: Mapping[str, Any],
) -> list[str]:
    """What tells the given env from the session's (``senv``, config.json's ``"env"``) besides
    its id and sizes, whether either was made by ``gymnasium.make`` or directly: the class of
    the unwrapped env (by name, so a class moved to another module resumes; kept since
    2026-11-27), the observation space as :func:`observation_space_text` writes it (kept
    since the first version; a wrapper that changes it makes another env), the step cap in
    force (kept for an env with a gymnasium id since 2026-11-26, for every env since
    2026-11-27), and ``gymnasium.make``'s plain arguments (``render_mode`` aside), which an env
    made directly does not show: a session whose env was made with some is refused such an
    env; of its arguments given as frozen dataclasses, those both sides keep whole
    (``make_kwargs``, as given; :func:`_object_problems`). Only what the session kept is
    compared."""
    differ: list[str] = []
    objects: list[str] = []
    stored_kw = senv.get("kwargs") or {}
    kept_class = senv.get("class")
    if kept_class and env_class and kept_class.rsplit(".", 1)[-1] != env_class.rsplit(".", 1)[-1]:
        differ.append(
            f"env class: the session's env is a {kept_class}, the given one a {env_class}"
        )
    kept_space = senv.get("observation_space")
    if kept_space is not None and space is not None:
        given = observation_space_text(space)
        if kept_class is None:  # kept before 2026-11-27, under the writer's print options
            same = _printed_as(kept_space, space)
        else:  # written with numpy's defaults (repr: a text kept under other options)
            same = kept_space in (given, repr(space))
        if same is False:
            differ.append(
                f"env observation space: the session's is {kept_space}, the given env's {given}"
            )
    kw_differ: dict[str, tuple[Any, Any]] = {}
    if senv.get("id") and env_id:  # both made by gymnasium.make (the same id)
        # what gymnasium.make was given, where both sides are plain values (an object is
        # kept only as its repr, which may name a memory address); render_mode may change
        given_kw = json.loads(json.dumps(env_kwargs))  # as the session stored its own
        # (one side's argument left to the env's default is written so, not as None)
        kw_differ = {
            k: (stored_kw.get(k, _NOT_GIVEN), given_kw.get(k, _NOT_GIVEN))
            for k in sorted(set(stored_kw) | set(given_kw))
            if k != "render_mode"
            and not kept_as_repr(stored_kw.get(k))
            and not kept_as_repr(given_kw.get(k))
            and stored_kw.get(k) != given_kw.get(k)
        }
        # an object both sides keep whole (a frozen dataclass: a TrafficScenario, a
        # CorridorMap): its kept forms, where the text above is not compared
        objects = _object_problems(stored_kw, senv.get("kwargs_objects"), make_kwargs)
        differ += objects
    unshown = {k: v for k, v in stored_kw.items() if k != "render_mode"}
    if senv.get("id") and not env_id and unshown:
        differ.append(
            f"env kwargs: the session's env was made by gymnasium.make with {unshown}, the "
            "given one directly (it has no gymnasium spec), so they cannot be compared"
        )
    has_cap = "max_episode_steps" in senv
    want = senv.get("max_episode_steps")
    if has_cap and want != cap:  # (written with "no cap" for None, on either side)
        caps = (_cap_text(want), _cap_text(cap))
        if senv.get("id"):  # as gymnasium.make's argument
            kw_differ["max_episode_steps"] = caps
        else:  # an env made directly: its TimeLimit's cap (or its own)
            differ.append(f"env step cap (max_episode_steps, stored, given): {caps}")
    if kw_differ:
        differ.append(f"env kwargs (stored, given): {kw_differ}")
    if not differ:
        return []
    return ["; ".join(differ) + f"; {_how_to_make(senv)}"]


def _how_to_make(senv: Mapping[str, Any]) -> str:
    """How to make the session's env (``senv``, config.json's ``"env"``), as a refusal ends:
    the ``gymnasium.make`` call with the arguments and step cap it keeps, each object kept
    whole written as its constructor call, with the imports it needs
    (:func:`_make_arguments_source`), or for an env made directly its class and step cap."""
    kept_class = senv.get("class")
    has_cap = "max_episode_steps" in senv
    want = senv.get("max_episode_steps")
    if senv.get("id"):
        capped, cap_notes = _cap_argument(senv["id"], want) if has_cap else ("", [])
        args, notes = _make_arguments_source(_kept_arguments(senv), limit=_CALL_CHARS)
        notes = cap_notes + notes
        call = "".join(f", {a}" for a in args).replace(_BREAK, " ")
        how = f"make the env as the session did, gymnasium.make({senv['id']!r}{capped}{call})"
        return how + (f" ({'; '.join(notes)})" if notes else "")
    how = "give the env the session was taught in"
    if kept_class:
        how += f", a {kept_class.rsplit('.', 1)[-1]} ({kept_class}) made as it was"
    if has_cap and want is not None:
        how += f", under gymnasium.wrappers.TimeLimit(env, {want})"
    elif has_cap:
        how += ", without a TimeLimit (the session's env had no step cap)"
    return how


def _cap_argument(env_id: str, want: int | None) -> tuple[str, list[str]]:
    """The ``max_episode_steps`` argument (``", max_episode_steps=n"``, or ``""``) that makes
    ``gymnasium.make(env_id, ...)`` give the session's step cap ``want`` (None: no cap), and a
    note where the installed gymnasium cannot: ``want`` where it is one; for no cap, nothing
    where the id registers none here (torchcbl/Driving-v0), else -1, which leaves gymnasium's
    TimeLimit off from gymnasium 1.0 on (before, it made a TimeLimit of -1 steps)."""
    import gymnasium

    if want is not None:
        return f", max_episode_steps={want}", []
    spec = gymnasium.envs.registration.registry.get(env_id)
    if spec is not None and spec.max_episode_steps is None:
        return "", []
    version = str(getattr(gymnasium, "__version__", ""))
    major = version.split(".", 1)[0]
    if major.isdigit() and int(major) < 1:
        return ", max_episode_steps=-1", [
            f"max_episode_steps=-1 leaves the TimeLimit off from gymnasium 1.0 on; gymnasium "
            f"{version} is installed: upgrade it"
        ]
    return ", max_episode_steps=-1", []


#: numpy's default print options: a Box's bounds are written with these, whatever a
#: program set (np.set_printoptions), so that config.json keeps one text per space
_NUMPY_PRINT_DEFAULTS: dict[str, Any] = {
    "precision": 8,
    "threshold": 1000,
    "edgeitems": 3,
    "linewidth": 75,
    "suppress": False,
    "nanstr": "nan",
    "infstr": "inf",
    "sign": "-",
    "floatmode": "maxprec",
    "formatter": None,
    "legacy": False,
}


_BOX_TEXT = re.compile(r"Box\((?P<bounds>.*), (?P<shape>\([0-9, ]*\)), (?P<dtype>\w+)\)", re.S)


def _printed_as(text: str, space: Any) -> bool | None:
    """Whether ``text`` is ``space`` as gymnasium printed it under any of numpy's print
    options (a session stored before the env's class was kept wrote the observation space's
    ``repr`` under the options its program had set, e.g. ``precision=3, suppress=True``):
    for a ``Box``, its shape and dtype as written, and each bound as printed, to the digits
    printed. ``None`` where the text cannot be read so (a ``Dict``, a summarized array, ...):
    such a session's space was not compared before, and is not now."""
    import gymnasium as gym

    if not text.startswith("Box("):
        if "[" in text or "Box(" in text:  # a space holding numbers numpy printed
            return None
        return text == repr(space)  # e.g. Discrete(2): no numpy print option changes it
    match = _BOX_TEXT.fullmatch(text)
    if match is None:
        return None
    if not isinstance(space, gym.spaces.Box):
        return False
    if match["shape"] != str(space.shape) or match["dtype"] != str(space.dtype):
        return False
    bounds = _split_bounds(match["bounds"])
    if bounds is None:
        return None
    for printed, given in zip(bounds, (space.low, space.high), strict=True):
        same = _numbers_printed_as(printed, np.asarray(given, np.float64).ravel())
        if same is not True:
            return same
    return True


def _split_bounds(text: str) -> tuple[str, str] | None:
    """``"low, high"`` of a Box's text as its two printed bounds (an array in brackets or
    one number), or ``None``."""
    if text.startswith("["):
        depth = 0
        for i, ch in enumerate(text):
            depth += {"[": 1, "]": -1}.get(ch, 0)
            if depth == 0:
                rest = text[i + 1 :]
                return (text[: i + 1], rest[2:]) if rest.startswith(", ") else None
        return None
    low, sep, high = text.partition(", ")
    return (low, high) if sep else None


def _numbers_printed_as(printed: str, values: np.ndarray) -> bool | None:
    """Whether ``printed`` (one number or a printed array) is ``values`` to the digits it
    shows; ``None`` where it cannot be read (a summarized array)."""
    tokens = printed.replace("[", " ").replace("]", " ").split()
    if "..." in tokens:
        return None
    try:
        numbers = [float(t) for t in tokens]
    except ValueError:
        return None
    if len(numbers) == 1:  # a uniform bound, written as one number
        tokens, numbers = tokens * values.size, numbers * values.size
    if len(numbers) != values.size:
        return False
    for token, number, value in zip(tokens, numbers, values.tolist(), strict=True):
        if not np.isfinite(number) or not np.isfinite(value):
            if not (number == value or (np.isnan(number) and np.isnan(value))):
                return False
            continue
        mantissa, _, exponent = token.lower().partition("e")
        digits = len(mantissa.partition(".")[2])
        tolerance = 0.5 * 10.0 ** (int(exponent or 0) - digits)
        if abs(number - value) > tolerance * (1 + 1e-6) + 1e-7 * abs(value):
            return False
    return True


def observation_space_text(space: Any) -> str:
    """An observation space as config.json keeps it (``"observation_space"``): gymnasium's
    ``repr`` of a ``Box``, ``Box(low, high, shape, dtype)`` with a uniform bound as one number,
    written with numpy's default print options (gymnasium's own repr follows the options in
    force when it is first asked for); other spaces by their ``repr``."""
    import gymnasium as gym

    if not isinstance(space, gym.spaces.Box):
        return repr(space)

    def short(a: np.ndarray) -> str:  # gymnasium's array_short_repr
        return str(np.min(a)) if a.size != 0 and np.min(a) == np.max(a) else str(a)

    with np.printoptions(**_NUMPY_PRINT_DEFAULTS):
        return f"Box({short(space.low)}, {short(space.high)}, {space.shape}, {space.dtype})"


def _model_problems(
    stored: dict[str, Any],
    model_class: str | None,
    model_args: dict[str, Any],
    model_type: type | None = None,
) -> list[str]:
    """What keeps a given model (its class name, its arguments as :func:`_model_args` reads
    them, or ``{"error": why}``; its class, where at hand) from being the session's."""
    kept_class = stored["model"].get("class", "GaussianMixtureSet")
    if "error" in model_args and kept_class == "GaussianMixtureSet":
        return [f"model: {model_args['error']}"]  # (which says to pass a GaussianMixtureSet)
    if model_class is not None and model_class != kept_class:
        return [
            f"model: the session's model is a {kept_class}, the given one a {model_class}; "
            + _pass_model(stored)
        ]
    if "error" in model_args:  # its arguments could not be read
        return [f"model: {model_args['error']}"]
    # both sides completed alike: a model's own ``init_args`` may lack the arguments added
    # since (and then holds their defaults, as the stored session's model did)
    kept = _with_default_args(stored["model"]["args"])
    model_args = _with_default_args(model_args)
    if model_args != kept:
        diff = {
            k: (kept.get(k), model_args.get(k))
            for k in sorted(set(kept) | set(model_args))
            if kept.get(k) != model_args.get(k)
        }
        return [f"model args (stored, given): {diff}; " + _pass_model(stored, model_type)]
    return []


def _pass_model(stored: dict[str, Any], model_type: type | None = None) -> str:
    """What to pass for a session's model: its class, made with the arguments the session
    kept (or, for the library's own class, nothing: the directory rebuilds it); where
    ``model_type`` is that class, the arguments of its own the session did not record."""
    kept_class = stored["model"].get("class", "GaussianMixtureSet")
    unrecorded = []
    if model_type is not None and model_type.__name__ == kept_class:
        unrecorded = _unrecorded_args(model_type, stored["model"]["args"])
    return (
        f"pass model={kept_class}(...) made as the session made it, "
        f"{kept_class}(**{stored['model']['args']})"
        + (", or leave model= out" if kept_class == "GaussianMixtureSet" else "")
        + (
            f" (its own arguments ({', '.join(unrecorded)}) are not recorded: give the class "
            "an init_args dict of all its constructor arguments, which sessions record, "
            "and make it with the values the session had)"
            if unrecorded
            else ""
        )
    )


def _comparable(config: dict[str, Any]) -> dict[str, Any]:
    """What a resume compares of a custom strategy (or rule) config: its class by its name
    (its module reads __main__ in a script and a package's name when imported), its relabel
    and custom flags, and the dicts it holds of an inherited ``to_config`` and of its rule,
    those compared alike where custom and whole otherwise."""
    out: dict[str, Any] = {
        "type": str(config.get("type")).rpartition(".")[2],
        "custom": bool(config.get("custom")),
        "relabel": bool(config.get("relabel")),
    }
    for key in ("inherited", "rule"):
        value = config.get(key)
        if isinstance(value, dict):
            out[key] = _comparable(value) if value.get("custom") else value
    return out


def _as_stored_before(config: dict[str, Any]) -> dict[str, Any]:
    """A strategy config as sessions stored it before a subclass that keeps its parent's
    ``to_config`` (a strategy's, or its rule's) was stored as custom: the inherited dict in
    the subclass's place."""
    inherited = config.get("inherited")
    if config.get("custom") and isinstance(inherited, dict):
        return _as_stored_before(inherited)
    rule = config.get("rule")
    if isinstance(rule, dict) and rule.get("custom") and isinstance(rule.get("inherited"), dict):
        out = {**config, "rule": rule["inherited"]}
        if not out["rule"].get("custom"):  # ConfidentExecution's: custom for its rule's sake
            out.pop("custom", None)
        return out
    return config


# keys a shipped strategy's to_config gained after sessions were first stored, each with the
# value a session stored without it taught with (NoveltyGated's scores_from: 2026-11-28)
_ADDED_STRATEGY_KEYS: dict[str, dict[str, Any]] = {"NoveltyGated": {"scores_from": "all"}}


def _with_added_keys(config: dict[str, Any]) -> dict[str, Any]:
    """A shipped strategy's config (also as a custom subclass's ``"inherited"`` dict) with the
    keys :data:`_ADDED_STRATEGY_KEYS` names that it lacks, at the value it taught with."""
    out = dict(config)
    if not out.get("custom"):
        for key, value in _ADDED_STRATEGY_KEYS.get(str(out.get("type")), {}).items():
            out.setdefault(key, value)
    inherited = out.get("inherited")
    if isinstance(inherited, dict):
        out["inherited"] = _with_added_keys(inherited)
    return out


def stored_strategy(stored: dict[str, Any]) -> dict[str, Any]:
    """The strategy config of a session; a format-1 session (no ``strategy`` entry) used
    confident execution with its stored rule. A key a shipped strategy's ``to_config`` gained
    since the session was stored reads as the value it taught with (a NoveltyGated session
    stored without ``scores_from``: ``"all"``)."""
    if "strategy" in stored:
        return _with_added_keys(dict(stored["strategy"]))
    return {"type": "ConfidentExecution", "rule": stored["rule"], "relabel": False}


def repair_journal(run_dir: str | os.PathLike[str]) -> str:
    """Recover a session whose journal has damaged or missing lines, keeping every byte;
    returns a report of what was kept.

    The journal is first copied to ``steps.journal.damaged`` (``-1``, ``-2``... if taken).
    Then it is rewritten with its valid lines before the first damaged one and every later
    valid line that still gives a gap-free log: a step that continues the log, an outcome or
    a correction of a step the log has. The lines it drops (steps after a lost one) stay in the
    copy. Afterwards the session resumes as usual. Needs the writer lock (no writer running).
    A session whose ``-wal`` or journal is missing while ``writer.lock`` says it held steps the
    log lacks is refused first (:class:`CorruptSessionError`, nothing changed): no rewrite of
    the journal mends that.
    """
    run = Path(run_dir)
    load_config(run)
    _check_log_present(run)
    journal = run / JOURNAL_NAME
    committed = _read_committed(run)
    valid = [(kind, values) for _, kind, values in _scan_journal(journal).entries]
    # before the lock: an error changes nothing
    _check_committed(run, committed, *_logged(run, valid), stacklevel=2)
    lock = _acquire_lock(run)
    try:
        scan = _scan_journal(journal)
        known = _sqlite_steps(run)
        next_step = max(known) + 1 if known else 0
        kept, dropped = [], []
        for number, kind, values in scan.entries:
            step = values[-1] if kind == "f" else values[0]
            ok = step in known or (kind == "s" and step == next_step)
            if ok and kind == "s" and step == next_step:
                known.add(step)
                next_step += 1
            (kept if ok else dropped).append(number)
        if not scan.damaged and not dropped:
            return f"{journal}: no damaged or missing line; nothing to repair."
        data = journal.read_bytes()
        for i in range(1000):
            backup = run / (JOURNAL_NAME + ".damaged" + (f"-{i}" if i else ""))
            if not backup.exists():
                break
        try:
            with open(backup, "xb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
        except OSError as exc:
            raise _write_error(exc, backup, "copying the damaged journal", _FREE_SPACE) from exc
        lines = data.split(b"\n")
        tmp = journal.with_name(JOURNAL_NAME + ".tmp")
        try:
            write_durably(journal, b"".join(lines[n - 1] + b"\n" for n in kept), tmp)
        except OSError as exc:
            raise _write_error(exc, journal, "rewriting the journal", _FREE_SPACE) from exc
    finally:
        lock.close()
    damaged = ", ".join(f"line {n} (byte {o}: {w})" for n, o, w in scan.damaged)
    return (
        f"{journal}: "
        + (f"damaged {damaged}" if damaged else "a step is missing (a line was removed)")
        + f"; kept {len(kept)} valid lines, dropped "
        f"{len(dropped)} valid lines that depend on a "
        + ("damaged or missing one" if damaged else "missing one")
        + (f" (lines {dropped[0]}..{dropped[-1]})" if dropped else "")
        + f". Every original byte is in {backup}. Resume the session to continue."
    )
