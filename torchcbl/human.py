"""A human teacher at the terminal: shows the situation, reads one key per decision.

:class:`TerminalTeacher` is a teacher in the sense of ``docs/architecture.md``: it is called as
``teacher(observation, info) -> action``. Each call draws the domain's text view of the
situation (a ``describe(observation, info) -> str`` function the domain supplies), a status line
the caller keeps up to date (demonstrations so far, autonomy, ...), and a prompt listing the
keys, then waits for the person to press one key. On a terminal too short for all of it (the
driving view is about 30 lines, a terminal's usual height 24), whose top then scrolls away, a
line above the keys says how many lines are cut off and to enlarge the window; on one narrower
than the view (the driving view is about 70 columns), whose lines then wrap, a line says so.

On a terminal the key is read without Enter: the terminal is switched to a non-canonical,
no-echo mode for the duration of the read and its settings are always restored afterwards,
also when the read is interrupted. Keys typed before a request is shown (while the agent acts on
its own) are dropped, not taken as its answer; a quit key or Ctrl-D among them still quits.
(Their timing is lost: Esc and a key typed ahead read as one Alt-key, so Esc then q typed ahead
does not quit; q at the request does.) A caller that calls
:meth:`TerminalTeacher.check_quit` between requests (``torchcbl teach`` does after each step)
stops at once on a quit key or Ctrl-D typed while the agent acts on its own, not at the next
request. When the input is not a terminal (a pipe, a file), one line is read per decision
instead; a line may hold a key (``w``), a key name (``up``), an action name (``forward``) or an
action number; its end (a closed pipe, ``/dev/null``) is read at the next request.

In a notebook (a Jupyter kernel, whose own stdin is a closed pipe) each key is typed into the
notebook's input box, the kernel's ``input()``, one line per decision as from a pipe.

Pressing ``q`` (or Ctrl-C, or Ctrl-D, the end of input, at a request or while the agent acts on
its own, or closing the input) raises :class:`TeachingInterrupted`, so a teaching session can
stop cleanly; the demonstrations it already recorded are on disk.

This module is domain-free; the views live beside each domain (``corridor.human``,
``sumo_scenarios.human``).
"""

from __future__ import annotations

import builtins
import contextlib
import os
import selectors
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import IO, Any

import numpy as np

from torchcbl.errors import TeachingInterrupted

try:  # POSIX only; elsewhere the teacher always reads lines.
    import termios
except ImportError:  # pragma: no cover - exercised on Windows only
    termios = None  # type: ignore[assignment]

__all__ = ["KEY_NAMES", "TeachingInterrupted", "TerminalTeacher"]

#: Names accepted in a key map for keys that are not printable characters.
KEY_NAMES: dict[str, str] = {
    "up": "\x1b[A",
    "down": "\x1b[B",
    "right": "\x1b[C",
    "left": "\x1b[D",
    "space": " ",
    "enter": "\r",
    "tab": "\t",
}
_LABELS = {seq: name for name, seq in KEY_NAMES.items()}
_CTRL_C = "\x03"
_CTRL_D = "\x04"
_ESC = "\x1b"
# Seconds to wait for the rest of an escape sequence after ESC (arrow keys send 3 bytes).
_ESCAPE_WAIT = 0.05
# how often a wait for a key wakes, so that a signal's Python handler runs (seconds)
_SIGNAL_WAIT = 0.2
_CLEAR_SCREEN = "\x1b[H\x1b[2J"
# F1-F4 after ESC, as read (ESC O P is read as ESC [ P), for naming a key that is no action.
_FUNCTION_KEYS = {"[P": "F1", "[Q": "F2", "[R": "F3", "[S": "F4"}


