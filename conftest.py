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
