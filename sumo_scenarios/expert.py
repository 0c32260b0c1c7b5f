"""A scripted driving expert with human-like inconsistency (the teacher of Section 5.2).

The expert prefers the left lane (SUMO lane 3), passes slower cars on the left shoulder (lane 4),
or in the middle lane (2) when that lane is wide open, and uses the right lane and right shoulder
only to escape when the lanes to its left are blocked. It never lets a car get within
``min_gap_m`` of it in its own lane (so, as in the paper's Figure 7, no demonstration has a car
within +-10 m in the ego's lane).

Human-like inconsistency: a lane change that is allowed but not yet necessary happens with
probability ``hazard`` per timestep (a seeded RNG), so its exact moment varies inside the window
where it is safe; it is forced at the last safe timestep.

It reads privileged information from ``info`` (every car's exact relative position and its lane's
closing speed); everything it decides on is also visible, up to clipping, in the observation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sumo_scenarios.env import LEFT, RIGHT, STAY
from sumo_scenarios.scenarios import N_LANES


@dataclass(frozen=True)
class ExpertConfig:
    """Settings of :class:`ScriptedExpert` (distances in metres, centre to centre).

    Attributes:
        min_gap_m: never have a car closer than this in the ego's own lane.
        open_m: a car ahead in the ego's lane closer than this opens the window to change lane.
        enter_ahead_m: enter a lane only if the nearest car ahead in it will be at least this far.
        clear_m: the middle lane counts as "wide open" (usable for passing) with no car within
            ``[-min_gap_m, clear_m]`` (beyond the 25 m sensing range: privileged look-ahead).
        middle_share: probability of passing in a wide-open middle lane instead of on the left
            shoulder.
        hazard: probability per timestep of making an allowed, not yet forced, lane change.
    """

    min_gap_m: float = 10.0
    open_m: float = 22.0
    enter_ahead_m: float = 16.0
    clear_m: float = 45.0
    middle_share: float = 0.5
    hazard: float = 0.4

    def __post_init__(self) -> None:
        if not 0.0 < self.hazard <= 1.0:
            raise ValueError("hazard must lie in (0, 1]")
        if not 5.0 <= self.min_gap_m < self.enter_ahead_m <= self.open_m + 10.0:
            raise ValueError("need 5 <= min_gap_m < enter_ahead_m <= open_m + 10")


class ScriptedExpert:
    """``teacher(observation, info) -> action`` for :class:`~sumo_scenarios.env.DrivingEnv`.

    Args:
        config: the expert's thresholds.
        seed: seed of the timing RNG (same seed + same inputs -> same actions).
    """

    def __init__(self, config: ExpertConfig | None = None, *, seed: int = 0) -> None:
        self.config = config or ExpertConfig()
        self._rng = np.random.default_rng(seed)

    def __call__(self, observation: np.ndarray, info: dict[str, Any]) -> int:
        try:
            lane = int(info["lane"])
            rel = np.asarray(info["car_rel_m"], dtype=np.float64)
            car_lane = np.asarray(info["car_lane"])
            closing = info["closing_speed_ms"]
            dt = float(info["step_length_s"])
        except KeyError as err:
            raise ValueError(f"the expert needs DrivingEnv's info, missing {err}") from None
        cfg = self.config

        def cars(lx: int) -> tuple[np.ndarray, float]:
            if lx not in closing:
                return np.zeros(0), 0.0
            return rel[car_lane == lx], closing[lx] * dt

        def can_enter(lx: int, ahead: float) -> bool:
            if not 0 <= lx < N_LANES:
                return False
            r, c = cars(lx)
            nxt = r - c  # where the cars will be, relative to us, after this step
            return not np.any((nxt > -cfg.min_gap_m) & (nxt < ahead))

        r, c = cars(lane)
        ahead = r[r > 0]
        gap = float(ahead.min()) if ahead.size else np.inf
        forced = gap - 2 * c < cfg.min_gap_m  # staying now leaves no safe step after this one
        threatened = gap <= cfg.open_m
        chance = self._rng.random() < cfg.hazard

        if threatened and (forced or chance):
            if lane == 3 and chance and self._rng.random() < cfg.middle_share:
                if can_enter(2, cfg.clear_m):
                    return RIGHT  # the middle lane is wide open: pass there this time
            if can_enter(lane + 1, cfg.enter_ahead_m):
                return LEFT
            if can_enter(lane - 1, cfg.enter_ahead_m):
                return RIGHT
            if forced and can_enter(lane - 1, cfg.min_gap_m):
                return RIGHT
            if forced and can_enter(lane + 1, cfg.min_gap_m):
                return LEFT
            return STAY
        if threatened:
            return STAY
        # Not threatened: drift towards the preferred left lane when it is safe to.
        if lane == 4:
            if chance and can_enter(3, cfg.open_m):
                return RIGHT
            return STAY
        if lane < 3 and chance and can_enter(lane + 1, cfg.enter_ahead_m):
            return LEFT
        return STAY
