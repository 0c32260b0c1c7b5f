"""The terminal teacher, driven through a real pseudo-terminal, and the domains' text views."""

from __future__ import annotations

import io
import os
import pty
import re
import select
import signal
import subprocess
import sys
import termios
import threading
import time

import gymnasium as gym
import numpy as np
import pytest

from torchcbl.human import TeachingInterrupted, TerminalTeacher

PROMPT = b"action? "
OBS = np.array([0.5], dtype=np.float32)


def _describe(observation, info):
    return f"x = {float(observation[0])!r}"  # exact, so a script can act on it


class Person(threading.Thread):
    """Plays the person at the other end of a pseudo-terminal.

    Waits for each prompt the teacher writes to the master side, records the terminal's local
    mode flags at that moment, then answers with the next item of ``answers``: bytes are typed,
    a callable is called instead. The deadline only keeps a broken teacher from hanging the run.
    """

    def __init__(self, master: int, slave: int, answers, deadline: float = 20.0):
        super().__init__(daemon=True)
        self.master, self.slave = master, slave
        self.answers = list(answers)
        self.deadline = time.monotonic() + deadline
        self.transcript = bytearray()
        self.lflags_at_prompt: list[int] = []

    def run(self) -> None:
        sent = 0
        while sent < len(self.answers) and time.monotonic() < self.deadline:
            if select.select([self.master], [], [], 0.05)[0]:
                try:
                    self.transcript += os.read(self.master, 4096)
                except OSError:
                    return
            if self.transcript.count(PROMPT) > sent:
                self.lflags_at_prompt.append(termios.tcgetattr(self.slave)[3])
                answer = self.answers[sent]
                if callable(answer):
                    answer()
                else:
                    os.write(self.master, answer)
                sent += 1

    def finish(self) -> str:
        self.join(timeout=20)
        assert not self.is_alive()
        while select.select([self.master], [], [], 0.05)[0]:
            try:
                chunk = os.read(self.master, 4096)
            except OSError:
                break
            if not chunk:
                break
            self.transcript += chunk
        return self.transcript.decode("utf-8", errors="replace")


@pytest.fixture
def terminal():
    """A pseudo-terminal (master, slave) with the slave in its normal, canonical mode."""
    master, slave = pty.openpty()
    yield master, slave
    for fd in (master, slave):
        try:
            os.close(fd)
        except OSError:
            pass


def _teacher(slave: int, **kw) -> TerminalTeacher:
    kw.setdefault("keys", {"w": 0, "up": 0, "a": 1, "left": 1, "d": 2, "right": 2})
    kw.setdefault("action_names", ("stay", "left", "right"))
    kw.setdefault("describe", _describe)
    out = open(slave, "w", encoding="utf-8", closefd=False)  # noqa: SIM115 - lives as long as the pty
    return TerminalTeacher(input=slave, output=out, **kw)


# ---------------------------------------------------------------- through a pseudo-terminal


@pytest.mark.timeout(60)
def test_single_keys_without_enter_choose_actions_and_terminal_is_restored(terminal):
    master, slave = terminal
    before = termios.tcgetattr(slave)
    keys = [b"w", b"\x1b[D", b"d", b"\x1bOA", b"A", b"\x1b[C"]  # OA: application-mode up
    person = Person(master, slave, keys)
    teacher = _teacher(slave)
    person.start()
    actions = [teacher(OBS, {}) for _ in keys]
    shown = person.finish()

    assert actions == [0, 1, 2, 0, 1, 2]
    assert teacher.n_decisions == len(keys)
    # While waiting for a key the terminal was non-canonical (no Enter needed) and silent.
    assert len(person.lflags_at_prompt) == len(keys)
    for lflag in person.lflags_at_prompt:
        assert not lflag & termios.ICANON
        assert not lflag & termios.ECHO
        assert not lflag & termios.ISIG
    assert termios.tcgetattr(slave) == before
    assert re.search(r"x = 0\.5\s", shown)
    assert "[w/up] stay" in shown and "[a/left] left" in shown
    assert shown.count("-> right") == 2


@pytest.mark.timeout(60)
def test_an_unknown_key_reprompts_with_the_valid_keys(terminal):
    master, slave = terminal
    person = Person(master, slave, [b"x", b"\x1b[B", b"a"])  # x and down arrow are not mapped
    teacher = _teacher(slave)
    person.start()
    action = teacher(OBS, {})
    shown = person.finish()

    assert action == 1
    assert shown.count("action? ") == 3
    assert "'x' is not a key here" in shown
    assert "'down' is not a key here" in shown
    assert "Valid keys: [w/up] stay  [a/left] left  [d/right] right  [q/Ctrl-C] quit" in shown


@pytest.mark.timeout(60)
@pytest.mark.parametrize("key", [b"q", b"\x03"], ids=["q", "ctrl-c"])
def test_quit_key_raises_teaching_interrupted_and_restores_terminal(terminal, key):
    master, slave = terminal
    before = termios.tcgetattr(slave)
    person = Person(master, slave, [b"w", key])
    teacher = _teacher(slave)
    person.start()
    assert teacher(OBS, {}) == 0
    with pytest.raises(TeachingInterrupted):
        teacher(OBS, {})
    person.finish()
    assert termios.tcgetattr(slave) == before
    assert teacher.n_decisions == 1


