"""Recording and replaying driving episodes.

An episode is fully determined by (scenario, SUMO settings, episode seed, start lane, actions):
:class:`EpisodeRecorder` (a gymnasium wrapper) records exactly that for every episode run through
it, and :func:`replay` re-runs it bit-identically. A replay can also be exported as SUMO FCD XML
(:func:`export_fcd`, readable by sumolib and SUMO's tools) or drawn into a GIF
(:func:`render_gif`). The episodes of a teaching session directory (``torchcbl teach driving``,
or a ``ConfidentTeacher`` on ``torchcbl/Driving-v0``) are read as records too
(:func:`session_episodes`). Nothing here writes a file unless asked to by name.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from sumo_scenarios.env import DrivingConfig, DrivingEnv, _settings_made
from sumo_scenarios.scenarios import (
    N_LANES,
    TrafficScenario,
    _as_int,
    _is_real,
    get_scenario,
)
from sumo_scenarios.sim import SimConfig

__all__ = [
    "EpisodeRecord",
    "EpisodeRecorder",
    "ReplayResult",
    "export_fcd",
    "load_records",
    "render_gif",
    "replay",
    "save_records",
    "session_episodes",
    "write_sumocfg",
]


@dataclass(frozen=True)
class EpisodeRecord:
    """One recorded episode.

    Attributes:
        scenario: the traffic scenario (all its fields, so a replay does not depend on names);
            a scenario's name (``"train"``) is taken as that scenario.
        sim: the SUMO settings (a :class:`~sumo_scenarios.sim.SimConfig`).
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

    def __post_init__(self) -> None:
        def is_int(v: Any) -> bool:
            return isinstance(v, int | np.integer) and not isinstance(v, bool)

        # the scenario itself, not its name: to_dict writes its fields, which from_dict (and
        # so load_records) needs; a name was saved as the name, and the file read back refused
        object.__setattr__(self, "scenario", get_scenario(self.scenario))
        if not isinstance(self.sim, SimConfig):
            raise ValueError(
                f"sim: expected a SimConfig (sumo_scenarios.sim), got {type(self.sim).__name__} "
                f"{self.sim!r:.60}"
            )
        if not is_int(self.episode_seed) or self.episode_seed < 0:
            raise ValueError(f"episode_seed: expected an int >= 0, got {self.episode_seed!r}")
        if not is_int(self.start_lane) or not 0 <= self.start_lane < N_LANES:
            raise ValueError(
                f"start_lane: expected a lane index 0-{N_LANES - 1}, got {self.start_lane!r}"
            )
        if not isinstance(self.actions, tuple) or not self.actions:
            raise ValueError(
                f"actions: expected a non-empty tuple of actions, got {self.actions!r:.40}"
            )
        bad = [a for a in self.actions if not is_int(a) or not 0 <= a < 3]
        if bad:
            raise ValueError(
                f"actions: expected 0 (stay), 1 (left) or 2 (right) at every step, got "
                f"{bad[:3]!r}{' ...' if len(bad) > 3 else ''}"
            )

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (inverse of :meth:`from_dict`)."""
        d = dataclasses.asdict(self)
        d["actions"] = list(self.actions)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EpisodeRecord:
        """Rebuild a record written by :meth:`to_dict`."""
        need = ("scenario", "sim", "episode_seed", "start_lane", "actions")
        if not isinstance(d, dict) or not set(need) <= d.keys():
            got = f"a dict with keys {sorted(map(str, d))}" if isinstance(d, dict) else repr(d)
            raise ValueError(
                f"an episode record is a dict with keys {list(need)} (as to_dict writes it), "
                f"got {got:.120}"
            )
        if not isinstance(d["scenario"], dict) or not isinstance(d["sim"], dict):
            raise ValueError(
                "an episode record's scenario and sim are dicts of their fields, got "
                f"{d['scenario']!r:.60} and {d['sim']!r:.60}"
            )
        sc = dict(d["scenario"])
        if "lane_speeds_mph" in sc:
            raise ValueError(
                "this episode was recorded with the old constant-speed traffic (lane_speeds_mph); "
                "it cannot be replayed on today's car-following traffic: record it again"
            )
        # written by every to_dict since the traffic got per-car speeds: a default in their
        # place would replay other traffic (TrafficScenario checks them and makes lists tuples)
        lacking = [k for k in ("mean_spacing_m", "speed_ranges_mph") if k not in sc]
        if lacking:
            raise ValueError(
                f"an episode record's scenario lacks {' and '.join(lacking)} (to_dict writes "
                f"every field of the scenario), got the fields {sorted(map(str, sc))}"
            )
        if not isinstance(d["actions"], list):
            raise ValueError(f"actions: expected a JSON list, got {d['actions']!r:.40}")
        return cls(  # the fields are checked as they are, not coerced (1.7 is no action)
            scenario=TrafficScenario(**sc),
            sim=SimConfig(**d["sim"]),
            episode_seed=d["episode_seed"],
            start_lane=d["start_lane"],
            actions=tuple(d["actions"]),
            label=str(d.get("label", "")),
        )


def save_records(records: list[EpisodeRecord], path: str | Path) -> None:
    """Write records as one JSON file."""
    Path(path).write_text(json.dumps([r.to_dict() for r in records]), encoding="utf-8")


def load_records(path: str | Path) -> list[EpisodeRecord]:
    """Read records written by :func:`save_records` (a JSON list of
    :meth:`EpisodeRecord.to_dict`; the driving experiment's ``seed_<k>/episodes.json`` is one).

    Raises:
        ValueError: the file is not JSON or not such a list, naming the file.
    """
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path} is not JSON ({exc}): expected episode records") from None
    if not isinstance(data, list):
        raise ValueError(
            f"{path} holds a JSON {type(data).__name__}, not a list of episode records (as "
            "save_records writes them; a teaching session's directory is read by "
            "session_episodes)"
        )
    try:
        return [EpisodeRecord.from_dict(d) for d in data]
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{path}: {exc}") from None


class EpisodeRecorder(gym.Wrapper):
    """Records every episode of a :class:`DrivingEnv` as an :class:`EpisodeRecord`.

    ``episodes`` lists finished and current episodes (the current one is in progress). An
    episode takes the ``label`` in force when it was reset; an episode in which no step was
    taken (a reset followed at once by another) is not recorded. A reset the env refuses
    (a bad seed or option) ends nothing: the episode it left running goes on being recorded.
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
        # the episode ends once the env's reset has run: a reset it refuses (a bad option)
        # leaves the episode running, and steps taken after it still belong to it
        obs, info = self.env.reset(**kwargs)
        self._flush()
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
    """Re-run a recorded episode. It takes this process's one libsumo simulation: a live
    DrivingEnv must be reset after it (its step says so).

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


_DRIVING_ID = "torchcbl/Driving-v0"

#: the classes a driving session's make arguments are rebuilt as (env_make_argument)
_MAKE_CLASSES: dict[str, Any] = {
    "sumo_scenarios.scenarios:TrafficScenario": TrafficScenario,
    "sumo_scenarios.sim:SimConfig": SimConfig,
    "sumo_scenarios.env:DrivingConfig": DrivingConfig,
}


def _session_make_kwargs(config: dict[str, Any]) -> tuple[dict[str, Any], dict[str, str]]:
    """What ``gymnasium.make`` was given for a driving session's env (``render_mode`` aside),
    objects made again (:func:`torchcbl.session.env_make_arguments`), and, by argument, why one
    cannot be (given as an object the session keeps only as text: a session written before
    2026-11-27, or an object of another class), in words: ``(kwargs, unknown)``. A start lane
    or step cap kept as the text of a numpy int is read as its int. What replay, evaluate and
    ``torchcbl teach driving --resume`` make the session's env again with."""
    import re

    from torchcbl.session import env_make_arguments

    kwargs, unknown = env_make_arguments(config, _MAKE_CLASSES)  # render_mode aside
    kept = (config.get("env") or {}).get("kwargs") or {}
    for name in ("start_lane", "max_episode_steps"):
        if name in unknown:  # a numpy int: "np.int64(3)" (numpy 1: "3")
            found = re.fullmatch(r"(?:\w+(?:\.\w+)*\()?(\d+)\)?", str(kept[name]["repr"]))
            if found:
                kwargs[name] = int(found.group(1))
                del unknown[name]
    return kwargs, unknown


def _session_make_settings(config: dict[str, Any]) -> tuple[dict[str, Any], dict[str, str]]:
    """What a driving session's env was made with: ``(settings, unknown)``, the arguments
    ``gymnasium.make`` was given (:func:`_session_make_kwargs`), a ``DrivingConfig``
    (``config=``) as its fields; and, by setting, why one cannot be known, in words."""
    kwargs, unknown = _session_make_kwargs(config)
    # a DrivingConfig, TrafficScenario or SimConfig given as a dict of its fields (an env made
    # again from its spec as JSON), as the env made it
    settings = _settings_made(kwargs)
    whole = settings.pop("config", None)
    if isinstance(whole, DrivingConfig):
        settings.update((f.name, getattr(whole, f.name)) for f in dataclasses.fields(DrivingConfig))
    elif "config" in unknown:  # none of its settings is known
        why = unknown.pop("config")
        unknown.update((f.name, why) for f in dataclasses.fields(DrivingConfig))
    elif whole is not None:
        settings["config"] = whole  # not a DrivingConfig: DrivingEnv's to refuse
    return settings, unknown


def session_episodes(
    run_dir: str | Path, *, check: bool | Sequence[int] = False
) -> list[EpisodeRecord]:
    """The episodes of a teaching session of the driving env, as records to replay.

    The session directory is one written by ``torchcbl teach driving`` or by a
    ``ConfidentTeacher`` on ``gymnasium.make("torchcbl/Driving-v0", ...)``. Each episode's record
    holds the actions the session executed, its road segment (the ``episode_seed`` of its steps'
    ``info``), its start lane (the lane of its first observation) and the env's settings (what
    ``gymnasium.make`` was given: a scenario's name, or ``TrafficScenario``, ``SimConfig`` and
    ``DrivingConfig`` objects, which the session keeps whole); its label is
    ``"<run_dir name>/episode <k>"`` (k: the session's episode number). A step whose action
    may never have run (a demonstration cut by a crash, ``info["torchcbl_interrupted"]``) is
    left out, and with it its episode when it was the first.

    Args:
        run_dir: the session directory.
        check: replay every episode (True), or those at these indices of the returned list,
            and compare its observations with the ones the session logged (bit for bit); a
            replay that diverges (another SUMO, another traffic version) raises ValueError
            naming the episode and the step.

    Raises:
        ValueError: not a session of the driving env, made with settings it keeps only as text
            (an object given to ``gymnasium.make`` by a session written before 2026-11-27, or
            one of another class than those above) or that the env does not take, or
            (``check``) a replay that diverges.
    """
    from torchcbl.session import load_config
    from torchcbl.session import load_records as load_steps

    run = Path(run_dir).resolve()  # its name labels the episodes, "." included
    env = load_config(run).get("env") or {}
    if env.get("id") != _DRIVING_ID:
        made = (
            f"of {env['id']!r}"
            if env.get("id")
            else "of an env made without gymnasium.make (as the experiments make theirs)"
        )
        raise ValueError(
            f"{run} is a teaching session {made}, not of {_DRIVING_ID!r}: only sessions of "
            "the driving env made by gymnasium.make replay from their log (the driving "
            "experiment's episodes are in its seed_<k>/episodes.json)"
        )
    kwargs, unknown = _session_make_settings(load_config(run))
    if unknown:
        raise ValueError(
            f"{run}: its episodes cannot be rebuilt: {'; '.join(sorted(set(unknown.values())))}"
            " (wrap the env in EpisodeRecorder to record them)"
        )
    try:
        config = DrivingConfig(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"{run}: its env's settings {kwargs} are not DrivingEnv's ({exc})"
        ) from None

    scenario = get_scenario(config.scenario)
    episodes: dict[int, list[Any]] = {}
    for r in load_steps(run):
        if r.info.get("torchcbl_interrupted"):
            continue  # its action may never have run
        episodes.setdefault(r.episode, []).append(r)
    if isinstance(check, bool):
        checked = set(range(len(episodes))) if check else set()
    else:
        checked = {int(i) for i in check}
        if any(not 0 <= i < len(episodes) for i in checked):
            raise ValueError(
                f"check: expected indices in [0, {len(episodes)}) (the session's episodes), "
                f"got {sorted(checked)}"
            )
    out = []
    for i, (k, steps) in enumerate(episodes.items()):
        seeds = {s.info.get("episode_seed") for s in steps}
        if len(seeds) != 1:
            raise ValueError(f"{run}: episode {k}'s steps name road segments {sorted(seeds)}")
        record = EpisodeRecord(
            scenario=scenario,
            sim=config.sim,
            episode_seed=int(seeds.pop()),
            start_lane=int(steps[0].observation[3]),
            actions=tuple(int(s.executed_action) for s in steps),
            label=f"{run.name}/episode {k}",
        )
        if i in checked:
            _check_against(record, np.asarray([s.observation for s in steps]), f"{run} {k}")
        out.append(record)
    return out


def _check_against(record: EpisodeRecord, logged: np.ndarray, where: str) -> None:
    """Raise ValueError unless the replay's decision-time observations equal ``logged`` [T, 4]."""
    result, _ = replay(record)
    replayed = result.observations[:-1].astype(np.float64)
    differ = np.flatnonzero(~np.all(replayed == logged, axis=1))
    if differ.size:
        t = int(differ[0])
        raise ValueError(
            f"episode {where}: the replay diverges from the logged observations at step {t} "
            f"(logged {logged[t].tolist()}, replayed {replayed[t].tolist()}): the session ran "
            "on other traffic or another SUMO"
        )


def export_fcd(record: EpisodeRecord, path: str | Path) -> Path:
    """Write the episode's SUMO FCD XML (every vehicle, every timestep) to ``path`` (gzipped
    when the name ends in ``.gz``, as SUMO writes it).

    One ``<timestep>`` per action, T in all: SUMO labels a state with the time its step began,
    so the timestep of time ``k * step_length_s`` holds the state after the env's step
    ``k + 1`` (``info["t"] == k + 1``), and the state at reset is not in the file (a GIF of
    the episode has T + 1 frames). The ego's ``x`` there is the road's start offset plus
    ``info["position_m"]`` (``SimConfig.ego_start_m``, 300 m by default)."""
    path = Path(path)
    replay(record, fcd_output=path)
    return path


def render_gif(
    record: EpisodeRecord,
    path: str | Path,
    *,
    every: int = 1,
    max_frames: int | None = None,
    fps: float | None = None,
) -> Path:
    """Draw the episode into a GIF: every ``every``-th timestep of the WHOLE episode (unless
    ``max_frames`` caps it), played at ``fps`` frames per second (default: real time at stride
    1, one frame per step length: 4 at the default 0.25 s steps). The frame delay is written in
    milliseconds, as imageio's GIF writer expects. ``path`` ends in ``.gif``, in a directory
    that exists: both are checked before the episode is replayed and drawn."""
    import imageio.v2 as imageio

    from sumo_scenarios.render import render_frame

    if fps is None:
        fps = 1.0 / record.sim.step_length_s
    counts_ok = all(
        _as_int(v) is not None and v >= 1
        for v in (every, *(() if max_frames is None else (max_frames,)))
    )
    if not counts_ok or not _is_real(fps) or not 0 < fps < float("inf"):
        raise ValueError(
            f"every and max_frames must be ints >= 1 and fps a number > 0, got every={every!r}, "
            f"max_frames={max_frames!r}, fps={fps!r}"
        )
    # checked first: these failed in imageio only after the whole replay and drawing (minutes
    # for a long episode), a name without a suffix leaving an empty file behind
    path = Path(path)
    if path.suffix.lower() != ".gif":
        raise ValueError(f"render_gif writes a GIF: give a path ending in .gif, got {str(path)!r}")
    if path.is_dir():
        raise ValueError(f"{str(path)!r} is a directory; give the GIF's file path (e.g. ep.gif)")
    if not path.parent.is_dir():
        raise ValueError(f"the directory of {str(path)!r} does not exist; create it first")
    every = int(every)
    max_frames = None if max_frames is None else int(max_frames)
    _, shots = replay(record, frames=True)
    shots = shots[::every]
    if max_frames is not None:
        shots = shots[:max_frames]
    images = [render_frame(f) for f in shots]
    imageio.mimsave(path, images, duration=1000.0 / fps, loop=0)
    return path


def _read_fcd(fcd: Path, record: EpisodeRecord) -> Any:
    """The root element of ``fcd``, refused (ValueError naming the file) unless it is an FCD
    of ``record``'s length and step length: one ``<timestep>`` per action, ``k *
    step_length_s`` seconds for the k-th (SUMO writes times to the millisecond or 2 decimals)."""
    import gzip
    import xml.etree.ElementTree as ET
    import zlib

    hint = "expected the episode's FCD file, written by export_fcd(record, path)"
    with fcd.open("rb") as f:  # SUMO gzips an output whose name ends in .gz
        zipped = f.read(2) == b"\x1f\x8b"
    try:
        with (gzip.open if zipped else open)(fcd, "rb") as f:
            root = ET.parse(f).getroot()
    except (ET.ParseError, EOFError, gzip.BadGzipFile, zlib.error) as exc:
        raise ValueError(f"{fcd} is not XML ({exc}): {hint}") from None
    if root.tag != "fcd-export":
        raise ValueError(
            f"{fcd} is not an FCD file (its root element is <{root.tag}>, not <fcd-export>): {hint}"
        )
    try:
        times = [float(ts.get("time", "")) for ts in root.findall("timestep")]
    except ValueError:
        raise ValueError(f"{fcd} has a <timestep> whose time is not a number: {hint}") from None
    dt, n = record.sim.step_length_s, len(record.actions)
    if len(times) != n or any(abs(t - k * dt) > 0.0051 for k, t in enumerate(times)):
        apart = f" {times[1] - times[0]:.3g} s apart" if len(times) > 1 else ""
        raise ValueError(
            f"{fcd} holds {len(times)} timesteps{apart}, and the record has {n} steps of "
            f"{dt:g} s: it is not this record's FCD; write it with export_fcd(record, path)"
        )
    return root


def _write_replay_input(root: Any, out: Path, road_end_m: float) -> None:
    """Write the recorded FCD (its parsed ``root``) for SUMO's fcd-replay device to ``out``, adding
    one entry per vanished car.

    The device inserts every vehicle of the file at its first recorded place and moves it to
    each recorded place in turn, but it never removes a vehicle whose trajectory ends: it leaves
    only when it reaches the end of its route. A car the episode took off (recycled) is
    therefore moved, one step after its last recorded one, to the end of its lane
    (``road_end_m``), where it arrives and leaves in that same step.
    """
    import xml.etree.ElementTree as ET

    steps = root.findall("timestep")
    last: dict[str, tuple[int, ET.Element]] = {}
    for i, ts in enumerate(steps):
        for v in ts.findall("vehicle"):
            last[v.get("id", "")] = (i, v)
    for i, v in last.values():
        if i + 1 < len(steps):
            e = ET.SubElement(steps[i + 1], "vehicle", dict(v.attrib))
            e.set("x", f"{road_end_m:.2f}")
            e.set("pos", f"{road_end_m:.2f}")
    ET.ElementTree(root).write(out, xml_declaration=True, encoding="UTF-8")


def _beside_fcd(fcd: Path, suffix: str) -> Path:
    """A file :func:`write_sumocfg` writes or names beside the FCD ``fcd``: the FCD's name
    less ``.gz``, ``.xml`` and ``.fcd`` (each if it ends so, in that order), plus ``suffix``:
    ``.replay.xml`` (the fcd-replay input) or ``.rerun.xml`` (the re-run FCD output)."""
    stem = fcd.name.removesuffix(".gz").removesuffix(".xml").removesuffix(".fcd")
    return fcd.with_name(stem + suffix)


def _refuse_commas(fcd_path: str | Path, path: str | Path) -> None:
    """Raise ValueError if a file the ``.sumocfg`` at ``path`` would list holds a comma in its
    path (SUMO splits file lists at commas, with no way to escape one: a configuration naming
    such a file was written, and ``sumo -c`` then failed with "Cannot read file 'a'").

    The files: the fcd-replay input named after ``fcd_path`` (relative to the configuration's
    directory) and the shipped network and vehicle types. It reads and writes nothing, so a
    caller can check before writing the FCD (``torchcbl replay`` does).
    """
    from sumo_scenarios.scenarios import data_path

    replay_input = _beside_fcd(Path(fcd_path).resolve(), ".replay.xml")
    try:
        named = str(replay_input.relative_to(Path(path).resolve().parent))
    except ValueError:
        named = str(replay_input)
    if "," in named:
        raise ValueError(
            f"a .sumocfg cannot name a file whose path holds a comma (SUMO splits file lists "
            f"at commas), and the FCD's fcd-replay input, named after it ({named}), holds one: "
            "give the FCD a name without a comma"
        )
    shipped = [str(data_path(n)) for n in ("road.net.xml", "driving.add.xml")]
    if any("," in p for p in shipped):
        raise ValueError(
            f"a .sumocfg cannot name a file whose path holds a comma (SUMO splits file lists "
            f"at commas), and the shipped network and vehicle types it names "
            f"({' and '.join(shipped)}) are under a path with one: move the package "
            "(sumo_scenarios) to a path without a comma"
        )


def write_sumocfg(record: EpisodeRecord, fcd_path: str | Path, path: str | Path) -> Path:
    """Write a ``.sumocfg`` that replays an exported FCD file in SUMO alone (``sumo-gui -c PATH``).

    Beside ``fcd_path`` (the FCD written by :func:`export_fcd` for this ``record``; gzipped
    too, as SUMO writes it for a name ending in ``.gz``) it writes
    ``<fcd stem>.replay.xml``, the input of SUMO's fcd-replay device: the recorded FCD plus,
    for every car the episode removed before its end, one entry at the end of its lane one
    step later, where SUMO lets it leave (the device itself never removes a vehicle). The
    configuration names the shipped network and additional file (vehicle types; absolute
    paths), the replay input and a re-run FCD output ``<fcd stem>.rerun.xml`` (both relative,
    so the three files move together), begin 0, the episode's end and step length, and
    sumo-gui's delay for real time. Under it every vehicle takes its recorded lane and
    position at every recorded step (the device moves it there; insertion checks are off so
    cars enter exactly where they were recorded): the re-run FCD equals the recorded one in
    every vehicle's x, y, lane and position, and in speed except at each car's first step.
    Contacts stay possible as in the episode (``collision.action none``, as when recording).

    A file the configuration lists (the replay input, named after the FCD, and the shipped
    network and vehicle types) may not hold a comma in its path, which SUMO splits file lists
    at: ValueError, before anything is written; so are an FCD that is not this record's (not
    FCD XML, or another number of timesteps or step length) and a ``path`` that is a directory
    or lies in one that does not exist.

    What SUMO prints: no error and no teleport. Each removed car is moved once to the lane end,
    which SUMO reports as "moved by TraCI" (shown for the first 3, then counted:
    ``aggregate-warnings 3``); emergency-braking warnings are off (threshold 1000), because
    the device sets every speed from the recording and a car enters at a speed of SUMO's
    choosing (the device does not pass the recorded one), so the first speed change of each
    car looks like a hard brake that the episode never had.
    """
    import re
    from xml.sax.saxutils import escape

    from sumo_scenarios.scenarios import data_path
    from sumo_scenarios.sim import libsumo_lane_length_from_net

    path = Path(path)
    fcd = Path(fcd_path).resolve()
    if not fcd.is_file():
        raise FileNotFoundError(
            f"write_sumocfg needs the episode's FCD file, {fcd} does not exist: "
            "write it first with export_fcd(record, path)"
        )
    # checked first: open() failed on these only once the replay input was written
    if path.is_dir():
        raise ValueError(f"{str(path)!r} is a directory; give the .sumocfg's file path")
    if not path.parent.is_dir():
        raise ValueError(f"the directory of {str(path)!r} does not exist; create it first")
    # (a gzipped FCD, "ep.fcd.xml.gz", is read as such; its replay input and re-run are plain)
    replay_input = _beside_fcd(fcd, ".replay.xml")
    rerun = _beside_fcd(fcd, ".rerun.xml")

    def rel(p: Path) -> str:
        try:
            return str(p.relative_to(path.resolve().parent))
        except ValueError:
            return str(p)

    _refuse_commas(fcd, path)
    root = _read_fcd(fcd, record)
    _write_replay_input(root, replay_input, libsumo_lane_length_from_net())

    def attr(value: object) -> str:  # a file name may hold & < > or a quote
        return escape(str(value), {'"': "&quot;"})

    def note(value: object) -> str:  # "--" may not appear inside an XML comment
        return re.sub("-(?=-)", "- ", str(value))

    dt = record.sim.step_length_s
    end = len(record.actions) * dt
    # device.fcd-replay.file: SUMO 1.28 renamed it "files" and still reads "file"; SUMO before
    # 1.28 (an admitted eclipse-sumo, or a sumo-gui of the user's own) knows only "file"
    text = f"""<?xml version="1.0" encoding="UTF-8"?>
<!-- Written by sumo_scenarios.replay.write_sumocfg for episode {note(record.label or "-")}
     (episode seed {record.episode_seed}); recorded FCD: {note(fcd.name)}.
     sumo-gui -c {note(path.name)} replays it (press play); sumo -c {note(path.name)} replays it
     headless and writes {note(rerun.name)}, whose positions equal the recorded ones. -->
<configuration>
    <input>
        <net-file value="{attr(data_path("road.net.xml"))}"/>
        <additional-files value="{attr(data_path("driving.add.xml"))}"/>
    </input>
    <time>
        <begin value="0"/>
        <end value="{end!r}"/>
        <step-length value="{dt!r}"/>
    </time>
    <processing>
        <collision.action value="none"/>
        <insertion-checks value="none"/>
        <eager-insert value="true"/>
        <emergencydecel.warning-threshold value="1000"/>
    </processing>
    <fcd_replay_device>
        <device.fcd-replay.file value="{attr(rel(replay_input))}"/>
    </fcd_replay_device>
    <output>
        <fcd-output value="{attr(rel(rerun))}"/>
    </output>
    <report>
        <no-step-log value="true"/>
        <aggregate-warnings value="3"/>
    </report>
    <gui_only>
        <delay value="{dt * 1000.0!r}"/>
    </gui_only>
</configuration>
"""
    path.write_text(text, encoding="utf-8")  # as its XML declaration says
    return path
