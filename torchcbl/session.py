"""Teaching sessions on disk: the run directory, its SQLite step log and model checkpoints.

Run directory layout (one directory per teaching session)::

    <run_dir>/
        config.json              what the session was started with: the TeachingConfig, the
                                 model's constructor arguments, the confidence rule, the env's
                                 id and spaces, the session seed and the log format version
        steps.sqlite             the step log: table ``steps``, one row per StepRecord;
                                 table ``corrections``, one row per CorrectionRecord (a
                                 label for an earlier step's observation, journalled and
                                 committed exactly like a demonstration)
        steps.sqlite-wal         SQLite's write-ahead log (present while a writer is open or
        steps.sqlite-shm         after a crash; never delete it by hand: it may hold commits)
        steps.journal            the steps not yet committed to steps.sqlite, one JSON line
                                 each (empty after a clean close; never delete it by hand)
        checkpoints/
            model-00000012.pt    ``{"n_demonstrations": 12, "state_dict": ...}`` of the model
                                 fitted on the first 12 demonstrations; one per refit, all
                                 kept (snapshots at stages come for free)

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
never acknowledged and is ignored: its action never ran.

Why a journal: a SQLite commit rewrites at least one whole page into the WAL (tens of
microseconds, plus periodic checkpoints), while a journal line is one small ``write()``; this
keeps the loop's own cost per step within the 200 us budget with every step durable.

Checkpoints are written to a temporary name and renamed, so a checkpoint file is complete or
absent. A checkpoint can lag behind the log (killed between the commit and the refit); then
:func:`load_model` refits deterministically on the logged demonstrations instead.
"""

from __future__ import annotations

import json
import os
import re
import sqlite3
import struct
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from torchcbl.errors import IncompatibleRunDirError
from torchcbl.records import CorrectionRecord, StepRecord, training_set

if TYPE_CHECKING:  # pragma: no cover
    from torchcbl.gmm import GaussianMixtureSet
    from torchcbl.policy import GreedyPolicy

__all__ = [
    "FORMAT",
    "IncompatibleRunDirError",
    "latest_checkpoint",
    "load_config",
    "load_corrections",
    "load_demonstrations",
    "load_labels",
    "load_model",
    "load_policy",
    "load_records",
    "restore_model",
]

FORMAT = "torchcbl.session/2"
#: Formats this version reads. Format 1 (before strategies) has no ``actor`` column and no
#: ``corrections`` table: its actor is derived (teacher when labelled, else agent), it has no
#: corrections, and resuming it upgrades the directory to format 2 in place.
READABLE_FORMATS = ("torchcbl.session/1", FORMAT)
CONFIG_NAME = "config.json"
LOG_NAME = "steps.sqlite"
JOURNAL_NAME = "steps.journal"
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


def _journal_line(kind: str, values: tuple[Any, ...]) -> bytes:
    """One journal line: ``["s", *row]`` (a step row, blobs as hex), ``["f", *finish]`` or
    ``["c", step, action]`` (a correction)."""
    if kind == "s":
        values = tuple(
            v.hex() if i in _BLOB_COLUMNS and v is not None else v for i, v in enumerate(values)
        )
    return (_JSON_LINE.encode([kind, *values]) + "\n").encode()