def _normalize_key(key: str) -> str:
    """Map a key-map entry (a character, a key name, or an escape sequence) to what is read."""
    if not isinstance(key, str) or not key:
        raise ValueError(f"a key must be a non-empty string, got {key!r}")
    lowered = key.lower()
    if lowered in KEY_NAMES:
        return KEY_NAMES[lowered]
    if key == "\n":
        return "\r"
    if key.startswith(_ESC + "O") and len(key) == 3:  # application cursor mode arrows
        return _ESC + "[" + key[2]
    if len(key) == 1 or key.startswith(_ESC):
        return key
    raise ValueError(
        f"unknown key {key!r}: use a single character, an escape sequence, or one of "
        f"{sorted(KEY_NAMES)}"
    )


def _label(key: str) -> str:
    """A short printable name for a key as read, as a keyboard names it: ``up``, ``Ctrl-Z``,
    ``Esc``, ``Alt-x``, ``F2``; another escape sequence as ``Esc`` and its printable rest."""
    if key in _LABELS:
        return _LABELS[key]
    if key == "\x7f":
        return "Backspace"
    if len(key) == 1 and ord(key) < 0x20 and key != _ESC:  # Ctrl-A is 1, ... Ctrl-_ is 31
        return f"Ctrl-{chr(ord(key) + 0x40)}"
    if key == _ESC:
        return "Esc"
    if key.startswith(_ESC):
        rest = key[1:]
        if len(rest) == 1 and rest.isprintable():
            return f"Alt-{rest}"
        if rest in _FUNCTION_KEYS:
            return _FUNCTION_KEYS[rest]
        return "Esc " + (rest if rest.isprintable() else repr(rest)[1:-1])
    if len(key) == 1 and not key.isprintable():
        return repr(key)[1:-1]
    return key


def _key_length(data: bytes) -> int | None:
    """How many bytes of ``data`` (not empty) the first key takes, as a terminal sends keys: an
    escape sequence (ESC [ ... final byte, ESC O x, ESC and one byte for Alt-x), a UTF-8
    character, or one byte. None when ``data`` ends inside the key and more bytes are needed."""
    if data[0] == 0x1B:
        if len(data) == 1:
            return None  # a lone ESC, or the start of a sequence
        if data[1:2] not in (b"[", b"O"):
            return 2
        for end in range(2, len(data)):
            if 0x40 <= data[end] <= 0x7E:  # final byte of a CSI sequence
                return end + 1
        return None
    if data[0] >= 0xC0:  # lead byte of a multi-byte UTF-8 character
        size = 2 if data[0] < 0xE0 else 3 if data[0] < 0xF0 else 4
        return size if len(data) >= size else None
    return 1


def _decode_key(data: bytes) -> str:
    """The key for the bytes of one key, in the form the key map uses."""
    key = data.decode("utf-8", errors="replace")
    if key == "\n":
        key = "\r"
    if key.startswith(_ESC + "O") and len(key) == 3:  # application mode, as ESC [ x
        key = _ESC + "[" + key[2]
    return key


def _split_keys(data: bytes) -> tuple[list[str], bytes]:
    """The keys in ``data``, and the bytes at its end that start a key cut off there."""
    keys = []
    while data:
        length = _key_length(data)
        if length is None:
            break
        keys.append(_decode_key(data[:length]))
        data = data[length:]
    return keys, data


def _lines_typed(fd: int, waits: selectors.BaseSelector, mode: list[Any]) -> bytes:
    """The lines typed on the terminal ``fd`` while it was in line mode (``mode``, its settings,
    canonical), read without waiting, before it leaves that mode. The end of input typed among
    them (Ctrl-D: an empty line, or one cut short, without its newline) raises
    :class:`TeachingInterrupted`, as Ctrl-D at a request does: leaving line mode would turn it
    into a NUL byte, a key like any other; the keys typed after it are then discarded, as
    those after a quit key are read and dropped. Nothing is read from a terminal not in line
    mode."""
    if not mode[3] & termios.ICANON:
        return b""
    cc = mode[6]
    ends = {b"\n"} | {c for c in (cc[termios.VEOL], cc[termios.VEOL2]) if c not in (b"\0", 0)}
    lines = b""
    while waits.select(0):  # in line mode: a whole line, or the end of input, is there
        try:
            line = os.read(fd, 4096)  # one line (a terminal's lines are at most 4095 bytes)
        except OSError as exc:  # EIO once the other end of a pseudo-terminal is gone
            raise TeachingInterrupted("teaching input closed") from exc
        if not line or line[-1:] not in ends:
            try:  # the keys typed after it answer nothing: not left for the shell to run
                termios.tcflush(fd, termios.TCIFLUSH)
            except (termios.error, OSError):
                pass
            eof = cc[termios.VEOF]
            name = _label(eof.decode("latin-1")) if isinstance(eof, bytes) else "Ctrl-D"
            raise TeachingInterrupted(f"teaching stopped by the person ({name})")
        lines += line
    return lines


