"""``python -m torchcbl``: the ``torchcbl`` command, for an environment whose scripts are not
on the PATH. Unlike the console script it imports modules from the current directory (Python
puts it first on ``sys.path`` for ``-m``; docs/benchmark.md, "Environments and teachers")."""

from __future__ import annotations

import sys

from torchcbl.cli import main

if __name__ == "__main__":
    sys.exit(main())
