"""Recording and replaying driving episodes.

An episode is fully determined by (scenario, SUMO settings, episode seed, start lane, actions):
:class:`EpisodeRecorder` (a gymnasium wrapper) records exactly that for every episode run through
it, and :func:`replay` re-runs it bit-identically. A replay can also be exported as SUMO FCD XML
(:func:`export_fcd`, readable by sumolib and SUMO's tools) or drawn into a GIF
(:func:`render_gif`). Nothing here writes a file unless asked to by name.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from sumo_scenarios.env import DrivingConfig, DrivingEnv
from sumo_scenarios.scenarios import TrafficScenario
from sumo_scenarios.sim import SimConfig


@dataclass(frozen=True)
class EpisodeRecord:
    """One recorded episode.

    Attributes:
        scenario: the traffic scenario (all its fields, so a replay does not depend on names).
        sim: the SUMO settings.
        episode_seed: the seed passed to ``reset`` (fixes the road segment).
        start_lane: the ego's lane at reset.
        actions: the executed actions, one per timestep.
        label: free text (e.g. ``"seed3/arm_a/eval_final"``).
    """

    scenario: TrafficScenario
    sim: SimConfig
    episode_seed: int
    start_lane: int
    actions: tuple[int, ...]
    label: str = ""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (inverse of :meth:`from_dict`)."""
        d = dataclasses.asdict(self)
        d["actions"] = list(self.actions)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EpisodeRecord:
        """Rebuild a record written by :meth:`to_dict`."""
        sc = dict(d["scenario"])
        if "lane_speeds_mph" in sc:
            raise ValueError(
                "this episode was recorded with the old constant-speed traffic (lane_speeds_mph); "
                "it cannot be replayed on today's car-following traffic: record it again"
            )
        sc["mean_spacing_m"] = tuple(sc["mean_spacing_m"])
        sc["speed_ranges_mph"] = tuple(tuple(r) for r in sc["speed_ranges_mph"])
        return cls(
            scenario=TrafficScenario(**sc),
            sim=SimConfig(**d["sim"]),
            episode_seed=int(d["episode_seed"]),
            start_lane=int(d["start_lane"]),
            actions=tuple(int(a) for a in d["actions"]),
            label=str(d.get("label", "")),
        )


def save_records(records: list[EpisodeRecord], path: str | Path) -> None:
    """Write records as one JSON file."""
    Path(path).write_text(json.dumps([r.to_dict() for r in records]))


def load_records(path: str | Path) -> list[EpisodeRecord]:
    """Read records written by :func:`save_records`."""
    return [EpisodeRecord.from_dict(d) for d in json.loads(Path(path).read_text())]


class EpisodeRecorder(gym.Wrapper):
    """Records every episode of a :class:`DrivingEnv` as an :class:`EpisodeRecord`.

    ``episodes`` lists finished and current episodes (the current one is in progress). An
    episode takes the ``label`` in force when it was reset; an episode in which no step was
    taken (a reset followed at once by another) is not recorded.
    """

    def __init__(self, env: gym.Env, label: str = "") -> None:
        super().__init__(env)
        if not isinstance(env.unwrapped, DrivingEnv):
            raise TypeError("EpisodeRecorder wraps a DrivingEnv")
        self.label = label
        self._done: list[EpisodeRecord] = []
        self._actions: list[int] = []
        self._head: dict[str, Any] | None = None

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        self._flush()
        obs, info = self.env.reset(**kwargs)
        base: DrivingEnv = self.env.unwrapped  # type: ignore[assignment]
        self._head = {
            "scenario": base.scenario,
            "sim": base.config.sim,
            "episode_seed": base.episode_seed,
            "start_lane": int(info["lane"]),
            "label": self.label,
        }
        self._actions = []
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        out = self.env.step(action)
        self._actions.append(int(action))
        return out

    def _flush(self) -> None:
        if self._head is not None and self._actions:
            self._done.append(EpisodeRecord(**self._head, actions=tuple(self._actions)))
        self._head = None

    @property
    def episodes(self) -> list[EpisodeRecord]:
        """All recorded episodes, the one in progress last."""
        cur = []
        if self._head is not None and self._actions:
            cur = [EpisodeRecord(**self._head, actions=tuple(self._actions))]
        return self._done + cur


@dataclass(frozen=True)
class ReplayResult:
    """What a replay produced: observations [T+1, 4] float32 (the reset one first), lanes [T+1]
    int64, contacts [T+1] bool."""

    observations: np.ndarray
    lanes: np.ndarray
    contacts: np.ndarray


