"""The scripted teleoperator: drives the map's target route.

:class:`CorridorExpert` is a teacher in the sense of ``docs/architecture.md``
(``teacher(observation, info) -> action``). It uses privileged information from ``info`` — the
robot's pose and its route segment, as a person with a joystick watching the robot would — plus
the map's route:

- On the route (within ``on_route_tolerance``, 0.2 m, of the tracked segment, i.e. inside its
  corridor (in corridors 0.4 m wide or narrower: two thirds of half the width), and heading
  along it within 25 degrees): the manoeuvre planned at the segment's end node is done at
  the decision point, ``turn_radius`` (0.2 m) before the node's centre: at the first position
  at most half a forward step (0.1 m) before it, ``remaining <= turn_radius + 0.1``, so a
  robot whose steps vary in length (motion noise) still turns at the nearest step, and one
  that overshot turns at once. A turn from the decision point lands on the centre line of the
  next corridor. Otherwise: forward.
- Heading against the route (within 45 degrees of its opposite) in the route's corridor: u-turn.
  (Away from the tracked segment, e.g. in a side corridor, the direction of a far segment says
  nothing: the way back below applies; turning there on the heading alone u-turned for ever
  at the end of a side corridor once the tracker stopped following corridors the route does not
  take.)
- Otherwise off the route (after a mistake of the learner; or past the segment's end node by
  more than half a step, down a corridor the route does not take): the shortest way back on the
  map's corridors, as a person who knows the map would drive it. Its goal is where the route's
  progress stands, since the progress only follows the robot near it: to be in the tracked
  segment's corridor heading along it, not past where the progress stands by more than half a
  metre (within half a metre of the segment's end: in the next segment's corridor heading
  along it). There the expert drives on and makes the route's manoeuvre at the corridor's end,
  as on the route (not judged on the walls: a wall in the way is the stuck rule's, below).
  Elsewhere a Dijkstra search over arrivals at the map's nodes (metres driven plus one step's
  length per turn) starts from the first actions the walls allow, judged on the map's walls
  with exact motion: forward if half a step is free (then on to the node ahead, turning there,
  now if the robot stands at its decision point), a turn if the first half of its quarter
  circle is free and it ends in a corridor clear of its side walls, a u-turn if half a step is
  free after it; ways
  ``info["blocked"]`` reports stopped are left out. If the walls allow none (the robot faces a
  side wall with no room), the turn that heads the shortest way, made where it stands, as a
  contact would leave it. The reactive rule this replaced (forward if the front was open, else
  a turn toward the open side, else a u-turn) could not see where the progress stood: after
  1-4 random actions it drove 1 of 300 circuits round a loop of the corridors against the route
  for the rest of the episode (the progress, left at the junction P3, never followed), and it
  u-turned at corners it took for dead ends. ``scripts/corridor_expert_recovery.py`` measures
  both against a learner's mistakes; the reactive rule is left as the fallback where no
  corridor runs any way the robot can face.
- Stuck: when the rules above say forward but a wall stops the robot at once
  (``info["blocked"]``, given after a contact: its body rests against a wall or a corner ahead
  that the three rays need not see; a learner's late turn at a junction leaves it pressed
  against the corner at its front-left with all three ranges open), the expert turns to a way
  that is free: of the turns (left, right, u-turn) after which a forward step is not stopped
  at once, the one whose heading is nearest the route's segment, a turn before a u-turn and
  away from the wall on a tie; a u-turn if none is free. Without this rule it pushed forward
  into the corner, as a person with a joystick would not, for up to the rest of the episode:
  with a manoeuvre made one or two steps late, 20 of 400 circuits never ended (0 with it;
  wall contacts per circuit 8.3 against 1.8), after 1-4 random actions 11 of 300 (1 with it).
  These are figures of the reactive rule above, before the way back
  (``scripts/corridor_expert_recovery.py`` and a test; with the way back, 27 of 400 and 15 of
  300 never end without this rule, 0 and 0 with it). Turning away from the wall whatever lay
  beyond rocked the robot between two turns in the inside corner of a junction.
"""

from __future__ import annotations

