"""The corridor world on pymunk: walls, a kinematic round robot, its range sensors and actions.

This is the ONLY module of the project that imports pymunk. Units: metres, radians; headings
are counter-clockwise from +x.

Motion. The robot is a circle on a kinematic body. An action is cut
into sub-steps of at most ``WorldConfig.substep`` metres of travel (or ``substep_angle`` radians
of rotation); before each sub-step the new pose is tested with ``Space.shape_query``, and a
sub-step whose position would overlap a wall is undone: the robot keeps its last free position,
stops translating for the rest of the action (rotation, which a round robot can always do,
completes) and the action reports a wall contact. So the robot never passes through a wall
(``substep`` must be less than the robot's diameter, else one sub-step could jump a wall).

- ``FORWARD``: ``forward_distance`` (0.20 m) straight ahead.
- ``TURN_LEFT`` / ``TURN_RIGHT``: a quarter circle of radius ``turn_radius`` (0.20 m): the robot
  rotates 90 degrees while advancing slowly (0.31 m of arc), ending ``turn_radius`` ahead and
  ``turn_radius`` to the side of where it started.
- ``U_TURN``: rotate 180 degrees in place (counter-clockwise).

Motion noise (``WorldConfig.forward_noise``, ``heading_noise``; both 0 by default, so motion is
exact unless asked; :meth:`WorldConfig.legged_robot` turns them on, and the Section 5.1
experiment uses it). The paper's AIBO walked: its steps varied in length and its turns were
imprecise. Here each action, when noisy, draws from the generator passed to
:meth:`CorridorWorld.step`:

- a length factor ``1 + forward_noise * N(0, 1)`` (clipped to [0.5, 1.5]) that scales the forward
  distance (or the turn's radius, i.e. how far a turn advances);
- a heading error ``N(0, 1)`` (clipped to 3 sd) times ``heading_noise`` for a turn or u-turn,
  ``forward_heading_noise`` for a forward step (radians): the action ends at the commanded
  heading plus this error, and a forward step walks along the erred heading (so it drifts
  sideways, about 0.5 cm per step at 1.5 degrees).

The commanded heading is the start heading plus the nominal rotations of the actions so far
(+-90 deg a turn, 180 deg a u-turn): the heading error does not add up from action to action. It
models a walk that holds its commanded heading within a few degrees (a gait with a heading
reference); with errors that added up (a random walk, about 3 deg x sqrt(60) = 23 deg after ten
circuits) no sequence of these four actions could straighten the robot, neither for a
teleoperator nor for a learned policy, and every long run would end against a wall.

Sensors. Three IR-like range sensors point left (+90 deg), front and right (-90 deg) from the
robot's centre; a reading is the distance from the centre to the nearest wall along the ray
(``Space.segment_query_first`` with a filter that excludes the robot), saturated at
``max_range``. While the robot stands still it takes ``n_readings`` (15) readings per sensor,
each with Gaussian noise of standard deviation ``noise_sd + noise_sd_per_m * distance``, each
clipped to ``[min_range, max_range]``, and reports their mean. The geometry does not change while
standing, so the ray is cast once per sensor and the 15 readings differ by their noise only.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, fields
from enum import IntEnum
from typing import Any

import numpy as np
import pymunk

from corridor.maps import CorridorMap, RouteProgress, load_map

__all__ = ["Action", "CorridorWorld", "WorldConfig", "N_ACTIONS", "SENSOR_NAMES", "pymunk_versions"]

SENSOR_NAMES = ("left", "front", "right")
_SENSOR_ANGLES = (math.pi / 2, 0.0, -math.pi / 2)
_ROBOT_CATEGORY = 0b10
_WALL_CATEGORY = 0b01


class Action(IntEnum):
    """The four actions of the paper's corridor robot."""

    FORWARD = 0
    TURN_LEFT = 1
    TURN_RIGHT = 2
    U_TURN = 3


N_ACTIONS = len(Action)