def _key_waits(fd: int) -> selectors.BaseSelector:
    """A selector waiting for ``fd`` to be readable: the system's best (epoll, kqueue), not
    select.select(), which refuses a descriptor >= 1024 (FD_SETSIZE). Where that one refuses
    the device (kqueue does some terminals, /dev/tty among them), select() (below 1024)."""
    waits: selectors.BaseSelector = selectors.DefaultSelector()
    try:
        waits.register(fd, selectors.EVENT_READ)
    except (OSError, ValueError):
        waits.close()
        waits = selectors.SelectSelector()  # holds no OS resource to leak if this raises
        waits.register(fd, selectors.EVENT_READ)
    return waits


@contextlib.contextmanager
def _restored_before_a_fatal_signal(fd: int, saved: list[Any]) -> Iterator[None]:
    """While in place, SIGTERM and SIGHUP whose default action (the process ends at once, no
    ``finally`` run) is set restore the terminal ``fd`` to ``saved`` first, then end the process
    by the signal as before; else a ``kill`` during a key's read left the terminal without echo
    or line editing. Only in the main thread (where Python runs signal handlers)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def restore_then_die(signum: int, frame: Any) -> None:
        try:
            termios.tcsetattr(fd, termios.TCSANOW, saved)
        except (termios.error, OSError):  # the terminal is gone (SIGHUP): nothing to restore
            pass
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)

    replaced = {}
    try:  # installed inside: a Ctrl-C between two installs still puts the first one back
        for signum in (signal.SIGTERM, signal.SIGHUP):
            if signal.getsignal(signum) is signal.SIG_DFL:
                replaced[signum] = signal.signal(signum, restore_then_die)
        yield
    finally:
        for signum, handler in replaced.items():
            signal.signal(signum, handler)


def _in_foreground(fd: int) -> bool:
    """Whether this process may use the terminal ``fd`` now: False for a background job of its
    controlling terminal (``torchcbl teach ... &``), which changing its settings would stop
    (SIGTTOU) and whose keys are another job's; True for any other terminal."""
    try:
        return os.tcgetpgrp(fd) == os.getpgrp()
    except OSError:  # not this process's controlling terminal: no job control applies
        return True


def _frontend_input() -> Callable[[], str] | None:
    """``input`` where a frontend replaced Python's own (a Jupyter kernel forwards it to the
    notebook's input box while a cell runs), else None."""
    current = builtins.input
    return None if getattr(current, "__self__", None) is builtins else current