def _journal_entries(path: Path) -> list[tuple[str, tuple[Any, ...]]]:
    """The complete lines of a journal, in order; a torn last line is left out."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return []
    entries = []
    for line in data.split(b"\n")[:-1]:  # the part after the last newline is torn or empty
        try:
            kind, *values = json.loads(line)
        except (ValueError, TypeError):
            break  # nothing valid can follow a damaged line
        if kind == "s":
            values = [
                bytes.fromhex(v) if i in _BLOB_COLUMNS and v is not None else v
                for i, v in enumerate(values)
            ]
            if len(values) == len(_FORMAT1_COLUMNS):  # written by a format-1 writer
                values.append(_derived_actor(values[_COLUMNS.index("teacher_action")]))
        entries.append((kind, tuple(values)))
    return entries


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
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
    os.replace(tmp, path)


def load_config(run_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """The ``config.json`` of a run directory.

    Raises:
        IncompatibleRunDirError: no config, unreadable config, or another log format.
    """
    path = Path(run_dir) / CONFIG_NAME
    if not path.is_file():
        raise IncompatibleRunDirError(
            f"{run_dir!s} is not a teaching session directory: {CONFIG_NAME} is missing. "
            "Start a session with ConfidentTeacher(..., run_dir=...) first."
        )
    try:
        config = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise IncompatibleRunDirError(f"{path} is not readable JSON: {exc}") from exc
    if not isinstance(config, dict) or config.get("format") not in READABLE_FORMATS:
        got = config.get("format") if isinstance(config, dict) else type(config).__name__
        raise IncompatibleRunDirError(
            f"{path}: expected a session format among {READABLE_FORMATS}, got {got!r}. This "
            "directory was written by another version of torchcbl or by something else; read "
            "it with that version, or start a new session in a new run_dir."
        )
    return config


class SessionStore:
    """Writer and reader of one run directory's step log and checkpoints (private helper).

    Not thread-safe; one writer per run directory.
    """

    def __init__(self, run_dir: Path, *, commit_every: int = 32) -> None:
        self.run_dir = Path(run_dir)
        self.commit_every = commit_every
        self._uncommitted = 0
        (self.run_dir / CHECKPOINT_DIR).mkdir(parents=True, exist_ok=True)
        # isolation_level=None: we issue BEGIN / COMMIT ourselves, so batching is explicit.
        self._db = sqlite3.connect(self.run_dir / LOG_NAME, isolation_level=None)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        if _upgrade_format1(self._db):
            config = load_config(self.run_dir)
            config["format"] = FORMAT
            write_json_atomic(self.run_dir / CONFIG_NAME, config)
        self._db.executescript(_SCHEMA)
        self._in_tx = False
        journal = self.run_dir / JOURNAL_NAME
        self._replay(_journal_entries(journal))  # steps a killed writer left only there
        self._journal = os.open(journal, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        os.ftruncate(self._journal, 0)

    def _replay(self, entries: list[tuple[str, tuple[Any, ...]]]) -> None:
        if not entries:
            return
        self._begin()
        for kind, values in entries:
            sql = _REPLACE if kind == "s" else _FINISH if kind == "f" else _CORRECT
            self._db.execute(sql, values)
        self._db.execute("COMMIT")
        self._in_tx = False

    # -- creation ---------------------------------------------------------------------------

    @classmethod
    def create(cls, run_dir: str | os.PathLike[str], config: dict[str, Any]) -> SessionStore:
        path = Path(run_dir)
        if (path / CONFIG_NAME).exists() or (path / LOG_NAME).exists():
            raise IncompatibleRunDirError(
                f"{path} already holds a teaching session. Continue it with "
                "ConfidentTeacher.resume(run_dir, env, teacher) or choose a new run_dir."
            )
        path.mkdir(parents=True, exist_ok=True)
        write_json_atomic(path / CONFIG_NAME, config)
        return cls(path)

    @classmethod
    def open_for_resume(
        cls, run_dir: str | os.PathLike[str], *, commit_every: int = 32
    ) -> tuple[SessionStore, list[StepRecord], list[CorrectionRecord]]:
        """Open an existing session for writing: replay its journal, mark a demonstration
        whose outcome was never written as interrupted, upgrade a format-1 log, and return the
        store with every record and correction."""
        load_config(run_dir)
        if not (Path(run_dir) / LOG_NAME).is_file():
            raise IncompatibleRunDirError(
                f"{Path(run_dir) / LOG_NAME} is missing: not a teaching session directory."
            )
        store = cls(Path(run_dir), commit_every=commit_every)
        store.finalize_pending()
        records = store.records()
        return store, records, store.corrections(records)

    # -- writing ----------------------------------------------------------------------------

    def _begin(self) -> None:
        if not self._in_tx:
            self._db.execute("BEGIN")
            self._in_tx = True

    def commit(self) -> None:
        """Commit the batched rows to SQLite and empty the journal (they are in both)."""
        if self._in_tx:
            self._db.execute("COMMIT")
            self._in_tx = False
            os.ftruncate(self._journal, 0)
        self._uncommitted = 0

    def _write(self, kind: str, values: tuple[Any, ...], sql: str) -> None:
        os.write(self._journal, _journal_line(kind, values))  # durable from here on
        self._begin()
        self._db.execute(sql, values)
        self._uncommitted += 1
        if self._uncommitted >= self.commit_every:
            self.commit()

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
        self._write("s", self.row(provisional, pending=True), _INSERT)

    def finish(self, record: StepRecord) -> None:
        """Complete a logged demonstration with the env's answer."""
        values = (
            record.reward,
            int(record.terminated),
            int(record.truncated),
            _info_json(record.info),
            record.step,
        )
        self._write("f", values, _FINISH)

    def append(self, record: StepRecord) -> None:
        """Log an autonomous step."""
        self._write("s", self.row(record, pending=False), _INSERT)

    def correct(self, correction: CorrectionRecord) -> None:
        """Make a correction (a label for an earlier step's observation) durable."""
        self._write("c", (correction.step, correction.action), _CORRECT)

    def finalize_pending(self) -> int:
        """Mark demonstrations whose outcome was never written; returns how many there were."""
        self._begin()
        cur = self._db.execute(
            "UPDATE steps SET truncated = 1, terminated = 0, reward = NULL, "
            "info = ?, pending = 0 WHERE pending = 1",
            (json.dumps({"torchcbl_interrupted": True}),),
        )
        self.commit()
        return cur.rowcount

    def save_checkpoint(self, model: torch.nn.Module, n_demonstrations: int) -> Path:
        directory = self.run_dir / CHECKPOINT_DIR
        path = directory / f"model-{n_demonstrations:08d}.pt"
        tmp = directory / f".model-{n_demonstrations:08d}.pt.tmp"
        torch.save({"n_demonstrations": n_demonstrations, "state_dict": model.state_dict()}, tmp)
        os.replace(tmp, path)
        return path

    def close(self) -> None:
        try:
            self.commit()
        finally:
            self._db.close()
            os.close(self._journal)

    # -- reading ----------------------------------------------------------------------------

    def records(self) -> list[StepRecord]:
        return list(_read_records(self._db))

    def corrections(self, records: list[StepRecord]) -> list[CorrectionRecord]:
        return _read_corrections(self._db, None, records)


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
    db: sqlite3.Connection, journal: Path | None
) -> tuple[list[tuple[Any, ...]], dict[int, int]]:
    """Every step row of the log in step order, with a journal's lines applied on top, and the
    corrections ``{step: action}``.

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
            if step not in rows or rows[step][pending]:
                rows[step] = values
        elif step in rows and rows[step][pending]:
            row = list(rows[step])
            for name, v in zip(FINISH_FIELDS, values[:4], strict=True):
                row[at[name]] = v
            row[pending] = 0
            rows[step] = tuple(row)
    return [rows[k] for k in sorted(rows)], corrections


def _read_records(db: sqlite3.Connection, journal: Path | None = None) -> Iterable[StepRecord]:
    for row in _rows(db, journal)[0]:
        yield _record_from_row(row)


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


def _read_corrections(
    db: sqlite3.Connection, journal: Path | None, records: list[StepRecord]
) -> list[CorrectionRecord]:
    return _corrections_of(records, _rows(db, journal)[1])


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


def _open_readonly(run_dir: str | os.PathLike[str]) -> sqlite3.Connection:
    path = Path(run_dir) / LOG_NAME
    if not path.is_file():
        raise IncompatibleRunDirError(f"{path} is missing: not a teaching session directory.")
    # Not mode=ro: reading a WAL database left by a killed writer may need to recover it.
    return sqlite3.connect(path)


def load_records(run_dir: str | os.PathLike[str]) -> list[StepRecord]:
    """All step records of a run directory, in step order (safe while a writer runs)."""
    load_config(run_dir)
    db = _open_readonly(run_dir)
    try:
        return list(_read_records(db, Path(run_dir) / JOURNAL_NAME))
    finally:
        db.close()


def load_corrections(run_dir: str | os.PathLike[str]) -> list[CorrectionRecord]:
    """Every correction of a run directory (labels for earlier steps), in step order."""
    load_config(run_dir)
    db = _open_readonly(run_dir)
    try:
        rows, corrections = _rows(db, Path(run_dir) / JOURNAL_NAME)
        return _corrections_of([_record_from_row(r) for r in rows], corrections)
    finally:
        db.close()


def _relabels(config: dict[str, Any]) -> bool:
    return bool(config.get("strategy", {}).get("relabel", False))


def load_labels(run_dir: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """Every label of the session in arrival order (demonstrations and corrections):
    observations [L, D] float64 and actions [L] int64, before any relabelling."""
    load_config(run_dir)
    db = _open_readonly(run_dir)
    try:
        rows, corrections = _rows(db, Path(run_dir) / JOURNAL_NAME)
    finally:
        db.close()
    records = [_record_from_row(r) for r in rows]
    xs, ys = label_sequence(records, _corrections_of(records, corrections))
    if not ys:
        return np.zeros((0, 0), dtype=np.float64), np.zeros(0, dtype=np.int64)
    return np.stack(xs), np.asarray(ys, dtype=np.int64)


def load_demonstrations(run_dir: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """The session's training set: observations [M, D] float64 and labels [M] int64.

    Every label in arrival order; with a strategy that relabels (``"relabel": true`` in the
    stored strategy, e.g. Confidence-Based Autonomy), a label for an observation already stored
    replaces that point's label instead of adding a point.
    """
    config = load_config(run_dir)
    x, y = load_labels(run_dir)
    if not len(y) or not _relabels(config):
        return x, y
    return training_set(list(x), y.tolist(), relabel=True)


def latest_checkpoint(
    run_dir: str | os.PathLike[str], *, at_most: int | None = None
) -> tuple[int, Path] | None:
    """(n_demonstrations, path) of the newest checkpoint (with at most ``at_most`` demos)."""
    directory = Path(run_dir) / CHECKPOINT_DIR
    best: tuple[int, Path] | None = None
    if directory.is_dir():
        for entry in directory.iterdir():
            m = _CKPT_RE.match(entry.name)
            if m is None:
                continue
            n = int(m.group(1))
            if (at_most is None or n <= at_most) and (best is None or n > best[0]):
                best = (n, entry)
    return best


def build_model(config: dict[str, Any]) -> GaussianMixtureSet:
    """A fresh, unfitted model built from a session config's ``model`` entry."""
    from torchcbl.gmm import GaussianMixtureSet

    spec = config.get("model", {})
    if spec.get("class") != "GaussianMixtureSet":
        raise IncompatibleRunDirError(
            f"the session's model class is {spec.get('class')!r}; only GaussianMixtureSet "
            "can be rebuilt from a run directory."
        )
    return GaussianMixtureSet(**spec["args"])


