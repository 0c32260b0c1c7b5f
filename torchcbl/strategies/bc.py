"""Behaviour cloning on non-interactive demonstrations (the baseline every method must beat).

The teacher drives and labels every step; the learner (the same Gaussian mixture set as the
other strategies, refitted every ``TeachingConfig.max_new`` labels) only watches. The label
budget is the caller's stop criterion (``run(max_demonstrations=N)``): N demonstrations along
the teacher's own trajectory, as in ``imitation``'s BC or the paper's non-interactive arm.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from torchcbl.strategies._phased import Decision, _StrategyDefaults

if TYPE_CHECKING:  # pragma: no cover
    from torchcbl.gmm import Classification

__all__ = ["BehaviourCloning"]


class BehaviourCloning(_StrategyDefaults):
    """Ask at every step and execute the teacher's action (no interaction, no state).

    Every step is recorded with phase ``"noninteractive"`` (asked by design).

    Hooks: ``decide`` always asks (phase ``"noninteractive"``) and ``actor`` always answers
    ``"teacher"``; ``bind`` notes the sizes only, and ``episode_start``, ``observe_label``,
    ``observe_step`` and ``observe_refit`` keep nothing (the loop refits the model on the
    labels itself). It works unbound."""

    @property
    def phase(self) -> str:
        """The phase of the next step: always ``"noninteractive"``."""
        return "noninteractive"

    def decide(self, observation: np.ndarray, c: Classification) -> Decision:
        """Always asks, phase ``"noninteractive"``."""
        return Decision(True, "noninteractive")

    def actor(
        self, decision: Decision, model_action: int, teacher_action: int | None
    ) -> Literal["teacher", "agent"]:
        """Always ``"teacher"``."""
        return "teacher"

    def to_config(self) -> dict[str, Any]:
        return {"type": "BehaviourCloning", "relabel": False}

    def __repr__(self) -> str:
        return "BehaviourCloning()"
