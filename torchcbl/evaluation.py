"""Small domain-free helpers the experiments share: summary statistics and provenance."""

from __future__ import annotations

import platform
from collections.abc import Iterable

import numpy as np

__all__ = ["mean_sd", "run_versions"]


def mean_sd(values: Iterable[float | None]) -> dict[str, float | int | None]:
    """Mean, sample standard deviation (ddof=1) and count of ``values``.

    None entries (e.g. a baseline that never learned) are left out and not counted; with no
    value left, mean and sd are None; with one value, sd is None (a spread needs two).
    """
    v = [float(x) for x in values if x is not None]
    if not v:
        return {"mean": None, "sd": None, "n": 0}
    return {
        "mean": float(np.mean(v)),
        "sd": float(np.std(v, ddof=1)) if len(v) > 1 else None,
        "n": len(v),
    }


def run_versions(**extra: str) -> dict[str, str]:
    """Versions of Python and the core's dependencies, plus ``extra`` (a domain's simulator),
    for a results.json to say what produced it."""
    import gymnasium
    import torch

    import torchcbl

    return {
        "python": platform.python_version(),
        "torchcbl": torchcbl.__version__,
        "torch": torch.__version__,
        "numpy": np.__version__,
        "gymnasium": gymnasium.__version__,
        **extra,
    }
