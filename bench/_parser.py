"""The bench scripts' argument parser: a usage mistake is one line and exit code 2, as with the
``torchcbl`` command (argparse's own prints its usage block first)."""

from __future__ import annotations

import argparse
from typing import NoReturn


class Parser(argparse.ArgumentParser):
    """argparse with the script's whole docstring as its --help text and one-line errors."""

    def __init__(self, doc: str | None) -> None:
        super().__init__(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}; see {self.prog} --help\n")
