"""Settings for every pytest run in this repository (tests/ and notebooks/)."""

from __future__ import annotations

import pytest


@pytest.hookimpl(tryfirst=True)
def pytest_terminal_summary(config: pytest.Config) -> None:
    # nbmake ends every run with an advertisement for itself, printed from this same hook when
    # its --nbmake option is on. By now every notebook has been collected and run, so the option
    # is turned off before nbmake's hook reads it; pytest's own summary is unchanged.
    if getattr(config.option, "nbmake", False):
        config.option.nbmake = False