@pytest.mark.timeout(60)
def test_a_quit_key_in_the_other_case_quits_on_a_terminal_as_over_a_pipe(terminal):
    """With caps lock on, "A" chose "left" on a terminal but "Q" was "not a key here", while a
    line "Q" from a pipe quit; and with "Q" mapped to an action, the pipe quit on "Q" where the
    terminal chose the action. Both now read a key alike."""
    master, slave = terminal
    before = termios.tcgetattr(slave)
    person = Person(master, slave, [b"Qw"])  # the old code went on to read "w" as "stay"
    teacher = _teacher(slave)
    person.start()
    with pytest.raises(TeachingInterrupted):
        teacher(OBS, {})
    person.finish()
    assert termios.tcgetattr(slave) == before
    with pytest.raises(TeachingInterrupted):
        TerminalTeacher({"w": 0}, ("go",), input=io.StringIO("Q\n"), output=io.StringIO())(OBS)
    keys = {"w": 0, "Q": 1}  # "Q" an action key, "q" the quit key
    piped = TerminalTeacher(keys, ("go", "back"), input=io.StringIO("Q\n"), output=io.StringIO())
    assert piped(OBS) == 1
    master2, slave2 = pty.openpty()
    try:
        person = Person(master2, slave2, [b"Q"])
        person.start()
        assert _teacher(slave2, keys=keys, action_names=("go", "back"))(OBS, {}) == 1
        person.finish()
    finally:
        os.close(master2)
        os.close(slave2)


@pytest.mark.timeout(60)
def test_keyboard_interrupt_while_waiting_restores_terminal(terminal):
    master, slave = terminal
    before = termios.tcgetattr(slave)
    # Ctrl-C as the kernel delivers it to a process blocked in read(): to the main thread. A
    # process-wide os.kill may land on another thread (pytest-timeout's, tqdm's monitor), and
    # then the main thread's read() is never interrupted (seen once in CI: a 60 s timeout).
    main = threading.main_thread().ident
    # A SIGINT that lands after the prompt but just before the main thread blocks in read()
    # only sets CPython's flag; its handler would run when read() returns, which it never does
    # (seen twice in CI, under load: a 60 s timeout). So the person presses Ctrl-C again every
    # 0.2 s until the handler has run; the handler raises once and ignores the later presses.
    fired = threading.Event()

    def once(signum, frame):
        if not fired.is_set():
            fired.set()
            raise KeyboardInterrupt

    def press_until_seen():
        give_up = time.monotonic() + 20.0
        while not fired.is_set() and time.monotonic() < give_up:
            signal.pthread_kill(main, signal.SIGINT)
            fired.wait(0.2)

    old = signal.signal(signal.SIGINT, once)
    try:
        person = Person(master, slave, [press_until_seen])
        teacher = _teacher(slave)
        person.start()
        with pytest.raises(TeachingInterrupted) as caught:
            teacher(OBS, {})
        person.finish()
    finally:
        signal.signal(signal.SIGINT, old)
    assert isinstance(caught.value.__cause__, KeyboardInterrupt)
    assert termios.tcgetattr(slave) == before


@pytest.mark.timeout(60)
def test_status_line_is_shown_and_can_be_updated(terminal):
    master, slave = terminal
    person = Person(master, slave, [b"w", b"w"])
    teacher = _teacher(slave, status="warming up")
    person.start()
    teacher(OBS, {})
    teacher.set_status("the agent asks: 3 of the last 20 steps")
    teacher(OBS, {})
    shown = person.finish()
    first, second = shown.split("-> stay", 1)
    assert "decision #1 | warming up" in first
    assert "decision #2 | the agent asks: 3 of the last 20 steps" in second
    assert "warming up" not in second


def _typed_ahead_then_w(master: int, slave: int, typed: bytes) -> TerminalTeacher:
    """``typed`` waiting in the terminal before a request, then "w" pressed at it: the request
    must take the "w" (stay), the keys typed ahead dropped. Returns the teacher."""
    os.write(master, typed)
    time.sleep(0.1)
    person = Person(master, slave, [b"w"])
    teacher = _teacher(slave)
    person.start()
    assert teacher(OBS, {}) == 0  # the key pressed after seeing the request
    shown = person.finish()
    assert shown.count("-> ") == 1 and "-> stay" in shown
    return teacher


@pytest.mark.timeout(60)
def test_a_key_typed_before_the_request_is_shown_does_not_answer_it(terminal):
    """A key pressed while the agent acted on its own (or a second press, a held arrow's
    repeat) waited in the terminal's buffer and answered the next request at once: a
    demonstration for a situation the person never saw. It is dropped now; a quit key typed
    ahead still quits."""
    master, slave = terminal
    teacher = _typed_ahead_then_w(master, slave, b"d")  # "d" pressed between two requests
    before = termios.tcgetattr(slave)
    os.write(master, b"dQ")  # "Q": caps lock on, as at a request
    time.sleep(0.1)
    with pytest.raises(TeachingInterrupted):
        teacher(OBS, {})
    assert termios.tcgetattr(slave) == before
    assert teacher.n_decisions == 1


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    "typed",
    [b"\x1bOQ", b"\x1b[1;2Q", b"\x1bq", b"\x1bOq", b"d\x1bOQ\x1bOq"],
    ids=["F2", "shift-F2", "alt-q", "keypad-1", "several"],
)
def test_a_key_ending_in_q_typed_ahead_is_dropped_not_taken_for_the_quit_key(terminal, typed):
    """F2 (ESC O Q), Shift-F2, Alt-q (ESC q) or keypad 1 in application mode (ESC O q) typed
    before a request quit the session: the pending bytes were checked one by one, so the
    sequence's last "q"/"Q" counted as the quit key, where at a request the same key is "not a
    key here". Typed ahead they are dropped like any other key."""
    _typed_ahead_then_w(*terminal, typed)


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    "typed",
    [b"q", b"Q", b"\x1bOQq", b"\x1b[21~", b"\x1bOP"],
    ids=["q", "Q", "F2-then-q", "F10-a-quit-key", "F1-a-quit-key"],
)
def test_a_quit_key_typed_ahead_still_quits(terminal, typed):
    """A quit key's whole escape sequence quits too; F1 (ESC O P) did not, as the key map reads
    it as ESC [ P and the pending bytes were searched for that."""
    master, slave = terminal
    before = termios.tcgetattr(slave)
    os.write(master, typed)
    time.sleep(0.1)
    teacher = _teacher(slave, quit_keys=("q", "\x1b[21~", "\x1bOP"))
    with pytest.raises(TeachingInterrupted):
        teacher(OBS, {})
    assert termios.tcgetattr(slave) == before
    assert teacher.n_decisions == 0


