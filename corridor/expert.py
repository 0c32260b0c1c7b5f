"""The scripted teleoperator: drives the map's target route.

:class:`CorridorExpert` is a teacher in the sense of ``docs/architecture.md``
(``teacher(observation, info) -> action``). It uses privileged information from ``info`` — the
robot's pose and its route segment, as a person with a joystick watching the robot would — plus
the map's route:

- On the route (within ``on_route_tolerance``, 0.2 m, of the tracked segment, i.e. inside its
  corridor, and heading along it within 25 degrees): the manoeuvre planned at the segment's end
  node is done at the decision point, ``turn_radius`` (0.2 m) before the node's centre: at the
  first position at most half a forward step (0.1 m) before it, ``remaining <= turn_radius +
  0.1``, so a robot whose steps vary in length (motion noise) still turns at the
  nearest step, and one that overshot turns at once. A turn from the decision point lands on the
  centre line of the next corridor. Otherwise: forward.
- Heading against the route (within 45 degrees of its opposite) in the route's corridor: u-turn.
  (Away from the tracked segment, e.g. in a side corridor, the direction of a far segment says
  nothing: the reactive rule below applies; turning there on the heading alone u-turned for ever
  at the end of a side corridor once the tracker stopped following corridors the route does not
  take.)
- Otherwise off the route (after a mistake of the learner; or past the segment's end node by
  more than half a step, down a corridor the route does not take): a reactive rule on the noise-free
  ranges: forward if the front is open (> ``open_range``), else turn toward the open side (left
  first), else u-turn. On a loop of corridors this drives on until the robot meets the route
  again; then the rules above take over (tested from random detours with motion noise).
- Stuck: when the rules above say forward but a wall stops the robot at once
  (``info["blocked"]``, given after a contact: its body rests against a wall or a corner ahead
  that the three rays need not see; a learner's late turn at a junction leaves it pressed
  against the corner at its front-left with all three ranges open), the expert turns to a way
  that is free: of the turns (left, right, u-turn) after which a forward step is not stopped
  at once, the one whose heading is nearest the route's segment, a turn before a u-turn and
  away from the wall on a tie; a u-turn if none is free. Without this rule it pushed forward
  into the corner, as a person with a joystick would not, for up to the rest of the episode:
  with a manoeuvre made one or two steps late, 20 of 400 circuits never ended (0 with it;
  wall contacts per circuit 8.3 against 1.8), after 1-4 random actions 11 of 300 (1 with it);
  ``scripts/corridor_expert_recovery.py`` and a test. Turning away from the wall whatever lay
  beyond rocked the robot between two turns in the inside corner of a junction.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from corridor.maps import LEFT, RIGHT, STRAIGHT, UTURN, CorridorMap
from corridor.world import Action, WorldConfig

__all__ = ["CorridorExpert"]


class CorridorExpert:
    """Scripted expert for a :class:`CorridorMap`.

    Args:
        corridor_map: the map whose route is driven.
        world_config: the robot's motion parameters (the turn radius sets the decision point).
        on_route_tolerance: lateral distance (metres) from the route still counted as on it.
        open_range: a range above this (metres) counts as open in the off-route rule.
    """

    def __init__(
        self,
        corridor_map: CorridorMap,
        world_config: WorldConfig | None = None,
        *,
        on_route_tolerance: float = 0.2,
        open_range: float = 0.6,
    ) -> None:
        self.map = corridor_map
        self.config = world_config or WorldConfig()
        self.route = corridor_map.route_polyline()
        self.on_route_tolerance = float(on_route_tolerance)
        self.open_range = float(open_range)

    def __call__(self, observation: np.ndarray, info: Mapping[str, Any]) -> int:
        """The expert's action (int, see :class:`corridor.world.Action`) for this step."""
        try:
            x, y, heading = (float(v) for v in info["pose"])
            seg = int(info["segment"])
        except KeyError as err:
            raise KeyError(f"CorridorExpert needs info[{err.args[0]!r}] from CorridorEnv") from err
        action = self._route_action(x, y, heading, seg, info)
        blocked = info.get("blocked")
        if action == Action.FORWARD and blocked is not None and blocked[0]:
            return self._unblock(heading, seg, blocked)
        return action

    def _unblock(self, heading: float, seg: int, blocked: Any) -> int:
        """Forward cannot pass the wall the robot rests against: of the turns after which a
        step is free, the one that heads most the route's way, away from that wall on a tie;
        a u-turn if every way is stopped."""
        way = self.route.segment_direction(seg)
        options = []
        for action, turn, flag in (
            (Action.TURN_LEFT, math.pi / 2, blocked[1]),
            (Action.TURN_RIGHT, -math.pi / 2, blocked[2]),
            (Action.U_TURN, math.pi, blocked[3]),
        ):
            if flag:
                continue
            h = heading + turn
            # to a tenth: a few degrees of heading error must not decide between the sides
            along = round(math.cos(h) * way[0] + math.sin(h) * way[1], 1)
            away = (action == Action.TURN_RIGHT) == (blocked[0] > 0)  # from the wall's side
            options.append((along, action != Action.U_TURN, away, int(action)))
        return max(options)[3] if options else int(Action.U_TURN)

    def _route_action(
        self, x: float, y: float, heading: float, seg: int, info: Mapping[str, Any]
    ) -> int:
        direction = self.route.segment_direction(seg)
        cos_err = math.cos(heading) * direction[0] + math.sin(heading) * direction[1]
        start = self.route.points[seg]
        rel = np.array([x, y]) - start
        lateral = abs(direction[0] * rel[1] - direction[1] * rel[0])
        remaining = float(self.route.segment_lengths[seg] - np.dot(rel, direction))
        if cos_err < -0.7 and lateral <= self.on_route_tolerance:
            return int(Action.U_TURN)
        overshot = remaining < -0.5 * self.config.forward_distance  # past the segment's end node
        if lateral > self.on_route_tolerance or cos_err < 0.9 or overshot:
            return self._reactive(info)
        kind = self.route.kinds[seg]
        at_decision = remaining <= self.config.turn_radius + 0.5 * self.config.forward_distance
        if kind == STRAIGHT or not at_decision:
            return int(Action.FORWARD)
        return int({LEFT: Action.TURN_LEFT, RIGHT: Action.TURN_RIGHT, UTURN: Action.U_TURN}[kind])

    def _reactive(self, info: Mapping[str, Any]) -> int:
        left, front, right = (float(v) for v in info["true_ranges"])
        if front > self.open_range:
            return int(Action.FORWARD)
        if left > self.open_range:
            return int(Action.TURN_LEFT)
        if right > self.open_range:
            return int(Action.TURN_RIGHT)
        return int(Action.U_TURN)