@dataclass(frozen=True)
class WorldConfig:
    """Robot, motion and sensor parameters (metres, radians).

    The defaults describe a small round robot with IR range sensors of 1.5 m (like the Sharp
    GP2Y0A02, 0.2-1.5 m): per-reading noise of 1 cm + 2% of the distance, averaged over 15
    readings (so about 0.5 cm at 0.3 m and 1 cm at 1.5 m).

    Sensors that cannot tell a near wall from a far one are refused (ValueError):
    ``max_range`` must exceed ``robot_radius`` (the rays start at the robot's centre and no
    wall comes nearer than its radius, so a shorter range reads ``max_range`` but for its
    noise, and tells nothing of the walls), and one standard deviation of a reading at full
    range, ``noise_sd + noise_sd_per_m * max_range``, must be less than the span of readings,
    ``max_range - min_range`` (else a wall at full range reads, one standard deviation off,
    as one at the minimum: a rule of thumb, not a proof that such sensors are useless, since
    the mean of many clipped readings still grows with the distance). The defaults' is 0.04 m
    of 1.45 m.
    """

    robot_radius: float = 0.12
    forward_distance: float = 0.20
    turn_radius: float = 0.20
    substep: float = 0.02
    substep_angle: float = math.pi / 16
    max_range: float = 1.5
    min_range: float = 0.05
    noise_sd: float = 0.01
    noise_sd_per_m: float = 0.02
    n_readings: int = 15
    forward_noise: float = 0.0
    heading_noise: float = 0.0
    forward_heading_noise: float = 0.0

    @classmethod
    def legged_robot(cls, **overrides: float) -> WorldConfig:
        """The Section 5.1 experiment's world: motion noise of a small legged robot, a forward
        step's length (and a turn's radius) with a standard deviation of 10% (2 cm of 20 cm), a
        turn's or u-turn's final heading with one of 3 degrees, a forward step's with 1.5
        degrees."""
        kwargs: dict[str, float] = {
            "forward_noise": 0.10,
            "heading_noise": math.radians(3.0),
            "forward_heading_noise": math.radians(1.5),
        }
        kwargs.update(overrides)
        return cls(**kwargs)

    @property
    def noisy_motion(self) -> bool:
        """Whether actions draw motion noise (then :meth:`CorridorWorld.step` needs a generator)."""
        return self.forward_noise > 0 or self.heading_noise > 0 or self.forward_heading_noise > 0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "n_readings":
                if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
                    raise ValueError(f"WorldConfig.n_readings must be an int >= 1, got {v!r}")
                object.__setattr__(self, f.name, int(v))  # numpy ints kept plain (JSON)
            elif (
                isinstance(v, (bool, np.bool_))
                or not isinstance(v, (int, float, np.integer, np.floating))
                or not math.isfinite(v)
            ):
                raise ValueError(f"WorldConfig.{f.name} must be a finite number, got {v!r}")
            else:
                object.__setattr__(self, f.name, float(v))  # numpy numbers kept plain (JSON)
        for name in ("robot_radius", "forward_distance", "turn_radius", "substep", "max_range"):
            if not getattr(self, name) > 0:
                raise ValueError(f"WorldConfig.{name} must be > 0, got {getattr(self, name)}")
        if not self.substep < 2 * self.robot_radius:
            # a longer sub-step can carry the robot across a wall (walls have no thickness)
            # between two overlap tests
            raise ValueError(
                f"WorldConfig.substep ({self.substep:g} m) must be less than the robot's "
                f"diameter (2 * robot_radius = {2 * self.robot_radius:g} m), or a sub-step can "
                "jump a wall; pass a smaller substep"
            )
        if not 0 < self.substep_angle <= math.pi / 2:
            raise ValueError("WorldConfig.substep_angle must be in (0, pi/2]")
        if not 0 <= self.min_range < self.max_range:
            raise ValueError("WorldConfig needs 0 <= min_range < max_range")
        if self.noise_sd < 0 or self.noise_sd_per_m < 0:
            raise ValueError("WorldConfig noise standard deviations must be >= 0")
        if not self.max_range > self.robot_radius:
            # the rays start at the robot's centre and no wall comes nearer than its radius
            raise ValueError(
                f"WorldConfig.max_range ({self.max_range:g} m) must exceed robot_radius "
                f"({self.robot_radius:g} m): the sensors sit at the robot's centre and no wall "
                "comes nearer than the robot's radius, so every reading would be max_range "
                "but for its noise; "
                f"pass a max_range above {self.robot_radius:g} m (the default is 1.5 m)"
            )
        far_sd = self.noise_sd + self.noise_sd_per_m * self.max_range
        span = self.max_range - self.min_range
        if not far_sd < span:
            raise ValueError(
                "WorldConfig: a reading's noise at the sensors' full range, noise_sd + "
                f"noise_sd_per_m * max_range = {far_sd:.3g} m (one standard deviation), must be "
                f"less than the span of readings, max_range - min_range = {span:.3g} m, or a "
                "wall at full range reads, one standard deviation off, as one at the minimum "
                f"(noise_sd={self.noise_sd:g}, noise_sd_per_m={self.noise_sd_per_m:g}, "
                f"max_range={self.max_range:g}, min_range={self.min_range:g}); pass a "
                "smaller noise_sd or noise_sd_per_m, or a wider span (the defaults are 0.01 m, "
                "0.02 per metre, min_range 0.05 m and max_range 1.5 m)"
            )
        if self.n_readings < 1:
            raise ValueError("WorldConfig.n_readings must be >= 1")
        if not 0 <= self.forward_noise <= 0.3:
            raise ValueError(
                f"WorldConfig.forward_noise is a fraction of the step length in [0, 0.3], "
                f"got {self.forward_noise}"
            )
        for name in ("heading_noise", "forward_heading_noise"):
            if not 0 <= getattr(self, name) <= math.radians(20):
                raise ValueError(
                    f"WorldConfig.{name} is in radians, in [0, {math.radians(20):.3f}] "
                    f"(20 deg), got {getattr(self, name)}; pass math.radians(degrees)"
                )