@pytest.mark.timeout(60)
def test_check_quit_takes_the_keys_typed_since_the_last_request_without_waiting(terminal):
    """check_quit() between requests: a key other than a quit key typed meanwhile is dropped
    (it answers no request), a quit key raises; no key, nothing happens, at once; the terminal
    is left in line mode, as it was, each time."""
    master, slave = terminal
    before = termios.tcgetattr(slave)
    teacher = _teacher(slave)
    teacher.check_quit()  # nothing typed: returns without waiting for a key
    os.write(master, b"d")
    time.sleep(0.1)
    teacher.check_quit()
    assert termios.tcgetattr(slave) == before
    person = Person(master, slave, [b"w"])
    person.start()
    assert teacher(OBS, {}) == 0  # the "d" was dropped, not taken for the answer
    person.finish()
    os.write(master, b"aq")
    time.sleep(0.1)
    with pytest.raises(TeachingInterrupted, match="stopped by the person"):
        teacher.check_quit()
    assert termios.tcgetattr(slave) == before
    assert teacher.n_decisions == 1


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    "typed",
    [b"\x04", b"d\x04", b"d\r\x04", b"\x04d\r"],
    ids=["ctrl-d", "key-then-ctrl-d", "line-then-ctrl-d", "ctrl-d-then-line"],
)
@pytest.mark.parametrize("at", ["check_quit", "request"])
def test_ctrl_d_typed_while_the_agent_drives_on_its_own_ends_the_session(terminal, typed, at):
    """Ctrl-D (end of input) typed while the agent acted on its own was dropped: the terminal,
    in line mode then, keeps it as the end of a line, which the switch to key-at-a-time mode
    for check_quit() or the next request turned into a NUL byte, dropped like any key typed
    ahead; the request then waited for a key. It ends the session now, as Ctrl-D at a request
    does, also after other keys on its line or before them; the terminal is left as it was."""
    master, slave = terminal
    before = termios.tcgetattr(slave)
    teacher = _teacher(slave)
    os.write(master, typed)
    time.sleep(0.1)
    # a "w" pressed later answers a request that (wrongly) waits for a key, so a teacher that
    # drops the Ctrl-D fails the test rather than hanging it
    late = threading.Timer(1.0, os.write, (master, b"w"))
    late.start()
    try:
        with pytest.raises(TeachingInterrupted, match=r"stopped by the person \(Ctrl-D\)"):
            teacher.check_quit() if at == "check_quit" else teacher(OBS, {})
    finally:
        late.cancel()
    assert termios.tcgetattr(slave) == before
    assert teacher.n_decisions == 0
    assert not select.select([slave], [], [], 0)[0]  # no line left for the shell to run


@pytest.mark.timeout(60)
def test_a_whole_line_typed_while_the_agent_drives_is_dropped_not_taken_for_ctrl_d(terminal):
    """A line ended with Enter while the agent acts on its own is keys typed ahead (dropped),
    not the end of input: the session goes on and the request takes the key pressed at it."""
    master, slave = terminal
    teacher = _teacher(slave)
    os.write(master, b"d\r")
    time.sleep(0.1)
    teacher.check_quit()
    _typed_ahead_then_w(master, slave, b"a\r")


@pytest.mark.timeout(60)
def test_ctrl_d_at_a_request_ends_the_session(terminal):
    """Ctrl-D pressed at a request (the terminal in key-at-a-time mode) stops as q does."""
    master, slave = terminal
    before = termios.tcgetattr(slave)
    person = Person(master, slave, [b"w", b"\x04"])
    teacher = _teacher(slave)
    person.start()
    assert teacher(OBS, {}) == 0
    with pytest.raises(TeachingInterrupted, match=r"stopped by the person \(Ctrl-D\)"):
        teacher(OBS, {})
    person.finish()
    assert termios.tcgetattr(slave) == before
    assert teacher.n_decisions == 1


