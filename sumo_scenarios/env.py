"""``DrivingEnv``: the paper's driving task (Section 5.2) as a gymnasium environment on SUMO.

Observation (``float32`` [4]):
    ``[d_right, d_middle, d_left, ego_lane]``. ``d_*`` is the signed distance, in METRES, from the
    ego to the nearest car (smallest absolute distance) in normal lane 1 (right), 2 (middle) and
    3 (left): car position minus ego position, so positive = ahead, negative = behind, clipped to
    [-25, 25]. Every car is 5 m long, so ``|d| < 5`` in the ego's lane is contact. A lane with no
    car within the clip range reads +25 or -25, the side of its nearest car: no normal lane is
    ever empty (whenever a lane's frontmost car falls short of the traffic window's far end,
    the scenario's ``ahead_m``, 60 m or more, ahead of the ego, a new car is placed beyond it).
    ``ego_lane`` is SUMO's lane index as a float: 0 right shoulder, 1 right, 2 middle, 3 left,
    4 left shoulder (SUMO counts from the right).

Actions (``Discrete(3)``): 0 stay, 1 shift one lane left (index + 1), 2 shift one lane right
(index - 1). A shift takes effect in the same timestep; a shift off the road is clamped (the
ego stays in its lane).

One timestep = one decision = ``config.sim.step_length_s`` of driving, 0.25 s by default (the
paper: 500 timesteps ~ 2.1 min). The ego drives at exactly 60 mph; traffic keeps its lane,
each car at its own desired speed (20-40 mph) under SUMO's car-following model, so cars slow
down behind slower ones. The road never ends.
``info["contact"]`` is True when, at the end of the step, the ego overlaps a car
in the lane it is in or the lane it just left (a geometric 1-D check: SUMO's own collision list is
unreliable). Cars are never removed on contact. Reward is ``-1`` on a contact step, else 0 (the
learner does not use it). Episodes never terminate; they are truncated after
``DrivingConfig.max_episode_steps`` (1000): for longer ones pass it to the env
(``DrivingEnv(max_episode_steps=n)``, or ``gymnasium.make(ENV_ID, config=DrivingConfig(
max_episode_steps=n))``). ``gymnasium.make``'s own ``max_episode_steps`` is not passed to the
env: gymnasium keeps it for a ``TimeLimit`` outside the env, which the env cannot see, so it can
only shorten episodes: an n above the env's cap changes nothing (the env truncates first),
without a warning.

A session taught in this env keeps a description of the traffic it drives, its SUMO settings and
start lane, and of the SUMO files it loads (:meth:`DrivingEnv.describe_inputs`), so resuming it
on other traffic or settings, however given (a name or a ``TrafficScenario``, an argument of
its own, inside a ``DrivingConfig`` or left to its default), is refused. Each writer of the
session records the SUMO release it ran (:meth:`DrivingEnv.describe_versions`); a resume under
another one is warned of, not refused.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import gymnasium as gym
import numpy as np

from sumo_scenarios.scenarios import (
    EGO_SPEED_MS,
    N_LANES,
    TRAFFIC_LANES,
    TrafficScenario,
    _as_int,
    data_path,
    described_fields,
    get_scenario,
)
from sumo_scenarios.sim import HighwaySim, SimConfig, sumo_versions

__all__ = [
    "ACTION_NAMES",
    "LEFT",
    "RIGHT",
    "SENSE_RANGE_M",
    "STAY",
    "DrivingConfig",
    "DrivingEnv",
    "Frame",
]

STAY, LEFT, RIGHT = 0, 1, 2
ACTION_NAMES = ("stay", "left", "right")
SENSE_RANGE_M = 25.0
"""Observation distances are clipped to +-this many metres."""


@dataclass(frozen=True)
class DrivingConfig:
    """Settings of :class:`DrivingEnv`.

    Attributes:
        scenario: a named scenario (``train``, ``eval``, ``light``) or a :class:`TrafficScenario`,
            kept as given; a session resumes with either spelling of the same traffic.
        max_episode_steps: timesteps before ``truncated`` (1000 = one paper evaluation trial).
        start_lane: the ego's lane at reset (2 = middle), unless ``options["ego_lane"]`` says.
        sim: SUMO settings (decision period etc.).
    """

    # a name stands for the shipped scenario of that name: a session resumes with either
    # spelling of the same traffic (torchcbl.session.RESUME_AS, spelled out: importing it would
    # import torch; tests/test_resume_checks.py checks the two)
    scenario: str | TrafficScenario = field(
        default="train", metadata={"torchcbl.resume_as": get_scenario}
    )
    max_episode_steps: int = 1000
    start_lane: int = 2
    sim: SimConfig = field(default_factory=SimConfig)

    def __post_init__(self) -> None:
        get_scenario(self.scenario)
        steps = _as_int(self.max_episode_steps)  # an int, not a bool / float / string
        if steps is None or steps < 1:
            raise ValueError(
                f"max_episode_steps must be an int >= 1, got {self.max_episode_steps!r}"
            )
        if _as_int(self.start_lane) is None or not 0 <= self.start_lane < N_LANES:
            raise ValueError(
                f"start_lane must be a lane index 0-{N_LANES - 1}, got {self.start_lane!r}"
            )
        if not isinstance(self.sim, SimConfig):
            raise ValueError(
                f"sim must be a SimConfig (sumo_scenarios.sim), got {type(self.sim).__name__}"
            )
        # plain ints, as SimConfig and TrafficScenario keep plain numbers: a numpy int (from a
        # sweep over an array) made the config's asdict fail json.dumps
        object.__setattr__(self, "max_episode_steps", int(self.max_episode_steps))
        object.__setattr__(self, "start_lane", int(self.start_lane))


def _from_fields(cls: type, value: Mapping[Any, Any], where: str) -> Any:
    """``cls(**value)``: the dataclass ``cls`` made from a dict of its fields (as gymnasium's
    ``EnvSpec.to_json`` writes one), a ValueError naming ``where`` for a key that is no field
    of it or a field it needs that is left out."""
    known = [f.name for f in dataclasses.fields(cls)]
    unknown = [k for k in value if k not in known]
    if unknown:
        is_no = (
            f"is no {cls.__name__} field" if len(unknown) == 1 else f"are no {cls.__name__} fields"
        )
        raise ValueError(
            f"{where}: {', '.join(map(repr, unknown))} {is_no}; the fields are {', '.join(known)}"
        )
    needed = [
        f.name
        for f in dataclasses.fields(cls)
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    missing = [k for k in needed if k not in value]
    if missing:
        raise ValueError(
            f"{where}: no {', '.join(map(repr, missing))}, which a {cls.__name__} needs; give "
            f"a dict of its fields ({', '.join(known)}) or a {cls.__name__}"
        )
    return cls(**value)


def _settings_made(settings: Mapping[str, Any], where: str = "") -> dict[str, Any]:
    """``settings`` (keyword settings of :class:`DrivingEnv`, or a ``DrivingConfig``'s fields)
    with ``config``, ``scenario`` and ``sim`` given as a dict of the fields of a
    :class:`DrivingConfig`, :class:`TrafficScenario` or :class:`SimConfig` made into that
    object. gymnasium's ``EnvSpec.to_json`` writes such an argument as that dict
    (``dataclasses.asdict``), so ``gymnasium.make(EnvSpec.from_json(text))`` (Minari's
    ``recover_environment``) gives it to the env; a name and an object pass as they are."""
    made = dict(settings)
    for name, cls in (("scenario", TrafficScenario), ("sim", SimConfig)):
        if isinstance(made.get(name), Mapping):
            made[name] = _from_fields(cls, made[name], f"{where}{name}")
    if isinstance(made.get("config"), Mapping):
        fields = _settings_made(made["config"], f"{where}config.")
        made["config"] = _from_fields(DrivingConfig, fields, f"{where}config")
    return made


@dataclass(frozen=True)
class Frame:
    """What a drawing needs of one timestep (positions: front bumpers, metres along the road).

    ``step`` is the steps taken since reset (``info["t"]`` of the step that led here; 0 at
    reset); :func:`~sumo_scenarios.render.render_frame` titles the image ``t=<step>``.

    ``action`` is the action (0 stay, 1 left, 2 right) of the step that led here; None at
    reset.

    ``prev_lane`` is the ego's lane before the step (its lane at reset on the first frame): a
    contact counts cars in it as well as in ``ego_lane``; None when unknown.
    """

    step: int
    ego_pos: float
    ego_lane: int
    car_pos: np.ndarray
    car_lane: np.ndarray
    contact: bool
    action: int | None
    prev_lane: int | None = None


class DrivingEnv(gym.Env):
    """The driving domain on libsumo. See the module docstring for spaces and units.

    libsumo holds one simulation per process. Several ``DrivingEnv`` may exist in a process
    (``gymnasium.utils.env_checker.check_env`` makes a second one), but the simulation belongs to
    the one reset last: an env whose road another env's reset took over raises ``RuntimeError``
    on ``step`` (saying so) until it is reset again, and so does an env whose last step was cut
    short (a Ctrl-C inside it). Two envs driving at once need two processes: gymnasium's
    ``AsyncVectorEnv`` (``gymnasium.make_vec(..., vectorization_mode="async")``) runs each in
    its own, while a ``SyncVectorEnv`` (``make_vec``'s default) of two raises that
    ``RuntimeError`` at its first step. A process forked from one whose simulation runs is
    refused (there give ``AsyncVectorEnv`` ``context="spawn"``), and so is a reset while a
    simulation of your own (``libsumo.start``) runs in the process. Always ``close()`` an env.

    The settings come as a :class:`DrivingConfig` (``config``) or as its fields by keyword
    (``scenario``, ``max_episode_steps``, ``start_lane``, ``sim``). A ``DrivingConfig``,
    ``TrafficScenario`` or ``SimConfig`` may also be given as a dict of its fields: how
    gymnasium's ``EnvSpec.to_json`` writes one, so ``gymnasium.make(EnvSpec.from_json(
    env.spec.to_json()))`` (Minari's ``recover_environment``) makes the same env again.

    ``reset(seed=s)`` fixes the road segment: the traffic is drawn from
    ``SeedSequence([scenario.seed, s])``. ``reset(options={"ego_lane": k})`` starts in lane k.
    ``reset(options={"fcd_output": path})`` asks SUMO to write FCD XML for that episode (the only
    way this env writes a file, on explicit request; finalised on the next reset or ``close``).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(
        self,
        config: DrivingConfig | Mapping[str, Any] | None = None,
        *,
        render_mode: Literal["rgb_array"] | None = None,
        **kwargs: Any,
    ) -> None:
        # a DrivingConfig, TrafficScenario or SimConfig as a dict of its fields: how
        # gymnasium's EnvSpec.to_json writes it, and so how gymnasium.make(EnvSpec.from_json())
        # gives it
        settings = _settings_made({"config": config, **kwargs})
        config = settings.pop("config")
        kwargs = settings
        if config is not None and not isinstance(config, DrivingConfig):  # (with keywords too)
            hint = (
                f"DrivingEnv(scenario={config!r}) for a scenario by name"
                if isinstance(config, str)
                else "the settings as keywords, DrivingEnv(scenario='eval', max_episode_steps="
                "500) or gymnasium.make(ENV_ID, scenario='eval', ...), or config=DrivingConfig("
                "scenario='eval', ...)"
            )
            raise TypeError(
                "config: expected a DrivingConfig (sumo_scenarios.env) or a dict of its fields, "
                f"got {type(config).__name__} {config!r:.60}; e.g. {hint}"
            )
        if config is None:
            config = DrivingConfig(**kwargs)
        elif kwargs:
            raise TypeError("pass either a DrivingConfig or keyword settings, not both")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']} (the env "
                f"draws frames as images; show them yourself), got {render_mode!r}"
            )
        self.config = config
        self.scenario = get_scenario(config.scenario)
        self.render_mode = render_mode
        # real time: one frame per decision period (4 at the default 0.25 s); a recorder such
        # as gymnasium's RecordVideo plays frames at this rate
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / config.sim.step_length_s}
        self.observation_space = gym.spaces.Box(
            low=np.array([-SENSE_RANGE_M] * 3 + [0.0], dtype=np.float32),
            high=np.array([SENSE_RANGE_M] * 3 + [N_LANES - 1.0], dtype=np.float32),
            dtype=np.float32,
        )
        self.action_space = gym.spaces.Discrete(3)
        self._sim = HighwaySim(self.scenario, config.sim)
        self._episode_seed: int | None = None
        # step count -> the action that led to that step's scene (None at reset): the scene
        # before a step and the one after it, set in one assignment before the simulation
        # steps, so a Ctrl-C at any point labels the scene drawn with its own action
        self._actions: dict[int, int | None] = {}

    # ------------------------------------------------------------------ gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a new road segment: ``(observation [4], info)``.

        ``seed`` fixes the segment (traffic drawn from ``SeedSequence([scenario.seed, seed])``;
        None draws one from the env's RNG). ``options``: ``ego_lane`` (0-4, default
        ``config.start_lane``) and ``fcd_output`` (a path for SUMO's FCD XML of this episode).
        The observation is ``[d_right, d_middle, d_left, lane]``: signed metres to the nearest
        car of each normal lane (ahead positive, clipped to +-25 m) and the ego's lane index.
        """
        if seed is not None:  # True is no seed; a numpy int is the int it holds
            given, seed = seed, _as_int(seed)
            if seed is None or seed < 0:
                raise ValueError(f"seed: expected None or an int >= 0, got {given!r}")
        options = dict(options or {})
        unknown = set(options) - {"ego_lane", "fcd_output"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}")
        if self.closed:
            raise RuntimeError("this DrivingEnv is closed; create a new one")
        given = options.get("ego_lane", self.config.start_lane)
        lane = _as_int(given)
        if lane is None or not 0 <= lane < N_LANES:
            raise ValueError(f"ego_lane: expected a lane index 0-{N_LANES - 1}, got {given!r}")
        fcd = options.get("fcd_output")
        if fcd and not Path(fcd).parent.is_dir():
            raise ValueError(
                f"fcd_output: the directory of {str(fcd)!r} does not exist; create it first"
            )
        if fcd and Path(fcd).is_dir():
            raise ValueError(
                f"fcd_output: {str(fcd)!r} is a directory; give the path of the XML file to write "
                "(e.g. episode.fcd.xml inside it)"
            )
        for name in ("road.net.xml", "driving.add.xml") if fcd else ():
            # SUMO reads it, then writes the FCD over it: the install is broken for good
            if Path(fcd).exists() and os.path.samefile(fcd, data_path(name)):
                raise ValueError(
                    f"fcd_output: {str(fcd)!r} is the shipped {name} (sumo_scenarios' data), "
                    "which SUMO would overwrite with the episode's FCD; give another path"
                )
        # the env's RNG only once the call is known good: a refused reset changes no later road
        super().reset(seed=seed)
        if seed is None:
            seed = int(self.np_random.integers(0, 2**31 - 1))
        rng = np.random.default_rng(np.random.SeedSequence([self.scenario.seed, int(seed)]))
        self._episode_seed = None  # until the new segment is in place: no step() on a half reset
        self._sim.reset(rng, int(seed), ego_lane=lane, fcd_path=Path(fcd) if fcd else None)
        self._episode_seed = int(seed)
        self._actions = {}
        return self._observe(), self._info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Drive one decision period (``config.sim.step_length_s``, 0.25 s by default):
        ``action`` 0 stay, 1 one lane left, 2 one lane right (at the road's edge a shift is a
        stay). Returns ``(observation [4], reward, terminated, truncated, info)``: reward -1 in
        a step in contact with a car, else 0; never terminated; truncated after
        ``config.max_episode_steps`` steps. ``info``: ``lane`` (the ego's, 0 right shoulder to
        4 left shoulder), ``contact`` (bool), ``t`` (steps since reset), ``episode_seed``,
        ``position_m`` (metres the ego has driven since reset, not SUMO's lane position),
        ``step_length_s``, ``closing_speed_ms`` (per lane, m/s, keyed ``"1"``-``"3"``) and
        the hidden traffic state
        ``car_rel_m`` / ``car_lane`` / ``car_closing_ms`` (for scripted experts only)."""
        if self.closed:
            raise RuntimeError("this DrivingEnv is closed; create a new one")
        if self._episode_seed is None:
            raise RuntimeError("call reset() before step() (none ran, or the last one failed)")
        a = _as_int(action)  # 1.7, "1" or True is no action: refused, not rounded
        if a not in (STAY, LEFT, RIGHT):
            raise ValueError(
                f"action must be 0 (stay), 1 (left) or 2 (right), got {action!r}"
                + (
                    "; a torch tensor is not taken as an action: pass int(action) (e.g. "
                    "int(GaussianMixtureSet.classify(obs[None]).action[0]))"
                    if hasattr(action, "detach")
                    else ""
                )
            )
        lane = self._sim.ego_lane
        target = lane + (1 if a == LEFT else -1 if a == RIGHT else 0)
        target = min(max(target, 0), N_LANES - 1)
        t = self._t
        self._actions = {t: self._actions.get(t), t + 1: a}
        self._sim.step(target)
        contact = self._sim.contact
        truncated = self._t >= self.config.max_episode_steps
        return self._observe(), -1.0 if contact else 0.0, False, truncated, self._info()

    def describe_inputs(self) -> dict[str, str | int | float]:
        """What this env drives, whichever way it was given (a scenario's name or its
        :class:`TrafficScenario`, as an argument of its own or inside a :class:`DrivingConfig`,
        or not at all: the defaults): ``traffic.<field>`` for each field of the scenario but its
        name, which changes nothing the traffic does (a number as it is, a per-lane tuple as
        its JSON text), ``sim.<field>`` for each of the :class:`SimConfig`, ``start_lane``, and
        ``<file>_sha256`` for the SUMO files the env loads (``road.net.xml``, the road, and
        ``driving.add.xml``, the vehicle types): the SHA-256 of each less its XML comments
        (netconvert's header names its version), CRLF line ends read as LF. The step cap is
        left out: a session keeps the cap in force, and resume compares it on its own.

        A teaching session keeps it, and :meth:`torchcbl.ConfidentTeacher.resume` refuses an
        env whose description differs (other traffic or settings, or a network changed since);
        a session stored before the env described itself keeps none and is not compared on it.

        Raises:
            FileNotFoundError: a shipped SUMO file is missing (naming it and how to restore
                it).
        """
        described = {
            **described_fields("traffic", self.scenario),
            **described_fields("sim", self.config.sim),
            "start_lane": self.config.start_lane,
        }
        for name in ("road.net.xml", "driving.add.xml"):
            text = re.sub(rb"<!--.*?-->", b"", data_path(name).read_bytes(), flags=re.S)
            # CRLF as LF: a checkout that converts line ends holds the same network for SUMO
            text = text.replace(b"\r\n", b"\n")
            described[f"{name}_sha256"] = hashlib.sha256(text).hexdigest()
        return described

    def describe_versions(self) -> dict[str, str]:
        """What this env runs on: ``{"sumo": release}``, the SUMO release libsumo runs
        (:func:`sumo_scenarios.sim.sumo_versions`). Each writer of a teaching session records
        it in ``writers.jsonl``, and :meth:`torchcbl.ConfidentTeacher.resume` warns where it
        differs from the last writer's (another release follows cars and places traffic
        otherwise; a resume under it is not refused)."""
        return sumo_versions()

    def __reduce_ex__(self, protocol: Any) -> Any:
        return self._sim.__reduce_ex__(protocol)  # refused, with what to do instead

    @property
    def _t(self) -> int:
        """Steps of this episode: the simulation's own count, one per step()."""
        return self._sim.steps

    def render(self) -> np.ndarray | None:
        """The current timestep drawn as an RGB image [H, W, 3] uint8 (``render_mode=
        "rgb_array"``), else None with a warning. Before a completed reset, or after a step
        cut short (a Ctrl-C inside it) until a reset: RuntimeError."""
        if self.render_mode != "rgb_array":
            gym.logger.warn("render() called with render_mode=None; pass render_mode='rgb_array'")
            return None
        from sumo_scenarios.render import render_frame

        return render_frame(self.frame())

    def close(self) -> None:
        """Release the SUMO simulation (if this env holds it) and finalise any FCD output."""
        self._sim.close()

    # ------------------------------------------------------------------ helpers
    @property
    def episode_seed(self) -> int | None:
        """The seed of the current road segment (what a replay needs)."""
        return self._episode_seed

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has run."""
        return self._sim.closed

    def frame(self) -> Frame:
        """A copy of the current scene for drawing (after a completed reset; not after a step
        cut short, whose scene is half updated)."""
        if self._episode_seed is None:  # it drew an empty road with the ego at 0 m
            raise RuntimeError(
                "reset() first: there is no scene to draw before a reset has completed "
                "(none ran, or the last one failed)"
            )
        if self._sim.cut_short:  # as step() after it: the ego moved, the cars in part
            fix = (
                "this DrivingEnv is closed, so it cannot be reset: create a new one to draw again"
                if self.closed
                else "reset() to draw again (on a fresh road segment)"
            )
            raise RuntimeError(
                "the env's last step did not finish (interrupted or raised inside it), and its "
                f"scene is half updated: {fix}"
            )
        s = self._sim
        return Frame(
            self._t,
            s.ego_pos,
            s.ego_lane,
            s.car_pos.copy(),
            s.car_lane.copy(),
            s.contact,
            self._actions.get(self._t),
            s.prev_lane,
        )

    def _observe(self) -> np.ndarray:
        s = self._sim
        rel = s.car_pos - s.ego_pos
        obs = np.empty(4, dtype=np.float32)
        for k, lane in enumerate(TRAFFIC_LANES):
            r = rel[s.car_lane == lane]
            if r.size == 0:
                obs[k] = SENSE_RANGE_M
            else:
                obs[k] = min(max(r[np.argmin(np.abs(r))], -SENSE_RANGE_M), SENSE_RANGE_M)
        obs[3] = s.ego_lane
        return obs

    def _info(self) -> dict[str, Any]:
        """Info of a step. ``car_rel_m`` / ``car_lane`` / ``car_closing_ms``, tuples of N numbers
        (``numpy.asarray`` makes them arrays), describe every car in the traffic window (hidden
        state: only scripted experts may read them). Tuples, not arrays: the number of cars
        varies, and gymnasium's vector envs stack an array info into one fixed-shape array (an
        AsyncVectorEnv of two driving envs failed at its first reset); a tuple they keep as is;
        ``closing_speed_ms`` maps each normal lane, by its number as text (``"1"``, ``"2"``,
        ``"3"``), to the closing speed (m/s, ego speed minus the car's speed over the last
        step) of the car the observation reports for that lane, which a driver sees (0 when no
        car is within sensing range). Text, not ints: gymnasium's vector envs and their info
        wrappers (``DictInfoToList``) take an info's keys, nested ones too, as text (an int key
        failed there), and a session's JSON log holds them so."""
        s = self._sim
        rel = s.car_pos - s.ego_pos
        car_closing = EGO_SPEED_MS - s.car_speed
        closing = {}
        for lane in TRAFFIC_LANES:
            m = np.flatnonzero(s.car_lane == lane)
            if m.size == 0:
                closing[str(lane)] = 0.0
                continue
            k = m[np.argmin(np.abs(rel[m]))]
            closing[str(lane)] = float(car_closing[k]) if abs(rel[k]) < SENSE_RANGE_M else 0.0
        return {
            "lane": s.ego_lane,
            "contact": s.contact,
            "t": self._t,
            "episode_seed": self._episode_seed,
            "position_m": s.distance_m,
            "car_lane": tuple(s.car_lane.tolist()),
            "car_rel_m": tuple(rel.tolist()),
            "car_closing_ms": tuple(car_closing.tolist()),
            "closing_speed_ms": closing,
            "step_length_s": self.config.sim.step_length_s,
        }
