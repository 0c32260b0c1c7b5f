"""torchcbl: confidence-based learning from demonstration with Gaussian mixture sets.

Reproduces and extends Chernova & Veloso, "Confidence-Based Policy Learning from Demonstration
Using Gaussian Mixture Models" (AAMAS 2007). The core is domain-free: it never imports a
simulator. See ``docs/architecture.md`` for how the parts fit together.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

# Public names, loaded on first use so `import torchcbl` stays light.
_EXPORTS = {
    "GaussianMixtureSet": "torchcbl.gmm",
    "Classification": "torchcbl.gmm",
    "FitReport": "torchcbl.gmm",
    "ConfidenceRule": "torchcbl.confidence",
    "DistanceRule": "torchcbl.confidence",
    "PosteriorRule": "torchcbl.confidence",
    "AutoThresholdRule": "torchcbl.confidence",
    "StepRecord": "torchcbl.records",
    "ConfidentExecution": "torchcbl.strategies",
    "ConfidenceBasedAutonomy": "torchcbl.strategies.cba",
    "ConfidentTeacher": "torchcbl.teaching",
    "TeachingConfig": "torchcbl.teaching",
    "evaluate_policy": "torchcbl.policy",
    "episode_results": "torchcbl.policy",
    "EpisodeResult": "torchcbl.policy",
    "GreedyPolicy": "torchcbl.policy",
    "CorrectionRecord": "torchcbl.records",
    "TeacherError": "torchcbl.errors",
    "EnvError": "torchcbl.errors",
    "load_policy": "torchcbl.session",
    "load_model": "torchcbl.session",
    "load_records": "torchcbl.session",
    "load_corrections": "torchcbl.session",
    "IncompatibleRunDirError": "torchcbl.errors",
    "CorruptSessionError": "torchcbl.errors",
    "SessionLockedError": "torchcbl.errors",
    "SessionWriteError": "torchcbl.errors",
    "TerminalTeacher": "torchcbl.human",
    "TeachingInterrupted": "torchcbl.errors",
}

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'torchcbl' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