class TerminalTeacher:
    """A teacher that asks a person at the terminal for each action, one key per decision.

    Args:
        keys: key map, key -> action index. A key is a single character (``"w"``), a name from
            :data:`KEY_NAMES` (``"up"``, ``"left"``, ``"space"``, ...) or a raw escape sequence.
            Letters also match in the other case when that case is not mapped itself. Every
            action must have at least one key.
        action_names: one name per action, in action order.
        describe: the domain's text view, ``describe(observation, info) -> str``. Without it
            the raw observation is shown.
        input: where keys are read from: a file object with ``fileno()`` or a file descriptor.
            Defaults to ``sys.stdin``. A terminal is read one key at a time; anything else one
            line at a time; by default, in a notebook, one line at a time from its input box.
        output: a text stream the view is written to. Defaults to ``sys.stdout``.
        quit_keys: keys that raise :class:`TeachingInterrupted`; Ctrl-C always does. A letter
            also quits in the other case when that case is not an action key.
        status: initial status line (see :meth:`set_status`).
        title: an optional heading shown above the view.
        clear_screen: redraw on a cleared screen each decision; ``None`` (default) clears only
            when ``output`` is a terminal.

    Raises:
        ValueError: for an empty or inconsistent key map or action names.
        TypeError: for a ``describe`` that is not callable.
    """

    def __init__(
        self,
        keys: Mapping[str, int],
        action_names: Sequence[str],
        describe: Callable[[np.ndarray, dict], str] | None = None,
        *,
        input: IO[Any] | int | None = None,
        output: IO[str] | None = None,
        quit_keys: Sequence[str] = ("q",),
        status: str = "",
        title: str = "",
        clear_screen: bool | None = None,
    ) -> None:
        names = list(action_names)
        if not names:
            raise ValueError("action_names must name at least one action")
        if any(not isinstance(n, str) or not n.strip() for n in names):
            raise ValueError(f"action names must be non-empty strings, got {names!r}")
        if len({n.lower() for n in names}) != len(names):
            raise ValueError(f"action names must be unique, got {names!r}")
        if describe is not None and not callable(describe):
            raise TypeError(f"describe must be callable, got {type(describe).__name__}")
        if not isinstance(keys, Mapping) or not keys:
            raise ValueError("keys must be a non-empty mapping key -> action")

        keymap: dict[str, int] = {}
        for key, action in keys.items():
            if isinstance(action, bool) or not isinstance(action, int | np.integer):
                raise ValueError(f"key {key!r} maps to {action!r}, not an action index")
            if not 0 <= int(action) < len(names):
                raise ValueError(
                    f"key {key!r} maps to action {action}, outside 0..{len(names) - 1}"
                )
            norm = _normalize_key(key)
            if norm in keymap and keymap[norm] != int(action):
                raise ValueError(f"key {key!r} is mapped to two different actions")
            keymap[norm] = int(action)
        missing = [names[a] for a in range(len(names)) if a not in keymap.values()]
        if missing:
            raise ValueError(f"no key for action(s) {missing}; every action needs a key")
        quits = list(dict.fromkeys(_normalize_key(k) for k in quit_keys))  # ordered, unique
        clash = sorted(_label(k) for k in quits if k in keymap)
        if clash:
            raise ValueError(f"quit key(s) {clash} are also action keys")

        self._keys = keymap
        self._quit = [*quits, _CTRL_C] if _CTRL_C not in quits else quits
        self.action_names: tuple[str, ...] = tuple(names)
        self._describe = describe
        self._input = sys.stdin if input is None else input
        self._default_input = input is None
        self._output = sys.stdout if output is None else output
        self.status: str = status
        """The status line shown under the view; the caller may assign it at any time."""
        self.title = title
        self._clear = clear_screen
        self.n_decisions: int = 0
        """How many decisions the person has answered so far; the status line shows the next
        as ``decision #(n_decisions + 1)``. A caller resuming a session may set it to the
        session's answered requests so the numbering goes on."""

    # ------------------------------------------------------------------ public

    @property
    def n_actions(self) -> int:
        """The number of actions."""
        return len(self.action_names)

    @property
    def keys(self) -> dict[str, int]:
        """The key map as read from the terminal (key names resolved), key -> action."""
        return dict(self._keys)

    def set_status(self, text: str) -> None:
        """Set the status line shown with the next view, e.g. ``"42 demos, autonomy 80%"``."""
        self.status = str(text)

    def help_text(self) -> str:
        """The key legend: each action with its keys, then the quit keys."""
        parts = []
        for action, name in enumerate(self.action_names):
            labels = [_label(k) for k, a in self._keys.items() if a == action]
            parts.append(f"[{'/'.join(labels)}] {name}")
        quits = [_label(k) for k in self._quit if k != _CTRL_C]
        parts.append(f"[{'/'.join(quits + ['Ctrl-C'])}] quit")
        return "  ".join(parts)

    def __call__(self, observation: np.ndarray, info: dict | None = None) -> int:
        """Show the situation and return the action the person chooses.

        Raises:
            TeachingInterrupted: the person pressed a quit key or Ctrl-C, or input ended.
        """
        info = {} if info is None else info
        self._show(observation, info)
        try:
            fd = self._input_fd()
            if fd is not None and termios is not None and os.isatty(fd):
                action = self._ask_key(fd)
            elif self._default_input and _frontend_input() is not None:
                action = self._ask_line(self._read_frontend_line)
            else:
                action = self._ask_line(self._read_line)
        except KeyboardInterrupt as exc:
            self._write("\n")
            raise TeachingInterrupted("teaching interrupted (Ctrl-C)") from exc
        self.n_decisions += 1
        self._write(f"-> {self.action_names[action]}\n")
        return action

    def check_quit(self) -> None:
        """Stop now if a quit key was typed since the last request (the agent acting on its own).

        Meant to be called between requests, e.g. after each step (``torchcbl teach`` calls it
        from the loop's ``on_step``, so a step is logged whole first). On a terminal the keys
        typed since the last read are taken without waiting for more: a quit key among them
        raises :class:`TeachingInterrupted`, as at a request, and so does Ctrl-D (the end of
        input, also after other keys on its line); the others are dropped, as keys typed ahead
        of a request are. The terminal leaves line mode only for that read
        (its settings are restored at once, also on an exception or a SIGTERM/SIGHUP) and keeps
        its signal keys: Ctrl-C raises :class:`KeyboardInterrupt` as it does between requests.
        Reads nothing and returns at once when the input is not a terminal (a pipe, a file, a
        notebook) or this process is a background job of its terminal.

        Raises:
            TeachingInterrupted: a quit key or Ctrl-D was typed, or the terminal was closed.
        """
        fd = self._input_fd()
        if fd is None or termios is None or not os.isatty(fd) or not _in_foreground(fd):
            return
        saved = termios.tcgetattr(fd)
        with _restored_before_a_fatal_signal(fd, saved), _key_waits(fd) as waits:
            try:
                mode = termios.tcgetattr(fd)
                # Non-canonical, so that keys typed without Enter can be read; echo and the
                # signal keys as they were (Ctrl-C stays SIGINT).
                mode[3] &= ~termios.ICANON
                mode[6][termios.VMIN] = 1
                mode[6][termios.VTIME] = 0
                typed = _lines_typed(fd, waits, saved)
                termios.tcsetattr(fd, termios.TCSANOW, mode)
                self._drop_typed_ahead(fd, waits, typed)
            finally:
                termios.tcsetattr(fd, termios.TCSANOW, saved)

    # ----------------------------------------------------------------- drawing

    def _write(self, text: str) -> None:
        self._output.write(text)
        self._output.flush()

    def _show(self, observation: np.ndarray, info: dict) -> None:
        clear = self._clear
        if clear is None:
            isatty = getattr(self._output, "isatty", None)
            clear = bool(isatty and isatty())
        lines = []
        if self.title:
            lines.append(self.title)
        if self._describe is not None:
            view = self._describe(observation, info).rstrip("\n")
        else:
            view = f"observation: {np.asarray(observation).tolist()}"
        lines.append(view)
        lines.append(
            f"decision #{self.n_decisions + 1}" + (f" | {self.status}" if self.status else "")
        )
        if clear:
            lines += self._cut_off_note(lines, view)
        self._write((_CLEAR_SCREEN if clear else "") + "\n".join(lines) + "\n")

    def _cut_off_note(self, lines: list[str], view: str) -> list[str]:
        """Lines saying the view is wider than the output terminal, its lines then wrapping (the
        driving view is about 70 columns), and that the screen is taller, its top then scrolling
        away (the driving view is ~30 lines, a terminal's usual height 24); else nothing."""
        try:
            columns, rows = os.get_terminal_size(self._output.fileno())
        except (AttributeError, OSError, ValueError):  # not a terminal, or no size known
            return []
        if rows < 1 or columns < 1:  # a pseudo-terminal nobody sized
            return []

        def height(text: str) -> int:  # terminal rows, a line longer than the width wrapping
            return sum(max(1, -(-len(line) // columns)) for line in text.split("\n"))

        notes = []
        wide = max(len(line) for line in view.split("\n"))
        if wide > columns:
            notes.append(
                f"(the view is {wide} columns wide, the window {columns}: its lines wrap; widen "
                "the window)"
            )
        # the screen: these lines, the notes, the key legend and the prompt line
        used = sum(height(line) for line in lines + notes) + height(self.help_text()) + 1
        if used <= rows:
            return notes
        note, note_rows = "", 1
        for _ in range(3):  # the note's own rows count, and its numbers set its length
            needed = used + note_rows
            note = (
                f"(the top {needed - rows} lines are cut off: {needed} rows needed, {rows} "
                "shown; enlarge the window)"
            )
            if height(note) == note_rows:
                break
            note_rows = height(note)
        return [*notes, note]

    def _prompt(self) -> None:
        self._write(f"{self.help_text()}\naction? ")

    def _invalid(self, what: str) -> None:
        self._write(f"\n{what} is not a key here. Valid keys: {self.help_text()}\n")

    # ----------------------------------------------------------------- reading

    def _input_fd(self) -> int | None:
        """The input's file descriptor, or None for a stream without one (e.g. StringIO)."""
        if isinstance(self._input, int):
            return self._input
        try:
            return self._input.fileno()
        except (AttributeError, OSError, ValueError):  # io.UnsupportedOperation is both
            return None

    def _ask_key(self, fd: int) -> int:
        saved = termios.tcgetattr(fd)
        with _restored_before_a_fatal_signal(fd, saved), _key_waits(fd) as waits:
            return self._ask_key_raw(fd, saved, waits)

    def _ask_key_raw(self, fd: int, saved: list[Any], waits: selectors.BaseSelector) -> int:
        try:
            mode = termios.tcgetattr(fd)
            # Non-canonical, no echo, no signal keys (Ctrl-C arrives as a byte and is ours),
            # no extended processing. Output processing is kept so newlines still work.
            mode[3] &= ~(termios.ICANON | termios.ECHO | termios.ISIG | termios.IEXTEN)
            mode[6][termios.VMIN] = 1
            mode[6][termios.VTIME] = 0
            typed = _lines_typed(fd, waits, saved)
            termios.tcsetattr(fd, termios.TCSANOW, mode)
            self._drop_typed_ahead(fd, waits, typed)
            self._prompt()
            while True:
                key = self._read_key(fd, waits)
                action = self._resolve_key(key)
                if action is not None:
                    return action
                self._invalid(repr(_label(key)))
                self._write("action? ")
        finally:
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)

    def _drop_typed_ahead(
        self, fd: int, waits: selectors.BaseSelector, pending: bytes = b""
    ) -> None:
        """Drop the keys typed before this request was shown (while the agent acted on its own,
        a second press, a held key's repeat): they would answer a situation the person has not
        seen. A quit key among them still quits. The pending bytes (``pending``, the lines
        already read in line mode, then those waiting) are split into keys as at a
        request, so an escape sequence ending in "q" (F2 is ESC O Q) is one key, not a quit."""
        while True:
            while waits.select(0):
                pending += self._read_byte(fd, waits)
            keys, pending = _split_keys(pending)
            for key in keys:
                self._resolve_key(key)  # raises for a quit key, as at a request
            if not pending:
                return
            if not self._more(waits):  # a key cut off at the end whose rest never came
                self._resolve_key(_decode_key(pending))
                return

    def _read_byte(self, fd: int, waits: selectors.BaseSelector) -> bytes:
        try:
            # waited for in short selects, not in one blocking read: a SIGTERM that lands
            # after Python's last check and before a blocking read() only sets a flag, and
            # its handler (which restores the terminal, then ends the process) would run at
            # the next key; between selects it runs within _SIGNAL_WAIT seconds
            while not waits.select(_SIGNAL_WAIT):
                pass
            byte = os.read(fd, 1)
        except OSError as exc:  # EIO once the other end of a pseudo-terminal is gone
            raise TeachingInterrupted("teaching input closed") from exc
        if not byte:
            raise TeachingInterrupted("teaching input closed")
        return byte

    def _more(self, waits: selectors.BaseSelector) -> bool:
        return bool(waits.select(_ESCAPE_WAIT))

    def _read_key(self, fd: int, waits: selectors.BaseSelector) -> str:
        data = self._read_byte(fd, waits)
        while _key_length(data) is None:
            if data[0] == 0x1B and not self._more(waits):  # a lone ESC, or a cut-off sequence
                break
            data += self._read_byte(fd, waits)
        return _decode_key(data)

    def _resolve_key(self, key: str) -> int | None:
        if key in self._quit or key == _CTRL_D:
            raise TeachingInterrupted(f"teaching stopped by the person ({_label(key)})")
        if key in self._keys:
            return self._keys[key]
        if len(key) == 1 and key.swapcase() in self._keys:
            return self._keys[key.swapcase()]
        if len(key) == 1 and key.swapcase() in self._quit:  # "Q" with caps lock on, as "W" acts
            raise TeachingInterrupted(f"teaching stopped by the person ({_label(key)})")
        return None

    def _read_line(self) -> str:
        if self._input is None:  # sys.stdin of a process started with fd 0 closed
            return ""
        if isinstance(self._input, int):
            chunks = []
            while True:
                byte = os.read(self._input, 1)
                if not byte:
                    break
                chunks.append(byte)
                if byte == b"\n":
                    break
            return b"".join(chunks).decode("utf-8", errors="replace")
        line = self._input.readline()
        if isinstance(line, bytes):
            line = line.decode("utf-8", errors="replace")
        return line

    def _read_frontend_line(self) -> str:
        """One entry of a notebook's input box (the kernel's ``input()``), with its newline."""
        frontend = _frontend_input()
        assert frontend is not None
        try:
            return frontend() + "\n"  # an empty entry is an empty line, not the end of input
        except EOFError:
            return ""
        except NotImplementedError as exc:  # IPython's StdinNotImplementedError
            raise RuntimeError(
                "TerminalTeacher: this notebook's frontend takes no typed input (its kernel "
                f"answered input() with {type(exc).__name__}: {exc}), so there is no input box "
                "to type keys into; teach in a frontend that has one (Jupyter Notebook or Lab, "
                "VS Code), or from a terminal (`torchcbl teach ...`, or a script run there)"
            ) from exc

    def _ask_line(self, read_line: Callable[[], str]) -> int:
        self._prompt()
        while True:
            line = read_line()
            if not line:
                raise TeachingInterrupted("teaching input closed")
            token = line.rstrip("\r\n")
            token = token.strip() or token[:1]  # a line of spaces means the space key
            action = self._resolve_token(token)
            if action is not None:
                return action
            self._invalid(repr(token))
            numbers = ", ".join(f"{a} {name}" for a, name in enumerate(self.action_names))
            self._write(
                f"(type a key, a key name, an action name or its number ({numbers}), then "
                "Enter)\naction? "
            )

    def _resolve_token(self, token: str) -> int | None:
        lowered = token.lower()
        # a single character is read as a key is on a terminal (its other case quits only when
        # not an action key); a longer token may name a quit key ("space")
        named = len(token) > 1 and any(lowered == _label(k) for k in self._quit)
        if lowered == "quit" or token in self._quit or named:
            raise TeachingInterrupted("teaching stopped by the person (quit)")
        if not token:
            return None
        if len(token) == 1:
            found = self._resolve_key(token)
            if found is not None:
                return found
        if lowered in KEY_NAMES and KEY_NAMES[lowered] in self._keys:
            return self._keys[KEY_NAMES[lowered]]
        for action, name in enumerate(self.action_names):
            if lowered == name.lower():
                return action
        if token.isdecimal() and int(token) < self.n_actions:  # "²" is a digit, no int
            return int(token)
        return None
