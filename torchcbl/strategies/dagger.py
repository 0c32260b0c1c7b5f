"""DAgger (Ross, Gordon & Bagnell, AISTATS 2011) for a discrete-action GMM learner.

The teacher labels every visited state. The executed action is the teacher's with probability
``beta``, else the learner's (the mixture policy of the paper's Algorithm 3.1). ``beta`` decays
geometrically per DAgger iteration, the paper's ``beta_i = p^(i-1)`` schedule::

    beta(step) = beta0 * decay ** (step // iteration_steps)

with ``step`` the 0-based index of the step in the session: iteration 1 is the first
``iteration_steps`` steps, iteration 2 the next ones, and so on. The learner refits on all the
labels so far, every ``TeachingConfig.max_new`` labels (more often than the paper's one refit
per iteration: the loop's refit schedule is shared by every strategy, so the comparison is fair).

The coin of step ``t`` is ``default_rng(SeedSequence([seed, t])).random()``: a function of the
seed and the step only, so a resumed session draws the same coins as an uninterrupted one.
With ``beta0 = 1, decay = 1`` DAgger is behaviour cloning on the teacher's trajectory; with
``beta0 = 0`` the learner drives from its first fit on (the teacher still labels every state).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from torchcbl.strategies._phased import Decision, _plain, _StrategyDefaults

if TYPE_CHECKING:  # pragma: no cover
    from torchcbl.gmm import Classification
    from torchcbl.records import StepRecord

__all__ = ["DAgger"]


def _unit(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 1:
        raise ValueError(f"DAgger: {name} must be a number in [0, 1], got {value!r}")
    return float(value)


class DAgger(_StrategyDefaults):
    """Label every state; execute the teacher's action with probability ``beta(step)``.

    Args:
        beta0: beta of the first iteration, in [0, 1] (the paper: 1).
        decay: beta's factor per iteration, in [0, 1] (the paper's ``p``; 0.5 by default).
        iteration_steps: steps per DAgger iteration (>= 1).
        seed: seeds the per-step coins.

    Hooks (its only state is the session's step count, which sets the beta and the coin):

    - ``bind``: the step count back to 0 (a session, new or resumed, replays its log).
    - ``decide``: always asks (every state is labelled), phase ``"noninteractive"``;
      ``Decision.state`` is the step's 0-based session index.
    - ``actor``: ``"teacher"`` where no model exists or ``coin(step) < beta(step)``, else
      ``"agent"`` (the label is recorded either way).
    - ``observe_step``: the step count becomes ``record.step + 1``, so the next step's beta
      and coin are those of the next index (replayed steps too).
    - ``episode_start``, ``observe_label``, ``observe_refit``: keep nothing (the loop refits
      the model on all labels itself).
    """

    _INIT_SETS = ("beta0", "decay", "iteration_steps", "seed", "_steps")

    def __init__(
        self,
        beta0: float = 1.0,
        decay: float = 0.5,
        iteration_steps: int = 50,
        seed: int = 0,
    ) -> None:
        beta0, decay, iteration_steps, seed = map(_plain, (beta0, decay, iteration_steps, seed))
        self.beta0 = _unit("beta0", beta0)
        self.decay = _unit("decay", decay)
        if isinstance(iteration_steps, bool) or not isinstance(iteration_steps, int):
            raise ValueError(
                f"DAgger: iteration_steps must be an int >= 1, got {iteration_steps!r}"
            )
        if iteration_steps < 1:
            raise ValueError(
                f"DAgger: iteration_steps must be an int >= 1, got {iteration_steps!r}"
            )
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"DAgger: seed must be an int >= 0, got {seed!r}")
        self.iteration_steps = iteration_steps
        self.seed = int(seed)
        self._steps = 0

    def bind(self, *, n_actions: int, n_features: int, config: Any) -> None:
        """The step count back to 0 (``config`` is not read)."""
        super().bind(n_actions=n_actions, n_features=n_features, config=config)
        self._steps = 0  # a session (new or resumed) replays its log from here

    def beta(self, step: int) -> float:
        """Probability that the teacher's action runs at 0-based session step ``step``."""
        return self.beta0 * self.decay ** (step // self.iteration_steps)

    def coin(self, step: int) -> float:
        """The uniform [0, 1) draw of step ``step`` (the teacher acts iff coin < beta)."""
        return float(np.random.default_rng(np.random.SeedSequence([self.seed, step])).random())

    @property
    def phase(self) -> str:
        """The phase of the next step: always ``"noninteractive"`` (every state is labelled)."""
        return "noninteractive"

    def decide(self, observation: np.ndarray, c: Classification) -> Decision:
        """Always asks, phase ``"noninteractive"``; ``Decision.state`` is the step's index."""
        return Decision(True, "noninteractive", self._steps)

    def actor(
        self, decision: Decision, model_action: int, teacher_action: int | None
    ) -> Literal["teacher", "agent"]:
        """``"teacher"`` where no model exists (``model_action < 0``) or
        ``coin(step) < beta(step)``, else ``"agent"``."""
        step = int(decision.state)
        if model_action < 0 or self.coin(step) < self.beta(step):
            return "teacher"
        return "agent"

    def _track_step(self, record: StepRecord, decision: Decision | None) -> None:
        self._steps = record.step + 1

    def to_config(self) -> dict[str, Any]:
        return {
            "type": "DAgger",
            "beta0": self.beta0,
            "decay": self.decay,
            "iteration_steps": self.iteration_steps,
            "seed": self.seed,
            "relabel": False,
        }

    def __repr__(self) -> str:
        return (
            f"DAgger(beta0={self.beta0}, decay={self.decay}, "
            f"iteration_steps={self.iteration_steps}, seed={self.seed})"
        )
