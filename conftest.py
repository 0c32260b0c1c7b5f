"""Settings for every pytest run in this repository (tests/ and notebooks/)."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Generator
from pathlib import Path

import pytest


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Generator[None, object, object]:
    """A notebook (run by nbmake) gets a temporary directory of its own as ``TMPDIR``, and fails
    if it leaves anything in it: a notebook run leaves nothing behind in /tmp."""
    if item.path.suffix != ".ipynb":
        return (yield)
    private = Path(tempfile.mkdtemp(prefix="torchcbl-notebook-"))
    saved = os.environ.get("TMPDIR")
    os.environ["TMPDIR"] = str(private)  # read by the kernel nbmake starts now
    try:
        result = yield
    finally:
        if saved is None:
            os.environ.pop("TMPDIR", None)
        else:
            os.environ["TMPDIR"] = saved
        left = sorted(p.name for p in private.iterdir())
        shutil.rmtree(private, ignore_errors=True)
    if left:
        raise AssertionError(
            f"{item.path.name} left {left} in its temporary directory; a notebook must remove "
            "what it writes there (tempfile.TemporaryDirectory and a last cell calling cleanup())"
        )
    return result


@pytest.hookimpl(tryfirst=True)
def pytest_terminal_summary(config: pytest.Config) -> None:
    # nbmake ends every run with an advertisement for itself, printed from this same hook when
    # its --nbmake option is on. By now every notebook has been collected and run, so the option
    # is turned off before nbmake's hook reads it; pytest's own summary is unchanged.
    if getattr(config.option, "nbmake", False):
        config.option.nbmake = False


def _ctrl_c_as_at_a_terminal() -> None:
    """The tests press Ctrl-C as a person at a terminal does, which Python turns into
    KeyboardInterrupt. A test run started in the background by a shell without job control
    (``cmd &`` in a script, nohup) inherits SIGINT ignored, as POSIX has it, and Python then
    keeps it ignored: every real-Ctrl-C test failed with "DID NOT RAISE KeyboardInterrupt"
    (two fresh-clone runs started so on 2026-11-27, and likely the flake seen the night
    before; the CI's foreground runs passed). Python's
    own handler is installed for the run in that case."""
    import signal

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


_ctrl_c_as_at_a_terminal()


def _sigint_state() -> tuple[object, ...]:
    """What decides whether a Ctrl-C raises KeyboardInterrupt in this process: the handler
    behind torchcbl's hook, torchcbl's hold depth and held signal, and the main thread's mask."""
    import signal
    import sys

    handler = signal.getsignal(signal.SIGINT)
    handler = getattr(handler, "torchcbl_chained", handler)
    session = sys.modules.get("torchcbl.session")
    hold = (session._hold_depth, list(session._held)) if session is not None else (0, [])
    blocked = signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    return handler, *hold, blocked


@pytest.fixture(autouse=True)
def _ctrl_c_left_as_found(request: pytest.FixtureRequest) -> Generator[None, None, None]:
    """A test that leaves Ctrl-C handled otherwise than it found it fails, naming what changed,
    and the state is put back."""
    import signal
    import sys

    before = _sigint_state()
    yield
    after = _sigint_state()
    if after == before:
        return
    signal.signal(signal.SIGINT, before[0])  # type: ignore[arg-type]
    session = sys.modules.get("torchcbl.session")
    if session is not None:
        session._hold_depth, session._held[:] = before[1], before[2]
    if after[3] != before[3]:
        how = signal.SIG_UNBLOCK if not before[3] else signal.SIG_BLOCK
        signal.pthread_sigmask(how, [signal.SIGINT])
    names = ("SIGINT handler", "torchcbl hold depth", "held signal", "SIGINT blocked")
    pairs = zip(names, before, after, strict=True)
    changed = [f"{n}: {b!r} -> {a!r}" for n, b, a in pairs if a != b]
    pytest.fail(f"{request.node.nodeid} left Ctrl-C handling changed: {'; '.join(changed)}")
