"""torchcbl: confidence-based learning from demonstration with Gaussian mixture sets.

Reproduces and extends Chernova & Veloso, "Confidence-Based Policy Learning from Demonstration
Using Gaussian Mixture Models" (AAMAS 2007). The core is domain-free: it never imports a
simulator. See ``docs/architecture.md`` for how the parts fit together.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

if TYPE_CHECKING:  # pragma: no cover
    # The names of _EXPORTS, for type checkers, which cannot see through __getattr__ (without
    # these every public name was Any to a user's mypy or pyright); "X as X" marks each as
    # exported (PEP 484), as __all__ is built at run time.
    from torchcbl.confidence import AutoThresholdRule as AutoThresholdRule
    from torchcbl.confidence import ConfidenceRule as ConfidenceRule
    from torchcbl.confidence import DistanceRule as DistanceRule
    from torchcbl.confidence import PosteriorRule as PosteriorRule
    from torchcbl.errors import CorruptSessionError as CorruptSessionError
    from torchcbl.errors import EnvError as EnvError
    from torchcbl.errors import IncompatibleRunDirError as IncompatibleRunDirError
    from torchcbl.errors import SessionLockedError as SessionLockedError
    from torchcbl.errors import SessionWriteError as SessionWriteError
    from torchcbl.errors import TeacherError as TeacherError
    from torchcbl.errors import TeachingInterrupted as TeachingInterrupted
    from torchcbl.gmm import Classification as Classification
    from torchcbl.gmm import FitReport as FitReport
    from torchcbl.gmm import GaussianMixtureSet as GaussianMixtureSet
    from torchcbl.human import TerminalTeacher as TerminalTeacher
    from torchcbl.policy import EpisodeResult as EpisodeResult
    from torchcbl.policy import GreedyPolicy as GreedyPolicy
    from torchcbl.policy import episode_results as episode_results
    from torchcbl.policy import evaluate_policy as evaluate_policy
    from torchcbl.records import CorrectionRecord as CorrectionRecord
    from torchcbl.records import StepRecord as StepRecord
    from torchcbl.session import SessionSummary as SessionSummary
    from torchcbl.session import describe as describe
    from torchcbl.session import load_corrections as load_corrections
    from torchcbl.session import load_model as load_model
    from torchcbl.session import load_models as load_models
    from torchcbl.session import load_policy as load_policy
    from torchcbl.session import load_records as load_records
    from torchcbl.strategies import ConfidentExecution as ConfidentExecution
    from torchcbl.strategies.cba import ConfidenceBasedAutonomy as ConfidenceBasedAutonomy
    from torchcbl.teaching import ConfidentTeacher as ConfidentTeacher
    from torchcbl.teaching import TeachingConfig as TeachingConfig

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
    "load_models": "torchcbl.session",
    "load_records": "torchcbl.session",
    "load_corrections": "torchcbl.session",
    "describe": "torchcbl.session",
    "SessionSummary": "torchcbl.session",
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
