"""A scripted driving expert with human-like inconsistency (the teacher of Section 5.2).

Preferences (consistent, as a human's are): the expert's home is the left lane (SUMO lane 3).
When a slower car ahead closes in, it passes on the left shoulder (4) (with ``middle_pass``, in
the middle lane (2) instead when that lane is visibly free: no car within ``[-min_gap_m, 25]``
m); once the passed car is behind it returns home. From the right lane or shoulder, where it only
ends up to escape when everything to its left is blocked, it drifts back left as soon as it is
safe. It never lets a car get within ``min_gap_m`` of it in its own lane (so, as in the paper's
Figure 7, no demonstration has a car within +-10 m in the ego's lane).

Human-like inconsistency: the exact MOMENT of a lane change varies inside the window where it is
safe. For every event (a car closing in ahead, a passed car falling behind) the expert draws a
fresh uniform ``u`` (seeded RNG) and acts when the gap crosses a threshold placed by ``u``
inside the safe window: it starts a change when the car ahead is between the last safe gap and
``change_far_m``; it returns home when the passed car is ``min_gap_m`` to
``min_gap_m + return_spread_m`` behind. A per-event threshold, unlike a constant per-step
probability, keeps the decision learnable: the share of demonstrations that change lane grows
with the urgency, so the majority label flips in the middle of the window instead of never.

It reads privileged information from ``info`` (every car's exact relative position and its lane's
closing speed); what it decides on is also visible, up to clipping, in the observation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from sumo_scenarios.env import LEFT, RIGHT, SENSE_RANGE_M, STAY
from sumo_scenarios.scenarios import N_LANES, _is_real

__all__ = [
    "HOME_LANE",
    "ExpertConfig",
    "ScriptedExpert",
]

HOME_LANE = 3
"""The expert's preferred lane (the left normal lane)."""


@dataclass(frozen=True)
class ExpertConfig:
    """Settings of :class:`ScriptedExpert` (distances in metres, centre to centre).

    Attributes:
        min_gap_m: never have a car closer than this in the ego's own lane.
        change_far_m: the farthest gap to the car ahead at which a change may start (the window
            of a change runs from here down to the last safe gap).
        enter_ahead_m: enter a lane only if the nearest car ahead in it will be at least this far.
        return_spread_m: a passed car must be ``min_gap_m`` plus up to this much (drawn per
            event) behind before the expert moves back into its lane.
        middle_pass: pass in a visibly free middle lane (else always on the left shoulder).
            Off by default: passing in the dense middle lane often ends in an escape to the
            right lane or shoulder (8-14 % of the expert's time there, 0.3 % contact), and the
            learned policies then stayed erratic within the 650-demonstration budget.
    """

    min_gap_m: float = 10.0
    change_far_m: float = 24.0
    enter_ahead_m: float = 16.0
    return_spread_m: float = 4.0
    middle_pass: bool = False

    def __post_init__(self) -> None:
        for name in ("min_gap_m", "change_far_m", "enter_ahead_m", "return_spread_m"):
            v = getattr(self, name)
            if not _is_real(v) or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number of metres, got {v!r}")
            object.__setattr__(self, name, float(v))  # plain, JSON-able (a numpy float too)
        if not 5.0 <= self.min_gap_m < self.enter_ahead_m <= self.change_far_m <= SENSE_RANGE_M:
            raise ValueError(
                "need 5 <= min_gap_m < enter_ahead_m <= change_far_m <= 25 (metres; 25 is the "
                f"sensing range), got min_gap_m={self.min_gap_m!r}, "
                f"enter_ahead_m={self.enter_ahead_m!r}, change_far_m={self.change_far_m!r}"
            )
        if not (math.isfinite(self.return_spread_m) and self.return_spread_m >= 0):
            raise ValueError(
                f"return_spread_m must be a finite distance >= 0 m, got {self.return_spread_m!r}"
            )
        if not isinstance(self.middle_pass, (bool, np.bool_)):
            raise ValueError(f"middle_pass must be True or False, got {self.middle_pass!r}")
        object.__setattr__(self, "middle_pass", bool(self.middle_pass))