def fit_count(n_demonstrations: int, max_new: int) -> int:
    """Demonstrations the loop's model stands on after ``n_demonstrations``, when every refit
    was the loop's own (one each time ``max_new`` new demonstrations have accumulated)."""
    return (n_demonstrations // max_new) * max_new


def fitted_count(run_dir: str | os.PathLike[str], n_demonstrations: int, max_new: int) -> int:
    """Demonstrations the live model stood on when ``n_demonstrations`` were logged.

    The last refit the directory knows of is its newest checkpoint with at most that many
    demonstrations (a refit may also be asked for by hand, :meth:`ConfidentTeacher.refit`, at
    any count); from there the loop refits every ``max_new`` demonstrations. A checkpoint
    missing because the process died before writing it is covered by the same schedule.
    """
    ckpt = latest_checkpoint(run_dir, at_most=n_demonstrations)
    last = 0 if ckpt is None else ckpt[0]
    return last + fit_count(n_demonstrations - last, max_new)


def restore_model(
    run_dir: str | os.PathLike[str],
    model: torch.nn.Module,
    xs: list[np.ndarray],
    ys: list[int],
    *,
    max_new: int,
    relabel: bool,
    store: SessionStore | None = None,
) -> int:
    """Bring ``model`` to where the session's live model stood after the labels ``xs, ys``:
    THE one "load the checkpoint or refit" path (resume and :func:`load_model` both use it).

    The model stood on the first ``k = fitted_count(run_dir, len(ys), max_new)`` labels. Its
    checkpoint is loaded when present; otherwise (the process died between logging and saving)
    the model is refitted deterministically on the training set of those labels, and with
    ``store`` the missing checkpoint is written. Returns ``k``.
    """
    k = fitted_count(run_dir, len(ys), max_new)
    ckpt = latest_checkpoint(run_dir, at_most=k)
    if ckpt is not None and ckpt[0] == k:
        model.load_state_dict(torch.load(ckpt[1], weights_only=True)["state_dict"])
    elif k > 0:
        x, y = training_set(xs[:k], ys[:k], relabel=relabel)
        model.fit(x, y)
        if store is not None:
            store.save_checkpoint(model, k)
    return k


def load_model(
    run_dir: str | os.PathLike[str], *, n_demonstrations: int | None = None
) -> GaussianMixtureSet:
    """The session's model as the loop had it, from its checkpoint or refitted from the log.

    Args:
        run_dir: a session directory.
        n_demonstrations: rebuild the model as it stood when this many labels (demonstrations
            and corrections) were logged (default: all of them).

    Returns:
        A GaussianMixtureSet fitted on the first ``fitted_count(run_dir, n, max_new)`` labels
        (unfitted when that is 0 and the session did not start from a fitted model). If the
        matching checkpoint is missing (the process was killed between logging and saving),
        the model is refitted deterministically on the logged labels.
    """
    config = load_config(run_dir)
    x, y = load_labels(run_dir)
    n = len(y) if n_demonstrations is None else min(int(n_demonstrations), len(y))
    model = build_model(config)
    restore_model(
        run_dir,
        model,
        list(x[:n]),
        y[:n].tolist(),
        max_new=int(config["teaching"]["max_new"]),
        relabel=_relabels(config),
    )
    return model


def load_policy(run_dir: str | os.PathLike[str]) -> GreedyPolicy:
    """The latest learned policy of a session directory, as a callable obs -> action."""
    from torchcbl.policy import GreedyPolicy

    return GreedyPolicy(load_model(run_dir))


def resume_problems(
    stored: dict[str, Any],
    *,
    n_features: int,
    n_actions: int,
    env_id: str | None,
    learning: tuple[dict[str, Any], dict[str, Any]] | None,
    model_args: dict[str, Any] | None,
    strategy: dict[str, Any] | None,
) -> list[str]:
    """What keeps a session from resuming with the given env, configuration, model and
    strategy (empty list: nothing). ``learning`` is (stored, given) learning fields;
    ``model_args`` / ``strategy`` None means "rebuilt from the directory", a strategy config
    with ``"custom": true`` is not compared."""
    problems: list[str] = []
    senv = stored["env"]
    if (senv["n_features"], senv["n_actions"]) != (n_features, n_actions):
        problems.append(
            f"env: the session has {senv['n_features']} features and {senv['n_actions']} "
            f"actions, the given env {n_features} and {n_actions}"
        )
    if senv.get("id") and env_id and senv["id"] != env_id:
        problems.append(f"env id: the session used {senv['id']!r}, got {env_id!r}")
    if learning is not None and learning[0] != learning[1]:
        diff = {
            k: (v, learning[1].get(k)) for k, v in learning[0].items() if learning[1].get(k) != v
        }
        problems.append(f"config (stored, given): {diff}; only the stop fields may change")
    if model_args is not None and model_args != stored["model"]["args"]:
        problems.append(f"model args: stored {stored['model']['args']}, given {model_args}")
    if strategy is not None and not strategy.get("custom"):
        want = stored_strategy(stored)
        if strategy != want:
            problems.append(f"strategy: stored {want}, given {strategy}")
    return problems


def stored_strategy(stored: dict[str, Any]) -> dict[str, Any]:
    """The strategy config of a session; a format-1 session (no ``strategy`` entry) used
    confident execution with its stored rule."""
    if "strategy" in stored:
        return dict(stored["strategy"])
    return {"type": "ConfidentExecution", "rule": stored["rule"], "relabel": False}
