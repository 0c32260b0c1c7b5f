"""The one-line text of an error, as every one-line message says its cause (no torchcbl
imports: the ground floor)."""

from __future__ import annotations


def one_line(exc: BaseException) -> str:
    """``exc``'s message on one line (each run of whitespace, newlines too, one space), or the
    name of its class where it has none (a bare ``raise RuntimeError``)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def counted(n: object, noun: str) -> str:
    """``n`` and ``noun``, plural unless ``n`` is 1: ``counted(1, "feature")`` is "1 feature",
    ``counted(3, "feature")`` "3 features" (a value that is not a number, e.g. None, is
    written as it is, the noun plural)."""
    return f"{n} {noun}{'' if n == 1 else 's'}"
