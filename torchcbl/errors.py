"""The errors the teaching loop and the session store raise (no other torchcbl imports)."""

from __future__ import annotations

__all__ = [
    "CorruptSessionError",
    "EnvError",
    "IncompatibleRunDirError",
    "SessionLockedError",
    "SessionWriteError",
    "TeacherError",
    "TeachingInterrupted",
]


class TeacherError(RuntimeError):
    """The teacher raised or gave an invalid action; nothing was recorded for that step."""


class TeachingInterrupted(Exception):
    """The teacher asked to stop teaching (a person pressed 'q' or Ctrl-C, input closed).

    A teacher raises it from inside its call; the loop lets it through unwrapped, after
    committing what was recorded: every demonstration before the interrupted decision is kept,
    the decision being asked about is not answered, and the session can be resumed.
    """


class EnvError(RuntimeError):
    """The environment raised or returned a non-finite / malformed observation or reward."""


class IncompatibleRunDirError(ValueError):
    """A run directory cannot be used with the given env, model, strategy or configuration,
    or was written in a log format this version of torchcbl cannot read."""


class CorruptSessionError(IncompatibleRunDirError):
    """A file of a run directory is damaged (a journal line that fails its checksum, an
    unreadable SQLite log, a config without a required key). The message names the file, the
    place and how to recover; torchcbl never deletes the damaged bytes."""


class SessionLockedError(IncompatibleRunDirError):
    """Another writer (process or ConfidentTeacher) has the run directory open. One writer
    per session; the lock is released when that writer closes or dies (even by SIGKILL).

    Attributes:
        holder: the holder as ``writer.lock`` names it ("process PID on HOST"), or
            "unknown".
    """

    holder: str = "unknown"


class SessionWriteError(OSError):
    """Writing the run directory failed (disk full, I/O error, permissions). The session in
    memory was kept equal to what is on disk: the step being written is not part of the
    session (or, after its action ran, was cut as interrupted); free space and call ``run()``
    again, or resume the directory later."""