_CHECKED_IN_A_BACKGROUND_JOB = """
import os, signal, sys
sys.path.insert(0, {root!r})
os.setsid()
tty = os.open({slave!r}, os.O_RDWR)  # the session's controlling terminal now
job = os.fork()
if job == 0:  # a job in the background of that terminal (`torchcbl teach ... &`)
    os.setpgid(0, 0)
    from torchcbl.human import TerminalTeacher
    TerminalTeacher({{"w": 0}}, ("stay",), input=tty, output=open(os.devnull, "w")).check_quit()
    os._exit(0)
_, status = os.waitpid(job, os.WUNTRACED)
if os.WIFSTOPPED(status):
    os.kill(job, signal.SIGKILL)
    os.waitpid(job, 0)
    print("stopped by", signal.Signals(os.WSTOPSIG(status)).name)
else:
    print("exit", os.waitstatus_to_exitcode(status))
"""


@pytest.mark.timeout(60)
def test_check_quit_in_a_background_job_leaves_the_terminal_alone(terminal):
    """A background job (`torchcbl teach ... &`) may not change its terminal's settings (the
    system stops it with SIGTTOU), and the keys typed there are the foreground's: check_quit
    neither stops it nor takes a "q" waiting there."""
    master, slave = terminal
    os.write(master, b"q")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    script = _CHECKED_IN_A_BACKGROUND_JOB.format(root=root, slave=os.ttyname(slave))
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=30, check=False
    )
    assert done.stdout.strip() == "exit 0", done.stdout + done.stderr


# ------------------------------------------------------------------- line-input fallback


def test_line_input_from_a_pipe():
    read_fd, write_fd = os.pipe()
    os.write(write_fd, b"x\nup\nright\n1\nD\n  \nq\n")
    os.close(write_fd)
    out = io.StringIO()
    with os.fdopen(read_fd, "r") as pipe:
        teacher = TerminalTeacher(
            {"w": 0, "up": 0, "a": 1, "d": 2, "space": 1},
            ("stay", "left", "right"),
            _describe,
            input=pipe,
            output=out,
        )
        # 'x' is rejected, then 'up' (a key name); an action name; an action number;
        # a capital letter; a line of spaces is the space key.
        assert [teacher(OBS, {}) for _ in range(5)] == [0, 2, 1, 2, 1]
        with pytest.raises(TeachingInterrupted, match="stopped"):
            teacher(OBS, {})
        with pytest.raises(TeachingInterrupted, match="closed"):
            teacher(OBS, {})
    assert "'x' is not a key here" in out.getvalue()
    assert "\x1b[2J" not in out.getvalue()  # no screen clearing on a non-terminal


def test_check_quit_reads_nothing_from_a_pipe():
    """Over a pipe (keys one line each, read at requests) check_quit leaves the input alone: a
    "q" line waits for the next request, which it quits."""
    read_fd, write_fd = os.pipe()
    os.write(write_fd, b"w\nq\n")
    os.close(write_fd)
    with os.fdopen(read_fd, "r") as pipe:
        teacher = TerminalTeacher({"w": 0}, ("stay",), input=pipe, output=io.StringIO())
        teacher.check_quit()
        assert teacher(OBS, {}) == 0
        teacher.check_quit()
        with pytest.raises(TeachingInterrupted, match="stopped"):
            teacher(OBS, {})


def test_input_without_a_file_descriptor_reads_lines():
    teacher = TerminalTeacher(
        {"w": 0, "s": 1}, ("go", "stop"), input=io.StringIO("s\n"), output=io.StringIO()
    )
    assert teacher(np.array([1.0, 2.0]), {}) == 1


def test_bad_key_maps_are_clear_errors():
    names = ("a0", "a1")
    with pytest.raises(ValueError, match="no key for action"):
        TerminalTeacher({"w": 0}, names)
    with pytest.raises(ValueError, match="outside 0..1"):
        TerminalTeacher({"w": 0, "s": 2}, names)
    with pytest.raises(ValueError, match="quit key"):
        TerminalTeacher({"w": 0, "q": 1}, names)
    with pytest.raises(ValueError, match="unknown key"):
        TerminalTeacher({"w": 0, "upp": 1}, names)
    with pytest.raises(ValueError, match="two different actions"):
        TerminalTeacher({"up": 0, "\x1b[A": 1}, names)
    with pytest.raises(ValueError, match="not an action index"):
        TerminalTeacher({"w": 0, "s": "1"}, names)
    with pytest.raises(ValueError, match="unique"):
        TerminalTeacher({"w": 0, "s": 1}, ("go", "Go"))
    with pytest.raises(TypeError, match="callable"):
        TerminalTeacher({"w": 0, "s": 1}, names, describe="x")


