"""How many checkpoints a teaching session keeps (``ConfidentTeacher(keep_checkpoints=)``): the
default and what a valid count is, in one place for the teacher, the session's reader, the
benchmark and the CLI.

Imports neither torch (``torchcbl.benchmark`` and the CLI import it without) nor, until a
count is checked, numpy (``torchcbl --help`` shows the default).
"""

from __future__ import annotations

from typing import Any

#: checkpoints a session keeps besides checkpoint 0 (``ConfidentTeacher(keep_checkpoints=)``)
DEFAULT_KEEP_CHECKPOINTS = 3


def is_keep_count(keep: Any) -> bool:
    """Whether ``keep`` is a number of checkpoints to keep: an int >= 1 (a Python or numpy
    one), not a bool. Each caller says in its own words what it expected (None, for every
    checkpoint, is the caller's to allow)."""
    from torchcbl.records import _is_int  # (numpy: only when a count is checked)

    return _is_int(keep) and keep >= 1