def pymunk_versions() -> dict[str, str]:
    """What the corridor world runs on: ``{"pymunk": version}``, the pymunk imported here (it
    ships the Chipmunk2D it runs). A teaching session's writers record it
    (:meth:`corridor.env.CorridorEnv.describe_versions`)."""
    return {"pymunk": str(pymunk.version)}


def _wrap(angle: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    a = math.remainder(angle, 2 * math.pi)
    return math.pi if a == -math.pi else a


class CorridorWorld:
    """A corridor map in a pymunk space with one robot; tracks progress along the route.

    Args:
        corridor_map: the map (walls and route): a :class:`CorridorMap`, or the name of a shipped
            map / a JSON path (as :class:`corridor.env.CorridorEnv` takes it).
        config: robot, motion and sensor parameters: a :class:`WorldConfig`, a dict of its
            fields, or None for the defaults.
    """

    def __init__(
        self,
        corridor_map: CorridorMap | str | os.PathLike[str],
        config: WorldConfig | Mapping[str, Any] | None = None,
    ) -> None:
        if isinstance(corridor_map, (str, os.PathLike)):
            corridor_map = load_map(corridor_map)
        if not isinstance(corridor_map, CorridorMap):
            raise TypeError(
                f"corridor_map: expected a CorridorMap, a map name or a map JSON path, got "
                f"{corridor_map!r:.80}"
            )
        if isinstance(config, Mapping):
            try:
                config = WorldConfig(**config)
            except TypeError as exc:
                raise TypeError(
                    f"world_config: expected a WorldConfig or a dict of its fields, got "
                    f"{dict(config)!r} ({exc})"
                ) from None
        if config is not None and not isinstance(config, WorldConfig):
            raise TypeError(
                f"world_config: expected a WorldConfig, a dict of its fields or None, got "
                f"{config!r:.80}"
            )
        self.map = corridor_map
        self.config = config or WorldConfig()
        if corridor_map.corridor_width <= 2 * self.config.robot_radius:
            raise ValueError(
                f"map {corridor_map.name!r}: its corridors ({corridor_map.corridor_width:g} m "
                f"wide) are no wider than the robot ({2 * self.config.robot_radius:g} m across, "
                "WorldConfig.robot_radius): it cannot drive them; widen the corridors or make "
                "the robot smaller"
            )
        self.route = corridor_map.route_polyline()
        # The route tracker's arc-length window (Route.locate's back and ahead, 0.5 m and 1 m)
        # must hold the farthest the progress moves in one action: the action's advance (a
        # turn's 2 x turn_radius at most, a step's forward_distance) plus, at a corner, up to a
        # corridor's width (a robot off the centre line projects on the corridors before and
        # after the corner up to a width apart): 0.4 + 0.6 = 1 m for the default robot on the
        # shipped maps. Scaled up where that is more: with 1 m ahead a robot whose turn (or
        # step) went farther, or one that cut a corner of a 1 m wide corridor on its inner
        # side, was never credited, and the progress stood still for the rest of the episode.
        advance = max(self.config.forward_distance, 2 * self.config.turn_radius)
        scale = max(1.0, corridor_map.corridor_width + advance)  # metres over the default 1 m
        self._window = {"back": 0.5 * scale, "ahead": 1.0 * scale}
        self._space = pymunk.Space()
        wall_filter = pymunk.ShapeFilter(categories=_WALL_CATEGORY)
        for a, b in corridor_map.walls():
            seg = pymunk.Segment(self._space.static_body, a, b, 0.0)
            seg.filter = wall_filter
            self._space.add(seg)
        self._body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        self._shape = pymunk.Circle(self._body, self.config.robot_radius)
        self._shape.filter = pymunk.ShapeFilter(categories=_ROBOT_CATEGORY, mask=_WALL_CATEGORY)
        self._space.add(self._body, self._shape)
        self._ray_filter = pymunk.ShapeFilter(mask=pymunk.ShapeFilter.ALL_MASKS() ^ _ROBOT_CATEGORY)
        self._x = self._y = self._heading = self._commanded = 0.0
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self, offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        """Put the robot at the map's start pose, moved by ``offset`` = (dx m, dy m, dheading
        rad), with zero progress. The commanded heading is the start pose's (so a heading offset
        is an error the first action removes, see the module docstring). Raises ValueError if
        the moved pose overlaps a wall or lies outside the corridors (:meth:`set_pose`)."""
        x, y, h = self.map.start_pose()
        dx, dy, dh = (float(v) for v in offset)
        self.set_pose(x + dx, y + dy, h + dh)
        self._commanded = _wrap(h)
        x, y = x + dx, y + dy
        self._s = 0.0
        self._s_max = 0.0
        self._progress = self.route.locate(
            x, y, h, 0.0, max_offset=self.map.corridor_width, **self._window
        )

    def set_pose(self, x: float, y: float, heading: float) -> None:
        """Place the robot (metres, radians); raises ValueError if a value is not finite, if
        its centre lies outside the map's corridors (in the solid between them, or beyond the
        map) or if it would overlap a wall. Progress is not changed (call :meth:`reset` for
        that)."""
        if not all(math.isfinite(float(v)) for v in (x, y, heading)):
            raise ValueError(f"pose must be finite metres and radians, got ({x}, {y}, {heading})")
        if not self.map.is_free(x, y):
            xmin, ymin, xmax, ymax = self.map.bounds()
            raise ValueError(
                f"pose ({x:.3f}, {y:.3f}) lies outside the corridors of map {self.map.name!r} "
                f"(in the solid between them, or beyond the map's x in [{xmin:g}, {xmax:g}], "
                f"y in [{ymin:g}, {ymax:g}] m); place the robot in a corridor"
            )
        if self._overlaps(x, y):
            self._body.position = (self._x, self._y)
            raise ValueError(f"pose ({x:.3f}, {y:.3f}) overlaps a wall")
        self._x, self._y, self._heading = float(x), float(y), _wrap(float(heading))
        self._commanded = self._heading
        self._body.position = (self._x, self._y)
        self._body.angle = self._heading

    def snapshot(self) -> tuple[float, ...]:
        """The robot's whole state (pose, commanded heading, route progress) as an opaque,
        hashable tuple for :meth:`restore`: a search over action sequences can branch from a
        state without replaying the actions that led there."""
        p = self._progress
        return (
            self._x,
            self._y,
            self._heading,
            self._commanded,
            self._s,
            self._s_max,
            p.s,
            float(p.segment),
            p.lateral,
            p.remaining,
        )

    def restore(self, snapshot: tuple[float, ...]) -> None:
        """Put the robot back in a state taken by :meth:`snapshot` (of a world on the same map)."""
        if len(snapshot) != 10:
            raise ValueError(
                f"expected a snapshot of 10 numbers from CorridorWorld.snapshot(), got "
                f"{len(snapshot)}"
            )
        x, y, h, cmd, s, s_max, ps, seg, lat, rem = snapshot
        self._x, self._y, self._heading, self._commanded = x, y, h, cmd
        self._s, self._s_max = s, s_max
        self._progress = RouteProgress(ps, int(seg), lat, rem)
        self._body.position = (x, y)
        self._body.angle = h

    def blocked(self, turn: float = 0.0) -> int:
        """Whether a wall stops the robot within half a forward step: 0 if a forward step
        without noise along the commanded heading (see the module docstring) turned by ``turn``
        radians (as after a turn made in place) takes it at least half its length; else the
        side of the wall point it meets first, +1 left of that heading, -1 right of it or
        straight ahead. A wall the three rays need not see counts too, e.g. a corner at the
        robot's front-left. The robot does not move."""
        cfg = self.config
        n = max(1, math.ceil(0.5 * cfg.forward_distance / cfg.substep - 1e-9))
        heading = self._commanded + float(turn)
        cos_h, sin_h = math.cos(heading), math.sin(heading)
        side = 0
        try:
            for k in range(1, n + 1):
                d = 0.5 * cfg.forward_distance * k / n
                deepest = min(
                    self._overlap_points(self._x + d * cos_h, self._y + d * sin_h),
                    key=lambda point: point.distance,
                    default=None,
                )
                if deepest is not None:
                    # the contact, between the robot's surface and the wall's
                    wx = 0.5 * (deepest.point_a.x + deepest.point_b.x)
                    wy = 0.5 * (deepest.point_a.y + deepest.point_b.y)
                    cross = cos_h * (wy - self._y) - sin_h * (wx - self._x)
                    side = 1 if cross > 0 else -1
                    break
        finally:
            self._body.position = (self._x, self._y)
        return side

    @property
    def pose(self) -> tuple[float, float, float]:
        """``(x, y, heading)``: metres, radians in (-pi, pi]."""
        return (self._x, self._y, self._heading)

    @property
    def progress(self) -> RouteProgress:
        """Where the robot is on the route (see :class:`corridor.maps.RouteProgress`)."""
        return self._progress

    @property
    def laps(self) -> int:
        """Circuits completed since :meth:`reset` (by the furthest progress reached)."""
        return int(math.floor((self._s_max + 0.05) / self.route.length))

    @property
    def lap_position(self) -> float:
        """Position along the current circuit, metres in [0, route length)."""
        return float(self._s % self.route.length)

    # ------------------------------------------------------------------ physics
    def _overlap_points(self, x: float, y: float) -> Iterator[Any]:
        """The contact points (pymunk ``ContactPoint``) at which the robot, moved to (x, y),
        overlaps a wall. Leaves the body there."""
        self._body.position = (x, y)
        for info in self._space.shape_query(self._shape):
            for point in info.contact_point_set.points:
                if point.distance < -1e-9:
                    yield point

    def _overlaps(self, x: float, y: float) -> bool:
        # the same test as _overlap_points, written out: it runs at every motion sub-step, and
        # the generator there costs 3-8% of the env's actions per second
        self._body.position = (x, y)
        for info in self._space.shape_query(self._shape):
            for point in info.contact_point_set.points:
                if point.distance < -1e-9:
                    return True
        return False

    @property
    def commanded_heading(self) -> float:
        """The heading the actions so far commanded (radians): the start heading plus their
        nominal rotations. Equal to ``pose[2]`` when motion is exact."""
        return self._commanded

    def step(self, action: int, rng: np.random.Generator | None = None) -> bool:
        """Execute one action; returns True if the robot touched a wall (the move was cut).

        ``rng`` draws the motion noise; it is required when ``config.noisy_motion`` and unused
        (nothing drawn) otherwise.
        """
        try:
            action = Action(int(action))
        except (ValueError, TypeError) as err:
            raise ValueError(
                f"action must be one of {[int(a) for a in Action]}, got {action!r}"
            ) from err
        cfg = self.config
        x0, y0, h0 = self._x, self._y, self._heading
        scale, err = 1.0, 0.0
        if cfg.noisy_motion:
            if rng is None:
                raise ValueError(
                    "this world has motion noise (WorldConfig.forward_noise / heading_noise > 0): "
                    "pass a numpy Generator, world.step(action, rng)"
                )
            z = rng.standard_normal(2)
            scale = min(1.5, max(0.5, 1.0 + cfg.forward_noise * float(z[0])))
            sd = cfg.forward_heading_noise if action == Action.FORWARD else cfg.heading_noise
            err = sd * min(3.0, max(-3.0, float(z[1])))
        # Heading offset to the commanded one before the action: the last action's heading
        # error, or a perturbed start's; exact motion keeps it at 0.0 (last-bit differences of
        # the two running sums are snapped away, so exact runs stay bit-identical).
        off0 = _wrap(h0 - self._commanded)
        if abs(off0) < 1e-9:
            off0 = 0.0
        if action == Action.FORWARD:
            dist = cfg.forward_distance * scale
            n = max(1, math.ceil(dist / cfg.substep - 1e-9))
            h1 = h0 + (err - off0)
            cos_h, sin_h = math.cos(h1), math.sin(h1)

            def pose_at(k: int) -> tuple[float, float, float]:
                d = dist * k / n
                return (x0 + d * cos_h, y0 + d * sin_h, h0 + (h1 - h0) * k / n)

            rotation = 0.0
        elif action in (Action.TURN_LEFT, Action.TURN_RIGHT):
            sign = 1.0 if action == Action.TURN_LEFT else -1.0
            r = cfg.turn_radius * scale
            rotation = sign * math.pi / 2
            turn = rotation + (err - off0)
            arc = r * abs(turn)
            n = max(
                1, math.ceil(arc / cfg.substep - 1e-9), math.ceil(abs(turn) / cfg.substep_angle)
            )
            # Centre of the arc, to the turning side.
            cx, cy = x0 - sign * r * math.sin(h0), y0 + sign * r * math.cos(h0)

            def pose_at(k: int) -> tuple[float, float, float]:
                h = h0 + turn * k / n
                return (cx + sign * r * math.sin(h), cy - sign * r * math.cos(h), h)

        else:
            rotation = math.pi
            turn = rotation + (err - off0)
            n = math.ceil(turn / cfg.substep_angle - 1e-9)

            def pose_at(k: int) -> tuple[float, float, float]:
                return (x0, y0, h0 + turn * k / n)

        contact = False
        x, y = x0, y0
        heading = h0
        for k in range(1, n + 1):
            nx, ny, heading = pose_at(k)
            if contact or (nx == x and ny == y):
                continue
            if self._overlaps(nx, ny):
                contact = True
                continue
            x, y = nx, ny
        self._x, self._y, self._heading = x, y, _wrap(heading)
        if rotation:
            self._commanded = _wrap(self._commanded + rotation)
        self._body.position = (x, y)
        self._body.angle = self._heading
        self._progress = self.route.locate(
            x, y, self._heading, self._s, max_offset=self.map.corridor_width, **self._window
        )
        self._s = self._progress.s
        self._s_max = max(self._s_max, self._s)
        return contact

    # ------------------------------------------------------------------ sensing
    def true_ranges(self) -> np.ndarray:
        """Noise-free distances ``[3]`` (left, front, right) from the robot centre to the nearest
        wall, metres, saturated at ``max_range``."""
        cfg = self.config
        out = np.empty(3)
        start = (self._x, self._y)
        for i, offset in enumerate(_SENSOR_ANGLES):
            a = self._heading + offset
            end = (self._x + cfg.max_range * math.cos(a), self._y + cfg.max_range * math.sin(a))
            hit = self._space.segment_query_first(start, end, 0.0, self._ray_filter)
            out[i] = cfg.max_range if hit is None else hit.alpha * cfg.max_range
        return out

    def sense(self, rng: np.random.Generator) -> np.ndarray:
        """One observation ``[3]`` float32 (left, front, right), metres: the mean of
        ``n_readings`` noisy, clipped readings per sensor taken while standing still."""
        cfg = self.config
        true = self.true_ranges()
        sd = cfg.noise_sd + cfg.noise_sd_per_m * true
        readings = true + sd * rng.standard_normal((cfg.n_readings, 3))
        np.clip(readings, cfg.min_range, cfg.max_range, out=readings)
        return readings.mean(axis=0).astype(np.float32)