def test_core_human_module_imports_no_domain():
    code = (
        "import sys, torchcbl.human\n"
        "print(','.join(m for m in ('corridor', 'sumo_scenarios', 'libsumo', 'pymunk')"
        " if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


# ------------------------------------------------------------------------- domain views


def _grid(view: str) -> dict[float, str]:
    """Rows of the driving view by their distance label."""
    rows = {}
    for line in view.splitlines():
        m = re.match(r"\s*([+-]\d+\.\d)m\|(.*)\|$", line)
        if m:
            rows[float(m.group(1))] = m.group(2)
    return rows


def _lane_of(row: str, mark: str) -> int:
    """The lane index (0 right shoulder .. 4 left shoulder) of ``mark`` in a row of the view."""
    cells = row.split(":")
    assert len(cells) == 5
    found = [i for i, cell in enumerate(cells) if mark in cell]
    assert len(found) == 1, row
    return 4 - found[0]


def test_driving_view_places_ego_and_cars_by_lane_and_distance():
    from sumo_scenarios.human import describe

    obs = np.array([-5.0, 10.0, 25.0, 2.0], dtype=np.float32)
    rows = _grid(describe(obs, {}))
    assert len(rows) == 21 and max(rows) == 25.0 and min(rows) == -25.0
    assert _lane_of(rows[0.0], "[E]") == 2
    assert _lane_of(rows[10.0], "[#]") == 2  # 10 m ahead in the ego's lane
    assert _lane_of(rows[-5.0], "[#]") == 1  # 5 m behind, one lane to the right
    drawn = sum(row.count("[#]") for row in rows.values())
    assert drawn == 2  # lane 3's car is out of range (clipped to 25) and not drawn

    shoulder = _grid(describe(np.array([25, 25, 7.4, 4], dtype=np.float32), {}))
    assert _lane_of(shoulder[0.0], "[E]") == 4
    assert _lane_of(shoulder[7.5], "[#]") == 3


def test_driving_view_shows_contact_and_overlap():
    from sumo_scenarios.human import describe

    obs = np.array([25.0, 0.4, -25.0, 2.0], dtype=np.float32)
    calm = describe(obs, {})
    touching = describe(obs, {"contact": True})
    assert "CONTACT" not in calm
    assert "CONTACT" in touching
    assert _lane_of(_grid(calm)[0.0], "[X]") == 2


@pytest.mark.parametrize("obs", [[1.0, 2.0, 3.0], [0, 0, 0, 5], [0, 0, 0, 2.5], [np.nan, 0, 0, 2]])
def test_driving_view_rejects_bad_observations(obs):
    from sumo_scenarios.human import describe

    with pytest.raises(ValueError):
        describe(np.asarray(obs, dtype=np.float32), {})


def test_corridor_view_bars_are_proportional_to_distance():
    from corridor.human import describe

    view = describe(np.array([0.3, 1.5, 4.0], dtype=np.float32), {}, max_range=3.0, width=30)
    bars = {
        m.group(1): m.group(3)
        for m in re.finditer(r"(left|front|right)\s+(\S+) m \|([# ]+)\|", view)
    }
    assert bars["left"].count("#") == 3
    assert bars["front"].count("#") == 15
    assert bars["right"].count("#") == 30
    assert "max" in view.splitlines()[3] and "max" not in view.splitlines()[2]
    for bad in ([1.0, 2.0], [1.0, -0.1, 2.0], [1.0, np.inf, 1.0]):
        with pytest.raises(ValueError):
            describe(np.asarray(bad), {})


def test_domain_teachers_map_keys_to_actions():
    from corridor.human import make_teacher as corridor_teacher
    from sumo_scenarios.human import make_teacher as driving_teacher

    corridor = corridor_teacher(input=io.StringIO(), output=io.StringIO()).keys
    assert corridor["\x1b[A"] == corridor["w"] == 0
    assert corridor["\x1b[D"] == corridor["a"] == 1
    assert corridor["\x1b[C"] == corridor["d"] == 2
    assert corridor["\x1b[B"] == corridor["s"] == 3
    driving = driving_teacher(input=io.StringIO(), output=io.StringIO()).keys
    assert driving[" "] == driving["w"] == driving["\x1b[A"] == 0
    assert driving["\x1b[D"] == driving["a"] == 1
    assert driving["\x1b[C"] == driving["d"] == 2

    out = io.StringIO()
    teacher = driving_teacher(input=io.StringIO("d\n"), output=out)
    assert teacher(np.array([12.0, -25.0, 25.0, 1.0]), {}) == 2
    assert "[E]" in out.getvalue() and "shift right" in out.getvalue()


@pytest.mark.timeout(60)
@pytest.mark.parametrize("rows", [24, 40])
def test_a_view_taller_than_the_terminal_says_its_top_is_cut_off(terminal, rows):
    """The driving view (title, legend, lane names, 21 rows of road, status, keys) is about 30
    lines: on a terminal of the usual 24 rows the title, the legend, the lane names and the
    road far ahead scrolled away unsaid. The screen now says so, and how to see it all."""
    import fcntl
    import struct

    from sumo_scenarios.human import make_teacher

    master, slave = terminal
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, 80, 0, 0))
    person = Person(master, slave, [b"w"])
    out = open(slave, "w", encoding="utf-8", closefd=False)  # noqa: SIM115 - lives as long as the pty
    teacher = make_teacher(input=slave, output=out, status="step 1 | demonstrations 1")
    person.start()
    assert teacher(np.array([10.0, -25.0, 25.0, 2.0], dtype=np.float32), {}) == 0
    shown = person.finish()
    if rows == 24:
        note = re.search(r"the top (\d+) lines are cut off: (\d+) rows needed, 24 shown", shown)
        assert note, shown[-600:]
        screen = shown.split("\x1b[2J")[-1].split("action? ")[0].splitlines()
        needed = sum(max(1, -(-len(line) // 80)) for line in screen) + 1  # + the prompt's
        assert int(note.group(2)) == needed and int(note.group(1)) == needed - 24
        assert "enlarge the window" in shown
    else:
        assert "rows" not in shown and "[E]" in shown


# ----------------------------------------------------------------------------- end to end

_PERSON_SCRIPT = r"""
import os, re, select, sys

fd = int(sys.argv[1])
buf, answered = b"", 0
while select.select([fd], [], [], 60)[0]:
    try:
        chunk = os.read(fd, 4096)
    except OSError:
        break
    if not chunk:
        break
    buf += chunk
    while b"action? " in buf:
        shown, buf = buf.split(b"action? ", 1)
        x = float(re.findall(rb"x = ([0-9.e+-]+)", shown)[-1])
        os.write(fd, b"a" if x < 0.5 else b"\x1b[C")  # 'a' low, right arrow high
        answered += 1
        shown_demos = re.findall(rb"(\d+) demonstrations so far", shown)
        print(answered, int(shown_demos[-1]) if shown_demos else -1, flush=True)
"""


class ThresholdEnv(gym.Env):
    """A tiny 1-D task: observe x in [0, 1]; action 0 is right below 0.5, action 1 above."""

    observation_space = gym.spaces.Box(0.0, 1.0, shape=(1,), dtype=np.float32)
    action_space = gym.spaces.Discrete(2)

    def _observe(self):
        self._x = np.array([self.np_random.uniform(0.0, 1.0)], dtype=np.float32)
        return self._x.copy()

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._t = 0
        return self._observe(), {}

    def step(self, action):
        correct = int(action) == int(self._x[0] >= 0.5)
        self._t += 1
        done = self._t >= 20
        info = {"is_success": True} if done else {}
        return self._observe(), float(correct), False, done, info


@pytest.mark.timeout(300)
def test_a_person_at_the_terminal_teaches_an_agent_that_asks_less_often(terminal, tmp_path):
    from torchcbl.teaching import ConfidentTeacher, TeachingConfig

    master, slave = terminal
    person = subprocess.Popen(
        [sys.executable, "-c", _PERSON_SCRIPT, str(master)],
        pass_fds=(master,),
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        teacher = _teacher(
            slave, keys={"a": 0, "left": 0, "d": 1, "right": 1}, action_names=("low", "high")
        )
        loop = ConfidentTeacher(
            ThresholdEnv(),
            teacher,
            config=TeachingConfig(noninteractive=False, max_steps=80),
            run_dir=tmp_path / "run",
            seed=0,
            progress=False,
            on_step=lambda r: teacher.set_status(
                f"{r.n_demonstrations} demonstrations so far, autonomy {r.autonomy_rate or 0:.0%}"
            ),
        )
        loop.run()
    finally:
        person.terminate()
        answers, _ = person.communicate(timeout=30)

    records = loop.records
    assert len(records) == 80
    asked = [r.teacher_action is not None for r in records]
    assert asked[0]  # no model yet: the agent must ask
    # Every request went through the terminal and was answered by the person, who saw the
    # live status: before answering request k, k-1 demonstrations had been recorded.
    lines = [tuple(map(int, line.split())) for line in answers.splitlines()]
    assert len(lines) == sum(asked) == teacher.n_decisions
    assert lines[0] == (1, -1)  # no status before the first step
    assert all(demos == k - 1 for k, demos in lines[1:])
    for r in records:
        if r.teacher_action is not None:
            assert r.teacher_action == int(r.observation[0] >= 0.5)
    assert sum(asked[40:]) < sum(asked[:40])
    # ... and what it learned from the person is right: it mostly acts correctly on its own.
    late = records[40:]
    assert sum(r.executed_action == int(r.observation[0] >= 0.5) for r in late) >= 0.8 * len(late)


def test_a_line_of_a_digit_that_is_no_number_is_an_invalid_key():
    """'²' (and other digits str.isdigit accepts) is no action number: the line teacher asked
    again for '1' but raised ValueError from int('²') (before 2026-11-27)."""
    out = io.StringIO()
    teacher = TerminalTeacher(
        {"w": 0, "s": 1}, ("go", "stop"), input=io.StringIO("²\n١\n"), output=out
    )
    assert teacher(np.zeros(2), {}) == 1  # '²' refused, then the Arabic-Indic digit one
    assert "'²' is not a key here" in out.getvalue()


_KERNEL_CELL = """
import sys
sys.path.insert(0, {root!r})
import numpy as np
from torchcbl.human import TerminalTeacher
teacher = TerminalTeacher({{"w": 0, "a": 1}}, ("stay", "left"))
try:
    print("ANSWERS", teacher(np.zeros(1), {{}}), teacher(np.zeros(1), {{}}))
except BaseException as exc:
    print("RAISED", type(exc).__name__, exc)
"""


def _in_a_kernel(typed: list[str] | None) -> str:
    """Run a cell that asks a default TerminalTeacher twice in a Jupyter kernel (whose stdin
    is a closed pipe, as in a notebook) and answer its input requests with ``typed``, as the
    notebook's input box would (None: a frontend that takes no input); the cell's output."""
    jupyter_client = pytest.importorskip("jupyter_client")
    pytest.importorskip("ipykernel")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    km, kc = jupyter_client.manager.start_new_kernel(kernel_name="python3")
    try:
        msg_id = kc.execute(_KERNEL_CELL.format(root=root), allow_stdin=typed is not None)
        answers = list(typed or [])
        out = []
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            if answers:
                try:
                    req = kc.get_stdin_msg(timeout=0.05)
                except Exception:  # noqa: BLE001 - queue.Empty: no request yet
                    req = None
                if req is not None and req["msg_type"] == "input_request":
                    kc.input(answers.pop(0))
            try:
                msg = kc.get_iopub_msg(timeout=0.05)
            except Exception:  # noqa: BLE001 - queue.Empty
                continue
            if msg["parent_header"].get("msg_id") != msg_id:
                continue
            if msg["msg_type"] == "stream":
                out.append(msg["content"]["text"])
            elif msg["msg_type"] == "status" and msg["content"]["execution_state"] == "idle":
                break
        return "".join(out)
    finally:
        kc.stop_channels()
        km.shutdown_kernel(now=True)


def test_in_a_notebook_the_keys_are_typed_into_the_input_box():
    """A notebook's kernel has a closed pipe as stdin: the default TerminalTeacher read end of
    input there and raised TeachingInterrupted ("teaching input closed") at its first
    decision, so a person could never teach from a notebook. It asks through the notebook's
    input box (the kernel's input()) now; an empty entry asks again."""
    out = _in_a_kernel(["", "a", "stay"])
    assert "ANSWERS 1 0" in out, out
    assert "not a key here" in out  # the empty entry


def test_in_a_notebook_whose_frontend_takes_no_input_the_error_says_so():
    out = _in_a_kernel(None)
    assert "RAISED" in out and "input box" in out and "torchcbl teach" in out, out


def test_a_process_started_with_its_stdin_closed_has_no_input_to_read(monkeypatch):
    """Python sets sys.stdin to None when fd 0 is closed (`torchcbl teach corridor <&-`): the
    default TerminalTeacher failed with AttributeError "'NoneType' object has no attribute
    'readline'" (the loop's TeacherError, exit code 1). No input is input closed."""
    monkeypatch.setattr(sys, "stdin", None)
    out = io.StringIO()
    teacher = TerminalTeacher({"w": 0}, ("stay",), output=out)
    with pytest.raises(TeachingInterrupted, match="teaching input closed"):
        teacher(OBS, {})
    assert out.getvalue().endswith(PROMPT.decode())


@pytest.mark.timeout(60)
def test_a_special_key_that_is_no_action_is_named_readably(terminal):
    """Esc, F2 (ESC O Q), Alt-x and Ctrl-Z (a byte, the terminal's signal keys being off) were
    refused as "'\\\\x1b[Q'" is not a key here: the key's repr quoted a second time, escapes
    doubled, unreadable to the person. They are named as a keyboard names them now."""
    master, slave = terminal
    typed = [b"\x1b", b"\x1bOQ", b"\x1bx", b"\x1a", b"\x7f", b"a"]
    person = Person(master, slave, typed)
    teacher = _teacher(slave)
    person.start()
    assert teacher(OBS, {}) == 1
    shown = person.finish()
    for name in ("Esc", "F2", "Alt-x", "Ctrl-Z", "Backspace"):
        assert f"'{name}' is not a key here" in shown, shown
    assert "\\x" not in shown


def test_a_line_teacher_says_which_number_is_which_action():
    """Reading lines (a pipe, a notebook), an invalid entry was answered "(type a key, a key
    name, an action name or number, then Enter)", but the legend numbers no action and the
    numbers count from 0: a person typing "1" for the first action, "forward", taught "turn
    left". The hint now says each action's number."""
    out = io.StringIO()
    names = ("forward", "turn left", "turn right", "u-turn")
    teacher = TerminalTeacher(
        {"w": 0, "a": 1, "d": 2, "s": 3}, names, input=io.StringIO("x\n0\n"), output=out
    )
    assert teacher(np.zeros(3), {}) == 0
    assert "0 forward, 1 turn left, 2 turn right, 3 u-turn" in out.getvalue(), out.getvalue()


def test_a_line_teacher_refuses_the_number_one_past_its_last_action():
    """Action numbers count from 0: with 3 actions "3" names none (it is n_actions, not the
    last action's number); it is an invalid entry, said so, and the next line is read."""
    out = io.StringIO()
    teacher = TerminalTeacher(
        {"w": 0, "a": 1, "d": 2},
        ("forward", "left", "right"),
        input=io.StringIO("3\n0\n"),
        output=out,
    )
    assert teacher(np.zeros(3), {}) == 0
    assert "'3' is not a key here" in out.getvalue(), out.getvalue()
    last = TerminalTeacher(
        {"w": 0, "a": 1, "d": 2},
        ("forward", "left", "right"),
        input=io.StringIO("2\n"),
        output=io.StringIO(),
    )
    assert last(np.zeros(3), {}) == 2  # the last action's number is one


_ASKED_IN_A_PROCESS = """
import signal, sys
signal.signal(signal.SIGHUP, signal.SIG_DFL)  # as a terminal's process has it (not under nohup)
sys.path.insert(0, {root!r})
import numpy as np
from torchcbl.human import TerminalTeacher
TerminalTeacher({{"w": 0}}, ("stay",), input=0)(np.zeros(1), {{}})
"""


@pytest.mark.timeout(60)
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_process_killed_while_it_waits_for_a_key_leaves_the_terminal_as_it_was(terminal, signum):
    """`kill PID` (SIGTERM: a timeout, a service manager) of `torchcbl teach` waiting for a key
    ended the process at once, its terminal left without echo, line editing or Ctrl-C (seen in
    tmux: `stty -a` after it said -isig -icanon -iexten -echo). The process still dies of the
    signal, as before, with the terminal restored first."""
    master, slave = terminal
    before = termios.tcgetattr(slave)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    child = subprocess.Popen(
        [sys.executable, "-c", _ASKED_IN_A_PROCESS.format(root=root)],
        stdin=slave,
        stdout=slave,
        stderr=subprocess.DEVNULL,
    )
    try:
        shown, deadline = b"", time.monotonic() + 30
        while PROMPT not in shown and time.monotonic() < deadline:
            if select.select([master], [], [], 0.1)[0]:
                shown += os.read(master, 4096)
        assert PROMPT in shown, shown
        child.send_signal(signum)  # once, as kill does: the wait for a key wakes for it
        child.wait(timeout=max(deadline - time.monotonic(), 1))
    finally:
        child.kill()
        child.wait()
    assert child.returncode == -signum
    assert termios.tcgetattr(slave) == before


@pytest.mark.timeout(60)
@pytest.mark.parametrize("columns", [50, 80])
def test_a_view_wider_than_the_terminal_says_so(terminal, columns):
    """On a terminal narrower than the driving view (a split pane of 50 columns) each row of
    the road wrapped, the right shoulder's cell drawn at the start of the next line, and
    nothing said that the window was too narrow (only a view too tall was told)."""
    import fcntl
    import struct

    from sumo_scenarios.human import describe, make_teacher

    master, slave = terminal
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 60, columns, 0, 0))
    person = Person(master, slave, [b"w"])
    out = open(slave, "w", encoding="utf-8", closefd=False)  # noqa: SIM115 - lives as long as the pty
    teacher = make_teacher(input=slave, output=out)
    obs = np.array([10.0, -25.0, 25.0, 0.0], dtype=np.float32)  # the ego on the right shoulder
    person.start()
    assert teacher(obs, {}) == 0
    shown = person.finish()
    wide = max(len(line) for line in describe(obs).splitlines())
    told = f"the view is {wide} columns wide, the window {columns}"
    assert (told in shown) == (columns < wide), shown[-800:]
    if columns < wide:
        assert "widen the window" in shown


@pytest.mark.timeout(60)
def test_waiting_for_a_key_leaves_the_programs_own_signal_handlers_as_they_were(terminal):
    """While a key is read, SIGTERM and SIGHUP at their default action get a handler that
    restores the terminal first; a program's own handler, or an ignored SIGHUP (nohup), is
    left alone, and after the read every handler is what it was."""
    master, slave = terminal
    own = []

    def handler(signum, frame):
        own.append(signum)

    old_term = signal.signal(signal.SIGTERM, handler)
    old_hup = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    during = []

    def look_then_press():  # while the key is awaited
        during.append((signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGHUP)))
        os.write(master, b"w")

    try:
        person = Person(master, slave, [look_then_press])
        out = open(slave, "w", encoding="utf-8", closefd=False)  # noqa: SIM115 - lives as long as the pty
        teacher = TerminalTeacher({"w": 0}, ("stay",), input=slave, output=out)
        person.start()
        assert teacher(np.zeros(1), {}) == 0
        person.finish()
        assert during == [(handler, signal.SIG_IGN)]
        assert signal.getsignal(signal.SIGTERM) is handler
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGTERM, old_term)
        signal.signal(signal.SIGHUP, old_hup)


