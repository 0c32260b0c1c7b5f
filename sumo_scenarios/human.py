"""Teaching the driving agent from the terminal: an ASCII view of the road and its keys.

The observation is float32 ``[d_lane1, d_lane2, d_lane3, ego_lane]`` (paper Section 5.2): the
signed distance in metres to the nearest car in each normal lane (ahead positive, clipped to
[-25, 25]) and the ego's lane, 0 = right shoulder, 1-3 normal lanes, 4 = left shoulder.
:func:`describe` draws the road top-down with ahead up and the left shoulder on the left, the
ego (``[E]``) in its lane and the nearest car in each normal lane (``[#]``) at its distance.
:func:`make_teacher` builds a :class:`torchcbl.human.TerminalTeacher` for the three actions.

This module only knows the observation layout; it imports neither the env nor SUMO.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from torchcbl.human import TerminalTeacher

__all__ = ["ACTION_NAMES", "KEYS", "describe", "make_teacher"]

#: The driving actions, in action order.
ACTION_NAMES: tuple[str, ...] = ("stay", "shift left", "shift right")
#: Key map: w/up/space stay, a/left shift left, d/right shift right.
KEYS: dict[str, int] = {"w": 0, "up": 0, "space": 0, "a": 1, "left": 1, "d": 2, "right": 2}

_N_LANES = 5
_HEADERS = ("R-sh", "right", "middle", "left", "L-sh")  # by lane index
_RANGE = 25.0
_CELL = 8


def _center(text: str) -> str:
    return text.center(_CELL)


def _check_metres_per_row(value: Any) -> None:
    """Refuse a row height that is not metres in (0, 25] (a text or None was a TypeError of a
    comparison, True a 1 m row)."""
    number = isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_
    )
    if not number or not 0 < value <= _RANGE:
        raise ValueError(f"metres_per_row must be metres in (0, {_RANGE:g}], got {value!r}")


def describe(
    observation: np.ndarray, info: dict | None = None, *, metres_per_row: float = 2.5
) -> str:
    """A top-down ASCII view of the road around the ego.

    Rows run from 25 m ahead (top) to 25 m behind (bottom), each labelled with its distance;
    columns are the five lanes, left shoulder first. A car whose clipped distance is +-25 m is
    out of range and is not drawn. A car drawn on the ego's own cell is shown as ``[X]``.

    Args:
        observation: ``[d_lane1, d_lane2, d_lane3, ego_lane]``.
        info: the env's info dict; a truthy ``"contact"`` entry is shown as a warning.
        metres_per_row: the distance one row stands for.

    Raises:
        ValueError: if the observation does not have that layout.
    """
    obs = np.asarray(observation, dtype=np.float64)
    if obs.shape != (4,):
        raise ValueError(
            f"a driving observation is [d_lane1, d_lane2, d_lane3, ego_lane], got shape {obs.shape}"
        )
    if not np.all(np.isfinite(obs)):
        raise ValueError(f"observation must be finite, got {obs.tolist()}")
    ego = int(round(obs[3]))
    if abs(obs[3] - ego) > 1e-3 or not 0 <= ego < _N_LANES:
        raise ValueError(f"ego lane must be an integer 0..4, got {obs[3]}")
    _check_metres_per_row(metres_per_row)

    half = int(round(_RANGE / metres_per_row))
    n_rows = 2 * half + 1
    grid = [[""] * _N_LANES for _ in range(n_rows)]  # row 0 = farthest ahead
    nearest = []
    for lane in (1, 2, 3):
        dist = float(np.clip(obs[lane - 1], -_RANGE, _RANGE))
        if abs(dist) >= _RANGE - 1e-6:
            nearest.append(f"{_HEADERS[lane]} none")
            continue
        nearest.append(f"{_HEADERS[lane]} {dist:+.1f} m")
        grid[half - int(round(dist / metres_per_row))][lane] = "[#]"
    grid[half][ego] = "[X]" if grid[half][ego] else "[E]"

    lines = []
    if info and info.get("contact"):
        lines.append("*** CONTACT: the ego is touching another car ***")
    lines.append(f"road ahead is up; one row = {metres_per_row:g} m; [E] you, [#] nearest car")
    lines.append(" " * 8 + " " + " ".join(_center(_HEADERS[lane]) for lane in range(4, -1, -1)))
    for row in range(n_rows):
        dist = (half - row) * metres_per_row
        cells = ":".join(_center(grid[row][lane]) for lane in range(4, -1, -1))
        lines.append(f"{dist:+7.1f}m|{cells}|")
    lines.append(f"lane: {_HEADERS[ego]} ({ego}); nearest car: " + ", ".join(nearest))
    return "\n".join(lines)


def make_teacher(*, metres_per_row: float = 2.5, **kwargs: Any) -> TerminalTeacher:
    """A terminal teacher for the driving agent.

    Args:
        metres_per_row: passed to :func:`describe`.
        **kwargs: passed to :class:`~torchcbl.human.TerminalTeacher` (``input``, ``output``,
            ``status``, ``title``, ...); ``keys`` and ``action_names`` may be overridden.
    """
    _check_metres_per_row(metres_per_row)  # before a session starts, not at its first question
    kwargs.setdefault("keys", KEYS)
    kwargs.setdefault("action_names", ACTION_NAMES)
    kwargs.setdefault("describe", functools.partial(describe, metres_per_row=metres_per_row))
    kwargs.setdefault("title", "Teach the driver")
    return TerminalTeacher(**kwargs)
