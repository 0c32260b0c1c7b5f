"""Reading a JSON file a user wrote (a corridor map, a traffic scenario): its text and its data,
each refusal a ValueError in the caller's words.

Torch-free and domain-free: the domains' loaders (``corridor.maps.load_map``,
``sumo_scenarios.scenarios.load_scenario``) import it, never the reverse.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any


def read_text(
    path: Path, *, not_text: Callable[[str], str], unreadable: Callable[[str], str]
) -> str:
    """The text of the file at ``path``, read as UTF-8 (as JSON is), a leading byte-order mark
    (Notepad's) dropped: it is no part of the JSON.

    Args:
        path: the file.
        not_text: the message where the file is not UTF-8 text (e.g. a PNG given for the
            JSON), given why (``"invalid start byte at byte 0"``).
        unreadable: the message where the file cannot be read, given the system's reason
            (``"Permission denied"``).

    Raises:
        ValueError: the file is not UTF-8 text or cannot be read (the caller's message).
    """
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(not_text(f"{exc.reason} at byte {exc.start}")) from None
    except OSError as exc:
        raise ValueError(unreadable(str(exc.strerror or exc))) from None


def loads(text: str, *, not_json: Callable[[str], str], given_twice: Callable[[str], str]) -> Any:
    """The data of a JSON text, refused where one object gives a key twice (``json.loads``
    would keep the last silently).

    Args:
        text: the JSON text.
        not_json: the message where ``text`` is not JSON, given the parser's words
            (``"Expecting value: line 1 column 1 (char 0)"``).
        given_twice: the message where a key is given twice, given the key.

    Raises:
        ValueError: ``text`` is not JSON or gives a key twice (the caller's message).
    """
    try:
        return json.loads(text, object_pairs_hook=_once)
    except json.JSONDecodeError as exc:
        raise ValueError(not_json(str(exc))) from None
    except _GivenTwice as exc:
        raise ValueError(given_twice(exc.args[0])) from None


class _GivenTwice(Exception):
    """A key written twice in one JSON object."""


def _once(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's dict (``json.loads``'s ``object_pairs_hook``); :class:`_GivenTwice` if
    a key is written twice."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _GivenTwice(key)
        out[key] = value
    return out