@pytest.mark.timeout(60)
def test_a_terminal_on_a_file_descriptor_above_1023_is_read(terminal):
    """select.select() takes no file descriptor >= 1024 (FD_SETSIZE): a teacher whose terminal
    had such a number (a notebook kernel or a harness with many SUMO and log files open) raised
    ValueError "filedescriptor out of range in select()" at its first key. Typed-ahead keys,
    a lone Esc (the wait for an escape sequence's rest) and an arrow key are read there now."""
    import fcntl
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard != resource.RLIM_INFINITY and hard < 1100:
        pytest.skip(f"the hard limit on open files ({hard}) leaves no descriptor above 1023")
    master, slave = terminal
    if soft != resource.RLIM_INFINITY and soft < 1100:
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    try:
        high = fcntl.fcntl(slave, fcntl.F_DUPFD, 1024)  # the lowest free one >= 1024
        try:
            before = termios.tcgetattr(high)
            os.write(master, b"d")  # typed ahead: dropped
            time.sleep(0.1)
            person = Person(master, high, [b"\x1b", b"\x1b[D"])
            teacher = _teacher(high)
            person.start()
            assert teacher(OBS, {}) == 1
            shown = person.finish()
            assert "'Esc' is not a key here" in shown and "-> left" in shown
            assert termios.tcgetattr(high) == before
        finally:
            os.close(high)
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


@pytest.mark.timeout(60)
@pytest.mark.parametrize("refusal", [OSError(22, "Invalid argument"), ValueError("bad fd")])
def test_a_terminal_the_default_selector_refuses_is_read_with_select(
    terminal, monkeypatch, refusal
):
    """The teacher waits for a key with selectors.DefaultSelector (epoll on Linux, kqueue on
    macOS). kqueue refuses some terminal devices (/dev/tty among them): registering one
    raised that OSError at the first key, and teaching stopped. A refused registration now
    falls back to select() (selectors.SelectSelector, for descriptors below 1024)."""
    import selectors

    class Refuses(selectors.DefaultSelector):  # type: ignore[misc, valid-type]
        def register(self, fileobj, events, data=None):
            raise refusal

    monkeypatch.setattr(selectors, "DefaultSelector", Refuses)
    master, slave = terminal
    before = termios.tcgetattr(slave)
    person = Person(master, slave, [b"a", b"\x1b[C"])
    teacher = _teacher(slave)
    person.start()
    assert [teacher(OBS, {}), teacher(OBS, {})] == [1, 2]
    shown = person.finish()
    assert "-> left" in shown and "-> right" in shown
    assert termios.tcgetattr(slave) == before
