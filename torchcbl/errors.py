"""The errors the teaching loop and the session store raise (no other torchcbl imports)."""

from __future__ import annotations

__all__ = ["EnvError", "IncompatibleRunDirError", "TeacherError", "TeachingInterrupted"]


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