import heapq
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
        on_route_tolerance: lateral distance (metres) from the route still counted as on it,
            less than half the corridor's width; None (default): 0.2, or on a map whose
            corridors are 0.4 m wide or narrower, where 0.2 is not inside the corridor, two
            thirds of half the width (as 0.2 is of the shipped maps' 0.3).
        open_range: a range above this (metres) counts as open in the reactive fallback of the
            way back (where no corridor runs any way the robot can face), less than the sensors'
            ``max_range``; None (default): 0.6, or 0.8 of ``max_range`` where that is shorter.
    """

    def __init__(
        self,
        corridor_map: CorridorMap,
        world_config: WorldConfig | None = None,
        *,
        on_route_tolerance: float | None = None,
        open_range: float | None = None,
    ) -> None:
        if not isinstance(corridor_map, CorridorMap):
            raise TypeError(
                f"corridor_map: expected a CorridorMap (corridor.maps.load_map(name)), got "
                f"{corridor_map!r:.80}"
            )
        if isinstance(world_config, Mapping):  # as CorridorEnv takes it
            world_config = WorldConfig(**world_config)
        if world_config is not None and not isinstance(world_config, WorldConfig):
            raise TypeError(
                f"world_config: expected a WorldConfig, a dict of its fields or None, got "
                f"{world_config!r:.80}"
            )
        self.map = corridor_map
        self.config = world_config or WorldConfig()
        half = corridor_map.corridor_width / 2
        if on_route_tolerance is None:
            on_route_tolerance = 0.2 if 0.2 < half else 2.0 * half / 3.0
        if open_range is None:
            open_range = min(0.6, 0.8 * self.config.max_range)
        for name, value, top, what in (
            ("on_route_tolerance", on_route_tolerance, half, "half the corridor's width"),
            ("open_range", open_range, self.config.max_range, "the range sensors' max_range"),
        ):
            ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
                value, (bool, np.bool_)
            )
            if not ok or not 0 < float(value) < top:
                raise ValueError(f"{name}: expected metres in (0, {top:g}) ({what}), got {value!r}")
        self.route = corridor_map.route_polyline()
        self.on_route_tolerance = float(on_route_tolerance)
        self.open_range = float(open_range)
        self._nodes = {n: np.asarray(xy, dtype=float) for n, xy in corridor_map.nodes.items()}
        # the map's geometry, once: each corridor's start node, unit direction and length, the
        # ways out of each node (next node, direction, length), and the walls as segments
        self._corridor_lines: list[tuple[str, str, np.ndarray, np.ndarray, float]] = []
        self._ways: dict[str, list[tuple[str, tuple[int, int], float]]] = {
            n: [] for n in self._nodes
        }
        for a, b in corridor_map.corridors:
            d = self._nodes[b] - self._nodes[a]
            length = float(np.linalg.norm(d))
            self._corridor_lines.append((a, b, self._nodes[a], d / length, length))
            self._ways[a].append((b, _axis_between(self._nodes[a], self._nodes[b]), length))
            self._ways[b].append((a, _axis_between(self._nodes[b], self._nodes[a]), length))
        walls = np.asarray(corridor_map.walls(), dtype=float)  # [M, 2 ends, 2] metres
        self._wall_start = walls[:, 0]
        self._wall_vec = walls[:, 1] - walls[:, 0]
        self._wall_len2 = np.einsum("md,md->m", self._wall_vec, self._wall_vec)
        # route segment k runs along the map corridor edges[k] = (a, b), from a toward b: the
        # first and the last (start point -> route[1], route[0] -> start point) both lie on the
        # corridor route[0] - route[1]
        r = corridor_map.route
        n = len(r) - 1
        self._edges = [(r[0], r[1]), *((r[k], r[k + 1]) for k in range(1, n)), (r[0], r[1])]

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
            return self._way_back(x, y, heading, seg, info)
        kind = self.route.kinds[seg]
        at_decision = remaining <= self.config.turn_radius + 0.5 * self.config.forward_distance
        if kind == STRAIGHT or not at_decision:
            return int(Action.FORWARD)
        return int({LEFT: Action.TURN_LEFT, RIGHT: Action.TURN_RIGHT, UTURN: Action.U_TURN}[kind])

    def _way_back(
        self, x: float, y: float, heading: float, seg: int, info: Mapping[str, Any]
    ) -> int:
        """Off the route: the first action of the shortest way, on the map's corridors, to
        where the circuit goes on (the route's progress only moves on near where it stands).

        The goal is to be in the tracked segment's corridor heading along it, not past where the
        progress stands by more than half a metre (or, within half a metre of the segment's
        end, in the next segment's corridor heading along it): there, drive on and make the
        route's manoeuvre at the end. Else a Dijkstra search over arrivals at the map's nodes
        (metres driven plus one forward step's length per turn), from the first actions the
        walls allow here: drive on to the node ahead (turning there, now if the robot stands
        at its decision point), or turn now, where the turn's arc is clear and ends in a
        corridor clear of its side walls. If the walls allow none of them (the robot faces a
        side wall), the turn that heads the shortest way, made where the robot stands as a
        contact would leave it."""
        step = self.config.forward_distance
        h = _axis(heading)
        hv = np.array(h, dtype=float)
        p = np.array([x, y])
        lap = info.get("lap_position")
        k = seg
        starts = self.route.segment_starts
        if lap is not None and starts[seg + 1] - float(lap) <= 0.5:
            k = (seg + 1) % len(self._edges)
        goal = self._edges[k]
        a_goal, b_goal = (self._nodes[v] for v in goal)
        u_goal = (b_goal - a_goal) / np.linalg.norm(b_goal - a_goal)
        # how far along the goal's corridor the robot may stand (metres from its start node)
        reach = math.inf
        if k == seg and lap is not None:
            at = self.route.points[seg] + (float(lap) - starts[seg]) * u_goal
            reach = float(np.dot(at - a_goal, u_goal)) + 0.5

        def in_goal(place: tuple[str, str] | None, q: np.ndarray) -> bool:
            return (
                place is not None
                and place == (goal[1], goal[0])  # (ahead, behind): heading along the goal
                and float(np.dot(q - a_goal, u_goal)) <= reach
            )

        if in_goal(self._corridor_along(p, h), p):
            if float(np.dot(b_goal - p, hv)) > self.config.turn_radius + 0.5 * step:
                return int(Action.FORWARD)
            return _turn_action(h, self._exit_direction(k))
        decide = self.config.turn_radius + 0.5 * step
        stopped = info.get("blocked")  # after a contact: the ways a wall stops at once
        if stopped is None:
            stopped = (0, 0, 0, 0)
        heap: list[tuple[float, int, str, tuple[int, int], int | None]] = []
        for in_place in (False, True):
            for action, h2 in (
                (Action.FORWARD, h),
                (Action.TURN_LEFT, (-h[1], h[0])),
                (Action.TURN_RIGHT, (h[1], -h[0])),
                (Action.U_TURN, (-h[0], -h[1])),
            ):
                if stopped[int(action)] or (in_place and action == Action.FORWARD):
                    continue
                if not in_place and not self._free(p, h, int(action)):
                    continue
                h2v = np.array(h2, dtype=float)
                # a quarter circle ends a turn radius on and aside, clear of the new corridor's
                # side walls; after a forward step or a u-turn (or in place) the robot is where
                # it is
                arc = not in_place and action in (Action.TURN_LEFT, Action.TURN_RIGHT)
                q = p + self.config.turn_radius * (hv + h2v) if arc else p
                place = self._corridor_along(q, h2, self.config.robot_radius if arc else 0.0)
                if place is None:
                    continue
                turned = 0.0 if action == Action.FORWARD else step
                if in_goal(place, q):
                    heap.append((turned, len(heap), "", (0, 0), int(action)))
                    continue
                t = float(np.dot(self._nodes[place[0]] - q, h2v))
                if t < -0.5 * step:  # past the node ahead, facing its far wall
                    continue
                at_node = action == Action.FORWARD and t <= decide
                heap.append(
                    (
                        max(t, 0.0) + turned,
                        len(heap),
                        place[0],
                        h2,
                        None if at_node else int(action),
                    )
                )
            if heap:
                break
        heapq.heapify(heap)
        order = len(heap)
        seen: set[tuple[str, tuple[int, int]]] = set()
        while heap:
            cost, _, node, d_in, first = heapq.heappop(heap)
            if node == "":  # the goal: costs only grow, so the first one popped is the best
                return int(first)  # type: ignore[arg-type]
            if (node, d_in) in seen:
                continue
            seen.add((node, d_in))
            for nxt, d_out, length in self._ways[node]:
                c = cost + (0.0 if d_out == d_in else step)
                act = _turn_action(d_in, d_out) if first is None else first
                if first is None and (stopped[act] or not self._free(p, h, act)):
                    continue  # a turn now, at the decision point, that a wall stops
                if (node, nxt) == goal:
                    heapq.heappush(heap, (c, order, "", (0, 0), act))
                else:
                    heapq.heappush(heap, (c + length, order, nxt, d_out, act))
                order += 1
        return self._reactive(info)  # no corridor runs any way the robot can face here

    def _free(self, p: np.ndarray, h: tuple[int, int], action: int) -> bool:
        """Whether the walls let ``action`` from ``p`` heading ``h`` start its way: the first
        half of its motion is free of contact (exact motion; forward: half a step, as
        ``info["blocked"]`` tests; a turn: the first half of its quarter circle, so a turn that
        ends touching a wall still gets the robot round; a u-turn turns in place, and is free if
        half a forward step is then)."""
        if action == Action.U_TURN:  # in place: free if the robot can then step away
            return self._free(p, (-h[0], -h[1]), int(Action.FORWARD))
        hv = np.array(h, dtype=float)
        if action == Action.FORWARD:
            pts = p + np.outer(np.linspace(0.25, 1.0, 4) * 0.5 * self.config.forward_distance, hv)
        else:
            side = np.array((-h[1], h[0]), dtype=float) * (
                1.0 if action == Action.TURN_LEFT else -1.0
            )
            th = np.linspace(1.0, 4.0, 4) * math.pi / 16
            r = self.config.turn_radius
            pts = p + np.outer(r * np.sin(th), hv) + np.outer(r * (1.0 - np.cos(th)), side)
        ab = self._wall_vec
        rel = pts[:, None, :] - self._wall_start[None]
        t = np.clip(np.einsum("nmd,md->nm", rel, ab) / self._wall_len2, 0.0, 1.0)
        d = np.linalg.norm(rel - t[..., None] * ab[None], axis=-1)
        return bool(d.min() >= self.config.robot_radius - 1e-9)

    def _exit_direction(self, k: int) -> tuple[int, int]:
        """The direction the route leaves segment ``k``'s corridor at its end node."""
        a, b = self._edges[k]
        for j in range(1, len(self._edges) + 1):
            c, d = self._edges[(k + j) % len(self._edges)]
            if c == b:
                return _axis_between(self._nodes[c], self._nodes[d])
        return _axis_between(self._nodes[a], self._nodes[b])

    def _corridor_along(
        self, p: np.ndarray, h: tuple[int, int], clearance: float = 0.0
    ) -> tuple[str, str] | None:
        """(node ahead, node behind) of the corridor running along ``h`` that holds ``p`` (its
        rectangle reaches half a width past both nodes); of several (in a junction), the one
        whose centre line passes nearest."""
        half = 0.5 * self.map.corridor_width - clearance + 1e-9
        best: tuple[float, str, str] | None = None
        for a, b, pa, d, length in self._corridor_lines:
            along = float(np.dot(d, h))
            if abs(along) < 0.5:
                continue
            rel = p - pa
            t = float(np.dot(rel, d))
            lateral = abs(float(d[0] * rel[1] - d[1] * rel[0]))
            if lateral > half or not -half <= t <= length + half:
                continue
            dist = float(np.linalg.norm(rel - min(max(t, 0.0), length) * d))
            if best is None or dist < best[0] - 1e-9:
                best = (dist, b, a) if along > 0 else (dist, a, b)
        return None if best is None else (best[1], best[2])

    def _reactive(self, info: Mapping[str, Any]) -> int:
        left, front, right = (float(v) for v in info["true_ranges"])
        if front > self.open_range:
            return int(Action.FORWARD)
        if left > self.open_range:
            return int(Action.TURN_LEFT)
        if right > self.open_range:
            return int(Action.TURN_RIGHT)
        return int(Action.U_TURN)


def _axis(heading: float) -> tuple[int, int]:
    """The axis direction nearest a heading (radians), as integer components."""
    q = round(heading / (math.pi / 2)) % 4
    return ((1, 0), (0, 1), (-1, 0), (0, -1))[q]


def _axis_between(a: np.ndarray, b: np.ndarray) -> tuple[int, int]:
    d = b - a
    return (int(np.sign(d[0])), 0) if abs(d[0]) >= abs(d[1]) else (0, int(np.sign(d[1])))


def _turn_action(d_in: tuple[int, int], d_out: tuple[int, int]) -> int:
    """The action that turns the robot from axis direction ``d_in`` to ``d_out``."""
    cross = d_in[0] * d_out[1] - d_in[1] * d_out[0]
    if cross > 0:
        return int(Action.TURN_LEFT)
    if cross < 0:
        return int(Action.TURN_RIGHT)
    return int(Action.FORWARD if d_in == d_out else Action.U_TURN)