class ScriptedExpert:
    """``teacher(observation, info) -> action`` for :class:`~sumo_scenarios.env.DrivingEnv`.

    Args:
        config: the expert's thresholds.
        seed: seed of the timing RNG (same seed + same inputs -> same actions).
    """

    def __init__(self, config: ExpertConfig | None = None, *, seed: int = 0) -> None:
        if config is not None and not isinstance(config, ExpertConfig):
            raise TypeError(
                f"config must be an ExpertConfig, got {type(config).__name__}; e.g. "
                "ScriptedExpert(ExpertConfig(min_gap_m=12.0))"
            )
        self.config = config or ExpertConfig()
        self._rng = np.random.default_rng(seed)
        self._u = float(self._rng.random())
        self._last: tuple[int, int | None, float] | None = None  # (lane, t, gap ahead)

    def _new_event(self) -> None:
        self._u = float(self._rng.random())

    def __call__(self, observation: np.ndarray, info: dict[str, Any]) -> int:
        """The expert's action (0 stay, 1 left, 2 right) for a :class:`DrivingEnv` observation
        [4] (metres, metres, metres, lane index) and its info (the expert reads the lane and
        the cars' positions relative to the ego, ``info["car_rel_m"]``, metres)."""
        try:
            lane = int(info["lane"])
            rel = np.asarray(info["car_rel_m"], dtype=np.float64)
            car_lane = np.asarray(info["car_lane"])
            car_closing = np.asarray(info["car_closing_ms"], dtype=np.float64)
            dt = float(info["step_length_s"])
        except KeyError as err:
            raise ValueError(f"the expert needs DrivingEnv's info, missing {err}") from None
        t = info.get("t")
        cfg = self.config

        def cars(lx: int) -> tuple[np.ndarray, np.ndarray]:
            m = car_lane == lx
            return rel[m], car_closing[m] * dt

        def can_enter(lx: int, ahead: float, behind: float = cfg.min_gap_m) -> bool:
            if not 0 <= lx < N_LANES:
                return False
            r, c = cars(lx)
            nxt = r - c  # where the cars will be, relative to us, after this step
            return not np.any((nxt > -behind) & (nxt < ahead))

        r, cc = cars(lane)
        ahead = r[r > 0]
        gap = float(ahead.min()) if ahead.size else np.inf
        c = float(cc[r > 0][np.argmin(ahead)]) if ahead.size else 0.0
        # A new event: another lane, a gap in the decisions, or a new car ahead.
        last = self._last
        if (
            last is None
            or last[0] != lane
            or t is None
            or last[1] is None
            or t != last[1] + 1
            or gap > last[2] + 1.0
        ):
            self._new_event()
        self._last = (lane, t, gap)

        last_safe = cfg.min_gap_m + 2 * c  # staying past this gap leaves no safe step
        forced = gap < last_safe
        trigger = last_safe + self._u * max(cfg.change_far_m - last_safe, 0.0)
        if gap <= trigger:
            order = [lane + 1, lane - 1]
            if lane == HOME_LANE and cfg.middle_pass and can_enter(2, SENSE_RANGE_M):
                order = [2, 4]
            for lx in order:
                if can_enter(lx, cfg.enter_ahead_m):
                    return LEFT if lx > lane else RIGHT
            if forced:
                for lx in order:
                    if can_enter(lx, cfg.min_gap_m):
                        return LEFT if lx > lane else RIGHT
            return STAY
        if lane == HOME_LANE:
            return STAY
        # Away from home and not pressed: head home once the lane there is clear far enough.
        target = lane - 1 if lane > HOME_LANE else lane + 1
        behind = cfg.min_gap_m + self._u * cfg.return_spread_m
        if can_enter(target, cfg.enter_ahead_m, behind):
            return LEFT if target > lane else RIGHT
        return STAY