def _env_for(record: EpisodeRecord) -> DrivingEnv:
    cfg = DrivingConfig(
        scenario=record.scenario,
        max_episode_steps=max(1, len(record.actions)),
        start_lane=record.start_lane,
        sim=record.sim,
    )
    return DrivingEnv(cfg)


def replay(
    record: EpisodeRecord, *, fcd_output: str | Path | None = None, frames: bool = False
) -> tuple[ReplayResult, list[Any]]:
    """Re-run a recorded episode (needs no other live DrivingEnv in this process).

    Returns the :class:`ReplayResult` and, if ``frames``, the list of
    :class:`~sumo_scenarios.env.Frame` per timestep (else an empty list). ``fcd_output`` makes
    SUMO write FCD XML of the episode to that path.
    """
    env = _env_for(record)
    try:
        opts: dict[str, Any] = {"ego_lane": record.start_lane}
        if fcd_output is not None:
            opts["fcd_output"] = str(fcd_output)
        obs, info = env.reset(seed=record.episode_seed, options=opts)
        o, lanes, contacts = [obs], [info["lane"]], [info["contact"]]
        shots = [env.frame()] if frames else []
        for a in record.actions:
            obs, _, _, _, info = env.step(a)
            o.append(obs)
            lanes.append(info["lane"])
            contacts.append(info["contact"])
            if frames:
                shots.append(env.frame())
    finally:
        env.close()
    result = ReplayResult(
        np.stack(o), np.asarray(lanes, dtype=np.int64), np.asarray(contacts, dtype=bool)
    )
    return result, shots


def export_fcd(record: EpisodeRecord, path: str | Path) -> Path:
    """Write the episode's SUMO FCD XML (every vehicle, every timestep) to ``path``."""
    path = Path(path)
    replay(record, fcd_output=path)
    return path


def render_gif(
    record: EpisodeRecord,
    path: str | Path,
    *,
    every: int = 1,
    max_frames: int | None = None,
    fps: float = 4.0,
) -> Path:
    """Draw the episode into a GIF: every ``every``-th timestep of the WHOLE episode (unless
    ``max_frames`` caps it), played at ``fps`` frames per second (4 = real time at stride 1 and
    0.25 s steps). The frame delay is written in milliseconds, as imageio's GIF writer expects."""
    import imageio.v2 as imageio

    from sumo_scenarios.render import render_frame

    if every < 1 or (max_frames is not None and max_frames < 1) or fps <= 0:
        raise ValueError(
            f"every and max_frames must be positive and fps > 0, got every={every}, "
            f"max_frames={max_frames}, fps={fps}"
        )
    _, shots = replay(record, frames=True)
    shots = shots[::every]
    if max_frames is not None:
        shots = shots[:max_frames]
    images = [render_frame(f) for f in shots]
    path = Path(path)
    imageio.mimsave(path, images, duration=1000.0 / fps, loop=0)
    return path


def write_sumocfg(record: EpisodeRecord, fcd_path: str | Path, path: str | Path) -> Path:
    """Write a ``.sumocfg`` beside an exported FCD file, for ``sumo-gui -c PATH``.

    It names the shipped network and additional file (absolute paths), the episode's step
    length, begin 0 and end at the episode's last step, and the FCD file (as ``fcd-output``
    of a re-run, under another name, so the recording is never overwritten). It holds no
    routes: the traffic of an episode is placed through the API, so SUMO on its own shows the
    empty road; use the FCD (sumo-gui's trajectory tools, or the GIF) to watch the cars.
    """
    from sumo_scenarios.scenarios import data_path

    path = Path(path)
    fcd = Path(fcd_path).resolve()
    end = len(record.actions) * record.sim.step_length_s
    text = f"""<?xml version="1.0" encoding="UTF-8"?>
<!-- Written by sumo_scenarios.replay.write_sumocfg for episode {record.label or "-"}
     (episode seed {record.episode_seed}); recorded FCD: {fcd.name} -->
<configuration>
    <input>
        <net-file value="{data_path("road.net.xml")}"/>
        <additional-files value="{data_path("driving.add.xml")}"/>
    </input>
    <time>
        <begin value="0"/>
        <end value="{end!r}"/>
        <step-length value="{record.sim.step_length_s!r}"/>
    </time>
    <processing>
        <collision.action value="warn"/>
    </processing>
    <output>
        <fcd-output value="{fcd.with_name(fcd.stem + ".rerun.xml")}"/>
    </output>
    <report>
        <no-step-log value="true"/>
    </report>
</configuration>
"""
    path.write_text(text)
    return path
