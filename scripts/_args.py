"""argparse types for the scripts' number flags: a malformed value is argparse's usage error
(exit code 2) before anything runs, not a traceback in the middle of a table."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def _whole(text: str) -> int | None:
    try:
        return int(text)
    except ValueError:
        return None


def int_at_least(minimum: int) -> Callable[[str], int]:
    """A whole number >= ``minimum``."""

    def parse(text: str) -> int:
        value = _whole(text)
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(f"expected a whole number >= {minimum}, got {text!r}")
        return value

    return parse


def ints_at_least(minimum: int) -> Callable[[str], list[int]]:
    """Comma-separated whole numbers >= ``minimum`` (at least one)."""

    def parse(text: str) -> list[int]:
        values = [_whole(t) for t in text.split(",")]
        if any(v is None or v < minimum for v in values):
            raise argparse.ArgumentTypeError(
                f"expected comma-separated whole numbers >= {minimum}, got {text!r}"
            )
        return values  # type: ignore[return-value]

    return parse


def numbers_at_least_zero(text: str) -> list[float]:
    """Comma-separated finite numbers >= 0 (at least one)."""
    try:
        values = [float(t) for t in text.split(",")]
    except ValueError:
        values = [-1.0]
    if not all(math.isfinite(v) and v >= 0 for v in values):
        raise argparse.ArgumentTypeError(
            f"expected comma-separated finite numbers >= 0 (e.g. 1e-3,0.01), got {text!r}"
        )
    return values


def seeds(text: str) -> list[int]:
    """Seeds as a range, ``0-9``, or a list, ``0,3,5`` (whole numbers >= 0)."""
    lo, dash, hi = text.partition("-")
    if dash:
        a, b = _whole(lo), _whole(hi)
        if a is not None and b is not None and 0 <= a <= b:
            return list(range(a, b + 1))
    else:
        values = [_whole(t) for t in text.split(",")]
        if all(v is not None and v >= 0 for v in values):
            return values  # type: ignore[return-value]
    raise argparse.ArgumentTypeError(
        f"expected seeds as a range, e.g. 0-9, or a list, e.g. 0,3,5, got {text!r}"
    )
