"""``CorridorEnv``: the corridor world as a gymnasium environment (id ``torchcbl/Corridor-v0``).

Observation: ``Box([0, 0, 0], [max_range] * 3, float32)``, the averaged range readings
(left, front, right) in metres. Actions: ``Discrete(4)``, see :class:`corridor.world.Action`
(0 forward, 1 turn left, 2 turn right, 3 u-turn).

Episode = one circuit. ``reset`` puts the robot at the map's start pose. The episode is
``terminated`` when the circuit is completed (the robot is back at the start, having followed
the route), with ``info["is_success"] = True`` iff no wall was touched during it; it is
``truncated`` after ``max_episode_steps`` actions (default 81: 3 x 27, the actions of a perfect
circuit on the default map as first drawn; 29 since its spur was lengthened, so 2.8 circuits; on
a map whose circuit takes more than 40 actions, two circuits), with ``info["is_success"] =
False``. The reward is 1 for completing the circuit, -1 for each wall contact, 0 otherwise (the
teaching loop does not use it).

Step caps. ``CorridorEnv(max_episode_steps=n)`` sets the env's own cap (``env.unwrapped.
max_episode_steps``), and warns when a circuit of the map does not fit in it.
``gymnasium.make(ENV_ID, max_episode_steps=n)`` does not pass n to the env: gymnasium keeps it
for a ``TimeLimit`` wrapper outside the env, which the env cannot see (gymnasium gives it a spec
without the cap). So an n shorter than a circuit cuts every episode mid-circuit without a
warning, and an n above the env's own cap (its default) changes nothing: the env truncates
first. To raise the env's own cap, make the env yourself, ``CorridorEnv(corridor_map,
max_episode_steps=n)``, or, where a gymnasium id is needed (``make_vec``, the benchmark), register
one whose kwargs carry it: ``gymnasium.register("mine/Corridor-v0", entry_point=
"corridor.env:CorridorEnv", kwargs={"max_episode_steps": n})``, then ``gymnasium.make(
"mine/Corridor-v0", ...)`` (it warns as ``CorridorEnv`` does).

``info`` after ``reset`` and every ``step``:
  ``pose`` ndarray [3] (x m, y m, heading rad); ``true_ranges`` ndarray [3] noise-free metres;
  ``contact`` bool (this step touched a wall); ``contacts`` int (this episode);
  ``blocked`` list of 4 ints, after a contact only (else zeros): for the robot's heading and
  the headings a turn left, a turn right and a u-turn would give it (rotating in place), 0 if
  a forward step without noise would take it at least half its length that way, else the side
  of the wall that stops it (+1 left, -1 right or ahead; :meth:`CorridorWorld.blocked`: a wall
  or corner the rays need not see counts);
  ``laps`` int (circuits completed this episode); ``lap_position`` metres along the route;
  ``progress`` fraction of the circuit in [0, 1]; ``segment`` int (route segment index);
  ``steps`` int; and ``is_success`` bool when the episode ends.

Randomness: the sensor noise, the motion noise (when ``WorldConfig`` asks for it) and the start
perturbation (when ``start_perturbation`` is set), all drawn from ``self.np_random`` (seeded by
``reset(seed=)``), so the same seed and actions give the same run.

Perturbed starts (``start_perturbation=(d, a)``): each ``reset`` moves the start pose by offsets
drawn uniformly in [-d, d] metres along x and y and [-a, a] radians of heading (redrawn until the
robot does not overlap a wall), to test a policy off the demonstrated route. ``a`` is less than
pi/4 (45 degrees): the first action turns the robot back to the start heading's axis (see
:meth:`CorridorWorld.reset`), so a larger offset, nearer another axis, would mislead whoever
steers by the axis the robot faces.

A session taught in this env keeps the digest of its map (:meth:`CorridorEnv.describe_inputs`),
so resuming it on a map edited since is refused. Each writer of the session records the pymunk
it ran (:meth:`CorridorEnv.describe_versions`); a resume under another one is warned of, not
refused.

Envs never write files; rendering returns RGB arrays (see :mod:`corridor.render` to save PNGs).
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from corridor.maps import CorridorMap, map_digest
from corridor.world import N_ACTIONS, CorridorWorld, WorldConfig, pymunk_versions

__all__ = ["CorridorEnv", "DEFAULT_MAP"]

DEFAULT_MAP = "figure2"
_TURNS = (0.0, math.pi / 2, -math.pi / 2, math.pi)  # ahead, turn left, turn right, u-turn


def _circuit_actions(world: CorridorWorld) -> int:
    """About how many actions a circuit of ``world``'s route takes with exact motion: a forward
    step per ``forward_distance`` of route, less one for each turn or u-turn (a turn from the
    decision point covers the corner); exactly the 29 of figure2 and the 34 of lshape."""
    route = world.route
    turns = sum(kind != "straight" for kind in route.kinds)
    return round(route.length / world.config.forward_distance) - turns


def _default_steps(world: CorridorWorld) -> int:
    """``CorridorEnv``'s default step cap for ``world``'s map and robot: 81, or two circuits of
    a route whose circuit takes more than 40 actions."""
    return max(81, 2 * _circuit_actions(world))


class CorridorEnv(gym.Env):
    """The robot corridor domain of the paper's Section 5.1.

    Args:
        corridor_map: a :class:`CorridorMap`, or the name of a shipped map / a JSON path.
        world_config: robot, motion and sensor parameters: a :class:`WorldConfig`, a dict of
            its fields (as ``gymnasium.make`` kwargs keep it), or None for the defaults.
        max_episode_steps: the env's own cap, actions before truncation; None = 81, or two
            circuits of a map whose circuit takes more than 40 actions. ``gymnasium.make``
            keeps its own ``max_episode_steps`` for a ``TimeLimit`` outside the env, which can
            only shorten episodes, unchecked (see the module docstring, "Step caps").
        render_mode: None or "rgb_array".
        start_perturbation: ``(metres, radians)`` half-widths of the uniform start offsets
            (metres less than half the corridor's width less the robot's radius, radians less
            than pi/4), or None for the map's exact start pose.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(
        self,
        corridor_map: CorridorMap | str | os.PathLike[str] = DEFAULT_MAP,
        world_config: WorldConfig | Mapping[str, Any] | None = None,
        max_episode_steps: int | None = None,
        render_mode: Literal["rgb_array"] | None = None,
        start_perturbation: tuple[float, float] | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        # a map name or path and a dict of WorldConfig fields (as gymnasium.make kwargs keep a
        # config) are CorridorWorld's to take
        self.world = CorridorWorld(corridor_map, world_config)
        corridor_map = self.world.map
        circuit = _circuit_actions(self.world)
        # the default is the only cap gymnasium.make can give the env (make keeps
        # max_episode_steps for its TimeLimit): 81, or two circuits of a longer map's route
        steps = _default_steps(self.world) if max_episode_steps is None else max_episode_steps
        if (
            isinstance(steps, (bool, np.bool_))
            or not isinstance(steps, (int, np.integer))
            or steps < 1
        ):
            raise ValueError(f"max_episode_steps must be an int >= 1, got {steps!r}")
        self.max_episode_steps = int(steps)
        if circuit > self.max_episode_steps:
            warnings.warn(
                f"map {corridor_map.name!r}: a circuit of its route takes about {circuit} "
                f"actions, more than max_episode_steps={self.max_episode_steps}, so every "
                "episode is cut before a circuit ends; pass a larger max_episode_steps, or "
                f"leave it None (here {_default_steps(self.world)}: 81, or two circuits of a "
                "longer route)",
                stacklevel=2,
            )
        self.render_mode = render_mode
        if start_perturbation is not None:
            half = corridor_map.corridor_width / 2 - self.world.config.robot_radius
            pair = (
                (
                    isinstance(start_perturbation, Sequence)
                    and not isinstance(start_perturbation, (str, bytes))
                    or isinstance(start_perturbation, np.ndarray)
                    and start_perturbation.ndim == 1
                )
                and len(start_perturbation) == 2
                and all(
                    isinstance(v, (int, float, np.integer, np.floating))
                    and not isinstance(v, (bool, np.bool_))
                    for v in start_perturbation
                )
            )
            d, a = (float(v) for v in start_perturbation) if pair else (math.nan, math.nan)
            if not (0 <= d < half and 0 <= a < np.pi / 4):
                why = (
                    ": a heading offset of 45 degrees or more can face the robot as near "
                    "another axis as the start heading's, while its first action turns it "
                    "back to the start heading's axis, so an expert (or policy) that steers "
                    "by the nearest axis can drive into a wall"
                    if a >= np.pi / 4
                    else ""
                )
                raise ValueError(
                    f"start_perturbation must be (metres in [0, {half:.2f}), radians in "
                    f"[0, pi/4)), got {start_perturbation!r}{why}"
                )
            start_perturbation = (d, a)
        self.start_perturbation = start_perturbation
        r = self.world.config.max_range
        self.observation_space = spaces.Box(0.0, r, shape=(3,), dtype=np.float32)
        self.action_space = spaces.Discrete(N_ACTIONS)
        self._steps = 0
        self._contacts = 0
        self._path: list[tuple[float, float]] = []
        self._last_obs = np.zeros(3, dtype=np.float32)
        self._was_reset = False  # step() before any reset would run on an unseeded generator

    @property
    def corridor_map(self) -> CorridorMap:
        """The map the env runs."""
        return self.world.map

    def describe_inputs(self) -> dict[str, str]:
        """What identifies this env's map beyond the name it was given: ``{"corridor_map_sha256":
        hex}`` (:func:`corridor.maps.map_digest`). A teaching session keeps it and
        :meth:`torchcbl.ConfidentTeacher.resume` refuses an env whose map differs (a map file
        edited since, or another ``CorridorMap`` object)."""
        return {"corridor_map_sha256": map_digest(self.world.map)}

    def describe_versions(self) -> dict[str, str]:
        """What this env runs on: ``{"pymunk": version}`` (:func:`corridor.world.pymunk_versions`).
        Each writer of a teaching session records it in ``writers.jsonl``, and
        :meth:`torchcbl.ConfidentTeacher.resume` warns where it differs from the last
        writer's (a resume under it is not refused)."""
        return pymunk_versions()

    @property
    def path(self) -> list[tuple[float, float]]:
        """Robot positions (metres) since the last reset, start included."""
        return list(self._path)

    def _info(self, contact: bool) -> dict[str, Any]:
        w = self.world
        return {
            "pose": np.asarray(w.pose, dtype=np.float64),
            "true_ranges": w.true_ranges(),
            "contact": bool(contact),
            # after a contact: which ways does a wall stop the robot at once (and on which side)?
            "blocked": [w.blocked(t) for t in _TURNS] if contact else [0, 0, 0, 0],
            "contacts": self._contacts,
            "laps": w.laps,
            "lap_position": w.lap_position,
            "progress": w.lap_position / w.route.length,
            "segment": w.progress.segment,
            "steps": self._steps,
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a circuit at the start pose. ``options`` takes nothing (an unknown key is an
        error, as in ``DrivingEnv``)."""
        super().reset(seed=seed)
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}; CorridorEnv takes none")
        if self.start_perturbation is None:
            self.world.reset()
        else:
            d, a = self.start_perturbation
            while True:
                u = self.np_random.uniform(-1.0, 1.0, size=3)
                try:
                    self.world.reset((d * float(u[0]), d * float(u[1]), a * float(u[2])))
                    break
                except ValueError:
                    continue
        self._steps = 0
        self._contacts = 0
        self._path = [self.world.pose[:2]]
        self._last_obs = self.world.sense(self.np_random)
        self._was_reset = True
        return self._last_obs.copy(), self._info(False)

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One action, then the robot stands still and senses."""
        # a bool is no action (gymnasium's Discrete takes True as 1): refused, as DrivingEnv
        # and the teaching loop refuse it
        if isinstance(action, (bool, np.bool_)) or not self.action_space.contains(action):
            integer = isinstance(action, (int, np.integer)) and not isinstance(
                action, (bool, np.bool_)
            )
            raise ValueError(
                f"action must be an int in [0, {N_ACTIONS}) (0 forward, 1 turn left, 2 turn "
                f"right, 3 u-turn), got {action!r}"
                + (
                    ""
                    if integer
                    else "; a torch tensor is not taken as an action: pass int(action) (e.g. "
                    "int(GaussianMixtureSet.classify(obs[None]).action[0]))"
                    if hasattr(action, "detach")
                    else "; pass int(action) of an integer action (a 0-d array); a bool or a "
                    "float is not rounded"
                )
            )
        if not self._was_reset:
            raise RuntimeError("call reset() before step()")
        laps_before = self.world.laps
        contact = self.world.step(int(action), self.np_random)
        self._steps += 1
        self._contacts += int(contact)
        self._path.append(self.world.pose[:2])
        self._last_obs = self.world.sense(self.np_random)
        terminated = self.world.laps > laps_before
        truncated = not terminated and self._steps >= self.max_episode_steps
        reward = (1.0 if terminated else 0.0) - (1.0 if contact else 0.0)
        info = self._info(contact)
        if terminated or truncated:
            info["is_success"] = bool(terminated and self._contacts == 0)
        return self._last_obs.copy(), reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """An RGB array [H, W, 3] uint8 of the map, robot, sensor rays and path so far."""
        if self.render_mode is None:
            gym.logger.warn("render() called with render_mode=None; pass render_mode='rgb_array'")
            return None
        from corridor.render import render_rgb

        return render_rgb(self.world, self._path, self._last_obs)
