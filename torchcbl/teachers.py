"""Generic human-like timing for any teacher: reaction delay and slips of the hand.

A teacher is any callable ``teacher(observation, info) -> action``. :class:`HumanTiming` wraps one
and makes it answer like a person at a keyboard (paper Section 5: the teachers were people):

- **reaction delay**: when the wrapped teacher first asks for an action other than the default
  (``default_action``, e.g. "stay" or "forward"), the key is pressed only after a delay of
  ``k`` steps, ``k`` drawn per event from ``delay_probs`` (``delay_probs[k]`` = P(delay = k));
  meanwhile the default action is answered. When the key is due, what the wrapped teacher asks
  for THEN is pressed: another non-default action if it changed its mind, and nothing (the
  default action) if it no longer asks for one (the person saw the gap close and held back).
- **missed key press**: with probability ``miss_prob`` a due non-default press is lost (the
  default action is answered); if the wrapped teacher still asks for it at the next step, the
  person reacts again: a new press, with its own delay drawn from ``delay_probs``;
- **doubled key press**: with probability ``double_prob`` a non-default press repeats at the
  next step, whatever the wrapped teacher asks then.

As a correcting teacher (:meth:`HumanTiming.correct`, asked at every autonomous step by CBA and
HG-DAgger) the person corrects with a key press that differs from the learner's action: where
the learner does what the person wants nothing is pressed, and while a press is pending, or
after a lost one, there is none (until 2026-11-27 the default action answered then counted as a
correction, so a learner that did what the person wanted was "corrected" to the default). Where
the person wants the default action and the learner did another, there is no key to wait for:
the correction is the default, at once.

Everything is drawn from one seeded ``numpy`` generator, so the same seed and the same inputs give
the same answers. Consecutive calls are recognised through ``info["t"]`` (the env's step
counter): a gap (the learner drove on its own in between, or a new episode) drops any pending
press. An env whose info has no ``"t"`` makes every call a gap: delayed presses are then missed
presses and no press is doubled (HumanTiming warns once); give such an env a step counter first.
Domain-free: it knows nothing of what the actions mean.
"""

from __future__ import annotations

import numbers
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from torchcbl._signatures import refuse_unless_a_teacher

__all__ = ["HumanTiming", "HumanTimingConfig"]


@dataclass(frozen=True)
class HumanTimingConfig:
    """Parameters of :class:`HumanTiming` (probabilities per event; delays in steps).

    Attributes:
        default_action: the action answered while a press is pending (the "do nothing" key).
        delay_probs: ``delay_probs[k]`` is the probability of reacting ``k`` steps late.
            Default: 0 steps 0.35, 1 step 0.45, 2 steps 0.2 (a step of the driving domain is
            0.25 s: a 0.25-0.5 s reaction time, a person's; for another step length
            ``sumo_scenarios.teacher.timing_for_step_length`` counts the same times in its
            steps).
        miss_prob: probability that a due non-default press is lost.
        double_prob: probability that a non-default press is repeated at the next step.
    """

    default_action: int = 0
    delay_probs: tuple[float, ...] = (0.35, 0.45, 0.2)
    miss_prob: float = 0.03
    double_prob: float = 0.02

    def __post_init__(self) -> None:
        a = self.default_action
        if isinstance(a, (bool, np.bool_)) or not isinstance(a, (int, np.integer)) or a < 0:
            raise ValueError(f"default_action must be an action index (an int >= 0), got {a!r}")
        p = np.asarray(self.delay_probs, dtype=np.float64)
        if p.ndim != 1 or p.size == 0 or np.any(p < 0) or not np.isclose(p.sum(), 1.0):
            raise ValueError(
                f"delay_probs must be non-negative probabilities summing to 1 (P(delay = k) for "
                f"k = 0, 1, ...), got {self.delay_probs}"
            )
        for name in ("miss_prob", "double_prob"):
            v = getattr(self, name)
            # any real number (a numpy float or int too), not a bool
            real = isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))
            if not real or not 0.0 <= v < 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1), got {v!r}")
            object.__setattr__(self, name, float(v))
        # a tuple, whatever sequence was given: the config stays hashable, as a frozen one is
        object.__setattr__(self, "delay_probs", tuple(float(x) for x in p))


def _action_index(answer: Any, teacher: Any) -> int:
    """The wrapped teacher's answer as an int (a numpy int or a 0-d integer array or tensor,
    such as ``logits.argmax()``, too); anything else is refused, not rounded, as the loop
    refuses it from a bare teacher (its range is checked there, against the env's actions)."""
    value = answer
    if getattr(value, "ndim", None) == 0 and callable(getattr(value, "item", None)):
        value = value.item()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(
            f"HumanTiming: the wrapped teacher ({type(teacher).__name__}) answered {answer!r:.80}; "
            "expected an int action index (it is not rounded); make it return an int"
        )
    return int(value)


