"""A human-like driving teacher: the paper's person at the keyboard, as a seeded model.

Chernova & Veloso's driving teacher was a person: inconsistent about exactly when to change lane,
driving mostly in the left three lanes (left shoulder, left, middle), rarely in the right lane or
on the right shoulder, slow to react by a step or two, occasionally slipping. :func:`make_teacher`
builds that teacher: :class:`HumanDriver` (the preferences, this module) wrapped in
:class:`torchcbl.teachers.HumanTiming` (reaction delay, missed and doubled key presses; generic).

What :class:`HumanDriver` sees is what a driver sees: the observation (the signed distance to the
nearest car in each normal lane, clipped to +-25 m, and its own lane) and ``info``'s
``closing_speed_ms`` (how fast each of those three cars is closing in, m/s) and
``step_length_s``. It never reads hidden state (other cars, exact positions beyond 25 m).

How it decides, per step (all draws from one seeded generator):

- **home lane that drifts**: it has a preferred lane, redrawn on average every
  ``home_every_s`` seconds from ``home_weights`` (left shoulder, left, middle).
- **per-event reaction threshold**: for each car closing in ahead in its lane it draws a
  time-to-contact threshold uniformly from ``ttc_range_s`` and changes lane once the time to
  contact falls below it (so the exact moment varies from event to event, not a fixed gap);
  below ``ttc_range_s[0]`` it takes any safe lane, the right ones included.
- **direction among the safe lanes**: when it must leave its lane and both neighbours are safe it
  moves toward its home lane with probability ``toward_home_prob``, else the other way (not
  always "left first").
- **going home**: away from home and not pressed, it moves one lane toward home once that lane is
  safe and has been for a per-event number of steps drawn from ``patience_steps``.

Safety of a lane: a shoulder is always free; a normal lane is safe to enter when its nearest car
is behind by more than ``behind_m`` or ahead with a time to contact of at least
``enter_ttc_s`` (or out of sight).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from torchcbl.teachers import HumanTiming, HumanTimingConfig

__all__ = ["HumanDriver", "HumanDriverConfig", "make_teacher"]

_STAY, _LEFT, _RIGHT = 0, 1, 2
_N_LANES = 5
_CAR_M = 5.0
_RANGE_M = 25.0


@dataclass(frozen=True)
class HumanDriverConfig:
    """Parameters of :class:`HumanDriver` (seconds, metres; lanes 0 right shoulder .. 4 left
    shoulder).

    Attributes:
        home_weights: probabilities of the home lane being the middle (2), left (3) and left
            shoulder (4) lane when it is redrawn.
        home_every_s: mean time between redraws of the home lane (exponential), seconds.
        ttc_range_s: per-event time-to-contact threshold range (uniform) for leaving the lane
            when a car closes in ahead; below the lower end the driver takes any safe lane.
        enter_ttc_s: a lane is entered only if its nearest car ahead is at least this time to
            contact away (or out of sight).
        urgent_ttc_s: the same, when the car ahead in its own lane is closer than the lower end
            of ``ttc_range_s`` (it then accepts a tighter gap).
        behind_m: a lane is entered only if its nearest car behind is more than this far behind
            (front bumper to front bumper).
        hidden_ttc_s: when the nearest car of a lane is behind, a car ahead may be hidden (the
            observation shows one car per lane); the lane is entered only if a car exactly as
            far ahead would leave this time to contact (0: the driver takes the chance).
        toward_home_prob: with two safe neighbours, the probability of moving toward home.
        patience_steps: (low, high) inclusive range of safe steps waited before going home,
            drawn per event.
    """

    home_weights: tuple[float, float, float] = (0.5, 0.35, 0.15)
    home_every_s: float = 30.0
    ttc_range_s: tuple[float, float] = (1.2, 2.4)
    enter_ttc_s: float = 1.2
    urgent_ttc_s: float = 0.8
    hidden_ttc_s: float = 0.4
    behind_m: float = 6.0
    toward_home_prob: float = 0.8
    patience_steps: tuple[int, int] = (0, 3)

    def __post_init__(self) -> None:
        w = np.asarray(self.home_weights, dtype=np.float64)
        if w.shape != (3,) or np.any(w < 0) or not np.isclose(w.sum(), 1.0):
            raise ValueError(
                f"home_weights must be 3 probabilities (middle, left, left shoulder) summing to "
                f"1, got {self.home_weights}"
            )
        lo, hi = self.ttc_range_s
        if not 0.0 < lo <= hi:
            raise ValueError(f"ttc_range_s must be (low, high) with 0 < low <= high, got {lo, hi}")
        if self.home_every_s <= 0 or self.enter_ttc_s <= 0 or self.behind_m < _CAR_M:
            raise ValueError("home_every_s and enter_ttc_s must be > 0 and behind_m >= 5 m")
        if not 0.0 <= self.toward_home_prob <= 1.0:
            raise ValueError(f"toward_home_prob must lie in [0, 1], got {self.toward_home_prob}")
        if not 0 <= self.patience_steps[0] <= self.patience_steps[1]:
            raise ValueError(f"patience_steps must be 0 <= low <= high, got {self.patience_steps}")


class HumanDriver:
    """Lane preferences of a human driver: ``teacher(observation, info) -> action``.

    Answers at once (no delay, no slips): wrap it in :class:`~torchcbl.teachers.HumanTiming`
    (or use :func:`make_teacher`). See the module docstring for the model.

    Args:
        config: a :class:`HumanDriverConfig`.
        seed: seeds every draw.
    """

    def __init__(self, config: HumanDriverConfig | None = None, *, seed: int = 0) -> None:
        self.config = config or HumanDriverConfig()
        self._rng = np.random.default_rng(seed)
        self.home = self._draw_home()
        self._ttc = self._draw_ttc()
        self._patience = self._draw_patience()
        self._safe_steps = 0
        self._going = False
        self._last: tuple[Any, int, float] | None = None  # (t, lane, gap ahead)

    def _draw_home(self) -> int:
        return int(self._rng.choice((2, 3, 4), p=self.config.home_weights))

    def _draw_ttc(self) -> float:
        lo, hi = self.config.ttc_range_s
        return float(self._rng.uniform(lo, hi))

    def _draw_patience(self) -> int:
        lo, hi = self.config.patience_steps
        return int(self._rng.integers(lo, hi + 1))

    def _safe(self, lane: int, d: np.ndarray, closing: dict, dt: float, urgent: bool) -> bool:
        if not 0 <= lane < _N_LANES:
            return False
        if lane in (0, 4):
            return True
        x = float(d[lane - 1])
        if abs(x) >= _RANGE_M:  # nothing within 25 m, ahead or behind
            return True
        c = max(float(closing.get(lane, 0.0)), 0.0)
        need = self.config.urgent_ttc_s if urgent else self.config.enter_ttc_s
        nxt = x - c * dt
        if x <= 0:
            # The nearest car is behind: a car ahead, if any, is at least |x| ahead (it would be
            # the nearest otherwise) and unseen. A cautious driver (``hidden_ttc_s``) assumes it
            # is exactly there and closes in like this one.
            ahead = -x - c * dt
            hidden = self.config.hidden_ttc_s
            return nxt < -self.config.behind_m and (hidden <= 0 or ahead > _CAR_M + c * hidden)
        return nxt > _CAR_M and (c <= 0 or (nxt - _CAR_M) / c >= need)

    def __call__(self, observation: np.ndarray, info: dict) -> int:
        obs = np.asarray(observation, dtype=np.float64)
        if obs.shape != (4,):
            raise ValueError(f"expected a driving observation of shape (4,), got {obs.shape}")
        try:
            closing = {int(k): float(v) for k, v in info["closing_speed_ms"].items()}
            dt = float(info["step_length_s"])
        except (KeyError, TypeError, AttributeError) as err:
            raise ValueError(
                f"HumanDriver needs DrivingEnv's info (closing_speed_ms, step_length_s): {err}"
            ) from None
        cfg = self.config
        d = obs[:3]
        lane = int(round(obs[3]))
        t = info.get("t")
        if self._rng.random() < dt / cfg.home_every_s:
            self.home = self._draw_home()
        gap = float(d[lane - 1]) if lane in (1, 2, 3) else np.inf
        if gap <= 0 or gap >= _RANGE_M:
            gap = np.inf
        c = closing.get(lane, 0.0) if np.isfinite(gap) else 0.0
        last = self._last
        if last is None or last[1] != lane or t is None or last[0] is None or t != last[0] + 1:
            self._ttc = self._draw_ttc()
            self._patience = self._draw_patience()
            self._safe_steps = 0
            self._going = False
        elif np.isfinite(gap) and gap > last[2] + 1.0:  # another car now the nearest ahead
            self._ttc = self._draw_ttc()
        self._last = (t, lane, gap)

        def move(target: int) -> int:
            return _LEFT if target > lane else _RIGHT

        ttc = (gap - _CAR_M) / c if np.isfinite(gap) and c > 0 else np.inf
        if ttc <= self._ttc:
            toward = lane + (1 if self.home > lane else -1 if self.home < lane else 1)
            away = 2 * lane - toward
            if self._rng.random() >= cfg.toward_home_prob:
                toward, away = away, toward
            urgent = ttc < cfg.ttc_range_s[0]
            for target in (toward, away):
                if self._safe(target, d, closing, dt, urgent):
                    return move(target)
            return _STAY
        if lane == self.home:
            self._safe_steps = 0
            self._going = False
            return _STAY
        target = lane + (1 if self.home > lane else -1)
        if self._safe(target, d, closing, dt, False):
            self._safe_steps += 1
            if self._going or self._safe_steps > self._patience:
                self._going = True  # decided: keeps asking until it has moved
                return move(target)
        else:
            self._safe_steps = 0
            self._going = False
        return _STAY


def make_teacher(
    seed: int = 0,
    *,
    driver: HumanDriverConfig | None = None,
    timing: HumanTimingConfig | None = None,
) -> HumanTiming:
    """The default human-like driving teacher: :class:`HumanDriver` in
    :class:`~torchcbl.teachers.HumanTiming` (stay = the default key), both seeded from ``seed``."""
    ss = np.random.SeedSequence([int(seed), 5_2])
    a, b = (int(s.generate_state(1)[0]) for s in ss.spawn(2))
    return HumanTiming(HumanDriver(driver, seed=a), timing or HumanTimingConfig(), seed=b)
