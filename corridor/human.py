"""Teaching the corridor robot from the terminal: a text view of its sensors and its keys.

The robot's observation is float32 ``[left, front, right]``: the distance in metres to the
nearest wall on each side and ahead (paper Section 5.1). :func:`describe` draws the three
readings as bars; :func:`make_teacher` builds a :class:`torchcbl.human.TerminalTeacher` with the
corridor's four actions on the arrow keys (or w/a/d/s).

This module only knows the observation layout; it does not import the env or the simulator.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from torchcbl.human import TerminalTeacher

__all__ = ["ACTION_NAMES", "KEYS", "describe", "make_teacher"]

#: The corridor's actions, in action order.
ACTION_NAMES: tuple[str, ...] = ("forward", "turn left", "turn right", "u-turn")
#: Key map: arrows or w/a/d/s.
KEYS: dict[str, int] = {
    "up": 0,
    "w": 0,
    "left": 1,
    "a": 1,
    "right": 2,
    "d": 2,
    "down": 3,
    "s": 3,
}
_SENSORS = ("left", "front", "right")


def _check_max_range(max_range: Any) -> None:
    """Refuse a full-bar distance that is not a finite number of metres > 0."""
    if (
        isinstance(max_range, (bool, np.bool_))
        or not isinstance(max_range, (int, float, np.integer, np.floating))
        or not (math.isfinite(max_range) and max_range > 0)
    ):
        raise ValueError(f"max_range: expected metres > 0 (the sensors' range), got {max_range!r}")


def describe(
    observation: np.ndarray, info: dict | None = None, *, max_range: float = 1.5, width: int = 30
) -> str:
    """The robot's three range readings as labelled bars.

    Args:
        observation: ``[left, front, right]`` distances in metres.
        info: the env's info dict; a truthy ``"contact"`` entry is shown as a warning.
        max_range: the distance drawn as a full bar (the sensor range, 1.5 m in the default
            world); readings at or beyond it are marked ``max``.
        width: bar width in characters.

    Raises:
        ValueError: if the observation is not three finite, non-negative distances.
    """
    obs = np.asarray(observation, dtype=np.float64)
    if obs.shape != (3,):
        raise ValueError(f"a corridor observation is [left, front, right], got shape {obs.shape}")
    if not np.all(np.isfinite(obs)) or np.any(obs < 0):
        raise ValueError(f"sensor distances must be finite and >= 0, got {obs.tolist()}")
    _check_max_range(max_range)
    if isinstance(width, (bool, np.bool_)) or not isinstance(width, (int, np.integer)) or width < 1:
        raise ValueError(f"width: expected an int >= 1 (characters), got {width!r}")
    lines = [f"robot sensors (distance to the nearest wall; full bar = {max_range:g} m)"]
    for name, dist in zip(_SENSORS, obs, strict=True):
        filled = int(round(min(dist, max_range) / max_range * width))
        bar = "#" * filled + " " * (width - filled)
        mark = "  max" if dist >= max_range else ""
        lines.append(f"  {name:<5} {dist:5.2f} m |{bar}|{mark}")
    if info and info.get("contact"):
        lines.append("  *** WALL CONTACT ***")
    return "\n".join(lines)


def make_teacher(*, max_range: float = 1.5, **kwargs: Any) -> TerminalTeacher:
    """A terminal teacher for the corridor robot.

    Args:
        max_range: passed to :func:`describe`.
        **kwargs: passed to :class:`~torchcbl.human.TerminalTeacher` (``input``, ``output``,
            ``status``, ``title``, ...); ``keys`` and ``action_names`` may be overridden.

    Raises:
        ValueError: if ``max_range`` is not metres > 0 (here, not at the first question).
    """
    _check_max_range(max_range)  # before a session starts, not at its first question
    kwargs.setdefault("keys", KEYS)
    kwargs.setdefault("action_names", ACTION_NAMES)
    kwargs.setdefault("describe", functools.partial(describe, max_range=max_range))
    kwargs.setdefault("title", "Teach the corridor robot")
    return TerminalTeacher(**kwargs)