class HumanTiming:
    """Wrap ``teacher(observation, info) -> action`` with a reaction delay and slips.

    Args:
        teacher: the teacher to wrap.
        config: a :class:`HumanTimingConfig`.
        seed: seeds the timing draws.

    Attributes:
        n_delayed, n_missed, n_doubled: counts of each kind of event so far.

    Raises:
        TypeError: ``teacher`` is not callable, or its signature cannot take
            ``(observation, info)`` (a policy of the observation alone), or ``config`` is not
            a :class:`HumanTimingConfig`.
    """

    def __init__(
        self,
        teacher: Callable[[np.ndarray, dict], int],
        config: HumanTimingConfig | None = None,
        *,
        seed: int = 0,
    ) -> None:
        if not callable(teacher):
            raise TypeError(
                f"teacher must be callable (observation, info) -> action, got {teacher!r}"
            )
        # else it failed only at the session's first request
        refuse_unless_a_teacher(
            teacher, "HumanTiming", "HumanTiming(lambda obs, info: policy(obs))"
        )
        if config is not None and not isinstance(config, HumanTimingConfig):
            raise TypeError(
                f"config must be a HumanTimingConfig, got {type(config).__name__}; e.g. "
                "HumanTiming(teacher, HumanTimingConfig(miss_prob=0.05))"
            )
        self.teacher = teacher
        self.config = config or HumanTimingConfig()
        self._rng = np.random.default_rng(seed)
        self._delays = np.arange(len(self.config.delay_probs))
        p = np.asarray(self.config.delay_probs, dtype=np.float64)
        # the config accepts a sum within np.isclose of 1, numpy's choice only within ~1e-8:
        # normalised, as the config promises probabilities (a sum of exactly 1 is unchanged)
        self._probs = p / p.sum()
        self._pending: tuple[int, int] | None = None  # (action, steps left)
        self._double: int | None = None
        self._last_t: Any = None
        self._warned_no_t = False
        self.n_delayed = self.n_missed = self.n_doubled = 0

    def _press(self, action: int) -> int:
        cfg = self.config
        if self._rng.random() < cfg.miss_prob:
            self.n_missed += 1
            return cfg.default_action
        if self._rng.random() < cfg.double_prob:
            self._double = action
            self.n_doubled += 1
        return action

    def __call__(self, observation: np.ndarray, info: dict) -> int:
        """The wrapped teacher's action for ``observation`` [D], as the person would press it:
        a press may come ``k`` steps late (``delay_probs``), be lost or be repeated; while one
        is pending the answer is ``default_action`` (``info["t"]`` tells consecutive steps
        apart)."""
        cfg = self.config
        wanted = self._next_step(observation, info)
        if self._double is not None:
            action, self._double = self._double, None
            return action
        if self._pending is not None:
            _, left = self._pending
            if left > 1:
                self._pending = (self._pending[0], left - 1)
                return cfg.default_action
            self._pending = None
            if wanted == cfg.default_action:
                return wanted  # the person held back: the reason to press is gone
            return self._press(wanted)
        if wanted == cfg.default_action:
            return wanted
        return self._react(wanted)

    def _next_step(self, observation: np.ndarray, info: dict) -> int:
        """Advance to this call's step (a gap drops a pending or doubled press) and return
        the wrapped teacher's action."""
        t = info.get("t") if isinstance(info, dict) else None
        if t is None and not self._warned_no_t:
            self._warned_no_t = True
            warnings.warn(
                "HumanTiming: the info given to the teacher has no 't' (the env's step "
                "counter), so every call counts as the first of a new run of steps: a delayed "
                "press is lost and drawn again at the next call, and no press is doubled. Give "
                "the env a step counter (info['t'] = the step's index in its episode, e.g. in "
                "a gymnasium.Wrapper) to get the configured reaction times.",
                stacklevel=3,  # the caller of __call__ / correct
            )
        if t is None or self._last_t is None or t != self._last_t + 1:
            self._pending = None
            self._double = None
        self._last_t = t
        return _action_index(self.teacher(observation, info), self.teacher)

    def _react(self, wanted: int) -> int:
        """The person decides to press ``wanted`` (not the default): now, or after a drawn
        delay (the default is answered meanwhile)."""
        delay = int(self._rng.choice(self._delays, p=self._probs))
        if delay == 0:
            return self._press(wanted)
        self.n_delayed += 1
        self._pending = (wanted, delay)
        return self.config.default_action

    def correct(self, observation: np.ndarray, info: dict, action: int) -> int | None:
        """The person watching the learner's autonomous ``action`` (for strategies that take
        corrections: CBA, HG-DAgger; one call per step, this or :meth:`__call__`): a
        correction is a key press that differs from ``action``, else None.

        Where the learner does what the person wants, there is nothing to press (and no draw
        is made; a press decided earlier and still pending is dropped). Where the person wants
        another non-default action, they react as to a request: the press comes after a drawn
        delay (no correction meanwhile), may be lost, or repeated at the next step (a slip,
        which corrects if the learner then does otherwise). Where the person wants the default
        action (no key to wait for) and the learner did another, the correction is the default,
        at once."""
        cfg = self.config
        action = int(action)
        wanted = self._next_step(observation, info)
        if self._double is not None:  # the key pressed again: a slip of the hand
            pressed, self._double = self._double, None
            return None if pressed == action else pressed
        if wanted == action:
            self._pending = None  # the reason to press is gone
            return None
        if wanted == cfg.default_action:
            self._pending = None
            return wanted
        if self._pending is not None:
            _, left = self._pending
            if left > 1:
                self._pending = (self._pending[0], left - 1)
                return None
            self._pending = None
            return self._correction(self._press(wanted), wanted)
        return self._correction(self._react(wanted), wanted)

    def _correction(self, answer: int, wanted: int) -> int | None:
        # the key press, if one landed (not a lost one, not one still pending)
        return wanted if answer == wanted else None

    def stats(self) -> dict[str, int]:
        """Counts of delayed, missed and doubled presses so far."""
        return {"delayed": self.n_delayed, "missed": self.n_missed, "doubled": self.n_doubled}
