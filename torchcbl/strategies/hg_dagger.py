"""HG-DAgger (Kelly et al., ICRA 2019): the teacher gates, taking over where the learner errs.

In HG-DAgger a human watches the learner drive and takes the controls when it does something
they would not do; only the states the human drives through are labelled, and the human hands
control back when satisfied. On this loop's discrete steps:

1. ``warmup`` demonstrations first (the teacher drives; HG-DAgger starts from a BC policy).
2. The learner drives. After each of its steps the teacher is offered to correct it (the
   loop's ``correct()``; a scripted teacher is wrapped with
   :func:`torchcbl.strategies.correcting`, which corrects when its own action differs).
   A correction is a label for the state the learner just acted in, and the teacher takes over.
3. While the teacher is in control it labels and executes every step; it hands back after the
   first step at which the learner's prediction (made before that label) equals its own.

Difference from a human gate: the gate sees the learner's action *after* it ran (the loop has
no look-ahead), so one wrong action is executed before each takeover, like a human's reaction
time. The teacher must watch every autonomous step: the benchmark counts those as monitored
steps (attention), though only corrections and takeover steps are labels. Control is not given
back at an episode boundary (the teacher keeps driving until the learner agrees), which keeps
the state a function of the labels alone (resume replays them in a different order than the
live run delivers them).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from torchcbl.strategies._phased import Decision, LabelKind, _plain, _StrategyDefaults

if TYPE_CHECKING:  # pragma: no cover
    from torchcbl.gmm import Classification

__all__ = ["HGDAgger"]


class HGDAgger(_StrategyDefaults):
    """Teacher-gated DAgger: learner drives; the teacher takes over when it disagrees.

    Args:
        warmup: demonstrations the teacher gives before the learner first drives (>= 0).

    Hooks (its state is the label count and whether the teacher is in control, a function
    of the labels alone):

    - ``bind``: no labels, the learner in control.
    - ``decide``: asks during the warmup (phase ``"noninteractive"``); then (phase
      ``"confident"``) asks where no model exists or while the teacher is in control.
    - ``actor``: the teacher on asked steps, the learner otherwise.
    - ``observe_label``: counts the label (the warmup); a correction (``kind="correction"``)
      hands control to the teacher; while the teacher is in control after the warmup, a
      demonstration equal to the learner's prediction (``model_action == action``) hands it
      back.
    - ``episode_start``, ``observe_step``, ``observe_refit``: keep nothing (control is not
      handed back at an episode's end).
    """

    wants_corrections = True
    _INIT_SETS = ("warmup", "_labels", "_control")

    def __init__(self, warmup: int = 10) -> None:
        warmup = _plain(warmup)
        if isinstance(warmup, bool) or not isinstance(warmup, int) or warmup < 0:
            raise ValueError(f"HGDAgger: warmup must be an int >= 0, got {warmup!r}")
        self.warmup = warmup
        self._labels = 0
        self._control = False

    def bind(self, *, n_actions: int, n_features: int, config: Any) -> None:
        """No labels, the learner in control (``config`` is not read)."""
        super().bind(n_actions=n_actions, n_features=n_features, config=config)
        self._labels = 0  # a session (new or resumed) replays its log from here
        self._control = False

    @property
    def teacher_in_control(self) -> bool:
        """Whether the teacher drives the next step (after a correction, until agreement)."""
        return self._control

    @property
    def phase(self) -> str:
        """The phase of the next step: ``"noninteractive"`` during the warmup, then
        ``"confident"``."""
        return "noninteractive" if self._labels < self.warmup else "confident"

    def decide(self, observation: np.ndarray, c: Classification) -> Decision:
        """Asks during the warmup; then where no model exists or while the teacher is in
        control.

        Raises:
            ValueError: ``observation`` is not one observation [D] (of the bound
                ``n_features``), or ``c`` is not of batch 1.
        """
        self._check_decide(observation, c)  # [D] and a c of batch 1, read at row 0
        if self._labels < self.warmup:
            return Decision(True, "noninteractive")
        return Decision(int(c.action[0]) < 0 or self._control, "confident")

    def _track_label(
        self, observation: np.ndarray, action: int, *, model_action: int, kind: LabelKind
    ) -> None:
        warm = self._labels < self.warmup
        self._labels += 1
        if kind == "correction":
            self._control = True
        elif self._control and not warm:
            self._control = int(model_action) != int(action)

    def to_config(self) -> dict[str, Any]:
        return {"type": "HGDAgger", "warmup": self.warmup, "relabel": False}

    def __repr__(self) -> str:
        return f"HGDAgger(warmup={self.warmup})"
